#!/usr/bin/env bash
# Voxelizes the three neurons into neurons.vdb (0.5 um voxels, about 1 s and 3.7 MB), the volume of
# neurons.json. Usage: samples/neurons/make_volume.sh [path/to/fluorosim] [voxel]
set -euo pipefail
here=$(cd "$(dirname "$0")" && pwd)
fluorosim=${1:-$here/../../build/apps/fluorosim}
voxel=${2:-0.5um}
"$fluorosim" voxelize "$here"/C010398B-P2.CNG.swc "$here"/C231296A-P3.CNG.swc "$here"/mp_ma_40984_gc2.CNG.swc \
  --voxel "$voxel" --dye AF488,AF594,AF647 --concentration 10uM,10uM,10uM -o "$here/neurons.vdb"
