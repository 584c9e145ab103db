# Sample run of arthrosim-surface --help: the bundled osmotic scenario on the
# coarse prepared knee (about 10 s; the prepare step is a fixture).
add_test(NAME sample.arthrosim-surface.prepare_coarse
  COMMAND arthrosim-prepare --model ${CMAKE_SOURCE_DIR}/data/models/knee_parametric/coarse
          --out ${CMAKE_BINARY_DIR}/surface_sample_prepared_coarse.h5)
set_tests_properties(sample.arthrosim-surface.prepare_coarse PROPERTIES LABELS sample TIMEOUT 120
  FIXTURES_SETUP surface_prepared_coarse)
add_test(NAME sample.arthrosim-surface.osmotic
  COMMAND arthrosim-surface --prepared ${CMAKE_BINARY_DIR}/surface_sample_prepared_coarse.h5
          --scene ${CMAKE_SOURCE_DIR}/data/scenes/osmotic.yaml --scenario osmotic
          --out ${CMAKE_BINARY_DIR}/surface_sample_osmotic.h5)
set_tests_properties(sample.arthrosim-surface.osmotic PROPERTIES LABELS sample TIMEOUT 300
  FIXTURES_REQUIRED surface_prepared_coarse)
# Generic case: the bundled cantilever plate scene (well under a second).
add_test(NAME sample.arthrosim-surface.cantilever
  COMMAND arthrosim-surface --scene ${CMAKE_SOURCE_DIR}/data/scenes/cantilever_plate.yaml
          --out ${CMAKE_BINARY_DIR}/surface_sample_cantilever.h5)
set_tests_properties(sample.arthrosim-surface.cantilever PROPERTIES LABELS sample TIMEOUT 60)
# The walking sample (a whole cycle: 312 s plus COMAK 21 s, docs/studies.md) is checked as
# a plan: the scene parses and the runner schedules prepare, COMAK and this stage.
add_test(NAME sample.arthrosim-surface.gait_plan
  COMMAND arthrosim run ${CMAKE_SOURCE_DIR}/data/scenes/gait.yaml --out ${CMAKE_BINARY_DIR}/sample_gait_plan --dry-run)
set_tests_properties(sample.arthrosim-surface.gait_plan PROPERTIES LABELS sample TIMEOUT 60
  PASS_REGULAR_EXPRESSION "surface.gait would run")
