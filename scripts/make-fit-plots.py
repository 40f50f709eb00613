#!/usr/bin/env python3
"""The fit sample's figure (docs/inverse.md): truth against fitted concentration per label with error bars,
and for each channel the observed stack, the model at the fit and the normalised residual (maximum
projections along z). Usage: make-fit-plots.py OUT_DIR FIGURE.png (OUT_DIR from samples/fit/run.sh)."""
import json
import sys
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
import tifffile

out, figure = Path(sys.argv[1]), Path(sys.argv[2])
fit = json.loads((out / "fit" / "fit.json").read_text())
truth = {1: 4.0, 2: 12.0, 3: 7.0}
with tifffile.TiffFile(out / "truth.ome.tif") as f:
    counts = f.asarray().astype(float)
model = tifffile.imread(out / "fit" / "model.ome.tif")
resid = tifffile.imread(out / "fit" / "normalised_residual.ome.tif")
channels = fit["channels"]
counts = counts.reshape(model.shape)
gain, offset = 0.46, 100.0
observed = (counts - offset) * gain

fig = plt.figure(figsize=(12, 3.2 * (1 + len(channels))), dpi=100)
grid = fig.add_gridspec(1 + len(channels), 3)
ax = fig.add_subplot(grid[0, :])
labels = [p["label"] for p in fit["parameters"]]
x = np.arange(len(labels))
ax.bar(x - 0.18, [truth[l] for l in labels], 0.34, color="0.75", label="truth")
ax.errorbar(x + 0.18, [p["concentration_uM"] for p in fit["parameters"]], yerr=[2 * p["concentration_standard_error_uM"] for p in fit["parameters"]],
            fmt="o", color="C3", capsize=6, label="fit ± 2 standard errors")
for i, p in enumerate(fit["parameters"]):
    ax.annotate(f"{100 * (p['concentration_uM'] / truth[p['label']] - 1):+.1f} %", (i + 0.18, p["concentration_uM"]), textcoords="offset points",
                xytext=(10, 4))
ax.set_xticks(x, [p["name"] for p in fit["parameters"]])
ax.set_ylabel("concentration (µM)")
ax.set_title(f"fluorosim fit: {len(labels)} labels, deviance / dof {fit['deviance_per_dof']:.2f}, {fit['iterations']} iterations, "
             f"{fit['forward_image_equivalents']:.0f} forward images, {fit['seconds']:.0f} s")
ax.legend()
for c, name in enumerate(channels):
    top = np.percentile(observed[c].max(axis=0), 99.5)
    for k, (img, title, cmap, lim) in enumerate([(observed[c].max(axis=0), f"{name}: observed (e⁻, max over z)", "gray", (0, top)),
                                                (model[c].max(axis=0), f"{name}: model at the fit", "gray", (0, top)),
                                                (resid[c].max(axis=0), f"{name}: normalised residual (max over z)", "RdBu_r", (-5, 5))]):
        a = fig.add_subplot(grid[1 + c, k])
        im = a.imshow(img, cmap=cmap, vmin=lim[0], vmax=lim[1])
        a.set_title(title, fontsize=9)
        a.axis("off")
        fig.colorbar(im, ax=a, fraction=0.046)
fig.tight_layout()
fig.savefig(figure)
print(f"wrote {figure}")
