#!/usr/bin/python3
"""Writes the seed corpora of the fuzz targets (tests/fuzz/corpus/<target>/)
from the bundled data: a few small, valid inputs per reader (a few KB each),
so that fuzzing starts from the formats' real structure, and
tests/common/data/hdf5_sparse.h5. The committed corpus is this script's
output (plus the regression inputs added by hand, named regression-*); rerun
it after a format change:

    /usr/bin/python3 tests/fuzz/make_corpus.py

Needs numpy and h5py (Debian python3-numpy, python3-h5py).
"""
import argparse
import os
import struct
import sys

import h5py
import numpy as np

ROOT = os.path.abspath(os.path.join(os.path.dirname(__file__), "..", ".."))
KNEE = os.path.join(ROOT, "data", "models", "knee_parametric")
TRIAL = os.path.join(ROOT, "data", "trials", "synthetic_gait")


def read_binary_stl(path):
    """(triangles, 3, 3) float32 corners of a binary STL [file units]."""
    with open(path, "rb") as f:
        data = f.read()
    n = struct.unpack_from("<I", data, 80)[0]
    tri = np.frombuffer(data, dtype=np.dtype([("n", "<f4", 3), ("v", "<f4", (3, 3)), ("a", "<u2")]),
                        count=n, offset=84)
    return np.array(tri["v"])


def weld(corners):
    """Unique vertices (first appearance order) and faces of STL corners."""
    index, verts, faces = {}, [], []
    for t in corners:
        f = []
        for p in t:
            key = tuple(float(x) for x in p)
            if key not in index:
                index[key] = len(verts)
                verts.append(key)
            f.append(index[key])
        faces.append(f)
    return np.array(verts), np.array(faces, dtype=np.int32)


def write(path, content):
    os.makedirs(os.path.dirname(path), exist_ok=True)
    mode = "wb" if isinstance(content, bytes) else "w"
    with open(path, mode) as f:
        f.write(content)


def fmt(x):
    return repr(float(x))


def meshes(out):
    corners = read_binary_stl(os.path.join(KNEE, "coarse", "patella_cartilage.stl"))[:12]
    V, F = weld(corners)
    # STL binary and ASCII (the binary header must not start with "solid").
    header = b"binary STL from the bundled patella cartilage (arthrosim fuzz corpus)".ljust(80, b" ")
    body = b"".join(struct.pack("<3f", 0, 0, 0) + t.astype("<f4").tobytes() + b"\0\0" for t in corners)
    write(os.path.join(out, "mesh_stl", "patella12_binary.stl"), header + struct.pack("<I", len(corners)) + body)
    lines = ["solid patella"]
    for t in corners:
        lines += ["  facet normal 0 0 1", "    outer loop"]
        lines += ["      vertex %s %s %s" % tuple(fmt(x) for x in p) for p in t]
        lines += ["    endloop", "  endfacet"]
    lines.append("endsolid patella")
    write(os.path.join(out, "mesh_stl", "patella12_ascii.stl"), "\n".join(lines) + "\n")
    # Binary file whose header starts with "solid" (exporters do this).
    write(os.path.join(out, "mesh_stl", "patella4_binary_solid_header.stl"),
          b"solid exported".ljust(80, b" ") + struct.pack("<I", 4) +
          b"".join(struct.pack("<3f", 0, 0, 0) + t.astype("<f4").tobytes() + b"\0\0" for t in corners[:4]))
    # OBJ: vertices, a comment, vt/vn, faces in the index forms the reader takes.
    obj = ["# patella cartilage patch (arthrosim fuzz corpus)", "o patch", "mtllib none.mtl"]
    obj += ["v %s %s %s" % tuple(fmt(x) for x in p) for p in V]
    obj += ["vt 0 0", "vn 0 0 1", "s off", "usemtl none"]
    for k, f in enumerate(F):
        if k % 3 == 0:
            obj.append("f %d %d %d" % tuple(i + 1 for i in f))
        elif k % 3 == 1:
            obj.append("f %d/1 %d/1/1 %d//1" % tuple(i + 1 for i in f))
        else:
            obj.append("f %d %d %d  # negative" % tuple(i - len(V) for i in f))
    obj.append("f 1 2 3 4")  # a quad, fan triangulated
    write(os.path.join(out, "mesh_obj", "patella_patch.obj"), "\n".join(obj) + "\n")
    quad = open(os.path.join(ROOT, "data", "scenes", "cantilever_plate.obj")).read()
    write(os.path.join(out, "mesh_obj", "cantilever_plate.obj"), quad)
    # PLY ascii and binary little endian (float and double vertices, uchar/int lists).
    def ply_header(fmt_name, vtype, extra=""):
        return ("ply\nformat %s 1.0\ncomment arthrosim fuzz corpus\nelement vertex %d\n"
                "property %s x\nproperty %s y\nproperty %s z\n%selement face %d\n"
                "property list uchar int vertex_indices\nend_header\n" %
                (fmt_name, len(V), vtype, vtype, vtype, extra, len(F)))
    ascii_ply = ply_header("ascii", "double") + "".join("%s %s %s\n" % tuple(fmt(x) for x in p) for p in V) + \
        "".join("3 %d %d %d\n" % tuple(f) for f in F)
    write(os.path.join(out, "mesh_ply", "patella_ascii.ply"), ascii_ply)
    binary = ply_header("binary_little_endian", "float").encode() + V.astype("<f4").tobytes() + \
        b"".join(struct.pack("<B3i", 3, *f) for f in F)
    write(os.path.join(out, "mesh_ply", "patella_binary_float.ply"), binary)
    header = ("ply\nformat binary_little_endian 1.0\nelement vertex %d\nproperty double x\nproperty double y\n"
              "property double z\nproperty uchar red\nelement face %d\nproperty list ushort uint vertex_index\n"
              "element edge 1\nproperty int vertex1\nproperty int vertex2\nend_header\n" % (len(V), len(F)))
    body = b"".join(struct.pack("<3dB", *p, 7) for p in V) + b"".join(struct.pack("<H3I", 3, *f) for f in F) + \
        struct.pack("<2i", 0, 1)
    write(os.path.join(out, "mesh_ply", "patella_binary_double_extra.ply"), header.encode() + body)
    # Legacy VTK polydata with point and cell fields.
    vtk = ["# vtk DataFile Version 3.0", "patella (arthrosim fuzz corpus)", "ASCII", "DATASET POLYDATA",
           "POINTS %d double" % len(V)]
    vtk += ["%s %s %s" % tuple(fmt(x) for x in p) for p in V]
    vtk.append("POLYGONS %d %d" % (len(F), 4 * len(F)))
    vtk += ["3 %d %d %d" % tuple(f) for f in F]
    vtk += ["LINES 1 3", "2 0 1", "POINT_DATA %d" % len(V), "SCALARS thickness_mm double 1", "LOOKUP_TABLE default"]
    vtk += ["%g" % (1.0 + 0.1 * i) for i in range(len(V))]
    vtk += ["NORMALS n double"] + ["0 0 1"] * len(V)
    vtk += ["CELL_DATA %d" % len(F), "VECTORS load double"] + ["0 -1 0"] * len(F)
    write(os.path.join(out, "mesh_vtk", "patella_fields.vtk"), "\n".join(vtk) + "\n")


def storage_head(path, rows):
    """A .mot file cut to its header and first `rows` rows (nRows adjusted)."""
    out = []
    with open(path) as f:
        lines = f.read().splitlines()
    end = lines.index("endheader")
    for line in lines[:end + 1]:
        out.append("nRows=%d" % rows if line.startswith("nRows=") else line)
    out += lines[end + 1:end + 2 + rows]
    return out


def storage(out):
    ik = storage_head(os.path.join(TRIAL, "ik.mot"), 8)
    write(os.path.join(out, "storage", "ik_head.mot"), "\n".join(ik) + "\n")
    grf = storage_head(os.path.join(TRIAL, "grf.mot"), 8)
    write(os.path.join(out, "storage", "grf_head.mot"), "\r\n".join(grf) + "\r\n")
    # OpenSim 4 style, state paths as labels, trailing blank line.
    sto = ["[activations]", "inDegrees=no", "DataType=double", "version=3", "OpenSimVersion=4.4", "endheader",
           "time\t/forceset/vasmed/activation\t/jointset/knee_r/knee_angle_r/value\tknee_angle_r_moment",
           "0\t0.01\t0.1\t1.5", "0.01\t0.02\t0.2\tnan", "0.02\t0.03\t0.3\t-inf", ""]
    write(os.path.join(out, "storage", "opensim4_paths.sto"), "\n".join(sto) + "\n")


def trials(out):
    yaml_lines = open(os.path.join(TRIAL, "trial.yaml")).read().splitlines()
    ik = storage_head(os.path.join(TRIAL, "ik.mot"), 10)
    grf = storage_head(os.path.join(TRIAL, "grf.mot"), 10)
    plain = [l for l in yaml_lines if not l.startswith("#") and not l.startswith("periodic")]
    text = "\n".join(plain + ["@@ ik.mot"] + ik + ["@@ grf.mot"] + grf) + "\n"
    write(os.path.join(out, "trial", "synthetic_head.txt"), text)
    # Knee loads instead of ground reactions, leg overrides, a negated column.
    desc = [l for l in plain if not l.startswith("grf_file") and not l.startswith("column.grf")]
    desc = [l.replace("column.knee_flexion: knee_angle_r", "column.knee_flexion: -knee_angle_r") for l in desc]
    desc += ["knee_loads_file: loads.sto", "leg.thigh_length_m: 0.41", "leg.hip_y_m: -0.07"]
    desc += ["column.knee_%s: %s" % (q, q) for q in
             ("force_x", "force_y", "force_z", "moment_x", "moment_y", "moment_z")]
    loads = ["knee loads", "version=1", "nRows=10", "nColumns=7", "inDegrees=no", "endheader",
             "time\tforce_x\tforce_y\tforce_z\tmoment_x\tmoment_y\tmoment_z"]
    loads += ["%.2f\t%d\t-700\t10\t1\t2\t3" % (0.01 * i, 5 * i) for i in range(10)]
    # One "cycle" of 0.09 s: the last row repeats the first one's posture.
    cycle = list(ik)
    first = cycle[-10].split("\t")
    cycle[-1] = "\t".join(["0.09000000"] + first[1:])
    write(os.path.join(out, "trial", "knee_loads_periodic.txt"),
          "\n".join(["periodic: true"] + desc + ["@@ ik.mot"] + cycle + ["@@ loads.sto"] + loads) + "\n")


def scenes(out):
    for name in ("osmotic.yaml", "cantilever_plate.yaml"):
        write(os.path.join(out, "scene", name), open(os.path.join(ROOT, "data", "scenes", name)).read())
    # The demo without its comments (the keys are what matters).
    demo = [l for l in open(os.path.join(ROOT, "data", "scenes", "demo.yaml")).read().splitlines()
            if not l.lstrip().startswith("#")]
    write(os.path.join(out, "scene", "demo_keys.yaml"), "\n".join(demo) + "\n")


def urdf(out):
    text = open(os.path.join(KNEE, "knee_coarse.urdf")).read()
    lines = text.splitlines()
    # Header, links, the knee's six joints, patella joints, hip/ankle, prescribed.
    keep = [l for l in lines if "arthrosim:ligament" not in l and "<bundle" not in l and
            "arthrosim:muscle" not in l and "<point" not in l and "</arthrosim:" not in l and
            "<!--" not in l.strip()[:4] and "Parametric right knee" not in l]
    keep = [l for l in keep if l.strip() != "</robot>"]
    small = [l for l in keep if "arthrosim:surface" not in l and "arthrosim:contact" not in l]
    extras = [
        '  <arthrosim:surface name="patella_cartilage" body="patella" mesh="coarse/patella_cartilage.stl" '
        'thickness_csv="coarse/patella_cartilage_thickness.csv" frame="reference"/>',
        '  <arthrosim:surface name="tibia_lateral_cartilage" body="tibia" mesh="coarse/tibia_lateral_cartilage.stl" '
        'unit="mm" thickness_mm="3" frame="reference"/>',
        '  <arthrosim:contact name="tp" casting="tibia_lateral_cartilage" target="patella_cartilage" '
        'youngs_modulus_mpa="10" poisson_ratio="0.45" law="nonlinear" max_overlap_factor="0.5"/>',
        '  <arthrosim:wrap_cylinder name="condyle" body="femur" xyz="0 -0.02 0" rpy="0 0 0" radius="0.025"/>',
        '  <arthrosim:ligament name="PT" stiffness="3000" damping="0.003">',
        '    <bundle frame="reference" reference_strain="0.02"><point body="patella" xyz="0.041 0.005 -0.008"/>'
        '<point body="tibia" xyz="0.022 -0.041 -0.002"/></bundle>',
        '    <bundle slack_length="0.05" stiffness="100"><point body="patella" xyz="0.041 0.005 0.008"/>'
        '<point body="tibia" xyz="0.022 -0.041 0.010"/></bundle>',
        '  </arthrosim:ligament>',
        '  <arthrosim:muscle name="bifemlh" max_isometric_force="1000" optimal_fiber_length="0.1" '
        'tendon_slack_length="0.3" frame="reference" wrap="condyle">',
        '    <point body="pelvis" xyz="-0.1 0.43 0.07"/>',
        '    <point body="tibia" xyz="-0.03 -0.04 0.03"/>',
        '  </arthrosim:muscle>',
        '</robot>',
    ]
    text = "\n".join(small + extras) + "\n"
    write(os.path.join(out, "urdf", "knee_small.urdf"), text)
    # The prepared target's model (prepared_fuzz.cc) is the same file.
    write(os.path.join(ROOT, "tests", "fuzz", "knee_small.urdf"), text)
    # Only the kinematic tree.
    tree = [l for l in small if "arthrosim:" not in l or "<robot" in l] + ["</robot>"]
    write(os.path.join(out, "urdf", "tree_only.urdf"), "\n".join(tree) + "\n")


class H5Spec:
    """Encoder of the h5spec records that tests/fuzz/h5spec.h decodes (see
    there): builds the bytes of a fuzz input describing an HDF5 file."""
    TYPES = {"f64": (0, "<d"), "f64be": (1, ">d"), "f32": (2, "<f"), "i32": (3, "<i"), "i64": (4, "<q"),
             "u8": (5, "<B"), "i16be": (6, ">h"), "u32": (7, "<I"), "str": (8, None), "fixed": (9, None),
             "compound": (10, None)}

    def __init__(self):
        self.data = bytearray()
        self.groups = ["/"]
        self.objects = ["/"]

    def _name(self, name):
        assert 0 < len(name) < 32
        self.data += bytes([len(name)]) + name.encode()

    def _text(self, text):
        b = text.encode()
        assert len(b) < 64
        self.data += bytes([len(b)]) + b

    def _path(self, parent, name):
        p = self.groups[parent]
        return ("/" if p == "/" else p + "/") + name

    def _typed(self, kind, dims, values, fixed_size=8):
        code, fmt_ = self.TYPES[kind]
        self.data.append(code)
        if kind == "fixed":
            self.data.append(fixed_size - 1)
        self.data.append(len(dims))
        self.data += bytes(dims)
        return code, fmt_

    def _values(self, kind, fmt_, values, fixed_size=8):
        if kind == "str":
            for v in values:
                self._text(v)
        elif kind == "fixed":
            for v in values:
                self.data += v.encode().ljust(fixed_size, b"\0")[:fixed_size]
        elif kind == "compound":
            for a, b in values:
                self.data += struct.pack("<di", a, b)
        else:
            for v in values:
                self.data += struct.pack(fmt_, v)

    def group(self, parent, name):
        self.data += bytes([0, parent])
        self._name(name)
        path = self._path(parent, name)
        self.groups.append(path)
        self.objects.append(path)
        return len(self.groups) - 1

    def dataset(self, parent, name, kind, dims, values, layout=0, fixed_size=8):
        self.data += bytes([1, parent])
        self._name(name)
        _, fmt_ = self._typed(kind, dims, values, fixed_size)
        self.data.append(layout)
        self._values(kind, fmt_, values, fixed_size)
        self.objects.append(self._path(parent, name))
        return len(self.objects) - 1

    def attribute(self, obj, name, kind, values, dims=(), fixed_size=8):
        self.data += bytes([2, 0, obj])
        self._name(name)
        _, fmt_ = self._typed(kind, list(dims), values, fixed_size)
        self._values(kind, fmt_, values, fixed_size)

    def soft_link(self, parent, name, target):
        self.data += bytes([3, parent])
        self._name(name)
        self._text(target)

    def hard_link(self, parent, name, obj):
        self.data += bytes([4, parent])
        self._name(name)
        self.data.append(obj)


def prepared(out):
    """Prepared-model files (as h5spec) for tests/fuzz/knee_small.urdf (its two
    contact surfaces): one triangle each, centred where the model's own meshes
    are (the reader checks that to 2 mm), and the same with the surface's
    first 8 welded vertices and the triangles among them."""
    surfaces = [("patella", "patella_cartilage.stl", "patella"),
                ("tibia_lateral", "tibia_lateral_cartilage.stl", "tibia")]
    for variant in ("one_triangle", "patch"):
        h = H5Spec()
        h.attribute(0, "schema", "str", ["arthrosim prepared model 1"])
        h.attribute(0, "length_unit", "str", ["m"])
        g = h.group(0, "surfaces")
        h.dataset(g, "names", "str", [2], [s[0] for s in surfaces])
        for name, stl, bone in surfaces:
            V, F = weld(read_binary_stl(os.path.join(KNEE, "coarse", stl)))
            if variant == "one_triangle":
                c = V.mean(axis=0) * 1e-3
                verts = np.array([c + [0.002, 0, 0], c + [-0.001, 0.002, 0], c + [-0.001, -0.002, 0]])
                faces = np.array([[0, 1, 2]])
            else:
                # The mean of 8 vertices lies within 2 mm of the whole mesh's only
                # by chance; move them so their centroid is the mesh's.
                verts = V[:8] * 1e-3
                verts = verts - verts.mean(axis=0) + V.mean(axis=0) * 1e-3
                faces = np.array([f for f in F if max(f) < 8][:8])
            sg = h.group(g, name)
            h.attribute(h.objects.index(h.groups[sg]), "source_file", "str", ["coarse/" + stl])
            h.attribute(h.objects.index(h.groups[sg]), "bone", "str", [bone])
            tg = h.group(sg, "triangles")
            h.dataset(tg, "vertices", "f64", [len(verts), 3], [float(x) for x in verts.ravel()])
            h.dataset(tg, "faces", "i32", [len(faces), 3], [int(x) for x in faces.ravel()])
            h.dataset(tg, "thickness", "f64", [len(verts)], [0.002] * len(verts), layout=1)
        write(os.path.join(out, "prepared", "small_%s.h5spec" % variant), bytes(h.data))


def hdf5(out):
    """What the stage files hold, as h5spec: vectors, matrices, rank-3 frames
    with the frame counter, strings, attributes of each type; then the other
    types, layouts and links the reader must refuse or survive."""
    h = H5Spec()
    h.attribute(0, "schema", "str", ["arthrosim kinematics 1"])
    h.attribute(0, "format_version", "i64", [1])
    h.attribute(0, "body_mass_kg", "f64", [61.0])
    h.dataset(0, "time", "f64", [4], [0.0, 0.01, 0.02, 0.03])
    b = h.group(0, "bodies")
    t = h.group(b, "tibia")
    X = np.tile(np.eye(4), (4, 1, 1))
    X[:, 1, 3] = [0.0, 0.001, 0.002, 0.003]
    xw = h.dataset(t, "X_W", "f64", [4, 4, 4], [float(x) for x in X.ravel()], layout=1)
    h.attribute(xw, "arthrosim_frames_complete", "i64", [3])
    c = h.group(0, "coordinates")
    h.dataset(c, "names", "str", [2], ["knee_flexion", "knee_tx"])
    h.dataset(c, "q", "f64", [4, 2], [0.0] * 8, layout=2)
    s = h.group(0, "solver")
    h.dataset(s, "status", "i32", [4], [0, 0, 1, 0])
    h.dataset(s, "faces", "i32", [1, 3], [0, 1, 2])
    write(os.path.join(out, "hdf5", "kinematics_like.h5spec"), bytes(h.data))
    h = H5Spec()
    h.attribute(0, "fixed", "fixed", ["abcdefgh"], fixed_size=8)
    h.attribute(0, "pair", "f64", [1.0, 2.0], dims=[2])
    h.attribute(0, "words", "str", ["a", "b"], dims=[2])
    h.dataset(0, "f32", "f32", [2, 3], [1.5] * 6)
    h.dataset(0, "big_endian", "f64be", [3], [1.0, 2.0, 3.0])
    h.dataset(0, "i16be", "i16be", [2], [-1, 7])
    h.dataset(0, "u32", "u32", [2], [1, 4000000000])
    h.dataset(0, "bytes", "u8", [4], [1, 2, 3, 4])
    h.dataset(0, "labels", "fixed", [2], ["femur", "tibia"], fixed_size=6)
    h.dataset(0, "records", "compound", [2], [(1.0, 2), (3.0, 4)])
    h.dataset(0, "scalar", "f64", [], [42.0])
    h.dataset(0, "empty", "f64", [0, 3], [], layout=1)
    # Sparse: (2^24, 3) declared, nothing written (reads as fill values).
    h.dataset(0, "sparse", "f64", [0xF4, 3], [], layout=1)
    g = h.group(0, "g")
    h.soft_link(g, "dangling", "/no/such/object")
    h.soft_link(g, "up", "/g")
    h.hard_link(g, "root", 0)
    write(os.path.join(out, "hdf5", "types_and_links.h5spec"), bytes(h.data))
    # Real files for the raw-bytes target (hdf5_raw, not run by CI).
    src = os.path.join(ROOT, "tests", "common", "data", "h5py_interop.h5")
    write(os.path.join(out, "hdf5_raw", "h5py_interop.h5"), open(src, "rb").read())


def test_data():
    """tests/common/data/hdf5_sparse.h5 for tests/common/fuzz_inputs_test.cc:
    datasets declaring far more elements than the file stores (never
    written: HDF5 reads them as fill values), and two that are stored."""
    path = os.path.join(ROOT, "tests", "common", "data", "hdf5_sparse.h5")
    with h5py.File(path, "w") as f:
        f.create_dataset("sparse_vector", shape=(2 ** 40,), maxshape=(None,), chunks=(1024,), dtype="<f8", track_times=False)
        f.create_dataset("sparse_matrix", shape=(2 ** 31, 3), chunks=(1024, 3), dtype="<i4", track_times=False)
        f.create_dataset("sparse_strings", shape=(2 ** 30,), chunks=(1024,), dtype=h5py.string_dtype(), track_times=False)
        f.create_dataset("compressed", data=np.zeros(1000), compression="gzip", track_times=False)
        f.create_dataset("written", data=np.array([1.0, 2.0, 3.0]), track_times=False)


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--out", default=os.path.join(ROOT, "tests", "fuzz", "corpus"),
                    help="corpus root (default: tests/fuzz/corpus)")
    a = ap.parse_args()
    for make in (meshes, storage, trials, scenes, urdf, prepared, hdf5):
        make(a.out)
    test_data()
    for target in sorted(os.listdir(a.out)):
        files = os.listdir(os.path.join(a.out, target))
        size = sum(os.path.getsize(os.path.join(a.out, target, n)) for n in files)
        print("%-10s %2d files %6d bytes" % (target, len(files), size))
    return 0


if __name__ == "__main__":
    sys.exit(main())
