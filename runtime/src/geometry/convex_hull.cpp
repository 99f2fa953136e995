#include "lmeform/convex_hull.hpp"

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <string>
#include <tuple>

#include "qhull_run.hpp"

namespace lmeform {

namespace {

double bbox_diagonal(const NodeSet& nodes) {
  const auto d = static_cast<std::size_t>(nodes.dim);
  if (nodes.size() == 0) return 0.0;
  double s = 0;
  for (std::size_t i = 0; i < d; ++i) {
    double mn = nodes.coords[i], mx = mn;
    for (std::size_t a = 0; a < nodes.size(); ++a) {
      mn = std::min(mn, nodes.coords[a * d + i]);
      mx = std::max(mx, nodes.coords[a * d + i]);
    }
    s += (mx - mn) * (mx - mn);
  }
  return std::sqrt(s);
}

ConvexHull hull_1d(const NodeSet& nodes) {
  const auto [mn, mx] = std::minmax_element(nodes.coords.begin(), nodes.coords.end());
  const int imin = static_cast<int>(mn - nodes.coords.begin()), imax = static_cast<int>(mx - nodes.coords.begin());
  ConvexHull h;
  h.dim = 1;
  h.vertices = {std::min(imin, imax), std::max(imin, imax)};
  h.facets = {imin, imax};
  h.normals = {-1.0, 1.0};
  h.offsets = {*mn, -*mx};
  h.measure = *mx - *mn;
  return h;
}

}  // namespace

ConvexHull convex_hull(const NodeSet& nodes) {
  detail::require_full_dimensional(nodes, "convex_hull");
  if (nodes.dim == 1) return hull_1d(nodes);

  // Qt: triangulated facets (edges in 2D, triangles in 3D); their hyperplanes are those of the merged faces.
  detail::QhullRun run(nodes, "Qt", "convex_hull");
  qhT* qh = run.get();
  const int d = nodes.dim;
  const auto du = static_cast<std::size_t>(d);
  ConvexHull h;
  h.dim = d;

  vertexT* vertex = nullptr;
  vertexT** vertexp = nullptr;
  facetT* facet = nullptr;
  FORALLvertices { h.vertices.push_back(qh_pointid(qh, vertex->point)); }
  std::sort(h.vertices.begin(), h.vertices.end());

  // An interior reference point for orientation and the measure: the mean of the hull vertices.
  std::array<double, 3> c{};
  for (int id : h.vertices)
    for (std::size_t i = 0; i < du; ++i) c[i] += nodes.coords[static_cast<std::size_t>(id) * du + i] / static_cast<double>(h.vertices.size());

  std::vector<std::tuple<std::array<double, 3>, double>> planes;
  std::vector<int> v;
  FORALLfacets {
    v.clear();
    FOREACHvertex_(facet->vertices) { v.push_back(qh_pointid(qh, vertex->point)); }
    if (static_cast<int>(v.size()) != d) {
      throw std::logic_error("convex_hull: qhull returned a facet with " + std::to_string(v.size()) + " vertices despite 'Qt'");
    }
    std::array<double, 3> n{};
    for (std::size_t i = 0; i < du; ++i) n[i] = facet->normal[i];
    planes.emplace_back(n, facet->offset);
    // The facet is oriented outward exactly when the simplex (c, facet) has positive measure; the
    // measures of these simplices also sum to the hull's measure.
    std::array<std::array<double, 3>, 3> e{};
    for (std::size_t k = 0; k < du; ++k)
      for (std::size_t i = 0; i < du; ++i) e[k][i] = nodes.coords[static_cast<std::size_t>(v[k]) * du + i] - c[i];
    double m = d == 2 ? (e[0][0] * e[1][1] - e[0][1] * e[1][0]) / 2.0
                      : (e[0][0] * (e[1][1] * e[2][2] - e[1][2] * e[2][1]) - e[0][1] * (e[1][0] * e[2][2] - e[1][2] * e[2][0]) +
                         e[0][2] * (e[1][0] * e[2][1] - e[1][1] * e[2][0])) / 6.0;
    if (m < 0) {
      std::swap(v[0], v[1]);
      m = -m;
    }
    h.measure += m;
    h.facets.insert(h.facets.end(), v.begin(), v.end());
  }
  std::sort(planes.begin(), planes.end());
  planes.erase(std::unique(planes.begin(), planes.end()), planes.end());
  for (const auto& [n, off] : planes) {
    h.normals.insert(h.normals.end(), n.begin(), n.begin() + d);
    h.offsets.push_back(off);
  }
  return h;
}

std::vector<int> hull_boundary_nodes(const NodeSet& nodes, double relative_tolerance) {
  return hull_boundary_nodes(nodes, convex_hull(nodes), relative_tolerance);
}

std::vector<int> hull_boundary_nodes(const NodeSet& nodes, const ConvexHull& hull, double relative_tolerance) {
  if (hull.dim != nodes.dim) throw std::invalid_argument("hull_boundary_nodes: hull is " + std::to_string(hull.dim) + "D, nodes " + std::to_string(nodes.dim) + "D");
  const double tol = relative_tolerance * bbox_diagonal(nodes);
  const auto d = static_cast<std::size_t>(nodes.dim);
  std::vector<int> out;
  // Every node lies in the hull, so a node on a supporting hyperplane lies on the hull's face in that plane.
  for (std::size_t a = 0; a < nodes.size(); ++a) {
    const auto x = nodes.point(a);
    for (std::size_t p = 0; p < hull.offsets.size(); ++p) {
      double s = hull.offsets[p];
      for (std::size_t i = 0; i < d; ++i) s += hull.normals[p * d + i] * x[i];
      if (std::abs(s) <= tol) {
        out.push_back(static_cast<int>(a));
        break;
      }
    }
  }
  return out;
}

std::vector<int> box_boundary_nodes(const NodeSet& nodes, const Box& box, double tolerance) {
  box.validate("box_boundary_nodes");
  if (box.dim != nodes.dim) throw std::invalid_argument("box_boundary_nodes: box is " + std::to_string(box.dim) + "D, nodes " + std::to_string(nodes.dim) + "D");
  const auto d = static_cast<std::size_t>(nodes.dim);
  std::vector<int> out;
  for (std::size_t a = 0; a < nodes.size(); ++a) {
    for (std::size_t i = 0; i < d; ++i) {
      const double x = nodes.coords[a * d + i];
      if (std::abs(x - box.lo[i]) <= tolerance || std::abs(x - box.hi[i]) <= tolerance) {
        out.push_back(static_cast<int>(a));
        break;
      }
    }
  }
  return out;
}

std::vector<char> index_mask(std::size_t size, const std::vector<int>& indices) {
  std::vector<char> m(size, 0);
  for (int i : indices) {
    if (i < 0 || static_cast<std::size_t>(i) >= size) throw std::out_of_range("index_mask: index " + std::to_string(i) + " outside [0, " + std::to_string(size) + ")");
    m[static_cast<std::size_t>(i)] = 1;
  }
  return m;
}

}  // namespace lmeform
