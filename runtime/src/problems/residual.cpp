// R(u; v) = 0 for all v by Newton's method (PETSc SNES, MUMPS LU by default, the options database
// passed through): the stationary driver of scenes that name model.residual.
#include <limits>

#include <fmt/format.h>

#include "problem_registry.hpp"
#include "stationary.hpp"
#include "nonlinear_solve.hpp"

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
    const JacobianSpec spec{"residual", [&space] {
                              return space.residual->create_matrix(Assembler::MatrixInsertion::Direct,
                                                                   coupled_components(*space.disc, space.residual->block_size(), space.fixed));
                            }};
    take_nonlinear_solve(solve_nonlinear(comm, space, u, b.scene->solver, [&](Vec x, Vec F) { space.residual->vector(x, F); },
                                         [&](Vec x, Mat A) { space.residual->matrix(x, A); }, spec),
                         result);
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
