#!/usr/bin/python3
"""docs/python.md's NumPy-in, ground-truth-out example, run as written, and its picture:
docs/images/ground_truth.png. Usage (from the repository, after the build):
  PYTHONPATH=build/python /usr/bin/python3 scripts/make-ground-truth-figure.py [OUT.png]"""
import json
import os
import sys
import tempfile

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

import fluorosim

here = os.path.dirname(os.path.abspath(__file__))
root = os.path.dirname(here)
out = sys.argv[1] if len(sys.argv) > 1 else os.path.join(root, "docs", "images", "ground_truth.png")
work = tempfile.mkdtemp()
os.chdir(root)

# The example of docs/python.md, line for line (fibre.vdb in a temporary folder).
z, y, x = np.mgrid[0:24, 0:64, 0:64]
c = 20.0 * np.exp(-((x - 20 - 0.5 * z) ** 2 + (y - 32) ** 2) / 6.0)
vdb = os.path.join(work, "fibre.vdb")
fluorosim.write_volume(vdb, {"AF488": c}, voxel="0.4 um", origin=["-12.8 um", "-12.8 um", "-4.8 um"])
scene = json.load(open("samples/lightsheet/beads.json"))
scene["shapes"] = scene["shapes"][:1]
scene["media"]["water"].update(dyes=[{"dye": "AF488", "grid": "AF488"}], volume={"file": vdb})
stack = fluorosim.acquire(scene, planes=8, spp=4, base="samples/lightsheet")
truth = fluorosim.ground_truth(scene, planes=8, base="samples/lightsheet")
measured = stack["expected"][0] - 0.5 * 0.01
perfect = truth["ideal"][0]
conc = truth["concentration"]["alexa_fluor_488"]
print("acquired / perfect:", measured.sum() / perfect.sum(), "largest concentration (M):", conc.max())

extent = [0, stack["pixel_size_um"] * measured.shape[2], stack["pixel_size_um"] * measured.shape[1], 0]
fig, axes = plt.subplots(1, 3, figsize=(11, 3.8))
panels = [(conc.max(0) * 1e6, "concentration on the detector grid (uM)"), (perfect.max(0), "perfect microscope (e-)"),
          (measured.max(0), "acquired, expected (e-)")]
for ax, (img, title) in zip(axes, panels):
    im = ax.imshow(img, cmap="magma", extent=extent)
    ax.set_title(title + ", max over z", fontsize=9)
    ax.set_xlabel("x (um)")
    fig.colorbar(im, ax=ax, fraction=0.046)
axes[0].set_ylabel("y (um), rows from the top")
fig.suptitle(f"A NumPy fibre (20 uM, 8 planes of {stack['z_step_um']:g} um): ground truth beside the simulated stack", fontsize=10)
fig.tight_layout()
fig.savefig(out, dpi=110)
print("wrote", out)
