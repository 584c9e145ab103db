#!/bin/sh
# Accuracy study of the biphasic stage on its two discretisation settings
# (docs/studies.md, "Biphasic stage"): element layers through the thickness
# (1, 2, 3, 4 at dt = 10 ms; reference 4) and the time step (20, 10, 5 ms at
# 2 element layers; reference 5 ms). Prints, per setting, the wall time and
# the relative difference of every key output against the reference
# (arthrosim-biphasic --compare-to), and the setting the 5 % rule recommends
# (the coarsest whose worst difference is <= 0.05).
#
#   scripts/biphasic_study.sh PREPARED.h5 KINEMATICS.h5 OUTDIR [BIN_DIR]
#
# PREPARED/KINEMATICS: e.g. out/demo/prepared.h5 and out/demo/kinematics.h5
# of `arthrosim run data/scenes/demo.yaml --out out/demo`.
set -eu
prepared=$1
kinematics=$2
out=$3
bin=${4:-build/bin}
mkdir -p "$out"
run() {  # name, extra options
  name=$1
  shift
  start=$(date +%s.%N)
  "$bin/arthrosim-biphasic" --prepared "$prepared" --kinematics "$kinematics" --out "$out/$name.h5" --quiet "$@" \
    > "$out/$name.log"
  end=$(date +%s.%N)
  echo "$name $(echo "$end - $start" | bc)" >> "$out/wall.txt"
}
study() {  # title, reference, settings...
  title=$1
  reference=$2
  shift 2
  echo "== $title (reference $reference)"
  recommended=""
  for name in "$@"; do
    worst=$("$bin/arthrosim-biphasic" --out "$out/$name.h5" --compare-to "$out/$reference.h5" --compare-only |
      tee "$out/$name.compare.txt" | awk '/worst/ {print $NF}')
    wall=$(awk -v n="$name" '$1 == n {print $2}' "$out/wall.txt" | tail -1)
    echo "$name: wall $wall s, worst relative difference $worst"
    awk '!/worst/ {printf "    %s %s %s\n", $2, $3, $4}' "$out/$name.compare.txt"
    if [ -z "$recommended" ] && awk -v w="$worst" 'BEGIN {exit !(w <= 0.05)}'; then recommended=$name; fi
  done
  echo "5 % rule: $recommended"
}
: > "$out/wall.txt"
for n in 4 3 2 1; do run "layers$n" --element-layers "$n"; done
for dt in 5 20; do run "dt$dt" --time-step-ms "$dt"; done
cp "$out/layers2.h5" "$out/dt10.h5"
awk '$1 == "layers2" {print "dt10", $2}' "$out/wall.txt" >> "$out/wall.txt"
study "element layers through the thickness, dt = 10 ms" layers4 layers1 layers2 layers3 layers4
study "time step, 2 element layers" dt5 dt20 dt10 dt5
