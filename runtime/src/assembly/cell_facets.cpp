#include "cell_facets.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <map>
#include <stdexcept>
#include <string>

namespace lmeform::detail {

namespace {

using Point = std::array<double, 3>;

Point point_of(const NodeSet& nodes, int a) {
  Point p{0, 0, 0};
  const auto x = nodes.point(static_cast<std::size_t>(a));
  for (std::size_t i = 0; i < x.size(); ++i) p[i] = x[i];
  return p;
}

Point sub(const Point& a, const Point& b) { return {a[0] - b[0], a[1] - b[1], a[2] - b[2]}; }
double dot(const Point& a, const Point& b) { return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]; }
Point cross(const Point& a, const Point& b) {
  return {a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]};
}

/// The facet's unit normal and measure (2D: the segment's, 3D: the triangle's), in an orientation
/// fixed by the order of its vertices.
std::pair<Point, double> normal_and_measure(const std::array<Point, 3>& p, int dim) {
  if (dim == 2) {
    const Point t = sub(p[1], p[0]);
    const double length = std::sqrt(dot(t, t));
    return {{t[1] / length, -t[0] / length, 0.0}, length};
  }
  const Point n = cross(sub(p[1], p[0]), sub(p[2], p[0]));
  const double twice_area = std::sqrt(dot(n, n));
  return {{n[0] / twice_area, n[1] / twice_area, n[2] / twice_area}, 0.5 * twice_area};
}

}  // namespace

std::size_t CellFacets::slot(int c) const {
  const auto it = std::lower_bound(cells.begin(), cells.end(), c);
  if (it == cells.end() || *it != c) throw std::out_of_range("CellFacets: cell " + std::to_string(c) + " is not among the cells whose facets were built");
  return static_cast<std::size_t>(it - cells.begin());
}

CellFacets cell_facets(const BackgroundCells& cells, const NodeSet& nodes, const QuadratureRule& rule, std::span<const int> which) {
  const int dim = cells.dim;
  if (dim != 2 && dim != 3) throw std::invalid_argument("cell_facets: 2D or 3D cells only");
  if (rule.dim != dim - 1) throw std::invalid_argument("cell_facets: a facet rule of dimension dim - 1 is needed");
  if (!std::is_sorted(which.begin(), which.end()) || std::adjacent_find(which.begin(), which.end()) != which.end())
    throw std::invalid_argument("cell_facets: the cells must be given ascending, each once");
  CellFacets out;
  out.dim = dim;
  out.points_per_facet = static_cast<int>(rule.size());
  out.cells.assign(which.begin(), which.end());
  const auto d = static_cast<std::size_t>(dim), per_cell = d + 1;
  out.cell_facets.resize(which.size() * per_cell);
  out.cell_signs.resize(which.size() * per_cell);
  const auto key_of = [&](std::span<const int> cell, std::size_t k) {
    std::array<int, 3> key{-1, -1, -1};
    std::size_t m = 0;
    for (std::size_t j = 0; j < per_cell; ++j)
      if (j != k) key[m++] = cell[j];
    for (std::size_t i = 1; i < d; ++i)  // insertion sort of 2 or 3 entries
      for (std::size_t j = i; j > 0 && key[j - 1] > key[j]; --j) std::swap(key[j - 1], key[j]);
    return key;
  };
  std::map<std::array<int, 3>, int> index;
  for (std::size_t s = 0; s < which.size(); ++s) {
    const auto c = static_cast<std::size_t>(which[s]);
    if (c >= cells.size()) throw std::out_of_range("cell_facets: no cell " + std::to_string(c));
    const auto cell = cells.cell(c);
    Point centroid{0, 0, 0};
    for (const int v : cell)
      for (std::size_t i = 0; i < 3; ++i) centroid[i] += point_of(nodes, v)[i] / double(per_cell);
    for (std::size_t k = 0; k < per_cell; ++k) {
      const std::array<int, 3> key = key_of(cell, k);
      auto [it, added] = index.emplace(key, static_cast<int>(index.size()));
      const int f = it->second;
      std::array<Point, 3> p{};
      for (std::size_t j = 0; j < d; ++j) p[j] = point_of(nodes, key[j]);
      const auto [normal, measure] = normal_and_measure(p, dim);
      const bool outward = dot(sub(p[0], centroid), normal) > 0;
      if (added) {
        for (std::size_t j = 0; j < d; ++j) out.vertices.push_back(key[j]);
        // The first cell fixes the normal's orientation: outward of it.
        for (std::size_t i = 0; i < d; ++i) out.normals.push_back(outward ? normal[i] : -normal[i]);
        for (std::size_t g = 0; g < rule.size(); ++g) {
          const auto xi = rule.point(g);
          for (std::size_t i = 0; i < d; ++i) {
            double x = p[0][i] + xi[0] * (p[1][i] - p[0][i]);
            if (dim == 3) x += xi[1] * (p[2][i] - p[0][i]);
            out.points.push_back(x);
          }
          // The reference segment has length 1, the reference triangle area 1/2.
          out.weights.push_back(rule.weights[g] * (dim == 2 ? measure : 2 * measure));
        }
        out.sharing.push_back(static_cast<int>(c));
        out.sharing.push_back(-1);
        out.cell_signs[s * per_cell + k] = 1;
      } else {
        const double* n0 = out.normals.data() + static_cast<std::size_t>(f) * d;
        double along = 0;
        for (std::size_t i = 0; i < d; ++i) along += n0[i] * (p[0][i] - centroid[i]);
        out.cell_signs[s * per_cell + k] = along > 0 ? 1 : -1;
        out.sharing[2 * static_cast<std::size_t>(f) + 1] = static_cast<int>(c);
      }
      out.cell_facets[s * per_cell + k] = f;
    }
  }
  // The cells outside `which` across the outer facets.
  if (which.size() < cells.size()) {
    std::vector<char> listed(cells.size(), 0);
    for (const int c : which) listed[static_cast<std::size_t>(c)] = 1;
    for (std::size_t c = 0; c < cells.size(); ++c) {
      if (listed[c]) continue;
      const auto cell = cells.cell(c);
      for (std::size_t k = 0; k < per_cell; ++k)
        if (const auto it = index.find(key_of(cell, k)); it != index.end())
          out.sharing[2 * static_cast<std::size_t>(it->second) + 1] = static_cast<int>(c);
    }
  }
  return out;
}

}  // namespace lmeform::detail
