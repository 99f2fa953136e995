#!/usr/bin/env bash
# Installs lmeform's build and run dependencies from Debian 12 packages.
# Idempotent: packages already present are skipped, and nothing is fetched when all are there.
set -euo pipefail

packages=(
  cmake g++ make pkg-config
  petsc-dev libeigen3-dev libboost-dev libmetis-dev
  libhdf5-openmpi-dev libopenmpi-dev openmpi-bin
  libnanoflann-dev libqhull-dev
  libgtest-dev libgmock-dev libbenchmark-dev
  libtomlplusplus-dev libcli11-dev nlohmann-json3-dev libfmt-dev
  python3-matplotlib python3-numpy python3-h5py
  # An optimized BLAS/LAPACK behind libblas.so.3 (Debian alternatives): MUMPS factorizes with it.
  # Serial flavour: ranks are the parallelism; threads would oversubscribe the cores.
  libopenblas0-serial
)

missing=()
for p in "${packages[@]}"; do
  if ! dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed"; then
    missing+=("$p")
  fi
done

if [ ${#missing[@]} -eq 0 ]; then
  echo "install-deps: all ${#packages[@]} packages present"
  exit 0
fi

echo "install-deps: installing ${#missing[@]} missing packages: ${missing[*]}"
SUDO=""
if [ "$(id -u)" -ne 0 ]; then SUDO="sudo"; fi
export DEBIAN_FRONTEND=noninteractive
$SUDO apt-get update -qq
# 'no alternatives for petsc' from update-alternatives is harmless (TOOLCHAIN.md).
$SUDO apt-get install -y -qq --no-install-recommends "${missing[@]}"
echo "install-deps: done"
