#!/usr/bin/python3
"""SYNTHETIC split-line map drawn on the bundled femur's distal view (docs/post.md).

Writes data/splitlines/synthetic_distal_femur.svg and .csv. Nothing here is measured
data. The outline is the femoral cartilage of the bundled parametric knee
(data/models/knee_parametric/coarse/femur_cartilage.stl) seen as arthrosim-post's
default view sees it: looking superiorly along +Y with anterior (+X) up, so that a view
point (x, y) = (-z, x) in mm of the model frame (docs/post.md, "Views"; the outline is
the boundary loop enclosing the largest projected area). Inside it a known axial
direction field is traced into short split-line dashes, and the whole drawing is
pushed through a known smooth warp into "figure" units, as if a researcher had traced
a published figure of another femur. The demo scene compares the stage-2 strain
directions with this map, so the report shows every figure of the comparison; its
angles say nothing about cartilage (the field is invented, see FIELD below).

View frame (mm, anterior up, medial to the right for this right knee):
  field   theta(x, y) = pi/2 + 0.35 sin(pi x / 32) - 0.25 (y - 6) / 25    [rad, axial]
          (lines run mostly antero-posteriorly and fan out towards the condyles)
Warp view -> map (map units, y up):
  bend    x1 = x + 1.2 sin(y / 9),  y1 = y + 0.8 sin(x / 11)
  affine  m  = 2.2 R(-12 deg) [[1, 0.08], [0, 1]] (x1, y1) + (150, -120)
The CSV holds one sample per dash point (x, y, angle_deg of the warped tangent,
counter-clockwise from +x) and the outline (every 4th boundary node); the SVG holds
the same outline as a closed polygon path and the dashes as polylines.
Deterministic: no randomness. Run with Debian's python3 + python3-numpy:
  /usr/bin/python3 scripts/make_synthetic_femur_map.py
"""
import math
import os
import struct
import sys
from collections import defaultdict

import numpy as np

from make_synthetic_splitlines import fmt, trace_dash  # same folder

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
STL = os.path.join(ROOT, "data", "models", "knee_parametric", "coarse", "femur_cartilage.stl")

ALPHA = math.radians(-12.0)
LIN = 2.2 * np.array([[math.cos(ALPHA), -math.sin(ALPHA)], [math.sin(ALPHA), math.cos(ALPHA)]]) @ np.array(
    [[1.0, 0.08], [0.0, 1.0]])
OFFSET = np.array([150.0, -120.0])


def read_binary_stl(path):
    data = open(path, "rb").read()
    n = struct.unpack("<I", data[80:84])[0]
    rec = np.dtype([("n", "<f4", 3), ("v", "<f4", (3, 3)), ("a", "<u2")])
    tri = np.frombuffer(data[84:84 + 50 * n], dtype=rec)
    v, idx = np.unique(tri["v"].reshape(-1, 3).astype(float), axis=0, return_inverse=True)
    return v, idx.reshape(-1, 3)


def boundary_loops(faces):
    count = defaultdict(int)
    for f in faces:
        for a, b in ((f[0], f[1]), (f[1], f[2]), (f[2], f[0])):
            count[(min(a, b), max(a, b))] += 1
    adj = defaultdict(list)
    for (a, b), c in sorted(count.items()):
        if c == 1:
            adj[a].append(b)
            adj[b].append(a)
    seen, loops = set(), []
    for start in sorted(adj):
        if start in seen:
            continue
        loop, prev, cur = [start], None, start
        seen.add(start)
        while True:
            nxt = [x for x in adj[cur] if x != prev][0]
            if nxt == start or nxt in seen:
                break
            loop.append(nxt)
            seen.add(nxt)
            prev, cur = cur, nxt
        loops.append(loop)
    return loops


def signed_area(p):
    return 0.5 * float(np.sum(p[:, 0] * np.roll(p[:, 1], -1) - np.roll(p[:, 0], -1) * p[:, 1]))


def view_outline():
    v, f = read_binary_stl(STL)
    view = np.stack([-v[:, 2], v[:, 0]], axis=1)  # (x, y) = (-z, x), mm
    best = max(boundary_loops(f), key=lambda loop: abs(signed_area(view[loop])))
    outline = view[best]
    if signed_area(outline) < 0:
        outline = outline[::-1]
    return outline


def theta(p):
    return math.pi / 2 + 0.35 * math.sin(math.pi * p[0] / 32.0) - 0.25 * (p[1] - 6.0) / 25.0


def warp(p):
    b = np.array([p[0] + 1.2 * math.sin(p[1] / 9.0), p[1] + 0.8 * math.sin(p[0] / 11.0)])
    return LIN @ b + OFFSET


def warp_jacobian(p):
    jb = np.array([[1.0, 1.2 / 9.0 * math.cos(p[1] / 9.0)], [0.8 / 11.0 * math.cos(p[0] / 11.0), 1.0]])
    return LIN @ jb


def inside(p, poly):
    """Even-odd point-in-polygon test."""
    x, y = p
    c = False
    j = len(poly) - 1
    for i in range(len(poly)):
        xi, yi = poly[i]
        xj, yj = poly[j]
        if (yi > y) != (yj > y) and x < (xj - xi) * (y - yi) / (yj - yi) + xi:
            c = not c
        j = i
    return c


def distance_to_polygon(p, poly):
    a, b = poly, np.roll(poly, -1, axis=0)
    ab = b - a
    t = np.clip(np.einsum("ij,ij->i", p - a, ab) / np.einsum("ij,ij->i", ab, ab), 0.0, 1.0)
    return float(np.min(np.linalg.norm(a + t[:, None] * ab - p, axis=1)))


def main():
    out_dir = os.path.join(ROOT, "data", "splitlines") if len(sys.argv) < 2 else sys.argv[1]
    os.makedirs(out_dir, exist_ok=True)
    outline = view_outline()
    lo, hi = outline.min(axis=0), outline.max(axis=0)
    dashes = []
    for gy in np.arange(math.floor(lo[1]), hi[1] + 0.01, 4.0):
        for gx in np.arange(math.floor(lo[0]), hi[0] + 0.01, 4.0):
            seed = np.array([gx + 2.0 * (round((gy - lo[1]) / 4.0) % 2), gy])
            if not inside(seed, outline) or distance_to_polygon(seed, outline) < 3.5:
                continue
            dash = trace_dash(seed, field=theta)
            if all(inside(q, outline) and distance_to_polygon(q, outline) > 1.0 for q in dash):
                dashes.append(dash)
    map_outline = np.array([warp(p) for p in outline[::4]])
    map_dashes = [np.array([warp(q) for q in d]) for d in dashes]
    stem = os.path.join(out_dir, "synthetic_distal_femur")
    header = ("SYNTHETIC split-line map made by scripts/make_synthetic_femur_map.py (not measured data): "
              "the bundled femur's distal-view outline with an invented field (docs/post.md)")
    with open(stem + ".csv", "w") as f:
        f.write(f"# {header}.\n# Map units, y up; angle_deg counter-clockwise from +x, axial.\n")
        f.write("[samples]\nx,y,angle_deg\n")
        for d, md in zip(dashes, map_dashes):
            for q, mq in zip(d, md):
                t = theta(q)
                v = warp_jacobian(q) @ np.array([math.cos(t), math.sin(t)])
                f.write(f"{fmt(mq[0])},{fmt(mq[1])},{fmt(math.degrees(math.atan2(v[1], v[0])))}\n")
        f.write("[outline]\nx,y\n")
        for q in map_outline:
            f.write(f"{fmt(q[0])},{fmt(q[1])}\n")

    def svg(m):
        return f"{fmt(m[0])},{fmt(-m[1])}"

    pts = np.concatenate([map_outline] + map_dashes)
    lo_s = np.array([pts[:, 0].min(), -pts[:, 1].max()]) - 5
    hi_s = np.array([pts[:, 0].max(), -pts[:, 1].min()]) + 5
    with open(stem + ".svg", "w") as f:
        f.write('<?xml version="1.0" encoding="UTF-8"?>\n')
        f.write(f"<!-- {header}. -->\n")
        f.write(f'<svg xmlns="http://www.w3.org/2000/svg" viewBox="{fmt(lo_s[0])} {fmt(lo_s[1])} '
                f'{fmt(hi_s[0] - lo_s[0])} {fmt(hi_s[1] - lo_s[1])}">\n')
        f.write("  <title>SYNTHETIC split-line map on the bundled femur's distal view</title>\n")
        f.write('  <path id="outline" fill="none" stroke="black" d="M ' +
                " L ".join(svg(q) for q in map_outline) + ' Z"/>\n')
        f.write('  <g class="dashes" stroke="blue" fill="none">\n')
        for md in map_dashes:
            f.write('    <polyline points="' + " ".join(svg(q) for q in md) + '"/>\n')
        f.write("  </g>\n</svg>\n")
    print(f"wrote {stem}.svg and .csv: outline {len(outline)} nodes ({len(map_outline)} kept), "
          f"{len(dashes)} dashes, {sum(len(d) for d in dashes)} samples")


if __name__ == "__main__":
    main()
