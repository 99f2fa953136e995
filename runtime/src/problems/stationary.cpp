#include "stationary.hpp"

#include "field_transfer.hpp"
#include "point_values.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <numeric>

#include <fmt/format.h>

#include "expressions.hpp"
#include "lmeform/node_sets.hpp"
#include "lmeform/cvt.hpp"
#include "lmeform/stopwatch.hpp"
#include "problem_registry.hpp"
#include "quantities.hpp"
#include "nonlinear_solve.hpp"

namespace lmeform::problems {

namespace {

/// L2, H1 and (where the forms tabulate Hessians) H2 errors of each unknown with an exact solution.
std::vector<FieldError> field_errors(MPI_Comm comm, const BoundScene& b, const ProblemSpace& space, const std::vector<double>& state,
                                     std::ostream* log) {
  std::vector<FieldError> out;
  const Discretization& disc = *space.disc;
  for (const BoundExactSolution& exact : b.exact) {
    const UnknownField& field = exact.field;
    const FormModule& errors = compile_error_form(b.dim, field.name, field.components, exact.expression, b.constants, exact.where, comm, log);
    // The error form has this unknown alone: its state is the unknown's components.
    PetscVector v = Assembler(disc, errors.at("l2", b.dim)).create_vector();
    set_from_original(disc, b.layout.values(state, field), field.components, v);
    auto norm = [&](const char* output) {
      const kernel::FormKernels& k = errors.at(output, b.dim);
      Assembler form(disc, k);
      for (int i = 0; i < k.n_constants; ++i) {
        const double c = space.constants.at(k.constants[i]);
        form.set_constant(k.constants[i], std::isnan(c) ? 0.0 : c);
      }
      return std::sqrt(std::max(0.0, form.value(v)));
    };
    FieldError e{field.name, norm("l2"), norm("h1")};
    // Hessians are tabulated only for forms that need them: a second-order problem does not pay for its H2 error.
    if (b.basis_order >= 2) e.h2 = norm("h2");
    out.push_back(e);
  }
  return out;
}

/// |∇u| of the first scalar unknown at the nodes (0 where it is prescribed): adaptivity indicators.
std::vector<double> gradient_norm_at_nodes(const BoundScene& b, const ProblemSpace& space, const std::vector<double>& state) {
  if (b.layout.fields.empty() || b.layout.fields.front().components != 1) return {};
  const Discretization& disc = *space.disc;
  const std::size_t n = disc.nodes().size();
  const auto bs = std::size_t(b.layout.dofs_per_node);
  const auto original = disc.original_index();
  std::vector<char> prescribed(n, 0);
  for (const auto& [node, dof] : space.fixed_pairs)
    if (dof == 0) prescribed[std::size_t(node)] = 1;
  std::vector<double> field(n);  // the discretization's order
  std::vector<char> skip(n);
  for (std::size_t r = 0; r < n; ++r) {
    const auto o = static_cast<std::size_t>(original[r]);
    field[r] = state[o * bs];
    skip[r] = prescribed[o];
  }
  const std::vector<double> norm = nodal_gradient_norm(disc.basis(), field, skip);
  std::vector<double> out(n, 0.0);
  for (std::size_t r = 0; r < n; ++r) out[static_cast<std::size_t>(original[r])] = norm[r];
  return out;
}

/// The point outputs at the nodes, in the nodes' original order.
std::vector<ReportField> point_output_fields(const BoundScene& b, const ProblemSpace& space, const std::vector<double>& state) {
  std::vector<ReportField> out;
  if (!b.write_point_fields || b.point_outputs.empty()) return out;
  const Discretization& disc = *space.disc;
  const std::size_t n = disc.nodes().size();
  const auto original = disc.original_index();
  const std::vector<double> renumbered = renumbered_state(disc, state, b.layout.dofs_per_node);
  for (const auto& [name, kernel] : b.point_outputs) {
    const PointEvaluator evaluator(*kernel, b.layout, space.constants, &b.geometry);
    const auto m = static_cast<std::size_t>(evaluator.n_values());
    ReportField field{name, evaluator.n_values(), std::vector<double>(n * m)};
    for (std::size_t r = 0; r < n; ++r)
      evaluator.evaluate(disc.basis(), disc.nodes().point(r), renumbered,
                         std::span<double>(field.values.data() + std::size_t(original[r]) * m, m));
    out.push_back(std::move(field));
  }
  return out;
}

/// The value of every energy term and constraint at u.
void record_values(const BoundScene& b, const ProblemSpace& space, Vec u, ProblemResult& result) {
  for (std::size_t i = 0; i < space.energy_terms.size(); ++i) result.values[b.energy[i].label] = space.energy_terms[i]->value(u);
  for (const auto& c : space.constraints) result.values[c.name] = c.functional->value(u);
}

}  // namespace

ProblemResult solve_problem(MPI_Comm comm, const BoundScene& b, const ProblemInput& input) {
  const Stopwatch clock;
  const ScopedPetscOptions petsc_options(b.scene->solver.petsc_options);
  ProblemResult result;
  result.nodes = input.nodes;
  const int bs = b.layout.dofs_per_node;
  ProblemSpace space = build_problem_space(comm, b, input);
  const Discretization& disc = *space.disc;
  result.discretization = space.disc;
  const auto h = disc.basis().spacing();
  result.h_min = *std::min_element(h.begin(), h.end());
  result.h_mean = std::accumulate(h.begin(), h.end(), 0.0) / static_cast<double>(h.size());
  for (const auto& c : b.constraints) result.constraint_names.push_back(c.name);
  PetscVector u = space.primary->create_vector();
  set_from_original(disc, space.state, bs, u);
  result.seconds_setup = clock.seconds();
  if (input.evaluate_only) {
    record_values(b, space, u, result);
    result.state = to_original(disc, u, bs);
    result.energy = std::numeric_limits<double>::quiet_NaN();
    result.message = "evaluated, not solved";
    return result;
  }
  const Stopwatch solve_clock;
  b.solver->solve(comm, b, space, input, u, result);
  result.seconds_solve = solve_clock.seconds();
  if (space.energy_terms.size() > 1) record_values(b, space, u, result);
  result.state = to_original(disc, u, bs);
  result.errors = field_errors(comm, b, space, result.state, input.log);
  result.quantities = evaluate_quantities(b, space, u, result);
  result.gradient_norm = gradient_norm_at_nodes(b, space, result.state);
  result.point_fields = point_output_fields(b, space, result.state);
  result.cells = delaunay(result.nodes);
  return result;
}

ReportFields state_fields(const StateLayout& layout, bool axisymmetric, const ProblemResult& r) {
  ReportFields out;
  out.nodes = r.nodes;
  out.cells = r.cells;
  for (const auto& u : layout.fields) out.fields.push_back({u.name, u.components, layout.values(r.state, u)});
  if (!r.gradient_norm.empty()) out.fields.push_back({"grad_" + layout.fields.front().name + "_norm", 1, r.gradient_norm});
  out.fields.insert(out.fields.end(), r.point_fields.begin(), r.point_fields.end());
  if (!layout.fields.empty() && layout.fields.front().components == 1) out.figure_field = layout.fields.front().name;
  out.mirror = axisymmetric;
  return out;
}

void take_nonlinear_solve(const NonlinearSolve& solve, ProblemResult& result) {
  result.converged = solve.converged;
  result.message = solve.message;
  result.iterations = solve.iterations;
  result.residual_norm = solve.residual_norm;
  result.active_lower = solve.active_lower;
  result.active_upper = solve.active_upper;
}

void describe_equation_solve(const ProblemResult& r, RunReport& report) {
  report.row("solver", r.message);
  report.json["energy"] = nullptr;
  report.json["iterations"] = r.iterations;
  report.json["residual_norm"] = json_number(r.residual_norm);
}

void describe_basis(const SceneNodes& nodes, RunReport& report) {
  report.row("basis", fmt::format("{}-order max-ent, gamma {:g}, support to weight {:g}, {} points per cell{}", to_string(nodes.basis),
                                  nodes.gamma, nodes.support_tolerance, nodes.quadrature_points,
                                  nodes.consistent_integration ? ", consistent integration" : ""));
  report.json["basis"] = to_string(nodes.basis);
  report.json["support_tolerance"] = nodes.support_tolerance;
  report.json["gamma"] = nodes.gamma;
  report.json["quadrature_points"] = nodes.quadrature_points;
}

void describe_errors(const ProblemResult& r, RunReport& report) {
  if (r.active_lower >= 0) report.json["active_set"] = {{"lower", r.active_lower}, {"upper", r.active_upper}};
  report.json["errors"] = nlohmann::json::array();
  for (const auto& e : r.errors) {
    const bool h2 = !std::isnan(e.h2);
    report.row("error of " + e.unknown, fmt::format("L2 {:.6e}, H1 semi-norm {:.6e}{}", e.l2, e.h1,
                                                    h2 ? fmt::format(", H2 semi-norm {:.6e}", e.h2) : std::string()));
    nlohmann::json row{{"unknown", e.unknown}, {"l2", json_number(e.l2)}, {"h1", json_number(e.h1)}};
    if (h2) row["h2"] = json_number(e.h2);
    report.json["errors"].push_back(row);
  }
}

void StationaryDriver::check(const DriverContext& ctx) const { (void)bind_scene(*ctx.scene, ctx.comm, ctx.log, *this); }

RunReport StationaryDriver::run(const DriverContext& ctx) const {
  const Scene& scene = *ctx.scene;
  const BoundScene bound = bind_scene(scene, ctx.comm, ctx.log, *this);
  ProblemInput input;
  input.nodes = initial_nodes(scene, ctx.comm, ctx.log);
  input.log = ctx.log;
  input.lme = bound.lme(AxisParity::even);
  const double h_min = spacing_summary(input.nodes).h_min;
  if (ctx.log != nullptr) *ctx.log << "== solve: " << input.nodes.size() << " nodes, h_min " << h_min << "\n";
  const ProblemResult r = solve_problem(ctx.comm, bound, input);
  RunReport report;
  report.problem = std::string(name());
  report.success = r.converged;
  report.status = r.converged ? "converged" : "FAILED: " + r.message;
  report.fields = state_fields(bound.layout, bound.axisymmetric, r);
  describe(bound, r, report);
  describe_errors(r, report);
  describe_quantities(r.quantities, report);
  report.row("nodes", fmt::format("{} (h_min {:.4g}, h_mean {:.4g})", r.nodes.size(), r.h_min, r.h_mean));
  describe_basis(ctx.scene->nodes, report);
  if (r.matrix_nonzeros > 0) {
    const auto rows = static_cast<double>(r.state.size());
    report.row("matrix", fmt::format("{} non-zeros, {:.0f} per row", r.matrix_nonzeros, static_cast<double>(r.matrix_nonzeros) / std::max(rows, 1.0)));
    report.json["matrix_nonzeros"] = r.matrix_nonzeros;
  }
  report.row("times", fmt::format("setup {:.2f} s, solve {:.2f} s", r.seconds_setup, r.seconds_solve));
  report.json["nodes"] = r.nodes.size();
  report.json["h_min"] = json_number(r.h_min);
  report.json["setup_s"] = json_number(r.seconds_setup);
  report.json["solve_s"] = json_number(r.seconds_solve);
  return report;
}

}  // namespace lmeform::problems
