#!/usr/bin/env bash
# Voxelizes the three sample neurons twice at 0.5 um: truth.vdb at the concentrations the sample's stack
# is acquired with (C010398B-P2 AF488 4 uM, C231296A-P3 AF594 12 uM, mp_ma_40984_gc2 AF488 7 uM) and
# template.vdb at 10 uM each, the fit's template. Labels 1, 2, 3 follow the file order.
# Usage: samples/fit/make_volumes.sh [path/to/fluorosim]
set -euo pipefail
here=$(cd "$(dirname "$0")" && pwd)
fluorosim=${1:-$here/../../build/apps/fluorosim}
neurons="$here/../neurons"
swc=("$neurons"/C010398B-P2.CNG.swc "$neurons"/C231296A-P3.CNG.swc "$neurons"/mp_ma_40984_gc2.CNG.swc)
"$fluorosim" voxelize "${swc[@]}" --voxel 0.5um --dye AF488,AF594,AF488 --concentration 4uM,12uM,7uM -o "$here/truth.vdb" >/dev/null
"$fluorosim" voxelize "${swc[@]}" --voxel 0.5um --dye AF488,AF594,AF488 --concentration 10uM -o "$here/template.vdb" >/dev/null
