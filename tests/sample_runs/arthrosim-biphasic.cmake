# Sample runs of arthrosim-biphasic (--help): five frames of the coarse bundled
# knee's stage-1 kinematics (COMAK on the prepared surfaces, a fixture), then
# the biphasic layers on them (about 10 s) and the comparison of two runs.
add_test(NAME sample.arthrosim-biphasic.prepare_coarse
  COMMAND arthrosim-prepare --model ${CMAKE_SOURCE_DIR}/data/models/knee_parametric/coarse
          --out ${CMAKE_BINARY_DIR}/sample_runs/biphasic_prepared.h5)
set_tests_properties(sample.arthrosim-biphasic.prepare_coarse PROPERTIES LABELS sample TIMEOUT 120
  FIXTURES_SETUP biphasic_prepared)
add_test(NAME sample.arthrosim-biphasic.kinematics
  COMMAND arthrosim-comak --model ${CMAKE_SOURCE_DIR}/data/models/knee_parametric/coarse
          --prepared ${CMAKE_BINARY_DIR}/sample_runs/biphasic_prepared.h5
          --trial ${CMAKE_SOURCE_DIR}/data/trials/synthetic_gait --first-frame 10 --last-frame 14 --quiet
          --out ${CMAKE_BINARY_DIR}/sample_runs/biphasic_kinematics.h5)
set_tests_properties(sample.arthrosim-biphasic.kinematics PROPERTIES LABELS sample TIMEOUT 300
  FIXTURES_REQUIRED biphasic_prepared FIXTURES_SETUP biphasic_kinematics)
add_test(NAME sample.arthrosim-biphasic.five_frames
  COMMAND arthrosim-biphasic --prepared ${CMAKE_BINARY_DIR}/sample_runs/biphasic_prepared.h5
          --kinematics ${CMAKE_BINARY_DIR}/sample_runs/biphasic_kinematics.h5 --element-layers 1 --quiet
          --out ${CMAKE_BINARY_DIR}/sample_runs/biphasic_five_frames.h5)
set_tests_properties(sample.arthrosim-biphasic.five_frames PROPERTIES LABELS sample TIMEOUT 300
  FIXTURES_REQUIRED biphasic_kinematics FIXTURES_SETUP biphasic_five_frames
  PASS_REGULAR_EXPRESSION "femur .* factorised 1 x")
add_test(NAME sample.arthrosim-biphasic.compare
  COMMAND arthrosim-biphasic --out ${CMAKE_BINARY_DIR}/sample_runs/biphasic_five_frames.h5
          --compare-to ${CMAKE_BINARY_DIR}/sample_runs/biphasic_five_frames.h5 --compare-only)
set_tests_properties(sample.arthrosim-biphasic.compare PROPERTIES LABELS sample TIMEOUT 60
  FIXTURES_REQUIRED biphasic_five_frames PASS_REGULAR_EXPRESSION "compare worst relative difference 0")
# The whole gait cycle through the runner (prepare, COMAK, this stage: about
# 6 min on a loaded 2-core machine) is checked as a plan.
add_test(NAME sample.arthrosim-biphasic.gait_plan
  COMMAND arthrosim run ${CMAKE_SOURCE_DIR}/data/scenes/biphasic_gait.yaml --out ${CMAKE_BINARY_DIR}/sample_runs/biphasic_gait_plan --dry-run)
set_tests_properties(sample.arthrosim-biphasic.gait_plan PROPERTIES LABELS sample TIMEOUT 60
  PASS_REGULAR_EXPRESSION "biphasic would run")
