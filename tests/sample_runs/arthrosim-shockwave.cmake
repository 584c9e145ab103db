# Sample runs of arthrosim-shockwave --help: the quick look at the 2 mm knee
# (about 10 s on one core), the seed's three 1 mm runs and the compression as
# plans (--dry-run: the model is built and the steps counted; the runs take
# about 12 min each with 2 threads on the loaded machine, docs/shockwave.md
# Performance), and the cartilage bar (under a second).
add_test(NAME sample.arthrosim-shockwave.prepare_coarse
  COMMAND arthrosim-prepare --model ${CMAKE_SOURCE_DIR}/data/models/knee_parametric/coarse
          --out ${CMAKE_BINARY_DIR}/shockwave_sample_prepared_coarse.h5)
set_tests_properties(sample.arthrosim-shockwave.prepare_coarse PROPERTIES LABELS sample TIMEOUT 120
  FIXTURES_SETUP shockwave_prepared_coarse)
add_test(NAME sample.arthrosim-shockwave.quick
  COMMAND arthrosim-shockwave --prepared ${CMAKE_BINARY_DIR}/shockwave_sample_prepared_coarse.h5
          --model ${CMAKE_SOURCE_DIR}/data/models/knee_parametric/coarse --automaton-diameter-mm 2 --end-time-us 10
          --quiet --out ${CMAKE_BINARY_DIR}/sample_runs/sw_quick)
set_tests_properties(sample.arthrosim-shockwave.quick PROPERTIES LABELS sample TIMEOUT 300
  FIXTURES_REQUIRED shockwave_prepared_coarse PASS_REGULAR_EXPRESSION "efd0.33: [0-9]+ steps")
add_test(NAME sample.arthrosim-shockwave.three_efd_plan
  COMMAND arthrosim-shockwave --prepared ${CMAKE_BINARY_DIR}/shockwave_sample_prepared_coarse.h5
          --model ${CMAKE_SOURCE_DIR}/data/models/knee_parametric/coarse --efd-mj-per-mm2 0.12 0.33 0.8
          --dry-run --quiet --out ${CMAKE_BINARY_DIR}/sample_runs/sw)
set_tests_properties(sample.arthrosim-shockwave.three_efd_plan PROPERTIES LABELS sample TIMEOUT 300
  FIXTURES_REQUIRED shockwave_prepared_coarse PASS_REGULAR_EXPRESSION "would run efd0.8: [0-9]+ steps")
add_test(NAME sample.arthrosim-shockwave.compression_plan
  COMMAND arthrosim-shockwave --prepared ${CMAKE_BINARY_DIR}/shockwave_sample_prepared_coarse.h5
          --model ${CMAKE_SOURCE_DIR}/data/models/knee_parametric/coarse --automaton-diameter-mm 2
          --effects mca_elastic pore_fluid filtration platen_compression --dry-run --quiet
          --out ${CMAKE_BINARY_DIR}/sample_runs/sw_stiff)
set_tests_properties(sample.arthrosim-shockwave.compression_plan PROPERTIES LABELS sample TIMEOUT 300
  FIXTURES_REQUIRED shockwave_prepared_coarse PASS_REGULAR_EXPRESSION "would run compression: [0-9]+ steps")
add_test(NAME sample.arthrosim-shockwave.bar
  COMMAND arthrosim-shockwave --geometry bar --bar-tissue cartilage --end-time-us 60 --pulse-rise-time-us 10
          --pulse-fall-time-us 10 --pulse-positive-duration-us 20 --pulse-tail-duration-us 0 --quiet
          --out ${CMAKE_BINARY_DIR}/sample_runs/sw_bar)
set_tests_properties(sample.arthrosim-shockwave.bar PROPERTIES LABELS sample TIMEOUT 60
  PASS_REGULAR_EXPRESSION "bar: p-wave speed 16[0-9][0-9]\\.[0-9] m/s")
# Bad input: an automaton larger than the cortical shell (exit 1, the reason named).
add_test(NAME sample.arthrosim-shockwave.too_coarse
  COMMAND arthrosim-shockwave --prepared ${CMAKE_BINARY_DIR}/shockwave_sample_prepared_coarse.h5
          --automaton-diameter-mm 3 --dry-run --out ${CMAKE_BINARY_DIR}/sample_runs/sw_bad)
set_tests_properties(sample.arthrosim-shockwave.too_coarse PROPERTIES LABELS sample TIMEOUT 60
  FIXTURES_REQUIRED shockwave_prepared_coarse WILL_FAIL TRUE)
# Through the stage table: the bar scene run by `arthrosim run` (the runner
# calls arthrosim-shockwave --scene and checks its effect ledger), and the
# plan of the seed's three runs (prepare, then the stage).
add_test(NAME sample.arthrosim-shockwave.scene_bar
  COMMAND arthrosim run data/scenes/shockwave_bar.yaml --out ${CMAKE_BINARY_DIR}/sample_runs/shockwave_bar_scene --jobs 1 --force
  WORKING_DIRECTORY ${CMAKE_SOURCE_DIR})
set_tests_properties(sample.arthrosim-shockwave.scene_bar PROPERTIES LABELS sample TIMEOUT 120
  PASS_REGULAR_EXPRESSION "finished: shockwave ran")
add_test(NAME sample.arthrosim-shockwave.scene_plan
  COMMAND arthrosim run data/scenes/shockwave.yaml --out ${CMAKE_BINARY_DIR}/sample_runs/shockwave_scene --dry-run
  WORKING_DIRECTORY ${CMAKE_SOURCE_DIR})
set_tests_properties(sample.arthrosim-shockwave.scene_plan PROPERTIES LABELS sample TIMEOUT 60
  PASS_REGULAR_EXPRESSION "plan: prepare shockwave post")
