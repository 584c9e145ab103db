#!/usr/bin/python3
"""Independent check of ShellVerification.StiffFoundationSpreadingNeedsTheBendingLengthResolved.

The shell strip of that test in cylindrical bending (nu = 0) is a Timoshenko
beam: linear elements for the deflection w and the rotation theta, the shear
strain integrated at one point (as the shell's assumed transverse shear), on
a Winkler foundation whose springs are either lumped at the nodes (the
surface stage's `foundation_integration: nodal`) or integrated consistently
over each element (`consistent`). A line load P at mid-length; printed: the
effective width W = P / (w0 k b) over its Richardson limit at each lambda h,
for both integrations (the test's printed figures agree to 4 digits).

  /usr/bin/python3 scripts/foundation_beam_model.py
"""
import numpy as np

# The test's strip: 1 mm, 400 MPa, 4 mm wide, on K / h with K = 37.93 MPa
# (10 MPa, nu 0.45) and h = 1.5 mm.
t, b, E = 1e-3, 4e-3, 400e6
G = E / 2
K = 10e6 * 0.55 / (1.45 * 0.1)
k = K / 1.5e-3
I, A = b * t ** 3 / 12, b * t
lam = (k * b / (4 * E * I)) ** 0.25
L, P = 12 / lam, 1e-3


def deflection(nx, consistent):
    h = L / nx
    n = 2 * (nx + 1)  # (w, theta) per node
    Kg = np.zeros((n, n))
    bend = E * I / h * np.array([[0, 0, 0, 0], [0, 1, 0, -1], [0, 0, 0, 0], [0, -1, 0, 1]])
    Bs = np.array([-1 / h, -0.5, 1 / h, -0.5])  # shear strain at the element centre
    shear = G * A * h * np.outer(Bs, Bs)
    if consistent:
        found = k * b * h / 6 * np.array([[2, 0, 1, 0], [0, 0, 0, 0], [1, 0, 2, 0], [0, 0, 0, 0]])
    else:
        found = k * b * h / 2 * np.diag([1.0, 0, 1, 0])
    Ke = bend + shear + found
    for e in range(nx):
        d = slice(2 * e, 2 * e + 4)
        Kg[d, d] += Ke
    f = np.zeros(n)
    f[2 * (nx // 2)] = P
    return np.linalg.solve(Kg, f)[2 * (nx // 2)]


nxs = [10, 20, 40, 80, 160]
for consistent in (False, True):
    W = [P / (deflection(nx, consistent) * k * b) for nx in nxs]
    limit = W[-1] + (W[-1] - W[-2]) / 3
    name = "consistent" if consistent else "nodal"
    for nx, w in zip(nxs, W):
        print("%-10s lambda h = %.3f: W / W_limit = %.4f" % (name, lam * L / nx, w / limit))
