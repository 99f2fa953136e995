#include "lmeform/level_set_topology.hpp"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <map>
#include <stdexcept>
#include <tuple>
#include <unordered_map>

namespace lmeform {

namespace {

/// Union-find over the level set's vertices.
class DisjointSets {
 public:
  void add() { parent_.push_back(static_cast<int>(parent_.size())); }
  int find(int a) {
    while (parent_[std::size_t(a)] != a) {
      parent_[std::size_t(a)] = parent_[std::size_t(parent_[std::size_t(a)])];
      a = parent_[std::size_t(a)];
    }
    return a;
  }
  void unite(int a, int b) {
    a = find(a);
    b = find(b);
    if (a != b) parent_[std::size_t(std::max(a, b))] = std::min(a, b);
  }

 private:
  std::vector<int> parent_;
};

/// The level set's vertices: the cell edges whose two nodes lie on either side of it, each once.
class CrossingEdges {
 public:
  explicit CrossingEdges(const std::vector<char>& positive) : positive_(positive) {}

  /// The crossing edge a–b, or -1 when both nodes lie on one side.
  int of(int a, int b) {
    if (positive_[std::size_t(a)] == positive_[std::size_t(b)]) return -1;
    const auto lo = static_cast<std::uint64_t>(std::min(a, b)), hi = static_cast<std::uint64_t>(std::max(a, b));
    const auto [it, inserted] = ids_.try_emplace((lo << 32) | hi, static_cast<int>(ends.size()));
    if (inserted) {
      ends.push_back({static_cast<int>(lo), static_cast<int>(hi)});
      cells_around.push_back(0);
      sets.add();
    }
    return it->second;
  }

  std::vector<std::array<int, 2>> ends;  ///< the edge's nodes
  std::vector<int> cells_around;         ///< 2D: the triangles it belongs to (1: a hull edge)
  DisjointSets sets;

 private:
  const std::vector<char>& positive_;
  std::unordered_map<std::uint64_t, int> ids_;
};

/// What one component counts while the cells are scanned.
struct Tally {
  LevelSetComponent component;
  long vertices = 0, edges = 0, faces = 0;
  int axis_ends = 0, other_ends = 0;  ///< curves: ends of an arc on the axis, elsewhere on the hull
  bool hull_face = false;             ///< surfaces: a polygon side on the hull
};

std::string count_of(std::size_t n, const std::string& one, const std::string& many) {
  return n == 1 ? one : std::to_string(n) + " " + many;
}

}  // namespace

LevelSetTopology level_set_topology(const NodeSet& nodes, const BackgroundCells& cells, std::span<const double> values,
                                    LevelSetGeometry geometry) {
  const int dim = geometry == LevelSetGeometry::spatial ? 3 : 2;
  if (nodes.dim != dim || cells.dim != dim || cells.vertices_per_cell != dim + 1)
    throw std::invalid_argument("level_set_topology: " + std::string(dim == 3 ? "spatial" : "planar and axisymmetric") +
                                " level sets need " + std::to_string(dim) + "D nodes and cells, got " + std::to_string(nodes.dim) +
                                "D nodes and " + std::to_string(cells.dim) + "D cells");
  if (values.size() != nodes.size())
    throw std::invalid_argument("level_set_topology: " + std::to_string(values.size()) + " values for " + std::to_string(nodes.size()) +
                                " nodes");
  std::vector<char> positive(values.size());
  for (std::size_t a = 0; a < values.size(); ++a) {
    if (!std::isfinite(values[a])) throw std::invalid_argument("level_set_topology: the value at node " + std::to_string(a) + " is not finite");
    positive[a] = values[a] >= 0 ? 1 : 0;  // 0 counts as positive: the level 0⁻
  }

  CrossingEdges crossing(positive);
  std::vector<int> pieces;  // per crossed cell: one of its crossing edges (the cell's polygon)
  // Spatial: the crossed triangular faces of the tetrahedra, (sorted nodes, a crossing edge), each
  // once per tetrahedron; a face listed once lies on the hull.
  std::vector<std::tuple<int, int, int, int>> faces;
  const auto vpc = std::size_t(cells.vertices_per_cell);
  for (std::size_t c = 0; c < cells.size(); ++c) {
    const auto v = cells.cell(c);
    int first = -1;
    for (std::size_t i = 0; i < vpc; ++i)
      for (std::size_t j = i + 1; j < vpc; ++j) {
        const int e = crossing.of(v[i], v[j]);
        if (e < 0) continue;
        if (first < 0) first = e;
        crossing.sets.unite(first, e);
        ++crossing.cells_around[std::size_t(e)];
      }
    if (first < 0) continue;
    pieces.push_back(first);
    if (dim != 3) continue;
    for (std::size_t skip = 0; skip < 4; ++skip) {
      std::array<int, 3> f{};
      for (std::size_t k = 0, n = 0; k < 4; ++k)
        if (k != skip) f[n++] = v[k];
      const int e = std::max({crossing.of(f[0], f[1]), crossing.of(f[1], f[2]), crossing.of(f[0], f[2])});
      if (e < 0) continue;
      std::sort(f.begin(), f.end());
      faces.emplace_back(f[0], f[1], f[2], e);
    }
  }

  // Tally each component: its vertices (with their crossing points), edges and polygons.
  double extent = 0;
  for (int i = 0; i < dim; ++i) {
    double lo = std::numeric_limits<double>::infinity(), hi = -lo;
    for (std::size_t a = 0; a < nodes.size(); ++a) {
      lo = std::min(lo, nodes.point(a)[std::size_t(i)]);
      hi = std::max(hi, nodes.point(a)[std::size_t(i)]);
    }
    if (nodes.size() > 0) extent = std::max(extent, hi - lo);
  }
  const double axis_tolerance = 1e-9 * extent;
  auto on_axis = [&](int a) { return std::abs(nodes.point(std::size_t(a))[0]) <= axis_tolerance; };
  std::map<int, Tally> tallies;
  for (std::size_t e = 0; e < crossing.ends.size(); ++e) {
    Tally& t = tallies[crossing.sets.find(static_cast<int>(e))];
    const auto [a, b] = crossing.ends[e];
    const double fa = values[std::size_t(a)], fb = values[std::size_t(b)];
    const double s = fa / (fa - fb);  // the two signs differ: fa - fb is not 0
    LevelSetComponent& comp = t.component;
    for (int i = 0; i < dim; ++i) {
      const auto k = std::size_t(i);
      const double x = nodes.point(std::size_t(a))[k] + s * (nodes.point(std::size_t(b))[k] - nodes.point(std::size_t(a))[k]);
      comp.lo[k] = t.vertices == 0 ? x : std::min(comp.lo[k], x);
      comp.hi[k] = t.vertices == 0 ? x : std::max(comp.hi[k], x);
    }
    ++t.vertices;
    if (dim == 2 && crossing.cells_around[e] == 1) {  // a hull edge: an end of an arc
      if (geometry == LevelSetGeometry::axisymmetric && on_axis(a) && on_axis(b)) ++t.axis_ends;
      else ++t.other_ends;
    }
  }
  for (const int first : pieces) {
    Tally& t = tallies[crossing.sets.find(first)];
    if (dim == 2) ++t.edges;  // a triangle's piece is a segment
    else ++t.faces;           // a tetrahedron's piece is a triangle or a quadrilateral
  }
  std::sort(faces.begin(), faces.end());
  for (std::size_t i = 0; i < faces.size();) {
    std::size_t j = i + 1;
    while (j < faces.size() && std::get<0>(faces[j]) == std::get<0>(faces[i]) && std::get<1>(faces[j]) == std::get<1>(faces[i]) &&
           std::get<2>(faces[j]) == std::get<2>(faces[i]))
      ++j;
    Tally& t = tallies[crossing.sets.find(std::get<3>(faces[i]))];
    ++t.edges;  // a crossed face holds one side of the polygons of the tetrahedra around it
    if (j - i == 1) t.hull_face = true;
    i = j;
  }

  LevelSetTopology topology;
  topology.geometry = geometry;
  for (auto& [root, t] : tallies) {
    LevelSetComponent c = t.component;
    c.crossings = std::size_t(t.vertices);
    c.euler_characteristic = static_cast<int>(t.vertices - t.edges + t.faces);
    switch (geometry) {
      case LevelSetGeometry::planar:
        c.closed = t.other_ends == 0;
        break;
      case LevelSetGeometry::axisymmetric:
        // A meridian loop off the axis revolves into a torus; an arc from the axis to the axis into a sphere.
        c.closed = t.other_ends == 0;
        if (c.closed) c.genus = t.axis_ends == 0 ? 1 : 0;
        break;
      case LevelSetGeometry::spatial: {
        c.closed = !t.hull_face;
        const int twice_genus = 2 - c.euler_characteristic;
        if (c.closed && (twice_genus < 0 || twice_genus % 2 != 0))
          throw std::logic_error("level_set_topology: a closed component with Euler characteristic " +
                                 std::to_string(c.euler_characteristic) + " (not a closed orientable surface)");
        if (c.closed) c.genus = twice_genus / 2;
        break;
      }
    }
    topology.components.push_back(c);
  }
  std::sort(topology.components.begin(), topology.components.end(), [](const LevelSetComponent& x, const LevelSetComponent& y) {
    return std::tie(x.lo[0], x.lo[1], x.lo[2], x.crossings) < std::tie(y.lo[0], y.lo[1], y.lo[2], y.crossings);
  });
  return topology;
}

bool LevelSetTopology::same_as(const LevelSetTopology& other) const {
  if (geometry != other.geometry || components.size() != other.components.size()) return false;
  auto signature = [](const LevelSetTopology& t) {
    std::vector<std::pair<bool, int>> s;
    for (const auto& c : t.components) s.emplace_back(c.closed, c.genus);
    std::sort(s.begin(), s.end());
    return s;
  };
  return signature(*this) == signature(other);
}

std::string LevelSetTopology::shapes() const {
  if (components.empty()) return "none";
  if (geometry == LevelSetGeometry::planar) {
    const auto closed = static_cast<std::size_t>(std::count_if(components.begin(), components.end(), [](const auto& c) { return c.closed; }));
    const std::size_t open = components.size() - closed;
    std::string text;
    if (closed > 0) text = count_of(closed, "1 closed curve", "closed curves");
    if (open > 0) text += (text.empty() ? "" : ", ") + count_of(open, "1 open curve", "open curves") + " (reaching the boundary)";
    return text;
  }
  std::map<int, std::size_t> kinds;  // genus (-1: open) -> count
  for (const auto& c : components) ++kinds[c.closed ? c.genus : -1];
  std::vector<std::string> nouns;
  for (const auto& [genus, n] : kinds) {
    if (genus == -1) nouns.push_back(count_of(n, "an open surface", "open surfaces") + " (reaching the boundary)");
    else if (genus == 0) nouns.push_back(count_of(n, "a sphere", "spheres"));
    else if (genus == 1) nouns.push_back(count_of(n, "a torus", "tori"));
    else nouns.push_back(count_of(n, "a genus-" + std::to_string(genus) + " surface", "genus-" + std::to_string(genus) + " surfaces"));
  }
  std::string text;
  for (std::size_t i = 0; i < nouns.size(); ++i) text += (i == 0 ? "" : i + 1 == nouns.size() ? " and " : ", ") + nouns[i];
  return text;
}

std::string LevelSetTopology::describe() const {
  if (components.empty()) return "no interface (the field has one sign)";
  if (geometry == LevelSetGeometry::planar) return shapes();
  std::string genera;
  for (const auto& c : components) genera += (genera.empty() ? "" : ", ") + (c.closed ? std::to_string(c.genus) : std::string("open"));
  return count_of(components.size(), "1 component", "components") + ", genus " + genera + " (" + shapes() + ")";
}

}  // namespace lmeform
