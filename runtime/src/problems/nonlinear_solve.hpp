// F(u) = 0 by Newton's method (PETSc SNES, MUMPS LU by default, the options database passed
// through), the fixed dofs held. Under the problem space's bounds it is a variational inequality:
// F = 0 where lower < u < upper, F pushing outward where u is at a bound, solved by PETSc's
// reduced-space active-set Newton (SNESVINEWTONRSLS). A residual problem's F is R, a bounded
// minimization's ∇E (Jacobian ∇²E), a bounded linear problem's A u − b (Jacobian A).
#pragma once

#include <mpi.h>

#include <functional>
#include <string>

#include "lmeform/petsc.hpp"
#include "lmeform/scene.hpp"
#include "problem_space.hpp"
#include "toolkit.hpp"

namespace lmeform::problems {

struct NonlinearSolve {
  bool converged = false;
  std::string message;
  int iterations = 0;
  double residual_norm = 0;
  long active_lower = -1, active_upper = -1;  ///< bounded: free dofs at their lower / upper bound at the end
};

/// What solve_nonlinear's Jacobian is: its name (solvers are kept per name and fixed dofs), a
/// function that creates its matrix for the space's fixed dofs, and whether it is symmetric
/// (a Hessian: factored by LDLᵀ).
struct JacobianSpec {
  std::string name;
  std::function<PetscMatrix()> create;
  MatrixSymmetry symmetry = MatrixSymmetry::General;
};

/// Solves from u (Dirichlet values imposed), the fixed dofs held, under space's bounds if it has
/// them. `residual(u, F)` and `jacobian(u, J)` assemble the problem without boundary conditions.
/// The SNES, its matrix and the direct solver's analysis are kept in the space
/// (ProblemSpace::kept_newton_solvers) and reused by the next solve of the same Jacobian with
/// the same fixed dofs.
[[nodiscard]] NonlinearSolve solve_nonlinear(MPI_Comm comm, ProblemSpace& space, Vec u, const SceneSolver& solver,
                                         const std::function<void(Vec, Vec)>& residual, const std::function<void(Vec, Mat)>& jacobian,
                                         const JacobianSpec& spec);

}  // namespace lmeform::problems
