#!/bin/sh
# Overhead of the biphasic stage's checkpoints (docs/biphasic.md, "Checkpoints"):
# the canonical two-layer case (4 element layers, 50 steps of 10 ms), stepping
# wall time with a checkpoint after every step (--checkpoint-interval-s 0)
# against none (86400 s), 3 runs each alternating; prints the medians and
# their ratio.
# Usage: scripts/biphasic_checkpoint_overhead.sh [build dir]
set -e
build=${1:-build}
bin=$(cd "$build" && pwd)/bin/arthrosim-biphasic
dir=$(mktemp -d)
trap 'rm -rf "$dir"' EXIT
"$bin" --canonical "$dir/case" --out "$dir/case/c.h5" --end-time-s 0.01 --quiet >/dev/null
stepping() {
  "$bin" --prepared "$dir/case/two_layers_prepared.h5" --kinematics "$dir/case/two_layers_kinematics.h5" \
    --layers femur,tibia_medial --end-time-s 0.5 --checkpoint-interval-s "$1" --out "$dir/b.h5" --quiet |
    sed -n 's/.*stepping \([0-9.]*\) s.*/\1/p'
}
every="" never=""
for i in 1 2 3; do
  every="$every $(stepping 0)"
  never="$never $(stepping 86400)"
done
median() { echo "$@" | tr ' ' '\n' | sed '/^$/d' | sort -g | sed -n 2p; }
e=$(median $every) n=$(median $never)
echo "stepping wall s, checkpoint every step:$every (median $e)"
echo "stepping wall s, no checkpoint:$never (median $n)"
awk -v e="$e" -v n="$n" 'BEGIN { printf "ratio every step / none: %.2f\n", e / n }'
