// One linear solve A x = b of an assembled problem through PETSc KSP, with what mixed problems need:
// - MUMPS LU by default; the options database overrides it (-ksp_type, -pc_type fieldsplit, ...);
// - the unknown fields named as PCFIELDSPLIT splits (-fieldsplit_u_..., -fieldsplit_p_...), so a
//   Schur-complement preconditioner is a matter of options;
// - unknowns known only up to a constant (the pressure of enclosed flow), fixed by ∫ u dx = 0:
//   with a direct solver through the bordered system [A c; cᵀ 0][x; λ] = [b; 0] (non-singular, one
//   dense row and column per condition); with an iterative one through the null space handed to the
//   Krylov method, the mean removed from the result.
#pragma once

#include <petscksp.h>

#include <span>
#include <string>
#include <vector>

#include "lmeform/petsc.hpp"
#include "toolkit.hpp"

namespace lmeform::problems {

struct LinearSystemLayout {
  int dofs_per_node = 1;
  std::vector<UnknownField> fields;
  /// For each zero-mean condition: c with c_i = ∫ N_a dx at the dofs of the field, 0 elsewhere.
  std::vector<Vec> mean_functionals;
  /// For each zero-mean condition: the constant mode (1 at the field's dofs, 0 elsewhere).
  std::vector<Vec> constant_modes;
};

struct LinearSolveReport {
  bool converged = false;
  int iterations = 0;
  double relative_residual = 0;        ///< |A x − b| / |b| of the system (bordered rows included)
  std::string message;
  std::string zero_mean_method;        ///< "", "constraint" or "null space"
  double seconds = 0;
};

/// [A C; Cᵀ 0] with the columns of C given as vectors of A's layout; the new rows and columns are
/// owned by the last rank, so that every dof of A keeps its global index.
[[nodiscard]] PetscMatrix bordered_matrix(MPI_Comm comm, Mat A, std::span<const Vec> columns);
/// A vector of the bordered layout holding v in its first part and zeros in the k border entries.
[[nodiscard]] PetscVector bordered_vector(MPI_Comm comm, Vec v, PetscInt k);

/// Solves A x = b (x: the start, with any Dirichlet values already in it). Collective.
[[nodiscard]] LinearSolveReport solve_linear_system(MPI_Comm comm, Mat A, Vec b, Vec x, const LinearSystemLayout& layout);

}  // namespace lmeform::problems
