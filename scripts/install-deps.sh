#!/usr/bin/env bash
# Installs the Debian 12 packages Fluorosim needs, skipping those already present. Run as root.
set -euo pipefail
packages=(
  g++ cmake ninja-build ccache pkg-config
  libtbb-dev libopenvdb-dev libboost-iostreams-dev libboost-dev
  libembree-dev libopenexr-dev libimath-dev libpng-dev libtiff-dev libassimp-dev
  libcli11-dev nlohmann-json3-dev libgtest-dev libbenchmark-dev libfftw3-dev
  # The concentration fit (optics/fit): Ceres Solver 2.1 and the Eigen it is built on.
  libceres-dev libeigen3-dev
  # The viewer (FLUOROSIM_WITH_VIEWER, docs/viewer.md): VTK 9.1 and X11 headers; its tests render
  # under a virtual X server (xvfb-run needs xauth) through Mesa's llvmpipe (libgl1-mesa-dri).
  libvtk9-dev libx11-dev xvfb xauth libgl1-mesa-dri
  libopenmpi-dev openmpi-bin
  pybind11-dev python3-dev python3-numpy python3-pytest python3-tifffile
)
if [[ "${1:-}" == "--docs" ]]; then packages+=(python3 python3-matplotlib python3-numpy); fi
# The libFuzzer harnesses (scripts/fuzz.sh) need clang and its runtime; the normal build does not.
if [[ "${1:-}" == "--fuzz" ]]; then packages+=(clang libclang-rt-14-dev); fi
missing=()
for p in "${packages[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
if ((${#missing[@]})); then
  echo "install-deps: installing ${missing[*]}" >&2
  if [[ $(id -u) -ne 0 ]]; then echo "install-deps: run as root to install packages" >&2; exit 1; fi
  export DEBIAN_FRONTEND=noninteractive
  apt-get update -qq
  apt-get install -y -qq --no-install-recommends "${missing[@]}" >/dev/null
else
  echo "install-deps: all packages present" >&2
fi
