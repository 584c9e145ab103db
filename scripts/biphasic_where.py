#!/usr/bin/python3
"""Where the biphasic stage's stress maxima sit (docs/studies.md, "Element
layers graded toward the surface"). Per layer of each biphasic.h5 given:
- the surface tensile maximum: the step and vertex of the largest
  max_tensile_stress, in how many steps the step's maximum is next to a vertex
  out of contact (surface/total_normal_stress <= 0), and the median distance
  from it to the nearest vertex out of contact;
- with --shear, the interface shear maximum: the step and vertex of the largest
  max_shear_stress, the median and smallest distance from the step's maximum
  to the layer's rim (vertices on edges of one articular quad), and in how many
  steps it is on the rim.

  /usr/bin/python3 scripts/biphasic_where.py [--shear] RUN1/biphasic.h5 [RUN2/biphasic.h5 ...]
"""
from collections import Counter
import sys

import h5py
import numpy as np


def shear(g, V, quads):
    ms = g["series/max_shear_stress"][:]
    mv = g["series/max_shear_vertex"][:]
    edges = Counter()
    for q in quads:
        for i in range(4):
            edges[tuple(sorted((q[i], q[(i + 1) % 4])))] += 1
    rim = np.array(sorted({x for e, c in edges.items() if c == 1 for x in e}))
    d = [np.min(np.linalg.norm(V[rim] - V[v], axis=1)) * 1e3 for v in mv if v >= 0]
    k = int(np.argmax(ms))
    return (f"interface shear largest {ms[k] / 1e6:.3g} MPa at step {k}, vertex {mv[k]}; distance to the rim: "
            f"median {np.median(d):.2f} mm, smallest {min(d):.2f} mm; on the rim in "
            f"{sum(x < 1e-6 for x in d)}/{len(d)} steps")


def main(paths, with_shear):
    for fn in paths:
        f = h5py.File(fn, "r")
        print(fn)
        for L in [n.decode() if isinstance(n, bytes) else n for n in f["layers/names"][:]]:
            g = f["layers/" + L]
            # articular_quads index the layer's nodes; articular_nodes maps vertex -> node
            node_to_vertex = {int(n): i for i, n in enumerate(g["articular_nodes"][:])}
            quads = [[node_to_vertex[int(x)] for x in q] for q in g["articular_quads"][:]]
            V = g["articular_vertices"][:]
            sigma = g["surface/total_normal_stress"][:]
            mt = g["series/max_tensile_stress"][:]
            mv = g["series/max_tensile_vertex"][:]
            nb = [set() for _ in range(len(V))]
            for q in quads:
                for a in q:
                    nb[a].update(q)
            at_edge, steps, dist = 0, 0, []
            for s in range(len(mt)):
                v = mv[s]
                if v < 0:
                    continue
                steps += 1
                c = sigma[s] > 0
                at_edge += any(not c[b] for b in nb[v])
                out = np.where(~c)[0]
                dist.append(np.min(np.linalg.norm(V[out] - V[v], axis=1)) * 1e3)
            k = int(np.argmax(mt))
            edge = np.median([np.linalg.norm(V[q[0]] - V[q[1]]) for q in quads]) * 1e3
            print(f"  {L}: largest {mt[k] / 1e6:.3g} MPa at step {k}, vertex {mv[k]}; next to a vertex out of "
                  f"contact in {at_edge}/{steps} steps; distance to the nearest vertex out of contact: median "
                  f"{np.median(dist):.2f} mm; surface edge length {edge:.2f} mm")
            if with_shear:
                print("    " + shear(g, V, quads))


if __name__ == "__main__":
    args = [a for a in sys.argv[1:] if a != "--shear"]
    if not args:
        sys.exit(__doc__)
    main(args, "--shear" in sys.argv[1:])
