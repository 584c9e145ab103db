// XDMF writer tests: the output is well-formed XML (checked by a small strict
// parser below), has the expected structure (temporal collection, one entry
// per step with its time), and every "file.h5:/dataset" it references exists
// in the HDF5 file with exactly the dims the XML states; every HyperSlab
// selects one existing step row. Bad inputs give errors naming the dataset.
#include "common/xdmf.h"

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <cctype>
#include <cstring>
#include <map>
#include <memory>
#include <sstream>

#include "common/error.h"

namespace arthrosim::common {
namespace {

namespace fs = std::filesystem;
using ::testing::HasSubstr;

fs::path temp_dir() {
  fs::path d = fs::path(ARTHROSIM_BINARY_DIR) / "test_output" / "xdmf_test";
  fs::create_directories(d);
  return d;
}

// ---- a minimal strict XML parser (elements, attributes, text, comments,
// prolog, DOCTYPE); throws std::runtime_error on anything malformed ------------
struct Node {
  std::string name;
  std::map<std::string, std::string> attrs;
  std::string text;
  std::vector<std::unique_ptr<Node>> children;
  std::vector<const Node*> find_all(const std::string& n) const {
    std::vector<const Node*> out;
    for (const auto& c : children) {
      if (c->name == n) out.push_back(c.get());
    }
    return out;
  }
};

class XmlParser {
 public:
  explicit XmlParser(std::string s) : s_(std::move(s)) {}
  std::unique_ptr<Node> parse() {
    skip_ws();
    if (starts("<?xml")) skip_past("?>");
    skip_misc();
    if (starts("<!DOCTYPE")) skip_past(">");
    skip_misc();
    auto root = element();
    skip_misc();
    if (i_ != s_.size()) error("content after the root element");
    return root;
  }

 private:
  [[noreturn]] void error(const std::string& m) const {
    throw std::runtime_error("XML error at offset " + std::to_string(i_) + ": " + m);
  }
  bool starts(const char* p) const { return s_.compare(i_, std::strlen(p), p) == 0; }
  void skip_ws() {
    while (i_ < s_.size() && std::isspace(static_cast<unsigned char>(s_[i_]))) ++i_;
  }
  void skip_past(const char* end) {
    const size_t p = s_.find(end, i_);
    if (p == std::string::npos) error(std::string("missing ") + end);
    i_ = p + std::strlen(end);
  }
  void skip_misc() {
    while (true) {
      skip_ws();
      if (starts("<!--")) {
        skip_past("-->");
      } else {
        return;
      }
    }
  }
  std::string name() {
    const size_t b = i_;
    while (i_ < s_.size() && (std::isalnum(static_cast<unsigned char>(s_[i_])) || s_[i_] == '_' || s_[i_] == ':' ||
                              s_[i_] == '-' || s_[i_] == '.')) {
      ++i_;
    }
    if (b == i_) error("expected a name");
    return s_.substr(b, i_ - b);
  }
  std::string unescape(const std::string& t) {
    std::string out;
    for (size_t k = 0; k < t.size(); ++k) {
      if (t[k] == '<') error("'<' in text or attribute");
      if (t[k] != '&') {
        out += t[k];
        continue;
      }
      const size_t e = t.find(';', k);
      if (e == std::string::npos) error("unterminated entity");
      const std::string ent = t.substr(k + 1, e - k - 1);
      static const std::map<std::string, char> known{{"amp", '&'}, {"lt", '<'}, {"gt", '>'}, {"quot", '"'}, {"apos", '\''}};
      auto it = known.find(ent);
      if (it == known.end()) error("unknown entity &" + ent + ";");
      out += it->second;
      k = e;
    }
    return out;
  }
  std::unique_ptr<Node> element() {
    if (!starts("<")) error("expected '<'");
    ++i_;
    auto n = std::make_unique<Node>();
    n->name = name();
    while (true) {
      skip_ws();
      if (starts("/>")) {
        i_ += 2;
        return n;
      }
      if (starts(">")) {
        ++i_;
        break;
      }
      const std::string key = name();
      skip_ws();
      if (!starts("=")) error("expected '=' after attribute " + key);
      ++i_;
      skip_ws();
      if (!starts("\"")) error("expected '\"' for attribute " + key);
      ++i_;
      const size_t e = s_.find('"', i_);
      if (e == std::string::npos) error("unterminated attribute");
      if (n->attrs.count(key)) error("duplicate attribute " + key);
      n->attrs[key] = unescape(s_.substr(i_, e - i_));
      i_ = e + 1;
    }
    while (true) {
      const size_t lt = s_.find('<', i_);
      if (lt == std::string::npos) error("unterminated element " + n->name);
      n->text += unescape(s_.substr(i_, lt - i_));
      i_ = lt;
      if (starts("<!--")) {
        skip_past("-->");
      } else if (starts("</")) {
        i_ += 2;
        const std::string closing = name();
        if (closing != n->name) error("</" + closing + "> closes <" + n->name + ">");
        skip_ws();
        if (!starts(">")) error("expected '>'");
        ++i_;
        return n;
      } else {
        n->children.push_back(element());
      }
    }
  }
  std::string s_;
  size_t i_ = 0;
};

std::vector<std::int64_t> parse_dims(const std::string& s) {
  std::istringstream in(s);
  std::vector<std::int64_t> d;
  for (std::int64_t v; in >> v;) d.push_back(v);
  return d;
}

// Checks one DataItem (plain HDF reference or HyperSlab) against the HDF5
// file; returns the dims of the values it yields.
std::vector<std::int64_t> check_data_item(const Node& item, const H5File& h5, const std::string& h5_name,
                                          int* references) {
  if (item.attrs.count("ItemType") && item.attrs.at("ItemType") == "HyperSlab") {
    const auto inner = item.find_all("DataItem");
    EXPECT_EQ(inner.size(), 2u);
    const std::vector<std::int64_t> sel = parse_dims(inner[0]->text);
    const std::vector<std::int64_t> ref_dims = check_data_item(*inner[1], h5, h5_name, references);
    const size_t r = ref_dims.size();
    EXPECT_EQ(parse_dims(inner[0]->attrs.at("Dimensions")), (std::vector<std::int64_t>{3, static_cast<std::int64_t>(r)}));
    EXPECT_EQ(sel.size(), 3 * r);
    std::vector<std::int64_t> count(sel.begin() + 2 * r, sel.end());
    // Every selected element lies within the complete frames (dims(), not
    // just the allocated extent).
    std::string text = inner[1]->text;
    const std::vector<std::int64_t> readable = h5.dims(text.substr(text.find(':') + 1));
    for (size_t k = 0; k < r; ++k) {
      const std::int64_t start = sel[k], stride = sel[r + k], cnt = sel[2 * r + k];
      EXPECT_GE(start, 0);
      EXPECT_GE(stride, 1);
      EXPECT_LE(start + (cnt - 1) * stride, readable[k] - 1) << "hyperslab outside the complete frames";
    }
    EXPECT_EQ(count, parse_dims(item.attrs.at("Dimensions")));
    return count;
  }
  EXPECT_EQ(item.attrs.at("Format"), "HDF");
  std::string text = item.text;
  text.erase(0, text.find_first_not_of(" \n\t"));
  text.erase(text.find_last_not_of(" \n\t") + 1);
  const size_t colon = text.find(':');
  EXPECT_NE(colon, std::string::npos);
  EXPECT_EQ(text.substr(0, colon), h5_name);
  const std::string dataset = text.substr(colon + 1);
  EXPECT_TRUE(h5.is_dataset(dataset)) << dataset;
  // The stated dims are the dataset's true extent (what a reader will find).
  const std::vector<std::int64_t> dims = parse_dims(item.attrs.at("Dimensions"));
  EXPECT_EQ(dims, h5.extent(dataset)) << dataset;
  const bool is_int = h5.type(dataset) == H5Type::kInt;
  EXPECT_EQ(item.attrs.at("NumberType"), is_int ? "Int" : "Float") << dataset;
  EXPECT_EQ(item.attrs.at("Precision"), is_int ? "4" : "8") << dataset;
  ++*references;
  return dims;
}

std::string read_text(const fs::path& p) {
  std::ifstream in(p);
  std::stringstream s;
  s << in.rdbuf();
  return s.str();
}

// Two surfaces: a static triangle mesh (2 triangles) with node and cell
// fields, and a deforming quad mesh (one quad) with a vector field.
void write_fixture(H5File& f, int n_steps) {
  Eigen::MatrixXd V(4, 3);
  V << 0, 0, 0, 1, 0, 0, 1, 1, 0, 0, 1, 0;
  Eigen::MatrixXi F(2, 3);
  F << 0, 1, 2, 0, 2, 3;
  f.write("tri/V", V);
  f.write("tri/F", F);
  Eigen::MatrixXd pressure(n_steps, 4);
  for (int k = 0; k < n_steps; ++k) pressure.row(k) = Eigen::RowVector4d::Constant(k * 1e5);
  f.write("tri/pressure_Pa", pressure);
  Eigen::MatrixXd cell_area(n_steps, 2);
  cell_area.setConstant(0.5);
  f.write("tri/cell_area", cell_area);
  f.write("tri/thickness", Eigen::VectorXd::Constant(4, 2e-3));
  f.write("tri/region", Eigen::VectorXi::Ones(2));
  Eigen::MatrixXi Q(1, 4);
  Q << 0, 1, 2, 3;
  f.write("quad/Q", Q);
  Tensor3d X;
  X.dims = {n_steps, 4, 3};
  X.data.assign(n_steps * 12, 0.0);
  for (int k = 0; k < n_steps; ++k) {
    for (int i = 0; i < 4; ++i) X(k, i, 0) = i + 0.1 * k;
  }
  f.write_tensor3("quad/X", X);
  f.write_tensor3("quad/u", X);
}

XdmfSeries fixture_series(int n_steps) {
  XdmfSeries s;
  for (int k = 0; k < n_steps; ++k) s.times.push_back(0.01 * k);
  XdmfSurface tri{"femoral cartilage & co", "tri/V", "/tri/F", XdmfCellType::kTriangle, {}};
  tri.fields = {{"pressure [Pa]", "tri/pressure_Pa", XdmfCenter::kNode, true},
                {"area", "tri/cell_area", XdmfCenter::kCell, true},
                {"thickness", "tri/thickness", XdmfCenter::kNode, false},
                {"region", "tri/region", XdmfCenter::kCell, false}};
  XdmfSurface quad{"shell", "quad/X", "quad/Q", XdmfCellType::kQuadrilateral, {}};
  quad.fields = {{"displacement", "quad/u", XdmfCenter::kNode, true}};
  s.surfaces = {tri, quad};
  return s;
}

TEST(Xdmf, TimeSeriesIsWellFormedAndReferencesExistingDatasets) {
  const int n_steps = 5;
  const fs::path h5_path = temp_dir() / "series.h5";
  const fs::path xdmf_path = temp_dir() / "series.xdmf";
  {
    H5File f(h5_path.string(), H5File::Mode::kTruncate);
    write_fixture(f, n_steps);
  }
  H5File f(h5_path.string(), H5File::Mode::kRead);
  write_xdmf(xdmf_path.string(), f, fixture_series(n_steps));

  std::unique_ptr<Node> root = XmlParser(read_text(xdmf_path)).parse();
  ASSERT_EQ(root->name, "Xdmf");
  const auto domains = root->find_all("Domain");
  ASSERT_EQ(domains.size(), 1u);
  const auto top = domains[0]->find_all("Grid");
  ASSERT_EQ(top.size(), 1u);
  EXPECT_EQ(top[0]->attrs.at("CollectionType"), "Temporal");
  const auto steps = top[0]->find_all("Grid");
  ASSERT_EQ(steps.size(), static_cast<size_t>(n_steps));
  int references = 0;
  for (int k = 0; k < n_steps; ++k) {
    const Node& step = *steps[k];
    EXPECT_EQ(step.attrs.at("CollectionType"), "Spatial");
    ASSERT_EQ(step.find_all("Time").size(), 1u);
    EXPECT_EQ(std::stod(step.find_all("Time")[0]->attrs.at("Value")), 0.01 * k);
    const auto grids = step.find_all("Grid");
    ASSERT_EQ(grids.size(), 2u);
    EXPECT_EQ(grids[0]->attrs.at("Name"), "femoral cartilage & co");  // escaped and parsed back
    for (const Node* g : grids) {
      const Node& topo = *g->find_all("Topology")[0];
      const auto topo_dims = check_data_item(*topo.find_all("DataItem")[0], f, "series.h5", &references);
      EXPECT_EQ(std::to_string(topo_dims[0]), topo.attrs.at("NumberOfElements"));
      EXPECT_EQ(std::to_string(topo_dims[1]), topo.attrs.at("NodesPerElement"));
      const Node& geom = *g->find_all("Geometry")[0];
      EXPECT_EQ(geom.attrs.at("GeometryType"), "XYZ");
      const auto geo_dims = check_data_item(*geom.find_all("DataItem")[0], f, "series.h5", &references);
      EXPECT_EQ(geo_dims.back(), 3);
      const std::int64_t n_nodes = geo_dims[geo_dims.size() - 2];
      for (const Node* a : g->find_all("Attribute")) {
        const auto d = check_data_item(*a->find_all("DataItem")[0], f, "series.h5", &references);
        std::int64_t values = 1;
        for (auto v : d) values *= v;
        const std::int64_t n = a->attrs.at("Center") == "Node" ? n_nodes : topo_dims[0];
        EXPECT_EQ(values, n * (a->attrs.at("AttributeType") == "Vector" ? 3 : 1)) << a->attrs.at("Name");
      }
    }
    // The per-step pressure of step k selects row k.
    const Node& p = *grids[0]->find_all("Attribute")[0];
    EXPECT_EQ(p.attrs.at("Name"), "pressure [Pa]");
    EXPECT_EQ(parse_dims(p.find_all("DataItem")[0]->find_all("DataItem")[0]->text),
              (std::vector<std::int64_t>{k, 0, 1, 1, 1, 4}));
  }
  // 2 surfaces x (topology + geometry) + 5 fields, per step.
  EXPECT_EQ(references, n_steps * (4 + 5));
}

TEST(Xdmf, StaticSingleSurfaceAndRelativeReference) {
  const fs::path sub = temp_dir() / "sub";
  fs::create_directories(sub);
  const fs::path h5_path = temp_dir() / "static.h5";
  {
    H5File f(h5_path.string(), H5File::Mode::kTruncate);
    write_fixture(f, 1);
  }
  H5File f(h5_path.string(), H5File::Mode::kRead);
  XdmfSeries s;
  XdmfSurface tri{"tibia", "tri/V", "tri/F", XdmfCellType::kTriangle, {}};
  tri.fields = {{"thickness", "tri/thickness", XdmfCenter::kNode, false}};
  s.surfaces = {tri};
  write_xdmf((sub / "static.xdmf").string(), f, s);
  std::unique_ptr<Node> root = XmlParser(read_text(sub / "static.xdmf")).parse();
  const auto grids = root->find_all("Domain")[0]->find_all("Grid");
  ASSERT_EQ(grids.size(), 1u);
  EXPECT_EQ(grids[0]->attrs.at("GridType"), "Uniform");
  EXPECT_TRUE(grids[0]->find_all("Time").empty());
  int references = 0;
  // The HDF5 file is one folder up from the XDMF file.
  check_data_item(*grids[0]->find_all("Geometry")[0]->find_all("DataItem")[0], f, "../static.h5", &references);
  check_data_item(*grids[0]->find_all("Attribute")[0]->find_all("DataItem")[0], f, "../static.h5", &references);
  EXPECT_EQ(references, 2);
}

TEST(Xdmf, BadDatasetsAreReportedByName) {
  const int n_steps = 3;
  const fs::path h5_path = temp_dir() / "bad.h5";
  {
    H5File f(h5_path.string(), H5File::Mode::kTruncate);
    write_fixture(f, n_steps);
    f.write("tri/F_bad", Eigen::MatrixXi::Constant(2, 3, 7));     // index 7 >= 4 nodes
    f.write("tri/pressure_short", Eigen::MatrixXd::Zero(2, 4));   // 2 steps instead of 3
    f.write("tri/field_wrong_n", Eigen::MatrixXd::Zero(3, 5));    // 5 values, 4 nodes
    f.write("tri/F_double", Eigen::MatrixXd::Zero(2, 3));
  }
  H5File f(h5_path.string(), H5File::Mode::kRead);
  auto message = [&](auto mutate) -> std::string {
    XdmfSeries s = fixture_series(n_steps);
    mutate(s);
    try {
      xdmf_text(f, "bad.h5", s);
    } catch (const InputError& e) {
      return e.what();
    }
    return "(no exception)";
  };
  EXPECT_THAT(message([](XdmfSeries& s) { s.surfaces[0].geometry_dataset = "tri/missing"; }),
              HasSubstr("bad.h5: error: dataset /tri/missing (for XDMF): not found"));
  EXPECT_THAT(message([](XdmfSeries& s) { s.surfaces[0].topology_dataset = "tri/F_bad"; }),
              HasSubstr("dataset /tri/F_bad (for XDMF): expected node indices in [0, 4), found [7, 7]"));
  EXPECT_THAT(message([](XdmfSeries& s) { s.surfaces[0].topology_dataset = "tri/F_double"; }),
              HasSubstr("dataset /tri/F_double (for XDMF): expected integer triangles of dims (M, 3), found "
                        "floating-point dims (2, 3)"));
  EXPECT_THAT(message([](XdmfSeries& s) { s.surfaces[1].cell_type = XdmfCellType::kTriangle; }),
              HasSubstr("dataset /quad/Q (for XDMF): expected integer triangles of dims (M, 3), found integer dims (1, 4)"));
  EXPECT_THAT(message([](XdmfSeries& s) { s.surfaces[0].fields[0].dataset = "tri/pressure_short"; }),
              HasSubstr("node field 'pressure [Pa]' of surface 'femoral cartilage & co': expected 3 steps as first "
                        "dimension, found dims (2, 4)"));
  EXPECT_THAT(message([](XdmfSeries& s) { s.surfaces[0].fields[0].dataset = "tri/field_wrong_n"; }),
              HasSubstr("expected dims (3, 4) or (3, 4, 3), found (3, 5)"));
  EXPECT_THAT(message([](XdmfSeries& s) {
                s.times.pop_back();
                s.surfaces.erase(s.surfaces.begin());  // the quad surface is checked first now
              }),
              HasSubstr("dataset /quad/X (for XDMF): expected dims (2, N, 3) for 2 time steps, found (3, 4, 3)"));
  EXPECT_THAT(message([](XdmfSeries& s) { s.surfaces.clear(); }), HasSubstr("no surface"));
}

// While an appender is open its dataset has more space allocated than frames
// written; the XDMF file must state the true extent and select only the
// complete frames.
TEST(Xdmf, OpenAppenderDatasetsAreReferencedByExtentAndSliced) {
  const fs::path h5_path = temp_dir() / "appending.h5";
  H5File f(h5_path.string(), H5File::Mode::kTruncate);
  write_fixture(f, 1);
  auto X = f.appender("live/X", {4, 3}, {.expected_frames = 10});
  auto p = f.appender("live/p", {4}, {.expected_frames = 10});
  for (int k = 0; k < 3; ++k) {
    X.append(Eigen::Matrix<double, 4, 3>::Constant(k));
    p.append(Eigen::Vector4d::Constant(k));
  }
  EXPECT_EQ(f.extent("live/X"), (std::vector<std::int64_t>{10, 4, 3}));
  EXPECT_EQ(f.dims("live/X"), (std::vector<std::int64_t>{3, 4, 3}));
  XdmfSeries s;
  s.times = {0.0, 0.1, 0.2};
  XdmfSurface surf{"live", "live/X", "tri/F", XdmfCellType::kTriangle, {}};
  surf.fields = {{"p", "live/p", XdmfCenter::kNode, true}};
  s.surfaces = {surf};
  const fs::path xdmf_path = temp_dir() / "appending.xdmf";
  write_xdmf(xdmf_path.string(), f, s);
  std::unique_ptr<Node> root = XmlParser(read_text(xdmf_path)).parse();
  const auto steps = root->find_all("Domain")[0]->find_all("Grid")[0]->find_all("Grid");
  ASSERT_EQ(steps.size(), 3u);
  int references = 0;
  for (const Node* g : steps) {
    check_data_item(*g->find_all("Geometry")[0]->find_all("DataItem")[0], f, "appending.h5", &references);
    check_data_item(*g->find_all("Attribute")[0]->find_all("DataItem")[0], f, "appending.h5", &references);
  }
  EXPECT_EQ(references, 6);
  // A static (not per-step) reference to an appended dataset selects its
  // complete rows: node positions appended one point per frame.
  auto V = f.appender("live/V", {3}, {.expected_frames = 10});
  for (int i = 0; i < 4; ++i) V.append(Eigen::Vector3d(i, 0, 0));
  XdmfSeries st;
  st.surfaces = {XdmfSurface{"points", "live/V", "tri/F", XdmfCellType::kTriangle, {}}};
  write_xdmf(xdmf_path.string(), f, st);
  root = XmlParser(read_text(xdmf_path)).parse();
  const Node& geo = *root->find_all("Domain")[0]->find_all("Grid")[0]->find_all("Geometry")[0]->find_all("DataItem")[0];
  EXPECT_EQ(geo.attrs.at("ItemType"), "HyperSlab");
  EXPECT_EQ(check_data_item(geo, f, "appending.h5", &references), (std::vector<std::int64_t>{4, 3}));
}

// The parser used above must itself reject malformed XML, or the
// well-formedness check would prove nothing.
TEST(Xdmf, TestXmlParserRejectsMalformedXml) {
  EXPECT_NO_THROW(XmlParser("<a x=\"1\"><b/>t&amp;</a>").parse());
  EXPECT_THROW(XmlParser("<a><b></a></b>").parse(), std::runtime_error);
  EXPECT_THROW(XmlParser("<a x=1></a>").parse(), std::runtime_error);
  EXPECT_THROW(XmlParser("<a>x & y</a>").parse(), std::runtime_error);
  EXPECT_THROW(XmlParser("<a></a><b/>").parse(), std::runtime_error);
  EXPECT_THROW(XmlParser("<a>").parse(), std::runtime_error);
  EXPECT_THROW(XmlParser("<a x=\"1\" x=\"2\"/>").parse(), std::runtime_error);
}

}  // namespace
}  // namespace arthrosim::common
