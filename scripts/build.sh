#!/usr/bin/env bash
# Configures and builds arthrosim (Release) into ./build. Usage: scripts/build.sh [extra cmake args]
# ARTHROSIM_WERROR=ON (set by .ci/run) makes warnings of the project's code errors.
set -euo pipefail
cd "$(dirname "$0")/.."
gen=()
command -v ninja >/dev/null && gen=(-G Ninja)
if [ ! -f build/CMakeCache.txt ]; then
  cmake -S . -B build "${gen[@]}" -DCMAKE_BUILD_TYPE=Release -DARTHROSIM_WERROR="${ARTHROSIM_WERROR:-OFF}" "$@"
fi
cmake --build build -j "$(nproc)"
