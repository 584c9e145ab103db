#!/usr/bin/env bash
# Installs every Debian 12 package arthrosim needs to build, test and run.
# Idempotent: packages already present are left alone, and apt-get update runs
# only when something is missing. Must run as root (or with sudo available).
set -euo pipefail
PACKAGES=(
  build-essential cmake ninja-build pkg-config git
  coinor-libipopt-dev libeigen3-dev liburdfdom-dev libtinyxml2-dev libcgal-dev
  libsuitesparse-dev libopenblas-dev libhdf5-dev libyaml-cpp-dev libcli11-dev
  libgtest-dev libgmock-dev libbenchmark-dev
  hdf5-tools python3 python3-numpy python3-h5py python3-matplotlib
  # Sanitizer suite and fuzzing (scripts/sanitize.sh): clang with libFuzzer
  # and the sanitizer runtimes, its OpenMP, the lld linker, llvm-symbolizer.
  clang-14 libclang-rt-14-dev libomp-14-dev lld-14 llvm-14
  # The post report drawn in a real browser (tests/pipelines/report_html_test.cc,
  # docs/post.md "Report"): headless Chromium renders it and checks every figure.
  chromium
  # Cohort studies (docs/cohorts.md): `arthrosim cohort` runs workflow/Snakefile
  # with Debian's Snakemake (7.21: local runs, --slurm, profiles).
  snakemake
)
missing=()
for p in "${PACKAGES[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
if [ ${#missing[@]} -eq 0 ]; then
  echo "install-deps: all ${#PACKAGES[@]} packages present"
  exit 0
fi
SUDO=""
[ "$(id -u)" -eq 0 ] || SUDO="sudo"
echo "install-deps: installing ${missing[*]}"
$SUDO apt-get update -qq
DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq --no-install-recommends "${missing[@]}"
