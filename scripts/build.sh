#!/usr/bin/env bash
# Configures and builds Fluorosim in ./build (Release speed with assertions). Extra arguments are
# ninja targets.
set -euo pipefail
cd "$(dirname "$0")/.."
# Configure once; afterwards ninja re-runs CMake itself when a CMakeLists.txt changes (3-4 s saved per call).
if [ ! -f build/build.ninja ]; then
  cmake -S . -B build -G Ninja -DCMAKE_BUILD_TYPE=RelWithAssert >/dev/null
fi
ninja -C build -j2 "$@"
