// Delaunay background cells: coverage (total measure = hull measure) for degenerate uniform grids and
// random sets, orientation, conformity, the empty-circumsphere property, errors, point location.
#include <gtest/gtest.h>

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <map>
#include <string>
#include <vector>

#include "lmeform/convex_hull.hpp"
#include "lmeform/delaunay.hpp"
#include "lmeform/node_sets.hpp"

namespace {

using namespace lmeform;

void expect_valid_cells(const BackgroundCells& cells, const NodeSet& nodes) {
  ASSERT_EQ(cells.dim, nodes.dim);
  ASSERT_EQ(cells.vertices_per_cell, nodes.dim + 1);
  ASSERT_EQ(cells.connectivity.size(), cells.size() * static_cast<std::size_t>(cells.vertices_per_cell));
  EXPECT_EQ(cells.dropped_flat_cells, 0U) << "qhull emitted flat cells";
  std::vector<char> used(nodes.size(), 0);
  for (std::size_t c = 0; c < cells.size(); ++c) {
    const double m = simplex_signed_measure(nodes, cells.cell(c));
    ASSERT_GT(m, 0.0) << "cell " << c << " is not positively oriented";
    EXPECT_NEAR(m, cells.measures[c], 1e-14 * m);
    for (int v : cells.cell(c)) used[static_cast<std::size_t>(v)] = 1;
  }
  EXPECT_EQ(std::count(used.begin(), used.end(), 0), 0) << "nodes left out of the triangulation";
}

// Conformity: every facet is shared by at most two cells; returns the facets owned by one cell.
std::vector<std::vector<int>> boundary_facets(const BackgroundCells& cells) {
  std::map<std::vector<int>, int> count;
  for (std::size_t c = 0; c < cells.size(); ++c) {
    const auto v = cells.cell(c);
    for (std::size_t skip = 0; skip < v.size(); ++skip) {
      std::vector<int> f;
      for (std::size_t k = 0; k < v.size(); ++k)
        if (k != skip) f.push_back(v[k]);
      std::sort(f.begin(), f.end());
      ++count[f];
    }
  }
  std::vector<std::vector<int>> out;
  for (const auto& [f, n] : count) {
    EXPECT_LE(n, 2) << "a facet is shared by " << n << " cells";
    if (n == 1) out.push_back(f);
  }
  return out;
}

TEST(Delaunay, UniformGrid2DIsCoveredWithoutFlatCells) {
  const Box box{2, {0.0, -1.0, 0.0}, {2.0, 0.5, 0.0}};
  const auto nodes = uniform_grid(box, std::array<int, 3>{21, 16, 1});
  const auto cells = delaunay(nodes);
  expect_valid_cells(cells, nodes);
  EXPECT_EQ(cells.size(), 2U * 20U * 15U);
  EXPECT_NEAR(cells.total_measure(), 3.0, 3e-14);
  EXPECT_EQ(boundary_facets(cells).size(), 2U * (20U + 15U));
}

TEST(Delaunay, UniformGrid3DIsCoveredWithoutFlatCells) {
  const Box box{3, {0.0, 0.0, 0.0}, {1.0, 2.0, 0.5}};
  const auto nodes = uniform_grid(box, std::array<int, 3>{7, 9, 5});
  const auto cells = delaunay(nodes);
  expect_valid_cells(cells, nodes);
  EXPECT_NEAR(cells.total_measure(), 1.0, 1e-13);
  // Each square face of the box is split into two triangles.
  EXPECT_EQ(boundary_facets(cells).size(), 2U * 2U * (6U * 8U + 8U * 4U + 6U * 4U));
}

TEST(Delaunay, RandomSetsCoverTheirHull) {
  for (int d = 2; d <= 3; ++d) {
    SCOPED_TRACE("dim " + std::to_string(d));
    const auto nodes = random_points(Box::unit(d), d == 2 ? 400 : 300, 17U + static_cast<unsigned>(d));
    const auto cells = delaunay(nodes);
    expect_valid_cells(cells, nodes);
    const auto hull = convex_hull(nodes);
    EXPECT_NEAR(cells.total_measure(), hull.measure, 1e-13 * hull.measure);
    EXPECT_EQ(boundary_facets(cells).size(), hull.facet_count());
  }
}

TEST(Delaunay, AllNodesCosphericalIsOneMergedCell) {
  // Nodes on a sphere form one merged Delaunay cell with many vertices (the qhull-faces branch).
  std::vector<double> s;
  const int n = 60;
  for (int i = 0; i < n; ++i) {
    const double z = -1 + 2.0 * (i + 0.5) / n, r = std::sqrt(1 - z * z), phi = 2.399963 * i;
    s.insert(s.end(), {r * std::cos(phi), r * std::sin(phi), z});
  }
  const NodeSet nodes(3, s);
  const auto cells = delaunay(nodes);
  expect_valid_cells(cells, nodes);
  const auto hull = convex_hull(nodes);
  EXPECT_NEAR(cells.total_measure(), hull.measure, 1e-13 * hull.measure);
  EXPECT_EQ(boundary_facets(cells).size(), hull.facet_count());
}

TEST(Delaunay, GradedSetIsCovered) {
  const auto nodes = graded_grid_2d();
  const auto cells = delaunay(nodes);
  expect_valid_cells(cells, nodes);
  EXPECT_NEAR(cells.total_measure(), 1.0, 1e-12);
}

// Empty circumsphere: no node strictly inside the circumsphere of any cell (relative slack 1e-9).
void expect_empty_circumspheres(const BackgroundCells& cells, const NodeSet& nodes) {
  const int d = nodes.dim;
  for (std::size_t c = 0; c < cells.size(); ++c) {
    const auto v = cells.cell(c);
    Eigen::MatrixXd A(d, d);
    Eigen::VectorXd b(d);
    const auto x0 = nodes.point(static_cast<std::size_t>(v[0]));
    for (int k = 0; k < d; ++k) {
      const auto xk = nodes.point(static_cast<std::size_t>(v[static_cast<std::size_t>(k) + 1]));
      double s = 0;
      for (int i = 0; i < d; ++i) {
        A(k, i) = 2 * (xk[static_cast<std::size_t>(i)] - x0[static_cast<std::size_t>(i)]);
        s += xk[static_cast<std::size_t>(i)] * xk[static_cast<std::size_t>(i)] - x0[static_cast<std::size_t>(i)] * x0[static_cast<std::size_t>(i)];
      }
      b(k) = s;
    }
    const Eigen::VectorXd centre = A.partialPivLu().solve(b);
    auto dist2 = [&](std::span<const double> x) {
      double s = 0;
      for (int i = 0; i < d; ++i) s += (x[static_cast<std::size_t>(i)] - centre(i)) * (x[static_cast<std::size_t>(i)] - centre(i));
      return s;
    };
    const double r2 = dist2(x0);
    for (std::size_t a = 0; a < nodes.size(); ++a) {
      if (std::find(v.begin(), v.end(), static_cast<int>(a)) != v.end()) continue;
      ASSERT_GE(dist2(nodes.point(a)), r2 * (1 - 1e-9)) << "node " << a << " inside the circumsphere of cell " << c;
    }
  }
}

TEST(Delaunay, EmptyCircumsphere) {
  for (int d = 2; d <= 3; ++d) {
    SCOPED_TRACE("dim " + std::to_string(d));
    const auto nodes = random_points(Box::unit(d), 60, 5U + static_cast<unsigned>(d));
    expect_empty_circumspheres(delaunay(nodes), nodes);
  }
}

TEST(Delaunay, OneDimensionalSegments) {
  const NodeSet nodes(1, {0.5, 0.0, 2.0, 1.0});
  const auto cells = delaunay(nodes);
  EXPECT_EQ(cells.connectivity, (std::vector<int>{1, 0, 0, 3, 3, 2}));
  EXPECT_DOUBLE_EQ(cells.total_measure(), 2.0);
}

template <class E>
void expect_error(auto&& f, const std::string& needle) {
  try {
    f();
    FAIL() << "expected an error containing '" << needle << "'";
  } catch (const E& e) {
    EXPECT_NE(std::string(e.what()).find(needle), std::string::npos) << e.what();
  }
}

TEST(Delaunay, DegenerateInputErrorsClearly) {
  expect_error<std::invalid_argument>([] { (void)delaunay(NodeSet(2, {0, 0, 1, 1})); }, "too few");
  expect_error<std::invalid_argument>([] { (void)delaunay(NodeSet(3, {0, 0, 0, 1, 0, 0, 0, 1, 0})); }, "too few");
  std::vector<double> line;
  for (int i = 0; i < 10; ++i) {
    line.push_back(0.1 * i);
    line.push_back(1.0 + 0.2 * i);
  }
  expect_error<std::invalid_argument>([&] { (void)delaunay(NodeSet(2, line)); }, "collinear");
  std::vector<double> plane;
  for (int i = 0; i < 4; ++i)
    for (int j = 0; j < 4; ++j) {
      plane.push_back(i);
      plane.push_back(j);
      plane.push_back(0.5 * i - 0.25 * j);
    }
  expect_error<std::invalid_argument>([&] { (void)delaunay(NodeSet(3, plane)); }, "coplanar");
  // A duplicate node is no vertex of any cell.
  auto dup = random_points(Box::unit(2), 20, 1);
  dup.coords.push_back(dup.coords[6]);
  dup.coords.push_back(dup.coords[7]);
  expect_error<std::invalid_argument>([&] { (void)delaunay(dup); }, "vertices of no cell");
  DelaunayOptions lenient;
  lenient.allow_unused_nodes = true;
  EXPECT_NO_THROW((void)delaunay(dup, lenient));
}

TEST(Delaunay, PointLocationAgreesWithBruteForce) {
  for (int d = 2; d <= 3; ++d) {
    SCOPED_TRACE("dim " + std::to_string(d));
    const auto nodes = random_points(Box::unit(d), 200, 9U + static_cast<unsigned>(d));
    const auto cells = delaunay(nodes);
    const CellLocator locator(cells, nodes);
    const auto queries = random_points(Box{d, {-0.2, -0.2, -0.2}, {1.2, 1.2, 1.2}}, 400, 99);
    int inside = 0;
    for (std::size_t q = 0; q < queries.size(); ++q) {
      const auto x = queries.point(q);
      const long fast = locator.locate(x);
      const long slow = locate_cell_brute_force(cells, nodes, x);
      ASSERT_EQ(fast < 0, slow < 0) << "query " << q;
      if (fast >= 0) {
        ++inside;
        const auto l = barycentric(cells, nodes, static_cast<std::size_t>(fast), x);
        for (int k = 0; k <= d; ++k) EXPECT_GE(l[static_cast<std::size_t>(k)], -1e-12);
      }
    }
    EXPECT_GT(inside, 100);
    // Cell vertices and centroids are found.
    for (std::size_t c = 0; c < cells.size(); c += 7) {
      std::array<double, 3> g{};
      for (int v : cells.cell(c))
        for (int i = 0; i < d; ++i) g[static_cast<std::size_t>(i)] += nodes.point(static_cast<std::size_t>(v))[static_cast<std::size_t>(i)] / (d + 1);
      EXPECT_EQ(locator.locate(std::span<const double>(g.data(), static_cast<std::size_t>(d))), static_cast<long>(c));
    }
  }
}

}  // namespace
