#!/usr/bin/python3
"""Sheet thickness and contrast against depth in scattering tissue (docs/validation.md, section 10).

Runs `fluorosim validate lightsheet --sigma-s S` for three scattering coefficients (g = 0.9, waist
5 um at 488 nm, focus in the middle of a 1 mm block) and plots the FWHM of the fluence across the
sheet (against the unscattered Gaussian beam's) and the contrast (peak over the value 3 w(x) off the
sheet) against the depth from the entry face. Writes docs/images/lightsheet_depth.png and
docs/generated/lightsheet-depth.json. Usage: scripts/make-lightsheet-depth-plot.py [path/to/fluorosim]
"""
import json
import os
import subprocess
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
CLI = sys.argv[1] if len(sys.argv) > 1 else os.path.join(ROOT, "build", "apps", "fluorosim")
OUT = os.path.join(ROOT, "docs", "generated")
os.makedirs(OUT, exist_ok=True)

runs = {}
for sigma in ["1/mm", "2/mm", "5/mm"]:
    path = os.path.join(OUT, "lightsheet-depth-%s.json" % sigma.replace("/", "_per_"))
    subprocess.run([CLI, "validate", "lightsheet", "--wavelength", "488", "--waist", "5", "--sigma-s", sigma, "--g", "0.9",
                    "--samples", "8192", "--positions", "10", "-o", path], check=True, stdout=subprocess.DEVNULL)
    with open(path) as f:
        runs[sigma] = json.load(f)
    os.remove(path)
with open(os.path.join(OUT, "lightsheet-depth.json"), "w") as f:
    json.dump(runs, f, indent=1)

fig, (a, b) = plt.subplots(1, 2, figsize=(10, 4))
first = next(iter(runs.values()))
a.plot(first["depths_um"], first["unscattered_fwhm_um"], "k--", label="no scattering (Gaussian beam)")
for sigma, r in runs.items():
    a.plot(r["depths_um"], r["fwhm_um"], "o-", label="σs = %s" % sigma)
    b.semilogy(r["depths_um"], r["contrast_at_3w"], "o-", label="σs = %s" % sigma)
a.set_xlabel("depth along the beam (µm)")
a.set_ylabel("sheet FWHM (µm)")
a.set_title("Sheet thickness (waist 5 µm at 500 µm)")
a.legend(fontsize=8)
b.set_xlabel("depth along the beam (µm)")
b.set_ylabel("fluence at the sheet / at 3 w(x) off it")
b.set_title("Contrast")
b.legend(fontsize=8)
fig.tight_layout()
fig.savefig(os.path.join(ROOT, "docs", "images", "lightsheet_depth.png"), dpi=90)
print("wrote docs/images/lightsheet_depth.png and docs/generated/lightsheet-depth.json")
