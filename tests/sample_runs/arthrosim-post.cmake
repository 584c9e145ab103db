# Sample runs of arthrosim-post on bundled data (seconds). Without a surface output the
# report lists what is missing; the synthetic map is still read and checked.
add_test(NAME sample.arthrosim-post.map_only
  COMMAND arthrosim-post --map ${CMAKE_SOURCE_DIR}/data/splitlines/synthetic_femur.svg
          --scene ${CMAKE_SOURCE_DIR}/data/scenes/osmotic.yaml --out ${CMAKE_BINARY_DIR}/sample_runs/post_map_only)
set_tests_properties(sample.arthrosim-post.map_only PROPERTIES LABELS sample TIMEOUT 60)
# The report's one layout for every stage: stage 1 alone (the five-frame
# kinematics of the biphasic samples), the biphasic layers and a shockwave run
# (the cartilage bar, under a second), then the report drawn in headless
# Chromium (scripts/report_check.sh; skipped when chromium is not installed).
add_test(NAME sample.arthrosim-post.shockwave_bar
  COMMAND arthrosim-shockwave --geometry bar --bar-tissue cartilage --end-time-us 30 --pulse-rise-time-us 10
          --pulse-fall-time-us 10 --pulse-positive-duration-us 20 --pulse-tail-duration-us 0 --quiet
          --out ${CMAKE_BINARY_DIR}/sample_runs/post_sw_bar)
set_tests_properties(sample.arthrosim-post.shockwave_bar PROPERTIES LABELS sample TIMEOUT 60
  FIXTURES_SETUP post_shockwave_bar)
# 6 figures: the biphasic series (4) + its peak contact pressure beside stage 1's
# elastic-foundation pressure, and the shockwave figure.
add_test(NAME sample.arthrosim-post.stages
  COMMAND arthrosim-post --kinematics ${CMAKE_BINARY_DIR}/sample_runs/biphasic_kinematics.h5
          --biphasic ${CMAKE_BINARY_DIR}/sample_runs/biphasic_five_frames.h5
          --shockwave ${CMAKE_BINARY_DIR}/sample_runs/post_sw_bar_efd0.33.h5
          --out ${CMAKE_BINARY_DIR}/sample_runs/post_stages)
set_tests_properties(sample.arthrosim-post.stages PROPERTIES LABELS sample TIMEOUT 60
  FIXTURES_REQUIRED "biphasic_five_frames;post_shockwave_bar" FIXTURES_SETUP post_stages
  PASS_REGULAR_EXPRESSION "wrote .*report.html \\(6 figures\\)")
# The biphasic table names where the largest stresses are (a region of the
# plate, through biphasic::read_layer_series), not a region code.
add_test(NAME sample.arthrosim-post.stages_regions
  COMMAND ${CMAKE_COMMAND} -E cat ${CMAKE_BINARY_DIR}/sample_runs/post_stages/report.html)
set_tests_properties(sample.arthrosim-post.stages_regions PROPERTIES LABELS sample TIMEOUT 30
  FIXTURES_REQUIRED post_stages
  PASS_REGULAR_EXPRESSION "<td>(central|anterior|posterior|medial|lateral) at [0-9.]+ s</td>")
add_test(NAME sample.arthrosim-post.stages_drawn
  COMMAND ${CMAKE_SOURCE_DIR}/scripts/report_check.sh ${CMAKE_BINARY_DIR}/sample_runs/post_stages/report.html)
set_tests_properties(sample.arthrosim-post.stages_drawn PROPERTIES LABELS sample TIMEOUT 150
  FIXTURES_REQUIRED post_stages SKIP_RETURN_CODE 77)
