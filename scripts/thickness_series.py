#!/usr/bin/env python3
"""Refinement series of the prepare stage's cartilage thickness.

Runs arthrosim-prepare on one model at several edge lengths and prints, per
cartilage surface and edge length (docs/prepared_model.md, "Measurements"):

- triangles, quads, whether the outline was kept or resampled;
- thickness: area-weighted mean, vertex mean, max, rim mean (outline,
  length-weighted), all after the min_thickness floor; and the area-weighted
  mean of the measured values (before the floor);
- where the values came from: % of vertices with a ray entry, inside the bone
  (overlap: measured 0), closest point (no ray entry), raised to the floor;
- element quality: smallest angle, admissible shell thickness;

then the relative change of mean, max and rim between the two finest edge
lengths, against the 5 % criterion of issue 28.

Needs h5py and numpy (Debian: python3-h5py, python3-numpy, i.e. /usr/bin/python3).

Sample runs:
  /usr/bin/python3 scripts/thickness_series.py --model data/models/lenhart2015 --edges 3,2,1.5,1,0.75
  /usr/bin/python3 scripts/thickness_series.py --model data/models/knee_parametric/medium --edges 3,2,1.5,1
"""
import argparse
import os
import subprocess
import sys
import tempfile
import time

import h5py
import numpy as np


def attr(g, k):
    v = g.attrs[k]
    return v.decode() if isinstance(v, bytes) else v


def surface_figures(h5, name):
    g = h5["/surfaces/" + name]
    tri = g["triangles"]
    V = tri["vertices"][()]
    F = tri["faces"][()]
    t = tri["thickness"][()]
    tm = tri["thickness_measured"][()]
    src = tri["thickness_source"][()]
    a = np.linalg.norm(np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]]), axis=1) / 2
    w = np.zeros(len(V))
    for k in range(3):
        np.add.at(w, F[:, k], a / 3)
    n = len(V)
    floor = h5["/"].attrs["min_thickness_m"]
    return {
        "triangles": len(F),
        "quads": len(g["quads/quads"]),
        "outline": attr(g, "outline"),
        "mean": attr(g, "thickness_mean_m"),
        "vmean": t.mean(),
        "measured_mean": (tm * w).sum() / w.sum(),
        "max": attr(g, "thickness_max_m"),
        "rim": attr(g, "thickness_rim_mean_m"),
        "ray": 100.0 * (src == 0).sum() / n,
        "inside": 100.0 * (src == 2).sum() / n,
        "closest": 100.0 * (src == 1).sum() / n,
        "floored": 100.0 * (tm < floor).sum() / n,
        "min_angle": attr(g, "min_angle_deg"),
        "shell": attr(g, "min_admissible_shell_thickness_m"),
    }


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--model", required=True, help="model folder (or meshes.yaml) given to arthrosim-prepare")
    ap.add_argument("--edges", default="3,2,1.5,1,0.75", help="edge lengths [mm], coarse to fine")
    ap.add_argument("--unit", help="--unit for arthrosim-prepare (without a manifest)")
    ap.add_argument("--prepare", default="build/bin/arthrosim-prepare", help="the arthrosim-prepare executable")
    ap.add_argument("--out", help="folder for the prepared files (default: a temporary folder)")
    ap.add_argument("--criterion", type=float, default=5.0, help="largest relative change [%%] between the two finest")
    args = ap.parse_args()
    edges = [float(e) for e in args.edges.split(",")]
    out = args.out or tempfile.mkdtemp(prefix="thickness_series_")
    os.makedirs(out, exist_ok=True)
    rows = {}
    for e in edges:
        path = os.path.join(out, "prepared_%gmm.h5" % e)
        cmd = [args.prepare, "--quiet", "--model", args.model, "--edge-length-mm", str(e), "--out", path]
        if args.unit:
            cmd += ["--unit", args.unit]
        t0 = time.time()
        r = subprocess.run(cmd, capture_output=True, text=True)
        if r.returncode != 0:
            sys.exit("failed: %s\n%s" % (" ".join(cmd), r.stderr))
        print("prepared %s at %g mm in %.1f s" % (args.model, e, time.time() - t0), file=sys.stderr)
        with h5py.File(path, "r") as h5:
            for s in h5["/surfaces/names"][()]:
                s = s.decode() if isinstance(s, bytes) else s
                rows.setdefault(s, []).append((e, surface_figures(h5, s)))
    print("| surface | edge [mm] | triangles | quads | outline | mean [mm] | vertex mean | measured mean | max [mm] "
          "| rim [mm] | ray % | inside % | closest % | floored % | min angle [deg] | shell [mm] |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|")
    verdicts = []
    for s, series in rows.items():
        for e, f in series:
            print("| %s | %g | %d | %d | %s | %.3f | %.3f | %.3f | %.3f | %.3f | %.1f | %.1f | %.1f | %.1f | %.1f | %.2f |" % (
                s, e, f["triangles"], f["quads"], f["outline"], f["mean"] * 1e3, f["vmean"] * 1e3,
                f["measured_mean"] * 1e3, f["max"] * 1e3, f["rim"] * 1e3, f["ray"], f["inside"], f["closest"],
                f["floored"], f["min_angle"], f["shell"] * 1e3))
        if len(series) >= 2:
            (e1, a), (e2, b) = series[-2], series[-1]
            ch = {k: 100.0 * abs(b[k] - a[k]) / abs(b[k]) for k in ("mean", "max", "rim")}
            ok = all(v <= args.criterion for v in ch.values())
            verdicts.append("%s: %g -> %g mm: mean %.2f %%, max %.2f %%, rim %.2f %% (%s, criterion %g %%)" % (
                s, e1, e2, ch["mean"], ch["max"], ch["rim"], "met" if ok else "NOT met", args.criterion))
    print()
    for v in verdicts:
        print(v)


if __name__ == "__main__":
    main()
