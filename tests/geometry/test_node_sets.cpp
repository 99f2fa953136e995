// Node-set factories: uniform grids, point files (round trip and file:line errors), the graded set,
// deterministic jitter.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include "lmeform/node_sets.hpp"

namespace {

using namespace lmeform;
namespace fs = std::filesystem;

fs::path temp_file(const std::string& name, const std::string& content) {
  const fs::path p = fs::path(LMEFORM_TEST_TMPDIR) / name;
  std::ofstream(p) << content;
  return p;
}

TEST(NodeSets, UniformGridCountsAndBounds) {
  const Box box{3, {-1.0, 0.0, 2.0}, {1.0, 0.3, 3.0}};
  const auto g = uniform_grid(box, std::array<int, 3>{5, 4, 3});
  ASSERT_EQ(g.dim, 3);
  ASSERT_EQ(g.size(), 60U);
  for (std::size_t i = 0; i < 3; ++i) {
    double lo = 1e300, hi = -1e300;
    for (std::size_t a = 0; a < g.size(); ++a) {
      lo = std::min(lo, g.point(a)[i]);
      hi = std::max(hi, g.point(a)[i]);
    }
    EXPECT_EQ(lo, box.lo[i]);
    EXPECT_EQ(hi, box.hi[i]);
  }
  // x varies fastest.
  EXPECT_DOUBLE_EQ(g.point(1)[0], -0.5);
  EXPECT_DOUBLE_EQ(g.point(5)[1], 0.1);

  EXPECT_EQ(uniform_grid(Box::unit(2), 0.1).size(), 121U);
  EXPECT_EQ(uniform_grid(Box{2, {0, 0, 0}, {2.0, 1.0, 0}}, 0.25).size(), 9U * 5U);
  EXPECT_EQ(uniform_grid(Box::unit(1), 0.2).size(), 6U);
  EXPECT_THROW((void)uniform_grid(Box::unit(2), std::array<int, 3>{1, 4, 0}), std::invalid_argument);
  EXPECT_THROW((void)uniform_grid(Box{2, {0, 0, 0}, {0, 1, 0}}, 0.1), std::invalid_argument);
  EXPECT_THROW((void)uniform_grid(Box::unit(2), -1.0), std::invalid_argument);
}

TEST(NodeSets, PointFilesRoundTrip) {
  const auto g = random_points(Box{3, {-1, -2, -3}, {1e-3, 2e5, 3}}, 50, 4);
  const fs::path p = fs::path(LMEFORM_TEST_TMPDIR) / "roundtrip.csv";
  write_points(p, g);
  const auto back = read_points(p);
  EXPECT_EQ(back.dim, 3);
  EXPECT_EQ(back.coords, g.coords);  // bit-exact with 17 significant digits

  const auto mixed = read_points(temp_file("mixed.txt", "# x y\n\n1 2\n 3.5,\t-4e-3 \r\n+5;6\n"));
  EXPECT_EQ(mixed.dim, 2);
  EXPECT_EQ(mixed.coords, (std::vector<double>{1, 2, 3.5, -4e-3, 5, 6}));
  EXPECT_EQ(read_points(temp_file("one.txt", "1 2 3\n"), 3).size(), 1U);
}

void expect_file_error(const std::string& name, const std::string& content, int dim, const std::string& needle) {
  const auto p = temp_file(name, content);
  try {
    (void)read_points(p, dim);
    FAIL() << "expected an error for " << name;
  } catch (const std::runtime_error& e) {
    const std::string what = e.what();
    EXPECT_NE(what.find(p.string() + needle), std::string::npos) << what;
  }
}

TEST(NodeSets, MalformedFilesNameFileAndLine) {
  expect_file_error("bad_number.csv", "0,0\n1,1\n1.0,abc\n", 0, ":3: cannot read 'abc' as a number");
  expect_file_error("bad_count.csv", "0,0\n# comment\n1,2,3\n", 0, ":3: expected 2 coordinates, found 3");
  expect_file_error("bad_dim.csv", "0,0\n", 3, ":1: expected 3 coordinates, found 2");
  expect_file_error("empty_field.csv", "0,,1\n", 0, ":1: empty field");
  expect_file_error("trailing.csv", "0,1,\n", 0, ":1: trailing separator");
  expect_file_error("nan.csv", "0 1\nnan 2\n", 0, ":2: non-finite");
  expect_file_error("four.csv", "1 2 3 4\n", 0, ":1: expected 1 to 3 coordinates, found 4");
  EXPECT_THROW((void)read_points(fs::path(LMEFORM_TEST_TMPDIR) / "does-not-exist.csv"), std::runtime_error);
  EXPECT_THROW((void)read_points(temp_file("blank.csv", "# nothing\n\n")), std::runtime_error);
}

std::vector<double> nearest_distances(const NodeSet& n) {
  std::vector<double> out(n.size(), 1e300);
  for (std::size_t a = 0; a < n.size(); ++a)
    for (std::size_t b = a + 1; b < n.size(); ++b) {
      const double d = std::hypot(n.point(a)[0] - n.point(b)[0], n.point(a)[1] - n.point(b)[1]);
      out[a] = std::min(out[a], d);
      out[b] = std::min(out[b], d);
    }
  return out;
}

TEST(NodeSets, GradedSetIsStronglyGraded) {
  const GradedGridOptions opt;
  const auto g = graded_grid_2d(opt);
  ASSERT_EQ(g.dim, 2);
  EXPECT_GT(g.size(), 500U);
  EXPECT_LT(g.size(), 20000U);
  for (std::size_t a = 0; a < g.size(); ++a) {
    const auto x = g.point(a);
    ASSERT_TRUE(x[0] >= 0 && x[0] <= 1 && x[1] >= 0 && x[1] <= 1) << "node " << a << " outside the box";
  }
  for (const auto& c : std::vector<std::array<double, 2>>{{0, 0}, {1, 0}, {1, 1}, {0, 1}}) {
    int found = 0;
    for (std::size_t a = 0; a < g.size(); ++a) found += g.point(a)[0] == c[0] && g.point(a)[1] == c[1];
    EXPECT_EQ(found, 1) << "corner (" << c[0] << ", " << c[1] << ")";
  }
  const auto nn = nearest_distances(g);
  const auto [mn, mx] = std::minmax_element(nn.begin(), nn.end());
  EXPECT_GT(*mn, 0.5 * opt.h_min) << "duplicate or too close nodes";
  EXPECT_GE(*mx / *mn, 10.0) << "spacing ratio " << *mx / *mn;
  // Robust version of the ratio, immune to a few outliers: 95th over 5th percentile.
  auto sorted = nn;
  std::sort(sorted.begin(), sorted.end());
  EXPECT_GE(sorted[sorted.size() * 95 / 100] / sorted[sorted.size() * 5 / 100], 5.0);
  // The spacing follows the target: no node is much closer to its neighbour than the local target, and
  // the set has no holes: every point of the box is within about twice the local target of a node.
  for (std::size_t a = 0; a < g.size(); ++a) EXPECT_GT(nn[a], 0.49 * graded_spacing(opt, g.point(a)[0], g.point(a)[1]));
  for (int i = 0; i <= 40; ++i)
    for (int j = 0; j <= 40; ++j) {
      const double x = i / 40.0, y = j / 40.0;
      double best = 1e300;
      for (std::size_t a = 0; a < g.size(); ++a) best = std::min(best, std::hypot(g.point(a)[0] - x, g.point(a)[1] - y));
      EXPECT_LT(best, 1.5 * graded_spacing(opt, x, y)) << "hole at (" << x << ", " << y << ")";
    }
  // Deterministic.
  EXPECT_EQ(graded_grid_2d(opt).coords, g.coords);
  GradedGridOptions other = opt;
  other.seed = 2;
  EXPECT_NE(graded_grid_2d(other).coords, g.coords);
}

TEST(NodeSets, JitterMovesOnlyInteriorNodesDeterministically) {
  const Box box{2, {0.0, 0.0, 0.0}, {2.0, 1.0, 0.0}};
  const auto g = uniform_grid(box, std::array<int, 3>{9, 5, 1});
  const auto j = jitter_interior(g, box, 0.05, 42);
  ASSERT_EQ(j.size(), g.size());
  int moved = 0;
  for (std::size_t a = 0; a < g.size(); ++a) {
    const auto x = g.point(a), y = j.point(a);
    const bool on_face = x[0] == 0 || x[0] == 2 || x[1] == 0 || x[1] == 1;
    if (on_face) {
      EXPECT_EQ(x[0], y[0]);
      EXPECT_EQ(x[1], y[1]);
    } else {
      moved += x[0] != y[0] || x[1] != y[1];
      EXPECT_LE(std::abs(x[0] - y[0]), 0.05);
      EXPECT_LE(std::abs(x[1] - y[1]), 0.05);
      EXPECT_TRUE(y[0] > 0 && y[0] < 2 && y[1] > 0 && y[1] < 1);
    }
  }
  EXPECT_EQ(moved, 7 * 3);
  EXPECT_EQ(jitter_interior(g, box, 0.05, 42).coords, j.coords);
  EXPECT_NE(jitter_interior(g, box, 0.05, 43).coords, j.coords);
  EXPECT_THROW((void)jitter_interior(g, Box::unit(3), 0.05, 1), std::invalid_argument);
}

}  // namespace
