#pragma once
// XDMF (eXtensible Data Model and Format, version 3 schema, also read by the
// legacy XDMF 2 reader) descriptions of surface meshes and their fields stored
// in an HDF5 file, so that any arthrosim result opens (and animates) in
// ParaView. The XDMF file holds only XML "light data": every array is a
// reference "file.h5:/dataset" into the HDF5 file.
//
// Layout written:
//  - no time steps: one Grid per surface (a spatial Collection if several);
//  - time steps: a temporal Collection with one entry per step, each holding
//    the surfaces of that step with <Time Value="t"/>. Per-step arrays are
//    read from (n_steps x N) or (n_steps x N x 3) datasets through HyperSlab
//    DataItems that select row `step`; static arrays are referenced whole.
//
// The writer reads the dims of every referenced dataset from the open HDF5
// file and checks them (InputError naming the dataset, expected and found),
// so an XDMF file never points at something that does not exist.
#include <string>
#include <vector>

#include "common/hdf5.h"

namespace arthrosim::common {

enum class XdmfCenter { kNode, kCell };

/// A field on a surface. Its kind follows from the dataset dims:
///  per_step == false: (N) or (N x 1) scalar, (N x 3) vector;
///  per_step == true:  (n_steps x N) scalar, (n_steps x N x 3) vector;
/// N = number of nodes (kNode) or cells (kCell).
struct XdmfField {
  std::string name;     ///< as shown in ParaView
  std::string dataset;  ///< HDF5 dataset path
  XdmfCenter center = XdmfCenter::kNode;
  bool per_step = true;
};

/// kHexahedron: 8 nodes per cell in VTK order (corners 0-3 around one face,
/// 4-7 around the opposite face in the same rotational order, 4 above 0), for
/// volume meshes; kPolyvertex: a point cloud (e.g. movable cellular automata),
/// its topology dataset (M x 1) point indices.
enum class XdmfCellType { kTriangle, kQuadrilateral, kHexahedron, kPolyvertex };

struct XdmfSurface {
  std::string name;
  /// Node coordinates [m]: (N x 3) static, or (n_steps x N x 3) when the
  /// surface deforms (detected from the rank).
  std::string geometry_dataset;
  /// Connectivity, 0-based int: (M x 3) triangles, (M x 4) quads, (M x 8)
  /// hexahedra or (M x 1) points.
  std::string topology_dataset;
  XdmfCellType cell_type = XdmfCellType::kTriangle;
  std::vector<XdmfField> fields;
};

struct XdmfSeries {
  /// Time of each step [s]; empty for a static description (then no field
  /// may be per_step and geometry must be rank 2).
  std::vector<double> times;
  std::vector<XdmfSurface> surfaces;
};

/// Writes `xdmf_path` describing `series`, whose datasets live in `h5`.
/// The HDF5 file is referenced by a path relative to the XDMF file's folder
/// (so the pair can be moved together). Throws InputError on a missing or
/// mis-shaped dataset, std::runtime_error if the file cannot be written.
void write_xdmf(const std::string& xdmf_path, const H5File& h5, const XdmfSeries& series);

/// The XML text write_xdmf would write, with `h5_reference` used verbatim as
/// the file part of every "file:/dataset" reference.
std::string xdmf_text(const H5File& h5, const std::string& h5_reference, const XdmfSeries& series);

}  // namespace arthrosim::common
