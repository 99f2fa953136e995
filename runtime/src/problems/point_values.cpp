#include "point_values.hpp"

#include <algorithm>
#include <cmath>
#include <stdexcept>

#include "lmeform/contractions.hpp"

namespace lmeform::problems {

namespace {

const UnknownField* field_of(const StateLayout& layout, const kernel::FieldInfo& u) {
  for (const UnknownField& f : layout.fields)
    if (f.name == u.name && f.components == u.components) return &f;
  return nullptr;
}

}  // namespace

// On the hull the LME weights of nodes off the edge vanish, so the value stays the edge's, and the
// dual problem is regular again (measured: a SENS crack reaching the right edge).
std::vector<double> evaluate_with_nearest_nodes(const LmeBasis& basis, std::span<const double> x, std::vector<int>& list, int order) {
  const NodeSet& nodes = basis.nodes();
  std::vector<std::pair<double, int>> by_distance;
  by_distance.reserve(nodes.size());
  for (std::size_t a = 0; a < nodes.size(); ++a) {
    if (std::find(list.begin(), list.end(), static_cast<int>(a)) != list.end()) continue;
    double d2 = 0;
    for (std::size_t i = 0; i < x.size(); ++i) d2 += (nodes.point(a)[i] - x[i]) * (nodes.point(a)[i] - x[i]);
    by_distance.emplace_back(d2, static_cast<int>(a));
  }
  constexpr std::size_t kMostAdded = 32;
  const std::size_t candidates = std::min(by_distance.size(), kMostAdded);
  std::partial_sort(by_distance.begin(), by_distance.begin() + std::ptrdiff_t(candidates), by_distance.end());
  for (std::size_t k = 0; k < candidates; ++k) {
    list.insert(std::upper_bound(list.begin(), list.end(), by_distance[k].second), by_distance[k].second);
    try {
      return basis.evaluate(x, list, order);
    } catch (const LmeEvaluationError& e) {
      const auto r = e.reason();
      if ((r != LmeFailure::degenerate && r != LmeFailure::too_few_neighbours && r != LmeFailure::outside_hull) || k + 1 == candidates) throw;
    }
  }
  return basis.evaluate(x, list, order);  // no other node: the original error
}

bool PointEvaluator::can_evaluate(const kernel::FormKernels& output, const StateLayout& layout) {
  if (output.kind != kernel::FunctionalKind::Point || output.point == nullptr) return false;
  if (output.n_coefficients > 0 || output.qdata_per_point > 0) return false;
  for (int i = 0; i < output.n_unknowns; ++i)
    if (field_of(layout, output.unknowns[i]) == nullptr) return false;
  return true;
}

PointEvaluator::PointEvaluator(const kernel::FormKernels& output, const StateLayout& layout,
                               const std::map<std::string, double, std::less<>>& constants, const Domain* domain)
    : kernel_(&output), domain_(domain), dofs_per_node_(layout.dofs_per_node) {
  if (!can_evaluate(output, layout))
    throw std::invalid_argument(std::string("PointEvaluator: ") + output.module + "." + output.name +
                                " is not a point output of the problem's unknowns alone");
  for (int i = 0; i < output.n_unknowns; ++i) {
    const UnknownField* f = field_of(layout, output.unknowns[i]);
    offsets_.push_back(f->offset);
    components_.push_back(f->components);
  }
  for (int i = 0; i < output.n_constants; ++i) {
    const auto it = constants.find(output.constants[i]);
    if (it == constants.end())
      throw std::invalid_argument(std::string("PointEvaluator: no value for the constant '") + output.constants[i] + "' of " + output.module +
                                  "." + output.name);
    constants_.push_back(it->second);
  }
}

void PointEvaluator::evaluate(const LmeBasis& basis, std::span<const double> x, std::span<const double> state, std::span<double> values,
                              double spacing) const {
  const kernel::FormKernels& k = *kernel_;
  const int order = k.basis_order;
  std::vector<double> at(x.begin(), x.end());
  std::vector<int> list = basis.neighbours(at);
  // Moves `at` the fraction `f` of its neighbours' mean spacing towards their centre.
  auto move_inward = [&](double f) {
    double h = 0;
    std::vector<double> centre(at.size(), 0.0);
    // The centre of the other neighbours: at a node, the node itself would pull it onto x.
    std::size_t others = 0;
    for (const int a : list) {
      const auto xa = basis.nodes().point(static_cast<std::size_t>(a));
      double d2 = 0;
      for (std::size_t i = 0; i < at.size(); ++i) d2 += (xa[i] - at[i]) * (xa[i] - at[i]);
      h += basis.spacing()[static_cast<std::size_t>(a)] / double(list.size());
      if (d2 <= 1e-24 * basis.spacing()[static_cast<std::size_t>(a)] * basis.spacing()[static_cast<std::size_t>(a)]) continue;
      for (std::size_t i = 0; i < at.size(); ++i) centre[i] += xa[i];
      ++others;
    }
    if (others == 0) return;
    for (double& c : centre) c /= double(others);
    double distance = 0;
    for (std::size_t i = 0; i < at.size(); ++i) distance += (centre[i] - at[i]) * (centre[i] - at[i]);
    distance = std::sqrt(distance);
    if (distance == 0) return;
    for (std::size_t i = 0; i < at.size(); ++i) at[i] += f * h * (centre[i] - at[i]) / distance;
    list = basis.neighbours(at);
  };
  if (order > 0 && domain_ != nullptr && domain_->depth(at) <= 1e-9 * domain_->diameter()) move_inward(1e-3);
  std::vector<double> jet;
  try {
    jet = basis.evaluate(at, list, order);
  } catch (const LmeEvaluationError& e) {
    if (e.reason() == LmeFailure::singular_jacobian) {
      // At a node whose neighbours carry almost no weight the dual problem's Hessian J vanishes
      // (p is the Kronecker delta to round-off): a hundredth of a spacing away it is regular.
      move_inward(1e-2);
      jet = basis.evaluate(at, list, order);
    } else if (e.reason() == LmeFailure::degenerate || e.reason() == LmeFailure::too_few_neighbours ||
               e.reason() == LmeFailure::outside_hull) {
      jet = evaluate_with_nearest_nodes(basis, at, list, order);
    } else {
      throw;
    }
  }
  const std::size_t n = list.size();
  std::vector<double> local(n * static_cast<std::size_t>(k.dofs_per_node));
  for (std::size_t m = 0; m < n; ++m) {
    std::size_t slot = m * static_cast<std::size_t>(k.dofs_per_node);
    for (std::size_t u = 0; u < offsets_.size(); ++u)
      for (int c = 0; c < components_[u]; ++c)
        local[slot++] = state[static_cast<std::size_t>(list[m]) * static_cast<std::size_t>(dofs_per_node_) +
                              static_cast<std::size_t>(offsets_[u] + c)];
  }
  std::vector<double> workspace(k.workspace_doubles != nullptr ? k.workspace_doubles(static_cast<int>(n), 1) + 1 : 1);
  const double weight = 1.0;
  kernel::CellInputs in;
  in.n_nodes = static_cast<int>(n);
  in.n_points = 1;
  in.basis_order = order;
  in.weights = &weight;
  in.points = at.data();
  in.basis = jet.data();
  in.unknowns = local.data();
  in.constants = constants_.empty() ? nullptr : constants_.data();
  in.workspace = workspace.data();
  in.contractions = &dense_contractions();
  if (k.reads_spacing) {
    if (!(spacing > 0))
      throw std::invalid_argument(std::string("PointEvaluator: ") + k.module + "." + k.name + " reads the node spacing: evaluate it at a node");
    in.spacing = &spacing;
  }
  k.point(in, values.data());
}

CellPointValues point_values_on_cells(const Discretization& disc, const kernel::FormKernels& output, std::span<const double> state,
                                     int dofs_per_node, int offset, std::span<const double> constants) {
  if (output.kind != kernel::FunctionalKind::Point || output.point == nullptr || output.n_coefficients > 0 || output.qdata_per_point > 0 ||
      output.reads_spacing || static_cast<std::size_t>(output.n_constants) != constants.size())
    throw std::invalid_argument(std::string("point_values_on_cells: ") + output.module + "." + output.name +
                                " is not a point output of the unknowns and the given constants");
  const int order = output.basis_order;
  const auto dofs = static_cast<std::size_t>(output.dofs_per_node), nv = static_cast<std::size_t>(output.n_values);
  const auto jet = static_cast<std::size_t>(kernel::jet_size(disc.dim(), order));
  const ElementSet& cells = disc.cells_domain();
  const auto original = disc.original_index();
  std::vector<double> tabulation(static_cast<std::size_t>(cells.max_element_points()) * jet * static_cast<std::size_t>(cells.max_element_nodes()));
  std::vector<double> local, values, workspace;
  LmeWorkspace ws;
  CellPointValues out;
  for (int e = 0; e < cells.n_elements(); ++e) {
    if (!cells.element_owned(e)) continue;
    const auto nodes = cells.element_nodes(e);
    const std::size_t n = nodes.size(), nq = static_cast<std::size_t>(cells.element_point_count(e));
    const auto first = static_cast<std::size_t>(cells.element_first_point(e));
    cells.tabulate(e, order, tabulation, ws);
    local.resize(n * dofs);
    for (std::size_t a = 0; a < n; ++a)
      for (std::size_t c = 0; c < dofs; ++c)
        local[a * dofs + c] = state[std::size_t(original[std::size_t(nodes[a])]) * std::size_t(dofs_per_node) + std::size_t(offset) + c];
    values.resize(nq * nv);
    workspace.resize(output.workspace_doubles != nullptr ? output.workspace_doubles(static_cast<int>(n), static_cast<int>(nq)) + 1 : 1);
    kernel::CellInputs in;
    in.n_nodes = static_cast<int>(n);
    in.n_points = static_cast<int>(nq);
    in.basis_order = order;
    in.weights = cells.weights().data() + first;
    in.points = cells.points().data() + first * static_cast<std::size_t>(disc.dim());
    in.basis = tabulation.data();
    in.unknowns = local.data();
    in.constants = constants.empty() ? nullptr : constants.data();
    in.workspace = workspace.data();
    in.contractions = &dense_contractions();
    output.point(in, values.data());
    for (std::size_t q = 0; q < nq; ++q) out.points.push_back(static_cast<int>(first + q));
    out.values.insert(out.values.end(), values.begin(), values.end());
  }
  return out;
}

std::vector<double> renumbered_state(const Discretization& disc, std::span<const double> original, int dofs_per_node) {
  const auto bs = static_cast<std::size_t>(dofs_per_node);
  const auto index = disc.original_index();
  std::vector<double> out(original.size());
  for (std::size_t r = 0; r < index.size(); ++r)
    std::copy_n(original.begin() + std::ptrdiff_t(std::size_t(index[r]) * bs), bs, out.begin() + std::ptrdiff_t(r * bs));
  return out;
}

}  // namespace lmeform::problems
