#!/usr/bin/python3
"""SYNTHETIC split-line map with a known answer (docs/post.md, "Synthetic map").

Writes data/splitlines/synthetic_femur.svg and data/splitlines/synthetic_femur.csv.
Nothing here is measured data: a known axial direction field is traced into short
split-line dashes in a "model" frame and pushed through a known smooth warp into
"map" coordinates, as if a researcher had traced a published figure.

Model frame (mm, y up):
  outline      r(phi) = 1 + 0.12 cos(2 phi) + 0.06 sin(3 phi),
               (x, y) = (25 r cos phi, 16 r sin phi)
  field        theta(x, y) = 0.7 sin(pi x / 30) + 0.4 y / 16        [rad, axial]
Warp model -> map (map units, y up):
  bend         x1 = x + 1.5 sin(y / 8),  y1 = y + 1.0 sin(x / 10)
  affine       m  = 1.6 R(20 deg) [[1, 0.1], [0, 1]] (x1, y1) + (120, -150)
Map -> SVG user units: (x_svg, y_svg) = (m_x, -m_y) (SVG y points down); the SVG
stores most dashes inside a <g transform="translate(10,5) scale(2)"> so the
reader's transform handling is exercised, the outline as cubic Bezier segments
(Catmull-Rom through 48 outline points), some dashes as relative paths.
The CSV holds, in map units, one sample per dash point (x, y, angle_deg of the
warped tangent, counter-clockwise from +x) and an [outline] section.
Deterministic: no randomness at all.
"""
import math
import os
import sys

import numpy as np

A_MM, B_MM = 25.0, 16.0


def outline_model(n):
    phi = 2.0 * np.pi * np.arange(n) / n
    r = 1.0 + 0.12 * np.cos(2 * phi) + 0.06 * np.sin(3 * phi)
    return np.stack([A_MM * r * np.cos(phi), B_MM * r * np.sin(phi)], axis=1)


def inside_model(p):
    phi = math.atan2(p[1] / B_MM, p[0] / A_MM)
    r = 1.0 + 0.12 * math.cos(2 * phi) + 0.06 * math.sin(3 * phi)
    return (p[0] / A_MM) ** 2 + (p[1] / B_MM) ** 2 < (r * 0.93) ** 2


def theta(p):
    return 0.7 * math.sin(math.pi * p[0] / 30.0) + 0.4 * p[1] / 16.0


ALPHA = math.radians(20.0)
LIN = 1.6 * np.array([[math.cos(ALPHA), -math.sin(ALPHA)], [math.sin(ALPHA), math.cos(ALPHA)]]) @ np.array(
    [[1.0, 0.1], [0.0, 1.0]])
OFFSET = np.array([120.0, -150.0])


def warp(p):
    x, y = p[0], p[1]
    b = np.array([x + 1.5 * math.sin(y / 8.0), y + 1.0 * math.sin(x / 10.0)])
    return LIN @ b + OFFSET


def warp_jacobian(p):
    x, y = p[0], p[1]
    jb = np.array([[1.0, 1.5 / 8.0 * math.cos(y / 8.0)], [1.0 / 10.0 * math.cos(x / 10.0), 1.0]])
    return LIN @ jb


def trace_dash(seed, half_length=3.0, step=0.5, field=None):
    """Streamline of the axial field (theta, or `field`) through seed, half_length mm each way."""
    field = theta if field is None else field
    pts = [np.array(seed)]
    for sign in (1.0, -1.0):
        p = np.array(seed)
        prev = None
        line = []
        for _ in range(int(round(half_length / step))):
            t = field(p)
            d = np.array([math.cos(t), math.sin(t)]) * sign
            if prev is not None and d @ prev < 0:
                d = -d
            # midpoint (RK2) step keeping the orientation consistent
            pm = p + 0.5 * step * d
            tm = field(pm)
            dm = np.array([math.cos(tm), math.sin(tm)])
            if dm @ d < 0:
                dm = -dm
            p = p + step * dm
            prev = dm
            line.append(p.copy())
        if sign > 0:
            pts = pts + line
        else:
            pts = list(reversed(line)) + pts
    return np.array(pts)


def fmt(v):
    return f"{v:.4f}".rstrip("0").rstrip(".")


def main():
    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    out_dir = os.path.join(root, "data", "splitlines") if len(sys.argv) < 2 else sys.argv[1]
    os.makedirs(out_dir, exist_ok=True)

    outline = np.array([warp(p) for p in outline_model(48)])
    dashes = []
    for gy in np.arange(-20.0, 20.01, 3.0):
        for gx in np.arange(-30.0, 30.01, 3.0):
            seed = np.array([gx + 0.75 * ((round(gy / 3.0)) % 2), gy])
            if not inside_model(seed):
                continue
            dash = trace_dash(seed)
            if not all(inside_model(q) for q in dash):
                continue
            dashes.append(dash)
    map_dashes = [np.array([warp(q) for q in d]) for d in dashes]

    # ---- CSV: samples at every dash point, angle of the warped field direction.
    csv_path = os.path.join(out_dir, "synthetic_femur.csv")
    with open(csv_path, "w") as f:
        f.write("# SYNTHETIC split-line map made by scripts/make_synthetic_splitlines.py (not measured data).\n")
        f.write("# Known field and warp: see docs/post.md. Map units, y up; angle_deg counter-clockwise from +x, axial.\n")
        f.write("[samples]\nx,y,angle_deg\n")
        for d, md in zip(dashes, map_dashes):
            for q, mq in zip(d, md):
                t = theta(q)
                v = warp_jacobian(q) @ np.array([math.cos(t), math.sin(t)])
                ang = math.degrees(math.atan2(v[1], v[0]))
                f.write(f"{fmt(mq[0])},{fmt(mq[1])},{fmt(ang)}\n")
        f.write("[outline]\nx,y\n")
        for q in outline:
            f.write(f"{fmt(q[0])},{fmt(q[1])}\n")

    # ---- SVG (user units: x_svg = x_map, y_svg = -y_map).
    def svg_pt(m):
        return np.array([m[0], -m[1]])

    n = len(outline)
    P = [svg_pt(q) for q in outline]
    d_attr = [f"M {fmt(P[0][0])},{fmt(P[0][1])}"]
    for i in range(n):  # Catmull-Rom segment i -> i+1 as a cubic Bezier
        p0, p1, p2, p3 = P[(i - 1) % n], P[i], P[(i + 1) % n], P[(i + 2) % n]
        c1 = p1 + (p2 - p0) / 6.0
        c2 = p2 - (p3 - p1) / 6.0
        d_attr.append(f"C {fmt(c1[0])},{fmt(c1[1])} {fmt(c2[0])},{fmt(c2[1])} {fmt(p2[0])},{fmt(p2[1])}")
    d_attr.append("Z")
    all_pts = np.concatenate([np.array(P)] + [np.array([svg_pt(q) for q in md]) for md in map_dashes])
    lo, hi = all_pts.min(axis=0) - 5, all_pts.max(axis=0) + 5
    svg_path = os.path.join(out_dir, "synthetic_femur.svg")
    with open(svg_path, "w") as f:
        f.write('<?xml version="1.0" encoding="UTF-8"?>\n')
        f.write("<!-- SYNTHETIC split-line map made by scripts/make_synthetic_splitlines.py (not measured data).\n"
                "     Known field and warp: see docs/post.md. -->\n")
        f.write(f'<svg xmlns="http://www.w3.org/2000/svg" viewBox="{fmt(lo[0])} {fmt(lo[1])} '
                f'{fmt(hi[0] - lo[0])} {fmt(hi[1] - lo[1])}">\n')
        f.write("  <title>SYNTHETIC split-line map</title>\n")
        f.write('  <path id="outline" fill="none" stroke="black" d="' + " ".join(d_attr) + '"/>\n')
        # Dashes: inside a translate+scale group as polylines (even index), as relative
        # paths at the top level (odd index).
        f.write('  <g class="dashes" transform="translate(10,5) scale(2)" stroke="blue" fill="none">\n')
        for k, md in enumerate(map_dashes):
            if k % 2 == 0:
                q = [(svg_pt(m) - np.array([10.0, 5.0])) / 2.0 for m in md]
                f.write('    <polyline points="' + " ".join(f"{fmt(a[0])},{fmt(a[1])}" for a in q) + '"/>\n')
        f.write("  </g>\n")
        for k, md in enumerate(map_dashes):
            if k % 2 == 1:
                q = [svg_pt(m) for m in md]
                parts = [f"m {fmt(q[0][0])},{fmt(q[0][1])}"]
                parts.append("l " + " ".join(f"{fmt(b[0] - a[0])},{fmt(b[1] - a[1])}" for a, b in zip(q[:-1], q[1:])))
                f.write('  <path stroke="red" fill="none" d="' + " ".join(parts) + '"/>\n')
        f.write("</svg>\n")
    print(f"wrote {svg_path} and {csv_path}: {len(dashes)} dashes, {sum(len(d) for d in dashes)} samples")


if __name__ == "__main__":
    main()
