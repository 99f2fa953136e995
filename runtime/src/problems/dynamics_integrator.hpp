// The time integrator behind run_dynamics: one object holding the run's state, whose named steps
// (a time step, a reset of the reference configuration, a re-mesh, a checkpoint, a restart) read
// top to bottom in run().
#pragma once

#include <array>
#include <filesystem>
#include <limits>
#include <map>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "bound_scene.hpp"
#include "dynamics.hpp"
#include "lmeform/output.hpp"
#include "lmeform/stopwatch.hpp"
#include <nlohmann/json.hpp>
#include "problem_space.hpp"

namespace lmeform::problems {

/// Measures of the deformation over the quadrature points: the smallest det F (and where), and the
/// largest distortion, the ratio of F's extreme singular values.
struct DeformationMeasures {
  double min_jacobian = std::numeric_limits<double>::infinity();
  long point = -1;                   ///< where: its number on every rank (Discretization::global_point)
  std::array<double, 3> position{};  ///< and its reference position
  double max_distortion = 1;
};

/// The scene's quadrature data that are jets of a nodal field: value, gradient, Hessian names.
struct FieldJets {
  std::string value, gradient, hessian;
};

struct ReferenceConfiguration;

class DynamicsIntegrator {
 public:
  DynamicsIntegrator(MPI_Comm comm, const Scene& scene, const DynamicsSettings& settings, const DynamicsOutput* output,
                     std::ostream* log);
  DynamicsIntegrator(const DynamicsIntegrator&) = delete;
  DynamicsIntegrator& operator=(const DynamicsIntegrator&) = delete;
  ~DynamicsIntegrator();

  /// From the start (or the checkpoint) to t_end, a failure or max_steps.
  [[nodiscard]] DynamicsRun run();

  /// What the integrator needs of the bound scene (SceneError otherwise); `lmeform run --check`
  /// calls it without building the integrator.
  static void check_scene(const Scene& scene, const DynamicsSettings& settings, const BoundScene& bound);

 private:
  /// The outcome of one attempt at a step.
  struct Attempt;

  // Setup
  [[nodiscard]] std::unique_ptr<ReferenceConfiguration> build_reference(const NodeSet& nodes, const std::vector<double>& state,
                                                           std::optional<CarriedQuadrature> carried,
                                                           std::map<std::string, std::vector<double>, std::less<>> qdata, bool keep_targets,
                                                           std::map<std::string, std::vector<double>, std::less<>> coefficients = {});
  void start();
  void resume();

  // The state
  [[nodiscard]] double energy_of(Vec state) const;
  [[nodiscard]] std::vector<double> constraint_values(Vec state) const;
  void apply_schedule(double t);
  /// A scheduled constant's value at t from its start value `base`.
  [[nodiscard]] double scheduled_value(const std::string& name, double base, double t) const;
  void check_scheduled_targets() const;
  void assemble_dissipation(Vec state);
  [[nodiscard]] DeformationMeasures measures_of(Vec state) const;
  [[nodiscard]] std::map<std::string, std::vector<double>, std::less<>> material_fields() const;
  [[nodiscard]] std::pair<std::vector<double>, std::vector<double>> material_node_positions(const std::vector<double>& y) const;

  // Named steps
  [[nodiscard]] bool advance();
  [[nodiscard]] Attempt attempt(double dt_step);
  [[nodiscard]] Attempt vti_attempt(double dt_step);
  [[nodiscard]] Attempt euler_attempt(double dt_step);
  void accept(const Attempt& a, double dt_step, double dt_try, double energy_before);
  void reset_reference();
  [[nodiscard]] bool remesh();
  [[nodiscard]] std::optional<LevelSetTopology> membrane_topology(const NodeSet& nodes, const BackgroundCells& cells,
                                                                  const std::vector<double>& field) const;
  [[nodiscard]] const std::vector<double>* topology_values() const;
  [[nodiscard]] NodeSet remeshed_nodes(const NodeSet& current, std::string& notes) const;
  [[nodiscard]] std::map<std::string, std::vector<double>, std::less<>> projected_fields(const NodeSet& current, const NodeSet& nodes,
                                                                                         const std::vector<double>& y, std::string& notes) const;

  // Outputs
  void record(Vec state, double energy, int newton, int rejected, double dt_taken, std::optional<DeformationMeasures> measures = std::nullopt);
  void write_series(Vec state);
  [[nodiscard]] nlohmann::json history_json() const;
  void write_checkpoint();
  void read_history(const std::filesystem::path& path);

  MPI_Comm comm_;
  int rank_ = 0;
  const Scene& scene_;
  const DynamicsSettings& settings_;
  const DynamicsOutput* output_;
  std::ostream* log_;   ///< progress of the run (rank 0)
  std::ostream* out_;   ///< rank 0's copy of log_, else null
  Stopwatch clock_;
  BoundScene bound_;
  int dim_ = 2;
  int bs_ = 0;
  int offset_ = 0;                          ///< of the deformation within a node's dofs
  bool euler_ = false;
  bool resets_ = false;
  std::map<std::string, FieldJets> jets_;

  DynamicsRun run_;
  NodeSet material_nodes_;                  ///< the nodes' identities (a re-mesh makes new ones)
  std::vector<std::vector<int>> dirichlet_sets_;
  std::size_t n_nodes_ = 0;
  std::size_t k_ = 0;                       ///< constraints
  std::vector<double> targets_;             ///< the current constraint targets (schedules move them)
  std::vector<double> scales_;              ///< the constraint scales of the start (nu is scaled by them)
  std::vector<double> base_targets_;
  std::vector<double> start_constraints_;
  std::unique_ptr<ReferenceConfiguration> ref_;
  std::vector<std::pair<std::string, std::vector<double>>> scalar_fields_;  ///< material nodal fields
  std::vector<double> nu_;                  ///< scaled multipliers
  std::optional<LevelSetTopology> topology_;  ///< of the current material field (set at the start and by re-meshes)
  double t_ = 0, dt_ = 0, target_decrement_ = 0;
  int step_ = 0, steps_since_reset_ = 0, steps_since_remesh_ = 0;
  std::size_t next_report_ = 0;
  std::optional<TimeSeriesWriter> series_;  ///< with an output folder
  std::vector<double> velocity_;
  std::filesystem::path checkpoint_path_, quadrature_path_, history_path_;
};

}  // namespace lmeform::problems
