#include "membrane_topology.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>
#include <string>

#include <fmt/format.h>

#include "point_values.hpp"

namespace lmeform::problems {

LevelSetGeometry level_set_geometry(int dim, bool axisymmetric) {
  if (dim == 3) return LevelSetGeometry::spatial;
  if (dim != 2) throw std::invalid_argument(fmt::format("level_set_geometry: no level-set topology in {}D", dim));
  return axisymmetric ? LevelSetGeometry::axisymmetric : LevelSetGeometry::planar;
}

std::vector<double> lme_values_at_nodes(MPI_Comm comm, const LmeBasis& basis, std::span<const double> coefficients) {
  const NodeSet& nodes = basis.nodes();
  if (coefficients.size() != nodes.size())
    throw std::invalid_argument(fmt::format("lme_values_at_nodes: {} coefficients for {} nodes", coefficients.size(), nodes.size()));
  // Each rank evaluates a block of the nodes; the blocks are then shared. A rank whose block throws
  // makes every rank throw, so that none waits in the exchange.
  int rank = 0, size = 1;
  MPI_Comm_rank(comm, &rank);
  MPI_Comm_size(comm, &size);
  const auto block_start = [&](int r) { return static_cast<int>(nodes.size() * static_cast<std::size_t>(r) / static_cast<std::size_t>(size)); };
  std::vector<double> values(nodes.size());
  std::string failure;
  try {
    // The block's lists in one search (a search per point uses the largest radius of a graded set).
    const auto d = static_cast<std::size_t>(nodes.dim);
    const std::span<const double> block(nodes.coords.data() + std::size_t(block_start(rank)) * d,
                                        std::size_t(block_start(rank + 1) - block_start(rank)) * d);
    const CsrLists lists = basis.neighbour_lists(block);
    for (int a = block_start(rank); a < block_start(rank + 1); ++a) {
      const auto x = nodes.point(std::size_t(a));
      const std::span<const int> list = lists[std::size_t(a - block_start(rank))];
      try {
        const std::vector<double> p = basis.evaluate(x, list, 0);
        double v = 0;
        for (std::size_t m = 0; m < list.size(); ++m) v += p[m] * coefficients[std::size_t(list[m])];
        values[std::size_t(a)] = v;
      } catch (const LmeEvaluationError&) {
        values[std::size_t(a)] = coefficients[std::size_t(a)];
      }
    }
  } catch (const std::exception& e) {
    failure = e.what();
  }
  int failed = failure.empty() ? 0 : 1;
  MPI_Allreduce(MPI_IN_PLACE, &failed, 1, MPI_INT, MPI_MAX, comm);
  if (failed != 0) throw std::runtime_error(failure.empty() ? "lme_values_at_nodes: another rank failed" : failure);
  std::vector<int> counts(static_cast<std::size_t>(size)), starts(static_cast<std::size_t>(size));
  for (int r = 0; r < size; ++r) {
    starts[std::size_t(r)] = block_start(r);
    counts[std::size_t(r)] = block_start(r + 1) - block_start(r);
  }
  MPI_Allgatherv(MPI_IN_PLACE, 0, MPI_DATATYPE_NULL, values.data(), counts.data(), starts.data(), MPI_DOUBLE, comm);
  return values;
}

LevelSetTopology field_topology(const Discretization& disc, std::span<const double> coefficients, LevelSetGeometry geometry,
                                std::span<const MirrorPlane> symmetry_planes) {
  const std::vector<double> renumbered = renumbered_state(disc, coefficients, 1);
  const std::vector<double> values = lme_values_at_nodes(disc.comm(), disc.basis(), renumbered);
  if (symmetry_planes.empty()) return level_set_topology(disc.nodes(), disc.cells(), values, geometry);
  return symmetric_level_set_topology(disc.nodes(), values, symmetry_planes, geometry);
}

LevelSetTopology symmetric_level_set_topology(const NodeSet& nodes, std::span<const double> values, std::span<const MirrorPlane> symmetry_planes,
                                              LevelSetGeometry geometry) {
  if (values.size() != nodes.size())
    throw std::invalid_argument(fmt::format("symmetric_level_set_topology: {} values for {} nodes", values.size(), nodes.size()));
  if (symmetry_planes.empty()) return level_set_topology(nodes, delaunay(nodes), values, geometry);
  const auto dim = static_cast<std::size_t>(nodes.dim);
  for (const MirrorPlane& m : symmetry_planes)
    if (m.axis < 0 || std::size_t(m.axis) >= dim)
      throw std::invalid_argument(fmt::format("symmetric_level_set_topology: a plane normal to axis {} in {}D", m.axis, dim));
  // Nodes on a plane (to round-off of the nodes' extent) are not copied across it: the images
  // must not duplicate them, or the triangulation of the whole would have coincident vertices.
  double extent = 0;
  for (std::size_t k = 0; k < dim; ++k) {
    double lo = std::numeric_limits<double>::infinity(), hi = -lo;
    for (std::size_t a = 0; a < nodes.size(); ++a) {
      lo = std::min(lo, nodes.coords[a * dim + k]);
      hi = std::max(hi, nodes.coords[a * dim + k]);
    }
    extent = std::max(extent, hi - lo);
  }
  const double on_plane = 1e-9 * extent;
  std::vector<double> coords = nodes.coords, all_values(values.begin(), values.end());
  for (std::size_t mask = 1; mask < (std::size_t(1) << symmetry_planes.size()); ++mask)
    for (std::size_t a = 0; a < nodes.size(); ++a) {
      std::vector<double> image(nodes.coords.begin() + std::ptrdiff_t(a * dim), nodes.coords.begin() + std::ptrdiff_t((a + 1) * dim));
      bool distinct = true;
      for (std::size_t p = 0; distinct && p < symmetry_planes.size(); ++p) {
        if ((mask & (std::size_t(1) << p)) == 0) continue;
        double& x = image[std::size_t(symmetry_planes[p].axis)];
        distinct = std::abs(x - symmetry_planes[p].position) > on_plane;
        x = 2 * symmetry_planes[p].position - x;
      }
      if (!distinct) continue;
      coords.insert(coords.end(), image.begin(), image.end());
      all_values.push_back(values[a]);
    }
  const NodeSet whole(nodes.dim, std::move(coords));
  return level_set_topology(whole, delaunay(whole), all_values, geometry);
}

LevelSetTopology field_topology(MPI_Comm comm, const NodeSet& nodes, const BackgroundCells& cells, std::span<const double> coefficients,
                                double gamma, const LmeOptions& lme, LevelSetGeometry geometry) {
  const std::vector<double> gammas(nodes.size(), gamma);
  const LmeBasis basis(nodes, gammas, lme);
  return level_set_topology(nodes, cells, lme_values_at_nodes(comm, basis, coefficients), geometry);
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
