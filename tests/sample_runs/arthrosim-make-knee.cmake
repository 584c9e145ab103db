# Sample run of arthrosim-make-knee --help: the coarse bundled model (about 5 s
# of CPU), written into the build tree.
add_test(NAME sample.arthrosim-make-knee.coarse
  COMMAND arthrosim-make-knee --edge-length-mm 3 --out ${CMAKE_BINARY_DIR}/sample_runs/knee_parametric_coarse)
set_tests_properties(sample.arthrosim-make-knee.coarse PROPERTIES LABELS sample TIMEOUT 120)
