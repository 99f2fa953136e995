// A stationary problem under bounds: F(u) = 0 where lower < u < upper, F pushing outward where u
// is at a bound (a variational inequality), solved by PETSc's reduced-space active-set Newton
// (SNESVINEWTONRSLS) with MUMPS LU on the free dofs' Jacobian. A minimization's F is ∇E and its
// Jacobian ∇²E; a residual problem's its R and dR/du; a linear problem's A u − b and A.
#pragma once

#include <mpi.h>

#include <functional>
#include <string>

#include "lmeform/petsc.hpp"
#include "lmeform/scene.hpp"
#include "problem_space.hpp"

namespace lmeform::problems {

struct BoundedSolve {
  bool converged = false;
  std::string message;
  int iterations = 0;
  double residual_norm = 0;
  long active_lower = 0, active_upper = 0;  ///< free dofs at their lower / upper bound at the end
};

/// Solves from u (Dirichlet values imposed), the fixed dofs held. `residual(u, F)` and
/// `jacobian(u, J)` assemble the problem without boundary conditions; J is their matrix.
[[nodiscard]] BoundedSolve solve_bounded(MPI_Comm comm, ProblemSpace& space, Vec u, const SceneSolver& solver,
                                         const std::function<void(Vec, Vec)>& residual, const std::function<void(Vec, Mat)>& jacobian, Mat J);

}  // namespace lmeform::problems
