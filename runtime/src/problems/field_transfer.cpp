#include "field_transfer.hpp"

#include <cmath>
#include <limits>
#include <optional>
#include <stdexcept>

#include <Eigen/Sparse>
#include <fmt/format.h>
#include <fmt/ranges.h>

#include "lmeform/delaunay.hpp"

namespace lmeform::problems {

namespace {

/// The vertices of a Delaunay cell of the nodes holding x (none outside their hull): for points
/// the plain neighbour lists cannot evaluate. Triangulated on first use.
class EnclosingCell {
 public:
  explicit EnclosingCell(const NodeSet& nodes) : nodes_(nodes) {}
  std::vector<int> operator()(std::span<const double> x) {
    if (!locator_) {
      cells_.emplace(delaunay(nodes_));
      locator_.emplace(*cells_, nodes_);
    }
    const long c = locator_->locate(x, 1e-10);
    if (c < 0) return {};
    const auto v = cells_->cell(std::size_t(c));
    return {v.begin(), v.end()};
  }

 private:
  const NodeSet& nodes_;
  std::optional<BackgroundCells> cells_;
  std::optional<CellLocator> locator_;
};

}  // namespace

std::vector<double> nodal_gradient_norm(const LmeBasis& basis, std::span<const double> field, std::span<const char> skip,
                                        std::size_t* undefined) {
  const NodeSet& nodes = basis.nodes();
  const int dim = nodes.dim;
  std::vector<double> norm(nodes.size(), 0.0);
  std::vector<std::size_t> undefined_at;
  // All lists in one search: on a graded set a search per point uses the largest support radius.
  const CsrLists lists = basis.neighbour_lists(nodes.coords);
  for (std::size_t a = 0; a < nodes.size(); ++a) {
    if (!skip.empty() && skip[a] != 0) continue;
    const auto x = nodes.point(a);
    const std::span<const int> list = lists[a];
    std::vector<double> jet;
    try {
      jet = basis.evaluate(x, list, 1);
    } catch (const LmeEvaluationError&) {
      undefined_at.push_back(a);
      continue;
    }
    double g2 = 0;
    for (int i = 0; i < dim; ++i) {
      double g = 0;
      for (std::size_t m = 0; m < list.size(); ++m) g += jet[std::size_t(1 + i) * list.size() + m] * field[std::size_t(list[m])];
      g2 += g * g;
    }
    norm[a] = std::sqrt(g2);
  }
  std::vector<double> filled = norm;
  for (const std::size_t a : undefined_at)
    for (const int neighbour : lists[a]) filled[a] = std::max(filled[a], norm[std::size_t(neighbour)]);
  if (undefined != nullptr) *undefined = undefined_at.size();
  return filled;
}

std::vector<double> interpolate_nodal_field(const NodeSet& old_nodes, std::span<const double> phi, double gamma, const LmeOptions& lme,
                                            const NodeSet& new_nodes, std::size_t* nearest_fallbacks,
                                            std::vector<std::array<double, 2>>* local_range) {
  if (local_range != nullptr) local_range->assign(new_nodes.size(), {INFINITY, -INFINITY});
  const std::vector<double> gammas(old_nodes.size(), gamma);
  const LmeBasis basis(old_nodes, gammas, lme);
  std::vector<double> out(new_nodes.size());
  EnclosingCell enclosing_cell(old_nodes);
  const CsrLists lists = basis.neighbour_lists(new_nodes.coords);
  for (std::size_t a = 0; a < new_nodes.size(); ++a) {
    const auto x = new_nodes.point(a);
    std::vector<int> list(lists[a].begin(), lists[a].end());
    try {
      // A new node on the boundary between two old ones far apart sees only interior old nodes.
      const auto p = evaluate_with_cell_fallback(basis, x, list, 0, [&] { return enclosing_cell(x); });
      double v = 0;
      for (std::size_t m = 0; m < list.size(); ++m) v += p[m] * phi[static_cast<std::size_t>(list[m])];
      out[a] = v;
      if (local_range != nullptr)
        for (const int b : list) {
          (*local_range)[a][0] = std::min((*local_range)[a][0], phi[std::size_t(b)]);
          (*local_range)[a][1] = std::max((*local_range)[a][1], phi[std::size_t(b)]);
        }
    } catch (const LmeEvaluationError&) {
      if (nearest_fallbacks == nullptr) throw;
      double best = std::numeric_limits<double>::infinity();
      for (std::size_t b = 0; b < old_nodes.size(); ++b) {
        double d2 = 0;
        for (int i = 0; i < old_nodes.dim; ++i) d2 += std::pow(old_nodes.point(b)[std::size_t(i)] - x[std::size_t(i)], 2);
        if (d2 < best) best = d2, out[a] = phi[b];
      }
      if (local_range != nullptr) (*local_range)[a] = {out[a], out[a]};
      ++*nearest_fallbacks;
    }
  }
  return out;
}

std::vector<double> fit_nodal_values(const NodeSet& nodes, std::span<const double> values, double gamma, const LmeOptions& lme,
                                     int iterations, std::span<const double> held) {
  if (values.size() != nodes.size() || (!held.empty() && held.size() != nodes.size()))
    throw std::invalid_argument(fmt::format("fit_nodal_values: {} values and {} held coefficients for {} nodes", values.size(), held.size(),
                                            nodes.size()));
  std::vector<double> phi(values.begin(), values.end());
  auto is_held = [&](std::size_t node) { return !held.empty() && !std::isnan(held[node]); };
  for (std::size_t node = 0; node < nodes.size(); ++node)
    if (is_held(node)) phi[node] = held[node];
  if (iterations <= 0) return phi;
  const LmeBasis basis(nodes, std::vector<double>(nodes.size(), gamma), lme);
  std::vector<std::vector<int>> rows(nodes.size());
  std::vector<std::vector<double>> weights(nodes.size());
  // A boundary node whose neighbours all lie on its own edge (a boundary refined more finely than
  // the nodes beside it) has a flat neighbourhood: its Delaunay cell's vertices join, as they do for
  // the discretization's hull facets (measured: SENS at l = 0.015, a new node on the right edge).
  EnclosingCell enclosing_cell(nodes);
  for (std::size_t node = 0; node < nodes.size(); ++node) {
    const auto x = nodes.point(node);
    rows[node] = basis.neighbours(x);
    weights[node] = evaluate_with_cell_fallback(basis, x, rows[node], 0, [&] { return enclosing_cell(x); });
  }
  std::vector<double> next(phi.size());
  for (int it = 0; it < iterations; ++it) {
    for (std::size_t node = 0; node < nodes.size(); ++node) {
      double v = 0;
      for (std::size_t m = 0; m < rows[node].size(); ++m) v += weights[node][m] * phi[std::size_t(rows[node][m])];
      next[node] = is_held(node) ? phi[node] : phi[node] + values[node] - v;
    }
    phi.swap(next);
  }
  return phi;
}

PointProjection project_point_values(const NodeSet& nodes, double gamma, const LmeOptions& lme, std::span<const double> points,
                                     std::span<const double> weights, std::span<const double> values, std::span<const double> start,
                                     double tolerance, int max_iterations, PointGradients gradients) {
  const int dim = nodes.dim;
  const std::size_t n = nodes.size();
  if (points.size() != weights.size() * std::size_t(dim) || values.size() != weights.size() || start.size() != n)
    throw std::invalid_argument(fmt::format("project_point_values: {} coordinates, {} weights, {} values and {} start values "
                                            "do not match {} nodes in dimension {}",
                                            points.size(), weights.size(), values.size(), start.size(), n, dim));
  const bool h1 = gradients.length > 0 && !gradients.values.empty();
  if (h1 && gradients.values.size() != weights.size() * std::size_t(dim))
    throw std::invalid_argument(fmt::format("project_point_values: {} gradient values for {} points in dimension {}",
                                            gradients.values.size(), weights.size(), dim));
  if (gradients.length < 0) throw std::invalid_argument("project_point_values: the gradient length must not be negative");
  const double l2 = gradients.length * gradients.length;
  const std::size_t jets = h1 ? std::size_t(1 + dim) : 1;  // value, then each derivative, per neighbour
  const LmeBasis basis(nodes, std::vector<double>(n, gamma), lme);
  struct Row {
    double weight;
    std::vector<int> nodes;
    std::vector<double> p;
  };
  std::vector<Row> rows;
  EnclosingCell enclosing_cell(nodes);
  Eigen::VectorXd rhs = Eigen::VectorXd::Zero(Eigen::Index(n)), diagonal = Eigen::VectorXd::Zero(Eigen::Index(n));
  for (std::size_t q = 0; q < weights.size(); ++q) {
    if (weights[q] <= 0) continue;
    const std::span<const double> x = points.subspan(q * std::size_t(dim), std::size_t(dim));
    Row r{weights[q], basis.neighbours(x), {}};
    r.p = evaluate_with_cell_fallback(basis, x, r.nodes, h1 ? 1 : 0, [&] { return enclosing_cell(x); });
    r.p.resize(jets * r.nodes.size());
    const std::size_t m = r.nodes.size();
    for (std::size_t a = 0; a < m; ++a) {
      rhs[r.nodes[a]] += r.weight * r.p[a] * values[q];
      diagonal[r.nodes[a]] += r.weight * r.p[a] * r.p[a];
      for (std::size_t i = 1; i < jets; ++i) {
        const double d = r.p[i * m + a];
        rhs[r.nodes[a]] += r.weight * l2 * d * gradients.values[q * std::size_t(dim) + i - 1];
        diagonal[r.nodes[a]] += r.weight * l2 * d * d;
      }
    }
    rows.push_back(std::move(r));
  }
  for (std::size_t a = 0; a < n; ++a)
    if (!(diagonal[Eigen::Index(a)] > 0))
      throw std::runtime_error(fmt::format("project_point_values: node {} at ({}) has no point in its support", a, fmt::join(nodes.point(a), ", ")));
  auto apply_mass = [&](const Eigen::VectorXd& c) {
    Eigen::VectorXd m = Eigen::VectorXd::Zero(c.size());
    for (const Row& r : rows) {
      const std::size_t count = r.nodes.size();
      for (std::size_t i = 0; i < jets; ++i) {
        const double* p = r.p.data() + i * count;
        double v = 0;
        for (std::size_t a = 0; a < count; ++a) v += p[a] * c[r.nodes[a]];
        v *= i == 0 ? r.weight : r.weight * l2;
        for (std::size_t a = 0; a < count; ++a) m[r.nodes[a]] += v * p[a];
      }
    }
    return m;
  };
  PointProjection result;
  Eigen::VectorXd c = Eigen::Map<const Eigen::VectorXd>(start.data(), Eigen::Index(n));
  Eigen::VectorXd residual = rhs - apply_mass(c);
  const double norm_rhs = std::max(rhs.norm(), 1e-300);
  Eigen::VectorXd z = residual.cwiseQuotient(diagonal), direction = z;
  double rz = residual.dot(z);
  result.relative_residual = residual.norm() / norm_rhs;
  while (result.relative_residual > tolerance && result.iterations < max_iterations) {
    const Eigen::VectorXd md = apply_mass(direction);
    const double alpha = rz / direction.dot(md);
    c += alpha * direction;
    residual -= alpha * md;
    z = residual.cwiseQuotient(diagonal);
    const double rz_next = residual.dot(z);
    direction = z + (rz_next / rz) * direction;
    rz = rz_next;
    ++result.iterations;
    result.relative_residual = residual.norm() / norm_rhs;
  }
  result.values.assign(c.data(), c.data() + c.size());
  return result;
}


}  // namespace lmeform::problems
