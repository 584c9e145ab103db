# Sample runs of arthrosim-prepare --help on the bundled knee (each ~1 s).
add_test(NAME sample.arthrosim-prepare.coarse
  COMMAND arthrosim-prepare --model ${CMAKE_SOURCE_DIR}/data/models/knee_parametric/coarse --edge-length-mm 3
          --out ${CMAKE_BINARY_DIR}/sample_runs/prepared_coarse.h5)
add_test(NAME sample.arthrosim-prepare.medium
  COMMAND arthrosim-prepare --model ${CMAKE_SOURCE_DIR}/data/models/knee_parametric/medium --edge-length-mm 2
          --out ${CMAKE_BINARY_DIR}/sample_runs/prepared_medium.h5)
set_tests_properties(sample.arthrosim-prepare.coarse sample.arthrosim-prepare.medium PROPERTIES LABELS sample TIMEOUT 60)
