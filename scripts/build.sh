#!/usr/bin/env bash
# Configures and builds Fluorosim in ./build (Release speed with assertions). Extra arguments are
# ninja targets.
set -euo pipefail
cd "$(dirname "$0")/.."
cmake -S . -B build -G Ninja -DCMAKE_BUILD_TYPE=RelWithAssert >/dev/null
ninja -C build -j2 "$@"
