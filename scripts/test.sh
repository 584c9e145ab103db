#!/usr/bin/env bash
# Runs the whole CTest suite of ./build (after scripts/build.sh).
set -euo pipefail
cd "$(dirname "$0")/../build"
ctest --output-on-failure -j "$(nproc)" --timeout 900 "$@"
