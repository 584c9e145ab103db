#!/usr/bin/env python3
"""Print the regeneration-criteria table of docs/shockwave.md from a shockwave summary.

    python3 scripts/shockwave_table.py OUT/shockwave_summary.json

One row per run and tissue (cartilage, menisci): the tissue's volume, the
volumes meeting each criterion and all three [mm^3], the largest peak
hydrostatic pressure [MPa], distortional strain [%] and pore pressure [MPa];
then per run the pulse peak [MPa] and the wall time [s].
"""
import json
import sys


def main(path):
    d = json.load(open(path))
    print("| EFD [mJ/mm^2] | tissue | volume | compressive | distortional | pore pressure | all three "
          "| peak P [MPa] | peak strain [%] | peak pore p [MPa] |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    for t in ("cartilage", "fibrocartilage"):
        for r in d["runs"]:
            x = r["tissues"][t]
            vols = " | ".join(f"{round(x[k]):,}" for k in
                              ("volume_mm3", "compressive_mm3", "distortional_mm3", "pore_mm3", "all_mm3"))
            print(f"| {r['efd_mj_per_mm2']} | {t} | {vols} | {x['max_peak_pressure_mpa']:.2f} "
                  f"| {100 * x['max_peak_distortional_strain']:.2f} | {x['max_peak_pore_pressure_mpa']:.2f} |")
    print()
    for r in d["runs"]:
        print(f"{r['label']}: pulse peak {r['pulse_peak_mpa']:.2f} MPa, wall {r['wall_s']:.0f} s")


if __name__ == "__main__":
    if len(sys.argv) != 2:
        sys.exit(__doc__)
    main(sys.argv[1])
