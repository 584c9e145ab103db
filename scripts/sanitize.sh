#!/usr/bin/env bash
# Sanitizer suite and bounded fuzzing (docs/testing.md). Run by scripts/test.sh
# after the CTest suite; on its own:
#
#   scripts/sanitize.sh                      # build, sanitizer suite, fuzz 10 s per target
#   scripts/sanitize.sh --fuzz-seconds 300   # fuzz longer
#   scripts/sanitize.sh --no-fuzz            # sanitizer suite only
#   scripts/sanitize.sh --no-suite --only mesh_ply --fuzz-seconds 600
#   scripts/sanitize.sh --no-suite --fuzz-seed 0 --fuzz-seconds 300   # new random inputs
#
# 1. Configures ./build-sanitize once (clang 14, -DARTHROSIM_SANITIZE=address,undefined,
#    -DARTHROSIM_FUZZ=ON, build type Sanitize = -O1, assertions on) and builds
#    only what is run: the libraries, the fast test executables (target
#    sanitize_suite, listed in tests/fuzz/CMakeLists.txt) and the fuzz targets.
# 2. Runs the fast suite under ASan+UBSan+LSan (ctest by label, plus the
#    replay of every committed fuzz corpus).
# 3. Fuzzes every target for a bounded time from its committed corpus
#    (tests/fuzz/corpus/<target>; new inputs go to build-sanitize/fuzz-corpus,
#    never into the repository). The mutation seed is fixed (1; --fuzz-seed N,
#    0 = a random seed each run): from the same corpus a run tries the same
#    inputs in the same order, as far as its time allows, so CI on a clean
#    clone repeats itself and a failure it finds is found again. A crash,
#    sanitizer report, leak, out-of-memory (> 2 GB RSS), an input running
#    longer than 10 s, or an exception other than common::InputError fails the
#    run; the input is kept in build-sanitize/fuzz-artifacts/ and its
#    reproduction command is printed.
# Extra cmake arguments for the first configure: ARTHROSIM_SANITIZE_CMAKE_ARGS.
set -euo pipefail
cd "$(dirname "$0")/.."
root=$(pwd)
build=${ARTHROSIM_SANITIZE_BUILD:-build-sanitize}
fuzz_seconds=10
fuzz_seed=1
run_suite=1
run_fuzz=1
only=""
jobs=$(nproc)
while [ $# -gt 0 ]; do
  case "$1" in
    --fuzz-seconds) fuzz_seconds=$2; shift 2 ;;
    --fuzz-seed) fuzz_seed=$2; shift 2 ;;
    --no-fuzz) run_fuzz=0; shift ;;
    --no-suite) run_suite=0; shift ;;
    --only) only=$2; shift 2 ;;
    --jobs) jobs=$2; shift 2 ;;
    -h|--help) sed -n '2,/^set -euo/p' "$0" | sed '$d' | sed 's/^# \{0,1\}//'; exit 0 ;;
    *) echo "sanitize.sh: unknown argument '$1' (see --help)" >&2; exit 2 ;;
  esac
done

CC_BIN=${CC_SANITIZE:-clang-14}
CXX_BIN=${CXX_SANITIZE:-clang++-14}
for tool in "$CC_BIN" "$CXX_BIN" llvm-symbolizer-14; do
  command -v "$tool" >/dev/null || { echo "sanitize.sh: $tool not found (bash scripts/install-deps.sh)" >&2; exit 1; }
done

t0=$(date +%s)
if [ ! -f "$build/CMakeCache.txt" ]; then
  gen=()
  command -v ninja >/dev/null && gen=(-G Ninja)
  # shellcheck disable=SC2086
  cmake -S . -B "$build" "${gen[@]}" -DCMAKE_BUILD_TYPE=Sanitize \
    -DCMAKE_C_COMPILER="$CC_BIN" -DCMAKE_CXX_COMPILER="$CXX_BIN" \
    -DCMAKE_EXE_LINKER_FLAGS=-fuse-ld=lld \
    -DARTHROSIM_SANITIZE=address,undefined -DARTHROSIM_FUZZ=ON -DARTHROSIM_BUILD_BENCHMARKS=OFF \
    ${ARTHROSIM_SANITIZE_CMAKE_ARGS:-}
fi
cmake --build "$build" -j "$jobs" --target sanitize_suite fuzz_targets
t_built=$(date +%s)
echo "sanitize.sh: build $((t_built - t0)) s"

export ASAN_SYMBOLIZER_PATH=${ASAN_SYMBOLIZER_PATH:-$(command -v llvm-symbolizer-14)}
export ASAN_OPTIONS=${ASAN_OPTIONS:-detect_leaks=1:strict_string_checks=1:detect_stack_use_after_return=1:check_initialization_order=1}
export UBSAN_OPTIONS=${UBSAN_OPTIONS:-print_stacktrace=1:halt_on_error=1}
# Leaks inside third-party libraries only (each with its reason and reproducer).
export LSAN_OPTIONS=${LSAN_OPTIONS:-suppressions=$root/tests/fuzz/lsan.supp:print_suppressions=0}

if [ "$run_suite" = 1 ]; then
  labels=$(sed -n 's/^ARTHROSIM_SANITIZE_LABELS:INTERNAL=//p' "$build/CMakeCache.txt")
  exclude=$(sed -n 's/^ARTHROSIM_SANITIZE_EXCLUDE:INTERNAL=//p' "$build/CMakeCache.txt")
  ctest --test-dir "$build" -L "$labels" -E "$exclude" --output-on-failure -j "$jobs" --timeout 600
  t_suite=$(date +%s)
  echo "sanitize.sh: sanitizer suite $((t_suite - t_built)) s"
fi

if [ "$run_fuzz" = 1 ]; then
  t_fuzz0=$(date +%s)
  work="$build/fuzz-corpus"
  artifacts="$build/fuzz-artifacts"
  logs="$build/fuzz-logs"
  rm -rf "$artifacts" "$logs"
  mkdir -p "$work" "$artifacts" "$logs"
  targets=()
  for exe in "$build"/fuzz/fuzz_*; do
    name=${exe##*/fuzz_}
    [ -n "$only" ] && [ "$name" != "$only" ] && continue
    # *_raw targets fuzz third-party parsers with known defects: by hand only.
    [ -z "$only" ] && [ "${name%_raw}" != "$name" ] && continue
    targets+=("$name")
  done
  [ ${#targets[@]} -gt 0 ] || { echo "sanitize.sh: no fuzz target${only:+ named $only}" >&2; exit 1; }
  fuzz_one() {
    local name=$1
    mkdir -p "$work/$name"
    local dict=()
    [ -f "$root/tests/fuzz/dict/$name.dict" ] && dict=(-dict="$root/tests/fuzz/dict/$name.dict")
    # -close_fd_mask=3: the readers' own diagnostics (urdfdom prints to the
    # console) are muted; libFuzzer and sanitizer reports still go to the log.
    if "$build/fuzz/fuzz_$name" -max_total_time="$fuzz_seconds" -seed="$fuzz_seed" -timeout=10 -rss_limit_mb=2048 \
        -close_fd_mask=3 -print_final_stats=1 -artifact_prefix="$artifacts/$name-" "${dict[@]}" \
        "$work/$name" "$root/tests/fuzz/corpus/$name" > "$logs/$name.log" 2>&1; then
      echo ok > "$logs/$name.status"
    else
      echo failed > "$logs/$name.status"
    fi
  }
  # Two targets at a time per core pair: each fuzzer is single-threaded.
  running=0
  for name in "${targets[@]}"; do
    fuzz_one "$name" &
    running=$((running + 1))
    if [ "$running" -ge "$jobs" ]; then
      wait -n
      running=$((running - 1))
    fi
  done
  wait
  failed=0
  printf '%-10s %10s %8s %8s %6s  %s\n' target executions exec/s seconds corpus result
  for name in "${targets[@]}"; do
    log="$logs/$name.log"
    runs=$(sed -n 's/^stat::number_of_executed_units: *//p' "$log" | tail -1)
    secs=$(sed -n 's/^Done [0-9]* runs in \([0-9]*\) second.*/\1/p' "$log" | tail -1)
    rate=$(sed -n 's/^stat::average_exec_per_sec: *//p' "$log" | tail -1)
    n_corpus=$(find "$work/$name" -type f | wc -l)
    status=$(cat "$logs/$name.status")
    printf '%-10s %10s %8s %8s %6s  %s\n' "$name" "${runs:-?}" "${rate:-?}" "${secs:-?}" "$n_corpus" "$status"
    if [ "$status" != ok ]; then
      failed=1
      echo "---- fuzz_$name failed; log $log:" >&2
      grep -v -E '^#[0-9]+|^INFO:' "$log" | tail -60 >&2
      for a in "$artifacts/$name-"*; do
        [ -e "$a" ] && echo "reproduce: $build/fuzz/fuzz_$name $a" >&2
      done
    fi
  done
  echo "sanitize.sh: fuzzing $(( $(date +%s) - t_fuzz0 )) s (${#targets[@]} targets, ${fuzz_seconds} s each, $jobs at a time, seed $fuzz_seed)"
  [ "$failed" = 0 ] || exit 1
fi
echo "sanitize.sh: total $(( $(date +%s) - t0 )) s"
