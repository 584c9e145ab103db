#!/usr/bin/python3
"""Generate the SYNTHETIC walking trial bundled in data/trials/synthetic_gait/.

SYNTHETIC DATA: nothing here was measured. One gait cycle (right heel strike to
the next right heel strike) of a 61 kg, 1.65 m subject is built from key points
of published normative gait curves, interpolated smoothly, and written the way
OpenSim users have their trials:

  ik.mot     joint angles (degrees, inDegrees=yes) and pelvis translations (m),
             OpenSim 4 .mot header, gait2392/Rajagopal-style column names.
  grf.mot    ground reaction on the right foot, columns named like an OpenSim
             ExternalLoads file (ground_force_v?, ground_force_p?, ground_torque_?).
  trial.yaml the trial description read by musculoskeletal/gait_trial.h.

Run (python3 with numpy; Debian: /usr/bin/python3 + python3-numpy):
  /usr/bin/python3 scripts/make_synthetic_trial.py --out data/trials/synthetic_gait
The output is deterministic (no random numbers); rerunning it reproduces the
bundled files byte for byte.

Sources of the key points (values read off the published mean curves, rounded;
the curves here are shaped like them, not fitted to tabulated data):
  * Sagittal knee and ankle angles, vertical/antero-posterior GRF: Winter D.A.
    (2009) Biomechanics and Motor Control of Human Movement, 4th ed., normative
    walking data (natural cadence), and Perry J. (1992) Gait Analysis.
    Knee: ~5 deg at heel strike, loading-response peak ~18 deg at ~15 % of the
    cycle, ~4 deg near 40 %, ~38 deg at toe-off (60 %), swing peak ~60 deg at
    ~72 %. Ankle (dorsiflexion +): 0 at heel strike, ~-6 deg at foot flat (7 %),
    ~+10 deg at 45 %, ~-17 deg just after toe-off (62 %), ~+8 deg in
    mid-swing (see the pelvis note below).
    Vertical GRF: double peak ~1.10 BW at ~22 % and ~77 % of stance, valley
    ~0.78 BW at mid-stance. AP GRF: braking ~-0.20 BW at ~15 % of stance,
    propulsion ~+0.20 BW at ~85 % of stance.
  * Hip flexion/adduction/rotation relative to the pelvis: Kadaba M.P. et al.
    (1989/1990) J Orthop Res 7:849-860 / 8:383-392. Flexion ~30 deg at heel
    strike, ~-10 deg at ~52 %, ~34 deg at ~87 %; adduction ~+8 deg at ~18 %,
    ~-6 deg abduction at ~70 %; rotation within +-5 deg (internal +).
  * Vertical GRF after the second peak: near-linear unloading during double
    support, ~0.60 BW at 90 % of stance (Winter 2009 curve shape).
  * Centre of pressure along the sole: keyed to the measured timing of the COP
    sub-phases (heel contact 0-7 %, forefoot contact 7-12 %, foot flat 12-61 %,
    push-off 61-100 % of stance; "Gait speed and gender effects on center of
    pressure progression during normal walking", 2013, 30 young adults), with
    anatomical positions at the boundaries (see COP_PROGRESSION). Issue 4: the
    earlier "shape only" curve left the COP ~3 cm too far back at loading
    response (external knee flexion moment 0.80 N m/kg instead of 0.4-0.6);
    docs/trials.md gives the measurement.
  * Medio-lateral GRF ~0.05 BW directed medially with a small lateral
    transient at heel contact (Winter 2009; Perry 1992).
  * Free moment: a few N m (e.g. Li Y. et al. 2001, J Exp Biol 204:47-58);
    peak values here -0.015 and +0.05 N m/kg are representative, not fitted.
  * Anthropometry (segment lengths as fractions of stature H): Winter (2009)
    Fig. 4.1 after Drillis & Contini: thigh 0.245 H, shank 0.246 H, ankle
    height 0.039 H, foot length 0.152 H. Hip joint centre in the pelvis frame:
    OpenSim gait2392 (-0.0707, -0.0661, 0.0835) m scaled by H / 1.80 m.

Interpolation: joint angles are periodic C2 cubic splines through the key
points (smooth accelerations; a spline may overshoot a key point by a fraction
of a degree -- the script prints the achieved extrema). Ground reactions are
monotone piecewise-cubic Hermite (Fritsch-Carlson) curves in % of stance,
zero at heel strike and toe-off, exactly zero in swing: no overshoot, the
vertical force never goes negative and the peaks equal the key values.

Pelvis: constant anterior tilt of 10 deg (pelvis_tilt = -10 deg, OpenSim sign:
rotation about +Z), obliquity (pelvis_list) a 4 deg sinusoid with the right
side highest at 17 % (contralateral drop in loading response; Kadaba 1990:
+-4-5 deg), no pelvis rotation. Its translation is solved so that
the stance foot rolls without slipping over its heel and then its toe (the
lower of the two is fixed in the lab). During right swing the pelvis follows
the left stance, taken as the right-stance solution half a cycle later,
mirrored about the walking line and advanced by half a stride (a symmetric
gait); the two are blended with smoothstep weights over the double-support
windows (0-10 % and 50-60 %), and the result is low-pass smoothed (periodic
Fourier truncation at 6 harmonics, < 5.3 Hz) so that velocities have no kinks.
The script prints how far the stance foot slides after smoothing and the
lowest point of the swing foot. The foot is rigid and flat-soled (no toes),
so mid-swing clearance needs ~8 deg of dorsiflexion at 78 %, more than the
~0-3 deg of the normative curves. The centre of pressure is then placed on the foot
actually described by ik.mot (heel-to-toe progression along the sole,
projected onto the floor y = 0), so that the two files are consistent with the
forward kinematics of musculoskeletal/gait_trial.h.

Lab frame (OpenSim): X forward (walking direction), Y up, Z to the right.
Forces in N on the right foot from the ground, COP in m, torque in N m about
the COP (free moment, only its Y component is non-zero).
"""
import argparse
import os

import numpy as np

# ---- subject and timing -------------------------------------------------------
MASS_KG = 61.0
HEIGHT_M = 1.65
G = 9.80665
BW = MASS_KG * G
CYCLE_S = 1.14          # gait cycle duration (cadence ~105 steps/min)
RATE_HZ = 100.0
STANCE_FRACTION = 0.60  # toe-off at 60 % of the cycle
PELVIS_TILT_DEG = -10.0  # anterior tilt (OpenSim: rotation about +Z)
# Pelvic obliquity (pelvis_list, rotation about +X; negative = right side up):
# the unloaded left side drops in right stance, peak 4 deg at ~17 % of the cycle
# (Kadaba et al. 1990 report +-4-5 deg). A sinusoid, so that list(t + T/2) =
# -list(t) as a left-right symmetric gait requires.
PELVIS_LIST_PEAK_DEG = 4.0
PELVIS_LIST_PEAK_PCT = 17.0

# ---- segment geometry from stature (Winter 2009 Fig. 4.1) ---------------------
THIGH_M = 0.245 * HEIGHT_M
SHANK_M = 0.246 * HEIGHT_M
ANKLE_HEIGHT_M = 0.039 * HEIGHT_M
FOOT_LENGTH_M = 0.152 * HEIGHT_M
HEEL_BEHIND_ANKLE = 0.22     # fraction of foot length the heel lies behind the ankle
P_PELVIS_HIP = np.array([-0.0707, -0.0661, 0.0835]) * HEIGHT_M / 1.80

# ---- key points: (percent of gait cycle, degrees) -----------------------------
KNEE_FLEXION = [(0, 5), (15, 18), (40, 4), (50, 13), (60, 38), (72, 60), (87, 27), (95, 6)]
HIP_FLEXION = [(0, 30), (10, 27), (30, 10), (52, -10), (62, 0), (75, 25), (87, 34)]
HIP_ADDUCTION = [(0, 2), (18, 8), (45, 3), (60, -3), (70, -6), (85, -2)]
HIP_ROTATION = [(0, 2), (15, 5), (50, 0), (70, -5), (90, 0)]
ANKLE_FLEXION = [(0, 0), (7, -6), (20, 3), (35, 8), (45, 10), (55, 0), (62, -17), (70, -5),
                 (78, 8), (92, 2)]

# ---- ground reaction key points: (percent of stance, value) -------------------
# Unloading in double support (83-100 % of stance = 50-60 % of the cycle) is
# close to linear from ~1.0 BW at contralateral heel strike to zero at toe-off
# (Winter 2009 normative curve): ~0.6 BW at 90 % of stance (was 0.70, which with
# the monotone interpolation kept ~0.5 BW at 94 % of stance).
GRF_VERTICAL_BW = [(0, 0), (4, 0.35), (10, 0.85), (22, 1.10), (35, 0.92), (50, 0.78),
                   (65, 0.92), (77, 1.10), (90, 0.60), (100, 0)]
GRF_AP_BW = [(0, 0), (15, -0.20), (30, -0.12), (50, 0.0), (55, 0.03), (70, 0.12),
             (85, 0.20), (95, 0.08), (100, 0)]
# Right foot: medial is -Z.
GRF_ML_BW = [(0, 0), (4, 0.02), (10, 0.0), (22, -0.05), (50, -0.035), (77, -0.05),
             (92, -0.02), (100, 0)]
FREE_MOMENT_NM_PER_KG = [(0, 0), (10, -0.015), (35, 0.0), (70, 0.05), (100, 0)]
# Centre of pressure: fraction of the heel-to-toe length along the sole, keyed to
# the sub-phases of COP progression measured in 30 healthy young adults with a
# foot pressure system ("Gait speed and gender effects on center of pressure
# progression during normal walking", Gait & Posture, 2013; values from its
# abstract: 7.0 / 4.8 / 48.8 / 39.4 % of stance for the four sub-phases):
# initial contact phase (heel only) 0-7 % of stance, forefoot
# contact phase 7-12 %, foot-flat phase 12-61 %, forefoot push-off 61-100 %.
# Positions at the phase boundaries are anatomical (not read off a curve): heel
# pad 0.05, end of heel contact 0.12, forefoot contact (COP jumps to the
# midfoot) 0.28, heel-off 0.60 (just behind the metatarsal heads at 0.73),
# toe-off 0.95 (hallux). The previous curve (0.02 -> 0.92, "shape only") kept
# the COP ~3 cm too far back in loading response, which gave an external knee
# flexion moment of 0.8 N m/kg there (normative 0.4-0.6).
COP_PROGRESSION = [(0, 0.05), (7, 0.12), (12, 0.28), (61, 0.60), (100, 0.95)]
# Medio-lateral COP offset from the foot's long axis (m, +Z lateral for the right
# foot): lateral heel contact, medial forefoot push-off.
COP_ML_M = [(0, 0.005), (100, -0.010)]


def periodic_cubic_spline(keys, period, t):
    """C2 periodic cubic spline through (x, y) keys (x in [0, period)), evaluated at t."""
    x = np.array([k[0] for k in keys], dtype=float)
    y = np.array([k[1] for k in keys], dtype=float)
    n = len(x)
    h = np.diff(np.append(x, x[0] + period))          # h[i] = x[i+1] - x[i], cyclic
    dy = np.diff(np.append(y, y[0])) / h
    # Unknown second derivatives M_i; cyclic system
    # h[i-1] M[i-1] + 2 (h[i-1] + h[i]) M[i] + h[i] M[i+1] = 6 (dy[i] - dy[i-1]).
    A = np.zeros((n, n))
    b = np.zeros(n)
    for i in range(n):
        A[i, (i - 1) % n] += h[i - 1]
        A[i, i] += 2.0 * (h[i - 1] + h[i])
        A[i, (i + 1) % n] += h[i]
        b[i] = 6.0 * (dy[i] - dy[i - 1])
    M = np.linalg.solve(A, b)
    tt = np.mod(t, period)
    idx = np.searchsorted(x, tt, side="right") - 1
    idx = np.clip(idx, 0, n - 1)
    x0 = x[idx]
    hi = h[idx]
    j = (idx + 1) % n
    a = (x0 + hi - tt) / hi
    c = (tt - x0) / hi
    return (a * y[idx] + c * y[j]
            + ((a ** 3 - a) * M[idx] + (c ** 3 - c) * M[j]) * hi ** 2 / 6.0)


def pchip(keys, t):
    """Monotone piecewise-cubic Hermite interpolation (Fritsch & Carlson 1980)."""
    x = np.array([k[0] for k in keys], dtype=float)
    y = np.array([k[1] for k in keys], dtype=float)
    h = np.diff(x)
    delta = np.diff(y) / h
    d = np.zeros_like(y)
    for i in range(1, len(x) - 1):
        if delta[i - 1] * delta[i] > 0.0:
            w1 = 2.0 * h[i] + h[i - 1]
            w2 = h[i] + 2.0 * h[i - 1]
            d[i] = (w1 + w2) / (w1 / delta[i - 1] + w2 / delta[i])
    # One-sided end slopes (three-point formula, limited as in Fritsch-Carlson).
    for i0, i1, s in ((0, 1, 1), (len(x) - 1, len(x) - 2, -1)):
        k0 = 0 if s == 1 else len(h) - 1
        k1 = 1 if s == 1 else len(h) - 2
        if len(h) < 2:
            d[i0] = delta[k0]
            continue
        dd = ((2 * h[k0] + h[k1]) * delta[k0] - h[k0] * delta[k1]) / (h[k0] + h[k1])
        if np.sign(dd) != np.sign(delta[k0]):
            dd = 0.0
        elif np.sign(delta[k0]) != np.sign(delta[k1]) and abs(dd) > abs(3 * delta[k0]):
            dd = 3 * delta[k0]
        d[i0] = dd
    tt = np.clip(t, x[0], x[-1])
    idx = np.clip(np.searchsorted(x, tt, side="right") - 1, 0, len(x) - 2)
    s = (tt - x[idx]) / h[idx]
    h00 = 2 * s ** 3 - 3 * s ** 2 + 1
    h10 = s ** 3 - 2 * s ** 2 + s
    h01 = -2 * s ** 3 + 3 * s ** 2
    h11 = s ** 3 - s ** 2
    return h00 * y[idx] + h10 * h[idx] * d[idx] + h01 * y[idx + 1] + h11 * h[idx] * d[idx + 1]


def rot_x(a):
    c, s = np.cos(a), np.sin(a)
    return np.array([[1, 0, 0], [0, c, -s], [0, s, c]])


def rot_y(a):
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])


def rot_z(a):
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])


def leg_chain(angles_deg):
    """Forward kinematics of the right leg with the pelvis origin at 0.

    Same conventions as musculoskeletal/gait_trial.h: pelvis and hip are body-fixed
    Z-X-Y rotations (OpenSim CustomJoint order: flexion/tilt about Z, adduction/list
    about X, rotation about Y), knee flexion is a rotation of the shank about -Z,
    ankle dorsiflexion a rotation of the foot about +Z. Returns a dict of points
    (pelvis frame origin at the lab origin) and the foot rotation.
    """
    R_WP = rot_z(np.radians(angles_deg["pelvis_tilt"])) @ rot_x(np.radians(angles_deg["pelvis_list"])) \
        @ rot_y(np.radians(angles_deg["pelvis_rotation"]))
    R_WF = R_WP @ rot_z(np.radians(angles_deg["hip_flexion_r"])) \
        @ rot_x(np.radians(angles_deg["hip_adduction_r"])) @ rot_y(np.radians(angles_deg["hip_rotation_r"]))
    R_WT = R_WF @ rot_z(-np.radians(angles_deg["knee_angle_r"]))
    R_WC = R_WT @ rot_z(np.radians(angles_deg["ankle_angle_r"]))
    hip = R_WP @ P_PELVIS_HIP
    knee = hip + R_WF @ np.array([0.0, -THIGH_M, 0.0])
    ankle = knee + R_WT @ np.array([0.0, -SHANK_M, 0.0])
    heel_x = -HEEL_BEHIND_ANKLE * FOOT_LENGTH_M
    heel = ankle + R_WC @ np.array([heel_x, -ANKLE_HEIGHT_M, 0.0])
    toe = ankle + R_WC @ np.array([heel_x + FOOT_LENGTH_M, -ANKLE_HEIGHT_M, 0.0])
    return {"hip": hip, "knee": knee, "ankle": ankle, "heel": heel, "toe": toe, "R_WC": R_WC}


def angles_at(t):
    pct = 100.0 * np.asarray(t) / CYCLE_S
    return {
        "pelvis_tilt": np.full_like(pct, PELVIS_TILT_DEG),
        "pelvis_list": -PELVIS_LIST_PEAK_DEG * np.sin(2 * np.pi * (pct - PELVIS_LIST_PEAK_PCT) / 100.0
                                                      + np.pi / 2),
        "pelvis_rotation": np.zeros_like(pct),
        "hip_flexion_r": periodic_cubic_spline(HIP_FLEXION, 100.0, pct),
        "hip_adduction_r": periodic_cubic_spline(HIP_ADDUCTION, 100.0, pct),
        "hip_rotation_r": periodic_cubic_spline(HIP_ROTATION, 100.0, pct),
        "knee_angle_r": periodic_cubic_spline(KNEE_FLEXION, 100.0, pct),
        "ankle_angle_r": periodic_cubic_spline(ANKLE_FLEXION, 100.0, pct),
    }


def chain_at(angles, i):
    return leg_chain({k: float(v[i]) for k, v in angles.items()})


def pelvis_trajectory(t_fine):
    """Rolling-foot pelvis translation on a fine periodic grid (see module doc)."""
    ang = angles_at(t_fine)
    n = len(t_fine)
    t_off = STANCE_FRACTION * CYCLE_S
    heel = np.array([chain_at(ang, i)["heel"] for i in range(n)])
    toe = np.array([chain_at(ang, i)["toe"] for i in range(n)])
    pelvis = np.zeros((n, 3))
    stance = t_fine <= t_off
    pivot_is_heel = heel[0, 1] <= toe[0, 1]
    # Heel on the floor at the lab origin's X/Z at heel strike.
    anchor = np.array([0.0, 0.0, 0.0]) if pivot_is_heel else None
    if not pivot_is_heel:
        raise SystemExit("key points give a toe-first contact; expected heel strike")
    for i in np.nonzero(stance)[0]:
        heel_lower = heel[i, 1] <= toe[i, 1]
        if heel_lower != pivot_is_heel:
            # Switch pivot: the new pivot is where it is now (both at the same height).
            current = anchor - (heel[i - 1] if pivot_is_heel else toe[i - 1])  # pelvis at i-1
            pivot_is_heel = heel_lower
            anchor = current + (heel[i - 1] if pivot_is_heel else toe[i - 1])
            anchor[1] = 0.0
        rel = heel[i] if pivot_is_heel else toe[i]
        pelvis[i] = anchor - rel
    # Swing of the right leg = stance of the left leg. With a left-right symmetric gait
    # the left-stance solution is the right one half a cycle later, mirrored in Z about
    # the walking line and advanced by half a stride. The two solutions are blended with
    # smooth weights over the double-support windows (0-10 % and 50-60 % of the cycle).
    half = n // 2                      # fine grid: index of T/2 (n odd, T/2 on the grid)
    i_mid = int(round(0.55 * (n - 1)))  # middle of the second double support
    i_q = int(round(0.05 * (n - 1)))    # middle of the first double support
    # Half stride and step width that make the two solutions meet in double support.
    half_stride = pelvis[i_mid, 0] - pelvis[i_q, 0]
    width = -pelvis[i_mid, 2] - pelvis[i_q, 2]

    def right(i):
        return pelvis[i]

    def left(i):
        # Left-stance pelvis at fine index i (any i in [0, n)), from the right stance
        # solution at i - half (wrapped into the right-stance interval).
        j = i - half
        shift = half_stride
        if j < 0:
            j += n - 1
            shift -= 2.0 * half_stride
        p = pelvis[j].copy()
        p[0] += shift
        p[2] = -width - p[2]
        return p

    pct = 100.0 * t_fine / CYCLE_S

    def smoothstep(a, b, x):
        u = np.clip((x - a) / (b - a), 0.0, 1.0)
        return u * u * (3 - 2 * u)

    w_right = np.where(pct < 50.0, smoothstep(0.0, 10.0, pct), 1.0 - smoothstep(50.0, 60.0, pct))
    out = np.zeros_like(pelvis)
    for i in range(n):
        pr = right(i) if stance[i] else np.zeros(3)
        pl = left(i) if (pct[i] <= 10.0 or pct[i] >= 50.0) else np.zeros(3)
        out[i] = w_right[i] * pr + (1.0 - w_right[i]) * pl
    stride = 2.0 * half_stride
    # Right stance at 0 % uses left(i) with the previous stride; make the last sample
    # equal to the first plus one stride exactly (periodicity).
    out[-1] = out[0] + np.array([stride, 0.0, 0.0])
    pelvis = out
    return pelvis, stride


def smooth_periodic(t_fine, values, stride_x, harmonics):
    """Fourier truncation of a periodic signal (x has a linear trend of one stride)."""
    trend = np.zeros_like(values)
    trend[:, 0] = stride_x * t_fine / CYCLE_S
    y = values - trend
    # Samples on [0, T) (the last fine sample equals the first plus the trend).
    y = y[:-1]
    n = len(y)
    spec = np.fft.rfft(y, axis=0)
    spec[harmonics + 1:] = 0.0
    out = np.fft.irfft(spec, n=n, axis=0)

    def evaluate(t):
        k = np.arange(harmonics + 1)
        phase = 2 * np.pi * np.outer(np.asarray(t) / CYCLE_S, k)
        res = np.zeros((len(np.atleast_1d(t)), values.shape[1]))
        for c in range(values.shape[1]):
            coef = spec[:harmonics + 1, c] / n
            w = np.where(k == 0, 1.0, 2.0)
            res[:, c] = (np.cos(phase) @ (w * coef.real)) - (np.sin(phase) @ (w * coef.imag))
        res[:, 0] += stride_x * np.asarray(t) / CYCLE_S
        return res

    return evaluate, out


def main():
    ap = argparse.ArgumentParser(description="Generate the SYNTHETIC bundled walking trial.")
    ap.add_argument("--out", default="data/trials/synthetic_gait", help="output folder")
    args = ap.parse_args()
    os.makedirs(args.out, exist_ok=True)

    # Pelvis translation on a fine grid, smoothed.
    fine_n = 2281  # 0.5 ms steps over one cycle, both ends included
    t_fine = np.linspace(0.0, CYCLE_S, fine_n)
    pelvis_raw, stride = pelvis_trajectory(t_fine)
    pelvis_at, _ = smooth_periodic(t_fine, pelvis_raw, stride, harmonics=6)
    # How far the smoothed pelvis departs from the rolling-foot solution in stance: the
    # distance the stance foot slides or lifts in the written kinematics.
    fine_stance = t_fine <= STANCE_FRACTION * CYCLE_S
    slip = np.abs(pelvis_at(t_fine) - pelvis_raw)[fine_stance]

    n = int(round(CYCLE_S * RATE_HZ)) + 1
    t = np.arange(n) / RATE_HZ
    ang = angles_at(t)
    pelvis = pelvis_at(t)

    # Ground reactions in stance.
    t_off = STANCE_FRACTION * CYCLE_S
    in_stance = t < t_off
    pst = 100.0 * t / t_off
    fy = np.where(in_stance, pchip(GRF_VERTICAL_BW, pst), 0.0) * BW
    fx = np.where(in_stance, pchip(GRF_AP_BW, pst), 0.0) * BW
    fz = np.where(in_stance, pchip(GRF_ML_BW, pst), 0.0) * BW
    ty = np.where(in_stance, pchip(FREE_MOMENT_NM_PER_KG, pst), 0.0) * MASS_KG
    cop = np.zeros((n, 3))
    for i in range(n):
        a = {k: float(v[i]) for k, v in ang.items()}
        ch = leg_chain(a)
        heel = ch["heel"] + pelvis[i]
        toe = ch["toe"] + pelvis[i]
        if in_stance[i]:
            s = float(pchip(COP_PROGRESSION, pst[i]))
            p = heel + s * (toe - heel)
            p[2] += float(pchip(COP_ML_M, pst[i]))
            p[1] = 0.0
            cop[i] = p
    # Swing: OpenSim files usually hold the last COP or zeros; force is zero, so the
    # point does not matter. Zeros are written.

    write_ik(os.path.join(args.out, "ik.mot"), t, ang, pelvis)
    write_grf(os.path.join(args.out, "grf.mot"), t, fx, fy, fz, cop, ty)
    write_yaml(os.path.join(args.out, "trial.yaml"))

    # Report what was produced (numbers quoted in docs/trials.md).
    def ext(name):
        v = ang[name]
        return f"{name}: min {v.min():.2f} deg at {100 * t[v.argmin()] / CYCLE_S:.0f}%, " \
               f"max {v.max():.2f} deg at {100 * t[v.argmax()] / CYCLE_S:.0f}%"
    print(f"SYNTHETIC trial: {n} rows, {t[-1]:.2f} s at {RATE_HZ:.0f} Hz, stride {stride:.3f} m, "
          f"mean speed {stride / CYCLE_S:.3f} m/s")
    for name in ("hip_flexion_r", "hip_adduction_r", "hip_rotation_r", "knee_angle_r", "ankle_angle_r"):
        print("  " + ext(name))
    i15 = int(round(0.15 * CYCLE_S * RATE_HZ))
    print(f"  knee flexion at 15%: {ang['knee_angle_r'][i15]:.2f} deg")
    clearance = min(min((leg_chain({k: float(v[i]) for k, v in ang.items()})[p] + pelvis[i])[1]
                        for p in ("heel", "toe")) for i in range(n) if not in_stance[i])
    print(f"  lowest heel/toe point in swing: {1000 * clearance:.1f} mm above the floor")
    print(f"  vertical GRF max {fy.max() / BW:.3f} BW, AP min {fx.min() / BW:.3f} max {fx.max() / BW:.3f} BW, "
          f"ML min {fz.min() / BW:.3f} BW, free moment {ty.min():.2f}..{ty.max():.2f} N m")
    print(f"  pelvis height {pelvis[:, 1].min():.3f}..{pelvis[:, 1].max():.3f} m; "
          f"stance foot slip after smoothing at most {1000 * slip[:, 0].max():.1f} mm (X), "
          f"{1000 * slip[:, 1].max():.1f} mm (Y), {1000 * slip[:, 2].max():.1f} mm (Z)")


HEADER_NOTE = ("SYNTHETIC DATA -- not measured. Generated by scripts/make_synthetic_trial.py "
               "from published normative gait curves (Winter 2009; Perry 1992; Kadaba 1989/1990).")


def write_table(path, name, columns, data, in_degrees):
    with open(path, "w") as f:
        f.write(f"{name}\n")
        f.write("version=1\n")
        f.write(f"nRows={data.shape[0]}\n")
        f.write(f"nColumns={data.shape[1]}\n")
        f.write(f"inDegrees={'yes' if in_degrees else 'no'}\n")
        f.write(f"{HEADER_NOTE}\n")
        f.write("Lab frame: X forward, Y up, Z right (OpenSim). Units: s, m, N, N m; angles in degrees.\n")
        f.write("endheader\n")
        f.write("\t".join(columns) + "\n")
        for row in data:
            f.write("\t".join(f"{v:.8f}" for v in row) + "\n")


def write_ik(path, t, ang, pelvis):
    cols = ["time", "pelvis_tilt", "pelvis_list", "pelvis_rotation", "pelvis_tx", "pelvis_ty",
            "pelvis_tz", "hip_flexion_r", "hip_adduction_r", "hip_rotation_r", "knee_angle_r",
            "ankle_angle_r"]
    data = np.column_stack([t, ang["pelvis_tilt"], ang["pelvis_list"], ang["pelvis_rotation"],
                            pelvis[:, 0], pelvis[:, 1], pelvis[:, 2], ang["hip_flexion_r"],
                            ang["hip_adduction_r"], ang["hip_rotation_r"], ang["knee_angle_r"],
                            ang["ankle_angle_r"]])
    write_table(path, "Coordinates (SYNTHETIC)", cols, data, True)


def write_grf(path, t, fx, fy, fz, cop, ty):
    cols = ["time", "ground_force_vx", "ground_force_vy", "ground_force_vz", "ground_force_px",
            "ground_force_py", "ground_force_pz", "ground_torque_x", "ground_torque_y",
            "ground_torque_z"]
    zero = np.zeros_like(t)
    data = np.column_stack([t, fx, fy, fz, cop[:, 0], cop[:, 1], cop[:, 2], zero, ty, zero])
    write_table(path, "GRF (SYNTHETIC)", cols, data, False)


def write_yaml(path):
    text = f"""# SYNTHETIC walking trial -- not measured data.
# Generated by scripts/make_synthetic_trial.py (see docs/trials.md); do not edit by hand.
# Flat "key: value" lines only (read line by line by musculoskeletal/gait_trial.cc).
synthetic: true
# One whole gait cycle: the last row is the first one a stride later.
periodic: true
description: SYNTHETIC one gait cycle from normative curves (Winter 2009, Perry 1992, Kadaba 1989)
subject_mass_kg: {MASS_KG}
subject_height_m: {HEIGHT_M}
side: right
lab_frame: opensim_x_forward_y_up_z_right
kinematics_file: ik.mot
grf_file: grf.mot
# Column mapping: arthrosim quantity -> column name; a leading '-' negates the column.
column.pelvis_tilt: pelvis_tilt
column.pelvis_list: pelvis_list
column.pelvis_rotation: pelvis_rotation
column.pelvis_tx: pelvis_tx
column.pelvis_ty: pelvis_ty
column.pelvis_tz: pelvis_tz
column.hip_flexion: hip_flexion_r
column.hip_adduction: hip_adduction_r
column.hip_rotation: hip_rotation_r
column.knee_flexion: knee_angle_r
column.ankle_flexion: ankle_angle_r
column.grf_force_x: ground_force_vx
column.grf_force_y: ground_force_vy
column.grf_force_z: ground_force_vz
column.grf_cop_x: ground_force_px
column.grf_cop_y: ground_force_py
column.grf_cop_z: ground_force_pz
column.grf_torque_x: ground_torque_x
column.grf_torque_y: ground_torque_y
column.grf_torque_z: ground_torque_z
"""
    with open(path, "w") as f:
        f.write(text)


if __name__ == "__main__":
    main()
