#!/usr/bin/env python3
"""Medial/lateral split of stage 1's tibiofemoral contact force.

Reads a kinematics file (arthrosim-comak, docs/kinematics_file.md) and prints
how /contact/tibiofemoral/{medial_force,lateral_force} were made (the group's
`compartments` attribute), the largest |medial + lateral - total| relative to
the total, and over a stance window: the medial share |F_m| / (|F_m| + |F_l|)
per frame (mean, median, range), the share of the force impulses, the frames
with medial > lateral, and both compartments at the first and second peaks of
the total (split at --mid).

    /usr/bin/python3 scripts/compartment_share.py OUT/kinematics.h5 --stance 1.263 1.942 --mid 1.6

Needs h5py and numpy (/usr/bin/python3 on Debian).
"""
import argparse

import h5py
import numpy as np


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("kinematics")
    ap.add_argument("--stance", nargs=2, type=float, metavar=("T0", "T1"), required=True,
                    help="stance window [s] on the file's clock")
    ap.add_argument("--mid", type=float, required=True, help="time [s] between the two peaks of the total")
    a = ap.parse_args()
    with h5py.File(a.kinematics, "r") as f:
        g = f["contact/tibiofemoral"]
        t = f["time"][:]
        total = g["force"][:]
        med, lat = g["medial_force"][:], g["lateral_force"][:]
        rule = g.attrs.get("compartments", b"(no attribute: written before the split existed)")
        bw = float(f.attrs.get("body_mass_kg", 0.0)) * 9.81
    if isinstance(rule, bytes):
        rule = rule.decode()
    F, m, l = (np.linalg.norm(x, axis=1) for x in (total, med, lat))
    print("compartments:", rule)
    err = np.linalg.norm(med + lat - total, axis=1) / np.maximum(F, 1e-300)
    print("largest |medial + lateral - total| / |total|: %.2e" % err[F > 0].max())
    st = (t >= a.stance[0]) & (t <= a.stance[1]) & (m + l > 0)
    share = m[st] / (m[st] + l[st])
    print("stance %.3f-%.3f s, %d frames: medial share mean %.3f, median %.3f, range %.3f-%.3f; impulse share %.3f; "
          "medial > lateral in %d of %d frames" % (a.stance[0], a.stance[1], st.sum(), share.mean(), np.median(share),
                                                     share.min(), share.max(), m[st].sum() / (m[st].sum() + l[st].sum()),
                                                     (m[st] > l[st]).sum(), st.sum()))
    unit, scale = ("BW", bw) if bw > 0 else ("N", 1.0)
    for name, sel in (("first peak", t < a.mid), ("second peak", t >= a.mid)):
        i = np.flatnonzero(sel)[np.argmax(F[sel])]
        print("%s t = %.3f s: total %.2f %s, medial %.2f, lateral %.2f (medial share %.3f)" %
              (name, t[i], F[i] / scale, unit, m[i] / scale, l[i] / scale, m[i] / (m[i] + l[i])))


if __name__ == "__main__":
    main()
