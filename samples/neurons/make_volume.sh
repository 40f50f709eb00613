#!/usr/bin/env bash
# Voxelizes the three neurons into neurons.vdb (0.5 um voxels, about 1 s and 3.7 MB), the volume of
# neurons.json. Usage: samples/neurons/make_volume.sh [path/to/fluorosim] [voxel]
# An existing neurons.vdb is kept when neurons.vdb.stamp shows it was made from the same SWC files,
# voxel size and fluorosim binary, and that the file is the one written then (checksums of all).
set -euo pipefail
here=$(cd "$(dirname "$0")" && pwd)
fluorosim=${1:-$here/../../build/apps/fluorosim}
voxel=${2:-0.5um}
swcs=("$here"/C010398B-P2.CNG.swc "$here"/C231296A-P3.CNG.swc "$here"/mp_ma_40984_gc2.CNG.swc)
stamp="voxel $voxel $(cat "${swcs[@]}" "$fluorosim" | sha256sum | cut -d' ' -f1)"
written() { sha256sum < "$here/neurons.vdb" | cut -d' ' -f1; }
if [[ -f "$here/neurons.vdb" && -f "$here/neurons.vdb.stamp" && "$(cat "$here/neurons.vdb.stamp")" == "$stamp $(written)" ]]; then
  echo "neurons.vdb is up to date (same SWC files, voxel size and fluorosim binary)"
  exit 0
fi
rm -f "$here/neurons.vdb.stamp"
"$fluorosim" voxelize "${swcs[@]}" --voxel "$voxel" --dye AF488,AF594,AF647 --concentration 10uM,10uM,10uM -o "$here/neurons.vdb"
echo "$stamp $(written)" > "$here/neurons.vdb.stamp"
