# arthrosim_add_library(NAME DIR): one library per top-level folder. Sources are
# every *.cc directly in DIR (CONFIGURE_DEPENDS so new files are picked up).
function(arthrosim_add_library name dir)
  file(GLOB _srcs CONFIGURE_DEPENDS ${dir}/*.cc)
  file(GLOB _hdrs CONFIGURE_DEPENDS ${dir}/*.h)
  if(NOT _srcs)
    # A library whose folder has no sources yet still needs one translation unit.
    set(_anchor ${CMAKE_BINARY_DIR}/generated/${name}_anchor.cc)
    file(WRITE ${_anchor} "// generated: ${name} has no sources of its own yet\n")
    set(_srcs ${_anchor})
  endif()
  add_library(${name} STATIC ${_srcs} ${_hdrs})
  target_include_directories(${name} PUBLIC ${CMAKE_SOURCE_DIR} ${CMAKE_BINARY_DIR}/generated)
  target_link_libraries(${name} PUBLIC Eigen3::Eigen)
  target_compile_options(${name} PRIVATE -Wall -Wextra -Wno-unused-parameter)
endfunction()
