// The small toolkit every problem driver shares: the layout of the state vector in unknown fields,
// the LME options of a scene's fields, the constrained minimizer's options from [solver], PETSc
// options scoped to a solve, the direct solver default, and name suggestions for messages.
#pragma once

#include <petscksp.h>

#include <span>
#include <string>
#include <string_view>
#include <vector>

#include "lmeform/constrained_minimizer.hpp"
#include "lmeform/lme_basis.hpp"
#include "lmeform/scene.hpp"

namespace lmeform::problems {

/// A nodal field of the state: name, components, offset within a node's dofs.
struct UnknownField {
  std::string name;
  int components = 1;
  int offset = 0;
};

/// The unknown fields of a state vector whose dofs are interleaved per node (the kernel contract's
/// layout): what splits a state into fields for output, errors and motions.
struct StateLayout {
  std::vector<UnknownField> fields;
  int dofs_per_node = 0;

  /// The field named `name`; throws std::out_of_range.
  [[nodiscard]] const UnknownField& field(std::string_view name) const;
  [[nodiscard]] bool has(std::string_view name) const;
  /// The values of one field, components interleaved, from a state of `nodes` nodes.
  [[nodiscard]] std::vector<double> values(std::span<const double> state, const UnknownField& f) const;
};

/// Whether a field is even in r across the axis of an axisymmetric scene (a scalar: φ_r(0, z) = 0)
/// or odd (a motion's radial component y_r).
enum class AxisParity { even, odd };

/// The LME options of a scene's fields: the smoothing passes on the nodal spacing, and for fields
/// even in r of an axisymmetric scene the basis mirrored across the axis, so that the symmetry
/// holds exactly and φ_r / r stays finite.
[[nodiscard]] LmeOptions lme_options(int spacing_smoothing, bool axisymmetric, AxisParity parity,
                                     LmeConsistency basis = LmeConsistency::first, double support_tolerance = 1e-6);
[[nodiscard]] LmeOptions lme_options(const Scene& scene, AxisParity parity);

/// The constrained minimizer's options from the scene's [solver] table.
[[nodiscard]] ConstrainedMinimizerOptions minimizer_options(const SceneSolver& solver, std::ostream* log);

/// PETSc options of the scene, set for a solve and cleared after it. The command line wins: an
/// option it already sets is left as it is.
class ScopedPetscOptions {
 public:
  explicit ScopedPetscOptions(const std::string& options);
  ~ScopedPetscOptions();
  ScopedPetscOptions(const ScopedPetscOptions&) = delete;
  ScopedPetscOptions& operator=(const ScopedPetscOptions&) = delete;

 private:
  std::vector<std::string> set_;
};

/// MUMPS LU: direct and robust for the indefinite saddle points of mixed problems; the options
/// database overrides it (-ksp_type gmres -pc_type fieldsplit ...). A symmetric matrix (a Hessian)
/// takes MUMPS's LDLᵀ, which pivots for indefinite matrices and costs about half the LU.
enum class MatrixSymmetry { General, Symmetric };
void configure_direct_solver(KSP ksp, MatrixSymmetry symmetry = MatrixSymmetry::General);

/// "; did you mean 'x'?" for the candidate closest to a misspelt name, else "".
[[nodiscard]] std::string did_you_mean(std::string_view name, const std::vector<std::string>& candidates);

}  // namespace lmeform::problems
