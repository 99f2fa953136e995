#include "membrane_topology.hpp"

#include <stdexcept>

#include <fmt/format.h>

#include "point_values.hpp"

namespace lmeform::problems {

LevelSetGeometry level_set_geometry(int dim, bool axisymmetric) {
  if (dim == 3) return LevelSetGeometry::spatial;
  if (dim != 2) throw std::invalid_argument(fmt::format("level_set_geometry: no level-set topology in {}D", dim));
  return axisymmetric ? LevelSetGeometry::axisymmetric : LevelSetGeometry::planar;
}

std::vector<double> lme_values_at_nodes(const LmeBasis& basis, std::span<const double> coefficients) {
  const NodeSet& nodes = basis.nodes();
  if (coefficients.size() != nodes.size())
    throw std::invalid_argument(fmt::format("lme_values_at_nodes: {} coefficients for {} nodes", coefficients.size(), nodes.size()));
  std::vector<double> values(nodes.size());
  for (std::size_t a = 0; a < nodes.size(); ++a) {
    const auto x = nodes.point(a);
    const std::vector<int> list = basis.neighbours(x);
    try {
      const std::vector<double> p = basis.evaluate(x, list, 0);
      double v = 0;
      for (std::size_t m = 0; m < list.size(); ++m) v += p[m] * coefficients[std::size_t(list[m])];
      values[a] = v;
    } catch (const LmeEvaluationError&) {
      values[a] = coefficients[a];
    }
  }
  return values;
}

LevelSetTopology field_topology(const Discretization& disc, std::span<const double> coefficients, LevelSetGeometry geometry) {
  const std::vector<double> renumbered = renumbered_state(disc, coefficients, 1);
  return level_set_topology(disc.nodes(), disc.cells(), lme_values_at_nodes(disc.basis(), renumbered), geometry);
}

LevelSetTopology field_topology(const NodeSet& nodes, const BackgroundCells& cells, std::span<const double> coefficients, double gamma,
                                const LmeOptions& lme, LevelSetGeometry geometry) {
  const std::vector<double> gammas(nodes.size(), gamma);
  const LmeBasis basis(nodes, gammas, lme);
  return level_set_topology(nodes, cells, lme_values_at_nodes(basis, coefficients), geometry);
}

nlohmann::json topology_json(const LevelSetTopology& topology) {
  nlohmann::json js;
  js["components"] = topology.components.size();
  js["closed"] = nlohmann::json::array();
  for (const auto& c : topology.components) js["closed"].push_back(c.closed);
  if (topology.geometry != LevelSetGeometry::planar) {
    js["genus"] = nlohmann::json::array();
    for (const auto& c : topology.components) js["genus"].push_back(c.closed ? nlohmann::json(c.genus) : nlohmann::json());
  }
  js["summary"] = topology.describe();
  return js;
}

LevelSetTopology topology_from_json(const nlohmann::json& js, LevelSetGeometry geometry) {
  LevelSetTopology t;
  t.geometry = geometry;
  const auto& closed = js.at("closed");
  for (std::size_t i = 0; i < closed.size(); ++i) {
    LevelSetComponent c;
    c.closed = closed[i].get<bool>();
    if (js.contains("genus") && !js["genus"][i].is_null()) c.genus = js["genus"][i].get<int>();
    t.components.push_back(c);
  }
  return t;
}

std::string topology_change_warning(const LevelSetTopology& initial, const LevelSetTopology& now, const std::string& where) {
  if (now.same_as(initial)) return {};
  return fmt::format("the membrane's topology changed at {}: {} -> {}", where, initial.describe(), now.describe());
}

}  // namespace lmeform::problems
