#include "nonlinear_solve.hpp"

#include <petscsnes.h>

#include <limits>

#include <fmt/format.h>

#include "toolkit.hpp"

// PETSc callbacks at global scope: inside namespace lmeform the name PetscError would find
// lmeform::PetscError, not the PETSc function PETSc's macros call.
namespace {

struct SnesContext {
  const std::function<void(Vec, Vec)>* residual;
  const std::function<void(Vec, Mat)>* jacobian;
  const std::vector<PetscInt>* fixed;
};

PetscErrorCode snes_residual(SNES, Vec u, Vec r, void* ctx) {
  auto* c = static_cast<SnesContext*>(ctx);
  try {
    (*c->residual)(u, r);
    // Fixed dofs hold their values: their equations u_i − g_i = 0 hold from the start.
    std::vector<PetscScalar> zeros(c->fixed->size(), 0.0);
    PetscCall(VecSetValues(r, static_cast<PetscInt>(c->fixed->size()), c->fixed->data(), zeros.data(), INSERT_VALUES));
    PetscCall(VecAssemblyBegin(r));
    PetscCall(VecAssemblyEnd(r));
  } catch (const std::exception& e) {
    SETERRQ(PETSC_COMM_SELF, PETSC_ERR_LIB, "%s", e.what());
  }
  return 0;
}

PetscErrorCode snes_jacobian(SNES, Vec u, Mat J, Mat, void* ctx) {
  auto* c = static_cast<SnesContext*>(ctx);
  try {
    (*c->jacobian)(u, J);
    PetscCall(MatZeroRowsColumns(J, static_cast<PetscInt>(c->fixed->size()), c->fixed->data(), 1.0, nullptr, nullptr));
  } catch (const std::exception& e) {
    SETERRQ(PETSC_COMM_SELF, PETSC_ERR_LIB, "%s", e.what());
  }
  return 0;
}

}  // namespace

namespace lmeform::problems {

namespace {

/// Free dofs at their lower and upper bounds (to a relative 1e-10 of the bound).
std::pair<long, long> active_set(const ProblemSpace& space, Vec u) {
  long at[2] = {0, 0};
  const VecReadView x(u), lo(space.lower_bound), hi(space.upper_bound);
  for (PetscInt i = 0; i < x.size(); ++i) {
    if (lo[i] > PETSC_NINFINITY && x[i] <= lo[i] + 1e-10 * std::max(1.0, std::abs(lo[i]))) ++at[0];
    else if (hi[i] < PETSC_INFINITY && x[i] >= hi[i] - 1e-10 * std::max(1.0, std::abs(hi[i]))) ++at[1];
  }
  MPI_Allreduce(MPI_IN_PLACE, at, 2, MPI_LONG, MPI_SUM, space.disc->comm());
  return {at[0], at[1]};
}

/// Whether a free (not fixed) dof has a finite bound on some rank: a solve whose bounds all fall on
/// fixed dofs (the held groups of a staggered solve) is a plain Newton solve.
bool free_dofs_bounded(const ProblemSpace& space) {
  if (!space.bounded()) return false;
  const VecReadView lo(space.lower_bound), hi(space.upper_bound);
  PetscInt first = 0, end = 0;
  LMEFORM_PETSC_CHECK(VecGetOwnershipRange(space.lower_bound, &first, &end));
  std::vector<unsigned char> fixed(static_cast<std::size_t>(lo.size()), 0);
  for (const PetscInt dof : space.fixed)
    if (dof >= first && dof < end) fixed[static_cast<std::size_t>(dof - first)] = 1;
  int bounded = 0;
  for (PetscInt i = 0; i < lo.size() && bounded == 0; ++i)
    if (fixed[static_cast<std::size_t>(i)] == 0 && (lo[i] > PETSC_NINFINITY || hi[i] < PETSC_INFINITY)) bounded = 1;
  MPI_Allreduce(MPI_IN_PLACE, &bounded, 1, MPI_INT, MPI_MAX, space.disc->comm());
  return bounded != 0;
}

}  // namespace

NonlinearSolve solve_nonlinear(MPI_Comm comm, ProblemSpace& space, Vec u, const SceneSolver& solver,
                               const std::function<void(Vec, Vec)>& residual, const std::function<void(Vec, Mat)>& jacobian, Mat J,
                               MatrixSymmetry symmetry) {
  SnesContext ctx{&residual, &jacobian, &space.fixed};
  PetscNonlinearSolver snes;
  LMEFORM_PETSC_CHECK(SNESCreate(comm, snes.out()));
  PetscVector r = space.primary->create_vector();
  LMEFORM_PETSC_CHECK(SNESSetFunction(snes, r, snes_residual, &ctx));
  LMEFORM_PETSC_CHECK(SNESSetJacobian(snes, J, J, snes_jacobian, &ctx));
  // The VI solver factors a new reduced matrix at every step (its inactive set): only where a free
  // dof has a bound. Otherwise the Jacobian keeps its structure and MUMPS its analysis.
  const bool variational_inequality = free_dofs_bounded(space);
  if (variational_inequality) {
    LMEFORM_PETSC_CHECK(SNESSetType(snes, SNESVINEWTONRSLS));
    LMEFORM_PETSC_CHECK(SNESVISetVariableBounds(snes, space.lower_bound, space.upper_bound));
  }
  KSP ksp = nullptr;
  LMEFORM_PETSC_CHECK(SNESGetKSP(snes, &ksp));
  configure_direct_solver(ksp, symmetry);
  LMEFORM_PETSC_CHECK(SNESSetTolerances(snes, 1e-12, solver.newton_tolerance, 1e-14, solver.max_newton_iterations, 10000));
  LMEFORM_PETSC_CHECK(SNESSetFromOptions(snes));
  LMEFORM_PETSC_CHECK(SNESSolve(snes, nullptr, u));
  SNESConvergedReason reason = SNES_CONVERGED_ITERATING;
  PetscInt its = 0;
  PetscReal norm = 0;
  LMEFORM_PETSC_CHECK(SNESGetConvergedReason(snes, &reason));
  LMEFORM_PETSC_CHECK(SNESGetIterationNumber(snes, &its));
  LMEFORM_PETSC_CHECK(SNESGetFunctionNorm(snes, &norm));
  NonlinearSolve out;
  out.converged = reason > 0;
  out.iterations = static_cast<int>(its);
  // SNES leaves the norm unset (0) when the residual is not finite: say so rather than print 0.
  if (reason == SNES_DIVERGED_FNORM_NAN) norm = std::numeric_limits<double>::quiet_NaN();
  out.residual_norm = norm;
  out.message = fmt::format("SNES {}{} after {} Newton steps, |R| = {:.3e}", variational_inequality ? "VI " : "", SNESConvergedReasons[reason], its, norm);
  if (space.bounded()) {
    std::tie(out.active_lower, out.active_upper) = active_set(space, u);
    out.message += fmt::format("; active set: {} dofs at the lower bound, {} at the upper", out.active_lower, out.active_upper);
  }
  return out;
}

}  // namespace lmeform::problems
