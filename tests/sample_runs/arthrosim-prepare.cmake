# Sample runs of arthrosim-prepare --help on the bundled knee (each ~1 s).
add_test(NAME sample.arthrosim-prepare.coarse
  COMMAND arthrosim-prepare --model ${CMAKE_SOURCE_DIR}/data/models/knee_parametric/coarse --edge-length-mm 3
          --out ${CMAKE_BINARY_DIR}/sample_runs/prepared_coarse.h5)
add_test(NAME sample.arthrosim-prepare.medium
  COMMAND arthrosim-prepare --model ${CMAKE_SOURCE_DIR}/data/models/knee_parametric/medium --edge-length-mm 2
          --out ${CMAKE_BINARY_DIR}/sample_runs/prepared_medium.h5)
set_tests_properties(sample.arthrosim-prepare.coarse sample.arthrosim-prepare.medium PROPERTIES LABELS sample TIMEOUT 60)
# The per-surface edge length of the sample in --help, and a malformed item
# (exit 1 with the expected form named).
add_test(NAME sample.arthrosim-prepare.surface_edge
  COMMAND arthrosim-prepare --model ${CMAKE_SOURCE_DIR}/data/models/knee_parametric/coarse --edge-length-mm 3
          --surface-edge-length-mm femur=4.2 --out ${CMAKE_BINARY_DIR}/sample_runs/prepared_anchor.h5)
set_tests_properties(sample.arthrosim-prepare.surface_edge PROPERTIES LABELS sample TIMEOUT 60
  PASS_REGULAR_EXPRESSION "cartilage femur on femur: [0-9]+ -> [0-9]+ triangles")
add_test(NAME sample.arthrosim-prepare.surface_edge_malformed
  COMMAND arthrosim-prepare --model ${CMAKE_SOURCE_DIR}/data/models/knee_parametric/coarse
          --surface-edge-length-mm femur4.2 --out ${CMAKE_BINARY_DIR}/sample_runs/prepared_bad.h5)
set_tests_properties(sample.arthrosim-prepare.surface_edge_malformed PROPERTIES LABELS sample TIMEOUT 60
  WILL_FAIL TRUE)
