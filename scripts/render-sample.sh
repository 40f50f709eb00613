#!/usr/bin/env bash
# README command 1: install what is missing, build, render the default sample.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/install-deps.sh
bash scripts/build.sh fluorosim
mkdir -p out
./build/apps/fluorosim render samples/cornell/scene.json -o out/cornell.exr "$@"
echo "Image: $(pwd)/out/cornell.exr (spectral OpenEXR) and $(pwd)/out/cornell.png (preview)"
