# Every sample run printed by an executable's --help is registered here as a
# CTest (label "sample"), run from the build directory with bundled data.
# Each executable's --help itself must work:
file(GLOB _apps CONFIGURE_DEPENDS ${CMAKE_SOURCE_DIR}/pipelines/apps/*.cc)
foreach(_app ${_apps})
  get_filename_component(_name ${_app} NAME_WE)
  add_test(NAME sample.${_name}.help COMMAND ${_name} --help)
  set_tests_properties(sample.${_name}.help PROPERTIES LABELS sample)
endforeach()
# Per-executable sample runs are added in tests/sample_runs/<name>.cmake.
# They write into build/sample_runs/, made here so that no sample depends on
# another having run first (a single sample run with ctest -R works too).
file(MAKE_DIRECTORY ${CMAKE_BINARY_DIR}/sample_runs)
file(GLOB _runs CONFIGURE_DEPENDS ${CMAKE_SOURCE_DIR}/tests/sample_runs/*.cmake)
foreach(_r ${_runs})
  include(${_r})
endforeach()
