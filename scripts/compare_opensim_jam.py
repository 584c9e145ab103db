#!/usr/bin/python3
"""Stage 1 on the lenhart2015 subject against opensim-jam's published COMAK.

Reads arthrosim's kinematics file (arthrosim-comak / `arthrosim run` on
data/scenes/lenhart2015_gait.yaml) and opensim-jam's walking_values.sto and
walking_activation.sto (bundled in
data/trials/lenhart2015_overground17/opensim_jam_comak/) and prints, over the
frames both have:

  - per secondary coordinate: RMS difference (deg or mm), both ranges;
  - the largest change between consecutive frames of every rotation (deg);
  - per knee muscle: the correlation of the activations and both means;
  - the tibiofemoral contact force (magnitude on the tibia, BW) and its two
    stance peaks (first in 1.25-1.55 s, second in 1.55-1.95 s);
  - solver figures: frames converged (Ipopt status 0 = Solve_Succeeded,
    1 = acceptable), wall time per frame (median, worst).

With --plot FILE.png it draws the secondary coordinates and the activations
against opensim-jam's (python3-matplotlib). With --json FILE it also writes
the figures as JSON.

    /usr/bin/python3 scripts/compare_opensim_jam.py OUT/kinematics.h5 [--plot F.png] [--json F.json]
"""
import argparse
import json
import math
import os
import sys

import h5py
import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
REF = os.path.join(HERE, "..", "data", "trials", "lenhart2015_overground17", "opensim_jam_comak")
KNEE_MUSCLES = ["bflh_r", "bfsh_r", "gaslat_r", "gasmed_r", "grac_r", "recfem_r", "sart_r", "semimem_r",
                "semiten_r", "tfl_r", "vasint_r", "vaslat_r", "vasmed_r"]
PLOT_MUSCLES = KNEE_MUSCLES + ["soleus_r", "tibant_r", "glmed1_r", "iliacus_r", "psoas_r"]
SECONDARY = ["knee_add_r", "knee_rot_r", "knee_tx_r", "knee_ty_r", "knee_tz_r",
             "pf_flex_r", "pf_rot_r", "pf_tilt_r", "pf_tx_r", "pf_ty_r", "pf_tz_r"]
ROTATIONS = {"knee_add_r", "knee_rot_r", "pf_flex_r", "pf_rot_r", "pf_tilt_r", "knee_flex_r"}
BW_KG = 62.0
G = 9.80665


def read_sto(path):
    """(labels, data) of an OpenSim .sto; angles stay as written (degrees if inDegrees=yes)."""
    with open(path) as f:
        lines = f.read().splitlines()
    end = next(i for i, l in enumerate(lines) if l.strip() == "endheader")
    labels = lines[end + 1].split("\t")
    labels = [l.strip() for l in labels if l.strip()]
    data = np.array([[float(x) for x in l.split()] for l in lines[end + 2:] if l.strip()])
    return labels, data


def decode(a):
    return [x.decode() if isinstance(x, bytes) else str(x) for x in a]


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("kinematics", help="arthrosim kinematics file (.h5)")
    ap.add_argument("--reference", default=REF, help="folder with walking_values.sto, walking_activation.sto")
    ap.add_argument("--plot", help="write a figure (PNG)")
    ap.add_argument("--json", help="write the figures as JSON")
    a = ap.parse_args()

    f = h5py.File(a.kinematics, "r")
    t = f["/time"][:]
    names = decode(f["/coordinates/names"][:])
    q = f["/coordinates/values"][:]
    act = f["/muscles/activation"][:]
    mnames = decode(f["/muscles/names"][:])
    status = f["/solver/status"][:]
    ipopt = f["/solver/ipopt_status"][:]
    wall = f["/solver/wall_time"][:]
    tf = f["/contact/tibiofemoral/force"][:]
    mass = float(f.attrs.get("body_mass_kg", BW_KG))

    vl, vd = read_sto(os.path.join(a.reference, "walking_values.sto"))
    al, ad = read_sto(os.path.join(a.reference, "walking_activation.sto"))
    # Common frames (times to 1e-6 s).
    ref_t = vd[:, 0]
    rows, refrows = [], []
    for i, ti in enumerate(t):
        j = np.where(np.abs(ref_t - ti) < 1e-6)[0]
        if len(j):
            rows.append(i)
            refrows.append(j[0])
    if not rows:
        sys.exit("no common frames with opensim-jam's results")
    rows, refrows = np.array(rows), np.array(refrows)
    out = {"frames": int(len(rows)), "time": [float(t[rows[0]]), float(t[rows[-1]])], "coordinates": {},
           "muscles": {}}

    def ours(name):
        v = q[rows, names.index(name)]
        return np.degrees(v) if name in ROTATIONS else v * 1e3

    def theirs(name):
        v = vd[refrows, vl.index(name)]
        return v if name in ROTATIONS else v * 1e3  # walking_values.sto: degrees, metres

    print(f"{len(rows)} common frames, {t[rows[0]]:.2f}-{t[rows[-1]]:.2f} s; {a.kinematics}")
    print("secondary coordinate   unit   RMS diff   arthrosim range        opensim-jam range     largest change between frames (ours / opensim-jam)")
    for n in SECONDARY:
        if n not in names:
            continue
        o, r = ours(n), theirs(n)
        rms = float(np.sqrt(np.mean((o - r) ** 2)))
        jump = float(np.max(np.abs(np.diff(o)))) if len(o) > 1 else 0.0
        jump_r = float(np.max(np.abs(np.diff(r)))) if len(r) > 1 else 0.0
        unit = "deg" if n in ROTATIONS else "mm"
        out["coordinates"][n] = {"unit": unit, "rms": rms, "ours": [float(o.min()), float(o.max())],
                                 "theirs": [float(r.min()), float(r.max())], "max_jump": jump,
                                 "max_jump_theirs": jump_r}
        print(f"{n:22s} {unit:4s} {rms:9.2f}   {o.min():7.2f} .. {o.max():7.2f}     {r.min():7.2f} .. {r.max():7.2f}"
              f"     {jump:6.2f} / {jump_r:6.2f}")
    # Activations.
    print("muscle        corr    mean ours  mean theirs")
    corrs = []
    for k, m in enumerate(mnames):
        lab = "/forceset/" + m
        if lab not in al:
            continue
        o = act[rows, k]
        r = ad[refrows, al.index(lab)]
        c = float(np.corrcoef(o, r)[0, 1]) if np.std(o) > 0 and np.std(r) > 0 else float("nan")
        corrs.append(c)
        out["muscles"][m] = {"corr": c, "mean_ours": float(o.mean()), "mean_theirs": float(r.mean())}
        print(f"{m:12s} {c:6.2f}   {o.mean():9.3f}  {r.mean():9.3f}")
    ks = [k for k, m in enumerate(mnames) if m in KNEE_MUSCLES and "/forceset/" + m in al]
    if ks:
        kc = [out["muscles"][mnames[k]]["corr"] for k in ks]
        kc = [c for c in kc if c == c]
        print(f"knee muscles: correlation median {np.median(kc):.2f}, lowest {min(kc):.2f}")
    # Tibiofemoral force in BW: magnitude on the tibia and its axial part
    # (-Y in the tibia frame, what opensim-jam's figure plots).
    F = np.linalg.norm(tf, axis=1) / (mass * G)
    Fa = -tf[:, 1] / (mass * G)
    out["tf_force_bw"] = {}
    for label, lo, hi in [("first peak", 1.25, 1.55), ("second peak", 1.55, 1.95)]:
        sel = np.where((t >= lo) & (t <= hi))[0]
        if len(sel):
            i = sel[np.argmax(F[sel])]
            j = sel[np.argmax(Fa[sel])]
            out["tf_force_bw"][label] = {"magnitude": [float(F[i]), float(t[i])], "axial": [float(Fa[j]), float(t[j])]}
            print(f"tibiofemoral force {label}: {F[i]:.2f} BW at {t[i]:.2f} s (axial {Fa[j]:.2f} BW at {t[j]:.2f} s; "
                  f"opensim-jam's figure without muscle weights: about "
                  f"{'3.3 BW at 1.28' if label == 'first peak' else '5.1 BW at 1.79'} s)")
    conv = int(np.sum(status == 0))
    succ = int(np.sum((status == 0) & (ipopt == 0)))
    out["solver"] = {"frames": int(len(t)), "converged": conv, "solve_succeeded": succ,
                     "acceptable": int(np.sum((status == 0) & (ipopt == 1))),
                     "median_s_per_frame": float(np.median(wall)), "worst_s_per_frame": float(np.max(wall))}
    print(f"solver: {conv}/{len(t)} converged ({succ} Solve_Succeeded, {conv - succ} acceptable); "
          f"wall time per frame median {np.median(wall):.3f} s, worst {np.max(wall):.3f} s")
    if a.json:
        with open(a.json, "w") as fj:
            json.dump(out, fj, indent=1)
    if a.plot:
        import matplotlib
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
        fig, axes = plt.subplots(5, 6, figsize=(22, 15))
        axes = axes.ravel()
        tt = t[rows]
        for k, n in enumerate(SECONDARY):
            ax = axes[k]
            ax.plot(tt, theirs(n), "k-", label="opensim-jam")
            ax.plot(tt, ours(n), "r-", label="arthrosim")
            ax.set_title(f"{n} [{'deg' if n in ROTATIONS else 'mm'}]")
        axes[0].legend()
        ax = axes[11]
        ax.plot(tt, Fa[rows], "r-")
        ax.set_title("tibiofemoral axial force [BW] (arthrosim)")
        shown = [m for m in PLOT_MUSCLES if m in mnames][:18]
        for k, m in enumerate(shown):
            ax = axes[12 + k]
            lab = "/forceset/" + m
            if lab in al:
                ax.plot(tt, ad[refrows, al.index(lab)], "k-")
            ax.plot(tt, act[rows, mnames.index(m)], "r-")
            ax.set_title(f"{m} activation")
            ax.set_ylim(0, 1)
        fig.tight_layout()
        fig.savefig(a.plot, dpi=80)
        print(f"figure: {a.plot}")


if __name__ == "__main__":
    main()
