#!/bin/sh
# Cost of checkpoints (docs/testing.md, "Checkpoint and resume"): wall time of
# the same run with a checkpoint after every frame / step (interval 0) and
# with the default interval (60 s: none in these short runs), median of N
# runs each, and the size of the last checkpoint.
#   scripts/checkpoint_overhead.sh [BUILD_DIR] [N] [STAGES]
# STAGES: any of "comak surface biphasic shockwave" (default all four).
# COMAK: the coarse knee, frames 0-19 of the synthetic trial. Surface: the
# walking scenario of tests/pipelines/resume_test.cc (femur and medial tibial
# cartilage at 10 mm edges, mesh contact, 5 HHT steps of 10 ms). Biphasic: the
# canonical two-layer case (4 element layers, 50 steps of 10 ms). Shockwave:
# the coarse knee at d = 2 mm (93,464 automata), one 0.33 mJ/mm^2 pulse for
# 5 us (42 steps, a frame every 1 us).
set -eu
B=$(cd "${1:-build}" && pwd); N=${2:-3}; STAGES=" ${3:-comak surface biphasic shockwave} "
ROOT=$(cd "$(dirname "$0")/.." && pwd)
W=$(mktemp -d); trap 'rm -rf "$W"' EXIT
cd "$W"
median() { sort -n | awk '{a[NR]=$1} END {print a[int((NR+1)/2)]}'; }
wall() { /usr/bin/time -f %e "$@" >/dev/null 2>time.txt || { cat time.txt; exit 1; }; tail -1 time.txt; }
if [ "${STAGES#* comak }" != "$STAGES" ]; then
COMAK="$B/bin/arthrosim-comak --model $ROOT/data/models/knee_parametric/coarse --trial $ROOT/data/trials/synthetic_gait --first-frame 0 --last-frame 19 --out k.h5 --quiet"
for i in $(seq "$N"); do wall $COMAK; done | median > comak_default.txt
for i in $(seq "$N"); do wall $COMAK --checkpoint-interval-s 0; done | median > comak_every.txt
# The size: a run killed right after its 19th checkpoint (19 of 20 frames).
ARTHROSIM_TEST_KILL_AT_CHECKPOINT=19 $COMAK --checkpoint-interval-s 0 >/dev/null 2>&1 || true
echo "comak (20 frames): median wall $(cat comak_default.txt) s without checkpoints, $(cat comak_every.txt) s with one after every frame; checkpoint after 19 frames: $(stat -c %s k.h5.checkpoint) bytes (output $(stat -c %s k.h5.partial) bytes so far)"
rm -f k.h5*
fi
if [ "${STAGES#* surface }" != "$STAGES" ]; then
$B/bin/arthrosim-comak --model $ROOT/data/models/knee_parametric/coarse --trial $ROOT/data/trials/synthetic_gait --first-frame 10 --last-frame 14 --out kin.h5 --quiet >/dev/null
$B/bin/arthrosim-prepare --model $ROOT/data/models/knee_parametric/coarse --edge-length-mm 10 --out prepared.h5 >/dev/null 2>&1
scene() {
  cat <<YAML
model: $ROOT/data/models/knee_parametric/coarse
trial: $ROOT/data/trials/synthetic_gait
outputs: [surface]
comak: {effects: [ligaments, muscles, tibiofemoral_contact, patellofemoral_contact]}
surface:
  scenarios:
    walk:
      surfaces: [femur, tibia_medial]
      contact_pairs: ["femur:tibia_medial"]
      time_step_s: 1e-2
      output_interval_ms: 10
      seating_time_s: 0.01
      seating_offset_mm: 2.5
      newton_tolerance: 1e-5
      newton_residual_floor_n: 2
      newton_increment_floor_mm: 1e-2
      max_newton_iterations: 25
      foundation_from_thickness: true
      foundation_damping_n_s_per_mm3: 1e-3
      contact_stiffness_n_per_mm3: 300
      contact_max_depth_mm: 3
      contact_smoothing_mm: 0.02
      periphery_normal: foundation
      checkpoint_interval_s: $1
      effects: [foundation_springs, foundation_damping, periphery_fixed, imposed_kinematics, inertia, mesh_contact]
YAML
}
scene 60 > default.yaml; scene 0 > every.yaml
SURFACE="$B/bin/arthrosim-surface --prepared prepared.h5 --kinematics kin.h5 --out s.h5 --quiet"
for i in $(seq "$N"); do wall $SURFACE --scene default.yaml; done | median > surface_default.txt
for i in $(seq "$N"); do wall $SURFACE --scene every.yaml; done | median > surface_every.txt
ARTHROSIM_TEST_KILL_AT_CHECKPOINT=4 $SURFACE --scene every.yaml >/dev/null 2>&1 || true
echo "surface (5 steps, 628 nodes): median wall $(cat surface_default.txt) s without checkpoints, $(cat surface_every.txt) s with one after every step; checkpoint after 4 steps: $(stat -c %s s.h5.checkpoint) bytes (output $(stat -c %s s.h5.partial) bytes so far)"
fi
if [ "${STAGES#* biphasic }" != "$STAGES" ]; then
$B/bin/arthrosim-biphasic --canonical case --out c.h5 --end-time-s 0.01 --quiet >/dev/null
BIPHASIC="$B/bin/arthrosim-biphasic --prepared case/two_layers_prepared.h5 --kinematics case/two_layers_kinematics.h5 --layers femur,tibia_medial --end-time-s 0.5 --out b.h5 --quiet"
for i in $(seq "$N"); do wall $BIPHASIC; done | median > biphasic_default.txt
for i in $(seq "$N"); do wall $BIPHASIC --checkpoint-interval-s 0; done | median > biphasic_every.txt
ARTHROSIM_TEST_KILL_AT_CHECKPOINT=49 $BIPHASIC --checkpoint-interval-s 0 >/dev/null 2>&1 || true
echo "biphasic (50 steps, 2 layers): median wall $(cat biphasic_default.txt) s without checkpoints, $(cat biphasic_every.txt) s with one after every step; checkpoint after 49 steps: $(stat -c %s b.h5.checkpoint) bytes (output $(stat -c %s b.h5.partial) bytes so far)"
fi
if [ "${STAGES#* shockwave }" != "$STAGES" ]; then
$B/bin/arthrosim-prepare --model $ROOT/data/models/knee_parametric/coarse --out sw_prepared.h5 >/dev/null 2>&1
SHOCKWAVE="$B/bin/arthrosim-shockwave --prepared sw_prepared.h5 --model $ROOT/data/models/knee_parametric/coarse --automaton-diameter-mm 2 --end-time-us 5 --output-interval-us 1 --out sw --quiet"
for i in $(seq "$N"); do wall $SHOCKWAVE; done | median > shockwave_default.txt
for i in $(seq "$N"); do wall $SHOCKWAVE --checkpoint-interval-s 0; done | median > shockwave_every.txt
ARTHROSIM_TEST_KILL_AT_CHECKPOINT=41 $SHOCKWAVE --checkpoint-interval-s 0 >/dev/null 2>&1 || true
echo "shockwave (2 mm knee, 93,464 automata, 42 steps): median wall $(cat shockwave_default.txt) s without checkpoints, $(cat shockwave_every.txt) s with one after every step; checkpoint after 41 steps: $(stat -c %s sw.checkpoint) bytes (output $(stat -c %s sw_efd0.33.h5.partial) bytes so far)"
fi
