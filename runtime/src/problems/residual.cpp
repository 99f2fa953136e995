// R(u; v) = 0 for all v by Newton's method (PETSc SNES, MUMPS LU by default, the options database
// passed through): the stationary driver of scenes that name model.residual.
#include <petscsnes.h>

#include <limits>

#include <fmt/format.h>

#include "problem_registry.hpp"
#include "stationary.hpp"
#include "variational_inequality.hpp"

// PETSc callbacks at global scope: inside namespace lmeform the name PetscError would find
// lmeform::PetscError, not the PETSc function PETSc's macros call.
namespace {

struct SnesContext {
  lmeform::Assembler* residual;
  const std::vector<PetscInt>* fixed;
};

PetscErrorCode snes_residual(SNES, Vec u, Vec r, void* ctx) {
  auto* c = static_cast<SnesContext*>(ctx);
  try {
    c->residual->vector(u, r);
    // Fixed dofs hold their prescribed values: their equations are u_i − g_i = 0, satisfied from the start.
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
    c->residual->matrix(u, J);
    PetscCall(MatZeroRowsColumns(J, static_cast<PetscInt>(c->fixed->size()), c->fixed->data(), 1.0, nullptr, nullptr));
  } catch (const std::exception& e) {
    SETERRQ(PETSC_COMM_SELF, PETSC_ERR_LIB, "%s", e.what());
  }
  return 0;
}

}  // namespace

namespace lmeform::problems {

namespace {

class ResidualDriver final : public StationaryDriver {
 public:
  [[nodiscard]] std::string_view name() const override { return "residual"; }
  [[nodiscard]] bool claims(const Scene& scene) const override { return scene.model.residual.has_value(); }
  [[nodiscard]] OutputRoles roles(const Scene& scene) const override {
    OutputRoles r;
    r.residual = scene.model.residual;
    return r;
  }
  void solve(MPI_Comm comm, const BoundScene& b, ProblemSpace& space, const ProblemInput&, Vec u, ProblemResult& result) const override {
    if (space.bounded()) {
      PetscMatrix J = space.residual->create_matrix();
      take_bounded_solve(solve_bounded(comm, space, u, b.scene->solver, [&](Vec x, Vec F) { space.residual->vector(x, F); },
                                       [&](Vec x, Mat A) { space.residual->matrix(x, A); }, J),
                         result);
      result.energy = std::numeric_limits<double>::quiet_NaN();
      return;
    }
    SnesContext ctx{space.residual, &space.fixed};
    PetscNonlinearSolver snes;
    LMEFORM_PETSC_CHECK(SNESCreate(comm, snes.out()));
    PetscMatrix J = space.residual->create_matrix();
    PetscVector r = space.residual->create_vector();
    LMEFORM_PETSC_CHECK(SNESSetFunction(snes, r, snes_residual, &ctx));
    LMEFORM_PETSC_CHECK(SNESSetJacobian(snes, J, J, snes_jacobian, &ctx));
    KSP ksp = nullptr;
    LMEFORM_PETSC_CHECK(SNESGetKSP(snes, &ksp));
    configure_direct_solver(ksp);
    const SceneSolver& solver = b.scene->solver;
    LMEFORM_PETSC_CHECK(SNESSetTolerances(snes, 1e-12, solver.newton_tolerance, 1e-14, solver.max_newton_iterations, 10000));
    LMEFORM_PETSC_CHECK(SNESSetFromOptions(snes));
    LMEFORM_PETSC_CHECK(SNESSolve(snes, nullptr, u));
    SNESConvergedReason reason = SNES_CONVERGED_ITERATING;
    PetscInt its = 0;
    PetscReal norm = 0;
    LMEFORM_PETSC_CHECK(SNESGetConvergedReason(snes, &reason));
    LMEFORM_PETSC_CHECK(SNESGetIterationNumber(snes, &its));
    LMEFORM_PETSC_CHECK(SNESGetFunctionNorm(snes, &norm));
    result.converged = reason > 0;
    result.message = fmt::format("SNES {} after {} Newton steps, |R| = {:.3e}", SNESConvergedReasons[reason], its, norm);
    result.iterations = static_cast<int>(its);
    result.residual_norm = norm;
    result.energy = std::numeric_limits<double>::quiet_NaN();
  }
  void residual(const BoundScene&, ProblemSpace& space, Vec u, const ProblemResult&, Vec out) const override { space.residual->vector(u, out); }
  void describe(const BoundScene&, const ProblemResult& r, RunReport& report) const override { describe_equation_solve(r, report); }
};

}  // namespace

const StationaryDriver& residual_driver() {
  static const ResidualDriver driver;
  return driver;
}

}  // namespace lmeform::problems
