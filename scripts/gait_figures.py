#!/usr/bin/env python3
"""Issue-6 figures of a walking surface run against its stage-1 kinematics.

Reads the kinematics file of arthrosim-comak (stage 1) and the output of
arthrosim-surface for a walking scenario (stage 2, docs/surface_output.md) and
prints, over the frames both cover (stage 2 on the stage-1 clock, /trial_time):

- the tibiofemoral contact force of both stages (force on the tibia, tibia
  frame; the axial component is tibia +Y, "Fz" in the seed's wording), the
  time-averaged RMS difference of the axial (compressive) force relative to the mean of
  stage 1, and the first/second peaks of each;
- the medial share of the axial force at stage 2's first peak;
- the largest femoral cartilage deflection and its time, and the extremes of
  the first and second principal strains over the femoral surface;
- the solver's per-step record: steps, Newton iterations, rejections, wall
  time, the worst penetration/deflection ratio (also over unfaded contacts only).

A run still being written can be read: only complete frames are used
(attribute arthrosim_frames_complete). Needs h5py and numpy (Debian:
python3-h5py, python3-numpy, i.e. /usr/bin/python3).

Sample runs:
  /usr/bin/python3 scripts/gait_figures.py out/gait/kinematics.h5 out/gait/surface_gait.h5
  /usr/bin/python3 scripts/gait_figures.py out/gait/kinematics.h5 out/gait/surface_gait.h5 \\
      --prepared out/gait/prepared.h5     # plus the rigid overlaps at the stage-1 poses
"""
import argparse
import os
import sys

os.environ.setdefault("HDF5_USE_FILE_LOCKING", "FALSE")
import h5py  # noqa: E402
import numpy as np  # noqa: E402


def complete(ds):
    n = int(ds.attrs.get("arthrosim_frames_complete", ds.shape[0]))
    return ds[:n]


def peaks(t, f, split, t0=0.0):
    """Largest value before and after time `split` (the stance trough), both
    times from the cycle's start t0 (the first stage-1 frame)."""
    a = np.where(t - t0 < split)[0]
    b = np.where((t - t0 >= split) & (t - t0 < 0.7))[0]
    out = []
    for idx in (a, b):
        if idx.size == 0:
            out.append((float("nan"), float("nan")))
        else:
            k = idx[np.argmax(f[idx])]
            out.append((float(f[k]), float(t[k])))
    return out


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("kinematics", help="stage-1 kinematics file (arthrosim-comak)")
    ap.add_argument("surface", help="stage-2 output of a walking scenario (arthrosim-surface)")
    ap.add_argument("--trough-s", type=float, default=0.3,
                    help="time separating the two stance peaks, from the first stage-1 frame [s]")
    ap.add_argument("--prepared", help="prepared model (arthrosim-prepare): also print the rigid overlap of the "
                    "tibial and femoral shell surfaces at the stage-1 poses, at rim and interior nodes, "
                    "stage 2's tibial contact pressure x nodal area (all, rim nodes, nodes above 30 MPa), and each "
                    "surface's contact and foundation force against stage 1's law at the shell nodes")
    ap.add_argument("--overlap-times", default="0,0.05,0.1,0.2,0.35,0.45,0.6",
                    help="trial times [s] for --prepared, comma separated")
    ap.add_argument("--matched-modulus-mpa", type=float, default=10.0,
                    help="E of the stage-1-matched foundation k_i = K / h_i (scene key matched_youngs_modulus_mpa)")
    ap.add_argument("--matched-poisson", type=float, default=0.45,
                    help="nu of the matched foundation (scene key matched_poisson_ratio)")
    a = ap.parse_args()
    k = h5py.File(a.kinematics, "r")
    s = h5py.File(a.surface, "r")
    if "/contact/tibiofemoral/force" not in s or "/trial_time" not in s:
        sys.exit(f"{a.surface}: no /contact/tibiofemoral/force or /trial_time (not a walking run with mesh_contact)")
    mass = float(k.attrs.get("body_mass_kg", float("nan")))
    bw = mass * 9.81
    t1 = k["time"][:]
    F1 = k["contact/tibiofemoral/force"][:]
    M1 = k["contact/tibiofemoral/medial_force"][:]
    tt = complete(s["trial_time"])
    F2 = complete(s["contact/tibiofemoral/force"])[: len(tt)]
    M2 = complete(s["contact/tibiofemoral/medial_force"])[: len(tt)]
    L2 = complete(s["contact/tibiofemoral/lateral_force"])[: len(tt)]
    n = min(len(tt), len(F2))
    keep = np.where((tt[:n] >= t1[0] - 1e-12) & (tt[:n] <= t1[-1] + 1e-12))[0]
    tt, F2, M2, L2 = tt[keep], F2[keep], M2[keep], L2[keep]
    # Stage 1 on stage 2's frame times (linear interpolation per component).
    F1i = np.stack([np.interp(tt, t1, F1[:, c]) for c in range(3)], axis=1)
    # Compression positive: the force on the tibia points distally (-Y).
    ax1, ax2 = -F1i[:, 1], -F2[:, 1]
    rms = float(np.sqrt(np.mean((ax2 - ax1) ** 2)))
    mean1 = float(np.mean(ax1))
    print(f"frames compared: {len(tt)} (trial time {tt[0]:.3f} .. {tt[-1]:.3f} s); body weight {bw:.1f} N")
    print(f"axial (compressive, -Y on the tibia) tibiofemoral force: stage 1 mean {mean1:.1f} N, stage 2 mean {np.mean(ax2):.1f} N")
    print(f"RMS difference {rms:.1f} N = {100 * rms / abs(mean1):.1f} % of the stage-1 mean")
    # The difference by phase of the cycle: an offset (the same N in every
    # phase) and an error proportional to the load look different here.
    ss = float(np.sum((ax2 - ax1) ** 2))
    for lo, hi, phase in ((0.0, 0.1, "loading"), (0.1, 0.25, "first peak"), (0.25, 0.45, "mid stance"),
                          (0.45, 0.65, "second peak, push-off"), (0.65, np.inf, "swing")):
        w = (tt - t1[0] >= lo) & (tt - t1[0] < hi)
        if not w.any():
            continue
        d = ax2[w] - ax1[w]
        print(f"  {phase:22s} {t1[0] + lo:.2f}-{min(t1[0] + hi, tt[-1]):.2f} s: stage 1 mean {np.mean(ax1[w]):7.1f} N, "
              f"stage 2 - stage 1 mean {np.mean(d):+7.1f} N, RMS {np.sqrt(np.mean(d ** 2)):6.1f} N "
              f"({100 * np.sum(d ** 2) / ss:4.1f} % of the squared difference)")
    for name, f in (("stage 1", ax1), ("stage 2", ax2)):
        (p1, tp1), (p2, tp2) = peaks(tt, f, a.trough_s, t1[0])
        print(f"{name}: first peak {p1:.0f} N = {p1 / bw:.2f} BW at {tp1:.2f} s, "
              f"second peak {p2:.0f} N = {p2 / bw:.2f} BW at {tp2:.2f} s")
    (p1, tp1), _ = peaks(tt, ax2, a.trough_s, t1[0])
    i1 = int(np.argmin(np.abs(tt - tp1)))
    share = -M2[i1, 1] / ax2[i1] if ax2[i1] != 0 else float("nan")
    print(f"stage 2 medial share of the axial force at its first peak: {100 * share:.0f} % "
          f"(medial {-M2[i1, 1]:.0f} N, lateral {-L2[i1, 1]:.0f} N)")
    frames = keep[keep < complete(s["time"]).shape[0]]
    D = s["surfaces/femur/deflection"]
    e1 = s["surfaces/femur/strain/e1"]
    e2 = s["surfaces/femur/strain/e2"]
    dmax, dt_, e1max, e1t, e2min, e2t = 0.0, 0.0, -np.inf, 0.0, np.inf, 0.0
    tr = complete(s["trial_time"])
    for f in frames:
        d = np.abs(D[f])
        if d.max() > dmax:
            dmax, dt_ = float(d.max()), float(tr[f])
        a1, a2 = e1[f], e2[f]
        if a1.max() > e1max:
            e1max, e1t = float(a1.max()), float(tr[f])
        if a2.min() < e2min:
            e2min, e2t = float(a2.min()), float(tr[f])
    print(f"femoral cartilage: max |deflection| {1e3 * dmax:.2f} mm at {dt_:.2f} s; "
          f"e1 max {100 * e1max:.2f} % at {e1t:.2f} s; e2 min {100 * e2min:.2f} % at {e2t:.2f} s")
    # The seed's figures are those of the first peak of the axial force
    # (femoral deflection 1.1 mm, principal strains about 3 % / -1 %).
    fp = int(np.argmin(np.abs(tr[: D.shape[0]] - tp1)))
    print(f"femoral cartilage at stage 2's first peak ({tr[fp]:.2f} s): max |deflection| "
          f"{1e3 * np.abs(D[fp]).max():.2f} mm, e1 max {100 * e1[fp].max():.2f} %, e2 min {100 * e2[fp].min():.2f} % "
          f"(seed: about 1.1 mm, 3 %, -1 %)")
    st = s["solver"]
    its = complete(st["newton_iterations"])
    wall = complete(st["wall_s"])
    rej = complete(st["rejections"])
    ratio = complete(st["penetration_ratio"]) if "penetration_ratio" in st else np.zeros(0)
    active = complete(st["active_contacts"]) if "active_contacts" in st else np.zeros(0)
    print(f"solver: {len(its)} steps to t = {complete(st['time'])[-1]:.3f} s, Newton iterations "
          f"{its.sum()} (median {np.median(its):.0f} per step), {rej.sum()} rejected attempts, "
          f"wall {wall.sum():.0f} s (median {np.median(wall):.2f} s per step)")
    if ratio.size:
        print(f"penetration/deflection: median {np.median(ratio):.3f}, max {ratio.max():.3f}; "
              f"steps over 0.1: {(ratio > 0.1).sum()}; active contacts per step: median {np.median(active):.0f}")
        if active.size == ratio.size:
            inc = active > 0
            met = int(((ratio <= 0.1) & inc).sum())
            print(f"accuracy rule (penetration <= 0.1 x deflection) met in {met} of {int(inc.sum())} steps in contact "
                  f"({100 * met / max(1, int(inc.sum())):.0f} %)")
    if "unfaded_penetration_ratio" in st:
        ri = complete(st["unfaded_penetration_ratio"])
        print(f"  unfaded contacts only (away from rims): median {np.median(ri):.3f}, max {ri.max():.3f}; "
              f"steps over 0.1: {(ri > 0.1).sum()}")
    for key in ("assembly_s", "contact_s", "factorization_s", "solve_s"):
        if key in st.attrs:
            print(f"  {key}: {float(st.attrs[key]):.1f}")
    print(f"run status: {s.attrs.get('status', '?')}")
    if a.prepared:
        times = [float(x) for x in a.overlap_times.split(",")]
        rigid_overlap(k, a.prepared, times)
        rim_share(s, a.prepared, times)
        foundation_balance(k, s, a.prepared, times, a.matched_modulus_mpa, a.matched_poisson)


def rigid_overlap(k, prepared, times):
    """Overlap of each tibial node with the femoral surface (signed distance
    to the nearest femoral node along that node's normal, positive inside),
    with both bones rigid at the stage-1 pose: what the shells must absorb by
    deflection and penetration. Prepared nodes are in the bone frames."""
    p = h5py.File(prepared, "r")
    Vf = p["surfaces/femur/quads/nodes"][:]
    Nf = p["surfaces/femur/quads/normals"][:]
    t1 = k["time"][:]
    XF, XT = k["bodies/femur/X_W"][:], k["bodies/tibia/X_W"][:]
    for tib in ("tibia_medial", "tibia_lateral"):
        g = "surfaces/" + tib + "/quads/"
        if g + "nodes" not in p:
            continue
        Vt = p[g + "nodes"][:]
        rim = np.zeros(len(Vt), bool)
        rim[p[g + "periphery"][:]] = True
        for t in times:
            i = int(np.argmin(np.abs(t1 - t)))
            A = np.linalg.inv(XF[i]) @ XT[i]  # tibia frame -> femur frame
            q = Vt @ A[:3, :3].T + A[:3, 3]
            j = np.array([np.argmin(((Vf - x) ** 2).sum(1)) for x in q])
            ov = -((q - Vf[j]) * Nf[j]).sum(1)
            print(f"rigid overlap {tib} at {t1[i]:.2f} s: rim max {1e3 * ov[rim].max():.2f} mm, "
                  f"interior max {1e3 * ov[~rim].max():.2f} mm")


def nodal_areas(V, Q):
    """A quarter of each adjacent quad's area per node (quad area from its
    diagonals)."""
    qa = 0.5 * np.linalg.norm(np.cross(V[Q[:, 2]] - V[Q[:, 0]], V[Q[:, 3]] - V[Q[:, 1]]), axis=1)
    area = np.zeros(len(V))
    for c in range(4):
        np.add.at(area, Q[:, c], qa / 4)
    return area


def rim_share(s, prepared, times):
    """Stage 2's tibial contact pressure times nodal area (a quarter of each
    adjacent quad), summed over all nodes, over the rim (periphery) nodes, and
    over nodes above 30 MPa: stage 1 samples triangle centres and never a rim,
    so force at rim nodes is force stage 1 does not have."""
    p = h5py.File(prepared, "r")
    tt = complete(s["trial_time"])
    for t in times:
        j = int(np.argmin(np.abs(tt - t)))
        tot = rim_f = high = 0.0
        for tib in ("tibia_medial", "tibia_lateral"):
            g = "surfaces/" + tib + "/quads/"
            if g + "nodes" not in p or "surfaces/" + tib + "/contact_pressure" not in s:
                continue
            V, Q = p[g + "nodes"][:], p[g + "quads"][:]
            rim = p[g + "on_periphery"][:].astype(bool)
            area = nodal_areas(V, Q)
            f = s["surfaces/" + tib + "/contact_pressure"][j] * area
            pr = s["surfaces/" + tib + "/contact_pressure"][j]
            tot, rim_f, high = tot + f.sum(), rim_f + f[rim].sum(), high + f[pr > 30e6].sum()
        print(f"stage 2 tibial pressure x area at {tt[j]:.2f} s: {tot:.1f} N, on rim nodes {rim_f:.1f} N, "
              f"on nodes above 30 MPa {high:.1f} N")


def foundation_balance(k, s, prepared, times, E_mpa, nu):
    """Where stage 2's contact force goes, per surface: contact pressure x
    nodal area against the compressive foundation springs' force
    K / h_i x compression x nodal area (the stage-1-matched foundation,
    foundation_from_thickness; their difference is what the shell carries
    itself), the largest lift of a node off its foundation, and on the tibial
    surfaces stage 1's elastic-foundation law K d / (h_tibia + h_femur)
    evaluated at the shell nodes (d: the rigid overlap along the node's
    normal at the stage-1 pose), summed over nodal areas and projected on the
    tibial axis: equal to stage 1's force up to quadrature, so a difference
    between the stages is not the shells' sampling of the same overlap."""
    p = h5py.File(prepared, "r")
    K = (1 - nu) * E_mpa * 1e6 / ((1 + nu) * (1 - 2 * nu))
    tt = complete(s["trial_time"])
    t1 = k["time"][:]
    XF, XT = k["bodies/femur/X_W"][:], k["bodies/tibia/X_W"][:]
    fV = p["surfaces/femur/triangles/vertices"][:]
    fF = p["surfaces/femur/triangles/faces"][:]
    fh = p["surfaces/femur/triangles/thickness"][:][fF].mean(1)  # per triangle, as stage 1
    a0, e1, e2 = fV[fF[:, 0]], fV[fF[:, 1]] - fV[fF[:, 0]], fV[fF[:, 2]] - fV[fF[:, 0]]
    fn = np.cross(e1, e2)
    fn /= np.linalg.norm(fn, axis=1)[:, None]

    def overlap(c, nrm):
        """First femoral triangle hit by the ray from c along -nrm within 20 mm
        (Moller-Trumbore against every triangle); (depth, triangle) or None."""
        d = -nrm
        P = np.cross(d, e2)
        det = (e1 * P).sum(1)
        ok = np.abs(det) > 1e-18
        inv = np.where(ok, 1.0 / np.where(ok, det, 1.0), 0.0)
        T = c - a0
        u = (T * P).sum(1) * inv
        Q = np.cross(T, e1)
        v = (Q @ d) * inv
        dist = (e2 * Q).sum(1) * inv
        hit = ok & (u >= 0) & (v >= 0) & (u + v <= 1) & (dist > 0) & (dist <= 0.02)
        if not hit.any():
            return None
        i = np.where(hit)[0]
        j = i[np.argmin(dist[i])]
        return (dist[j], j) if fn[j] @ nrm < 0 else None

    for t in times:
        j = int(np.argmin(np.abs(tt - t)))
        i1 = int(np.argmin(np.abs(t1 - tt[j])))
        X = np.linalg.inv(XF[i1]) @ XT[i1]  # tibia frame -> femur frame
        parts, ef_axial, ef_rim = [], 0.0, 0.0
        for surf in ("femur", "tibia_medial", "tibia_lateral"):
            g = "surfaces/" + surf + "/quads/"
            if g + "nodes" not in p or "surfaces/" + surf + "/deflection" not in s:
                continue
            V, Q = p[g + "nodes"][:], p[g + "quads"][:]
            h = p[g + "thickness"][:]
            rim = p[g + "on_periphery"][:].astype(bool)
            area = nodal_areas(V, Q)
            defl = s["surfaces/" + surf + "/deflection"][j]
            ff = K / h * np.maximum(0.0, -defl) * area
            pc = s["surfaces/" + surf + "/contact_pressure"][j] * area if "surfaces/" + surf + "/contact_pressure" in s \
                else np.zeros(len(V))
            parts.append(f"{surf}: contact {pc.sum():.0f} N, foundation {ff.sum():.0f} N "
                         f"(rim {ff[rim].sum():.0f}), largest lift off the foundation {1e3 * max(0.0, defl.max()):.2f} mm")
            if surf.startswith("tibia"):
                Nn = p[g + "normals"][:]
                for x, nrm, a_, hh, on_rim in zip(V, Nn, area, h, rim):
                    nw = X[:3, :3] @ nrm
                    r = overlap(X[:3, :3] @ x + X[:3, 3], nw)
                    if r is not None:
                        f = K * r[0] / (hh + fh[r[1]]) * a_ * (nw @ X[:3, 1])
                        ef_axial += f
                        ef_rim += f if on_rim else 0.0
        print(f"force balance at {tt[j]:.2f} s: " + "; ".join(parts))
        print(f"  stage 1's law at the tibial shell nodes (rigid overlap): axial {ef_axial:.0f} N "
              f"(rim nodes {ef_rim:.0f} N); "
              f"stage 1 {-k['contact/tibiofemoral/force'][i1, 1]:.0f} N, stage 2 "
              f"{-s['contact/tibiofemoral/force'][j, 1]:.0f} N")

if __name__ == "__main__":
    main()
