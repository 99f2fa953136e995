// The phase-field vesicle model (seed statics, eq. (1) of Paper A): what belongs to it and to no
// other model lives here. A scene opts in with a [vesicle] table; its forms and constants are
// ordinary ([model], [constants]); this model adds
//   * the targets from a sphere: area A0 of the sphere of `radius`, volume V0 = v · its volume
//     (reduced_volume), with the feasibility check V0 <= V_max(A0);
//   * the initial phase field tanh(d / (√2 ε)) of an ellipsoid or sphere;
//   * the resolution rule ε ≥ resolution_factor · h_min, checked before each solve;
//   * the adaptivity schedule (seed Table B.6): CVT relocations with the density ρ = 1 + f |∇φ|, or
//     new grids graded from the interface (resolve), and continuation in ε (interface re-profiled,
//     multipliers warm-started);
//   * the axisymmetric basis mirrored across the axis.
#pragma once

#include <array>
#include <map>
#include <optional>
#include <ostream>
#include <span>
#include <string>
#include <vector>

#include "lmeform/cvt.hpp"
#include "lmeform/level_set_topology.hpp"
#include "lmeform/lme_basis.hpp"
#include "lmeform/node_set.hpp"
#include "lmeform/scene.hpp"
#include "problem_registry.hpp"
#include "stationary.hpp"

namespace lmeform::problems {

/// One stage of the progressive CVT schedule: relocate the nodes by Lloyd iterations for the
/// density ρ = 1 + f |∇φ| of the current solution, then solve at eps. lloyd_iterations = 0: no
/// relocation, the stage only lowers eps on the current grid.
struct AdaptivityStage {
  double eps = 0;
  double f = 0;
  int lloyd_iterations = 20;
  /// Instead of relocating with ρ = 1 + f |∇φ|: a new grid that resolves the interface of the
  /// current solution for every ε down to this one (interface_spacing), its node count following
  /// the interface length.
  std::optional<double> resolve;
  /// A side solve: later stages that are not branches continue from the last stage that is not one
  /// (seed Table 3 reports O12 at ε = 0.02 while O13 is adapted from O12 at ε = 0.025).
  bool branch = false;
  /// The stage builds a new grid (else it only lowers ε on the grid of the stage it continues from).
  [[nodiscard]] bool new_grid() const { return resolve.has_value() || lloyd_iterations > 0; }
};

/// How an interface-resolving grid is graded: spacing h_interface = ε_resolve / resolution_factor
/// within `band` · ε_resolve of the interface φ = 0, growing by `grading` per unit distance (|∇h|
/// bounded: steep grading costs LME accuracy) up to `coarsening` · h_interface.
struct InterfaceResolution {
  double band = 3.0;
  double grading = 0.2;
  double coarsening = 8.0;
  std::size_t max_nodes = 60000;
};

struct VesicleAdaptivity {
  std::vector<AdaptivityStage> stages;
  bool start_from_density = false;     ///< Lloyd from the density's node placement, else from the current nodes
  double samples_per_node = 64;
  InterfaceResolution interface;
  int fit_iterations = 0;              ///< > 0: a stage's start coefficients fitted to its start values (fit_nodal_values)
};

/// The [vesicle] table of a scene.
struct VesicleModel {
  std::string field = "phi";           ///< the phase field (a scalar unknown of the forms)
  std::string width = "eps";           ///< the constant that is the interface width ε
  double eps = 0;                      ///< ε of the first solve ([constants])
  std::optional<double> area;          ///< A0 (from radius), set as the target of constraint "area"
  std::optional<double> volume;        ///< V0 (from reduced_volume), target of constraint "volume"
  std::optional<double> reduced_volume;
  enum class Shape { ellipsoid, sphere, stomatocyte } shape = Shape::ellipsoid;
  std::array<double, 3> center{};
  std::array<double, 3> semi_axes{};
  /// A stomatocyte (a cup): the shell of `cup_thickness` around the sphere of radius `cup_radius`
  /// about `center`, open at the top (the last axis) within `cup_aperture` radians of the pole, its
  /// rim rounded. (semi_axes then hold its outer extent, for the domain check.)
  double cup_radius = 0;
  double cup_thickness = 0;
  double cup_aperture = 0;
  std::optional<double> profile_eps;   ///< width of the initial profile (default: eps)
  /// The first grid resolves the initial profile's interface for every ε ≥ this (resolve_interface;
  /// for shapes whose features a uniform grid at the first ε would merge).
  std::optional<double> initial_resolve;
  double resolution_factor = 2.0;      ///< ε ≥ resolution_factor · h_min (seed App. B)
  std::optional<VesicleAdaptivity> adaptivity;
  /// A stage whose membrane (φ = 0) has another topology than the start's is rejected and ends the
  /// run; else it is kept with a warning.
  bool topology_guard = false;
};

/// The extension tables this model reads (for load_scene).
inline constexpr std::string_view kVesicleExtension = "vesicle";

/// Reads [vesicle]; nullopt when the scene has none. Throws SceneError.
[[nodiscard]] std::optional<VesicleModel> read_vesicle(const Scene& scene);

/// The largest volume bounded by area A0 (the sphere's): A0^{3/2} / (6 sqrt(pi)); dim = 2: the
/// largest area bounded by a curve of length A0, A0^2 / (4 pi).
[[nodiscard]] double max_volume_for_area(double A0, int dim = 3);

/// The semi-axes (equatorial, polar) of the spheroid with area A0 and reduced volume v, oblate
/// (polar < equatorial) or prolate; dim = 2: the ellipse with perimeter A0 and reduced area v.
[[nodiscard]] std::array<double, 2> spheroid_semi_axes(double A0, double v, int dim, bool oblate);

/// Throws SceneError unless 0 < V0 <= max_volume_for_area(A0, dim).
void check_feasible(double A0, double V0, int dim = 3);

/// The most membrane a phase field of width ε can hold in a box: its measure (area in 2D, volume in
/// 3D, the volume of revolution of the (r, z) box when axisymmetric) over 2ε — interfaces stacked 2ε
/// apart, an upper bound far above any vesicle's area (a sphere of radius R in a box of side 3R:
/// 4πR² against 13.5 R³/ε). A target beyond it cannot be a membrane.
[[nodiscard]] double membrane_area_capacity(const Box& domain, bool axisymmetric, double eps);

/// The largest value a scheduled constraint target reaches in a run, and the schedule's key.
struct ScheduledTarget {
  std::string constraint;
  double peak = 0;
  std::string where;
};

/// The phase-field vesicle's rules for scheduled targets: the membrane's area (the constraint
/// `area`, interface width `eps`) must stay within membrane_area_capacity. Throws SceneError naming
/// the schedule's key; a scene without them is not a vesicle and passes.
void check_vesicle_targets(const BoundScene& b, const std::map<std::string, double, std::less<>>& constants,
                           std::span<const ScheduledTarget> targets);

/// tanh(d / (√2 ε)) with d the signed distance to the model's initial shape (> 0 inside).
/// (For a stomatocyte, d is exact: the distance to the cup's mid-surface, an arc in the meridian plane.)
[[nodiscard]] double initial_profile(const VesicleModel& model, std::span<const double> x, int dim);

/// A phase field of interface width eps_from re-profiled to eps_to: tanh(atanh(phi) eps_from / eps_to)
/// (phi clamped into (-1, 1)). Exact for a tanh profile; the start of a continuation in eps.
[[nodiscard]] std::vector<double> rescale_interface(std::span<const double> phi, double eps_from, double eps_to);

/// One solve of the schedule.
struct StageRecord {
  int stage = 0;
  double eps = 0;      ///< the interface width of the stage
  std::string grid;    ///< "uniform" / "file", then "cvt-1", "cvt-2", ... per relocation
  int generation = 0;  ///< relocations along the chain of stages that led here
  std::string label;   ///< " (branch)" for a side solve
  int nodes = 0;
  double h_min = 0;    ///< SpacingSummary::h_min of the stage's grid
  ProblemResult result;
  /// The topology of the solution's φ = 0 (none when it could not be evaluated).
  std::optional<LevelSetTopology> topology;
  double topology_s = 0;  ///< evaluating it (stage 0: the start's too)
  double wall_s = 0;   ///< this stage: relocation + setup + solve
  double adapt_s = 0;  ///< of which the relocation
  double peak_rss_mb = 0;  ///< the largest peak resident set of any rank at the stage's end (MiB)
};

struct VesicleRun {
  std::vector<StageRecord> stages;  ///< the finished stages, in order
  /// Empty when every stage ran; else "stage k: <why>" for the stage that could not run. A stage
  /// whose solver did not converge is the last one, with its result's message.
  std::string failure;
  double wall_s = 0;                ///< the whole run, node set generation included
  StateLayout layout;               ///< the layout of every stage's state
  /// The topology of the first stage's start (the initial profile or [initial]).
  std::optional<LevelSetTopology> initial_topology;
  /// A stage the topology guard rejected (not in `stages`): it ends the run.
  std::optional<StageRecord> rejected;
  std::vector<std::string> warnings;  ///< changes of topology from one stage to the next, checkpoints not written
};

/// Runs a vesicle scene: binds it with the model's targets filled in, then solves the first stage
/// and every adaptivity stage (relocation, resolution check, continuation in eps from the previous
/// stage, multipliers warm-started). A stage that cannot run ends the schedule (VesicleRun::failure).
/// Each stage's membrane topology is compared with the previous stage's (the first: its start's):
/// a change is a warning, or with topology_guard the end of the run.
/// With a checkpoint folder, every converged stage that is kept is written there
/// (vesicle_checkpoint.hpp), and with checkpoint.restart the schedule resumes after the last one.
struct VesicleCheckpoint;
[[nodiscard]] VesicleRun run_vesicle(MPI_Comm comm, const Scene& scene, const VesicleModel& model, std::ostream* log,
                                     const VesicleCheckpoint* checkpoint = nullptr);

/// The scene with what the model derives: the area and volume targets of its sphere, and the
/// moment's natural size (the volume times the vesicle's half-height, ~ V0).
[[nodiscard]] Scene with_vesicle_targets(const Scene& scene, const VesicleModel& model);

/// Binds a scene completed with the model's targets; throws SceneError unless its problem minimizes
/// energies of the model's one scalar field.
[[nodiscard]] BoundScene bind_vesicle(const Scene& completed, MPI_Comm comm, std::ostream* log, const VesicleModel& model);

/// The driver of scenes with a [vesicle] table.
[[nodiscard]] const ProblemDriver& vesicle_driver();

/// The spacing field of an interface-resolving grid: h(x) = min(coarsening · h_interface,
/// h_interface + grading · max(0, d(x) − band · eps_resolve)), d the distance to the zero level set
/// of the nodal values phi (found on the Delaunay edges of `nodes`). Throws std::invalid_argument
/// when phi has no sign change.
[[nodiscard]] SpacingFunction interface_spacing(const NodeSet& nodes, std::span<const double> phi, double eps_resolve,
                                             double h_interface, const InterfaceResolution& resolution);

/// A grid that resolves the interface of the nodal values phi on `nodes` (a solution, or the
/// initial profile) for every ε ≥ eps_resolve: cvt_for_spacing of interface_spacing with
/// h_interface = eps_resolve / resolution_factor, made finer and rebuilt (at most three times)
/// until eps_resolve ≥ resolution_factor · h_min holds as measured.
[[nodiscard]] NodeSet resolve_interface(const NodeSet& nodes, std::span<const double> phi, const Box& box, double eps_resolve,
                                        double resolution_factor, const InterfaceResolution& resolution,
                                        const CvtOptions& cvt, std::ostream* log = nullptr);

/// One CVT adaptation of a solved state: Lloyd iterations with density ρ = 1 + f·|∇φ| on the box.
[[nodiscard]] NodeSet adapt_nodes(const ProblemResult& solved, const Box& box, double f, const CvtOptions& cvt,
                                  CvtReport* report = nullptr);

}  // namespace lmeform::problems
