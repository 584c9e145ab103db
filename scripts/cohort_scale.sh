#!/usr/bin/env bash
# Scale of a cohort by dry run (docs/cohorts.md, "Scale"): writes a cohort of
# SUBJECTS subjects x SETTINGS settings on a scene (default the demo: prepare,
# comak, three surface scenarios, post), plans it with `arthrosim cohort
# --plan-only` and has Snakemake plan every job without running one
# (`snakemake -n --quiet rules`). Prints the planning times, the job count and
# the size of the plan. The subjects are the bundled knee over different trial
# windows (trial.end_s), the settings the osmotic pressure: planning cost does
# not depend on which knee a subject is.
#   scripts/cohort_scale.sh                 # 1,000 x 10 in build/cohort_scale
#   scripts/cohort_scale.sh 100 10 /tmp/scale data/cohorts/tiny_knee.yaml
set -euo pipefail
cd "$(dirname "$0")/.."
subjects=${1:-1000}
settings=${2:-10}
out=${3:-build/cohort_scale}
scene=${4:-data/scenes/demo.yaml}
mkdir -p "$out"
out=$(cd "$out" && pwd)
cohort="$out/cohort.yaml"
{
  echo "description: scale test -- $subjects subjects x $settings settings (dry run only)"
  echo "scene: $(pwd)/$scene"
  echo "settings:"
  printf "  surface.scenarios.osmotic.osmotic_pressure_mpa: ["
  for ((k = 1; k <= settings; k++)); do printf "%s%s" "$([ $k -gt 1 ] && echo ', ')" "0.$(printf %02d $k)"; done
  echo "]"
  echo "subjects:"
  for ((i = 0; i < subjects; i++)); do
    echo "  s$(printf %05d $i):"
    echo "    model: $(pwd)/data/models/knee_parametric/coarse"
    echo "    trial: $(pwd)/data/trials/synthetic_gait"
    echo "    set: {trial.end_s: 0.$(printf %04d $((2000 + i)))}"
  done
} > "$cohort"
t0=$(date +%s.%N)
build/bin/arthrosim cohort "$cohort" --out "$out/run" --plan-only > "$out/plan.log"
t1=$(date +%s.%N)
snakemake --snakefile workflow/Snakefile --configfile workflow/config.yaml --directory "$out/run" \
  --config plan="$out/run/plan.json" -n --quiet rules > "$out/dry_run.log" 2>&1
t2=$(date +%s.%N)
jobs=$(awk '$1 == "total" {print $2}' "$out/dry_run.log")
echo "cohort_scale: $subjects subjects x $settings settings on $scene"
echo "  arthrosim cohort --plan-only (scenes + plan.json): $(echo "$t1 - $t0" | bc) s; $(head -1 "$out/plan.log" | sed 's/^arthrosim cohort: //')"
echo "  plan.json: $(du -m "$out/run/plan.json" | cut -f1) MB"
echo "  snakemake -n: $(echo "$t2 - $t1" | bc) s for ${jobs:-?} jobs (job stats: $out/dry_run.log)"
