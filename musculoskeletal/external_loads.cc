#include "musculoskeletal/external_loads.h"

#include <tinyxml2.h>

#include <filesystem>
#include <fstream>
#include <map>
#include <sstream>

#include "common/error.h"

namespace arthrosim::musculoskeletal {

namespace {

using common::InputError;
using tinyxml2::XMLElement;

std::string trimmed(const char* s) {
  if (!s) return "";
  std::string v(s);
  const auto b = v.find_first_not_of(" \t\r\n");
  if (b == std::string::npos) return "";
  const auto e = v.find_last_not_of(" \t\r\n");
  return v.substr(b, e - b + 1);
}

// Text of child `tag` of e, or "" when absent; *line gets its line (or e's).
std::string child_text(const XMLElement* e, const char* tag, int* line = nullptr) {
  const XMLElement* c = e->FirstChildElement(tag);
  if (line) *line = c ? c->GetLineNum() : e->GetLineNum();
  return c ? trimmed(c->GetText()) : "";
}

}  // namespace

ExternalLoadsSpec parse_external_loads(const std::string& xml, const std::string& file,
                                       const std::string& directory) {
  tinyxml2::XMLDocument doc;
  if (doc.Parse(xml.c_str(), xml.size()) != tinyxml2::XML_SUCCESS)
    throw InputError(file, doc.ErrorLineNum(), std::string("expected well-formed XML: ") + doc.ErrorStr());
  const XMLElement* root = doc.RootElement();
  // <OpenSimDocument><ExternalLoads> or a bare <ExternalLoads>.
  const XMLElement* loads = root && std::string(root->Name()) == "ExternalLoads"
                                ? root
                                : (root ? root->FirstChildElement("ExternalLoads") : nullptr);
  if (!loads)
    throw InputError(file, root ? root->GetLineNum() : 0,
                     std::string("expected an <ExternalLoads> element, found ") +
                         (root ? "<" + std::string(root->Name()) + "> without one" : "none"));
  ExternalLoadsSpec spec;
  spec.file = file;
  const std::string datafile = child_text(loads, "datafile", &spec.datafile_line);
  if (datafile.empty())
    throw InputError(file, spec.datafile_line,
                     "expected a <datafile> naming the force data (.mot/.sto), found none");
  const std::filesystem::path p(datafile);
  spec.datafile = (p.is_absolute() || directory.empty()) ? p.string()
                                                         : (std::filesystem::path(directory) / p).string();
  const XMLElement* objects = loads->FirstChildElement("objects");
  std::map<std::string, int> seen;
  for (const XMLElement* f = objects ? objects->FirstChildElement() : nullptr; f; f = f->NextSiblingElement()) {
    const std::string tag = f->Name();
    if (tag != "ExternalForce")
      throw InputError(file, f->GetLineNum(),
                       "expected <ExternalForce> elements in <objects>, found <" + tag + ">");
    ExternalForceSpec s;
    s.line = f->GetLineNum();
    s.name = trimmed(f->Attribute("name"));
    if (s.name.empty()) throw InputError(file, s.line, "expected a name on <ExternalForce>, found none");
    if (auto [it, fresh] = seen.emplace(s.name, s.line); !fresh)
      throw InputError(file, s.line, "duplicate ExternalForce '" + s.name + "' (first on line " +
                                         std::to_string(it->second) + ")");
    int line = 0;
    s.applied_to_body = child_text(f, "applied_to_body", &line);
    if (s.applied_to_body.empty())
      throw InputError(file, line, "ExternalForce '" + s.name + "': expected <applied_to_body>, found none");
    for (const char* frame_tag : {"force_expressed_in_body", "point_expressed_in_body"}) {
      const std::string frame = child_text(f, frame_tag, &line);
      if (!frame.empty() && frame != "ground")
        throw InputError(file, line,
                         "ExternalForce '" + s.name + "': expected " + frame_tag +
                             " ground (the only frame arthrosim applies), found '" + frame + "'");
    }
    for (const char* source_tag : {"data_source_name", "datafile"}) {
      const std::string src = child_text(f, source_tag, &line);
      if (!src.empty())
        throw InputError(file, line,
                         "ExternalForce '" + s.name + "': expected the data in the ExternalLoads' "
                         "<datafile>, found a per-force " + source_tag + " '" + src + "' (not supported)");
    }
    s.force_identifier = child_text(f, "force_identifier", &s.force_line);
    s.point_identifier = child_text(f, "point_identifier", &s.point_line);
    s.torque_identifier = child_text(f, "torque_identifier", &s.torque_line);
    if (s.force_identifier.empty())
      throw InputError(file, s.force_line,
                       "ExternalForce '" + s.name + "': expected a <force_identifier>, found none");
    spec.forces.push_back(std::move(s));
  }
  if (spec.forces.empty())
    throw InputError(file, loads->GetLineNum(), "expected at least one <ExternalForce>, found none");
  return spec;
}

ExternalLoadsSpec read_external_loads(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) throw InputError(path, 0, "expected a readable ExternalLoads file, found none");
  std::stringstream ss;
  ss << in.rdbuf();
  return parse_external_loads(ss.str(), path, std::filesystem::path(path).parent_path().string());
}

std::array<int, 3> identifier_columns(const std::vector<std::string>& labels,
                                      const std::string& identifier, const std::string& data_file,
                                      const std::string& spec_file, int line) {
  std::vector<int> found;
  for (std::size_t i = 1; i < labels.size(); ++i)
    if (labels[i].compare(0, identifier.size(), identifier) == 0) found.push_back(static_cast<int>(i));
  if (found.size() != 3) {
    std::string list;
    for (int i : found) list += (list.empty() ? "" : ", ") + labels[i];
    throw InputError(spec_file, line,
                     "identifier '" + identifier + "': expected 3 columns of " + data_file +
                         " starting with it, found " + std::to_string(found.size()) +
                         (list.empty() ? "" : " (" + list + ")"));
  }
  return {found[0], found[1], found[2]};
}

}  // namespace arthrosim::musculoskeletal
