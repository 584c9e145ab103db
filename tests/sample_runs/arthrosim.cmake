# Sample runs of `arthrosim --help` (label "sample"); `arthrosim --help` itself
# is registered by tests/sample_runs.cmake.
#
# `arthrosim schema`: prints the scene reference; must succeed and list a key
# of every block and every effect vocabulary entry it documents.
add_test(NAME sample.arthrosim.schema COMMAND arthrosim schema)
set_tests_properties(sample.arthrosim.schema PROPERTIES LABELS sample
  PASS_REGULAR_EXPRESSION "edge_length_mm.*ipopt_tolerance.*time_step_s.*angle_threshold_deg.*mesh_contact")
