#include "lmeform/quadrature_adequacy.hpp"

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <string>

#include "lmeform/neighbourhoods.hpp"
#include "lmeform/contractions.hpp"

namespace lmeform {

namespace {

std::vector<int> rule_sizes(int dim) {
  switch (dim) {
    case 2: return triangle_rule_sizes();
    case 3: return tetrahedron_rule_sizes();
    default: throw std::invalid_argument("quadrature check: dimension " + std::to_string(dim) + " has no simplex rules");
  }
}

QuadratureRule rule_of(int dim, int points) { return dim == 2 ? triangle_rule(points) : tetrahedron_rule(points); }

// Maps reference points of a rule onto one cell (affine map from its vertices).
void map_rule(const QuadratureRule& rule, const NodeSet& nodes, std::span<const int> vertices, double measure,
              std::vector<double>& points, std::vector<double>& weights) {
  const int d = nodes.dim;
  const double scale = measure / reference_measure(d);
  points.assign(rule.size() * static_cast<std::size_t>(d), 0.0);
  weights.resize(rule.size());
  for (std::size_t q = 0; q < rule.size(); ++q) {
    const auto xi = rule.point(q);
    double lambda0 = 1.0;
    for (int i = 0; i < d; ++i) lambda0 -= xi[static_cast<std::size_t>(i)];
    for (int i = 0; i < d; ++i) {
      double x = lambda0 * nodes.point(static_cast<std::size_t>(vertices[0]))[static_cast<std::size_t>(i)];
      for (int k = 0; k < d; ++k) {
        x += xi[static_cast<std::size_t>(k)] * nodes.point(static_cast<std::size_t>(vertices[static_cast<std::size_t>(k) + 1]))[static_cast<std::size_t>(i)];
      }
      points[q * static_cast<std::size_t>(d) + static_cast<std::size_t>(i)] = x;
    }
    weights[q] = rule.weights[q] * scale;
  }
}

}  // namespace

int next_richer_rule(int dim, int points) {
  const auto sizes = rule_sizes(dim);
  const auto it = std::upper_bound(sizes.begin(), sizes.end(), points);
  if (it == sizes.end()) {
    throw std::invalid_argument("quadrature check: no rule richer than " + std::to_string(points) + " points in " +
                                std::to_string(dim) + "D");
  }
  return *it;
}

QuadratureAdequacy check_quadrature(const Discretization& disc, const kernel::FormKernels& form,
                                    std::span<const double> u_original, std::span<const double> constants,
                                    int points, int richer_points, int stride) {
  const int d = disc.dim();
  if (form.dim != d) throw std::invalid_argument("quadrature check: form dimension differs from the discretization's");
  if (static_cast<int>(constants.size()) != form.n_constants) {
    throw std::invalid_argument("quadrature check: form '" + std::string(form.name) + "' expects " +
                                std::to_string(form.n_constants) + " constants, got " + std::to_string(constants.size()));
  }
  if (form.n_qdata > 0 || form.n_coefficients > 0) {
    throw std::invalid_argument("quadrature check: forms with coefficients or quadrature data are not supported");
  }
  if (richer_points == 0) richer_points = next_richer_rule(d, points);
  if (stride < 1) stride = 1;
  const QuadratureRule rule = rule_of(d, points);
  const QuadratureRule richer = rule_of(d, richer_points);
  const int bs = form.dofs_per_node;
  const int order = form.basis_order;
  const int jet = kernel::jet_size(d, order);
  const LmeBasis& basis = disc.basis();
  const BackgroundCells& cells = disc.cells();

  double energy[2] = {0, 0};
  double gradient_difference_sq = 0, gradient_reference_sq = 0;
  int sampled = 0;
  std::vector<double> pts[2], wts[2], tab, workspace, u_local, g[2];
  LmeWorkspace ws;
  for (std::size_t c = 0; c < cells.size(); c += static_cast<std::size_t>(stride)) {
    ++sampled;
    const auto vertices = cells.cell(c);
    map_rule(rule, disc.nodes(), vertices, cells.measures[c], pts[0], wts[0]);
    map_rule(richer, disc.nodes(), vertices, cells.measures[c], pts[1], wts[1]);
    // One list for both rules: the union of every point's primal list.
    std::vector<double> all_points(pts[0]);
    all_points.insert(all_points.end(), pts[1].begin(), pts[1].end());
    const CsrLists lists = basis.neighbour_lists(all_points);
    const CsrLists cell_list = union_of_groups(lists, static_cast<int>(lists.size()), disc.n_nodes());
    const auto nodes = cell_list[0];
    const int n = static_cast<int>(nodes.size());
    u_local.resize(static_cast<std::size_t>(n * bs));
    for (int a = 0; a < n; ++a) {
      const auto original = static_cast<std::size_t>(disc.original_index()[static_cast<std::size_t>(nodes[static_cast<std::size_t>(a)])]);
      for (int k = 0; k < bs; ++k) u_local[static_cast<std::size_t>(a * bs + k)] = u_original[original * static_cast<std::size_t>(bs) + static_cast<std::size_t>(k)];
    }
    for (int r = 0; r < 2; ++r) {
      const int nq = static_cast<int>(wts[r].size());
      tab.resize(static_cast<std::size_t>(nq * jet * n));
      basis.tabulate_cell(pts[r], nodes, order, tab, ws);
      workspace.resize(form.workspace_doubles(n, nq));
      kernel::CellInputs in;
      in.contractions = &dense_contractions();
      in.n_nodes = n;
      in.n_points = nq;
      in.basis_order = order;
      in.weights = wts[r].data();
      in.points = pts[r].data();
      in.basis = tab.data();
      in.unknowns = u_local.data();
      in.constants = constants.data();
      in.workspace = workspace.data();
      energy[r] += form.value != nullptr ? form.value(in) : 0.0;
      g[r].assign(static_cast<std::size_t>(n * bs), 0.0);
      if (form.vector != nullptr) form.vector(in, g[r].data());
    }
    for (std::size_t i = 0; i < g[0].size(); ++i) {
      gradient_difference_sq += (g[0][i] - g[1][i]) * (g[0][i] - g[1][i]);
      gradient_reference_sq += g[1][i] * g[1][i];
    }
  }
  QuadratureAdequacy result;
  result.points = points;
  result.richer_points = richer_points;
  result.cells_sampled = sampled;
  result.energy_relative_difference = std::abs(energy[0] - energy[1]) / std::max(std::abs(energy[1]), 1e-300);
  result.gradient_relative_difference = std::sqrt(gradient_difference_sq / std::max(gradient_reference_sq, 1e-300));
  return result;
}

}  // namespace lmeform
