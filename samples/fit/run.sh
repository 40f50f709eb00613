#!/usr/bin/env bash
# The fit sample: three neurons (C010398B-P2 with AF488 at 4 uM, C231296A-P3 with AF594 at 12 uM,
# mp_ma_40984_gc2 with AF488 at 7 uM) acquired as a noisy two-channel stack (truth.json), then fitted
# back with the same neurons at 10 uM as the template (template.json): out/fit/fit.json and, with
# matplotlib (scripts/install-deps.sh --docs), the figure docs/images/fit_sample.png.
# Usage: bash samples/fit/run.sh [path/to/fluorosim]
set -euo pipefail
here=$(cd "$(dirname "$0")" && pwd)
root=$(cd "$here/../.." && pwd)
fluorosim=${1:-$root/build/apps/fluorosim}
out=$root/out/fit
mkdir -p "$out"
bash "$here/make_volumes.sh" "$fluorosim"
"$fluorosim" acquire "$here/truth.json" -o "$out/truth.ome.tif" --seed 1 > "$out/acquire.json"
"$fluorosim" fit "$here/template.json" --stack "$out/truth.ome.tif" --seed 2 -o "$out/fit" > "$out/fit.json"
if /usr/bin/python3 -c "import matplotlib" 2>/dev/null; then
  /usr/bin/python3 "$root/scripts/make-fit-plots.py" "$out" "$root/docs/images/fit_sample.png"
else
  echo "fit sample: matplotlib is not installed (bash scripts/install-deps.sh --docs): no figure" >&2
fi
/usr/bin/python3 - "$out/fit/fit.json" <<'PY'
import json, sys
truth = {1: 4.0, 2: 12.0, 3: 7.0}
for p in json.load(open(sys.argv[1]))["parameters"]:
    t = truth[p["label"]]
    print(f"{p['name']}: {p['concentration_uM']:.3f} +- {p['concentration_standard_error_uM']:.3f} uM (truth {t} uM, {100 * (p['concentration_uM'] / t - 1):+.1f} %)")
PY
