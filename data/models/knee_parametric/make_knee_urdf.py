#!/usr/bin/env python3
"""Writes the bundled knee model file(s) of the parametric knee.

    python3 data/models/knee_parametric/make_knee_urdf.py            # knee.urdf (medium) + knee_coarse.urdf

The meshes, per-vertex thickness files and landmarks.yaml under coarse/ and
medium/ come from the knee geometry generator (docs/knee_geometry.md). This
script only places the soft tissues on that geometry; every number below has
its source in a comment, and docs/model_format.md explains the file format.

Model frame (all coordinates here, in millimetres, converted to metres on
output): femur frame at full extension, origin at the midpoint of the flexion
axis, X anterior, Y superior, Z right (= lateral, this is a right knee).
Attachment points are written with frame="reference" (model frame at q = 0).

Sources
  [L15]  Lenhart RL et al. 2015, Ann Biomed Eng 43:2675 (knee model of seed
         002): 14 ligament groups, bundle counts and stiffness per bundle,
         13 knee-crossing muscles and their F_max (values in
         /work/shared/references.md, taken from clnsmith/opensim-jam).
  [B91]  Blankevoort L, Huiskes R 1991, J Biomech Eng 113:263: e_t = 0.06.
  [W09]  Winter DA 2009, Biomechanics and Motor Control of Human Movement:
         segment masses (thigh 0.100, leg 0.0465 of body mass).
  [S02]  seed 002: subject 61 kg, 1.65 m.
  [ANAT] Attachment sites: approximate, placed on the parametric bones by
         anatomical description (Gray's Anatomy; LaPrade 2003/2007 for the MCL,
         LCL and posterolateral corner; Amis 2003 for the patellofemoral
         ligaments; Delp 1990 / Arnold 2010 muscle paths). They are not the
         MR-derived sites of [L15]; they are placed so that each structure
         runs in its anatomical direction on this geometry.
  [REF]  Reference strains at full extension: assumed values within the
         range used for knee models calibrated like [L15] (-0.05 .. 0.05:
         cruciates and collaterals near taut in extension, PCL and
         patellofemoral ligaments slack). They are NOT the calibrated
         lenhart2015 values (not available here) and should be calibrated
         against passive laxity data before quantitative use. Values written:
         -0.03 .. 0.03 (see ligaments()).
  [OS]   OpenSim Blankevoort1991Ligament (used by [L15] through opensim-jam):
         damping coefficient c = 0.003 N s per unit strain rate (its default).
  [GEO]  docs/knee_geometry.md: bone and cartilage meshes, per-vertex
         cartilage thickness, landmarks (incl. hip and ankle centres from
         Winter's segment-length fractions of the 1.65 m stature [S02]).

Parameters that are not written to the file take the loader's defaults,
which carry their own sources: transition strain e_t = 0.06 [B91]
(musculoskeletal/ligament.h) and the contact ray length factor
max_overlap_factor = 1 (rays as long as the combined thickness; a modelling
choice, musculoskeletal/contact.h).

Values without a physical source, stated as such:
  - inertia tensors are written as zero: the statics (settle, COMAK) use
    neither mass nor inertia, no dynamics runs on this model;
  - the patella mass 0.02 kg (order of magnitude only; unused by statics);
  - the joint <limit>s are wide bounds chosen by hand (flexion -20..140 deg,
    other rotations +-20..45 deg, translations +-30 mm tibia / +-50 mm
    patella); URDF requires them for revolute/prismatic joints; COMAK uses
    them as the bounds of the secondary coordinates in its NLP, the passive
    settle ignores them. They are generous bounds, not physiological limits;
  - the pelvis and calcaneus points of the hip/knee-crossing and gastrocnemius
    paths (ischial tuberosity, AIIS, ASIS, iliac crest, pubic ramus,
    calcaneal tuberosity) are offsets from the hip and ankle centres placed
    by anatomical description [ANAT], as are all via points.
"""
import math
import os
import sys

import yaml

HERE = os.path.dirname(os.path.abspath(__file__))


def load_landmarks(res):
    with open(os.path.join(HERE, res, "landmarks.yaml")) as f:
        y = yaml.safe_load(f)
    lm = {}
    for body, pts in y["landmarks"].items():
        for name, p in pts.items():
            lm[body + "." + name] = [1000.0 * v for v in p]  # mm
    return lm


def add(a, b):
    return [a[0] + b[0], a[1] + b[1], a[2] + b[2]]


def fmt(p_mm):
    return "%.6f %.6f %.6f" % tuple(v * 1e-3 for v in p_mm)


def spread(p, axis, width, n):
    """n points centred on p spread over `width` mm along a unit axis."""
    if n == 1:
        return [p]
    return [add(p, [axis[k] * (-width / 2 + width * i / (n - 1)) for k in range(3)]) for i in range(n)]


def ligaments(L):
    """14 groups of [L15]: (name, stiffness per bundle [L15], reference strain [REF],
    list of (femur/patella/tibia point pairs))."""
    X, Y, Z = [1, 0, 0], [0, 1, 0], [0, 0, 1]
    med_epi, lat_epi = L["femur.medial_epicondyle"], L["femur.lateral_epicondyle"]
    fib = L["tibia.fibular_head"]
    tub = L["tibia.tuberosity"]
    apex, base = L["patella.apex"], L["patella.base"]
    pmed, plat = L["patella.medial_border"], L["patella.lateral_border"]
    mpc, lpc = L["tibia.medial_plateau_centre"], L["tibia.lateral_plateau_centre"]
    groups = []

    def group(name, body_a, pa, body_b, pb, k, e_ref, wrap=None):
        assert len(pa) == len(pb)
        groups.append((name, k, e_ref, [((body_a, a), (body_b, b)) for a, b in zip(pa, pb)], wrap))

    # Superficial MCL: medial epicondyle (slightly posterior/proximal) to the
    # proximal medial tibia ~60 mm below the joint line [ANAT]; 6 x 500 [L15].
    group("MCLs", "femur", spread(add(med_epi, [-3, 3, 1]), X, 10, 6),
          "tibia", spread(add(mpc, [4, -58, -12]), X, 12, 6), 500, 0.03)
    # Deep MCL: epicondyle to the medial plateau rim just below the joint line; 5 x 500.
    group("MCLd", "femur", spread(add(med_epi, [-2, -4, 2]), X, 10, 5),
          "tibia", spread(add(mpc, [0, -8, -14]), X, 14, 5), 500, 0.03)
    # Posterior oblique ligament: posterior to the epicondyle to the posteromedial tibia; 5 x 500.
    group("MCLpo", "femur", spread(add(med_epi, [-10, 0, 3]), Y, 8, 5),
          "tibia", spread(add(mpc, [-17, -10, -10]), Y, 6, 5), 500, 0.02)
    # ACL: lateral wall of the notch (posterior) to the tibia anterior of the spines;
    # anteromedial and posterolateral bundles, 6 x 820 each [L15].
    notch = L["femur.intercondylar_notch_roof"]
    group("ACLam", "femur", spread(add(notch, [-8, -4, 8]), Y, 6, 6),
          "tibia", spread([10, mpc[1] + 1, -3], X, 6, 6), 820, 0.02)
    group("ACLpl", "femur", spread(add(notch, [-14, -10, 9]), Y, 6, 6),
          "tibia", spread([4, mpc[1] + 1, 1], X, 6, 6), 820, 0.01)
    # PCL: medial wall of the notch (anterior) to the posterior tibial fossa;
    # anterolateral 5 x 900 and posteromedial 5 x 300 [L15]; slack at extension.
    group("PCLal", "femur", spread(add(notch, [4, -10, -8]), X, 6, 5),
          "tibia", spread([-22, mpc[1] - 8, 0], Z, 8, 5), 900, -0.03)
    group("PCLpm", "femur", spread(add(notch, [-4, -16, -9]), X, 6, 5),
          "tibia", spread([-24, mpc[1] - 11, -2], Z, 8, 5), 300, -0.02)
    # LCL: lateral epicondyle to the fibular head; 4 x 600 [L15].
    group("LCL", "femur", spread(add(lat_epi, [-2, 2, 0]), X, 6, 4),
          "tibia", spread(add(fib, [2, -2, 4]), X, 6, 4), 600, 0.02)
    # Popliteofibular ligament: popliteus tendon near the lateral condyle to the fibular head; 5 x 440.
    group("PFL", "femur", spread(add(lat_epi, [-12, -12, -3]), X, 6, 5),
          "tibia", spread(add(fib, [-2, 3, 0]), X, 5, 5), 440, 0.01)
    # Posterior capsule: 8 bundles across the back of the knee, from above the
    # posterior condyles to the posterior tibial rim; 8 x 500 [L15].
    zs = [-30 + 60 * i / 7 for i in range(8)]
    group("PCAP", "femur", [[-30, 18, z] for z in zs],
          "tibia", [[-26, mpc[1] - 14, z] for z in zs], 500, 0.0)
    # Patellar tendon: patellar apex to the tibial tuberosity; 6 x 3000 [L15].
    group("PT", "patella", spread(add(apex, [-2, 2, 0]), Z, 16, 6),
          "tibia", spread(add(tub, [-2, 3, 0]), Z, 12, 6), 3000, 0.02)
    # Medial patellofemoral ligament: medial border of the patella to the
    # adductor-tubercle / medial-epicondyle region; 6 x 150 [L15].
    group("mPFL", "patella", spread(add(pmed, [-3, 0, 0]), Y, 14, 6),
          "femur", spread(add(med_epi, [2, 6, 0]), Y, 8, 6), 150, -0.02)
    # Lateral patellofemoral ligament: lateral border to the lateral epicondyle; 8 x 150.
    group("lPFL", "patella", spread(add(plat, [-3, 0, 0]), Y, 16, 8),
          "femur", spread(add(lat_epi, [2, 4, 0]), Y, 10, 8), 150, -0.02)
    # Iliotibial band (its knee part): lateral distal femur to Gerdy's tubercle; 1 x 10000.
    gerdy = add(lpc, [14, -14, 8])
    group("ITB", "femur", [add(lat_epi, [4, 60, 3])], "tibia", [gerdy], 10000, 0.01)
    return groups


def muscles(L):
    """13 knee-crossing muscles of [L15] with F_max [L15] and via-point paths [ANAT]."""
    H = L["limb.hip_centre"]
    A = L["limb.ankle_centre"]
    base, pmed, plat = L["patella.base"], L["patella.medial_border"], L["patella.lateral_border"]
    fib = L["tibia.fibular_head"]
    mpc, lpc = L["tibia.medial_plateau_centre"], L["tibia.lateral_plateau_centre"]
    tub = L["tibia.tuberosity"]
    pes = add(tub, [-10, -25, -28])           # pes anserinus, anteromedial tibia
    gerdy = add(lpc, [14, -14, 8])
    ischial = add(H, [-50, -60, -25])         # ischial tuberosity (pelvis)
    aiis = add(H, [30, 35, 5])                # anterior inferior iliac spine
    asis = add(H, [45, 60, 40])               # anterior superior iliac spine
    crest = add(H, [35, 75, 55])              # anterior iliac crest (TFL)
    pubis = add(H, [10, -35, -65])            # inferior pubic ramus (gracilis)
    calc = add(A, [-55, -30, 0])              # calcaneal tuberosity (Achilles insertion)
    m = []
    # (name, F_max [N] [L15], [(body, point_mm), ...])
    m.append(("recfem", 848.8, [("pelvis", aiis), ("femur", [38, 60, 0]), ("patella", add(base, [0, -2, 0]))]))
    m.append(("vasmed", 1443.7, [("femur", [10, 140, -12]), ("femur", [30, 45, -18]),
                                 ("patella", add(base, [0, -4, -10]))]))
    m.append(("vaslat", 2255.4, [("femur", [12, 200, 14]), ("femur", [30, 55, 20]),
                                 ("patella", add(base, [0, -4, 10]))]))
    m.append(("vasint", 1024.2, [("femur", [26, 160, 0]), ("femur", [36, 55, 0]),
                                 ("patella", add(base, [0, -1, 0]))]))
    m.append(("bflh", 705.2, [("pelvis", ischial), ("femur", [-28, 40, 30]), ("tibia", add(fib, [0, 2, 2]))]))
    m.append(("bfsh", 631.6, [("femur", [-8, 150, 10]), ("femur", [-26, 35, 32]), ("tibia", add(fib, [1, 0, 2]))]))
    m.append(("semimem", 1162.7, [("pelvis", ischial), ("femur", [-32, 35, -28]),
                                  ("tibia", add(mpc, [-18, -12, -8]))]))
    m.append(("semiten", 301.9, [("pelvis", add(ischial, [0, -3, -3])), ("femur", [-32, 45, -30]),
                                 ("tibia", add(mpc, [-14, -22, -14])), ("tibia", pes)]))
    m.append(("grac", 137.3, [("pelvis", pubis), ("femur", [-20, 45, -36]),
                              ("tibia", add(mpc, [-10, -20, -18])), ("tibia", add(pes, [0, 2, 0]))]))
    m.append(("sart", 113.5, [("pelvis", asis), ("femur", [-14, 60, -38]),
                              ("tibia", add(mpc, [-8, -18, -18])), ("tibia", add(pes, [2, 4, 0]))]))
    m.append(("tfl", 155.0, [("pelvis", crest), ("femur", [8, 200, 40]), ("femur", [2, 40, 40]),
                             ("tibia", gerdy)]))
    m.append(("gasmed", 1308.0, [("femur", [-24, 18, -24]), ("tibia", [-32, -60, -18]), ("calcaneus", calc)]))
    m.append(("gaslat", 606.4, [("femur", [-24, 18, 24]), ("tibia", [-32, -60, 18]), ("calcaneus", calc)]))
    return m


def chain(prefix, parent, child, names, axes, origins, limits):
    out = []
    prev = parent
    for i, (n, ax, org, lim) in enumerate(zip(names, axes, origins, limits)):
        link = child if i == len(names) - 1 else "%s_%s_link" % (prefix, n)
        if i < len(names) - 1:
            out.append('  <link name="%s"/>' % link)
        typ = "prismatic" if n in ("tx", "ty", "tz") else "revolute"
        out.append('  <joint name="%s_%s" type="%s">' % (prefix, n, typ))
        out.append('    <parent link="%s"/><child link="%s"/>' % (prev, link))
        out.append('    <origin xyz="%s" rpy="0 0 0"/>' % fmt(org))
        out.append('    <axis xyz="%s"/>' % ax)
        out.append('    <limit lower="%.4f" upper="%.4f" effort="0" velocity="0"/>' % lim)
        out.append("  </joint>")
        prev = link
    return out


def write(res, out_name):
    L = load_landmarks(res)
    body_mass = 61.0  # [S02]
    o = []
    o.append('<?xml version="1.0"?>')
    o.append("<!-- Generated by make_knee_urdf.py from %s/landmarks.yaml; edit the script, not this file."
             % res)
    o.append("     Parametric right knee, 12 DOF (docs/model_format.md). Sources: see the script. -->")
    o.append('<robot name="knee_parametric_%s" xmlns:arthrosim="https://arthrosim.org/model">' % res)

    def link(name, mass, mesh=None, com_y=0.0, rg_transverse=0.0, rg_long=0.0):
        o.append('  <link name="%s">' % name)
        if mass:
            it, il = mass * rg_transverse ** 2, mass * rg_long ** 2
            o.append('    <inertial><origin xyz="0 %.4f 0"/><mass value="%.4f"/>'
                     '<inertia ixx="%.5f" ixy="0" ixz="0" iyy="%.5f" iyz="0" izz="%.5f"/></inertial>'
                     % (com_y, mass, it, il, it))
        if mesh:
            o.append('    <visual><geometry><mesh filename="%s/%s.stl" scale="0.001 0.001 0.001"/></geometry></visual>'
                     % (res, mesh))
        o.append("  </link>")

    # Segment masses [W09] (thigh 0.100, leg 0.0465 of 61 kg); patella 0.02 kg (small,
    # order of magnitude of a patella). The statics use none of them; COMAK's optional
    # body inertia (comak.body_inertia, docs/comak.md) uses the tibia's and the
    # patella's. The tibia link carries the shank segment as the trial's inverse
    # dynamics does (musculoskeletal/anthropometry.h, docs/trials.md): COM 0.433 of
    # the shank length L = 0.246 x 1.65 m below the knee on the flexion axis,
    # radius of gyration 0.302 L about the transverse axes [W09] and 0.1 L about
    # the long axis (order of de Leva 1996), so the option and the inverse dynamics
    # describe the same body. Femur and patella: mass only, zero inertia tensors
    # (the femur is moved by the trial; the patella's inertia is negligible).
    shank_length = 0.246 * 1.65  # [W09] segment length / height, the subject's 1.65 m [S02]
    link("femur", 0.100 * body_mass, "femur_bone")
    link("tibia", 0.0465 * body_mass, "tibia_bone", com_y=-0.433 * shank_length,
         rg_transverse=0.302 * shank_length, rg_long=0.1 * shank_length)
    link("patella", 0.02, "patella_bone")
    link("pelvis", None)
    link("calcaneus", None)
    rad = math.radians
    # Joint limits: wide hand-chosen bounds (COMAK's variable bounds), not
    # physiological limits (see the module docstring).
    # Tibiofemoral: flexion about -Z (positive = flexion), adduction about +X
    # (positive = varus of this right knee), internal rotation about +Y, then
    # translations along X (anterior), Y (superior), Z (lateral); all at the
    # model origin on the flexion axis.
    o += chain("knee", "femur", "tibia",
               ["flexion", "adduction", "rotation", "tx", "ty", "tz"],
               ["0 0 -1", "1 0 0", "0 1 0", "1 0 0", "0 1 0", "0 0 1"],
               [[0, 0, 0]] * 6,
               [(rad(-20), rad(140)), (rad(-20), rad(20)), (rad(-45), rad(45)),
                (-0.03, 0.03), (-0.03, 0.03), (-0.03, 0.03)])
    # Patellofemoral: flexion about the femoral flexion axis (the patella
    # travels round the trochlea), then rotation (about X, anterior axis), tilt
    # (about Y) and translations at the patella centre.
    pc = L["patella.centre"]
    o += chain("pf", "femur", "patella",
               ["flexion", "rotation", "tilt", "tx", "ty", "tz"],
               ["0 0 -1", "1 0 0", "0 1 0", "1 0 0", "0 1 0", "0 0 1"],
               [[0, 0, 0], pc, [0, 0, 0], [0, 0, 0], [0, 0, 0], [0, 0, 0]],
               [(rad(-30), rad(140)), (rad(-45), rad(45)), (rad(-45), rad(45)),
                (-0.05, 0.05), (-0.05, 0.05), (-0.05, 0.05)])
    # Prescribed hip: the pelvis hangs on the femur (root), so the chain is the
    # inverse of pelvis->femur Rz(flexion) Rx(adduction) Ry(rotation):
    # femur->pelvis = Ry(-rotation) Rx(-adduction) Rz(-flexion), at the hip centre.
    H = L["limb.hip_centre"]
    o.append('  <link name="hip_rotation_link"/><link name="hip_adduction_link"/>')
    for i, (n, ax, parent, child) in enumerate([("hip_rotation", "0 -1 0", "femur", "hip_rotation_link"),
                                                 ("hip_adduction", "-1 0 0", "hip_rotation_link", "hip_adduction_link"),
                                                 ("hip_flexion", "0 0 -1", "hip_adduction_link", "pelvis")]):
        o.append('  <joint name="%s" type="revolute"><parent link="%s"/><child link="%s"/>' % (n, parent, child))
        o.append('    <origin xyz="%s"/><axis xyz="%s"/>' % (fmt(H if i == 0 else [0, 0, 0]), ax))
        o.append('    <limit lower="-2.0" upper="2.0" effort="0" velocity="0"/></joint>')
    # Prescribed ankle: dorsiflexion about +Z at the ankle centre.
    o.append('  <joint name="ankle_flexion" type="revolute"><parent link="tibia"/><child link="calcaneus"/>')
    o.append('    <origin xyz="%s"/><axis xyz="0 0 1"/>' % fmt(L["limb.ankle_centre"]))
    o.append('    <limit lower="-1.0" upper="1.0" effort="0" velocity="0"/></joint>')
    for j in ("hip_flexion", "hip_adduction", "hip_rotation", "ankle_flexion"):
        o.append('  <arthrosim:prescribed joint="%s"/>' % j)

    # Cartilage surfaces (meshes and analytic per-vertex thickness from the
    # generator) and contact pairs: E = 10 MPa, nu = 0.45, linear law, cast
    # from the tibia and patella onto the femur [L15].
    o.append("  <!-- cartilage: meshes in the model frame at extension (frame=reference) -->")
    for name, body, stem in [("femur_cartilage", "femur", "femur_cartilage"),
                             ("tibia_medial_cartilage", "tibia", "tibia_medial_cartilage"),
                             ("tibia_lateral_cartilage", "tibia", "tibia_lateral_cartilage"),
                             ("patella_cartilage", "patella", "patella_cartilage")]:
        o.append('  <arthrosim:surface name="%s" body="%s" mesh="%s/%s.stl" unit="mm" '
                 'thickness_csv="%s/%s_thickness.csv" frame="reference"/>' % (name, body, res, stem, res, stem))
    for name, cast in [("tf_medial", "tibia_medial_cartilage"), ("tf_lateral", "tibia_lateral_cartilage"),
                       ("pf", "patella_cartilage")]:
        o.append('  <arthrosim:contact name="%s" casting="%s" target="femur_cartilage" '
                 'youngs_modulus_mpa="10" poisson_ratio="0.45" law="linear"/>' % (name, cast))

    # Damping 0.003 N s per unit strain rate [OS]; e_t not written (loader default 0.06 [B91]).
    o.append("  <!-- ligaments: 14 groups of lenhart2015 (stiffness per bundle [N/strain]),")
    o.append("       slack lengths from the reference strain at full extension (q = 0) -->")
    for name, k, e_ref, bundles, wrap in ligaments(L):
        o.append('  <arthrosim:ligament name="%s" stiffness="%g" reference_strain="%g" damping="0.003">'
                 % (name, k, e_ref))
        for (ba, pa), (bb, pb) in bundles:
            o.append('    <bundle frame="reference"><point body="%s" xyz="%s"/><point body="%s" xyz="%s"/></bundle>'
                     % (ba, fmt(pa), bb, fmt(pb)))
        o.append("  </arthrosim:ligament>")
    o.append("  <!-- muscles: the 13 knee-crossing muscles of lenhart2015, F_max [N] -->")
    for name, fmax, pts in muscles(L):
        o.append('  <arthrosim:muscle name="%s" max_isometric_force="%g" frame="reference">' % (name, fmax))
        for b, p in pts:
            o.append('    <point body="%s" xyz="%s"/>' % (b, fmt(p)))
        o.append("  </arthrosim:muscle>")
    o.append("</robot>")
    with open(os.path.join(HERE, out_name), "w") as f:
        f.write("\n".join(o) + "\n")
    print("wrote", os.path.join(HERE, out_name))


if __name__ == "__main__":
    write("medium", "knee.urdf")
    write("coarse", "knee_coarse.urdf")
