#!/usr/bin/python3
"""Specks in an acquired stack, as the camera and the preview see them.

For each STACK (the NAME.ome.tif given to `fluorosim acquire -o`), from NAME.expected.ome.tif and
NAME.stderr.ome.tif: the pixels whose Monte Carlo variance (stderr²) exceeds the camera's (expected
electrons + read noise²) 1, 10 and 100 times, the pixels over 200 e- whose standard error is over half
their value, and the largest standard error. With --reference REF (a run of the same scene with many more
photons and another seed), also the preview's view: each channel's maximum projection over the planes, in
the preview's scale (its 99.5th percentile, as `fluorosim acquire` draws NAME.preview.png), less the
reference's; the largest excess and deficit as a share of full scale, and the pixels off by over 5 %
(13 of 255 grey levels).

Usage: /usr/bin/python3 scripts/stack-specks.py [--read-noise 1.4] [--reference REF.ome.tif] STACK.ome.tif ...
Needs Debian's python3-tifffile and python3-numpy.
"""
import argparse

import numpy as np
import tifffile


def part(stack, kind):
    return tifffile.imread(stack.replace(".ome.tif", f".{kind}.ome.tif")).astype(float)


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("stacks", nargs="+")
    ap.add_argument("--read-noise", type=float, default=1.4)
    ap.add_argument("--reference")
    a = ap.parse_args()
    ref = part(a.reference, "expected") if a.reference else None
    for stack in a.stacks:
        e, s = part(stack, "expected"), part(stack, "stderr")
        ratio = s**2 / (np.maximum(e, 0) + a.read_noise**2)
        line = [stack, f"MC/camera variance >1: {(ratio > 1).sum()}, >10: {(ratio > 10).sum()}, >100: {(ratio > 100).sum()}",
                f">200 e- with stderr over half: {((e > 200) & (s > 0.5 * e)).sum()}", f"largest stderr {s.max():.0f} e-"]
        if ref is not None:
            channels = e.reshape((-1,) + e.shape[-3:])  # (channel, plane, y, x)
            refs = ref.reshape(channels.shape)
            for c in range(channels.shape[0]):
                mine, theirs = channels[c].max(0), refs[c].max(0)
                off = (mine - theirs) / np.percentile(mine, 99.5)
                line.append(f"preview channel {c}: +{100 * off.max():.1f} % / -{100 * -off.min():.1f} % of full scale, "
                            f"{(abs(off) > 0.05).sum()} pixels off by over 5 %")
        print("; ".join(line))


if __name__ == "__main__":
    main()
