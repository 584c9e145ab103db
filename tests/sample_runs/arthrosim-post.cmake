# Sample runs of arthrosim-post on bundled data (seconds). Without a surface output the
# report lists what is missing; the synthetic map is still read and checked.
add_test(NAME sample.arthrosim-post.map_only
  COMMAND arthrosim-post --map ${CMAKE_SOURCE_DIR}/data/splitlines/synthetic_femur.svg
          --scene ${CMAKE_SOURCE_DIR}/data/scenes/osmotic.yaml --out ${CMAKE_BINARY_DIR}/sample_runs/post_map_only)
set_tests_properties(sample.arthrosim-post.map_only PROPERTIES LABELS sample TIMEOUT 60)
