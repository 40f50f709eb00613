#!/usr/bin/env bash
# Monte Carlo noise against the camera's shot noise, and time, for the light-sheet neuron sample:
# one 256 x 256 plane in both channels, rendered with seeds 1 and 2 per configuration, compared with
# scripts/noise_ratio.py (a copy of the workplace tool; median MC variance / shot-noise variance over
# the brightest 10 % of pixels). Usage: scripts/noise-vs-time.sh [build/apps/fluorosim] > table.md
# Needs samples/neurons/neurons.vdb (samples/neurons/make_volume.sh) and python3-numpy/-tifffile.
set -euo pipefail
here=$(cd "$(dirname "$0")/.." && pwd)
fluorosim=${1:-$here/build/apps/fluorosim}
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
scene=$here/samples/lightsheet/neurons.json
# The same scene in clear tissue (no scattering; max_depth 200 for the refracting block).
/usr/bin/python3 - "$scene" "$work/clear.json" <<'PY'
import json, os, sys
j = json.load(open(sys.argv[1]))
j["media"]["tissue"]["sigma_s"] = "0 /mm"
j.setdefault("render", {})["max_depth"] = 200
base = os.path.dirname(os.path.abspath(sys.argv[1]))
j["media"]["tissue"]["volume"]["file"] = os.path.join(base, j["media"]["tissue"]["volume"]["file"])
for s in j["shapes"]:
    if "file" in s: s["file"] = os.path.join(base, s["file"])
json.dump(j, open(sys.argv[2], "w"))
PY
echo "| tissue | estimator | spp (paths / direct) | seconds per plane (2 channels) | median MC / shot variance | relative RMS MC error | sum ratio |"
echo "| --- | --- | --- | --- | --- | --- | --- |"
run() {  # tissue scene estimator spp direct
    local tag=$1 file=$2 est=$3 spp=$4 direct=$5 seconds=0
    for seed in 1 2; do
        "$fluorosim" acquire "$file" -o "$work/$seed.ome.tif" --planes 1 --seed "$seed" --estimator "$est" --spp "$spp" \
            --direct-spp "$direct" > "$work/$seed.json" 2> /dev/null
        seconds=$(/usr/bin/python3 -c "import json; print(json.load(open('$work/$seed.json'))['seconds'])")
    done
    /usr/bin/python3 "$here/scripts/noise_ratio.py" "$work/1.expected.ome.tif" "$work/2.expected.ome.tif" --read-noise 1.4 > "$work/r.json"
    /usr/bin/python3 - "$work/r.json" "$tag" "$est" "$spp" "$direct" "$seconds" <<'PY'
import json, sys
r = json.load(open(sys.argv[1])); tag, est, spp, direct, sec = sys.argv[2:]
d = direct if est == "split" else "-"
print(f"| {tag} | {est} | {spp} / {d} | {float(sec):.1f} | {r['median_mc_over_shot_variance']:.3g} | {r['relative_rms_mc_error']:.3g} | {r['sum_ratio_a_over_b']:.3f} |")
PY
}
for tissue in "sigma_s 1/mm:$scene" "clear:$work/clear.json"; do
    tag=${tissue%%:*} file=${tissue#*:}
    run "$tag" "$file" path 16 64
    run "$tag" "$file" split 4 64
    run "$tag" "$file" split 16 256
done
