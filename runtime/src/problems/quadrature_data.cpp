#include "quadrature_data.hpp"

#include <fmt/format.h>

#include "field_transfer.hpp"
#include "lmeform/kernel.hpp"

namespace lmeform::problems {

namespace {

/// φ, ∇φ or ∇∇φ of a scalar nodal field (original node order) at every quadrature point (each rank
/// computes the points of the elements it owns; summed over the ranks), jet-size values each: the
/// reference field of a Lagrangian form. `field_basis` interpolates (its nodes in the original
/// numbering); with a null basis the discretization's own.
std::vector<double> interpolated_field_qdata(const Discretization& disc, std::span<const double> original_values, int derivative,
                                             const LmeBasis* field_basis) {
  const auto& quad = disc.quadrature();
  const auto& lists = disc.point_lists();
  const int dim = disc.dim();
  const std::size_t size = derivative == 0 ? 1 : derivative == 1 ? std::size_t(dim) : std::size_t(dim * dim);
  const std::size_t first = derivative == 0 ? 0 : derivative == 1 ? 1 : 1 + std::size_t(dim);
  const auto original = disc.original_index();
  std::vector<double> out(quad.size() * size, 0.0);
  std::vector<int> own_list;
  for (int e = 0; e < disc.n_elements(); ++e) {
    if (!disc.element_owned(e)) continue;
    for (int q = disc.element_first_point(e); q < disc.element_first_point(e) + disc.element_point_count(e); ++q) {
      const auto x = quad.point(std::size_t(q));
      std::span<const int> list = lists[std::size_t(q)];
      std::vector<double> jet;
      if (field_basis != nullptr) {
        own_list = field_basis->neighbours(x);
        jet = evaluate_with_cell_fallback(*field_basis, x, own_list, derivative, [&] {
          std::vector<int> vertices;
          for (const int v : disc.cells().cell(std::size_t(q) / std::size_t(quad.points_per_cell)))
            vertices.push_back(original[std::size_t(v)]);
          return vertices;
        });
        list = own_list;
      } else {
        jet = disc.basis().evaluate(x, list, derivative);
      }
      for (std::size_t m = 0; m < list.size(); ++m) {
        const auto node = field_basis != nullptr ? std::size_t(list[m]) : std::size_t(original[std::size_t(list[m])]);
        const double phi = original_values[node];
        if (derivative < 2) {
          for (std::size_t c = 0; c < size; ++c) out[std::size_t(q) * size + c] += jet[(first + c) * list.size() + m] * phi;
          continue;
        }
        for (int i = 0; i < dim; ++i)
          for (int j = i; j < dim; ++j) {
            const auto row = static_cast<std::size_t>(kernel::hessian_slot(i, j, dim));
            const double v = jet[row * list.size() + m] * phi;
            out[std::size_t(q) * size + std::size_t(i * dim + j)] += v;
            if (i != j) out[std::size_t(q) * size + std::size_t(j * dim + i)] += v;
          }
      }
    }
  }
  MPI_Allreduce(MPI_IN_PLACE, out.data(), static_cast<int>(out.size()), MPI_DOUBLE, MPI_SUM, disc.comm());
  return out;
}

}  // namespace

std::vector<double> support_size_qdata(const Discretization& disc) {
  // The partition of unity weights each nodal spacing by the node's share of the point: the local
  // length scale of the basis the point actually sees (a plain mean over the support would count
  // far, barely contributing nodes as much as the nearest ones, and jump as nodes enter it).
  const auto& quad = disc.quadrature();
  const auto& lists = disc.point_lists();
  const auto h = disc.basis().spacing();
  std::vector<double> out(quad.size());
  for (std::size_t q = 0; q < quad.size(); ++q) {
    const auto list = lists[q];
    const auto p = disc.basis().evaluate(quad.point(q), list, 0);
    double s = 0;
    for (std::size_t m = 0; m < list.size(); ++m) s += p[m] * h[static_cast<std::size_t>(list[m])];
    out[q] = s;
  }
  return out;
}

QuadratureData::QuadratureData(const BoundScene& b, const Discretization& disc, const ProblemInput& input)
    : bound_(b), disc_(disc), input_(input) {}

const std::vector<double>& QuadratureData::values(const BoundQdata& source) {
  if (const auto it = computed_.find(source.name); it != computed_.end()) return it->second;
  if (input_.qdata_values.contains(source.name) || source.source == SceneQdata::Source::field)
    field_data_names_.push_back(source.name);
  return computed_[source.name] = compute(source);
}

std::map<std::string, std::vector<double>, std::less<>> QuadratureData::field_data() const {
  std::map<std::string, std::vector<double>, std::less<>> out;
  for (const auto& name : field_data_names_) out[name] = computed_.at(name);
  return out;
}

std::vector<double> QuadratureData::compute(const BoundQdata& source) {
  const std::size_t points = disc_.quadrature().size();
  const auto size = static_cast<std::size_t>(source.size);
  if (const auto given = input_.qdata_values.find(source.name); given != input_.qdata_values.end()) {
    if (given->second.size() != points * size)
      throw std::invalid_argument(fmt::format("build_problem_space: {} values of '{}' for {} points x {}", given->second.size(),
                                              given->first, points, size));
    return given->second;
  }
  using Source = SceneQdata::Source;
  switch (source.source) {
    case Source::zero: return std::vector<double>(points * size, 0.0);
    case Source::support_size:
      if (support_size_.empty()) support_size_ = support_size_qdata(disc_);
      return support_size_;
    case Source::value: {
      std::vector<double> out(points * size);
      std::vector<double> v(size, source.value.number);
      for (std::size_t q = 0; q < points; ++q) {
        if (source.value.is_expression()) bound_.expressions->evaluate(source.value.expression, disc_.quadrature().point(q), v);
        std::copy(v.begin(), v.end(), out.begin() + std::ptrdiff_t(q * size));
      }
      return out;
    }
    case Source::field: return field_jets(source);
  }
  throw std::logic_error("unknown quadrature-data source");
}

std::vector<double> QuadratureData::field_jets(const BoundQdata& source) {
  auto& values = field_jets_[{source.field, source.derivative}];
  if (!values.empty()) return values;
  const auto given = input_.coefficient_values.find(source.field);
  const std::vector<double> field =
      given != input_.coefficient_values.end() ? given->second : coefficient_values(bound_, source.field, 1, input_.nodes);
  const bool mirror_fields = bound_.axisymmetric && input_.lme.mirror_axis < 0;
  if (mirror_fields && !field_basis_) {
    LmeOptions lme = input_.lme;
    lme.mirror_axis = 0;
    lme.mirror_position = 0.0;
    field_basis_.emplace(input_.nodes, std::vector<double>{bound_.discretization.gamma}, lme);
  }
  values = interpolated_field_qdata(disc_, field, source.derivative, field_basis_ ? &*field_basis_ : nullptr);
  return values;
}

}  // namespace lmeform::problems
