// The topology of {f = 0} from analytic fields sampled at nodes: circles in the plane, spheres and
// tori as surfaces of revolution (meridians in the half-plane r >= 0) and in space, on uniform and
// jittered Delaunay cells, and level sets passing exactly through nodes.
#include <gtest/gtest.h>

#include <cmath>
#include <functional>
#include <random>

#include "lmeform/delaunay.hpp"
#include "lmeform/level_set_topology.hpp"

namespace lmeform {
namespace {

using Field = std::function<double(const double*)>;

/// A grid of n points per axis over [lo, hi]^dim (per axis), moved by up to `jitter` of the spacing
/// (boundary nodes only along their side, so the box stays the hull).
NodeSet grid(int dim, std::array<double, 3> lo, std::array<double, 3> hi, int n, double jitter = 0, unsigned seed = 7) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> u(-jitter, jitter);
  std::vector<double> coords;
  const int total = dim == 2 ? n * n : n * n * n;
  for (int id = 0; id < total; ++id) {
    int rest = id;
    for (int i = 0; i < dim; ++i) {
      const int k = rest % n;
      rest /= n;
      const double h = (hi[std::size_t(i)] - lo[std::size_t(i)]) / (n - 1);
      const bool boundary = k == 0 || k == n - 1;
      coords.push_back(lo[std::size_t(i)] + k * h + (boundary ? 0.0 : u(rng) * h));
    }
  }
  return NodeSet(dim, coords);
}

LevelSetTopology topology_of(const NodeSet& nodes, const Field& f, LevelSetGeometry g) {
  const BackgroundCells cells = delaunay(nodes);
  std::vector<double> values(nodes.size());
  for (std::size_t a = 0; a < nodes.size(); ++a) values[a] = f(nodes.point(a).data());
  return level_set_topology(nodes, cells, values, g);
}

std::vector<int> genera(const LevelSetTopology& t) {
  std::vector<int> g;
  for (const auto& c : t.components) g.push_back(c.genus);
  std::sort(g.begin(), g.end());
  return g;
}

double sphere(const double* x, double cx, double cy, double cz, double radius, int dim) {
  const double d2 = (x[0] - cx) * (x[0] - cx) + (x[1] - cy) * (x[1] - cy) + (dim == 3 ? (x[2] - cz) * (x[2] - cz) : 0.0);
  return radius - std::sqrt(d2);
}

// ---- planar curves ----

TEST(LevelSetTopology, PlanarCircleTwoCirclesAnnulusAndAnOpenCurve) {
  const NodeSet nodes = grid(2, {-1, -1, 0}, {1, 1, 0}, 41);
  const auto g = LevelSetGeometry::planar;
  const LevelSetTopology circle = topology_of(nodes, [](const double* x) { return sphere(x, 0, 0, 0, 0.5, 2); }, g);
  ASSERT_EQ(circle.components.size(), 1u);
  EXPECT_TRUE(circle.components[0].closed);
  EXPECT_EQ(circle.components[0].euler_characteristic, 0);
  EXPECT_EQ(circle.components[0].genus, -1);
  EXPECT_NEAR(circle.components[0].hi[0], 0.5, 1e-12);  // the crossing on the grid line y = 0 is exact
  EXPECT_EQ(circle.describe(), "1 closed curve");

  const LevelSetTopology two = topology_of(
      nodes, [](const double* x) { return std::max(sphere(x, -0.5, 0, 0, 0.3, 2), sphere(x, 0.5, 0, 0, 0.3, 2)); }, g);
  EXPECT_EQ(two.components.size(), 2u);
  EXPECT_EQ(two.describe(), "2 closed curves");
  EXPECT_FALSE(two.same_as(circle));

  // An annulus has two boundary curves: the same topology as two circles in the plane.
  const LevelSetTopology annulus = topology_of(nodes, [](const double* x) { return 0.15 - std::abs(std::hypot(x[0], x[1]) - 0.5); }, g);
  EXPECT_EQ(annulus.components.size(), 2u);
  EXPECT_TRUE(annulus.same_as(two));

  // A circle cut by the boundary is an open curve (an arc, Euler characteristic 1).
  const LevelSetTopology open = topology_of(nodes, [](const double* x) { return sphere(x, 1, 0, 0, 0.5, 2); }, g);
  ASSERT_EQ(open.components.size(), 1u);
  EXPECT_FALSE(open.components[0].closed);
  EXPECT_EQ(open.components[0].euler_characteristic, 1);
  EXPECT_EQ(open.describe(), "1 open curve (reaching the boundary)");

  EXPECT_EQ(topology_of(nodes, [](const double*) { return -1.0; }, g).describe(), "no interface (the field has one sign)");
}

// ---- surfaces of revolution: meridians in r >= 0 ----

TEST(LevelSetTopology, AxisymmetricSphereTorusAndTwoSpheres) {
  for (const double jitter : {0.0, 0.3}) {
    SCOPED_TRACE("jitter " + std::to_string(jitter));
    const NodeSet nodes = grid(2, {0, -1, 0}, {1, 1, 0}, 41, jitter);
    const auto g = LevelSetGeometry::axisymmetric;
    const LevelSetTopology s = topology_of(nodes, [](const double* x) { return sphere(x, 0, 0.1, 0, 0.6, 2); }, g);
    ASSERT_EQ(s.components.size(), 1u);
    EXPECT_TRUE(s.components[0].closed);
    EXPECT_EQ(s.components[0].genus, 0);
    EXPECT_EQ(s.components[0].euler_characteristic, 1);  // the meridian is an arc from the axis to the axis
    EXPECT_EQ(s.describe(), "1 component, genus 0 (a sphere)");

    // A torus: the meridian is a circle of radius 0.2 about (r, z) = (0.5, 0), off the axis.
    const LevelSetTopology t = topology_of(nodes, [](const double* x) { return 0.2 - std::hypot(x[0] - 0.5, x[1]); }, g);
    ASSERT_EQ(t.components.size(), 1u);
    EXPECT_TRUE(t.components[0].closed);
    EXPECT_EQ(t.components[0].genus, 1);
    EXPECT_EQ(t.describe(), "1 component, genus 1 (a torus)");
    EXPECT_FALSE(t.same_as(s));

    const LevelSetTopology two = topology_of(
        nodes, [](const double* x) { return std::max(sphere(x, 0, -0.5, 0, 0.3, 2), sphere(x, 0, 0.5, 0, 0.3, 2)); }, g);
    EXPECT_EQ(genera(two), (std::vector<int>{0, 0}));
    EXPECT_EQ(two.describe(), "2 components, genus 0, 0 (2 spheres)");
    EXPECT_FALSE(two.same_as(s));

    // A sphere and a torus around it.
    const LevelSetTopology both = topology_of(
        nodes, [](const double* x) { return std::max(sphere(x, 0, 0, 0, 0.25, 2), 0.15 - std::hypot(x[0] - 0.65, x[1])); }, g);
    EXPECT_EQ(genera(both), (std::vector<int>{0, 1}));
    EXPECT_EQ(both.describe(), "2 components, genus 0, 1 (a sphere and a torus)");

    // A sphere cut by the side z = 1 is open: its meridian runs from the axis to that side.
    const LevelSetTopology open = topology_of(nodes, [](const double* x) { return sphere(x, 0, 0.8, 0, 0.5, 2); }, g);
    ASSERT_EQ(open.components.size(), 1u);
    EXPECT_FALSE(open.components[0].closed);
    EXPECT_EQ(open.components[0].genus, -1);
  }
}

TEST(LevelSetTopology, LevelSetThroughNodesIsStillOneSphere) {
  // Spacing 0.05: the circle of radius 0.5 passes exactly through the nodes (0.5, 0), (0.3, 0.4),
  // (0.4, 0.3), (0, 0.5), ... A zero counts as positive, consistently, so the curve is still one arc.
  const NodeSet nodes = grid(2, {0, -1, 0}, {1, 1, 0}, 41);
  const auto on_circle = [](const double* x) { return 0.25 - (x[0] * x[0] + x[1] * x[1]); };
  std::size_t zeros = 0;
  for (std::size_t a = 0; a < nodes.size(); ++a) zeros += on_circle(nodes.point(a).data()) == 0.0 ? 1 : 0;
  ASSERT_GE(zeros, 4u);
  const LevelSetTopology s = topology_of(nodes, on_circle, LevelSetGeometry::axisymmetric);
  EXPECT_EQ(s.describe(), "1 component, genus 0 (a sphere)");
  // The same with the signs flipped (the zeros now on the other side of the level).
  const LevelSetTopology flipped = topology_of(nodes, [&](const double* x) { return -on_circle(x); }, LevelSetGeometry::axisymmetric);
  ASSERT_EQ(flipped.components.size(), 1u);
  EXPECT_EQ(flipped.components[0].genus, 0);
}

// ---- surfaces in space: marching tetrahedra, genus from V - E + F ----

TEST(LevelSetTopology, SpatialSphereTorusTwoSpheresAndAnOpenPlane) {
  for (const double jitter : {0.0, 0.3}) {
    SCOPED_TRACE("jitter " + std::to_string(jitter));
    const NodeSet nodes = grid(3, {-1, -1, -1}, {1, 1, 1}, 17, jitter);
    const auto g = LevelSetGeometry::spatial;
    const LevelSetTopology s = topology_of(nodes, [](const double* x) { return sphere(x, 0.05, 0, 0, 0.6, 3); }, g);
    ASSERT_EQ(s.components.size(), 1u);
    EXPECT_TRUE(s.components[0].closed);
    EXPECT_EQ(s.components[0].euler_characteristic, 2);
    EXPECT_EQ(s.describe(), "1 component, genus 0 (a sphere)");

    const LevelSetTopology t = topology_of(
        nodes, [](const double* x) { return 0.25 - std::hypot(std::hypot(x[0], x[1]) - 0.6, x[2]); }, g);
    ASSERT_EQ(t.components.size(), 1u);
    EXPECT_EQ(t.components[0].euler_characteristic, 0);
    EXPECT_EQ(t.describe(), "1 component, genus 1 (a torus)");

    const LevelSetTopology two = topology_of(
        nodes, [](const double* x) { return std::max(sphere(x, -0.5, 0, 0, 0.35, 3), sphere(x, 0.5, 0, 0, 0.35, 3)); }, g);
    EXPECT_EQ(genera(two), (std::vector<int>{0, 0}));
    EXPECT_TRUE(two.components[0].hi[0] < 0 && two.components[1].lo[0] > 0);  // ordered by position

    // A hollow ball (a shell) has two boundary spheres.
    const LevelSetTopology shell = topology_of(nodes, [](const double* x) { return 0.2 - std::abs(std::hypot(x[0], x[1], x[2]) - 0.55); }, g);
    EXPECT_EQ(genera(shell), (std::vector<int>{0, 0}));

    const LevelSetTopology plane = topology_of(nodes, [](const double* x) { return x[2] - 0.03; }, g);
    ASSERT_EQ(plane.components.size(), 1u);
    EXPECT_FALSE(plane.components[0].closed);
    EXPECT_EQ(plane.components[0].euler_characteristic, 1);  // a disc
  }
}

TEST(LevelSetTopology, SpatialGenusTwo) {
  // Two tori side by side, overlapping in a bridge: a surface with two handles.
  const NodeSet nodes = grid(3, {-1.5, -1, -1}, {1.5, 1, 1}, 31);
  auto torus = [](const double* x, double cx) { return 0.25 - std::hypot(std::hypot(x[0] - cx, x[1]) - 0.55, x[2]); };
  const LevelSetTopology t = topology_of(nodes, [&](const double* x) { return std::max(torus(x, -0.65), torus(x, 0.65)); },
                                         LevelSetGeometry::spatial);
  ASSERT_EQ(t.components.size(), 1u);
  EXPECT_EQ(t.components[0].genus, 2);
  EXPECT_EQ(t.describe(), "1 component, genus 2 (a genus-2 surface)");
}

TEST(LevelSetTopology, RefusesMismatchedInput) {
  const NodeSet nodes = grid(2, {0, 0, 0}, {1, 1, 0}, 5);
  const BackgroundCells cells = delaunay(nodes);
  const std::vector<double> few(3, 1.0);
  EXPECT_THROW((void)level_set_topology(nodes, cells, few, LevelSetGeometry::planar), std::invalid_argument);
  const std::vector<double> values(nodes.size(), 1.0);
  EXPECT_THROW((void)level_set_topology(nodes, cells, values, LevelSetGeometry::spatial), std::invalid_argument);
  std::vector<double> nan = values;
  nan[3] = std::nan("");
  EXPECT_THROW((void)level_set_topology(nodes, cells, nan, LevelSetGeometry::planar), std::invalid_argument);
}

}  // namespace
}  // namespace lmeform
