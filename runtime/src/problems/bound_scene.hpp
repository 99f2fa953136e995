// A scene bound to its loaded forms: every name the scene uses checked against the forms, every
// table turned into what the lower layers need (outputs with their kernels, the unknowns' layout,
// constants, Dirichlet data, nodal fields, quadrature-data sources, expressions). Binding is the
// one place that reads the scene's problem tables; the problem space, the solves and the drivers
// read the bound scene. A driver says which outputs it solves with, and in which role
// (OutputRoles); binding knows no kind of problem.
#pragma once

#include <mpi.h>

#include <filesystem>
#include <iosfwd>
#include <map>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "expressions.hpp"
#include "lmeform/form_registry.hpp"
#include "lmeform/kernel.hpp"
#include "lmeform/node_sets.hpp"
#include "lmeform/scene.hpp"
#include "toolkit.hpp"

namespace lmeform::problems {

class StationaryDriver;

/// Which outputs of the forms a problem is made of, and what they are for.
struct OutputRoles {
  /// Energies summed into the objective of a minimization.
  std::vector<SceneName> energies;
  /// Every energy output of the forms (in the scene's dimension) is summed into the objective.
  bool all_energies = false;
  /// The scene's [constraints] constrain the objective (else a [constraints] table is refused).
  bool constraints = false;
  std::optional<SceneName> residual;
  std::optional<SceneName> bilinear, linear;
  /// Energies a driver assembles besides the problem (a time integrator's dissipation): their
  /// constants and data are checked like the problem's; they may name other unknowns (same dofs
  /// per node), and a coefficient named after an unknown of the problem is its current value.
  std::vector<SceneName> auxiliary;
  /// Constants a driver sets itself (not required in [constants]).
  std::vector<std::string> provided_constants;
};

/// One output of the problem: its kernels, one per integration domain (the cells, and for a form
/// with boundary integrals each boundary part it integrates over), summed by the assembly.
struct BoundOutput {
  std::string label;  ///< "module.output"
  std::vector<const kernel::FormKernels*> kernels;
  [[nodiscard]] const kernel::FormKernels& first() const { return *kernels.front(); }
};

struct BoundConstraint {
  std::string name;
  BoundOutput output;
  double target = 0;
  double scale = 1;
  std::string target_constant;  ///< the form's constant holding the target ("" for a number)
  bool initial = false;         ///< the target is the constraint's value at the start state
  bool scale_given = false;     ///< the scene gave the scale (else it follows the target)
};

/// A value of a bound scene entry: a number, or a compiled point expression (handle into
/// BoundScene::expressions).
struct BoundValue {
  double number = 0;
  int expression = -1;
  [[nodiscard]] bool is_expression() const noexcept { return expression >= 0; }
};

/// An entry of [initial] or [coefficients]: a nodal field's values, from a value or a previous
/// run's output file.
struct BoundNodalField {
  std::string name;             ///< the unknown or coefficient it sets
  BoundValue value;
  std::filesystem::path file;   ///< non-empty: read from this HDF5 output
  std::string dataset;          ///< the file's field
  std::string where;
};

/// A [[dirichlet]] entry: nodal values of chosen components of an unknown on named boundary parts.
struct BoundDirichlet {
  std::vector<std::string> parts;
  UnknownField field;
  std::vector<int> components;  ///< every component when the scene lists none
  BoundValue value;
  std::string where;
};

/// An [[equipotential]] entry: a scalar unknown held equal, at a value the solve finds, on the
/// nodes of some boundary parts (a floating electrode), with its total charge given.
struct BoundEquipotential {
  std::vector<std::string> parts;
  UnknownField field;
  double charge = 0;            ///< the prescribed total charge: the energy gains charge × the common value
  std::string name;             ///< prefix of the reported quantities <name>_potential, <name>_charge
  std::string where;
};

/// Where a quadrature datum comes from.
struct BoundQdata {
  std::string name;
  SceneQdata::Source source = SceneQdata::Source::zero;
  int size = 1;                 ///< values per point
  BoundValue value;             ///< Source::value
  std::string field;            ///< Source::field: the [coefficients] field
  int derivative = 0;           ///< Source::field: 0 value, 1 gradient, 2 Hessian
  std::string where;
};

/// An exact solution of one unknown ([reference.solution]): errors are reported against it.
struct BoundExactSolution {
  UnknownField field;
  std::string expression;
  std::string where;
};

/// Bounds of an unknown ([bounds]): a value (number or expression) or the previous state per side.
struct BoundBound {
  UnknownField field;
  std::optional<BoundValue> lower, upper;
  bool lower_previous = false, upper_previous = false;
  std::string where;
};

/// A quantity of interest ([quantities]), with what it reads bound.
struct BoundQuantity {
  SceneQuantity scene;
  UnknownField field;                 ///< reaction, probe of an unknown
  const kernel::FormKernels* point = nullptr;  ///< probe of a point output
  std::optional<BoundOutput> integral;  ///< integral: its generated kernels; energy: the problem's output
};

/// What the discretization of a scene is made of.
struct DiscretizationSettings {
  double gamma = 0.8;
  int quadrature_points = 6;
  int spacing_smoothing = 5;
  bool consistent_integration = false;  ///< gradients corrected cell by cell (DiscretizationOptions)
  LmeConsistency basis = LmeConsistency::first;  ///< first- or second-order max-ent basis
  PartitionMethod partition = PartitionMethod::Metis;  ///< how the nodes are split among ranks
  double support_tolerance = 1e-6;  ///< LmeOptions::tol0: the Gaussian weight at the support's edge
  std::vector<MirrorPlane> mirrors;  ///< [domain] mirror: planes the fields are even across
};

/// A scene with its forms loaded and every name checked against them.
struct BoundScene {
  const Scene* scene = nullptr;  ///< for drivers that read their own tables; lower layers do not
  std::string source;            ///< the scene file, for messages
  MPI_Comm comm = MPI_COMM_SELF; ///< the ranks it was bound on, which read its field files together
  int dim = 2;
  bool axisymmetric = false;
  Box domain;                    ///< the box, or the bounding box of the geometry
  Domain geometry;               ///< with its named boundary parts
  int boundary_points = 3;       ///< of the rule per boundary segment (2D) or triangle (3D)
  /// The boundary parts the outputs integrate over (ds(part); "" for ds), each once.
  std::vector<std::string> boundary_parts;
  DiscretizationSettings discretization;
  /// The stationary solve of this problem (minimization, residual, linear): the driver whose
  /// roles bound the outputs.
  const StationaryDriver* solver = nullptr;

  std::vector<const FormModule*> modules;
  std::vector<BoundOutput> energy;       ///< the summed energy terms
  std::vector<BoundConstraint> constraints;
  std::optional<BoundOutput> residual;
  std::optional<BoundOutput> bilinear, linear;
  std::vector<BoundOutput> auxiliary;
  /// The output that owns the dof layout (first energy, the residual or the bilinear form).
  const BoundOutput* primary = nullptr;

  StateLayout layout;                    ///< the unknowns
  int basis_order = 0;                   ///< the highest derivative order the kernels read
  /// Every constant of the used kernels: the scene's value, else the form's default (NaN: set by
  /// the driver or from a constraint's start value).
  std::map<std::string, double, std::less<>> constants;
  std::shared_ptr<PointExpressions> expressions;
  std::vector<BoundNodalField> initial;
  std::vector<BoundNodalField> coefficients;
  std::vector<UnknownField> coefficient_fields;  ///< the known nodal fields the kernels read
  std::vector<BoundDirichlet> dirichlet;
  std::vector<BoundQdata> qdata;
  std::vector<std::string> zero_mean;    ///< scalar unknowns fixed by ∫ u dx = 0
  /// Saddle points: the unknowns the energy is maximized over (model.maximize).
  std::vector<std::string> maximize;
  std::vector<BoundEquipotential> equipotentials;
  std::vector<BoundExactSolution> exact;
  std::vector<BoundQuantity> quantities;
  /// The point outputs of the forms (`point NAME = ...`) that the unknowns and constants alone
  /// determine, with their field names ("stress", or "module.stress" when two forms define it):
  /// written at the nodes with a solution when the scene writes fields, and probed.
  std::vector<std::pair<std::string, const kernel::FormKernels*>> point_outputs;
  bool write_point_fields = false;
  std::vector<BoundBound> bounds;

  [[nodiscard]] const UnknownField& unknown(std::string_view name) const { return layout.field(name); }
  /// Every output the problem assembles, in the order: energies, constraints, residual, bilinear,
  /// linear, auxiliary.
  [[nodiscard]] std::vector<const BoundOutput*> outputs() const;
  /// The nodal-spacing smoothing and the axis mirror for a field of this parity.
  [[nodiscard]] LmeOptions lme(AxisParity parity) const;
};

/// Loads the scene's forms (built-in or JIT, collective over comm), binds the outputs of `solver`'s
/// roles (extended by `extra`: auxiliary outputs, provided constants) and checks every name the
/// scene uses against the forms. Throws SceneError naming file, line and key, or FormLoadError for a
/// form that cannot be loaded.
[[nodiscard]] BoundScene bind_scene(const Scene& scene, MPI_Comm comm, std::ostream* log, const StationaryDriver& solver,
                                    const OutputRoles& extra = {});

/// Binds with the stationary driver that claims the scene's [model] outputs (problem_registry).
[[nodiscard]] BoundScene bind_scene(const Scene& scene, MPI_Comm comm, std::ostream* log, const OutputRoles& extra = {});

}  // namespace lmeform::problems
