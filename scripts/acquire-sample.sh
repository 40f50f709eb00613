#!/usr/bin/env bash
# README command 1: install what is missing, build, and run the main job: voxelize the sample neurons
# and acquire a two-channel light-sheet stack of them (samples/lightsheet/neurons.json) with its preview.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/install-deps.sh
bash scripts/build.sh fluorosim
mkdir -p out
bash samples/neurons/make_volume.sh "$(pwd)/build/apps/fluorosim"
./build/apps/fluorosim acquire samples/lightsheet/neurons.json -o out/neurons.ome.tif "$@" > out/neurons.summary.json
echo "Stack: $(pwd)/out/neurons.ome.tif (OME-TIFF, 2 channels), expected photoelectrons and their standard errors beside it"
echo "Picture: $(pwd)/out/neurons.preview.png; summary: $(pwd)/out/neurons.summary.json"
