# Sample runs of `arthrosim --help` (label "sample"); `arthrosim --help` itself
# is registered by tests/sample_runs.cmake.

# `arthrosim schema`: prints the scene reference.
add_test(NAME sample.arthrosim.schema COMMAND arthrosim schema)
set_tests_properties(sample.arthrosim.schema PROPERTIES LABELS sample
  PASS_REGULAR_EXPRESSION "edge_length_mm.*ipopt_tolerance.*time_step_s.*angle_threshold_deg.*mesh_contact")

# The demo scene runs prepare, comak, the three surface scenarios and post;
# registered once that program is part of the source tree. The suite shortens
# the two walking scenarios to their first 30 ms (seating plus three steps)
# with --set; the README names the demo as bundled (the whole gait cycle).
if(EXISTS ${CMAKE_SOURCE_DIR}/pipelines/apps/arthrosim-prepare.cc)
  set(_demo_out ${CMAKE_BINARY_DIR}/sample_runs/arthrosim_demo)
  set(_demo_short --set surface.scenarios.gait.end_time_s=0.03 --set surface.scenarios.gait_osmotic.end_time_s=0.03)
  # `arthrosim run data/scenes/demo.yaml --out out/demo` (--force: always run
  # the stage, whatever an earlier ctest left behind).
  add_test(NAME sample.arthrosim.demo
    COMMAND arthrosim run data/scenes/demo.yaml --out ${_demo_out} --force ${_demo_short}
    WORKING_DIRECTORY ${CMAKE_SOURCE_DIR})
  set_tests_properties(sample.arthrosim.demo PROPERTIES LABELS sample
    FIXTURES_SETUP arthrosim_demo
    TIMEOUT 600
    # With --jobs (default: the number of cores) stages whose inputs are ready
    # run side by side and finish in any order, so the per-stage lines are
    # checked by what must not appear: a stage that built a term its scenario
    # did not ask for (the runner fails it too) or an osmotic scene that moved.
    PASS_REGULAR_EXPRESSION "with 2 setting\\(s\\) written to .*scene_set.yaml.*comak: effects built: ligaments [0-9]+, muscles 13.*arthrosim: finished: prepare ran .*comak ran .*surface.osmotic ran .*surface.gait ran .*surface.gait_osmotic ran .*post ran"
    FAIL_REGULAR_EXPRESSION "[1-9][0-9]* failed;surface.gait: effects built: [^\n]*osmotic_pressure;surface.osmotic: effects built: [^\n]*(mesh_contact|imposed_kinematics);surface.gait[a-z_]*: effects built: [^\n]*patellofemoral")
  # The same run again reuses every stage.
  add_test(NAME sample.arthrosim.demo_reuse
    COMMAND arthrosim run data/scenes/demo.yaml --out ${_demo_out} ${_demo_short}
    WORKING_DIRECTORY ${CMAKE_SOURCE_DIR})
  set_tests_properties(sample.arthrosim.demo_reuse PROPERTIES LABELS sample
    FIXTURES_REQUIRED arthrosim_demo
    PASS_REGULAR_EXPRESSION "prepare: skipping .* inputs, options and code unchanged.*arthrosim: finished: prepare reused, comak reused, surface.osmotic reused, surface.gait reused, surface.gait_osmotic reused, post reused")
  # The demo's report drawn in headless Chromium: every figure draws
  # (scripts/report_check.sh, the page's own check; skipped without chromium).
  add_test(NAME sample.arthrosim.demo_report_drawn
    COMMAND ${CMAKE_SOURCE_DIR}/scripts/report_check.sh ${_demo_out}/report.html)
  set_tests_properties(sample.arthrosim.demo_report_drawn PROPERTIES LABELS sample TIMEOUT 150
    FIXTURES_REQUIRED arthrosim_demo DEPENDS sample.arthrosim.demo_reuse SKIP_RETURN_CODE 77)
  # `--dry-run` on the same folder: says it would reuse, runs nothing.
  add_test(NAME sample.arthrosim.demo_dry_run
    COMMAND arthrosim run data/scenes/demo.yaml --out ${_demo_out} --dry-run ${_demo_short}
    WORKING_DIRECTORY ${CMAKE_SOURCE_DIR})
  set_tests_properties(sample.arthrosim.demo_dry_run PROPERTIES LABELS sample
    FIXTURES_REQUIRED arthrosim_demo DEPENDS sample.arthrosim.demo_reuse
    PASS_REGULAR_EXPRESSION "prepare: would skip .*dry run finished: prepare would be reused")
  # The demo as bundled (no --set) walks the whole cycle (no end_time_s): a
  # dry run in the same folder sees the option change and would rerun them.
  add_test(NAME sample.arthrosim.demo_bundled_dry_run
    COMMAND arthrosim run data/scenes/demo.yaml --out ${_demo_out} --dry-run
    WORKING_DIRECTORY ${CMAKE_SOURCE_DIR})
  set_tests_properties(sample.arthrosim.demo_bundled_dry_run PROPERTIES LABELS sample
    FIXTURES_REQUIRED arthrosim_demo DEPENDS sample.arthrosim.demo_dry_run
    PASS_REGULAR_EXPRESSION "surface.gait: would run .*options changed: .*surface.gait.end_time_s 0.03 -> \\(unset\\)")
endif()

# `arthrosim run --set`: an unknown key and a bad value stop before anything
# runs (exit 1), naming the key or the line and column of the written scene.
add_test(NAME sample.arthrosim.set_unknown_key
  COMMAND sh -c "$<TARGET_FILE:arthrosim> run data/scenes/osmotic.yaml --out ${CMAKE_BINARY_DIR}/sample_runs/arthrosim_set --dry-run --set surface.scenarios.osmotic.pressure=0.1 2>&1; echo exit=$?"
  WORKING_DIRECTORY ${CMAKE_SOURCE_DIR})
set_tests_properties(sample.arthrosim.set_unknown_key PROPERTIES LABELS sample
  PASS_REGULAR_EXPRESSION "unknown scene key 'surface.scenarios.osmotic.pressure'.*exit=1")
add_test(NAME sample.arthrosim.set_bad_value
  COMMAND sh -c "$<TARGET_FILE:arthrosim> run data/scenes/osmotic.yaml --out ${CMAKE_BINARY_DIR}/sample_runs/arthrosim_set --dry-run --set surface.scenarios.osmotic.osmotic_pressure_mpa=abc 2>&1; echo exit=$?"
  WORKING_DIRECTORY ${CMAKE_SOURCE_DIR})
set_tests_properties(sample.arthrosim.set_bad_value PROPERTIES LABELS sample
  PASS_REGULAR_EXPRESSION "scene_set.yaml:[0-9]+:[0-9]+: error: 'osmotic_pressure_mpa': expected a number, found 'abc'.*exit=1")
add_test(NAME sample.arthrosim.set_malformed
  COMMAND sh -c "$<TARGET_FILE:arthrosim> run data/scenes/osmotic.yaml --out ${CMAKE_BINARY_DIR}/sample_runs/arthrosim_set --dry-run --set prepare.edge_length_mm 2>&1; echo exit=$?"
  WORKING_DIRECTORY ${CMAKE_SOURCE_DIR})
set_tests_properties(sample.arthrosim.set_malformed PROPERTIES LABELS sample
  PASS_REGULAR_EXPRESSION "--set: expected KEY=VALUE, found 'prepare.edge_length_mm'.*exit=1")
add_test(NAME sample.arthrosim.set_dry_run
  COMMAND arthrosim run data/scenes/osmotic.yaml --out ${CMAKE_BINARY_DIR}/sample_runs/arthrosim_set --dry-run
          --set prepare.edge_length_mm=2.5
  WORKING_DIRECTORY ${CMAKE_SOURCE_DIR})
set_tests_properties(sample.arthrosim.set_dry_run PROPERTIES LABELS sample
  PASS_REGULAR_EXPRESSION "with 1 setting\\(s\\) written to .*scene_set.yaml.*plan: prepare surface.osmotic")

# `arthrosim run data/scenes/osmotic.yaml`: prepare, then the osmotic surface
# scenario; no musculoskeletal stage, no mesh contact (the runner checks the
# stage's effect ledger and prints it). Registered once arthrosim-surface is
# in the tree. gait.yaml and gait_osmotic.yaml need arthrosim-comak.
if(EXISTS ${CMAKE_SOURCE_DIR}/pipelines/apps/arthrosim-surface.cc)
  add_test(NAME sample.arthrosim.osmotic
    COMMAND arthrosim run data/scenes/osmotic.yaml --out ${CMAKE_BINARY_DIR}/sample_runs/arthrosim_osmotic --force
    WORKING_DIRECTORY ${CMAKE_SOURCE_DIR})
  set_tests_properties(sample.arthrosim.osmotic PROPERTIES LABELS sample TIMEOUT 600
    PASS_REGULAR_EXPRESSION "plan: prepare surface.osmotic\n.*surface.osmotic: effects built: foundation_springs [0-9]+, foundation_damping [0-9]+, osmotic_pressure [0-9]+, periphery_fixed [0-9]+, inertia [0-9]+\n.*arthrosim: finished: prepare ran .*surface.osmotic ran"
    FAIL_REGULAR_EXPRESSION "mesh_contact|comak")
endif()

# `arthrosim study accuracy --help`: the accuracy-versus-time study and its sample runs.
add_test(NAME sample.arthrosim.study_accuracy_help COMMAND arthrosim study accuracy --help)
set_tests_properties(sample.arthrosim.study_accuracy_help PROPERTIES LABELS sample
  PASS_REGULAR_EXPRESSION "Sample runs.*arthrosim study accuracy data/studies/.*--vary TEXT.*KEY=V1,V2")

# The 2 x 2 grid of `arthrosim study accuracy --help` on the cantilever plate
# (surface stage only, about a second): every setting runs, prepare is reused.
add_test(NAME sample.arthrosim.study_accuracy_grid
  COMMAND arthrosim study accuracy data/scenes/cantilever_plate.yaml
    --vary surface.scenarios.cantilever.youngs_modulus_mpa=100,400
    --vary surface.scenarios.cantilever.shell_thickness_mm=1,2
    --reference surface.scenarios.cantilever.youngs_modulus_mpa=400
    --out ${CMAKE_BINARY_DIR}/sample_runs/arthrosim_study_grid
  WORKING_DIRECTORY ${CMAKE_SOURCE_DIR})
set_tests_properties(sample.arthrosim.study_accuracy_grid PROPERTIES LABELS sample
  PASS_REGULAR_EXPRESSION "study: \\[4/4\\] done.*prepare reused.*recommended for surface.cantilever: .*study: wrote .*report.html")

# The --set sample of `arthrosim --help` (gait over stance), as a dry run:
# the plan and the written scene, nothing solved.
add_test(NAME sample.arthrosim.set_gait_stance
  COMMAND arthrosim run data/scenes/gait.yaml --out ${CMAKE_BINARY_DIR}/sample_runs/gait_stance
          --set surface.scenarios.gait.end_time_s=0.63 --dry-run
  WORKING_DIRECTORY ${CMAKE_SOURCE_DIR})
set_tests_properties(sample.arthrosim.set_gait_stance PROPERTIES LABELS sample
  PASS_REGULAR_EXPRESSION "with 1 setting\\(s\\) written to .*gait_stance/scene_set.yaml.*plan: prepare comak surface.gait\n")

# The real subject's biphasic scenario: the plan is prepare -> comak -> biphasic
# (a dry run; the short-window figures are in docs/biphasic.md, "The real subject").
add_test(NAME sample.arthrosim.lenhart2015_biphasic_dry_run
  COMMAND arthrosim run data/scenes/lenhart2015_biphasic.yaml
          --out ${CMAKE_BINARY_DIR}/sample_runs/lenhart2015_biphasic --dry-run
  WORKING_DIRECTORY ${CMAKE_SOURCE_DIR})
set_tests_properties(sample.arthrosim.lenhart2015_biphasic_dry_run PROPERTIES LABELS sample TIMEOUT 60
  PASS_REGULAR_EXPRESSION "plan: prepare comak biphasic\n.*dry run finished: prepare would run, comak would run, biphasic would run")
