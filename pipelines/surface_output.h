#pragma once
// The surface stage's output file, surface_<scenario>.h5 (schema
// docs/surface_output.md): its one writer (used by the surface stage) and its
// one reader (used by the post stage and the study). No other file names a
// dataset of it.
#include <Eigen/Core>
#include <cstdint>
#include <filesystem>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "common/effects.h"
#include "common/mesh.h"

namespace arthrosim::common {
class H5File;
struct RunMetadata;
}  // namespace arthrosim::common

namespace arthrosim::pipelines::surface_output {

/// The value of the root attribute `schema`.
inline constexpr const char* kSchema = "arthrosim surface output 2";
/// "surface_<scenario>.h5".
std::string file_name(const std::string& scenario);

// ---------------------------------------------------------------------------
// Writer
// ---------------------------------------------------------------------------

/// What the file will hold (fixed when it is created).
struct Layout {
  std::string scenario;
  std::string prepared_model;  ///< path, "" for a generic mesh
  std::string mesh;            ///< generic mesh path, "" otherwise
  std::string mode;            ///< "steady_state", "quasi_static" or "hht"
  double seating_time_s = 0;
  std::int64_t frames_expected = 0;  ///< for the appenders' allocation
  std::int64_t steps_expected = 0;
  bool contact = false;           ///< contact pressure, contact force, penetration series
  bool trial_time = false;        ///< /trial_time (imposed kinematics)
  bool change = false;            ///< /solver/change_m (steady_state_change_mm)
  bool augmentations = false;     ///< /solver/contact_augmentations (contact_augmentations > 0)
  std::vector<std::string> contact_pairs;
  /// Root attribute partial_input: the PARTIAL INPUT line of a run on an
  /// incomplete kinematics file (--allow-partial; common/file_check.h).
  std::string partial_input;
};

/// One surface's static part.
struct SurfaceGeometry {
  std::string name;
  std::string bone;  ///< "" for a generic mesh
  common::Points3 nodes;
  common::Quads quads;
  common::Points3 normals, basis_a1, basis_a2;
  std::vector<int> fixed;  ///< 1 for a constrained node, per node
};

/// One surface's fields at one frame (N nodes).
struct SurfaceFrame {
  Eigen::MatrixXd displacement;      ///< N x 3 [m]
  Eigen::VectorXd deflection;        ///< N [m]
  Eigen::MatrixXd E;                 ///< N x 3
  Eigen::VectorXd e1, e2;            ///< N
  Eigen::MatrixXd e1_dir;            ///< N x 3
  Eigen::VectorXd contact_pressure;  ///< N [Pa]; with Layout::contact only
};

/// The tibiofemoral contact force of one frame (Layout::contact).
struct ContactFrame {
  Eigen::Vector3d force = Eigen::Vector3d::Zero();  ///< on the second surfaces, in their bone frame [N]
  Eigen::Vector3d medial_force = Eigen::Vector3d::Zero();
  Eigen::Vector3d lateral_force = Eigen::Vector3d::Zero();
  double area = 0;             ///< [m^2]
  double max_penetration = 0;  ///< [m]
};

/// The solver's record of one output step (the /solver series).
struct StepRecord {
  double time = 0, dt = 0;
  int newton_iterations = 0;
  double residual_N = 0, residual_tolerance_N = 0;
  int rejections = 0;
  double wall_s = 0, max_deflection_m = 0;
  double change_m = 0;  ///< Layout::change
  // Layout::contact:
  double max_penetration_m = 0, penetration_ratio = 0;
  int active_contacts = 0;
  double max_rim_depth_m = 0, max_unfaded_penetration_m = 0, unfaded_penetration_ratio = 0;
  int augmentations = 0;  ///< Layout::augmentations: multiplier updates taken in this step
};

/// A surface's summary attributes (at the end of a run).
struct SurfaceSummaryAttributes {
  double max_deflection_m = 0, max_deflection_time_s = 0;
  double e1_min = 0, e1_max = 0, e2_min = 0;
  double final_residual_N = 0, residual_tolerance_N = 0;
};

class Writer {
 public:
  /// Creates (truncates) `path`.partial and writes the run metadata, the
  /// header attributes (status "running") and the effect ledger; complete()
  /// renames it to `path` (common/output_file.h), so a previous complete
  /// output stays until then and a killed or failed run leaves only
  /// `path`.partial.
  Writer(const std::string& path, const common::RunMetadata& metadata, const Layout& layout,
         const common::EffectLedger& ledger);
  ~Writer();
  Writer(const Writer&) = delete;
  Writer& operator=(const Writer&) = delete;

  /// Static part of one surface and its per-frame series (in order).
  void add_surface(const SurfaceGeometry& surface);
  /// After the static part: the file is complete up to here.
  void flush();
  /// One output frame: every surface's fields (in add_surface order), the
  /// contact force, then /time (so /time counts complete frames) and the
  /// ParaView sidecar.
  void append_frame(double t, double trial_time, const std::vector<SurfaceFrame>& surfaces,
                    const ContactFrame* contact);
  void append_step(const StepRecord& step);
  /// Attributes of the end of a run.
  void set_surface_summary(const std::string& surface, const SurfaceSummaryAttributes& summary);
  /// Reactions of a generic mesh's constraints (docs/surface_output.md):
  /// /surfaces/<surface>/reactions/<name> (frames x 3) [N] with attributes
  /// set, components; written at the end of a completed run.
  void set_reactions(const std::string& surface, const std::string& name, const std::string& set,
                     const std::string& components, const Eigen::MatrixXd& frames_x3);
  void set_solver_attribute(const std::string& name, double value);
  void set_solver_attribute(const std::string& name, std::int64_t value);
  void set_solver_attribute(const std::string& name, const std::string& value);
  void set_root_attribute(const std::string& name, double value);
  /// Closes every series, sets status "completed" and flushes.
  void complete();
  /// Sets status "failed: <why>" and flushes (frames written stay).
  void fail(const std::string& why);

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

// ---------------------------------------------------------------------------
// Reader
// ---------------------------------------------------------------------------

/// A surface's strain field over the complete frames.
struct StrainField {
  std::string file, surface;
  common::QuadMesh mesh;                ///< reference nodes [m] and quads
  Eigen::VectorXd time;                 ///< per frame: /trial_time when present (the kinematics clock), else /time
  Eigen::MatrixXd e1;                   ///< frames x nodes
  std::vector<Eigen::MatrixXd> e1_dir;  ///< per frame, nodes x 3
  Eigen::MatrixXd deflection;           ///< frames x nodes (empty when absent)
};

/// The accuracy-rule series per step (contact runs).
struct PenetrationSeries {
  Eigen::VectorXd time;             ///< per step, on the file's clock
  Eigen::VectorXd ratio;            ///< penetration / deflection
  Eigen::VectorXi active_contacts;
  bool has_unfaded = false;         ///< the file has the unfaded series
  Eigen::VectorXd unfaded_ratio;
  std::optional<double> limit;      ///< /solver@penetration_limit
  double trial_offset_s = 0;        ///< the file's clock -> the kinematics clock (seating first)
};

/// A frame-level vector series: times (on the file's /time clock, or the
/// kinematics clock for `trial_clock`) and values.
struct Series {
  Eigen::VectorXd time;
  Eigen::MatrixXd values;
};

class Reader {
 public:
  /// Opens `path` (InputError naming it when it cannot be read).
  explicit Reader(const std::string& path);
  ~Reader();
  const std::string& path() const;

  /// Surfaces in the file.
  std::vector<std::string> surfaces() const;
  /// /time: one entry per complete frame.
  Eigen::VectorXd time() const;
  /// The frames' times on the kinematics file's clock (/trial_time when
  /// present, else /time).
  Eigen::VectorXd trial_time() const;
  StrainField strain_field(const std::string& surface) const;
  /// The deflection of one surface over the complete frames (frames x nodes),
  /// or nullopt when the file has none; `why` says what is missing.
  std::optional<Eigen::MatrixXd> deflection(const std::string& surface, std::string& why) const;
  /// The tibiofemoral contact force over the complete frames (frames x 3)
  /// on the /time clock, or nullopt when the run wrote none.
  std::optional<Series> contact_force() const;
  /// The largest contact pressure over the nodes of every surface per
  /// complete frame [Pa] (values frames x 1), on the kinematics clock
  /// (/trial_time), or nullopt with `why` when the file has no
  /// contact_pressure or no /trial_time (a run without imposed kinematics is
  /// not on the trial's clock).
  std::optional<Series> max_contact_pressure(std::string& why) const;
  /// The run's effect ledger, or nullopt for a file without one.
  std::optional<common::EffectLedger> ledger() const;
  /// The accuracy rule per step, or nullopt for a run without contact.
  std::optional<PenetrationSeries> penetration() const;
  /// The file itself (for generic listings: attributes, force groups).
  const common::H5File& file() const;

 private:
  std::unique_ptr<common::H5File> f_;
};

/// Datasets of the contact force group (for the generic force-series listing).
inline constexpr const char* kContactGroup = "/contact/tibiofemoral";
inline constexpr const char* kContactForce = "/contact/tibiofemoral/force";

}  // namespace arthrosim::pipelines::surface_output
