// Convex domains with named parts (domain.hpp): validation of polygons and polyhedra, measures,
// node sets on them (corners and edges covered, nodes inside and spread), and boundary
// quadrature whose weights give each part's length or area to round-off.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <numbers>
#include <set>

#include "lmeform/domain.hpp"

namespace lmeform {
namespace {

SpacingFunction uniform(double h) {
  return {[h](std::span<const double>) { return h; }, h};
}

double min_distance(const NodeSet& nodes) {
  double m = std::numeric_limits<double>::infinity();
  for (std::size_t a = 0; a < nodes.size(); ++a)
    for (std::size_t b = a + 1; b < nodes.size(); ++b) {
      double d2 = 0;
      for (int i = 0; i < nodes.dim; ++i) d2 += std::pow(nodes.point(a)[std::size_t(i)] - nodes.point(b)[std::size_t(i)], 2);
      m = std::min(m, std::sqrt(d2));
    }
  return m;
}

void expect_error(const std::function<void()>& f, const std::string& fragment) {
  try {
    f();
    ADD_FAILURE() << "no error; expected one containing '" << fragment << "'";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find(fragment), std::string::npos) << e.what();
  }
}

const std::vector<std::array<double, 2>> kTrapezoid{{0, 0}, {4, 0}, {3, 2}, {1, 2}};

TEST(Domain, PolygonMeasuresAndParts) {
  const Domain d = Domain::polygon(kTrapezoid, {"bottom", "right", "top", "left"});
  EXPECT_EQ(d.dim(), 2);
  EXPECT_NEAR(d.measure(), 6.0, 1e-14);
  EXPECT_NEAR(d.part_measure("bottom"), 4.0, 1e-14);
  EXPECT_NEAR(d.part_measure("right"), std::sqrt(5.0), 1e-14);
  EXPECT_NEAR(d.part_measure(""), 6.0 + 2 * std::sqrt(5.0), 1e-13);
  EXPECT_EQ(d.part_names(), (std::vector<std::string>{"bottom", "right", "top", "left"}));
  EXPECT_FALSE(d.has_part("tip"));
  // Outward normals: bottom (0, -1), top (0, 1).
  EXPECT_NEAR(d.faces()[0].normal[1], -1.0, 1e-15);
  EXPECT_NEAR(d.faces()[2].normal[1], 1.0, 1e-15);
  const std::array<double, 2> inside{2, 1}, outside{0.2, 1.9};
  EXPECT_NEAR(d.depth(inside), 1.0, 1e-14);
  EXPECT_FALSE(d.contains(outside, 1e-12));
}

TEST(Domain, AClockwisePolygonKeepsItsPartNamesOnTheirEdges) {
  std::vector<std::array<double, 2>> cw(kTrapezoid.rbegin(), kTrapezoid.rend());  // (1,2) (3,2) (4,0) (0,0)
  const Domain d = Domain::polygon(cw, {"top", "right", "bottom", "left"});
  EXPECT_NEAR(d.part_measure("bottom"), 4.0, 1e-14);
  EXPECT_NEAR(d.part_measure("top"), 2.0, 1e-14);
  for (const int f : d.faces_of("bottom")) EXPECT_NEAR(d.faces()[std::size_t(f)].normal[1], -1.0, 1e-15);
}

TEST(Domain, BadPolygonsAreRefusedWithTheReason) {
  expect_error([] { (void)Domain::polygon({{0, 0}, {1, 0}}); }, "at least 3 vertices");
  expect_error([] { (void)Domain::polygon({{0, 0}, {2, 0}, {1, 0.2}, {2, 2}, {0, 2}}); }, "re-entrant corner");
  expect_error([] { (void)Domain::polygon({{0, 0}, {1, 0}, {2, 0}, {1, 1}}); }, "collinear");
  expect_error([] { (void)Domain::polygon({{0, 0}, {1, 1}, {1, 0}, {0, 1}}); }, "enclose no area");  // a symmetric bow tie
  expect_error([] { (void)Domain::polygon({{0, 0}, {2, 2}, {2, 0}, {0, 1}}); }, "not convex");        // a lopsided one
  expect_error([] { (void)Domain::polygon({{0, 0}, {1, 0}, {1, 0}, {0, 1}}); }, "repeats");
  expect_error([] { (void)Domain::polygon(kTrapezoid, {"a", "b"}); }, "2 part names for 4 faces");
  // A pentagram turns twice around with left turns only.
  std::vector<std::array<double, 2>> star;
  for (int k = 0; k < 5; ++k) star.push_back({std::cos(4 * std::numbers::pi * k / 5), std::sin(4 * std::numbers::pi * k / 5)});
  expect_error([&] { (void)Domain::polygon(star); }, "intersects itself");
}

TEST(Domain, BoxFacesAndAxisymmetricAliases) {
  Box b;
  b.dim = 2;
  b.lo = {0, 0, 0};
  b.hi = {1.5, 2, 0};
  const Domain d = Domain::box(b, true);
  EXPECT_NEAR(d.measure(), 3.0, 1e-14);
  EXPECT_NEAR(d.part_measure("r_max"), 2.0, 1e-14);
  EXPECT_NEAR(d.part_measure("axis"), 2.0, 1e-14);
  EXPECT_NEAR(d.part_measure("z_min"), 1.5, 1e-14);
  EXPECT_NEAR(d.part_measure("x_max"), 2.0, 1e-14);
  EXPECT_TRUE(Domain::box(b).faces_of("r_max").empty());  // aliases only when axisymmetric
}

Domain cube() {
  const std::vector<std::array<double, 3>> v{{0, 0, 0}, {1, 0, 0}, {1, 1, 0}, {0, 1, 0}, {0, 0, 1}, {1, 0, 1}, {1, 1, 1}, {0, 1, 1}};
  return Domain::polyhedron(v, {{0, 1, 2, 3}, {4, 5, 6, 7}, {0, 1, 5, 4}, {1, 2, 6, 5}, {2, 3, 7, 6}, {3, 0, 4, 7}},
                            {"bottom", "top", "front", "right", "back", "left"});
}

TEST(Domain, PolyhedronMeasuresAndErrors) {
  const Domain d = cube();
  EXPECT_NEAR(d.measure(), 1.0, 1e-14);
  EXPECT_NEAR(d.part_measure("top"), 1.0, 1e-14);
  EXPECT_NEAR(d.part_measure(""), 6.0, 1e-13);
  for (const int f : d.faces_of("top")) EXPECT_NEAR(d.faces()[std::size_t(f)].normal[2], 1.0, 1e-15);
  for (const int f : d.faces_of("bottom")) EXPECT_NEAR(d.faces()[std::size_t(f)].normal[2], -1.0, 1e-15);
  std::vector<std::array<double, 3>> v{{0, 0, 0}, {1, 0, 0}, {1, 1, 0.2}, {0, 1, 0}, {0, 0, 1}, {1, 0, 1}, {1, 1, 1}, {0, 1, 1}};
  expect_error([&] { (void)Domain::polyhedron(v, {{0, 1, 2, 3}, {4, 5, 6, 7}, {0, 1, 5, 4}, {1, 2, 6, 5}, {2, 3, 7, 6}, {3, 0, 4, 7}}); },
               "not planar");
  expect_error([] { (void)Domain::polyhedron({{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {0, 0, 1}}, {{0, 1, 2}, {0, 1, 3}, {0, 2, 3}, {0, 1, 2}}); },
               "do not close");
}

TEST(Domain, NodesCoverCornersAndEdgesAndStayInside) {
  const Domain d = Domain::polygon(kTrapezoid, {"bottom", "right", "top", "left"});
  const double h = 0.2;
  const NodeSet nodes = domain_nodes(d, uniform(h));
  for (std::size_t a = 0; a < nodes.size(); ++a) ASSERT_TRUE(d.contains(nodes.point(a), 1e-12));
  std::size_t corners = 0;
  for (const auto& v : d.vertices())
    for (std::size_t a = 0; a < nodes.size(); ++a)
      if (std::hypot(nodes.point(a)[0] - v[0], nodes.point(a)[1] - v[1]) < 1e-12) ++corners;
  EXPECT_EQ(corners, 4u);
  // 4 / 0.2 = 20 segments on the bottom: 21 nodes with its corners.
  EXPECT_EQ(d.nodes_on(nodes, "bottom").size(), 21u);
  EXPECT_GT(min_distance(nodes), 0.45 * h);
  // The area over h² bounds the count within the packing of a Poisson-disk sample.
  EXPECT_GT(double(nodes.size()), 0.6 * d.measure() / (h * h));
  EXPECT_LT(double(nodes.size()), 2.0 * d.measure() / (h * h));
}

TEST(Domain, GradedNodesAreDenserNearTheGradingTarget) {
  const Domain d = Domain::polygon({{0, 0}, {1, 0}, {1, 1}, {0, 1}});
  // Fine (0.02) near x = 0, coarse (0.1) beyond x = 0.4.
  SpacingFunction s{[](std::span<const double> x) { return std::min(0.1, 0.02 + 0.2 * x[0]); }, 0.02};
  const NodeSet nodes = domain_nodes(d, s);
  std::size_t left = 0, right = 0;
  for (std::size_t a = 0; a < nodes.size(); ++a) {
    if (nodes.point(a)[0] < 0.2) ++left;
    if (nodes.point(a)[0] > 0.8) ++right;
  }
  EXPECT_GT(left, 4 * right);
}

TEST(Domain, BoundaryQuadratureGivesEachPartsLength) {
  const Domain d = Domain::polygon(kTrapezoid, {"bottom", "right", "top", ""});
  const NodeSet nodes = domain_nodes(d, uniform(0.3));
  for (const std::string part : {"bottom", "right", "top", ""}) {
    const BoundaryQuadrature q = boundary_quadrature(d, nodes, part, 3);
    double length = 0, x_moment = 0;
    for (std::size_t k = 0; k < q.size(); ++k) {
      length += q.weights[k];
      x_moment += q.weights[k] * q.points[2 * k];
      EXPECT_NEAR(std::hypot(q.normals[2 * k], q.normals[2 * k + 1]), 1.0, 1e-15);
    }
    EXPECT_NEAR(length, d.part_measure(part), 1e-13) << part;
    if (part == "bottom") {
      EXPECT_NEAR(x_moment, 8.0, 1e-12);  // ∫_0^4 x dx
    }
    EXPECT_EQ(q.facet_vertices.size(), 2 * q.facets());
  }
  // The outward normal of "right": (2, 1)/√5.
  const BoundaryQuadrature right = boundary_quadrature(d, nodes, "right", 2);
  EXPECT_NEAR(right.normals[0], 2 / std::sqrt(5.0), 1e-14);
  EXPECT_NEAR(right.normals[1], 1 / std::sqrt(5.0), 1e-14);
  expect_error([&] { (void)boundary_quadrature(d, nodes, "tip", 2); }, "no part 'tip'");
  // Without the corners the edge is not covered.
  expect_error([&] { (void)boundary_quadrature(d, NodeSet(2, {1, 1, 2, 1, 2, 1.5}), "bottom", 2); }, "corners");
}

TEST(Domain, PolyhedronNodesAndFaceQuadrature) {
  const Domain d = cube();
  const NodeSet nodes = domain_nodes(d, uniform(0.25));
  for (std::size_t a = 0; a < nodes.size(); ++a) ASSERT_TRUE(d.contains(nodes.point(a), 1e-12));
  EXPECT_GT(min_distance(nodes), 0.4 * 0.25);
  for (const std::string part : {"top", "left", ""}) {
    const BoundaryQuadrature q = boundary_quadrature(d, nodes, part, 3);
    double area = 0;
    for (const double w : q.weights) area += w;
    EXPECT_NEAR(area, d.part_measure(part), 1e-12) << part;
  }
}

}  // namespace
}  // namespace lmeform

namespace lmeform {
namespace {

/// The spacing h_near within `band` of the sphere |x| = radius, growing by `grading` per unit
/// distance beyond it, up to h_far: the shape of an interface-resolving spacing.
SpacingFunction toward_sphere(double radius, double h_near, double band, double grading, double h_far) {
  return {[=](std::span<const double> x) {
            double r2 = 0;
            for (const double c : x) r2 += c * c;
            const double d = std::abs(std::sqrt(r2) - radius);
            return std::min(h_far, h_near + grading * std::max(0.0, d - band));
          },
          h_near};
}

TEST(NestedGrids, AConstantSpacingGivesTheUniformGrid) {
  const Box box{3, {0, 0, 0}, {1, 0.5, 0.75}};
  const NodeSet nested = nested_grids(box, uniform(0.125));
  const NodeSet grid = uniform_grid(box, 0.125);
  ASSERT_EQ(nested.size(), grid.size());
  for (std::size_t a = 0; a < grid.size(); ++a)
    for (std::size_t i = 0; i < 3; ++i) EXPECT_NEAR(nested.point(a)[i], grid.point(a)[i], 1e-15) << a;
}

TEST(NestedGrids, NodesNearTheInterfaceFormTheFinestGridAndTheFarOnesTheCoarsest) {
  for (const int dim : {2, 3}) {
    const Box box = Box::unit(dim);
    const double fine = 1.0 / 64, coarse = 1.0 / 8;
    const NodeSet nodes = nested_grids(box, toward_sphere(0.5, fine, 0.05, 0.3, coarse));
    // Every node is a vertex of the finest grid, none is repeated, all lie in the box.
    std::set<std::array<long, 3>> seen;
    for (std::size_t a = 0; a < nodes.size(); ++a) {
      std::array<long, 3> index{0, 0, 0};
      for (std::size_t i = 0; i < std::size_t(dim); ++i) {
        const double c = nodes.point(a)[i];
        ASSERT_GE(c, 0.0);
        ASSERT_LE(c, 1.0);
        index[i] = std::lround(c / fine);
        EXPECT_NEAR(c, double(index[i]) * fine, 1e-14);
      }
      EXPECT_TRUE(seen.insert(index).second) << "node " << a << " repeated";
    }
    // Around points of the interface every vertex of the finest grid's cell is a node.
    for (const double angle : {0.1, 0.7, 1.3}) {
      const std::array<double, 3> x{0.5 * std::cos(angle) * (dim == 3 ? std::sqrt(0.5) : 1.0), 0.5 * std::sin(angle),
                                    dim == 3 ? 0.5 * std::cos(angle) * std::sqrt(0.5) : 0.0};
      for (int v = 0; v < (1 << dim); ++v) {
        std::array<long, 3> index{0, 0, 0};
        for (std::size_t i = 0; i < std::size_t(dim); ++i) index[i] = long(std::floor(x[i] / fine)) + ((v >> i) & 1);
        EXPECT_TRUE(seen.count(index)) << "dim " << dim << ": the finest grid's vertex (" << index[0] << ", " << index[1] << ", "
                                       << index[2] << ") next to the interface is missing";
      }
    }
    // At the far corner the next node is the coarsest grid's spacing away.
    double next = std::numeric_limits<double>::infinity();
    for (std::size_t a = 0; a < nodes.size(); ++a) {
      double d2 = 0;
      for (std::size_t i = 0; i < std::size_t(dim); ++i) d2 += std::pow(nodes.point(a)[i] - 1.0, 2);
      if (d2 > 0) next = std::min(next, std::sqrt(d2));
    }
    EXPECT_NEAR(next, coarse, 1e-12) << "dim " << dim;
    // Far fewer nodes than the finest grid, more than the coarsest.
    const double finest_grid = std::pow(65.0, dim), coarsest_grid = std::pow(9.0, dim);
    EXPECT_LT(double(nodes.size()), 0.5 * finest_grid) << "dim " << dim;
    EXPECT_GT(double(nodes.size()), 2 * coarsest_grid) << "dim " << dim;
  }
}

TEST(NestedGrids, AFinerSpacingWithTheSameLevelZeroContainsTheCoarserSet) {
  // A refinement that follows a field: the spacing finer only around one more point. With level 0
  // fixed, the finer set holds every node of the coarser one (without it, level 0 follows the
  // largest sampled h, which a spacing fine over much of the box would lower).
  const Box box = Box::unit(2);
  const double h0 = 0.1, fine = 0.0125;
  const auto near = [=](std::vector<std::array<double, 2>> points) {
    return SpacingFunction{[=](std::span<const double> x) {
                             double h = h0;
                             for (const auto& p : points) h = std::min(h, fine + 0.6 * std::max(0.0, std::hypot(x[0] - p[0], x[1] - p[1]) - 0.02));
                             return h;
                           },
                           fine};
  };
  const NodeSet coarse = nested_grids(box, near({{0.3, 0.3}}), 2'000'000, h0);
  const NodeSet finer = nested_grids(box, near({{0.3, 0.3}, {0.7, 0.6}}), 2'000'000, h0);
  ASSERT_GT(finer.size(), coarse.size());
  std::set<std::pair<long, long>> in_finer;
  for (std::size_t a = 0; a < finer.size(); ++a) in_finer.insert({std::lround(finer.point(a)[0] / fine), std::lround(finer.point(a)[1] / fine)});
  for (std::size_t a = 0; a < coarse.size(); ++a)
    EXPECT_TRUE(in_finer.count({std::lround(coarse.point(a)[0] / fine), std::lround(coarse.point(a)[1] / fine)}))
        << "node (" << coarse.point(a)[0] << ", " << coarse.point(a)[1] << ") of the coarser set is missing";
  EXPECT_THROW((void)nested_grids(box, uniform(0.1), 1000, -1.0), std::invalid_argument);
}

TEST(NestedGrids, BadSpacingsAndBudgetsAreRefused) {
  const Box box = Box::unit(3);
  EXPECT_THROW((void)nested_grids(box, uniform(0.0)), std::invalid_argument);
  EXPECT_THROW((void)nested_grids(box, {[](std::span<const double> x) { return x[0] > 0.5 ? -1.0 : 0.1; }, 0.1}), std::invalid_argument);
  expect_error([&] { (void)nested_grids(box, uniform(0.01), 1000); }, "max_nodes");
  EXPECT_THROW((void)nested_grids(Box::unit(1), uniform(0.1)), std::invalid_argument);
}

}  // namespace
}  // namespace lmeform
