# Sample runs of arthrosim-make-knee --help (coarse ~5 s, medium ~10 s of CPU),
# written into the build tree. The fine model (1 mm, about a minute) is listed
# in --help as on-demand use for benchmarks, not as a sample run.
add_test(NAME sample.arthrosim-make-knee.coarse
  COMMAND arthrosim-make-knee --edge-length-mm 3 --out ${CMAKE_BINARY_DIR}/sample_runs/knee_parametric_coarse)
add_test(NAME sample.arthrosim-make-knee.medium
  COMMAND arthrosim-make-knee --edge-length-mm 2 --out ${CMAKE_BINARY_DIR}/sample_runs/knee_parametric_medium)
set_tests_properties(sample.arthrosim-make-knee.coarse sample.arthrosim-make-knee.medium
  PROPERTIES LABELS sample TIMEOUT 120)
