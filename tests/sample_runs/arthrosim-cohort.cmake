# Sample runs of `arthrosim cohort --help` (label "sample"). The whole tiny
# cohort runs in tests/workflow/cohort_test.cc (the same shape with its own
# trial copies); here: planning it, and Snakemake's dry run of the plan
# (skipped, exit 77, where snakemake is not installed).
set(_cohort_out ${CMAKE_BINARY_DIR}/sample_runs/cohort_tiny)
add_test(NAME sample.arthrosim.cohort_plan_only
  COMMAND arthrosim cohort data/cohorts/tiny.yaml --out ${_cohort_out} --plan-only
  WORKING_DIRECTORY ${CMAKE_SOURCE_DIR})
set_tests_properties(sample.arthrosim.cohort_plan_only PROPERTIES LABELS sample
  FIXTURES_SETUP arthrosim_cohort_plan
  PASS_REGULAR_EXPRESSION "2 subject\\(s\\) x 2 setting\\(s\\): 16 stage runs planned in .*plan.json.*to run it: snakemake --snakefile .*workflow/Snakefile")
add_test(NAME sample.arthrosim.cohort_dry_run
  COMMAND sh -c "command -v snakemake >/dev/null || exit 77; $<TARGET_FILE:arthrosim> cohort data/cohorts/tiny.yaml --out ${_cohort_out} --dry-run"
  WORKING_DIRECTORY ${CMAKE_SOURCE_DIR})
set_tests_properties(sample.arthrosim.cohort_dry_run PROPERTIES LABELS sample
  FIXTURES_REQUIRED arthrosim_cohort_plan SKIP_RETURN_CODE 77
  PASS_REGULAR_EXPRESSION "stage_comak +4 .*stage_post +4 .*stage_prepare +4 .*stage_surface_osmotic +4 .*total +18 .*This was a dry-run")
# A bad cohort file stops before anything runs, naming file, line, expected and found.
add_test(NAME sample.arthrosim.cohort_bad_file
  COMMAND sh -c "printf 'scene: tiny_knee.yaml\\nsubject:\\n  a: {}\\n' > ${CMAKE_BINARY_DIR}/sample_runs/bad_cohort.yaml; $<TARGET_FILE:arthrosim> cohort ${CMAKE_BINARY_DIR}/sample_runs/bad_cohort.yaml --out ${_cohort_out}_bad 2>&1; echo exit=$?"
  WORKING_DIRECTORY ${CMAKE_SOURCE_DIR})
set_tests_properties(sample.arthrosim.cohort_bad_file PROPERTIES LABELS sample
  PASS_REGULAR_EXPRESSION "bad_cohort.yaml:2:1: error: expected a key of a cohort file \\(description, scene, set, settings, subjects\\), found .subject..*exit=1")
