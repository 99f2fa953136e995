#include "quantities.hpp"

#include <fmt/format.h>

#include "point_values.hpp"
#include "problem_registry.hpp"
#include "saddle_point.hpp"
#include "stationary.hpp"

namespace lmeform::problems {

namespace {

std::string column(const BoundQuantity& q, int component, int components) {
  return components == 1 ? q.scene.name : fmt::format("{}[{}]", q.scene.name, component);
}

/// The residual summed over the part's nodes, per component of the field.
void add_reaction(const BoundQuantity& q, const BoundScene& b, ProblemSpace& space, Vec residual, QuantityValues& out) {
  const Discretization& disc = *space.disc;
  const std::vector<int> nodes = boundary_nodes(b.geometry, space.nodes, q.scene.part, space.part_nodes);
  const int bs = b.layout.dofs_per_node;
  std::vector<double> sums(std::size_t(q.field.components), 0.0);
  {
    const VecReadView r(residual);
    const auto renumbered = disc.renumbered_index();
    for (const int n : nodes) {
      const int node = renumbered[std::size_t(n)];
      if (!disc.owns(node)) continue;
      for (int c = 0; c < q.field.components; ++c) sums[std::size_t(c)] += r[(node - disc.owned_begin()) * bs + q.field.offset + c];
    }
  }
  MPI_Allreduce(MPI_IN_PLACE, sums.data(), static_cast<int>(sums.size()), MPI_DOUBLE, MPI_SUM, disc.comm());
  for (int c = 0; c < q.field.components; ++c)
    if (q.scene.component < 0 || q.scene.component == c) out.emplace_back(column(q, c, q.scene.component < 0 ? q.field.components : 1), sums[std::size_t(c)]);
}

/// A point output at the probe, evaluated with the basis of the solve.
void add_point_probe(const BoundQuantity& q, const BoundScene& b, ProblemSpace& space, const std::vector<double>& state, QuantityValues& out) {
  const Discretization& disc = *space.disc;
  const std::span<const double> x(q.scene.point.data(), std::size_t(b.dim));
  const PointEvaluator evaluator(*q.point, b.layout, space.constants, &b.geometry);
  std::vector<double> values(static_cast<std::size_t>(evaluator.n_values()));
  try {
    evaluator.evaluate(disc.basis(), x, renumbered_state(disc, state, b.layout.dofs_per_node), values);
  } catch (const LmeEvaluationError& e) {
    throw SceneError(fmt::format("{}: the probe cannot be evaluated: {}", q.scene.where, e.what()));
  }
  for (int c = 0; c < evaluator.n_values(); ++c)
    if (q.scene.component < 0 || q.scene.component == c)
      out.emplace_back(column(q, c, q.scene.component < 0 ? evaluator.n_values() : 1), values[std::size_t(c)]);
}

/// The field's value at the probe: Σ_a p_a(x) u_a over the point's LME neighbours.
void add_probe(const BoundQuantity& q, const BoundScene& b, ProblemSpace& space, const std::vector<double>& state, QuantityValues& out) {
  const Discretization& disc = *space.disc;
  const std::span<const double> x(q.scene.point.data(), std::size_t(b.dim));
  const auto list = disc.basis().neighbours(x);
  std::vector<double> p;
  try {
    p = disc.basis().evaluate(x, list, 0);
  } catch (const LmeEvaluationError& e) {
    throw SceneError(fmt::format("{}: the probe cannot be evaluated: {}", q.scene.where, e.what()));
  }
  const auto bs = std::size_t(b.layout.dofs_per_node);
  for (int c = 0; c < q.field.components; ++c) {
    if (q.scene.component >= 0 && q.scene.component != c) continue;
    double v = 0;
    for (std::size_t m = 0; m < list.size(); ++m)
      v += p[m] * state[std::size_t(disc.original_index()[std::size_t(list[m])]) * bs + std::size_t(q.field.offset + c)];
    out.emplace_back(column(q, c, q.scene.component < 0 ? q.field.components : 1), v);
  }
}

}  // namespace

QuantityValues evaluate_quantities(const BoundScene& b, ProblemSpace& space, Vec u, const ProblemResult& result) {
  QuantityValues out;
  if (b.quantities.empty() && b.equipotentials.empty()) return out;
  const bool reactions =
      !b.equipotentials.empty() ||
      std::any_of(b.quantities.begin(), b.quantities.end(), [](const BoundQuantity& q) { return q.scene.kind == SceneQuantity::Kind::reaction; });
  PetscVector residual;
  if (reactions) {
    residual = space.primary->create_vector();
    b.solver->residual(b, space, u, result, residual);
  }
  const std::vector<double> state = to_original(*space.disc, u, b.layout.dofs_per_node);
  for (const BoundQuantity& q : b.quantities) {
    switch (q.scene.kind) {
      case SceneQuantity::Kind::reaction: add_reaction(q, b, space, residual, out); break;
      case SceneQuantity::Kind::probe:
        if (q.point != nullptr) add_point_probe(q, b, space, state, out);
        else add_probe(q, b, space, state, out);
        break;
      case SceneQuantity::Kind::integral: out.emplace_back(q.scene.name, space.assemblers.at(q.integral->label)->value(u)); break;
      case SceneQuantity::Kind::constant: out.emplace_back(q.scene.name, space.constants.at(q.scene.constant)); break;
      case SceneQuantity::Kind::energy: out.emplace_back(q.scene.name, space.assemblers.at(q.integral->label)->value(u)); break;
    }
  }
  add_equipotential_quantities(b, space, u, residual, out);
  return out;
}

void describe_quantities(const QuantityValues& values, RunReport& report) {
  if (values.empty()) return;
  report.json["quantities"] = nlohmann::json::object();
  for (const auto& [name, value] : values) {
    report.row(name, fmt::format("{:.10g}", value));
    report.json["quantities"][name] = json_number(value);
  }
}

}  // namespace lmeform::problems
