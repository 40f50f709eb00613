#!/usr/bin/env python3
"""Write the two closed meshes of a sealed glass vial filled with liquid, for the fluorescence samples.

    python3 samples/fluorescence/make_vial_obj.py

writes, next to this script:

    vial_glass.obj   the outer surface of the vial: a closed cylinder, radius 25 mm, height 110 mm
    vial_liquid.obj  the liquid: a closed cylinder, radius 23 mm, from y = 2 mm to y = 108 mm

Coordinates are in millimetres, the cylinder axis is +y and the bottom of the vial is centred on
the origin, so a scene places a vial standing on the floor with "translate": [x, "0 mm", z].
The vial is sealed and completely full: the glass is a 2 mm layer on every side (wall, bottom and
top) and the space between the two surfaces is glass. In the scene, vial_glass.obj has
"interior": "glass" (and vacuum outside) and vial_liquid.obj has "interior": <the dye solution>,
"exterior": "glass".

Both meshes are watertight triangle meshes with shared vertices, wound counter-clockwise seen
from outside, so the geometric normal (b - a) x (c - a) of every triangle points outward, as
docs/scene-format.md requires for interfaces between media. The script checks this (every edge
used once in each direction, positive enclosed volume close to the cylinder's) before writing.
The output is deterministic: re-running it rewrites identical files.
"""

import math
import os
import sys

SEGMENTS = 96          # facets around the axis; 96 keeps the silhouette smooth at 256 px
OUTER_RADIUS = 25.0    # mm
OUTER_HEIGHT = 110.0   # mm
WALL = 2.0             # mm, glass thickness on the side, the bottom and the top


def cylinder(radius, y0, y1, segments):
    """Closed cylinder around +y from y0 to y1: (vertices, triangles), triangles as 0-based indices."""
    angles = [2.0 * math.pi * i / segments for i in range(segments)]
    bottom = [(radius * math.cos(a), y0, radius * math.sin(a)) for a in angles]
    top = [(radius * math.cos(a), y1, radius * math.sin(a)) for a in angles]
    vertices = bottom + top + [(0.0, y0, 0.0), (0.0, y1, 0.0)]
    n = segments
    bc, tc = 2 * n, 2 * n + 1
    triangles = []
    for i in range(n):
        j = (i + 1) % n
        b0, b1, t0, t1 = i, j, n + i, n + j
        # side: normal points away from the axis
        triangles.append((b0, t1, b1))
        triangles.append((b0, t0, t1))
        # bottom cap: normal -y; top cap: normal +y
        triangles.append((bc, b0, b1))
        triangles.append((tc, t1, t0))
    return vertices, triangles


def sub(a, b):
    return (a[0] - b[0], a[1] - b[1], a[2] - b[2])


def cross(a, b):
    return (a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0])


def check_closed_outward(name, vertices, triangles, radius, height, segments):
    directed = {}
    for t in triangles:
        for k in range(3):
            e = (t[k], t[(k + 1) % 3])
            directed[e] = directed.get(e, 0) + 1
    for (a, b), count in directed.items():
        if count != 1 or directed.get((b, a)) != 1:
            sys.exit(f"{name}: edge ({a}, {b}) is not shared by exactly two oppositely wound triangles")
    # Signed volume by the divergence theorem: positive iff the normals point outward.
    volume = 0.0
    for a, b, c in triangles:
        pa, pb, pc = vertices[a], vertices[b], vertices[c]
        volume += (pa[0] * (pb[1] * pc[2] - pb[2] * pc[1])
                   - pa[1] * (pb[0] * pc[2] - pb[2] * pc[0])
                   + pa[2] * (pb[0] * pc[1] - pb[1] * pc[0])) / 6.0
    polygon = 0.5 * segments * radius * radius * math.sin(2.0 * math.pi / segments)
    expected = polygon * height
    if not abs(volume - expected) <= 1e-9 * expected:
        sys.exit(f"{name}: enclosed volume {volume} mm^3, expected {expected} mm^3 (wrong winding?)")
    # Each side normal must point away from the axis, each cap normal along its own side.
    for a, b, c in triangles:
        pa, pb, pc = vertices[a], vertices[b], vertices[c]
        nrm = cross(sub(pb, pa), sub(pc, pa))
        centroid = [(pa[k] + pb[k] + pc[k]) / 3.0 for k in range(3)]
        mid_y = (min(v[1] for v in vertices) + max(v[1] for v in vertices)) / 2.0
        outward = (centroid[0], centroid[1] - mid_y, centroid[2])
        if nrm[0] * outward[0] + nrm[1] * outward[1] + nrm[2] * outward[2] <= 0.0:
            sys.exit(f"{name}: triangle ({a}, {b}, {c}) faces inward")
    return volume


def write_obj(path, comment, vertices, triangles):
    lines = [f"# {line}" for line in comment] + [f"o {os.path.splitext(os.path.basename(path))[0]}"]
    lines += [f"v {x:.6f} {y:.6f} {z:.6f}" for x, y, z in vertices]
    lines += [f"f {a + 1} {b + 1} {c + 1}" for a, b, c in triangles]
    with open(path, "w", newline="\n") as f:
        f.write("\n".join(lines) + "\n")


def main():
    here = os.path.dirname(os.path.abspath(__file__))
    inner_radius = OUTER_RADIUS - WALL
    parts = [
        ("vial_glass.obj", OUTER_RADIUS, 0.0, OUTER_HEIGHT,
         f"outer surface of a sealed glass vial: closed cylinder, radius {OUTER_RADIUS:g} mm, y from 0 to {OUTER_HEIGHT:g} mm"),
        ("vial_liquid.obj", inner_radius, WALL, OUTER_HEIGHT - WALL,
         f"liquid inside the vial: closed cylinder, radius {inner_radius:g} mm, y from {WALL:g} to {OUTER_HEIGHT - WALL:g} mm"),
    ]
    for name, radius, y0, y1, what in parts:
        vertices, triangles = cylinder(radius, y0, y1, SEGMENTS)
        volume = check_closed_outward(name, vertices, triangles, radius, y1 - y0, SEGMENTS)
        comment = [
            "Written by make_vial_obj.py (samples/fluorescence); do not edit, re-run the script.",
            what + f", {SEGMENTS} segments.",
            "Units: mm. Axis +y, bottom centred on the origin. Closed, counter-clockwise seen from outside (outward normals).",
            f"{len(vertices)} vertices, {len(triangles)} triangles, enclosed volume {volume:.1f} mm^3.",
        ]
        write_obj(os.path.join(here, name), comment, vertices, triangles)
        print(f"wrote {name}: {len(vertices)} vertices, {len(triangles)} triangles, volume {volume:.1f} mm^3")


if __name__ == "__main__":
    main()
