#!/usr/bin/python3
"""Monte Carlo error of the fluorescent layer of a paper scene (samples/fluorescence), per integrator.

Renders the scene twice (seeds 1 and 2, or the pair given by --seeds A,B) with each integrator and budget given, through the Python
module, and prints one JSON line per render pair: the relative RMS error of the fluorescent layer
over the pixels of the dyed liquid, estimated from the two seeds (per-pixel variance of one render =
half the squared difference), divided by the mean fluorescent value there, and the seconds per render.

The liquid's pixels: those whose central camera ray meets a liquid-filled sphere's glass (the shapes of
type sphere whose "interior" is a dyed medium, grown to the glass shell around them). Meshes (the vials):
those whose central ray meets the vertical cylinder around the glass mesh that holds a dyed liquid mesh
(the mesh's x-z radius and y range, translated as the scene places it).
With --whole: the whole image's total (elastic + fluorescent) RGB instead, for scenes without dyes.

Usage: PYTHONPATH=build/python scripts/paper-scene-error.py [--whole] [--seeds A,B] SCENE.json path:40 mnee:4 light:32 light:32:0 ...
(light:SPP:R sets render.merge_radius_pixels to R; 0 turns photon merging off)
"""
import json
import math
import sys

import numpy as np

import fluorosim


def liquid_mask(scene):
    cam = scene["camera"]
    mm = lambda v: np.array([float(str(c).split()[0]) for c in v])
    pos, look, up = mm(cam["position"]), mm(cam["look_at"]), np.array(cam["up"], float)
    w, h = cam["resolution"]
    n = (look - pos) / np.linalg.norm(look - pos)
    s = np.cross(n, up)
    s /= np.linalg.norm(s)
    t = np.cross(s, n)
    tan = math.tan(math.radians(cam["fov_y_deg"]) / 2)
    xs = (2 * (np.arange(w) + 0.5) / w - 1) * tan * w / h
    ys = (1 - 2 * (np.arange(h) + 0.5) / h) * tan
    d = n[None, None, :] + s[None, None, :] * xs[None, :, None] + t[None, None, :] * ys[:, None, None]
    d /= np.linalg.norm(d, axis=2, keepdims=True)
    dyed = {k for k, m in scene["media"].items() if m.get("dyes")}
    liquids = [sh for sh in scene["shapes"] if sh["type"] == "sphere" and sh.get("interior") in dyed]
    mask = np.zeros((h, w), bool)
    # Meshes of a dyed liquid: the vertical cylinder around the glass mesh at the same place.
    base = scene.get("_base", ".")
    for sh in scene["shapes"]:
        if sh["type"] != "mesh" or sh.get("interior") not in dyed:
            continue
        glass = [o for o in scene["shapes"] if o["type"] == "mesh" and o.get("translate") == sh.get("translate") and o is not sh]
        obj = (glass or [sh])[0]["file"]
        v = np.array([[float(x) for x in line.split()[1:4]] for line in open(f"{base}/{obj}") if line.startswith("v ")])
        t = mm(sh.get("translate", ["0 mm"] * 3))
        radius, y0, y1 = np.sqrt(v[:, 0] ** 2 + v[:, 2] ** 2).max(), v[:, 1].min() + t[1], v[:, 1].max() + t[1]
        # Ray pos + s d against x² + z² = r² around (t.x, t.z), then the hit's height.
        ox, oz = pos[0] - t[0], pos[2] - t[2]
        a = d[..., 0] ** 2 + d[..., 2] ** 2
        b = ox * d[..., 0] + oz * d[..., 2]
        disc = b * b - a * (ox * ox + oz * oz - radius * radius)
        sHit = (-b - np.sqrt(np.maximum(disc, 0))) / np.maximum(a, 1e-12)
        yHit = pos[1] + sHit * d[..., 1]
        mask |= (disc > 0) & (yHit >= y0) & (yHit <= y1)
    for sh in liquids:
        c = mm(sh["center"])
        # The glass shell around the liquid: the largest sphere with the same centre.
        r = max(float(o["radius"].split()[0]) for o in scene["shapes"] if o["type"] == "sphere" and np.allclose(mm(o["center"]), c))
        oc = pos - c
        b = d @ oc
        mask |= (b * b - (oc @ oc - r * r)) > 0
    return mask


def fluorescent(result):
    return result["rgb_layers"]["fluorescent"].sum(axis=2)


def main():
    args = sys.argv[1:]
    whole = "--whole" in args
    if whole:
        args.remove("--whole")
    seeds = (1, 2)
    if "--seeds" in args:
        i = args.index("--seeds")
        given = args[i + 1] if i + 1 < len(args) else ""
        try:
            seeds = tuple(int(v) for v in given.split(","))
        except ValueError:
            seeds = ()
        if len(seeds) != 2:
            sys.exit(f"paper-scene-error.py: --seeds takes two integer seeds A,B, got {given!r}")
        del args[i:i + 2]
    path = args[0]
    with open(path) as f:
        scene = json.load(f)
    w, h = scene["camera"]["resolution"]
    scene["_base"] = path.rsplit("/", 1)[0] if "/" in path else "."
    mask = np.ones((h, w), bool) if whole else liquid_mask(scene)
    del scene["_base"]
    layer = (lambda r: r["rgb"].sum(axis=2)) if whole else fluorescent

    base = path.rsplit("/", 1)[0] if "/" in path else "."
    for spec in args[1:]:
        integrator, spp, *radius = spec.split(":")
        scene["render"]["integrator"] = integrator
        scene["render"].pop("merge_radius_pixels", None)
        if radius:
            scene["render"]["merge_radius_pixels"] = float(radius[0])
        runs = [fluorosim.render(scene, spp=int(spp), seed=seed, base=base) for seed in seeds]
        a, b = layer(runs[0])[mask], layer(runs[1])[mask]
        mean = 0.5 * (a.mean() + b.mean())
        rms = math.sqrt(np.mean((a - b) ** 2) / 2) / mean if mean > 0 else float("nan")
        seconds = 0.5 * (runs[0]["seconds"] + runs[1]["seconds"])
        print(json.dumps({"scene": path, "integrator": integrator, "spp": int(spp), "seeds": list(seeds), **({"merge_radius_pixels": float(radius[0])} if radius else {}),
                          "pixels": int(mask.sum()),
                          "layer": "total" if whole else "fluorescent", "mean": float(mean), "relative_rms_error": rms, "seconds_per_render": seconds,
                          "relative_mse_x_seconds": rms * rms * seconds}), flush=True)


if __name__ == "__main__":
    main()
