#!/usr/bin/python3
"""The real subject's gait walk at several shell resolutions (stage 2 against
stage 1: docs/surface_output.md, "The real subject", resolution series).

For each variant, writes a copy of data/scenes/lenhart2015_gait.yaml with only
the gait scenario and the variant's per-surface edge lengths (prepare's
`surface_edge_length_mm`, a list the runner's --set cannot change), runs it
with `arthrosim run` (prepare, COMAK, surface.gait) and prints
scripts/gait_figures.py's comparison with stage 1, the wall time, and per shell surface the number of quads and the
shells' bending length against their size: lambda h, with lambda =
(k / 4D)^(1/4) the foundation's bending wavenumber (k = K / h_cartilage,
K from the run's matched modulus and Poisson ratio, 37.93 MPa from 10 MPa /
0.45; D = E t^3 / (12 (1 - nu^2)) of the run's shell, the seed's 1 mm, 400 MPa) and h the square root of a quad's
area (ShellVerification.StiffFoundationSpreadingNeedsTheBendingLengthResolved:
a line load spreads 18 % too wide at lambda h = 1.2, 4.9 % at 0.6).

  nice /usr/bin/python3 scripts/lenhart2015_resolution.py OUTDIR [--window] [--bin build/bin]
      [--variants seed,tibia15,both]

  seed     femur 4 mm (3,588 shells, the seed's count), tibial plateaus 3 mm (the scene)
  tibia2   femur 4 mm, tibial plateaus 2 mm
  tibia15  femur 4 mm, tibial plateaus 1.5 mm
  both     femur 2 mm (14,421 shells), tibial plateaus 1.5 mm

--window runs 1.21-1.33 s (the gait scenario to 0.11 s: 12 frames in contact)
instead of the whole walk (1.21-2.32 s). Whole walk, one variant at a time on
the 2-core machine: about 6, 15 and 24 min.
"""
import argparse
import os
import subprocess
import sys
import time

import h5py
import numpy as np
import yaml

VARIANTS = {
    "seed": ["femur=4"],
    "tibia2": ["femur=4", "tibia_medial=2", "tibia_lateral=2"],
    "tibia15": ["femur=4", "tibia_medial=1.5", "tibia_lateral=1.5"],
    "both": ["femur=2", "tibia_medial=1.5", "tibia_lateral=1.5"],
}


def bending_length_table(prepared, surface):
    # The shell and matched-foundation options as the surface stage resolved
    # them (its /options attribute: "surface.gait.<key> = <value>" lines).
    with h5py.File(surface, "r") as f:
        opts = dict(line.split(" = ", 1) for line in f.attrs["options"].splitlines() if " = " in line)
    o = lambda key: float(opts["surface.gait." + key])
    E, t, nu = o("youngs_modulus_mpa") * 1e6, o("shell_thickness_mm") * 1e-3, o("poisson_ratio")
    Em, num = o("matched_youngs_modulus_mpa") * 1e6, o("matched_poisson_ratio")
    K = (1 - num) * Em / ((1 + num) * (1 - 2 * num))
    D = E * t ** 3 / (12 * (1 - nu ** 2))
    with h5py.File(prepared, "r") as f:
        for s in ("femur", "tibia_medial", "tibia_lateral"):
            g = f["surfaces/%s/quads" % s]
            V, Q, h = g["nodes"][:], g["quads"][:], g["thickness"][:]
            area = 0.5 * np.linalg.norm(np.cross(V[Q[:, 2]] - V[Q[:, 0]], V[Q[:, 3]] - V[Q[:, 1]]), axis=1)
            lam = (K / h[Q].mean(axis=1) / (4 * D)) ** 0.25
            lh = lam * np.sqrt(area)
            print("  %-14s %6d quads, sqrt(area) mean %.2f mm, lambda h median %.2f, 90th percentile %.2f"
                  % (s, len(Q), np.sqrt(area).mean() * 1e3, np.median(lh), np.percentile(lh, 90)))


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("out")
    ap.add_argument("--window", action="store_true", help="1.21-1.33 s only")
    ap.add_argument("--bin", default="build/bin")
    ap.add_argument("--variants", default="seed,tibia15,both")
    ap.add_argument("--foundation", choices=["scene", "nodal", "consistent"], default="scene",
                    help="the gait scenario's foundation_integration (default: as in the scene)")
    a = ap.parse_args()
    root = os.path.abspath(os.path.join(os.path.dirname(__file__), ".."))
    scene = yaml.safe_load(open(os.path.join(root, "data/scenes/lenhart2015_gait.yaml")))
    scene["model"] = os.path.join(root, "data/models/lenhart2015")
    scene["trial"] = os.path.join(root, "data/trials/lenhart2015_overground17")
    gait = scene["surface"]["scenarios"]["gait"]
    scene["surface"]["scenarios"] = {"gait": gait}
    scene.pop("post", None)
    scene["outputs"] = ["surface"]
    if a.foundation != "scene":
        gait["foundation_integration"] = a.foundation
    if a.window:
        scene["trial.end_s"] = 1.33
        gait["end_time_s"] = 0.11
    os.makedirs(a.out, exist_ok=True)
    for name in a.variants.split(","):
        if name not in VARIANTS:
            sys.exit("unknown variant %r; expected any of %s" % (name, ", ".join(VARIANTS)))
        scene["prepare"]["surface_edge_length_mm"] = VARIANTS[name]
        d = os.path.abspath(os.path.join(a.out, name if a.foundation == "scene" else name + "_" + a.foundation))
        os.makedirs(d, exist_ok=True)
        path = os.path.join(d, "scene.yaml")
        with open(path, "w") as f:
            yaml.safe_dump(scene, f, sort_keys=False)
        t0 = time.time()
        with open(os.path.join(d, "run.log"), "w") as log:
            rc = subprocess.call([os.path.join(a.bin, "arthrosim"), "run", path, "--out", d, "--jobs", "1"],
                                 stdout=log, stderr=subprocess.STDOUT)
        if rc != 0:
            sys.exit("%s: arthrosim run failed (exit %d), see %s/run.log" % (name, rc, d))
        print("== %s (%s): %.0f s wall" % (name, ", ".join(VARIANTS[name]), time.time() - t0), flush=True)
        bending_length_table(os.path.join(d, "prepared.h5"), os.path.join(d, "surface_gait.h5"))
        subprocess.check_call([sys.executable, os.path.join(root, "scripts/gait_figures.py"),
                               os.path.join(d, "kinematics.h5"), os.path.join(d, "surface_gait.h5")])


if __name__ == "__main__":
    main()
