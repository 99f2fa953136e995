// Octree (quadtree) vertex sets that follow a spacing function (domain.hpp).
#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <stdexcept>
#include <vector>

#include <fmt/format.h>
#include <fmt/ranges.h>

#include "lmeform/domain.hpp"

namespace lmeform {

namespace {

/// The largest spacing over a sample of the box (17 points per axis, corners included): the level-0
/// grid. Every sampled value is checked, so a spacing that is not positive and finite is refused
/// before any refinement.
double largest_spacing(const Box& box, const SpacingFunction& spacing) {
  constexpr int samples = 17;
  const int nz = box.dim == 3 ? samples : 1;
  double largest = spacing.h_min;
  std::array<double, 3> x{};
  for (int k = 0; k < nz; ++k)
    for (int j = 0; j < samples; ++j)
      for (int i = 0; i < samples; ++i) {
        const std::array<int, 3> index{i, j, k};
        for (std::size_t a = 0; a < std::size_t(box.dim); ++a)
          x[a] = box.lo[a] + (box.hi[a] - box.lo[a]) * index[a] / double(samples - 1);
        const double h = spacing.h(std::span<const double>(x.data(), std::size_t(box.dim)));
        if (!(h > 0) || !std::isfinite(h))
          throw std::invalid_argument(fmt::format("nested_grids: the spacing at ({}) is {}: it must be positive and finite",
                                                  fmt::join(std::span<const double>(x.data(), std::size_t(box.dim)), ", "), h));
        largest = std::max(largest, h);
      }
  return largest;
}

}  // namespace

NodeSet nested_grids(const Box& box, const SpacingFunction& spacing, std::size_t max_nodes, double level0_spacing) {
  box.validate("nested_grids");
  if (box.dim != 2 && box.dim != 3) throw std::invalid_argument(fmt::format("nested_grids: a 2D or 3D box, got dimension {}", box.dim));
  if (!(spacing.h_min > 0) || !std::isfinite(spacing.h_min) || !spacing.h)
    throw std::invalid_argument(fmt::format("nested_grids: h_min = {} must be positive and finite, with a spacing function", spacing.h_min));
  const auto dim = std::size_t(box.dim);
  if (level0_spacing < 0 || !std::isfinite(level0_spacing))
    throw std::invalid_argument(fmt::format("nested_grids: level0_spacing = {} must be positive and finite (or 0: the largest h)", level0_spacing));
  const double largest = largest_spacing(box, spacing);
  const double coarsest = level0_spacing > 0 ? std::max(level0_spacing, largest) : largest;

  // Level 0: about the coarsest spacing on every axis; level l halves it l times.
  std::array<std::int64_t, 3> cells0{1, 1, 1};
  std::array<double, 3> length{};
  for (std::size_t a = 0; a < dim; ++a) {
    length[a] = box.hi[a] - box.lo[a];
    cells0[a] = std::max<std::int64_t>(1, std::llround(length[a] / coarsest));
  }
  const auto size_at = [&](int level) {
    double s = 0;
    for (std::size_t a = 0; a < dim; ++a) s = std::max(s, length[a] / (double(cells0[a]) * std::ldexp(1.0, level)));
    return s;
  };
  int finest = 0;
  while (size_at(finest) > spacing.h_min * (1 + 1e-12)) {
    if (++finest > 20)
      throw std::invalid_argument(fmt::format("nested_grids: h_min = {} needs more than 20 halvings of the level-0 spacing {}", spacing.h_min,
                                              size_at(0)));
  }
  // Integer coordinates on the finest grid: intervals[a] + 1 points per axis.
  std::array<std::int64_t, 3> intervals{0, 0, 0};
  for (std::size_t a = 0; a < dim; ++a) intervals[a] = cells0[a] << finest;
  const auto key = [&](std::int64_t i, std::int64_t j, std::int64_t k) {
    return std::uint64_t(i + (intervals[0] + 1) * (j + (intervals[1] + 1) * k));
  };

  struct Cell {
    std::array<std::int64_t, 3> corner;  ///< on the finest grid
    int level;
  };
  std::vector<Cell> pending;
  for (std::int64_t k = 0; k < (dim == 3 ? cells0[2] : 1); ++k)
    for (std::int64_t j = 0; j < cells0[1]; ++j)
      for (std::int64_t i = 0; i < cells0[0]; ++i)
        pending.push_back({{i << finest, j << finest, k << finest}, 0});

  std::vector<std::uint64_t> vertices;
  const std::size_t corners = std::size_t(1) << dim, budget = 4 * corners * max_nodes;
  std::array<double, 3> centre{};
  while (!pending.empty()) {
    const Cell c = pending.back();
    pending.pop_back();
    const std::int64_t width = std::int64_t(1) << (finest - c.level);
    for (std::size_t a = 0; a < dim; ++a)
      centre[a] = box.lo[a] + length[a] * (double(c.corner[a]) + 0.5 * double(width)) / double(intervals[a]);
    const bool refine = c.level < finest && spacing.h(std::span<const double>(centre.data(), dim)) < size_at(c.level) * (1 - 1e-12);
    if (refine) {
      const std::int64_t half = width / 2;
      for (std::size_t child = 0; child < corners; ++child) {
        Cell d{c.corner, c.level + 1};
        for (std::size_t a = 0; a < dim; ++a)
          if ((child >> a) & 1U) d.corner[a] += half;
        pending.push_back(d);
      }
      continue;
    }
    for (std::size_t v = 0; v < corners; ++v) {
      std::array<std::int64_t, 3> p = c.corner;
      for (std::size_t a = 0; a < dim; ++a)
        if ((v >> a) & 1U) p[a] += width;
      vertices.push_back(key(p[0], p[1], p[2]));
    }
    if (vertices.size() > budget) {
      std::sort(vertices.begin(), vertices.end());
      vertices.erase(std::unique(vertices.begin(), vertices.end()), vertices.end());
      if (vertices.size() > max_nodes)
        throw std::invalid_argument(fmt::format("nested_grids: more than {} nodes (max_nodes) down to the spacing {:.4g}", max_nodes,
                                                size_at(finest)));
    }
  }
  std::sort(vertices.begin(), vertices.end());
  vertices.erase(std::unique(vertices.begin(), vertices.end()), vertices.end());
  if (vertices.size() > max_nodes)
    throw std::invalid_argument(fmt::format("nested_grids: {} nodes down to the spacing {:.4g}, more than max_nodes = {}", vertices.size(),
                                            size_at(finest), max_nodes));

  std::vector<double> coords;
  coords.reserve(vertices.size() * dim);
  for (const std::uint64_t v : vertices) {
    std::array<std::int64_t, 3> p{};
    std::uint64_t rest = v;
    for (std::size_t a = 0; a < 3; ++a) {
      const auto n = std::uint64_t(intervals[a] + 1);
      p[a] = std::int64_t(rest % n);
      rest /= n;
    }
    for (std::size_t a = 0; a < dim; ++a)
      coords.push_back(p[a] == intervals[a] ? box.hi[a] : box.lo[a] + length[a] * double(p[a]) / double(intervals[a]));
  }
  return NodeSet(box.dim, std::move(coords));
}

}  // namespace lmeform
