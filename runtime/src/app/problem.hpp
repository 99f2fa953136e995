// Any model from its forms and a scene: the scene bound to its loaded forms (every name checked),
// and one solve on a node set. The kind of problem follows from the outputs the scene names:
// energies (+ constraints) go to the constrained Newton minimizer, a residual to PETSc SNES, a
// bilinear + linear pair to one PETSc KSP solve. Nothing here knows a particular model; models with
// conveniences of their own (the phase-field vesicle) call solve_problem with their choices.
#pragma once

#include <mpi.h>

#include <iosfwd>
#include <map>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "expressions.hpp"
#include "lmeform/assembler.hpp"
#include "lmeform/constrained_minimizer.hpp"
#include "lmeform/discretization.hpp"
#include "lmeform/delaunay.hpp"
#include "lmeform/form_registry.hpp"
#include "lmeform/lme_basis.hpp"
#include "lmeform/node_set.hpp"
#include "lmeform/scene.hpp"

namespace lmeform::app {

/// An unknown field of the problem: name, components, offset within a node's dofs.
struct UnknownField {
  std::string name;
  int components = 1;
  int offset = 0;
};

struct BoundConstraint {
  std::string name;
  const kernel::FormKernels* kernel = nullptr;
  double target = 0;
  double scale = 1;
  std::string target_constant;         ///< the form's constant holding the target ("" for a number)
  bool initial = false;                ///< the target is the constraint's value at the start state
};

/// A scene with its forms loaded and every name checked against them.
struct BoundScene {
  const Scene* scene = nullptr;
  std::vector<const FormModule*> modules;
  ProblemKind kind = ProblemKind::minimization;
  std::vector<const kernel::FormKernels*> energy;  ///< minimization: the summed energy terms
  /// Energies a model assembles besides the problem's own (a time integrator's dissipation): their
  /// constants and data are checked like the problem's; they may have other unknown names (same
  /// dofs per node), and a coefficient named after an unknown of the problem is its current value.
  std::vector<const kernel::FormKernels*> auxiliary;
  std::vector<BoundConstraint> constraints;
  const kernel::FormKernels* residual = nullptr;
  const kernel::FormKernels* bilinear = nullptr;
  const kernel::FormKernels* linear = nullptr;
  std::vector<UnknownField> unknowns;
  int dofs_per_node = 0;
  int basis_order = 0;                 ///< the highest derivative order the kernels read
  /// Every constant of the used kernels: the scene's value, else the form's default.
  std::map<std::string, double, std::less<>> constants;
  /// Point expressions of the scene (initial fields, Dirichlet values), compiled.
  std::shared_ptr<PointExpressions> expressions;
  std::vector<int> initial_expression;    ///< per scene.initial entry: expression handle or -1
  std::vector<int> dirichlet_expression;  ///< per scene.dirichlet entry: expression handle or -1
  std::vector<UnknownField> coefficients;  ///< the known nodal fields the kernels read (offsets unused)
  std::vector<int> coefficient_expression; ///< per scene.coefficients entry: expression handle or -1
  std::map<std::string, int, std::less<>> qdata_expression;  ///< qdata given by value: expression handle or -1 (a number)
  std::vector<std::string> zero_mean;     ///< unknowns fixed by ∫ u dx = 0 (scalar unknowns)

  [[nodiscard]] const UnknownField& unknown(std::string_view name) const;
  /// Every kernel the problem assembles.
  [[nodiscard]] std::vector<const kernel::FormKernels*> kernels() const;
};

/// Loads the scene's forms (built-in or JIT, collective over comm) and checks every name the scene
/// uses against them: outputs, constants (did-you-mean over the forms' constants), constraint
/// names, unknowns, quadrature data, expressions. Throws SceneError naming file, line and key, or
/// FormLoadError for a form that cannot be loaded.
/// `provided_constants`: constants a model sets itself (not required in [constants]);
/// `provided_qdata`: quadrature data a model supplies itself; `auxiliary_energies`: energy outputs
/// a model assembles besides the problem (BoundScene::auxiliary).
[[nodiscard]] BoundScene bind_scene(const Scene& scene, MPI_Comm comm, std::ostream* log,
                                    const std::vector<std::string>& provided_constants = {},
                                    const std::vector<std::string>& provided_qdata = {},
                                    const std::vector<SceneName>& auxiliary_energies = {});

/// What one solve starts from; empty members take the scene's choice.
struct ProblemInput {
  NodeSet nodes;
  std::map<std::string, double, std::less<>> constants;  ///< overrides (e.g. eps of a continuation stage)
  std::map<std::string, double, std::less<>> targets;    ///< constraint targets, by constraint name
  std::map<std::string, double, std::less<>> scales;     ///< constraint scales, by constraint name
  std::vector<double> initial;               ///< original node order, dofs interleaved; empty: the scene's [initial]
  std::vector<double> initial_multipliers;   ///< physical units, one per constraint; empty: zero
  LmeOptions lme;                            ///< mirror symmetry, spacing smoothing
  std::ostream* log = nullptr;
  /// Only evaluate the energies and constraints at the start (ProblemResult::values), no solve.
  bool evaluate_only = false;
  /// Cells and quadrature points carried from a previous reference configuration (a reset).
  std::optional<CarriedQuadrature> carried;
  /// Quadrature data given by value, by name (every global point, the datum's size each): they
  /// replace the scene's provider (a reset's pushed-forward reference field).
  std::map<std::string, std::vector<double>, std::less<>> qdata_values;
  /// Nodal values of scalar [coefficients] fields, by name (input.nodes order): they replace the
  /// scene's (a re-mesh's projected reference field).
  std::map<std::string, std::vector<double>, std::less<>> coefficient_values;
  /// The nodes (original numbering) of each [[dirichlet]] entry, in scene order, in place of the
  /// nodes found on its boundary parts: a moving node set keeps its material boundary (after a reset,
  /// a node that was free stays free wherever its coefficient lies).
  std::vector<std::vector<int>> dirichlet_nodes;
  /// A discretization of these nodes built by an earlier solve of the same scene (ProblemResult::
  /// discretization): reused, not rebuilt (a continuation stage that changes a constant only).
  std::shared_ptr<Discretization> discretization;
};

/// The nodes (original numbering) on the boundary parts of each [[dirichlet]] entry, in scene order;
/// throws SceneError for an entry whose parts hold no node.
[[nodiscard]] std::vector<std::vector<int>> dirichlet_nodes(const Scene& scene, const NodeSet& nodes);

/// Error of one unknown against the scene's exact solution.
struct FieldError {
  std::string unknown;
  double l2 = 0;
  double h1 = 0;                             ///< semi-norm |∇(u − u_exact)|
};

struct ProblemResult {
  bool converged = false;
  std::string message;
  ConstrainedResult minimization;            ///< minimization problems (energy, multipliers, ...)
  double energy = 0;                         ///< Σ energies at the solution (NaN for other problems)
  double residual_norm = 0;                  ///< final |R| (residual problems) or |Au − b| / |b| (linear)
  int iterations = 0;                        ///< Newton / Krylov iterations
  NodeSet nodes;                             ///< original order
  BackgroundCells cells;                     ///< original numbering
  std::vector<double> state;                 ///< original order, dofs interleaved
  std::vector<double> gradient_norm;         ///< |∇u| of the first scalar unknown at the nodes (0 where fixed)
  std::vector<std::string> constraint_names;
  std::vector<FieldError> errors;
  /// Each energy term ("module.output") and constraint (by name) at the state: filled by
  /// evaluate_only, and after a solve whose energy has several terms.
  std::map<std::string, double, std::less<>> values;
  double h_min = 0, h_mean = 0;
  double seconds_setup = 0, seconds_solve = 0;
  double seconds_assembly = 0;               ///< linear problems: assembly of A and b (in seconds_solve)
  /// Linear problems with zero-mean unknowns: how the level was fixed ("constraint": a bordered
  /// system, "null space": the Krylov method's null space + the mean removed afterwards).
  std::string zero_mean_method;
  /// The solve's discretization, for a later solve on the same nodes (ProblemInput::discretization).
  std::shared_ptr<Discretization> discretization;
};

/// The assembly side of one problem on one node set: the discretization, one Assembler per output
/// with its constants, coefficients and quadrature data set, the Dirichlet dofs and the start.
/// What solve_problem solves once, and what a time integrator steps.
struct ProblemSpace {
  std::shared_ptr<Discretization> disc;
  std::map<std::string, double, std::less<>> constants;  ///< every constant, resolved (targets included)
  std::vector<std::unique_ptr<Assembler>> assemblers;    ///< owners of the pointers below
  std::vector<PetscVector> coefficient_vectors;          ///< alive as long as the assemblers reading them
  std::vector<Assembler*> energy_terms;                  ///< BoundScene::energy, in order
  std::vector<ScalarConstraint> constraints;             ///< BoundScene::constraints, targets and scales set
  std::vector<Assembler*> auxiliary;                     ///< BoundScene::auxiliary, in order
  Assembler* primary = nullptr;                          ///< owns the dof layout (first energy, residual, bilinear)
  Assembler* linear = nullptr;
  std::vector<std::pair<int, int>> fixed_pairs;          ///< (original node, dof within the node) with Dirichlet values
  std::vector<PetscInt> fixed;                           ///< the same as owned global dofs
  std::vector<char> first_scalar_fixed;                  ///< per original node: the first scalar unknown is prescribed
  std::vector<double> state;                             ///< the start (original order), Dirichlet values imposed
  /// Every quadrature datum the assemblers read, by name: all global points, the datum's size each.
  std::map<std::string, std::vector<double>, std::less<>> qdata;
};

/// Builds the ProblemSpace of input.nodes (collective over comm). Throws SceneError for a constant
/// without a value or quadrature data of the wrong shape.
[[nodiscard]] ProblemSpace build_problem_space(MPI_Comm comm, const BoundScene& b, const ProblemInput& input);

/// One solve on input.nodes. Collective over comm. Throws for what cannot run (an LME evaluation
/// that fails, a linear solve that breaks down); a solver that does not converge is reported in the
/// result instead.
[[nodiscard]] ProblemResult solve_problem(MPI_Comm comm, const BoundScene& bound, const ProblemInput& input);

/// The scene's initial node set (uniform grid, uniform CVT of a node count, or a point file whose
/// points must lie in the domain).
[[nodiscard]] NodeSet initial_nodes(const Scene& scene, std::ostream* log = nullptr);

/// Values of the scene's [initial] fields at the nodes (original order, dofs interleaved; unknowns
/// without an entry start at 0).
[[nodiscard]] std::vector<double> initial_state(const BoundScene& bound, const NodeSet& nodes);

/// Values at the nodes (original order) of one entry of the scene's [coefficients] (components
/// interleaved). Throws SceneError when the scene gives no such field.
[[nodiscard]] std::vector<double> coefficient_values(const BoundScene& bound, const std::string& name, int components,
                                                     const NodeSet& nodes);

/// One solve of a run: a single solve, or a stage of a model's schedule.
struct StageRecord {
  int stage = 0;
  double parameter = 0;  ///< the continuation parameter of a staged model at this stage (RunSchedule)
  std::string grid;    ///< "uniform" / "file", then "cvt-1", "cvt-2", ... per relocation
  int generation = 0;  ///< relocations along the chain of stages that led here
  std::string label;   ///< " (branch)" for a side solve
  int nodes = 0;
  double h_min = 0;    ///< SpacingSummary::h_min of the stage's grid
  ProblemResult result;
  double wall_s = 0;   ///< this stage: relocation + setup + solve
  double adapt_s = 0;  ///< of which the relocation
};

struct SceneRun {
  std::vector<StageRecord> stages;  ///< the finished stages, in order
  /// Empty when every stage ran; else "stage k: <why>" for the stage that could not run. A stage
  /// whose solver did not converge is the last one, with its result's message.
  std::string failure;
  double wall_s = 0;                ///< the whole run, node set generation included
  std::vector<UnknownField> unknowns;  ///< the layout of every stage's state
  /// Set by a model that runs a schedule of stages (the vesicle's CVT adaptivity in eps): the name
  /// of the constant it continues in; empty for a single solve.
  std::string parameter;
  /// What a model's constraint multipliers mean physically (e.g. "tension"), by constraint name.
  std::map<std::string, std::string, std::less<>> multiplier_meanings;
};



/// A scalar nodal field (values at old_nodes) evaluated at new points with the LME basis of the old
/// nodes (values only): a field carried to another node set (an adapted grid, a re-mesh).
/// A point the old basis cannot evaluate (outside the hull of its neighbours, where a motion tore
/// the old nodes apart) throws LmeEvaluationError, unless `nearest_fallbacks` is given: then it
/// takes the value of its nearest old node, counted there (for a start guess, not a result).
[[nodiscard]] std::vector<double> interpolate_nodal_field(const NodeSet& old_nodes, std::span<const double> phi, double gamma,
                                                          const LmeOptions& lme, const NodeSet& new_nodes,
                                                          std::size_t* nearest_fallbacks = nullptr);

/// Nodal coefficients whose LME field takes the given values at the nodes themselves: LME is not
/// interpolating (Σ_a p_a(x_b) φ_a ≠ φ_b), so using values as coefficients smooths the field once
/// more (an interface widens). Richardson iterations on P φ = g, P_ba = p_a(x_b), an averaging
/// operator with eigenvalues in (0, 1]; 0 iterations returns the values.
[[nodiscard]] std::vector<double> fit_nodal_values(const NodeSet& nodes, std::span<const double> values, double gamma,
                                                   const LmeOptions& lme, int iterations);

/// The L2 projection onto the LME space of `nodes` of a field known only at weighted points (a
/// field carried by quadrature points, as a material field after a motion): the coefficients c
/// minimizing Σ_q w_q (Σ_a p_a(x_q) c_a − v_q)². The mass matrix is never formed (a point sees
/// O(100) nodes at small γ): Jacobi-preconditioned conjugate gradients from `start`, to a relative
/// residual `tolerance`. Points with w_q ≤ 0 are skipped. Throws std::runtime_error if a node has
/// no point in its support.
struct PointProjection {
  std::vector<double> values;
  int iterations = 0;
  double relative_residual = 0;
};
/// The field's gradient at the same points (dim values per point) and a length ℓ: the projection
/// then minimizes Σ_q w_q [(φ(x_q) − v_q)² + ℓ² |∇φ(x_q) − g_q|²], an H1 fit for fields whose use
/// depends on their derivatives. ℓ = 0 or no values: the L2 projection.
struct PointGradients {
  std::span<const double> values;
  double length = 0;
};
[[nodiscard]] PointProjection project_point_values(const NodeSet& nodes, double gamma, const LmeOptions& lme,
                                                   std::span<const double> points, std::span<const double> weights,
                                                   std::span<const double> values, std::span<const double> start,
                                                   double tolerance = 1e-8, int max_iterations = 5000,
                                                   PointGradients gradients = {});

/// "; did you mean 'x'?" for the candidate closest to a misspelt name, else "".
[[nodiscard]] std::string did_you_mean(std::string_view name, const std::vector<std::string>& candidates);

/// The original indices of the nodes on a named boundary part (box sides, "hull", "axis").
[[nodiscard]] std::vector<int> boundary_nodes(const Scene& scene, const NodeSet& nodes, const std::string& part);

}  // namespace lmeform::app
