#pragma once
// Surface mesh files. Inside arthrosim coordinates are metres; files carry a
// length unit (millimetres by default, as MR/CT segmentations and CAD exports
// usually do) that is converted at this edge and nowhere else.
//
// Read:  STL (ASCII and binary, detected from the content, not the first word:
//        binary files may start with "solid"), OBJ (v/f; polygons are fan
//        triangulated; vt/vn/vp/g/o/s/usemtl/mtllib and comments ignored;
//        1-based and negative indices, "i/j/k" index forms), PLY (ascii and
//        binary_little_endian; vertex x,y,z as float or double; face list with
//        uchar/char/ushort/short/int/uint counts and int/uint/short/ushort/char/
//        uchar indices; other elements and properties are skipped).
//        Legacy VTK ASCII polydata (see read_vtk). Quad meshes (shells):
//        read_quad_obj (with vn, g), read_quad_vtk (with fields).
// Write: STL (binary or ASCII), OBJ, PLY (binary or ASCII), legacy VTK ASCII
//        polydata (with optional point/cell data fields); OBJ and VTK for quad
//        meshes too.
//
// Errors throw InputError: "file:line: error: expected ..., found ..." for text
// formats; for binary content the message names the byte offset and the
// face/vertex index. An empty mesh (no triangles) is an error on read.
#include <map>
#include <string>
#include <vector>

#include "common/mesh.h"

namespace arthrosim::common {

/// Length unit of the numbers in a mesh file.
enum class LengthUnit { kMillimetre, kCentimetre, kMetre };

/// Metres per file unit (1e-3 for mm, 1e-2 for cm, 1 for m).
double metres_per_unit(LengthUnit unit);
/// "mm", "cm", "m".
std::string unit_name(LengthUnit unit);
/// Parses "mm", "cm", "m" (also "millimetre(s)", "centimetre(s)", "metre(s)",
/// "meter(s)"); throws InputError naming the accepted values otherwise.
LengthUnit parse_length_unit(const std::string& text);

struct MeshReadOptions {
  /// Unit of the coordinates in the file; values are multiplied by
  /// metres_per_unit(unit) so the mesh is in metres. Default: millimetres.
  LengthUnit unit = LengthUnit::kMillimetre;
  /// STL stores every triangle's corners separately. When true, corners with
  /// bit-identical coordinates are merged into one vertex (numbered in order of
  /// first appearance, so the result is deterministic). When false, the mesh
  /// has 3 vertices per triangle.
  bool weld_stl_vertices = true;
};

struct MeshWriteOptions {
  /// Unit of the numbers written (mesh metres are divided by
  /// metres_per_unit(unit)). Default millimetres, matching MeshReadOptions so a
  /// write/read round trip with default options is the identity.
  LengthUnit unit = LengthUnit::kMillimetre;
  /// Significant digits for ASCII formats (17 = round-trip exact doubles).
  int precision = 17;
};

enum class MeshFormat { kStl, kObj, kPly, kVtk };
/// Format from the file extension (case-insensitive .stl .obj .ply .vtk);
/// throws InputError naming the file and the supported extensions otherwise.
MeshFormat format_from_extension(const std::string& path);

/// Reads a triangle mesh (format from the extension: .stl .obj .ply .vtk).
/// The mesh name is the path.
TriangleMesh read_mesh(const std::string& path, const MeshReadOptions& options = {});
TriangleMesh read_stl(const std::string& path, const MeshReadOptions& options = {});
TriangleMesh read_obj(const std::string& path, const MeshReadOptions& options = {});
TriangleMesh read_ply(const std::string& path, const MeshReadOptions& options = {});

/// The same parsers on in-memory file content; `name` is used in messages and
/// as the mesh name.
TriangleMesh parse_stl(const std::string& content, const std::string& name,
                       const MeshReadOptions& options = {});
TriangleMesh parse_obj(const std::string& content, const std::string& name,
                       const MeshReadOptions& options = {});
TriangleMesh parse_ply(const std::string& content, const std::string& name,
                       const MeshReadOptions& options = {});

enum class StlEncoding { kBinary, kAscii };
enum class PlyEncoding { kBinaryLittleEndian, kAscii };

/// A named field for VTK output: values has one row per point (or per cell)
/// and 1 column (scalars) or 3 columns (vectors).
struct VtkField {
  enum class Location { kPoint, kCell };
  std::string name;  ///< no whitespace
  Eigen::MatrixXd values;
  Location location = Location::kPoint;
};

/// Legacy VTK reader for what write_vtk writes (and similar files): ASCII,
/// DATASET POLYDATA, POINTS + POLYGONS (fan triangulated; VERTICES/LINES
/// skipped), POINT_DATA/CELL_DATA with SCALARS (1 component), VECTORS and
/// NORMALS. Field values are not unit-converted; cell fields refer to the
/// file's polygons (before triangulation). `fields` may be null.
TriangleMesh read_vtk(const std::string& path, const MeshReadOptions& options = {},
                      std::vector<VtkField>* fields = nullptr);
TriangleMesh parse_vtk(const std::string& content, const std::string& name,
                       const MeshReadOptions& options = {}, std::vector<VtkField>* fields = nullptr);

/// Face groups of a quad OBJ ('g' lines): group name -> quad indices.
using FaceGroups = std::map<std::string, std::vector<int>>;

/// Quad OBJ (shell meshes): 'v x y z' and 4-node 'f' lines (index forms i,
/// i/j, i/j/k, i//k; negative = relative); 'vn' vertex normals referenced by
/// the faces (i/j/k, i//k) go to `normals` (unit rows, one per vertex) when
/// every face gives them (left empty when none does); 'g' lines name the
/// groups of the faces after them (into `groups`); comments,
/// vt/vp/o/s/usemtl/mtllib/l lines are skipped. Anything else, a face that is
/// not a quad, normals on some faces only, two different normals of one
/// vertex or a normal on the side opposite to the faces' orientation
/// (counter-clockwise seen from the normal) is an InputError with file:line.
QuadMesh read_quad_obj(const std::string& path, const MeshReadOptions& options = {}, Points3* normals = nullptr,
                       FaceGroups* groups = nullptr);
/// Legacy VTK ASCII polydata whose POLYGONS are all quads (header and
/// sections as read_vtk; POINT_DATA/CELL_DATA fields into `fields`, cell
/// fields per quad). A polygon that is not a quad is an InputError with
/// file:line.
QuadMesh read_quad_vtk(const std::string& path, const MeshReadOptions& options = {},
                       std::vector<VtkField>* fields = nullptr);
QuadMesh parse_quad_vtk(const std::string& content, const std::string& name, const MeshReadOptions& options = {},
                        std::vector<VtkField>* fields = nullptr);

/// Writers throw InputError if the file cannot be written, and if a mesh has
/// non-finite coordinates or out-of-range indices (a writer never produces a
/// file its own reader would reject).
void write_stl(const TriangleMesh& mesh, const std::string& path,
               StlEncoding encoding = StlEncoding::kBinary, const MeshWriteOptions& options = {});
void write_obj(const TriangleMesh& mesh, const std::string& path, const MeshWriteOptions& options = {});
void write_obj(const QuadMesh& mesh, const std::string& path, const MeshWriteOptions& options = {});
/// Legacy VTK (ASCII, DATASET POLYDATA). Field sizes must match the point or
/// cell count (InputError otherwise). Field values are written as given (no
/// unit conversion: put the unit in the field name).
void write_vtk(const TriangleMesh& mesh, const std::string& path,
               const std::vector<VtkField>& fields = {}, const MeshWriteOptions& options = {});
void write_vtk(const QuadMesh& mesh, const std::string& path,
               const std::vector<VtkField>& fields = {}, const MeshWriteOptions& options = {});
void write_ply(const TriangleMesh& mesh, const std::string& path,
               PlyEncoding encoding = PlyEncoding::kBinaryLittleEndian, const MeshWriteOptions& options = {});
/// Writes by extension: .stl (binary), .obj, .ply (binary), .vtk.
void write_mesh(const TriangleMesh& mesh, const std::string& path, const MeshWriteOptions& options = {});

}  // namespace arthrosim::common
