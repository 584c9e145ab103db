#!/usr/bin/env bash
# Per-stage cost of one run of a scene, as the cohort workflow runs it
# (docs/cohorts.md, "Resources"): plans SCENE as a one-subject cohort
# (`arthrosim cohort --plan-only`), then runs each planned stage program one
# after the other under /usr/bin/time -v, in OUT, and prints per stage the wall
# time, the CPU time (user + system) and the peak resident set size. These are
# the figures behind workflow/config.yaml's threads, mem_mb and runtime.
#   scripts/cohort_measure.sh data/scenes/demo.yaml out/measure_demo
#   scripts/cohort_measure.sh data/cohorts/tiny_knee.yaml out/measure_tiny
set -euo pipefail
cd "$(dirname "$0")/.."
scene=${1:?usage: scripts/cohort_measure.sh SCENE OUT}
out=${2:?usage: scripts/cohort_measure.sh SCENE OUT}
mkdir -p "$out"
out=$(cd "$out" && pwd)
printf 'description: one run of %s (scripts/cohort_measure.sh)\nscene: %s\nsubjects:\n  one: {}\n' \
  "$scene" "$(pwd)/$scene" > "$out/cohort.yaml"
build/bin/arthrosim cohort "$out/cohort.yaml" --out "$out" --plan-only > /dev/null
/usr/bin/python3 - "$out" <<'PY'
import json, os, re, subprocess, sys
out = sys.argv[1]
plan = json.load(open(os.path.join(out, "plan.json")))
print(f"{'stage run':24} {'wall [s]':>9} {'CPU [s]':>9} {'peak RSS [MB]':>14}   (load average before)")
for job in plan["jobs"]:
    os.makedirs(os.path.join(out, "runs", job["subject"], job["setting"]), exist_ok=True)
    load = open("/proc/loadavg").read().split()[0]
    cmd = ["/usr/bin/time", "-v", os.path.join(plan["stage_dir"], job["executable"])] + job["arguments"]
    r = subprocess.run(cmd, cwd=out, capture_output=True, text=True)
    t = r.stderr
    if r.returncode != 0:
        sys.exit(f"cohort_measure: {job['step']} failed (exit {r.returncode}):\n{t[-2000:]}")
    def field(name):
        return re.search(re.escape(name) + r": (.*)", t).group(1).strip()
    wall = field("Elapsed (wall clock) time (h:mm:ss or m:ss)").split(":")
    wall_s = sum(float(x) * 60 ** i for i, x in enumerate(reversed(wall)))
    cpu = float(field("User time (seconds)")) + float(field("System time (seconds)"))
    rss = int(field("Maximum resident set size (kbytes)")) / 1024
    print(f"{job['step']:24} {wall_s:9.2f} {cpu:9.2f} {rss:14.0f}   ({load})", flush=True)
PY
