# Sample run of arthrosim-comak (--help): the coarse bundled knee over the
# first three frames of the SYNTHETIC trial (a few seconds), written into the
# build tree. Exit code 2 would mean a frame failed.
add_test(NAME sample.arthrosim-comak.coarse
  COMMAND arthrosim-comak --model ${CMAKE_SOURCE_DIR}/data/models/knee_parametric/knee_coarse.urdf
          --trial ${CMAKE_SOURCE_DIR}/data/trials/synthetic_gait
          --out ${CMAKE_BINARY_DIR}/sample_runs/comak_coarse.h5 --first-frame 0 --last-frame 2)
set_tests_properties(sample.arthrosim-comak.coarse PROPERTIES LABELS sample TIMEOUT 120)
# The same through a model folder and the demo scene's comak block (effects,
# Ipopt tolerance and limits), as the runner calls the stage.
add_test(NAME sample.arthrosim-comak.scene
  COMMAND arthrosim-comak --model ${CMAKE_SOURCE_DIR}/data/models/knee_parametric/coarse
          --scene ${CMAKE_SOURCE_DIR}/data/scenes/demo.yaml
          --trial ${CMAKE_SOURCE_DIR}/data/trials/synthetic_gait
          --out ${CMAKE_BINARY_DIR}/sample_runs/comak_scene.h5 --first-frame 0 --last-frame 2)
set_tests_properties(sample.arthrosim-comak.scene PROPERTIES LABELS sample TIMEOUT 120)
# With the ankle equilibrium row (soleus and tibialis anterior stand-ins
# added) over three push-off frames.
add_test(NAME sample.arthrosim-comak.ankle
  COMMAND arthrosim-comak --model ${CMAKE_SOURCE_DIR}/data/models/knee_parametric/knee_coarse.urdf
          --ankle-equilibrium --trial ${CMAKE_SOURCE_DIR}/data/trials/synthetic_gait
          --out ${CMAKE_BINARY_DIR}/sample_runs/comak_ankle.h5 --first-frame 50 --last-frame 52)
set_tests_properties(sample.arthrosim-comak.ankle PROPERTIES LABELS sample TIMEOUT 120)
# scripts/kinematics_branches.py (docs/comak.md, "Step control") on the first
# sample's kinematics file: it must read the file and report its 3 frames.
set_tests_properties(sample.arthrosim-comak.coarse PROPERTIES FIXTURES_SETUP comak_coarse_h5)
add_test(NAME sample.script.kinematics_branches
  COMMAND /usr/bin/python3 ${CMAKE_SOURCE_DIR}/scripts/kinematics_branches.py
          ${CMAKE_BINARY_DIR}/sample_runs/comak_coarse.h5 --frames 0:2)
set_tests_properties(sample.script.kinematics_branches PROPERTIES LABELS sample TIMEOUT 60
  FIXTURES_REQUIRED comak_coarse_h5
  PASS_REGULAR_EXPRESSION "3 frames \\(0\\.\\.2\\), 3 converged, objective sum [0-9.e+-]+ m\\^3.*largest \\|pf_flexion")
# A checkpoint after every frame (docs/testing.md, "Checkpoint and resume"):
# the run ends with the kinematics file and no checkpoint left.
add_test(NAME sample.arthrosim-comak.checkpoints
  COMMAND arthrosim-comak --model ${CMAKE_SOURCE_DIR}/data/models/knee_parametric/knee_coarse.urdf
          --checkpoint-interval-s 0 --trial ${CMAKE_SOURCE_DIR}/data/trials/synthetic_gait
          --out ${CMAKE_BINARY_DIR}/sample_runs/comak_checkpoints.h5 --first-frame 0 --last-frame 4)
set_tests_properties(sample.arthrosim-comak.checkpoints PROPERTIES LABELS sample TIMEOUT 120)
