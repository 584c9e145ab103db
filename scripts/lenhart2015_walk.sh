#!/bin/sh
# The real subject's whole walk through every stage (issue 28's checks;
# figures in docs/surface_output.md, "The real subject"): runs
# data/scenes/lenhart2015_gait.yaml (prepare at the seed's femoral resolution,
# COMAK over 1.21-2.32 s, the seed's three surface scenarios, post) and prints
#   - the run's wall and CPU time and peak memory (/usr/bin/time),
#   - stage 1 against OpenSim-JAM's published COMAK (scripts/compare_opensim_jam.py),
#   - per walking scenario: the axial-force RMS difference to stage 1, the
#     seed's accuracy rule per step, femoral deflection and principal strains
#     at the first peak beside the seed's (scripts/gait_figures.py).
# About 6 min on the 2-core machine (the two walks side by side with
# --jobs 2; one at a time: --jobs 1). Long: run it with nice.
#
#   nice scripts/lenhart2015_walk.sh OUTDIR [BIN_DIR] [--jobs N] [--set KEY=VALUE ...]
#
# A short window to try settings: ... --set trial.end_s=1.3
#   --set surface.scenarios.gait.end_time_s=0.09 --set surface.scenarios.gait_osmotic.end_time_s=0.09
set -eu
out=$1
shift
bin=build/bin
if [ $# -gt 0 ] && [ "${1#--}" = "$1" ]; then bin=$1; shift; fi
here=$(dirname "$0")
mkdir -p "$out"
/usr/bin/time -f "whole pipeline: %e s wall, %U s user, %S s system, peak RSS %M KB" \
  "$bin/arthrosim" run "$here/../data/scenes/lenhart2015_gait.yaml" --out "$out" "$@" > "$out/run.log" 2> "$out/time.log" \
  || { tail -20 "$out/run.log" "$out/time.log"; exit 1; }
grep -E "^arthrosim: finished" "$out/run.log"
tail -1 "$out/time.log"
echo "== stage 1 against OpenSim-JAM's COMAK"
/usr/bin/python3 "$here/compare_opensim_jam.py" "$out/kinematics.h5" | grep -E "^knee_|tibiofemoral force|solver"
for sc in gait gait_osmotic; do
  echo "== stage 2 $sc against stage 1"
  /usr/bin/python3 "$here/gait_figures.py" "$out/kinematics.h5" "$out/surface_$sc.h5"
done
echo "== post: $out/report.html, $out/summary.json"
