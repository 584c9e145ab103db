// XDMF writer (see xdmf.h). The XML is written by hand: it is a handful of
// element kinds, and the only heavy data are references into the HDF5 file.
#include "common/xdmf.h"

#include <cstdio>
#include <filesystem>
#include <fstream>
#include <sstream>

#include "common/error.h"

namespace arthrosim::common {
namespace {

std::int64_t nodes_per_cell(XdmfCellType type) {
  switch (type) {
    case XdmfCellType::kTriangle: return 3;
    case XdmfCellType::kQuadrilateral: return 4;
    case XdmfCellType::kHexahedron: return 8;
    case XdmfCellType::kPolyvertex: return 1;
  }
  return 0;
}
const char* cell_name(XdmfCellType type) {
  switch (type) {
    case XdmfCellType::kTriangle: return "triangles";
    case XdmfCellType::kQuadrilateral: return "quads";
    case XdmfCellType::kHexahedron: return "hexahedra";
    case XdmfCellType::kPolyvertex: return "points";
  }
  return "";
}
const char* topology_type(XdmfCellType type) {
  switch (type) {
    case XdmfCellType::kTriangle: return "Triangle";
    case XdmfCellType::kQuadrilateral: return "Quadrilateral";
    case XdmfCellType::kHexahedron: return "Hexahedron";
    case XdmfCellType::kPolyvertex: return "Polyvertex";
  }
  return "";
}

namespace fs = std::filesystem;

std::string escape(const std::string& s) {
  std::string out;
  for (char c : s) {
    switch (c) {
      case '&': out += "&amp;"; break;
      case '<': out += "&lt;"; break;
      case '>': out += "&gt;"; break;
      case '"': out += "&quot;"; break;
      case '\'': out += "&apos;"; break;
      default: out += c;
    }
  }
  return out;
}

std::string number(double v) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.17g", v);
  return buf;
}

std::string join(const std::vector<std::int64_t>& d) {
  std::string s;
  for (size_t i = 0; i < d.size(); ++i) s += (i ? " " : "") + std::to_string(d[i]);
  return s;
}

std::string dims_text(const std::vector<std::int64_t>& d) {
  std::string s = "(";
  for (size_t i = 0; i < d.size(); ++i) s += (i ? ", " : "") + std::to_string(d[i]);
  return s + ")";
}

// A dataset referenced by the XDMF file, with its checked dims and type.
struct Ref {
  std::string dataset;
  std::vector<std::int64_t> dims;    // readable dims (complete frames)
  std::vector<std::int64_t> extent;  // allocated extent (larger while appending)
  bool is_int = false;
  bool per_step = false;  // first dimension is the step
};

class Builder {
 public:
  Builder(const H5File& h5, std::string h5_reference, const XdmfSeries& series)
      : h5_(h5), ref_(std::move(h5_reference)), series_(series) {}

  std::string build() {
    const size_t n_steps = series_.times.size();
    std::vector<SurfaceRefs> surfaces;
    for (const XdmfSurface& s : series_.surfaces) surfaces.push_back(check_surface(s));

    out_ << "<?xml version=\"1.0\" encoding=\"utf-8\"?>\n";
    out_ << "<!DOCTYPE Xdmf SYSTEM \"Xdmf.dtd\" []>\n";
    out_ << "<Xdmf Version=\"3.0\" xmlns:xi=\"http://www.w3.org/2001/XInclude\">\n";
    out_ << "  <Domain>\n";
    if (n_steps == 0) {
      write_step(surfaces, -1, 2);
    } else {
      out_ << "    <Grid Name=\"time_series\" GridType=\"Collection\" CollectionType=\"Temporal\">\n";
      for (size_t k = 0; k < n_steps; ++k) write_step(surfaces, static_cast<std::int64_t>(k), 3);
      out_ << "    </Grid>\n";
    }
    out_ << "  </Domain>\n";
    out_ << "</Xdmf>\n";
    return out_.str();
  }

 private:
  struct FieldRef {
    const XdmfField* field;
    Ref ref;
    bool vector = false;
  };
  struct SurfaceRefs {
    const XdmfSurface* surface;
    Ref geometry;
    Ref topology;
    std::int64_t n_nodes = 0;
    std::int64_t n_cells = 0;
    std::vector<FieldRef> fields;
  };

  [[noreturn]] void fail(const std::string& dataset, const std::string& message) const {
    throw InputError(h5_.path(), 0, "dataset " + dataset + " (for XDMF): " + message);
  }

  Ref inspect(const std::string& dataset) const {
    Ref r;
    r.dataset = dataset.empty() || dataset[0] != '/' ? "/" + dataset : dataset;
    if (!h5_.is_dataset(r.dataset)) fail(r.dataset, "not found");
    r.dims = h5_.dims(r.dataset);
    r.extent = h5_.extent(r.dataset);
    const H5Type t = h5_.type(r.dataset);
    if (t != H5Type::kDouble && t != H5Type::kInt) fail(r.dataset, "expected a numeric dataset");
    r.is_int = t == H5Type::kInt;
    return r;
  }

  SurfaceRefs check_surface(const XdmfSurface& s) const {
    const auto n_steps = static_cast<std::int64_t>(series_.times.size());
    SurfaceRefs out;
    out.surface = &s;
    // Geometry: (N x 3) or (n_steps x N x 3).
    out.geometry = inspect(s.geometry_dataset);
    const auto& g = out.geometry.dims;
    if (g.size() == 2 && g[1] == 3) {
      out.n_nodes = g[0];
    } else if (g.size() == 3 && g[2] == 3 && n_steps > 0) {
      if (g[0] != n_steps) {
        fail(out.geometry.dataset, "expected dims (" + std::to_string(n_steps) + ", N, 3) for " +
                                       std::to_string(n_steps) + " time steps, found " + dims_text(g));
      }
      out.geometry.per_step = true;
      out.n_nodes = g[1];
    } else {
      fail(out.geometry.dataset, std::string("expected node coordinates of dims (N, 3)") +
                                     (n_steps > 0 ? " or (n_steps, N, 3)" : "") + ", found " + dims_text(g));
    }
    if (out.geometry.is_int) fail(out.geometry.dataset, "expected floating-point coordinates, found integer");
    // Topology: (M x 3) triangles or (M x 4) quads, int, indices in [0, N).
    out.topology = inspect(s.topology_dataset);
    const std::int64_t per_cell = nodes_per_cell(s.cell_type);
    const auto& t = out.topology.dims;
    if (!out.topology.is_int || t.size() != 2 || t[1] != per_cell) {
      fail(out.topology.dataset, "expected integer " + std::string(cell_name(s.cell_type)) +
                                     " of dims (M, " + std::to_string(per_cell) + "), found " +
                                     (out.topology.is_int ? "integer" : "floating-point") + " dims " +
                                     dims_text(t));
    }
    out.n_cells = t[0];
    const Eigen::MatrixXi cells = h5_.read_matrix_int(out.topology.dataset);
    if (cells.size() > 0 && (cells.minCoeff() < 0 || cells.maxCoeff() >= out.n_nodes)) {
      fail(out.topology.dataset, "expected node indices in [0, " + std::to_string(out.n_nodes) + "), found [" +
                                     std::to_string(cells.minCoeff()) + ", " + std::to_string(cells.maxCoeff()) +
                                     "]");
    }
    for (const XdmfField& f : s.fields) {
      FieldRef fr{&f, inspect(f.dataset), false};
      const std::int64_t n = f.center == XdmfCenter::kNode ? out.n_nodes : out.n_cells;
      std::vector<std::int64_t> d = fr.ref.dims;
      const std::string what = std::string(f.center == XdmfCenter::kNode ? "node" : "cell") + " field '" +
                               f.name + "' of surface '" + s.name + "'";
      if (f.per_step) {
        if (n_steps == 0) fail(fr.ref.dataset, what + ": per-step field in a series without time steps");
        if (d.empty() || d[0] != n_steps) {
          fail(fr.ref.dataset, what + ": expected " + std::to_string(n_steps) + " steps as first dimension, found dims " +
                                   dims_text(d));
        }
        d.erase(d.begin());
        fr.ref.per_step = true;
      }
      const bool scalar = (d.size() == 1 && d[0] == n) || (d.size() == 2 && d[0] == n && d[1] == 1);
      const bool vector = d.size() == 2 && d[0] == n && d[1] == 3;
      if (!scalar && !vector) {
        const std::string s_n = std::to_string(n);
        const std::string prefix = f.per_step ? std::to_string(n_steps) + ", " : "";
        fail(fr.ref.dataset, what + ": expected dims (" + prefix + s_n + ") or (" + prefix + s_n + ", 3), found " +
                                 dims_text(fr.ref.dims));
      }
      fr.vector = vector;
      out.fields.push_back(fr);
    }
    return out;
  }

  std::string type_attrs(const Ref& r) const {
    return r.is_int ? "NumberType=\"Int\" Precision=\"4\"" : "NumberType=\"Float\" Precision=\"8\"";
  }

  // DataItem for `r`: the whole dataset, or through a HyperSlab (start,
  // stride, count rows) row `step` of a per-step dataset, or the complete
  // frames of a dataset whose allocated extent is larger (appender open).
  // The HDF item always states the true extent of the dataset.
  void data_item(const Ref& r, std::int64_t step, const std::string& pad) {
    const std::string heavy = escape(ref_) + ":" + escape(r.dataset);
    if (!r.per_step && r.extent == r.dims) {
      out_ << pad << "<DataItem Dimensions=\"" << join(r.dims) << "\" " << type_attrs(r) << " Format=\"HDF\">"
           << heavy << "</DataItem>\n";
      return;
    }
    std::vector<std::int64_t> count = r.dims;
    std::vector<std::int64_t> start(r.dims.size(), 0), stride(r.dims.size(), 1);
    if (r.per_step) {
      count[0] = 1;
      start[0] = step;
    }
    out_ << pad << "<DataItem ItemType=\"HyperSlab\" Type=\"HyperSlab\" Dimensions=\"" << join(count) << "\" "
         << type_attrs(r) << ">\n";
    out_ << pad << "  <DataItem Dimensions=\"3 " << r.dims.size() << "\" NumberType=\"Int\" Format=\"XML\">"
         << join(start) << " " << join(stride) << " " << join(count) << "</DataItem>\n";
    out_ << pad << "  <DataItem Dimensions=\"" << join(r.extent) << "\" " << type_attrs(r) << " Format=\"HDF\">"
         << heavy << "</DataItem>\n";
    out_ << pad << "</DataItem>\n";
  }

  void write_surface(const SurfaceRefs& s, std::int64_t step, int depth, bool with_time) {
    const std::string pad(2 * depth, ' ');
    const XdmfSurface& surf = *s.surface;
    out_ << pad << "<Grid Name=\"" << escape(surf.name) << "\" GridType=\"Uniform\">\n";
    if (with_time) out_ << pad << "  <Time Value=\"" << number(series_.times[step]) << "\"/>\n";
    out_ << pad << "  <Topology TopologyType=\"" << topology_type(surf.cell_type) << "\" NumberOfElements=\""
         << s.n_cells << "\" NodesPerElement=\"" << nodes_per_cell(surf.cell_type) << "\">\n";
    data_item(s.topology, step, pad + "    ");
    out_ << pad << "  </Topology>\n";
    out_ << pad << "  <Geometry GeometryType=\"XYZ\">\n";
    data_item(s.geometry, step, pad + "    ");
    out_ << pad << "  </Geometry>\n";
    for (const FieldRef& f : s.fields) {
      out_ << pad << "  <Attribute Name=\"" << escape(f.field->name) << "\" AttributeType=\""
           << (f.vector ? "Vector" : "Scalar") << "\" Center=\""
           << (f.field->center == XdmfCenter::kNode ? "Node" : "Cell") << "\">\n";
      data_item(f.ref, step, pad + "    ");
      out_ << pad << "  </Attribute>\n";
    }
    out_ << pad << "</Grid>\n";
  }

  // One step (or the static description, step = -1) at indentation `depth`.
  void write_step(const std::vector<SurfaceRefs>& surfaces, std::int64_t step, int depth) {
    const bool timed = step >= 0;
    if (surfaces.size() == 1) {
      write_surface(surfaces[0], step, depth, timed);
      return;
    }
    const std::string pad(2 * depth, ' ');
    out_ << pad << "<Grid Name=\"" << (timed ? "step_" + std::to_string(step) : std::string("surfaces"))
         << "\" GridType=\"Collection\" CollectionType=\"Spatial\">\n";
    if (timed) out_ << pad << "  <Time Value=\"" << number(series_.times[step]) << "\"/>\n";
    for (const SurfaceRefs& s : surfaces) write_surface(s, step, depth + 1, false);
    out_ << pad << "</Grid>\n";
  }

  const H5File& h5_;
  std::string ref_;
  const XdmfSeries& series_;
  std::ostringstream out_;
};

}  // namespace

std::string xdmf_text(const H5File& h5, const std::string& h5_reference, const XdmfSeries& series) {
  if (series.surfaces.empty()) throw InputError(h5.path(), 0, "XDMF: no surface to describe");
  return Builder(h5, h5_reference, series).build();
}

void write_xdmf(const std::string& xdmf_path, const H5File& h5, const XdmfSeries& series) {
  // Reference the HDF5 file relative to the XDMF file's folder.
  const fs::path xdmf_dir = fs::weakly_canonical(fs::absolute(xdmf_path)).parent_path();
  const fs::path h5_abs = fs::weakly_canonical(fs::absolute(h5.path()));
  fs::path rel = h5_abs.lexically_relative(xdmf_dir);
  if (rel.empty()) rel = h5_abs;
  const std::string text = xdmf_text(h5, rel.generic_string(), series);
  std::ofstream out(xdmf_path, std::ios::binary | std::ios::trunc);
  out << text;
  out.close();
  if (!out) throw std::runtime_error(xdmf_path + ": error: cannot write the XDMF file");
}

}  // namespace arthrosim::common
