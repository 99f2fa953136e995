// a(u, v) = l(v) for all v by one linear solve (PETSc KSP, MUMPS LU by default): the stationary
// driver of scenes that name model.bilinear and model.linear. Unknowns known only up to a constant
// (model.zero_mean) are fixed by ∫ u dx = 0.
#include <limits>

#include <fmt/format.h>

#include "expressions.hpp"
#include "lmeform/stopwatch.hpp"
#include "linear_system.hpp"
#include "problem_registry.hpp"
#include "stationary.hpp"
#include "nonlinear_solve.hpp"

namespace lmeform::problems {

namespace {

/// c_a = ∫ N_a dx at the dofs of a zero-mean field (the gradient of ∫ u dx, assembled like any
/// form) and the field's constant mode.
void add_zero_mean_condition(MPI_Comm comm, const BoundScene& b, const ProblemSpace& space, const UnknownField& f, std::ostream* log,
                             LinearSystemLayout& layout, std::vector<PetscVector>& keep) {
  const Discretization& disc = *space.disc;
  const int bs = b.layout.dofs_per_node;
  const FormModule& integral = compile_integral_form(b.dim, comm, log);
  Assembler integral_form(disc, integral.at("integral", b.dim));
  PetscVector one = integral_form.create_vector(), weights = integral_form.create_vector();
  LMEFORM_PETSC_CHECK(VecSet(one, 1.0));
  integral_form.vector(one, weights);
  PetscVector c = space.primary->create_vector(), mode = space.primary->create_vector();
  LMEFORM_PETSC_CHECK(VecSet(c, 0.0));
  LMEFORM_PETSC_CHECK(VecSet(mode, 0.0));
  {
    const VecReadView w(weights);
    VecWriteView cv(c), mv(mode);
    for (PetscInt i = 0; i < w.size(); ++i) {
      cv[i * bs + f.offset] = w[i];
      mv[i * bs + f.offset] = 1.0;
    }
  }
  layout.mean_functionals.push_back(c);
  layout.constant_modes.push_back(mode);
  keep.push_back(std::move(c));
  keep.push_back(std::move(mode));
}

class LinearDriver final : public StationaryDriver {
 public:
  [[nodiscard]] std::string_view name() const override { return "linear"; }
  [[nodiscard]] bool claims(const Scene& scene) const override { return scene.model.bilinear.has_value(); }
  [[nodiscard]] OutputRoles roles(const Scene& scene) const override {
    OutputRoles r;
    r.bilinear = scene.model.bilinear;
    r.linear = scene.model.linear;
    return r;
  }
  void solve(MPI_Comm comm, const BoundScene& b, ProblemSpace& space, const ProblemInput& input, Vec u,
             ProblemResult& result) const override {
    const Stopwatch clock;
    PetscMatrix A = space.bilinear->create_matrix();
    PetscVector rhs = space.linear->create_vector(), x = space.bilinear->create_vector();
    space.bilinear->matrix(u, A);
    space.linear->vector(u, rhs);
    result.seconds_assembly = clock.seconds();
    MatInfo info{};
    LMEFORM_PETSC_CHECK(MatGetInfo(A, MAT_GLOBAL_SUM, &info));
    result.matrix_nonzeros = static_cast<long long>(info.nz_used);
    if (space.bounded()) {
      if (!b.zero_mean.empty()) throw SceneError(fmt::format("{}: [bounds] and model.zero_mean together are not supported", b.source));
      // A bounded linear problem is a linear complementarity problem: F = A u − b, Jacobian A.
      const auto residual = [&](Vec y, Vec F) {
        LMEFORM_PETSC_CHECK(MatMult(A, y, F));
        LMEFORM_PETSC_CHECK(VecAXPY(F, -1.0, rhs));
      };
      const auto jacobian = [&](Vec, Mat M) { LMEFORM_PETSC_CHECK(MatCopy(A, M, SAME_NONZERO_PATTERN)); };
      // The whole structure: the fixed dofs' columns carry the prescribed values into A u − b.
      const JacobianSpec spec{"bilinear", [&space] { return space.bilinear->create_matrix(); }};
      take_nonlinear_solve(solve_nonlinear(comm, space, u, b.scene->solver, residual, jacobian, spec), result);
      result.energy = std::numeric_limits<double>::quiet_NaN();
      return;
    }
    LMEFORM_PETSC_CHECK(VecCopy(u, x));
    apply_dirichlet(A, rhs, x, space.fixed);
    LinearSystemLayout layout;
    layout.dofs_per_node = b.layout.dofs_per_node;
    layout.fields = b.layout.fields;
    std::vector<PetscVector> keep;
    for (const auto& name : b.zero_mean) add_zero_mean_condition(comm, b, space, b.unknown(name), input.log, layout, keep);
    const LinearSolveReport solve = solve_linear_system(comm, A, rhs, x, layout);
    result.residual_norm = solve.relative_residual;
    result.converged = solve.converged;
    result.message = solve.message;
    result.iterations = solve.iterations;
    result.zero_mean_method = solve.zero_mean_method;
    result.energy = std::numeric_limits<double>::quiet_NaN();
    LMEFORM_PETSC_CHECK(VecCopy(x, u));
  }
  void residual(const BoundScene&, ProblemSpace& space, Vec u, const ProblemResult&, Vec out) const override {
    PetscMatrix A = space.bilinear->create_matrix();
    PetscVector b = space.linear->create_vector();
    space.bilinear->matrix(u, A);
    space.linear->vector(u, b);
    LMEFORM_PETSC_CHECK(MatMult(A, u, out));
    LMEFORM_PETSC_CHECK(VecAXPY(out, -1.0, b));
  }
  void describe(const BoundScene&, const ProblemResult& r, RunReport& report) const override { describe_equation_solve(r, report); }
};

}  // namespace

const StationaryDriver& linear_driver() {
  static const LinearDriver driver;
  return driver;
}

}  // namespace lmeform::problems
