#pragma once
// `arthrosim import-osim MODEL.osim --out DIR`: the command-line side of the
// OpenSim importer (musculoskeletal/osim_import.h, docs/import.md). Kept in
// its own header so the driver (arthrosim.cc) only registers and runs it.
#include <CLI/CLI.hpp>

#include <filesystem>
#include <iostream>
#include <string>
#include <vector>

#include "common/error.h"
#include "musculoskeletal/osim_import.h"

namespace arthrosim::pipelines {

struct ImportOsimCommand {
  CLI::App* app = nullptr;
  std::string model, out;
  std::string muscles = "knee";
  musculoskeletal::OsimImportOptions options;
};

inline void add_import_osim_command(CLI::App& parent, ImportOsimCommand& c) {
  c.app = parent.add_subcommand(
      "import-osim",
      "import an OpenSim 4.x model with OpenSim-JAM components (knee, ligaments, muscles, contact)\n"
      "into arthrosim's model format: DIR/<model>.urdf, DIR/Geometry/, DIR/import_report.md\n"
      "(what was not imported and why). Method: docs/import.md.");
  c.app->add_option("MODEL", c.model, "OpenSim model (.osim)")->required()->check(CLI::ExistingFile);
  c.app->add_option("--out", c.out, "output folder (created when missing)")->required();
  c.app->add_option("--knee-joint", c.options.knee_joint, "tibiofemoral joint; its parent body is the root")
      ->capture_default_str();
  c.app->add_option("--patellofemoral-joint", c.options.patellofemoral_joint,
                    "patellofemoral joint (its coordinates are free too); '' for none")
      ->capture_default_str();
  c.app->add_option("--knee-flexion", c.options.knee_flexion,
                    "the knee joint's primary coordinate (default: its rotation1 coordinate)");
  c.app->add_option("--muscles", c.muscles,
                    "knee: muscles crossing the knee or patellofemoral joint; leg: every muscle on the leg")
      ->check(CLI::IsMember({"knee", "leg"}))
      ->capture_default_str();
  c.app->add_option("--geometry", c.options.geometry_dirs,
                    "extra folder with mesh files (after MODEL's Geometry/ and MODEL's folder); repeatable");
  c.app->add_flag("--without-wrapping", c.options.without_wrapping,
                  "leave wrap objects and path wraps out (each is listed in the report)");
  c.app->add_option("--urdf-name", c.options.urdf_name, "file name of the model in DIR (default <model>.urdf)");
  c.app->footer(
      "Sample run (from the repository root):\n"
      "  build/bin/arthrosim import-osim data/models/lenhart2015/source/lenhart2015.osim \\\n"
      "      --geometry data/models/lenhart2015/Geometry --out out/lenhart2015\n"
      "      the bundled real subject (data/models/lenhart2015 was made this way)\n");
}

/// Runs the command when it was parsed; returns the exit status.
inline int run_import_osim_command(ImportOsimCommand& c) {
  c.options.muscles =
      c.muscles == "leg" ? musculoskeletal::ImportMuscles::kLeg : musculoskeletal::ImportMuscles::kKnee;
  try {
    const auto s = musculoskeletal::import_osim(c.model, c.out, c.options);
    std::cout << "arthrosim import-osim: " << s.model_name << " -> " << s.urdf_path << "\n  " << s.bodies
              << " bodies, " << s.coordinates << " coordinates (" << s.free_coordinates << " free), "
              << s.ligament_bundles << " ligament bundles in " << s.ligament_groups << " groups, " << s.muscles
              << " muscles, " << s.path_wraps << " path wraps on";
    for (const auto& [kind, n] : s.wrap_objects) std::cout << " " << n << " " << kind;
    std::cout << ", " << s.contacts << " contact pairs, " << s.coordinate_springs << " coordinate springs\n  "
              << s.not_imported << " elements not imported, listed with their lines in " << s.report_path << "\n";
    return 0;
  } catch (const common::InputError& e) {
    std::cerr << "arthrosim import-osim: " << e.what() << "\n";
    return 1;
  } catch (const std::filesystem::filesystem_error& e) {
    std::cerr << "arthrosim import-osim: error: " << e.what() << "\n";
    return 1;
  }
}

}  // namespace arthrosim::pipelines
