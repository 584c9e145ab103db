#!/usr/bin/env bash
# Runs the whole CTest suite of ./build (after scripts/build.sh), then the
# sanitizer suite and bounded fuzzing (scripts/sanitize.sh, docs/testing.md).
# Arguments go to ctest, and then only ctest runs (scripts/test.sh -L stability);
# ARTHROSIM_SANITIZE_CHECKS=0 skips the sanitizer stage.
set -euo pipefail
cd "$(dirname "$0")/.."
(cd build && ctest --output-on-failure -j "$(nproc)" --timeout 900 "$@")
if [ $# -eq 0 ] && [ "${ARTHROSIM_SANITIZE_CHECKS:-1}" != 0 ]; then
  scripts/sanitize.sh
fi
