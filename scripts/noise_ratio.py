#!/usr/bin/env python3
"""Monte Carlo noise against camera shot noise, from two renders of the same stack.
# Copied from the workplace tools (../shared/tools/noise_ratio.py) so that the project measures itself.

Usage: noise_ratio.py A.expected.ome.tif B.expected.ome.tif [--top 0.10] [--read-noise 1.4]

A and B are float stacks of expected photoelectrons of the same scene, planes and channels,
rendered with two different seeds. Per pixel, the Monte Carlo variance of one render is estimated
as (a - b)^2 / 2 and compared with the shot-noise variance of the expected signal, m + read^2
(m = (a + b) / 2 in electrons). Over the brightest fraction `--top` of pixels (default 10 %), it
prints the median and mean of that ratio, the relative RMS Monte Carlo error, and the ratio of the
two image sums. A ratio of 0.25 means Monte Carlo adds a quarter of the camera's own noise variance.
Needs numpy and tifffile (Debian: python3-numpy python3-tifffile; call /usr/bin/python3)."""
import argparse, json, sys
import numpy as np
import tifffile

def main():
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("a"); p.add_argument("b")
    p.add_argument("--top", type=float, default=0.10)
    p.add_argument("--read-noise", type=float, default=0.0, help="read noise in electrons (adds read^2 to the shot variance)")
    args = p.parse_args()
    a = tifffile.imread(args.a).astype(np.float64)
    b = tifffile.imread(args.b).astype(np.float64)
    if a.shape != b.shape:
        sys.exit(f"noise_ratio: shapes differ: {a.shape} vs {b.shape}")
    m = 0.5 * (a + b)
    d2 = 0.5 * (a - b) ** 2
    cut = np.quantile(m, 1 - args.top)
    sel = m >= cut
    if not sel.any() or m[sel].mean() <= 0:
        sys.exit("noise_ratio: no signal")
    ratio = d2[sel] / (m[sel] + args.read_noise ** 2)
    out = {
        "pixels": int(sel.sum()),
        "mean_signal_e": float(m[sel].mean()),
        "median_mc_over_shot_variance": float(np.median(ratio)),
        "mean_mc_over_shot_variance": float(ratio.mean()),
        "relative_rms_mc_error": float(np.sqrt(d2[sel].mean()) / m[sel].mean()),
        "sum_ratio_a_over_b": float(a.sum() / b.sum()) if b.sum() > 0 else None,
    }
    print(json.dumps(out))

if __name__ == "__main__":
    main()
