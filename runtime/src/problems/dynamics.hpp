// Gradient-flow dynamics of any energy with a dissipation (seed Paper B): a scene with a [dynamics]
// table moves its deformation unknown y (the nodal positions of a Lagrangian description) by
//   VTI:            y^{n+1} = argmin ½ (y − yⁿ)ᵀ K(yⁿ) (y − yⁿ) + Δt E(y)   s.t. C_i(y) = c_i,
//   forward Euler:  [K ∇C; ∇Cᵀ 0] [ẏ; σ] = [−∇E; 0],  y^{n+1} = yⁿ + Δt ẏ,
// K the Hessian of the scene's dissipation output (quadratic in the velocity, its coefficient y set
// to yⁿ). The constraints are the scene's ([constraints]; `area = "initial"` keeps the value of the
// start). Adaptive Δt keeps the energy decrement per step near a target; a step whose Newton
// fails, or whose map folds (det F ≤ 0 at a quadrature point), is rejected and retried with Δt/2,
// leaving the accepted state untouched. The reference configuration can be reset to the current
// one (every N steps, or when F is distorted, or when a step would fold the map) without any
// projection: quadrature points are carried, reference field jets pushed forward. Nothing here knows a particular model: the vesicle scenes
// in demos/dynamics name the Lagrangian Helfrich forms, the reference phase field and the time unit
// μR0³/k themselves.
#pragma once

#include <mpi.h>

#include <filesystem>
#include <iosfwd>
#include <map>
#include <optional>
#include <string>
#include <vector>

#include "lmeform/delaunay.hpp"
#include "lmeform/level_set_topology.hpp"
#include "lmeform/node_set.hpp"
#include "lmeform/scene.hpp"
#include "problem_registry.hpp"

namespace lmeform::problems {

inline constexpr std::string_view kDynamicsExtension = "dynamics";

/// A constant (or constraint target constant) that changes during the run: a rate over an interval
/// or a jump at a time. Times in the scene's time unit (t*).
struct ScheduledConstant {
  std::string name;
  std::string where;
  enum class Kind { rate, jump } kind = Kind::rate;
  double rate = 0;        ///< rate: relative change per unit t*, value(t) = v0 (1 + rate (min(t, until) − from)) for t > from
  double from = 0, until = 0;
  double at = 0;          ///< jump: the time
  double value = 0;       ///< jump: the value from `at` on
};

/// The [dynamics] table.
struct DynamicsSettings {
  enum class Method { vti, forward_euler } method = Method::vti;
  std::string deformation = "y";          ///< the unknown that is the motion
  SceneName dissipation;                  ///< an energy output, quadratic in its unknown, reading `deformation`
  double time_unit = 1;                   ///< t* = t / time_unit
  double t_start = 0;                     ///< t* of the start
  double t_end = 0;                       ///< t* of the end
  double dt = 0;                          ///< the first Δt*
  bool adaptive = true;
  double dt_max = 0;                      ///< 0: unbounded
  double dt_min = 0;                      ///< 0: dt · 2⁻²⁰
  double growth = 2;                      ///< largest Δt factor per accepted step
  double energy_decrement = 0;            ///< target |ΔE| per step; 0: the first step's
  int target_newton = 8;                  ///< more Newton iterations than this: Δt shrinks (the chord
                                          ///< iteration of a reused Hessian takes 3-5)
  int max_steps = 100000;
  int max_retries = 12;                   ///< halvings of one step before the run stops
  bool hessian_every_iteration = false;   ///< VTI: else the Hessian of E once per step (seed)
  double min_jacobian = 0;                ///< det F below this at a quadrature point rejects a step
  bool require_decrease = false;          ///< a step that raises the energy is rejected (forward Euler's instability)
  int remesh_every = 0;                   ///< a full re-mesh with projection every N steps (0: never)
  std::string remesh_field = "phi";       ///< the scalar [coefficients] field whose gradient the new nodes follow
  double remesh_factor = 100;             ///< f of the CVT density 1 + f |∇φ|
  int remesh_iterations = 20;             ///< Lloyd iterations of a re-mesh
  std::size_t remesh_nodes = 0;           ///< nodes after a re-mesh (0: as many as before); placed by the density
  /// How a re-mesh carries a scalar field: `points`, the L2 projection of its values at the current
  /// quadrature points (fields with a [qdata] value jet: the material field itself); `nodes`, its
  /// nodal values interpolated at the new nodes and fitted (remesh_fit_iterations).
  enum class Projection { points, nodes } remesh_projection = Projection::points;
  int remesh_fit_iterations = 20;         ///< `nodes`: iterations fitting the new nodal values to the old field (0: copy)
  /// The scalar [coefficients] field whose φ = 0 is the membrane, its topology reported per step
  /// (default: remesh_field when the scene has it, else none). The motion carries the field, so
  /// only a re-mesh's projection can change the topology.
  std::string topology_field;
  bool topology_field_given = false;
  bool topology_guard = false;            ///< a re-mesh that changes the topology stops the run before it
  /// `points`: ℓ of an H1 fit, Σ w [(φ − φ_q)² + ℓ² |∇φ − ∇φ_q|²], for fields with a gradient jet
  /// too (0: the L2 projection)
  double remesh_gradient_length = 0;
  int reset_every = 0;                    ///< reset the reference configuration every N steps (0: never)
  double reset_distortion = 0;            ///< ... or when σ_max/σ_min of F exceeds this (0: never)
  int output_every = 10;                  ///< time-series files every N steps (0: start and end only)
  int checkpoint_every = 0;               ///< checkpoint every N steps (0: none)
  std::vector<double> report_times;       ///< t* where the run lands exactly and records E
  std::vector<ScheduledConstant> schedule;
  /// Start from this state (original node order, dofs interleaved) instead of the scene's [initial].
  std::vector<double> start_state;
  std::vector<double> start_multipliers;
};

[[nodiscard]] std::optional<DynamicsSettings> read_dynamics(const Scene& scene);

/// One accepted step.
struct DynamicsStep {
  int step = 0;
  double t_star = 0, dt_star = 0;
  double energy = 0;
  std::vector<double> constraints;        ///< values, in the scene's constraint order
  std::vector<double> multipliers;
  int newton_iterations = 0;
  int rejected = 0;                       ///< attempts rejected before this one
  double min_jacobian = 0;                ///< min det F over the quadrature points
  double distortion = 1;                  ///< max σ_max/σ_min of F over the quadrature points
  int resets = 0;                         ///< resets of the reference configuration so far
  double wall_s = 0;                      ///< since the start of the run
  std::optional<LevelSetTopology> topology;  ///< of the membrane (DynamicsSettings::topology_field)
};

/// What a reset of the reference configuration changed (relative): zero up to round-off and the
/// basis' consistency error, since it describes the same physical state.
struct ResetChange {
  double energy = 0;
  std::vector<double> constraints;
  /// How well the new basis reproduces the identity at the carried points (max |F − I|, max |∂²y/∂X∂X|):
  /// the part of a change that the basis' consistency error explains.
  double gradient_consistency = 0;
  double hessian_consistency = 0;
};

struct DynamicsRun {
  std::vector<DynamicsStep> history;      ///< step 0 is the start
  std::string failure;                    ///< empty when t_end was reached
  std::vector<std::string> constraint_names;
  int accepted = 0, rejected = 0, resets = 0;
  int gradient_evaluations = 0, hessian_evaluations = 0;
  double seconds_setup = 0, seconds_dissipation = 0, seconds_hessian = 0, seconds_solve = 0, seconds_reset = 0;
  double wall_s = 0;
  std::map<double, double> energy_at;     ///< report time -> E
  std::vector<ResetChange> reset_changes; ///< one per reset
  int remeshes = 0;
  std::vector<double> remesh_changes;     ///< relative change of E by each re-mesh's projection
  std::optional<LevelSetTopology> initial_topology;  ///< the membrane's at the start
  std::vector<std::string> warnings;      ///< changes of the membrane's topology
  NodeSet reference_nodes;                ///< original order
  BackgroundCells cells;
  std::vector<double> final_state;        ///< original order
  std::vector<double> final_multipliers;
  double h_min = 0;
};

struct DynamicsOutput {
  std::filesystem::path directory;        ///< time series, history JSON, checkpoint
  std::string name;
  bool restart = false;                   ///< resume from directory/<name>_checkpoint.h5
};

/// Runs the scene's dynamics. `output` null: no files. Collective over comm. Throws SceneError for
/// a scene that cannot run; a run that stops early says why in DynamicsRun::failure.
[[nodiscard]] DynamicsRun run_dynamics(MPI_Comm comm, const Scene& scene, const DynamicsSettings& settings,
                                       const DynamicsOutput* output, std::ostream* log);

/// The driver of scenes with a [dynamics] table.
[[nodiscard]] const ProblemDriver& dynamics_driver();

}  // namespace lmeform::problems
