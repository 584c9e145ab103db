#!/usr/bin/env python3
"""Quarter Scordelis-Lo roof as a quad OBJ (mm as written; see scordelis_lo_roof.yaml).

Cylinder of radius 25 about the x axis, 0 <= x <= 25 (half the length 50;
x = 0 is midspan), 0 <= theta <= 40 deg from the crown (y = R sin theta,
z = R cos theta). n x n quads; node (i, j) = j (n + 1) + i, i along x,
j along theta, so the free-edge midpoint (x = 0, theta = 40 deg) is node
n (n + 1). Quads counter-clockwise seen from outside (normals outward).

usage: make_scordelis_lo_mesh.py N OUT.obj
"""
import math
import sys

n = int(sys.argv[1])
R, half_length, angle = 25.0, 25.0, math.radians(40.0)
with open(sys.argv[2], "w") as f:
    f.write(f"# quarter Scordelis-Lo roof, {n} x {n} quads (make_scordelis_lo_mesh.py {n})\n")
    for j in range(n + 1):
        th = angle * j / n
        for i in range(n + 1):
            f.write(f"v {half_length * i / n:.17g} {R * math.sin(th):.17g} {R * math.cos(th):.17g}\n")
    for j in range(n):
        for i in range(n):
            a = j * (n + 1) + i + 1
            f.write(f"f {a} {a + 1} {a + n + 2} {a + n + 1}\n")
