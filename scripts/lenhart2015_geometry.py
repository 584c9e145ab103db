#!/usr/bin/python3
"""Builds data/models/lenhart2015/Geometry from the two public sources.

The lenhart2015 knee meshes (OpenSim-JAM, clnsmith/opensim-jam, Apache-2.0)
are incomplete in that repository: the femoral cartilage, the femur bone and
the tibia bone are stored there as blobs that are not available. The
repository mbblomquist/opensim-jam-tutorial (lenhart2015/Geometry) has all
six, but its femur bone, femoral cartilage, tibia bone and tibial cartilage
were rotated by +1.5 deg about the Y (long) axis of their body frames in its
last commit ("Added OA model with osteophytes"): its tibial cartilage equals
clnsmith's after Ry(+1.5 deg) to 3e-9 m, and its own earlier partial meshes
(femur/tibia cartilage "-lateral", taken from the unrotated files) match the
rotated ones after the same rotation. This script therefore takes

  - the tibial and patellar cartilage and the patella bone from clnsmith's
    repository as they are (the geometry opensim-jam's published results
    were computed with), and
  - the femur bone, the femoral cartilage and the tibia bone from the
    tutorial, rotated back by Ry(-1.5 deg) (rotation about the body frame's
    origin, as the forward rotation was; checked below on the tibial
    cartilage, which exists in both),

and writes all six as binary STL (float32, metres, the body frames of the
.osim) under the .osim's file names. It checks that the tutorial's patellar
meshes equal clnsmith's and that the rotated-back tutorial tibial cartilage
equals clnsmith's to 1e-6 m, and prints the triangle counts and bounding
boxes.

    /usr/bin/python3 scripts/lenhart2015_geometry.py \\
        --jam DIR_WITH_CLNSMITH_STLS --tutorial DIR_WITH_TUTORIAL_STLS \\
        --out data/models/lenhart2015/Geometry

(DIR_WITH_...: folders holding lenhart2015-R-*.stl of each source, e.g.
opensim-jam/opensim-jam-release/models/lenhart2015/Geometry and
opensim-jam-tutorial/lenhart2015/Geometry.) Needs python3-numpy.
"""
import argparse
import math
import os
import struct
import sys

import numpy as np

NAMES = ["femur-bone", "femur-cartilage", "tibia-bone", "tibia-cartilage", "patella-bone", "patella-cartilage"]
FROM_TUTORIAL = {"femur-bone", "femur-cartilage", "tibia-bone"}
ANGLE_DEG = -1.5


def read_stl(path):
    """Triangles (n, 3, 3) in float64 from an ASCII or binary STL."""
    data = open(path, "rb").read()
    if len(data) == 0:
        sys.exit(f"{path}: empty file")
    if data[:5] == b"solid" and b"facet" in data[:400]:
        v = [[float(x) for x in line.split()[1:4]] for line in data.decode().splitlines()
             if line.strip().startswith("vertex")]
        return np.array(v).reshape(-1, 3, 3)
    n = struct.unpack("<I", data[80:84])[0]
    rec = np.dtype([("n", "<f4", 3), ("v", "<f4", (3, 3)), ("a", "<u2")])
    if len(data) < 84 + 50 * n:
        sys.exit(f"{path}: binary STL shorter than its {n} triangles")
    return np.frombuffer(data[84:84 + 50 * n], dtype=rec)["v"].astype(np.float64)


def write_stl(path, tri, header):
    tri32 = tri.astype(np.float32)
    e1 = tri32[:, 1] - tri32[:, 0]
    e2 = tri32[:, 2] - tri32[:, 0]
    nrm = np.cross(e1, e2)
    nrm /= np.maximum(np.linalg.norm(nrm, axis=1, keepdims=True), 1e-30)
    rec = np.zeros(len(tri32), dtype=np.dtype([("n", "<f4", 3), ("v", "<f4", (3, 3)), ("a", "<u2")]))
    rec["n"] = nrm
    rec["v"] = tri32
    with open(path, "wb") as f:
        f.write(header.encode()[:80].ljust(80, b" "))
        f.write(struct.pack("<I", len(tri32)))
        f.write(rec.tobytes())


def rot_y(deg):
    c, s = math.cos(math.radians(deg)), math.sin(math.radians(deg))
    return np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--jam", required=True, help="folder with clnsmith/opensim-jam's lenhart2015-R-*.stl")
    ap.add_argument("--tutorial", required=True, help="folder with mbblomquist/opensim-jam-tutorial's lenhart2015-R-*.stl")
    ap.add_argument("--out", required=True)
    a = ap.parse_args()
    os.makedirs(a.out, exist_ok=True)
    R = rot_y(ANGLE_DEG)
    # Checks: the rotation maps the tutorial's tibial cartilage onto clnsmith's,
    # and the patellar meshes are the same in both.
    tut_tc = read_stl(os.path.join(a.tutorial, "lenhart2015-R-tibia-cartilage.stl"))
    jam_tc = read_stl(os.path.join(a.jam, "lenhart2015-R-tibia-cartilage.stl"))
    err = np.abs(np.einsum("ij,nkj->nki", R, tut_tc) - jam_tc).max()
    print(f"tibial cartilage: tutorial rotated by {ANGLE_DEG} deg about Y vs clnsmith: max |difference| {err:.3g} m")
    if err > 1e-6:
        sys.exit("the tutorial's meshes are not clnsmith's rotated by +1.5 deg about Y; not converting")
    for n in ["patella-bone", "patella-cartilage"]:
        d = np.abs(read_stl(os.path.join(a.tutorial, f"lenhart2015-R-{n}.stl")) -
                   read_stl(os.path.join(a.jam, f"lenhart2015-R-{n}.stl"))).max()
        print(f"{n}: tutorial vs clnsmith max |difference| {d:.3g} m")
        if d > 0:
            sys.exit(f"{n} differs between the sources")
    for n in NAMES:
        src = a.tutorial if n in FROM_TUTORIAL else a.jam
        tri = read_stl(os.path.join(src, f"lenhart2015-R-{n}.stl"))
        if n in FROM_TUTORIAL:
            tri = np.einsum("ij,nkj->nki", R, tri)
            origin = f"mbblomquist/opensim-jam-tutorial rotated {ANGLE_DEG} deg about Y"
        else:
            origin = "clnsmith/opensim-jam"
        out = os.path.join(a.out, f"lenhart2015-R-{n}.stl")
        write_stl(out, tri, f"lenhart2015 {n} (OpenSim-JAM, Apache-2.0) from {origin}")
        back = read_stl(out)
        v = back.reshape(-1, 3)
        print(f"{n}: {len(back)} triangles, float32 rounding {np.abs(back - tri).max():.2g} m, "
              f"bbox {np.round(v.min(0) * 1e3, 2)} .. {np.round(v.max(0) * 1e3, 2)} mm -> {out}")


if __name__ == "__main__":
    main()
