// Mesh file round trips in every format and unit, and parser errors with
// file/line (text) or byte offset/face index (binary).
#include "common/mesh_io.h"

#include <gtest/gtest.h>

#include <cstring>
#include <filesystem>
#include <fstream>
#include <sstream>

#include "common/error.h"
#include "tests/common/test_meshes.h"

namespace arthrosim::common {
namespace {

namespace fs = std::filesystem;

std::string out_dir() {
  const fs::path d = fs::path(ARTHROSIM_BINARY_DIR) / "tests" / "mesh_io_test_files";
  fs::create_directories(d);
  return d.string();
}

std::string file_bytes(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  std::ostringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

void put_bytes(const std::string& path, const std::string& bytes) {
  std::ofstream out(path, std::ios::binary);
  out.write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
}

// The sphere used for round trips: 30 mm radius, irregular coordinates so every
// digit matters.
TriangleMesh sphere() { return testing::perturbed_sphere(2, 0.03, 0.05, 99); }

// Same vertices (to a relative tolerance) and identical triangles.
void expect_same_mesh(const TriangleMesh& a, const TriangleMesh& b, double rel_tol) {
  ASSERT_EQ(a.num_vertices(), b.num_vertices());
  ASSERT_EQ(a.num_triangles(), b.num_triangles());
  EXPECT_EQ(a.F, b.F);
  const double scale = a.V.cwiseAbs().maxCoeff();
  EXPECT_LE((a.V - b.V).cwiseAbs().maxCoeff(), rel_tol * scale);
}

// Same triangles geometrically (STL loses the vertex numbering: welded vertices
// are numbered in order of first appearance), corner by corner.
void expect_same_triangles(const TriangleMesh& a, const TriangleMesh& b, double abs_tol) {
  ASSERT_EQ(a.num_triangles(), b.num_triangles());
  double worst = 0.0;
  for (int t = 0; t < a.num_triangles(); ++t)
    for (int k = 0; k < 3; ++k) worst = std::max(worst, (a.vertex(a.F(t, k)) - b.vertex(b.F(t, k))).norm());
  EXPECT_LE(worst, abs_tol);
}

TEST(MeshIo, BinaryStlRoundTripWeldsVertices) {
  const TriangleMesh m = sphere();
  const std::string path = out_dir() + "/sphere_binary.stl";
  write_stl(m, path, StlEncoding::kBinary);
  EXPECT_EQ(fs::file_size(path), 84u + 50u * m.num_triangles());
  const TriangleMesh r = read_stl(path);
  // Welding recovers the shared vertices exactly (each is written from one value).
  EXPECT_EQ(r.num_vertices(), m.num_vertices());
  // float32 in the file: relative rounding 2^-24 = 6e-8 of a 33 mm coordinate
  // (in mm), i.e. < 2e-9 m; allow 4e-9 m.
  expect_same_triangles(m, r, 4e-9);
  EXPECT_EQ(r.name, path);
  // Without welding every triangle has its own three vertices.
  MeshReadOptions no_weld;
  no_weld.weld_stl_vertices = false;
  EXPECT_EQ(read_stl(path, no_weld).num_vertices(), 3 * m.num_triangles());
}

TEST(MeshIo, AsciiStlRoundTripIsExactTo17Digits) {
  const TriangleMesh m = sphere();
  const std::string path = out_dir() + "/sphere_ascii.stl";
  write_stl(m, path, StlEncoding::kAscii);
  EXPECT_EQ(file_bytes(path).rfind("solid", 0), 0u);
  const TriangleMesh r = read_mesh(path);
  EXPECT_EQ(r.num_vertices(), m.num_vertices());
  // 17 significant digits round-trip a double; the mm <-> m scaling adds at most
  // a few ulp: 1e-15 relative of 0.033 m.
  expect_same_triangles(m, r, 1e-15 * 0.04);
}

TEST(MeshIo, BinaryStlStartingWithSolidIsReadAsBinary) {
  // Several exporters put "solid <name>" in the 80-byte binary header.
  const TriangleMesh m = sphere();
  const std::string path = out_dir() + "/solid_header.stl";
  write_stl(m, path, StlEncoding::kBinary);
  std::string bytes = file_bytes(path);
  const std::string fake = "solid exported_by_some_cad_tool";
  std::memcpy(bytes.data(), fake.data(), fake.size());
  put_bytes(path, bytes);
  const TriangleMesh r = read_stl(path);
  EXPECT_EQ(r.num_triangles(), m.num_triangles());
  expect_same_triangles(m, r, 4e-9);
}

TEST(MeshIo, ObjRoundTripKeepsNumbering) {
  const TriangleMesh m = sphere();
  const std::string path = out_dir() + "/sphere.obj";
  write_obj(m, path);
  expect_same_mesh(m, read_mesh(path), 1e-15);
}

TEST(MeshIo, PlyRoundTripBinaryAndAscii) {
  const TriangleMesh m = sphere();
  for (auto enc : {PlyEncoding::kBinaryLittleEndian, PlyEncoding::kAscii}) {
    const std::string path = out_dir() + (enc == PlyEncoding::kAscii ? "/sphere_ascii.ply" : "/sphere_binary.ply");
    write_ply(m, path, enc);
    expect_same_mesh(m, read_mesh(path), 1e-15);
  }
}

TEST(MeshIo, VtkRoundTripWithFields) {
  const TriangleMesh m = sphere();
  const std::string path = out_dir() + "/sphere.vtk";
  VtkField thickness{"thickness_m", m.V.rowwise().norm() * 0.1, VtkField::Location::kPoint};
  VtkField normals{"normal", triangle_normals(m), VtkField::Location::kCell};
  write_vtk(m, path, {thickness, normals});
  std::vector<VtkField> fields;
  const TriangleMesh r = read_vtk(path, {}, &fields);
  expect_same_mesh(m, r, 1e-15);
  ASSERT_EQ(fields.size(), 2u);
  EXPECT_EQ(fields[0].name, "thickness_m");
  EXPECT_EQ(fields[0].location, VtkField::Location::kPoint);
  EXPECT_EQ(fields[0].values, thickness.values);  // 17 digits: exact
  EXPECT_EQ(fields[1].name, "normal");
  EXPECT_EQ(fields[1].location, VtkField::Location::kCell);
  EXPECT_EQ(fields[1].values, normals.values);
  // Field sizes are checked.
  VtkField wrong{"bad", Eigen::MatrixXd::Zero(3, 1), VtkField::Location::kPoint};
  EXPECT_THROW(write_vtk(m, path, {wrong}), InputError);
}

TEST(MeshIo, QuadMeshObjAndVtk) {
  const QuadMesh q = split_triangles_to_quads(sphere());
  // Both readers fan-triangulate polygons (0,1,2), (0,2,3): that is triangulate(q).
  const TriangleMesh expected = triangulate(q);
  const std::string obj = out_dir() + "/quads.obj";
  const std::string vtk = out_dir() + "/quads.vtk";
  write_obj(q, obj);
  write_vtk(q, vtk, {{"node_id", Eigen::VectorXd::LinSpaced(q.num_nodes(), 0, q.num_nodes() - 1)}});
  expect_same_mesh(expected, read_obj(obj), 1e-15);
  expect_same_mesh(expected, read_vtk(vtk), 1e-15);
  EXPECT_NE(file_bytes(obj).find("\nf 1 "), std::string::npos);
}

TEST(MeshIo, UnitsAreConvertedAtTheFileEdge) {
  const TriangleMesh m = sphere();
  const std::string path = out_dir() + "/units.obj";
  MeshWriteOptions in_metres;
  in_metres.unit = LengthUnit::kMetre;
  write_obj(m, path, in_metres);
  // Read the metre file as millimetres (the default): 1000x too small.
  const TriangleMesh as_mm = read_obj(path);
  EXPECT_NEAR(as_mm.V.cwiseAbs().maxCoeff(), 1e-3 * m.V.cwiseAbs().maxCoeff(), 1e-18);
  MeshReadOptions cm;
  cm.unit = LengthUnit::kCentimetre;
  EXPECT_NEAR(read_obj(path, cm).V(5, 1), 1e-2 * m.V(5, 1), 1e-17);
  MeshReadOptions metres;
  metres.unit = parse_length_unit("m");
  expect_same_mesh(m, read_obj(path, metres), 1e-15);
  EXPECT_EQ(parse_length_unit("millimetres"), LengthUnit::kMillimetre);
  EXPECT_THROW(parse_length_unit("inch"), InputError);
  // Default write is millimetres: numbers 1000x the metre values.
  const std::string mm_path = out_dir() + "/units_mm.obj";
  write_obj(m, mm_path);
  MeshReadOptions as_metres;
  as_metres.unit = LengthUnit::kMetre;
  EXPECT_NEAR(read_obj(mm_path, as_metres).V(0, 0), 1e3 * m.V(0, 0), 1e-12);
}

TEST(MeshIo, ObjPolygonsNegativeIndicesAndIgnoredStatements) {
  const std::string obj =
      "# a square and a pentagon\n"
      "mtllib x.mtl\no thing\n"
      "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\n"
      "vt 0 0\nvn 0 0 1\n"
      "g group\ns off\nusemtl m\n"
      "f 1/1/1 2/1/1 3/1/1 4/1/1\n"
      "v 2 0 0\nv 3 0 0\nv 3 1 0\nv 2.5 2 0\nv 2 1 0\n"
      "f -5//1 -4//1 -3//1 -2//1 -1//1 # trailing comment\n";
  const TriangleMesh m = parse_obj(obj, "inline.obj");
  ASSERT_EQ(m.num_vertices(), 9);
  ASSERT_EQ(m.num_triangles(), 2 + 3);
  EXPECT_EQ(m.F.row(1), Eigen::RowVector3i(0, 2, 3));
  EXPECT_EQ(m.F.row(2), Eigen::RowVector3i(4, 5, 6));
  EXPECT_EQ(m.F.row(4), Eigen::RowVector3i(4, 7, 8));
  // Millimetres by default: square of 1 mm^2 + pentagon 1 + 0.5 mm^2.
  EXPECT_NEAR(surface_area(m), 2.5e-6, 1e-20);
}

// Expects an InputError whose message contains every fragment.
void expect_error(const std::function<void()>& f, const std::vector<std::string>& fragments) {
  try {
    f();
    ADD_FAILURE() << "no InputError thrown";
  } catch (const InputError& e) {
    const std::string what = e.what();
    for (const auto& frag : fragments) EXPECT_NE(what.find(frag), std::string::npos) << "'" << frag << "' not in: " << what;
  }
}

TEST(MeshIo, ErrorsNameFileLineAndWhatWasFound) {
  // OBJ: bad face index on line 5.
  expect_error([] { parse_obj("v 0 0 0\nv 1 0 0\nv 0 1 0\n\nf 1 2 7\n", "bad.obj"); },
               {"bad.obj:5: error:", "1..3", "found 7"});
  expect_error([] { parse_obj("v 0 0 0\nv 1 x 0\n", "nonnum.obj"); }, {"nonnum.obj:2:", "expected a number", "'x'"});
  expect_error([] { parse_obj("v 0 0 0\nf 1 0 1\n", "zero.obj"); }, {"zero.obj:2:", "found 0"});
  expect_error([] { parse_obj("v 0 0 0\nv 1 0 0\nv 0 1 0\n", "empty.obj"); }, {"empty.obj", "at least one triangle"});
  expect_error([] { parse_obj("v 0 0 0\ncurv 0 1\n", "kw.obj"); }, {"kw.obj:2:", "'curv'"});
  // ASCII STL: non-numeric and NaN coordinates, missing keywords.
  const std::string facet = "solid t\n facet normal 0 0 1\n  outer loop\n   vertex 0 0 0\n   vertex 1 0 0\n";
  expect_error([&] { parse_stl(facet + "   vertex 0 abc 0\n  endloop\n endfacet\nendsolid\n", "t.stl"); },
               {"t.stl:6:", "expected a number", "'abc'"});
  expect_error([&] { parse_stl(facet + "   vertex 0 nan 0\n  endloop\n endfacet\nendsolid\n", "n.stl"); },
               {"n.stl:6:", "finite", "'nan'"});
  expect_error([&] { parse_stl(facet + "   vertex 0 1 0\n endfacet\nendsolid\n", "k.stl"); },
               {"k.stl:7:", "'endloop'", "'endfacet'"});
  expect_error([] { parse_stl("solid empty\nendsolid empty\n", "e.stl"); }, {"e.stl", "at least one triangle"});
  // Binary STL: truncated (count says 10 triangles, only 3.5 present).
  std::string bin(84 + 175, '\0');
  const uint32_t n = 10;
  std::memcpy(bin.data() + 80, &n, 4);
  expect_error([&] { parse_stl(bin, "trunc.stl"); },
               {"trunc.stl: error:", "truncated", "584 bytes for 10 triangles", "found 259", "triangle 3", "byte offset 234"});
  // Binary STL with a NaN coordinate in triangle 1.
  std::string bin2(84 + 100, '\0');
  const uint32_t two = 2;
  std::memcpy(bin2.data() + 80, &two, 4);
  const float nan = std::numeric_limits<float>::quiet_NaN();
  std::memcpy(bin2.data() + 84 + 50 + 12 + 4, &nan, 4);
  expect_error([&] { parse_stl(bin2, "nan.stl"); }, {"nan.stl", "triangle 1", "byte offset 150"});
  expect_error([] { parse_stl("garbage", "g.stl"); }, {"g.stl", "'solid'", "found 7 bytes"});
  // A truncated binary file whose header starts with "solid" is still
  // recognised as binary and reported as truncated.
  std::string solid_bin = bin;
  std::memcpy(solid_bin.data(), "solid part", 10);
  expect_error([&] { parse_stl(solid_bin, "sb.stl"); }, {"sb.stl: error:", "truncated", "triangle 3"});
  // PLY: unsupported format, bad index, truncated binary body.
  const std::string ply_head = "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
                               "property float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n";
  expect_error([&] { parse_ply(ply_head + "0 0 0\n1 0 0\n0 1 0\n3 0 1 3\n", "i.ply"); },
               {"i.ply:13:", "0..2", "face 0", "found 3"});
  expect_error([&] { parse_ply(ply_head + "0 0 0\n1 0 0\n0 q 0\n3 0 1 2\n", "q.ply"); }, {"q.ply:12:", "'q'"});
  std::string be = ply_head;
  be.replace(be.find("ascii"), 5, "binary_big_endian");
  expect_error([&] { parse_ply(be, "be.ply"); }, {"be.ply:2:", "ascii or binary_little_endian", "binary_big_endian"});
  std::string le = ply_head;
  le.replace(le.find("ascii"), 5, "binary_little_endian");
  expect_error([&] { parse_ply(le + std::string(20, '\0'), "t.ply"); }, {"t.ply", "truncated", "vertex 1", "byte offset"});
  // Unknown extension, missing file.
  expect_error([] { read_mesh("model.step"); }, {"model.step", ".stl, .obj, .ply or .vtk", "'.step'"});
  expect_error([] { read_mesh(out_dir() + "/does_not_exist.stl"); }, {"does_not_exist.stl", "readable"});
}

TEST(MeshIo, AsciiStlToleratesNanNormalsAndCrLf) {
  // Normals are recomputed, so exporters' "nan" normals of degenerate facets
  // are accepted; Windows line endings and upper-case keywords too.
  const std::string stl =
      "solid x\r\n facet normal nan nan nan\r\n  outer loop\r\n   vertex 0 0 0\r\n   vertex 1 0 0\r\n"
      "   vertex 0 1 0\r\n  endloop\r\n endfacet\r\n FACET NORMAL 0 0 1\r\n  OUTER LOOP\r\n   VERTEX 1 0 0\r\n"
      "   VERTEX 1 1 0\r\n   VERTEX 0 1 0\r\n  ENDLOOP\r\n ENDFACET\r\nendsolid x\r\n";
  const TriangleMesh m = parse_stl(stl, "crlf.stl");
  EXPECT_EQ(m.num_vertices(), 4);
  EXPECT_EQ(m.num_triangles(), 2);
  EXPECT_NEAR(surface_area(m), 1e-6, 1e-21);
  // Welded vertices are numbered in order of first appearance.
  EXPECT_EQ(m.F.row(0), Eigen::RowVector3i(0, 1, 2));
  EXPECT_EQ(m.F.row(1), Eigen::RowVector3i(1, 3, 2));
}

TEST(MeshIo, PlyWithExtraPropertiesElementsAndTypes) {
  // float x/y/z among other properties, uchar colours, an extra element, int
  // counts and uint indices, binary little endian.
  std::string ply =
      "ply\nformat binary_little_endian 1.0\ncomment test\nelement vertex 4\nproperty uchar red\n"
      "property double x\nproperty double y\nproperty double z\nproperty float confidence\n"
      "element face 2\nproperty list int uint vertex_indices\nproperty uchar flags\n"
      "element edge 1\nproperty int vertex1\nproperty int vertex2\nend_header\n";
  auto put = [&](const auto& v) { ply.append(reinterpret_cast<const char*>(&v), sizeof(v)); };
  const double P[4][3] = {{0, 0, 0}, {2, 0, 0}, {2, 2, 0}, {0, 2, 0}};
  for (const auto& p : P) {
    put(uint8_t{255});
    put(p[0]);
    put(p[1]);
    put(p[2]);
    put(0.5f);
  }
  put(int32_t{3});
  put(uint32_t{0}), put(uint32_t{1}), put(uint32_t{2});
  put(uint8_t{7});
  put(int32_t{3});
  put(uint32_t{0}), put(uint32_t{2}), put(uint32_t{3});
  put(uint8_t{7});
  put(int32_t{0}), put(int32_t{1});
  MeshReadOptions metres;
  metres.unit = LengthUnit::kMetre;
  const TriangleMesh m = parse_ply(ply, "extra.ply", metres);
  ASSERT_EQ(m.num_vertices(), 4);
  ASSERT_EQ(m.num_triangles(), 2);
  EXPECT_EQ(m.F.row(1), Eigen::RowVector3i(0, 2, 3));
  EXPECT_DOUBLE_EQ(surface_area(m), 4.0);
}

TEST(MeshIo, WritersRefuseNonFiniteMeshes) {
  TriangleMesh m = sphere();
  m.V(3, 0) = std::numeric_limits<double>::infinity();
  expect_error([&] { write_stl(m, out_dir() + "/inf.stl"); }, {"inf.stl", "vertex 3"});
  expect_error([&] { write_obj(sphere(), "/nonexistent_dir/x.obj"); }, {"/nonexistent_dir/x.obj", "writable"});
}

}  // namespace
}  // namespace arthrosim::common
