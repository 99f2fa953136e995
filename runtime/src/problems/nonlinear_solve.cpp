#include "nonlinear_solve.hpp"

#include <petscsnes.h>

#include <algorithm>
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

/// The kept solver for `spec` with the space's fixed dofs, or a new one (the oldest dropped
/// beyond a few). A kept SNES keeps its KSP, whose factorization sees the same matrix with the
/// same nonzero structure and so repeats only the numeric phase.
ProblemSpace::KeptNewtonSolver& kept_solver(MPI_Comm comm, ProblemSpace& space, const JacobianSpec& spec, bool variational_inequality,
                                            const SceneSolver& solver) {
  constexpr std::size_t kMostKept = 4;
  auto& kept = space.kept_newton_solvers;
  const auto found = std::find_if(kept.begin(), kept.end(), [&](const ProblemSpace::KeptNewtonSolver& k) {
    return k.jacobian == spec.name && k.variational_inequality == variational_inequality && k.options_prefix == space.solver_options_prefix &&
           k.fixed == space.fixed;
  });
  // Each rank compares its own fixed dofs; the SNES objects are collective, so the lists change in
  // step on every rank: a solver is reused only where every rank found the same one.
  int index[2] = {found == kept.end() ? -1 : static_cast<int>(found - kept.begin()), 0};
  index[1] = -index[0];
  MPI_Allreduce(MPI_IN_PLACE, index, 2, MPI_INT, MPI_MIN, comm);
  if (index[0] >= 0 && index[0] == -index[1]) {
    const auto same = kept.begin() + index[0];
    std::rotate(same, same + 1, kept.end());  // most recently used last
    return kept.back();
  }
  if (kept.size() >= kMostKept) kept.erase(kept.begin());
  ProblemSpace::KeptNewtonSolver k;
  k.jacobian = spec.name;
  k.fixed = space.fixed;
  k.variational_inequality = variational_inequality;
  k.options_prefix = space.solver_options_prefix;
  k.matrix = spec.create();
  k.residual = space.primary->create_vector();
  LMEFORM_PETSC_CHECK(SNESCreate(comm, k.snes.out()));
  if (!k.options_prefix.empty()) LMEFORM_PETSC_CHECK(SNESSetOptionsPrefix(k.snes, k.options_prefix.c_str()));
  if (variational_inequality) LMEFORM_PETSC_CHECK(SNESSetType(k.snes, SNESVINEWTONRSLS));
  KSP ksp = nullptr;
  LMEFORM_PETSC_CHECK(SNESGetKSP(k.snes, &ksp));
  configure_direct_solver(ksp, spec.symmetry);
  LMEFORM_PETSC_CHECK(SNESSetTolerances(k.snes, 1e-12, solver.newton_tolerance, 1e-14, solver.max_newton_iterations, 10000));
  LMEFORM_PETSC_CHECK(SNESSetFromOptions(k.snes));
  kept.push_back(std::move(k));
  return kept.back();
}

struct SnesOutcome {
  SNESConvergedReason reason = SNES_CONVERGED_ITERATING;
  PetscInt iterations = 0;
  PetscReal norm = 0;
};

SnesOutcome outcome_of(SNES snes) {
  SnesOutcome o;
  LMEFORM_PETSC_CHECK(SNESGetConvergedReason(snes, &o.reason));
  LMEFORM_PETSC_CHECK(SNESGetIterationNumber(snes, &o.iterations));
  LMEFORM_PETSC_CHECK(SNESGetFunctionNorm(snes, &o.norm));
  return o;
}

/// A Hessian's Newton direction minimizes; the default line search asks |R| to fall, which an
/// energy with kinks in its second derivative (a tension-compression split's max(tr ε, 0)²) can
/// refuse forever while the energy still falls: the Newton steps then cycle between active
/// patterns (measured: SENT on nested grids, |R| stuck at 4.5e-6 for 25 steps, the same with
/// every cut of the load, as the energy is homogeneous in it). A minimization that failed so is
/// solved again from `start` with the critical-point line search, which minimizes the energy
/// along the direction (R·direction = 0): 15 Newton steps there. Returns what the log should say
/// of the retry (empty: none); `outcome` becomes the retry's, its iterations both solves'.
std::string resolve_along_energy(SNES snes, Vec start, Vec u, SnesOutcome& outcome) {
  if (outcome.reason > 0 || outcome.reason == SNES_DIVERGED_FNORM_NAN || outcome.reason == SNES_DIVERGED_FUNCTION_DOMAIN) return {};
  SNESLineSearch line_search = nullptr;
  LMEFORM_PETSC_CHECK(SNESGetLineSearch(snes, &line_search));
  SNESLineSearchType type = nullptr;
  LMEFORM_PETSC_CHECK(SNESLineSearchGetType(line_search, &type));
  const std::string kept_type = type != nullptr ? type : SNESLINESEARCHBT;
  if (kept_type == SNESLINESEARCHCP) return {};
  const std::string said = fmt::format(" (the {} line search gave {} after {} steps, |R| = {:.3e}; solved again with the critical-point one)",
                                       kept_type, SNESConvergedReasons[outcome.reason], outcome.iterations, outcome.norm);
  const PetscInt first_iterations = outcome.iterations;
  LMEFORM_PETSC_CHECK(VecCopy(start, u));
  LMEFORM_PETSC_CHECK(SNESLineSearchSetType(line_search, SNESLINESEARCHCP));
  const PetscErrorCode solved = SNESSolve(snes, nullptr, u);
  LMEFORM_PETSC_CHECK(SNESLineSearchSetType(line_search, kept_type.c_str()));  // the kept solver keeps its default
  LMEFORM_PETSC_CHECK(solved);
  outcome = outcome_of(snes);
  outcome.iterations += first_iterations;
  return said;
}

}  // namespace

NonlinearSolve solve_nonlinear(MPI_Comm comm, ProblemSpace& space, Vec u, const SceneSolver& solver,
                               const std::function<void(Vec, Vec)>& residual, const std::function<void(Vec, Mat)>& jacobian,
                               const JacobianSpec& spec) {
  SnesContext ctx{&residual, &jacobian, &space.fixed};
  // The VI solver factors a new reduced matrix at every step (its inactive set): only where a free
  // dof has a bound. Otherwise the Jacobian keeps its structure and MUMPS its analysis.
  const bool variational_inequality = free_dofs_bounded(space);
  ProblemSpace::KeptNewtonSolver& kept = kept_solver(comm, space, spec, variational_inequality, solver);
  SNES snes = kept.snes;
  // The callbacks' context lives for this solve only: set again every time.
  LMEFORM_PETSC_CHECK(SNESSetFunction(snes, kept.residual, snes_residual, &ctx));
  LMEFORM_PETSC_CHECK(SNESSetJacobian(snes, kept.matrix, kept.matrix, snes_jacobian, &ctx));
  if (variational_inequality) LMEFORM_PETSC_CHECK(SNESVISetVariableBounds(snes, space.lower_bound, space.upper_bound));
  // A minimization keeps its start, from which resolve_along_energy solves it again if it fails.
  const bool minimizes = spec.symmetry == MatrixSymmetry::Symmetric && !variational_inequality;
  PetscVector start;
  if (minimizes) {
    start = space.primary->create_vector();
    LMEFORM_PETSC_CHECK(VecCopy(u, start));
  }
  LMEFORM_PETSC_CHECK(SNESSolve(snes, nullptr, u));
  SnesOutcome outcome = outcome_of(snes);
  std::string retried;
  if (minimizes) retried = resolve_along_energy(snes, start, u, outcome);
  NonlinearSolve out;
  out.converged = outcome.reason > 0;
  out.iterations = static_cast<int>(outcome.iterations);
  // SNES leaves the norm unset (0) when the residual is not finite: say so rather than print 0.
  if (outcome.reason == SNES_DIVERGED_FNORM_NAN) outcome.norm = std::numeric_limits<double>::quiet_NaN();
  out.residual_norm = outcome.norm;
  out.message = fmt::format("SNES {}{} after {} Newton steps, |R| = {:.3e}{}", variational_inequality ? "VI " : "",
                            SNESConvergedReasons[outcome.reason], outcome.iterations, outcome.norm, retried);
  if (space.bounded()) {
    std::tie(out.active_lower, out.active_upper) = active_set(space, u);
    out.message += fmt::format("; active set: {} dofs at the lower bound, {} at the upper", out.active_lower, out.active_upper);
  }
  return out;
}

}  // namespace lmeform::problems
