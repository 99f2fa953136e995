#include "minimization.hpp"

#include <fmt/format.h>

#include "lmeform/constrained_minimizer.hpp"
#include "nonlinear_solve.hpp"

namespace lmeform::problems {

namespace {

/// Minimization under bounds: ∇E = 0 as a variational inequality with the Hessian as Jacobian.
void solve_bounded_minimization(MPI_Comm comm, const BoundScene& b, ProblemSpace& space, Vec u, ProblemResult& result) {
  const auto gradient = [&](Vec x, Vec F) {
    LMEFORM_PETSC_CHECK(VecZeroEntries(F));
    for (Assembler* term : space.energy_terms) term->add_vector(x, F, 1.0);
  };
  const auto hessian = [&](Vec x, Mat A) {
    std::vector<Assembler::MatrixTerm> terms;
    for (Assembler* term : space.energy_terms) terms.push_back({term, 1.0});
    space.primary->matrix_sum(x, terms, A);
  };
  // The Hessian and its principal submatrices (the VI's inactive set) are symmetric: LDLᵀ, which
  // made the SENT of sent_fast.toml 5-10 % faster on 2 ranks with the same forces to 1e-15.
  // Unknowns held fixed wholesale (the other groups of a staggered solve) keep only their diagonal.
  const JacobianSpec spec{"hessian",
                          [&space] {
                            return space.primary->create_matrix(Assembler::MatrixInsertion::Direct,
                                                                coupled_components(*space.disc, space.primary->block_size(), space.fixed));
                          },
                          MatrixSymmetry::Symmetric};
  take_nonlinear_solve(solve_nonlinear(comm, space, u, b.scene->solver, gradient, hessian, spec), result);
  result.energy = space.energy(u);
  result.minimization.energy = result.energy;
  result.minimization.converged = result.converged;
  result.minimization.newton_iterations = result.iterations;
}

class MinimizationDriver final : public StationaryDriver {
 public:
  [[nodiscard]] std::string_view name() const override { return "minimization"; }
  [[nodiscard]] bool claims(const Scene& scene) const override {
    return !scene.model.residual && !scene.model.bilinear && !scene.model.linear;
  }
  [[nodiscard]] OutputRoles roles(const Scene& scene) const override {
    OutputRoles r;
    r.energies = scene.model.energy;
    r.all_energies = scene.model.energy.empty();
    r.constraints = true;
    return r;
  }
  void solve(MPI_Comm comm, const BoundScene& b, ProblemSpace& space, const ProblemInput& input, Vec u, ProblemResult& result) const override {
    if (space.bounded()) {
      solve_bounded_minimization(comm, b, space, u, result);
      return;
    }
    ConstrainedMinimizer minimizer(space.energy_terms, space.constraints, minimizer_options(b.scene->solver, input.log));
    minimizer.set_fixed_dofs(space.fixed);
    std::vector<double> nu;  // the minimizer works with multipliers of the scaled constraints
    if (!input.initial_multipliers.empty()) {
      if (input.initial_multipliers.size() != space.constraints.size())
        throw std::invalid_argument(fmt::format("solve_problem: {} starting multipliers for {} constraints", input.initial_multipliers.size(),
                                                space.constraints.size()));
      for (std::size_t i = 0; i < space.constraints.size(); ++i) nu.push_back(input.initial_multipliers[i] * space.constraints[i].scale);
    }
    result.minimization = minimizer.minimize(u, nu);
    result.converged = result.minimization.converged;
    result.message = result.minimization.message;
    result.energy = result.minimization.energy;
    result.iterations = result.minimization.augmented_iterations + result.minimization.newton_iterations;
  }
  void residual(const BoundScene&, ProblemSpace& space, Vec u, const ProblemResult& r, Vec out) const override {
    LMEFORM_PETSC_CHECK(VecZeroEntries(out));
    for (Assembler* term : space.energy_terms) term->add_vector(u, out, 1.0);
    const auto& sigma = r.minimization.multipliers;
    for (std::size_t i = 0; i < space.constraints.size() && i < sigma.size(); ++i) space.constraints[i].functional->add_vector(u, out, -sigma[i]);
  }
  void describe(const BoundScene& b, const ProblemResult& r, RunReport& report) const override {
    describe_minimization(b.scene->reference.energy, r, report);
  }
};

/// Whether the minimizer's result is a minimum, from the inertia of its last Newton Hessian.
void describe_second_order(const ConstrainedResult& m, RunReport& report, std::string_view perturbation) {
  report.json["negative_curvature_directions"] = m.negative_curvature_directions;
  if (m.negative_curvature_directions < 0) return;
  if (m.negative_curvature_directions == 0) {
    report.row("second-order check", "a minimum (the Hessian is positive definite along the constraints)");
    return;
  }
  const std::string what = fmt::format("{} direction{} of negative curvature along the constraints", m.negative_curvature_directions,
                                       m.negative_curvature_directions == 1 ? "" : "s");
  report.row("second-order check", "NOT a minimum: " + what);
  report.warnings.push_back("the result is a stationary point with " + what +
                            " (a saddle, not a minimum). A start with the symmetry of the domain and the nodes keeps "
                            "that symmetry and can converge to its symmetric saddle: start from a state perturbed off it" +
                            (perturbation.empty() ? std::string() : " (" + std::string(perturbation) + ")"));
}

}  // namespace

void describe_minimization(const std::optional<double>& reference, const ProblemResult& r, RunReport& report,
                           const MultiplierMeanings& meanings, std::string_view perturbation) {
  const double relative = reference ? (r.energy - *reference) / *reference : std::nan("");
  report.row("energy", fmt::format("{:.6f}", r.energy));
  if (reference) report.row("reference energy", fmt::format("{:.6f} (relative error {:+.3f} %)", *reference, 100 * relative));
  report.json["energy"] = json_number(r.energy);
  report.json["relative_error_reference"] = json_number(relative);
  report.json["iterations"] = r.iterations;
  report.json["residual_norm"] = json_number(r.residual_norm);
  report.json["newton_iterations"] = r.minimization.newton_iterations;
  report.json["augmented_iterations"] = r.minimization.augmented_iterations;
  report.json["multipliers"] = nlohmann::json::object();
  report.json["constraint_residuals"] = nlohmann::json::object();
  const ConstrainedResult& m = r.minimization;
  for (std::size_t i = 0; i < r.constraint_names.size() && i < m.multipliers.size(); ++i) {
    const std::string& c = r.constraint_names[i];
    const auto named = meanings.find(c);
    const std::string meaning = named == meanings.end() ? "" : " (" + named->second + ")";
    report.row(c + " constraint", fmt::format("{:.6g} (relative residual {:.1e}), multiplier{} {:.6g}", m.constraint_values[i],
                                              m.relative_residuals[i], meaning, m.multipliers[i]));
    report.json["multipliers"][c] = json_number(m.multipliers[i]);
    report.json["constraint_residuals"][c] = json_number(m.relative_residuals[i]);
  }
  report.row("Newton iterations", fmt::format("{} augmented Lagrangian + {} KKT", m.augmented_iterations, m.newton_iterations));
  describe_second_order(m, report, perturbation);
  if (report.fields) report.fields->attributes.emplace("energy", r.energy);
}

const StationaryDriver& minimization_driver() {
  static const MinimizationDriver driver;
  return driver;
}

}  // namespace lmeform::problems
