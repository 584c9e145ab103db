#!/usr/bin/env python3
"""Where stage 2's tibiofemoral force departs from stage 1's on one walk, frame
by frame: stage 1's elastic-foundation law (p = K d / (h_tibia + h_femur),
d the rigid overlap along the ray, docs/comak.md) re-evaluated at the stage-1
pose with each of stage 2's choices switched in one at a time, beside the
stage-2 runs given.

  S1      stage 1 as it is: rays from the prepared tibial TRIANGLE centres onto
          the femoral triangles, thickness per triangle = mean of its vertices
          (msk::use_prepared_surfaces); must reproduce the kinematics file's
          force (checks this script)
  S1q1    the same law sampled at the tibial QUAD nodes (stage 2's nodes, nodal
          area a quarter of each adjacent quad) with stage 1's tibial
          thickness map (linear from the triangle vertices), onto the femoral
          triangles (triangle-mean thickness): sampling alone
  S1q     as S1q1 with the tibial quad node's own cast thickness (stage 2's
          tibial map)
  S2map   as S1q, onto the femoral quad surface (each quad split 0-2) with the
          femoral quad nodes' thickness interpolated at the hit: stage 2's
          geometry and thickness map, one pass
  S2pass  as S2map, two passes (femoral nodes cast onto the tibial quad
          surfaces too), each with half weight: stage 2's contact sampling.
          This is what stage 2 gives for independent springs in series
          without penetration (no shell, no damping, no inertia), if its
          gap were stage 1's ray depth.
  S2cp    as S2map with stage 2's vertex-face gap: the depth normal to the
          hit face (closest point) and the force along that face's normal
  S2cp2   S2cp over both passes, half weight each: stage 2's contact law
          and sampling applied to the rigid overlap

Then, per run given (label=surface_gait.h5), stage 2's axial force at the
frame. Axial: compressive force on the tibia along tibia -Y [N].

Sample run (docs/contact.md, "Stage 2 against stage 1 on the real subject"):
  /usr/bin/python3 scripts/contact_decomposition.py out/kinematics.h5 out/prepared.h5 \\
      penalty=out/surface_gait.h5 aug=out_aug/surface_gait.h5 --times 1.21,1.23,1.26,1.28,1.29
"""
import argparse
import os

os.environ.setdefault("HDF5_USE_FILE_LOCKING", "FALSE")
import h5py  # noqa: E402
import numpy as np  # noqa: E402


def tri_normals(V, F):
    n = np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]])
    return n / np.linalg.norm(n, axis=1)[:, None]


def quads_to_tris(Q):
    return np.vstack([Q[:, [0, 1, 2]], Q[:, [0, 2, 3]]])


def nodal_areas(V, Q):
    qa = 0.5 * np.linalg.norm(np.cross(V[Q[:, 2]] - V[Q[:, 0]], V[Q[:, 3]] - V[Q[:, 1]]), axis=1)
    a = np.zeros(len(V))
    for c in range(4):
        np.add.at(a, Q[:, c], qa / 4)
    return a


def stage1_map_at_nodes(V, F, h, P):
    """Stage 1's thickness map (the triangle vertices' values, linear over each
    triangle: the triangle's mean is stage 1's per-triangle value) at points P
    lying on the triangles (the quad nodes: vertices, edge midpoints and
    centres of the triangles they were split from)."""
    c = V[F].mean(1)
    out = np.empty(len(P))
    for j, x in enumerate(P):
        for i in np.argsort(((c - x) ** 2).sum(1))[:6]:
            a, b, d = V[F[i]]
            T = np.column_stack([b - a, d - a])
            uv = np.linalg.lstsq(T, x - a, rcond=None)[0]
            w = np.array([1 - uv.sum(), uv[0], uv[1]])
            if w.min() > -1e-6:
                out[j] = w @ h[F[i]]
                break
        else:
            raise RuntimeError(f"node {j} lies on none of its nearest triangles")
    return out


class Target:
    """Triangle surface with a thickness per vertex (interpolated at a hit) or
    per triangle; first hit of a ray within dmax facing the caster."""

    def __init__(self, V, F, h_vertex=None, h_tri=None):
        self.V, self.F = V, F
        self.a0 = V[F[:, 0]]
        self.e1 = V[F[:, 1]] - self.a0
        self.e2 = V[F[:, 2]] - self.a0
        self.n = tri_normals(V, F)
        self.hv, self.ht = h_vertex, h_tri

    def hit(self, c, nrm, dmax=0.02):
        d = -nrm
        P = np.cross(d, self.e2)
        det = (self.e1 * P).sum(1)
        ok = np.abs(det) > 1e-18
        inv = np.where(ok, 1.0 / np.where(ok, det, 1.0), 0.0)
        T = c - self.a0
        u = (T * P).sum(1) * inv
        Q = np.cross(T, self.e1)
        v = (Q @ d) * inv
        dist = (self.e2 * Q).sum(1) * inv
        h = ok & (u >= 0) & (v >= 0) & (u + v <= 1) & (dist > 0) & (dist <= dmax)
        if not h.any():
            return None
        i = np.where(h)[0]
        j = i[np.argmin(dist[i])]
        if self.n[j] @ nrm >= 0:
            return None
        if self.ht is not None:
            hh = self.ht[j]
        else:
            f = self.F[j]
            hh = (1 - u[j] - v[j]) * self.hv[f[0]] + u[j] * self.hv[f[1]] + v[j] * self.hv[f[2]]
        return dist[j], hh, self.n[j]


def cast(points, normals, areas, h, target, K, R=np.eye(3), t=np.zeros(3), closest=False):
    """Sum of p A (direction . y) over the casting points (frame of the
    casting body; R, t map it into the target's frame), in the casting frame
    (sign handled by the caller). closest=False: stage 1's ray depth and the
    force along the caster's normal; closest=True: stage 2's vertex-face gap,
    the depth normal to the hit face (ray depth x |n . m|, exact when the
    closest point lies on the hit face) and the force along that face's
    normal (-m, expressed in the casting frame)."""
    s = 0.0
    for x, n, a, hh in zip(points, normals, areas, h):
        r = target.hit(R @ x + t, R @ n)
        if r is not None:
            if closest:
                m = R.T @ r[2]
                s += K * r[0] * abs(n @ m) / (hh + r[1]) * a * (-m[1])
            else:
                s += K * r[0] / (hh + r[1]) * a * n[1]
    return s


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("kinematics")
    ap.add_argument("prepared")
    ap.add_argument("runs", nargs="*", help="label=surface_gait.h5")
    ap.add_argument("--times", default="1.23,1.26,1.28,1.31")
    ap.add_argument("--modulus-mpa", type=float, default=10.0)
    ap.add_argument("--poisson", type=float, default=0.45)
    a = ap.parse_args()
    K = (1 - a.poisson) * a.modulus_mpa * 1e6 / ((1 + a.poisson) * (1 - 2 * a.poisson))
    k = h5py.File(a.kinematics, "r")
    p = h5py.File(a.prepared, "r")
    t1 = k["time"][:]
    XF, XT = k["bodies/femur/X_W"][:], k["bodies/tibia/X_W"][:]
    F1 = k["contact/tibiofemoral/force"][:]

    def surf(name):
        g = p["surfaces/" + name]
        return dict(tV=g["triangles/vertices"][:], tF=g["triangles/faces"][:], th=g["triangles/thickness"][:],
                    qV=g["quads/nodes"][:], qN=g["quads/normals"][:], qQ=g["quads/quads"][:],
                    qh=g["quads/thickness"][:])

    fem = surf("femur")
    tibs = [surf(n) for n in ("tibia_medial", "tibia_lateral")]
    for sd in tibs + [fem]:
        sd["qh1"] = stage1_map_at_nodes(sd["tV"], sd["tF"], sd["th"], sd["qV"])
    fem_tri = Target(fem["tV"], fem["tF"], h_tri=fem["th"][fem["tF"]].mean(1))
    fem_quad = Target(fem["qV"], quads_to_tris(fem["qQ"]), h_vertex=fem["qh"])
    tib_quad = [Target(s["qV"], quads_to_tris(s["qQ"]), h_vertex=s["qh"]) for s in tibs]
    runs = []
    for r in a.runs:
        lab, path = r.split("=", 1)
        s = h5py.File(path, "r")
        n = int(s["trial_time"].attrs.get("arthrosim_frames_complete", s["trial_time"].shape[0]))
        runs.append((lab, s["trial_time"][:n], s["contact/tibiofemoral/force"][:n]))
    hdr = f"{'time':>6} {'stage1':>7} {'S1':>7} {'S1q1':>7} {'S1q':>7} {'S2map':>7} {'S2pass':>7} {'S2cp':>7} {'S2cp2':>7}" + "".join(
        f" {lab:>10}" for lab, _, _ in runs)
    print(f"axial tibiofemoral force [N], K = {K / 1e6:.2f} MPa")
    print(hdr)
    for tq in [float(x) for x in a.times.split(",")]:
        i = int(np.argmin(np.abs(t1 - tq)))
        X = np.linalg.inv(XF[i]) @ XT[i]  # tibia -> femur frame
        R, t = X[:3, :3], X[:3, 3]
        Ri, ti = R.T, -R.T @ t  # femur -> tibia frame
        s1 = s1q = s1q1 = s2m = s2c = 0.0
        for s in tibs:
            V, F = s["tV"], s["tF"]
            c = V[F].mean(1)
            n = tri_normals(V, F)
            A = 0.5 * np.linalg.norm(np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]]), axis=1)
            s1 += cast(c, n, A, s["th"][F].mean(1), fem_tri, K, R, t)
            qa = nodal_areas(s["qV"], s["qQ"])
            s1q += cast(s["qV"], s["qN"], qa, s["qh"], fem_tri, K, R, t)
            s1q1 += cast(s["qV"], s["qN"], qa, s["qh1"], fem_tri, K, R, t)
            s2m += cast(s["qV"], s["qN"], qa, s["qh"], fem_quad, K, R, t)
            s2c += cast(s["qV"], s["qN"], qa, s["qh"], fem_quad, K, R, t, closest=True)
        # Femoral nodes onto the tibial quad surfaces (tibia frame); the force
        # on the tibia is the opposite of the femoral node's, so its axial
        # compression is +(force on the femoral node) . y_tibia.
        fa = nodal_areas(fem["qV"], fem["qQ"])
        Pf = fem["qV"] @ Ri.T + ti
        Nf = fem["qN"] @ Ri.T
        near = np.zeros(len(Pf), bool)
        for s in tibs:
            lo, hi = s["qV"].min(0) - 0.005, s["qV"].max(0) + 0.005
            near |= np.all((Pf > lo) & (Pf < hi), axis=1)
        s2f = s2fc = 0.0
        for j in np.where(near)[0]:
            best = None
            for tg in tib_quad:
                r = tg.hit(Pf[j], Nf[j])
                if r is not None and (best is None or r[0] < best[0]):
                    best = r
            if best is not None:
                p_ = K * best[0] / (fem["qh"][j] + best[1]) * fa[j]
                s2f += -p_ * Nf[j][1]  # ray: force on the femoral node along its normal
                s2fc += p_ * abs(Nf[j] @ best[2]) * best[2][1]  # closest: along the tibial face normal m
        s2p = 0.5 * (s2m + s2f)
        s2pc = 0.5 * (s2c + s2fc)
        row = (f"{t1[i]:6.2f} {-F1[i, 1]:7.0f} {s1:7.0f} {s1q1:7.0f} {s1q:7.0f} {s2m:7.0f} {s2p:7.0f} {s2c:7.0f} "
               f"{s2pc:7.0f}")
        for lab, tt, Fs in runs:
            j = int(np.argmin(np.abs(tt - t1[i])))
            row += f" {-Fs[j, 1]:10.0f}" if abs(tt[j] - t1[i]) < 1e-6 else f" {'-':>10}"
        print(row)


if __name__ == "__main__":
    main()
