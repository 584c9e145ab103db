#pragma once
// OpenSim ExternalLoads files (the XML an OpenSim user hands to inverse
// dynamics, COMAK or CMC, e.g. opensim-jam's overground_17_ext_loads.xml):
// which force acts on which body, the columns of the data file that hold it,
// and the frames it is expressed in. Read with tinyxml2, every error names
// the file and line.
//
// What is read, per <ExternalForce name=...>:
//   applied_to_body          the body the force acts on (e.g. calcn_r);
//   force_expressed_in_body  must be "ground" (default "ground");
//   point_expressed_in_body  must be "ground" (default "ground");
//   force_identifier, point_identifier, torque_identifier
//       column-label prefixes in the data file, as OpenSim resolves them:
//       the columns whose labels start with the identifier, exactly three
//       (x, y, z in the file's order). point_identifier and
//       torque_identifier may be empty (no point: the force acts at the
//       body origin; no torque: zero), force_identifier may not.
// and <datafile> (relative to the XML file). Anything else an ExternalForce
// can carry (data_source_name, a per-force data source) is refused naming
// its line, so nothing is silently ignored.
//
// Units and conventions are OpenSim's: N, m, N m in the lab frame, the force
// ON the body FROM the ground; the torque is applied as a free couple.
#include <array>
#include <string>
#include <vector>

namespace arthrosim::musculoskeletal {

struct ExternalForceSpec {
  std::string name;                 ///< <ExternalForce name=...>
  std::string applied_to_body;
  std::string force_identifier;     ///< column prefix, e.g. "ground_force_2_v"
  std::string point_identifier;     ///< may be empty
  std::string torque_identifier;    ///< may be empty
  int line = 0;                     ///< line of the <ExternalForce> element
  int force_line = 0, point_line = 0, torque_line = 0;  ///< lines of the identifiers
};

struct ExternalLoadsSpec {
  std::string file;      ///< the XML file as given
  std::string datafile;  ///< resolved against the XML file's folder
  int datafile_line = 0;
  std::vector<ExternalForceSpec> forces;
};

/// Reads an ExternalLoads XML file. Throws common::InputError
/// "file:line: error: expected ..., found ..." on malformed XML, a missing
/// <ExternalLoads> or <datafile>, a force without applied_to_body or
/// force_identifier, a frame other than ground, a per-force data source, or
/// duplicate force names.
ExternalLoadsSpec read_external_loads(const std::string& path);
/// Same from text; `file` names it in messages, `directory` resolves <datafile>.
ExternalLoadsSpec parse_external_loads(const std::string& xml, const std::string& file,
                                       const std::string& directory);

/// Columns of `identifier` among `labels` (labels[0] = time is skipped): the
/// labels starting with it, which must be exactly three (OpenSim's rule).
/// Throws InputError naming spec_file:line, the identifier and what was found.
std::array<int, 3> identifier_columns(const std::vector<std::string>& labels,
                                      const std::string& identifier, const std::string& data_file,
                                      const std::string& spec_file, int line);

}  // namespace arthrosim::musculoskeletal
