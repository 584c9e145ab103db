#!/usr/bin/env python3
"""Torsional laxity of a knee model under compression, measured with COMAK.

A diagnostic of the musculoskeletal model (docs/comak.md, "Rotational
laxity"): the knee is held at one flexion angle, a compressive force along the
tibial axis is applied, and an axial moment on the tibia is swept from -M to
+M. Each frame is one COMAK solve (muscles, ligaments, contact; flexion
prescribed), so the secondary coordinates settle wherever the passive
structures and the muscles balance the moment. The script prints the axial
rotation (knee_rotation; + = internal tibial rotation for the right knee)
against the moment and the torsional stiffness at zero moment.

The trial is written to a scratch folder with the loads given directly
(knee_loads_file, docs/trials.md): force and moment ON the tibia, tibia frame
(X anterior, Y proximal, Z lateral), about the knee centre. Compression is the
ground pushing the tibia proximally (+Y).

Joint load is known to reduce the rotational laxity of real knees
substantially (Markolf, Bargar, Shoemaker & Amstutz 1981, J Bone Joint Surg Am
63:570); compare with laxity data of your own choice before calibrating.

Sample runs (a few seconds each; h5py: Debian python3-h5py, i.e. /usr/bin/python3):
  python3 scripts/knee_laxity.py --model data/models/knee_parametric/knee_coarse.urdf
  python3 scripts/knee_laxity.py --model data/models/knee_parametric/knee.urdf \\
      --flexion-deg 20 --compression-bw 2 --moment-nm 10 --frames 11
  python3 scripts/knee_laxity.py --model data/models/knee_parametric/knee_coarse.urdf \\
      --scale-stiffness all=3          # every ligament group 3x stiffer
"""
import argparse
import os
import shutil
import subprocess
import sys
import tempfile

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)


def write_mot(path, name, columns, rows, in_degrees):
    with open(path, "w") as f:
        f.write(f"{name}\nversion=1\nnRows={len(rows)}\nnColumns={len(columns)}\n")
        f.write(f"inDegrees={'yes' if in_degrees else 'no'}\n")
        f.write("Written by scripts/knee_laxity.py (a laxity probe, not measured data).\nendheader\n")
        f.write("\t".join(columns) + "\n")
        for r in rows:
            f.write("\t".join(f"{v:.10g}" for v in r) + "\n")


def scaled_model(urdf, specs, work):
    """A copy of the URDF in `work` with scaled ligament stiffness; the model
    folder's other entries are linked next to it so relative mesh paths hold."""
    import re
    factors = {}
    for spec in specs:
        name, _, f = spec.partition("=")
        try:
            factors[name] = float(f)
        except ValueError:
            sys.exit(f"--scale-stiffness: expected GROUP=FACTOR, found '{spec}'")
    if os.path.isdir(urdf):
        sys.exit("--scale-stiffness needs the model's URDF file, not its folder")
    src_dir = os.path.dirname(os.path.abspath(urdf))
    for entry in os.listdir(src_dir):
        dst = os.path.join(work, entry)
        if not os.path.exists(dst):
            os.symlink(os.path.join(src_dir, entry), dst)
    text = open(urdf).read()
    seen = set()

    def rep(m):
        name = m.group(1)
        f = factors.get(name, factors.get("all"))
        if f is None:
            return m.group(0)
        seen.add(name)
        return f'<arthrosim:ligament name="{name}" stiffness="{float(m.group(2)) * f:g}"'
    text = re.sub(r'<arthrosim:ligament name="([^"]+)" stiffness="([^"]+)"', rep, text)
    missing = [n for n in factors if n != "all" and n not in seen]
    if missing:
        sys.exit(f"--scale-stiffness: no ligament group named {', '.join(missing)} in {urdf}")
    out = os.path.join(work, "scaled_" + os.path.basename(urdf))
    with open(out, "w") as f:
        f.write(text)
    return out


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--model", required=True, help="model URDF or folder")
    ap.add_argument("--flexion-deg", type=float, default=20.0)
    ap.add_argument("--compression-bw", type=float, default=1.0, help="axial compressive force [body weights]")
    ap.add_argument("--moment-nm", type=float, default=10.0, help="sweep the axial moment over [-M, M] [N m]")
    ap.add_argument("--frames", type=int, default=11, help="moments in the sweep (odd: includes 0)")
    ap.add_argument("--mass-kg", type=float, default=61.0)
    ap.add_argument("--comak", default=os.path.join(ROOT, "build", "bin", "arthrosim-comak"))
    ap.add_argument("--keep", help="keep the trial and the kinematics file in this folder")
    ap.add_argument("--scale-stiffness", action="append", default=[], metavar="GROUP=FACTOR",
                    help="multiply a ligament group's stiffness (URDF copy in the scratch folder; "
                         "GROUP 'all' for every group), repeatable")
    a = ap.parse_args()
    if a.frames < 2:
        sys.exit("--frames must be >= 2")
    work = a.keep or tempfile.mkdtemp(prefix="arthrosim_laxity_")
    os.makedirs(work, exist_ok=True)
    n = a.frames
    dt = 0.01
    times = [i * dt for i in range(n)]
    moments = [-a.moment_nm + 2 * a.moment_nm * i / (n - 1) for i in range(n)]
    force_y = a.compression_bw * a.mass_kg * 9.81
    write_mot(os.path.join(work, "ik.mot"), "laxity kinematics",
              ["time", "hip_flexion", "hip_adduction", "hip_rotation", "knee_angle", "ankle_angle"],
              [[t, a.flexion_deg, 0.0, 0.0, a.flexion_deg, 0.0] for t in times], True)
    write_mot(os.path.join(work, "knee_loads.mot"), "laxity knee loads",
              ["time", "fx", "fy", "fz", "mx", "my", "mz"],
              [[t, 0.0, force_y, 0.0, 0.0, m, 0.0] for t, m in zip(times, moments)], False)
    with open(os.path.join(work, "trial.yaml"), "w") as f:
        f.write("# Laxity probe written by scripts/knee_laxity.py (not measured data).\n")
        f.write(f"description: axial moment sweep at {a.flexion_deg} deg flexion\n")
        f.write(f"subject_mass_kg: {a.mass_kg}\nsubject_height_m: 1.65\nside: right\n")
        f.write("lab_frame: opensim_x_forward_y_up_z_right\n")
        f.write("kinematics_file: ik.mot\nknee_loads_file: knee_loads.mot\n")
        for q, c in [("hip_flexion", "hip_flexion"), ("hip_adduction", "hip_adduction"),
                     ("hip_rotation", "hip_rotation"), ("knee_flexion", "knee_angle"),
                     ("ankle_flexion", "ankle_angle"), ("knee_force_x", "fx"), ("knee_force_y", "fy"),
                     ("knee_force_z", "fz"), ("knee_moment_x", "mx"), ("knee_moment_y", "my"),
                     ("knee_moment_z", "mz")]:
            f.write(f"column.{q}: {c}\n")
    model = a.model
    if a.scale_stiffness:
        model = scaled_model(a.model, a.scale_stiffness, work)
    out = os.path.join(work, "laxity.h5")
    cmd = [a.comak, "--model", model, "--trial", work, "--out", out, "--no-pressure", "-q"]
    r = subprocess.run(cmd)
    if r.returncode not in (0, 2):  # 2: some frames failed (reported below)
        sys.exit(f"arthrosim-comak failed with exit code {r.returncode}: {' '.join(cmd)}")
    os.environ.setdefault("HDF5_USE_FILE_LOCKING", "FALSE")
    import h5py  # noqa: E402 (only needed here)
    import math
    with h5py.File(out, "r") as f:
        names = [s.decode() for s in f["coordinates/names"][:]]
        q = f["coordinates/values"][:]
        status = f["solver/status"][:]
        lig_force = f["ligaments/force"][:].sum(axis=1)
    rot = [math.degrees(v) for v in q[:, names.index("knee_rotation")]]
    add = [math.degrees(v) for v in q[:, names.index("knee_adduction")]]
    scaled = f" (ligament stiffness scaled: {', '.join(a.scale_stiffness)})" if a.scale_stiffness else ""
    print(f"model {a.model}{scaled}: flexion {a.flexion_deg} deg, compression {a.compression_bw} BW ({force_y:.0f} N)")
    # knee_ty: tibia along its long axis relative to the femur (smaller = condyles seated deeper);
    # ligament force: sum over every bundle (patellar tendon included).
    ty = [1000.0 * v for v in q[:, names.index("knee_ty")]]
    print(" moment_Nm  rotation_deg  adduction_deg  knee_ty_mm  ligament_force_N  status")
    for m, r_, d, y, lf, s in zip(moments, rot, add, ty, lig_force, status):
        print(f" {m:9.2f}  {r_:12.2f}  {d:13.2f}  {y:10.2f}  {lf:16.0f}  {'ok' if s == 0 else 'FAILED'}")
    mid = n // 2
    i0, i1 = (mid - 1, mid + 1) if n % 2 == 1 else (mid - 1, mid)
    k = (moments[i1] - moments[i0]) / math.radians(rot[i1] - rot[i0]) if rot[i1] != rot[i0] else float("inf")
    print(f"torsional stiffness about zero moment: {k:.1f} N m/rad ({k * math.pi / 180:.2f} N m/deg)")
    print(f"total rotation over +-{a.moment_nm} N m: {rot[-1] - rot[0]:.1f} deg")
    if not a.keep:
        shutil.rmtree(work)


if __name__ == "__main__":
    main()
