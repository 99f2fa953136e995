#include "quadrature_data.hpp"

#include <fmt/format.h>

#include "field_transfer.hpp"
#include "lmeform/kernel.hpp"

namespace lmeform::problems {

namespace {

/// Whether every rank holds every point of the domain in one numbering: then each rank computes
/// the points of the elements it owns and the ranks sum them; otherwise each rank computes the
/// points it holds.
bool shared_points(const Discretization& disc, const ElementSet& domain) { return domain.boundary() || disc.points_on_every_rank(); }

/// φ and its derivatives up to `order` (∇φ, then ∇∇φ) of a scalar nodal field (original node order)
/// at the domain's points, one array per derivative, jet-size values each: the reference field of a
/// Lagrangian form. One neighbour search and one evaluation of the basis per point serve every
/// derivative. `field_basis` interpolates (its nodes in the original numbering); with a null basis
/// the discretization's own.
std::vector<std::vector<double>> interpolated_field_jets(const Discretization& disc, const ElementSet& domain,
                                                         std::span<const double> original_values, int order, const LmeBasis* field_basis) {
  const auto& lists = domain.point_lists();
  const int dim = disc.dim();
  const auto d = std::size_t(dim);
  // A cell's vertices restore the hull of a point's list where the field's own basis sees too few
  // neighbours (boundary points lie on the hull of their lists' facets already).
  const bool cells = !domain.boundary();
  const auto original = disc.original_index();
  std::vector<std::vector<double>> out;
  for (int k = 0; k <= order; ++k) out.emplace_back(domain.n_points() * (k == 0 ? 1 : k == 1 ? d : d * d), 0.0);
  std::vector<int> own_list;
  const bool shared = shared_points(disc, domain);
  for (int e = 0; e < domain.n_elements(); ++e) {
    if (shared && !domain.element_owned(e)) continue;
    for (int q = domain.element_first_point(e); q < domain.element_first_point(e) + domain.element_point_count(e); ++q) {
      const auto x = domain.point(std::size_t(q));
      std::span<const int> list = lists[std::size_t(q)];
      std::vector<double> jet;
      if (field_basis != nullptr) {
        own_list = field_basis->neighbours(x);
        jet = evaluate_with_cell_fallback(*field_basis, x, own_list, order, [&] {
          std::vector<int> vertices;
          if (cells)
            for (const int v : disc.cells().cell(std::size_t(disc.point_cell(std::size_t(q))))) vertices.push_back(original[std::size_t(v)]);
          return vertices;
        });
        list = own_list;
      } else {
        jet = disc.basis().evaluate(x, list, order);
      }
      const auto p = std::size_t(q);
      for (std::size_t m = 0; m < list.size(); ++m) {
        const auto node = field_basis != nullptr ? std::size_t(list[m]) : std::size_t(original[std::size_t(list[m])]);
        const double phi = original_values[node];
        out[0][p] += jet[m] * phi;
        if (order < 1) continue;
        for (std::size_t c = 0; c < d; ++c) out[1][p * d + c] += jet[(1 + c) * list.size() + m] * phi;
        if (order < 2) continue;
        for (int i = 0; i < dim; ++i)
          for (int j = i; j < dim; ++j) {
            const auto row = static_cast<std::size_t>(kernel::hessian_slot(i, j, dim));
            const double v = jet[row * list.size() + m] * phi;
            out[2][p * d * d + std::size_t(i * dim + j)] += v;
            if (i != j) out[2][p * d * d + std::size_t(j * dim + i)] += v;
          }
      }
    }
  }
  if (shared)
    for (auto& values : out) MPI_Allreduce(MPI_IN_PLACE, values.data(), static_cast<int>(values.size()), MPI_DOUBLE, MPI_SUM, disc.comm());
  return out;
}

}  // namespace

std::vector<double> support_size_qdata(const Discretization& disc, const ElementSet& domain) {
  // The partition of unity weights each nodal spacing by the node's share of the point: the local
  // length scale of the basis the point actually sees (a plain mean over the support would count
  // far, barely contributing nodes as much as the nearest ones, and jump as nodes enter it).
  // The shares are the basis values the domain has tabulated already (a second evaluation of the
  // basis here cost 11 % of a second-order Stokes solve).
  const auto h = disc.basis().spacing();
  std::vector<double> tabulation(static_cast<std::size_t>(domain.max_element_points()) * static_cast<std::size_t>(domain.max_element_nodes()));
  LmeWorkspace ws;
  std::vector<double> out(domain.n_points(), 0.0);
  const bool shared = shared_points(disc, domain);
  for (int e = 0; e < domain.n_elements(); ++e) {
    if (shared && !domain.element_owned(e)) continue;
    const auto nodes = domain.element_nodes(e);
    const std::size_t n = nodes.size();
    domain.tabulate(e, 0, tabulation, ws);
    for (int k = 0; k < domain.element_point_count(e); ++k) {
      double s = 0;
      for (std::size_t a = 0; a < n; ++a) s += tabulation[static_cast<std::size_t>(k) * n + a] * h[static_cast<std::size_t>(nodes[a])];
      out[static_cast<std::size_t>(domain.element_first_point(e) + k)] = s;
    }
  }
  if (shared) MPI_Allreduce(MPI_IN_PLACE, out.data(), static_cast<int>(out.size()), MPI_DOUBLE, MPI_SUM, disc.comm());
  return out;
}

QuadratureData::QuadratureData(const BoundScene& b, const Discretization& disc, const ProblemInput& input)
    : bound_(b), disc_(disc), input_(input) {}

const std::vector<double>& QuadratureData::values(const BoundQdata& source) { return values(source, disc_.cells_domain()); }

const std::vector<double>& QuadratureData::values(const BoundQdata& source, const ElementSet& domain) {
  const auto key = std::pair{&domain, source.name};
  if (const auto it = computed_.find(key); it != computed_.end()) return it->second;
  if (!domain.boundary() && (input_.qdata_values.contains(source.name) || source.source == SceneQdata::Source::field))
    field_data_names_.push_back(source.name);
  return computed_[key] = compute(source, domain);
}

std::map<std::string, std::vector<double>, std::less<>> QuadratureData::field_data() const {
  std::map<std::string, std::vector<double>, std::less<>> out;
  for (const auto& name : field_data_names_) out[name] = computed_.at({&disc_.cells_domain(), name});
  return out;
}

std::vector<double> QuadratureData::compute(const BoundQdata& source, const ElementSet& domain) {
  const std::size_t points = domain.n_points();
  const auto size = static_cast<std::size_t>(source.size);
  if (const auto given = input_.qdata_values.find(source.name); given != input_.qdata_values.end()) {
    if (domain.boundary())
      throw SceneError(fmt::format("{}: quadrature data '{}' given by the driver exist at the cells' points only; a boundary "
                                   "integral cannot read them",
                                   bound_.source, source.name));
    const std::size_t every_point = disc_.cells().size() * static_cast<std::size_t>(disc_.quadrature().points_per_cell);
    if (given->second.size() != every_point * size)
      throw std::invalid_argument(fmt::format("build_problem_space: {} values of '{}' for {} points x {}", given->second.size(),
                                              given->first, every_point, size));
    std::vector<double> mine(points * size);
    for (std::size_t q = 0; q < points; ++q)
      std::copy_n(given->second.begin() + std::ptrdiff_t(disc_.global_point(q) * size), size, mine.begin() + std::ptrdiff_t(q * size));
    return mine;
  }
  using Source = SceneQdata::Source;
  switch (source.source) {
    case Source::zero: return std::vector<double>(points * size, 0.0);
    case Source::support_size: {
      auto& rho = support_size_[&domain];
      if (rho.empty()) rho = support_size_qdata(disc_, domain);
      return rho;
    }
    case Source::value: {
      std::vector<double> out(points * size);
      std::vector<double> v(size, source.value.number);
      for (std::size_t q = 0; q < points; ++q) {
        if (source.value.is_expression()) bound_.expressions->evaluate(source.value.expression, domain.point(q), v);
        std::copy(v.begin(), v.end(), out.begin() + std::ptrdiff_t(q * size));
      }
      return out;
    }
    case Source::field: return field_jets(source, domain);
  }
  throw std::logic_error("unknown quadrature-data source");
}

std::vector<double> QuadratureData::field_jets(const BoundQdata& source, const ElementSet& domain) {
  auto& values = field_jets_[{&domain, source.field, source.derivative}];
  if (!values.empty()) return values;
  const auto given = input_.coefficient_values.find(source.field);
  const std::vector<double> field =
      given != input_.coefficient_values.end() ? given->second : coefficient_values(bound_, source.field, 1, input_.nodes);
  const bool mirror_fields = bound_.axisymmetric && input_.lme.mirrors.empty();
  if (mirror_fields && !field_basis_) {
    LmeOptions lme = input_.lme;
    lme.mirrors = {MirrorPlane{0, 0.0}};
    field_basis_.emplace(input_.nodes, std::vector<double>{bound_.discretization.gamma}, lme);
  }
  // Every jet of the field the scene reads, from one evaluation of the basis per point.
  int order = source.derivative;
  for (const BoundQdata& q : bound_.qdata)
    if (q.source == SceneQdata::Source::field && q.field == source.field) order = std::max(order, q.derivative);
  std::vector<std::vector<double>> jets = interpolated_field_jets(disc_, domain, field, order, field_basis_ ? &*field_basis_ : nullptr);
  for (int k = 0; k <= order; ++k) field_jets_[{&domain, source.field, k}] = std::move(jets[std::size_t(k)]);
  return values;
}

}  // namespace lmeform::problems
