#!/usr/bin/env python3
"""Branch jumps in a stage-1 kinematics file (docs/comak.md, "Step control").

COMAK solves each frame of a trial on its own; the problem has several local
optima (the knee's laxity, the faceted contact), so consecutive frames can
land on different branches: the secondary coordinates jump between frames
while the prescribed flexion moves by about 2.5 deg. This script reads a
kinematics file (docs/kinematics_file.md) and prints, per secondary
coordinate, the largest change between consecutive frames and where it
happens, the objective summed over the frames, how many frames needed more
than one Ipopt attempt, and the largest departure of the patellar flexion from
0.7 x the knee flexion (the patella follows the trochlea at roughly that
ratio; a departure of tens of degrees means the patella left its groove).

Sample runs (h5py: Debian python3-h5py, i.e. /usr/bin/python3):
  /usr/bin/python3 scripts/kinematics_branches.py out/demo/kinematics.h5
  /usr/bin/python3 scripts/kinematics_branches.py out/demo/kinematics.h5 --frames 60:72
"""
import argparse
import sys

try:
    import h5py
    import numpy as np
except ImportError as e:  # pragma: no cover - environment message
    sys.exit(f"kinematics_branches.py: needs numpy and h5py (Debian python3-h5py; run with /usr/bin/python3): {e}")


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("kinematics", help="stage-1 kinematics file (arthrosim-comak --out)")
    ap.add_argument("--frames", help="also print the coordinates of rows FIRST:LAST (file rows, inclusive)")
    a = ap.parse_args()
    try:
        f = h5py.File(a.kinematics, "r")
        names = [n.decode() if isinstance(n, bytes) else str(n) for n in f["/coordinates/names"][:]]
        q = f["/coordinates/values"][:]
        objective = f["/solver/objective"][:]
        attempts = f["/solver/attempts"][:]
        status = f["/solver/status"][:]
        index = f["/frame_index"][:]
    except (OSError, KeyError) as e:
        sys.exit(f"kinematics_branches.py: {a.kinematics}: not a kinematics file ({e})")
    if not np.all(np.isfinite(q)):
        bad = np.argwhere(~np.isfinite(q))[0]
        sys.exit(f"kinematics_branches.py: {a.kinematics}:/coordinates/values: non-finite value at frame row {bad[0]}, "
                 f"coordinate {names[bad[1]]}")
    revolute = ["flexion" in n or "rotation" in n or "tilt" in n or "adduction" in n for n in names]
    scale = np.array([180 / np.pi if r else 1e3 for r in revolute])  # deg, mm
    unit = ["deg" if r else "mm" for r in revolute]
    print(f"{a.kinematics}: {len(index)} frames ({index[0]}..{index[-1]}), {int(np.sum(status == 0))} converged, "
          f"objective sum {objective.sum():.4e} m^3, frames with 3 or more Ipopt solves (retries, re-solves): "
          f"{int(np.sum(attempts > 2))}")
    if len(index) > 1:
        d = np.abs(np.diff(q * scale, axis=0))
        print("largest change between consecutive frames:")
        for j, n in enumerate(names):
            k = int(d[:, j].argmax())
            print(f"  {n:16s} {d[k, j]:8.2f} {unit[j]:3s} between frames {index[k]} and {index[k + 1]}")
    if "knee_flexion" in names and "pf_flexion" in names:
        kf, pf = names.index("knee_flexion"), names.index("pf_flexion")
        dev = np.degrees(q[:, pf] - 0.7 * q[:, kf])
        k = int(np.abs(dev).argmax())
        print(f"largest |pf_flexion - 0.7 knee_flexion|: {abs(dev[k]):.1f} deg at frame {index[k]} "
              f"(knee {np.degrees(q[k, kf]):.1f} deg, patella {np.degrees(q[k, pf]):.1f} deg)")
    if a.frames:
        first, last = (int(x) for x in a.frames.split(":"))
        print("frame  " + " ".join(f"{n[:9]:>9s}" for n in names) + "  objective")
        for i in range(max(first, 0), min(last, len(index) - 1) + 1):
            print(f"{index[i]:5d}  " + " ".join(f"{v:9.3f}" for v in q[i] * scale) + f"  {objective[i]:.3e}")


if __name__ == "__main__":
    main()
