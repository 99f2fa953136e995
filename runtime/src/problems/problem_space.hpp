// The assembly side of a bound problem on one node set: the discretization, one Assembler per
// output (constants, coefficients and quadrature data set; an output's integrals over its domains
// inside it), the Dirichlet dofs and the start. What a stationary solve solves once, and what a
// time integrator or a load-stepping driver steps.
#pragma once

#include <mpi.h>

#include <iosfwd>
#include <map>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "bound_scene.hpp"
#include "lmeform/assembler.hpp"
#include "lmeform/constrained_minimizer.hpp"
#include "lmeform/discretization.hpp"
#include "lmeform/node_set.hpp"

namespace lmeform::problems {

/// What one problem space is built from; empty members take the scene's choice.
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
  /// A start outside [bounds] is moved onto them instead of refused (a state carried to new nodes,
  /// whose fitted coefficients overshoot a bound by the transfer's error).
  bool clamp_start_to_bounds = false;
  /// Cells and quadrature points carried from a previous reference configuration (a reset).
  std::optional<CarriedQuadrature> carried;
  /// Quadrature data given by value, by name (every point of every cell, numbered as a carried
  /// quadrature, the datum's size each; each rank keeps its points' values): they replace the
  /// scene's source (a reset's pushed-forward reference field).
  std::map<std::string, std::vector<double>, std::less<>> qdata_values;
  /// Nodal values of scalar [coefficients] fields, by name (input.nodes order): they replace the
  /// scene's (a re-mesh's projected reference field).
  std::map<std::string, std::vector<double>, std::less<>> coefficient_values;
  /// The nodes (original numbering) of each [[dirichlet]] entry, in scene order, in place of the
  /// nodes found on its boundary parts: a moving node set keeps its material boundary.
  std::vector<std::vector<int>> dirichlet_nodes;
  /// The nodes (original numbering) of named boundary parts, in place of the nodes the geometry
  /// finds on them: the parts of a node set that moves with the material (a free surface folding
  /// onto a plate joins the plate's part). Dirichlet entries and reactions on these parts use them.
  std::map<std::string, std::vector<int>, std::less<>> part_nodes;
  /// DiscretizationOptions::flat_cell_tolerance (a moving node set raises it).
  double flat_cell_tolerance = 1e-12;
  /// A discretization of these nodes built by an earlier solve of the same scene: reused, not
  /// rebuilt (a continuation stage that changes a constant only).
  std::shared_ptr<Discretization> discretization;
};

struct ProblemSpace {
  std::shared_ptr<Discretization> disc;
  NodeSet nodes;                                         ///< the nodes, original order
  std::map<std::string, double, std::less<>> constants;  ///< every constant, resolved (targets included)
  /// One assembler per output of the problem, by its label "module.output".
  std::map<std::string, std::unique_ptr<Assembler>, std::less<>> assemblers;
  /// The coefficient fields of each output that reads some, by label: alive as long as the
  /// assemblers reading them (a driver may change them and set them again).
  std::map<std::string, PetscVector, std::less<>> coefficient_vectors;
  std::vector<Assembler*> energy_terms;                  ///< BoundScene::energy, in order
  std::vector<ScalarConstraint> constraints;             ///< BoundScene::constraints, targets and scales set
  std::vector<Assembler*> auxiliary;                     ///< BoundScene::auxiliary, in order
  Assembler* residual = nullptr;
  Assembler* bilinear = nullptr;
  Assembler* linear = nullptr;
  Assembler* primary = nullptr;                          ///< owns the dof layout (first energy, residual, bilinear)
  std::vector<std::vector<int>> dirichlet_nodes;         ///< per [[dirichlet]] entry, original numbering
  std::map<std::string, std::vector<int>, std::less<>> part_nodes;  ///< ProblemInput::part_nodes
  std::vector<std::pair<int, int>> fixed_pairs;          ///< (original node, dof within the node) with Dirichlet values
  std::vector<PetscInt> fixed;                           ///< the same as owned global dofs
  std::vector<double> state;                             ///< the start (original order), Dirichlet values imposed
  /// The quadrature data the driver gave or computed from fields (ProblemInput::qdata_values, [qdata]
  /// field jets), by name: the points this rank holds (Discretization::quadrature()), the datum's
  /// size each.
  std::map<std::string, std::vector<double>, std::less<>> qdata;
  /// [bounds]: the lower and upper bound of every dof (±infinity where free or prescribed);
  /// empty when the problem has none.
  PetscVector lower_bound, upper_bound;

  [[nodiscard]] bool bounded() const noexcept { return static_cast<Vec>(lower_bound) != nullptr; }
  /// A Newton solver kept for the next solve of the same Jacobian with the same fixed dofs: the
  /// groups of a staggered solve are solved again every round of every load step, and so build
  /// their matrix structure and the direct solver's analysis once (solve_nonlinear).
  struct KeptNewtonSolver {
    std::string jacobian;          ///< which Jacobian (the driver's name for it)
    std::vector<PetscInt> fixed;   ///< the fixed dofs it was built for
    bool variational_inequality = false;
    std::string options_prefix;    ///< the PETSc options prefix it was built with
    PetscMatrix matrix;
    PetscVector residual;
    PetscNonlinearSolver snes;
  };
  std::vector<KeptNewtonSolver> kept_newton_solvers;  ///< the most recently used last
  /// The PETSc options prefix of the next Newton solves ("": none). A staggered solve sets its
  /// group's ("v_" for the group ["v"]), so that `-v_ksp_type cg -v_pc_type hypre` reaches
  /// that group's linear solves alone.
  std::string solver_options_prefix;
  /// The bounds given as "previous" become the state u (after a converged load step).
  void update_previous_bounds(const BoundScene& b, Vec u);

  /// Sets a constant in every assembler that reads it.
  void set_constant(const std::string& name, double value);
  /// Writes the Dirichlet values, evaluated with the expressions' current constants, into u
  /// (owned dofs): a load step's prescribed values.
  void impose_dirichlet_values(const BoundScene& b, Vec u) const;
  /// Σ energies at u.
  [[nodiscard]] double energy(Vec u) const;
  /// The constraints' values at u, in order.
  [[nodiscard]] std::vector<double> constraint_values(Vec u) const;
};

/// Builds the ProblemSpace of input.nodes (collective over comm). Throws SceneError for a constant
/// without a value or quadrature data of the wrong shape.
[[nodiscard]] ProblemSpace build_problem_space(MPI_Comm comm, const BoundScene& b, const ProblemInput& input);

/// The nodes (original numbering) on the boundary parts of each [[dirichlet]] entry, in scene
/// order; throws SceneError for an entry whose parts hold no node.
[[nodiscard]] std::vector<std::vector<int>> dirichlet_nodes(const BoundScene& b, const NodeSet& nodes,
                                                          const std::map<std::string, std::vector<int>, std::less<>>& part_nodes = {});

/// The original indices of the nodes on a named boundary part of the domain ("hull": the nodes on
/// the convex hull of the node set).
[[nodiscard]] std::vector<int> boundary_nodes(const Domain& geometry, const NodeSet& nodes, const std::string& part);
/// The same, taken from `part_nodes` when the part is there (a part that follows its nodes).
[[nodiscard]] std::vector<int> boundary_nodes(const Domain& geometry, const NodeSet& nodes, const std::string& part,
                                              const std::map<std::string, std::vector<int>, std::less<>>& part_nodes);

/// Values at the nodes (original order, dofs interleaved) of the scene's [initial] fields (unknowns
/// without an entry start at 0).
[[nodiscard]] std::vector<double> initial_state(const BoundScene& b, const NodeSet& nodes);

/// Values at the nodes (original order) of one [coefficients] field (components interleaved).
/// Throws SceneError when the scene gives no such field.
[[nodiscard]] std::vector<double> coefficient_values(const BoundScene& b, const std::string& name, int components, const NodeSet& nodes);

/// The layout of the coefficient fields kernel `k` reads (coefficient_components_per_node per node).
[[nodiscard]] StateLayout kernel_coefficient_layout(const kernel::FormKernels& k);

/// Values at the nodes (original order) of the coefficient fields kernel `k` reads, in its layout
/// (coefficient_components_per_node per node): from [coefficients], or from `given` for scalar fields.
[[nodiscard]] std::vector<double> kernel_coefficient_values(const BoundScene& b, const kernel::FormKernels& k, const NodeSet& nodes,
                                                            const std::map<std::string, std::vector<double>, std::less<>>& given);

/// The scene's initial node set (uniform grid, uniform CVT of a node count, or a point file whose
/// points must lie in the domain).
[[nodiscard]] NodeSet initial_nodes(const Scene& scene, MPI_Comm comm, std::ostream* log = nullptr);

}  // namespace lmeform::problems
