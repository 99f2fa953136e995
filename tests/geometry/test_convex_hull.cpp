// Convex-hull boundary: box grids (hull test = box-face test), random sets against an independent
// monotone-chain hull (2D) and the Delaunay boundary faces (3D), facet orientation.
#include <gtest/gtest.h>

#include <algorithm>
#include <map>
#include <set>
#include <vector>

#include "lmeform/convex_hull.hpp"
#include "lmeform/delaunay.hpp"
#include "lmeform/node_sets.hpp"

namespace {

using namespace lmeform;

TEST(ConvexHull, BoxGridBoundary) {
  const Box b2{2, {0.0, 0.0, 0.0}, {3.0, 1.0, 0.0}};
  const auto g2 = uniform_grid(b2, std::array<int, 3>{6, 5, 1});
  const auto h2 = convex_hull(g2);
  EXPECT_NEAR(h2.measure, 3.0, 1e-13);
  EXPECT_EQ(h2.vertices, (std::vector<int>{0, 5, 24, 29}));  // the corners only
  EXPECT_EQ(h2.offsets.size(), 4U);                          // four supporting lines
  const auto bd2 = hull_boundary_nodes(g2);
  EXPECT_EQ(bd2.size(), 2U * (6U + 5U) - 4U);
  EXPECT_EQ(bd2, box_boundary_nodes(g2, b2));

  const Box b3{3, {0.0, 0.0, 0.0}, {1.0, 1.0, 2.0}};
  const auto g3 = jitter_interior(uniform_grid(b3, std::array<int, 3>{5, 4, 3}), b3, 0.01, 1);
  const auto h3 = convex_hull(g3);
  EXPECT_NEAR(h3.measure, 2.0, 1e-13);
  EXPECT_EQ(h3.vertices.size(), 8U);
  EXPECT_EQ(h3.offsets.size(), 6U);
  const auto bd3 = hull_boundary_nodes(g3, h3);
  EXPECT_EQ(bd3.size(), 60U - 3U * 2U * 1U);
  EXPECT_EQ(bd3, box_boundary_nodes(g3, b3));
  const auto mask = index_mask(g3.size(), bd3);
  EXPECT_EQ(std::count(mask.begin(), mask.end(), 1), 54);
}

// Andrew's monotone chain: the strictly convex hull vertices, independent of qhull.
std::vector<int> monotone_chain(const NodeSet& n) {
  std::vector<int> idx(n.size());
  for (std::size_t a = 0; a < n.size(); ++a) idx[a] = static_cast<int>(a);
  auto x = [&](int a) { return n.point(static_cast<std::size_t>(a))[0]; };
  auto y = [&](int a) { return n.point(static_cast<std::size_t>(a))[1]; };
  std::sort(idx.begin(), idx.end(), [&](int a, int b) { return x(a) < x(b) || (x(a) == x(b) && y(a) < y(b)); });
  auto cross = [&](int o, int a, int b) { return (x(a) - x(o)) * (y(b) - y(o)) - (y(a) - y(o)) * (x(b) - x(o)); };
  std::vector<int> h(2 * idx.size());
  std::size_t k = 0;
  for (std::size_t i = 0; i < idx.size(); ++i) {
    while (k >= 2 && cross(h[k - 2], h[k - 1], idx[i]) <= 0) --k;
    h[k++] = idx[i];
  }
  for (std::size_t i = idx.size() - 1, t = k + 1; i > 0; --i) {
    while (k >= t && cross(h[k - 2], h[k - 1], idx[i - 1]) <= 0) --k;
    h[k++] = idx[i - 1];
  }
  h.resize(k - 1);
  std::sort(h.begin(), h.end());
  return h;
}

TEST(ConvexHull, RandomSet2DMatchesMonotoneChain) {
  for (std::uint64_t seed = 1; seed <= 5; ++seed) {
    const auto n = random_points(Box::unit(2), 300, seed);
    const auto h = convex_hull(n);
    const auto expected = monotone_chain(n);
    EXPECT_EQ(h.vertices, expected);
    EXPECT_EQ(hull_boundary_nodes(n, h), expected);
    EXPECT_EQ(h.facet_count(), expected.size());
  }
}

TEST(ConvexHull, RandomSet3DMatchesDelaunayBoundary) {
  const auto n = random_points(Box{3, {0, 0, 0}, {1, 2, 3}}, 400, 8);
  const auto h = convex_hull(n);
  const auto cells = delaunay(n);
  std::map<std::vector<int>, int> count;
  for (std::size_t c = 0; c < cells.size(); ++c) {
    const auto v = cells.cell(c);
    for (std::size_t skip = 0; skip < 4; ++skip) {
      std::vector<int> f;
      for (std::size_t k = 0; k < 4; ++k)
        if (k != skip) f.push_back(v[k]);
      std::sort(f.begin(), f.end());
      ++count[f];
    }
  }
  std::set<int> on_boundary;
  for (const auto& [f, m] : count)
    if (m == 1) on_boundary.insert(f.begin(), f.end());
  EXPECT_EQ(std::vector<int>(on_boundary.begin(), on_boundary.end()), h.vertices);
  EXPECT_EQ(hull_boundary_nodes(n, h), h.vertices);
  EXPECT_NEAR(h.measure, cells.total_measure(), 1e-12 * h.measure);
  // Outward orientation: every node is on the inner side of every facet's plane.
  for (std::size_t f = 0; f < h.facet_count(); ++f) {
    const auto a = n.point(static_cast<std::size_t>(h.facets[3 * f])), b = n.point(static_cast<std::size_t>(h.facets[3 * f + 1])),
               c = n.point(static_cast<std::size_t>(h.facets[3 * f + 2]));
    const double u[3] = {b[0] - a[0], b[1] - a[1], b[2] - a[2]}, w[3] = {c[0] - a[0], c[1] - a[1], c[2] - a[2]};
    const double nrm[3] = {u[1] * w[2] - u[2] * w[1], u[2] * w[0] - u[0] * w[2], u[0] * w[1] - u[1] * w[0]};
    for (std::size_t p = 0; p < n.size(); p += 5) {
      const auto x = n.point(p);
      EXPECT_LE(nrm[0] * (x[0] - a[0]) + nrm[1] * (x[1] - a[1]) + nrm[2] * (x[2] - a[2]), 1e-12) << "facet " << f;
    }
  }
}

TEST(ConvexHull, OneDimensional) {
  const NodeSet n(1, {0.3, -1.0, 2.5, 0.0});
  const auto h = convex_hull(n);
  EXPECT_EQ(h.vertices, (std::vector<int>{1, 2}));
  EXPECT_DOUBLE_EQ(h.measure, 3.5);
  EXPECT_EQ(hull_boundary_nodes(n), (std::vector<int>{1, 2}));
}

}  // namespace
