#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <numeric>
#include <vector>

#include "lme_test_util.hpp"
#include "lmeform/neighbour_search.hpp"

namespace lmeform {
namespace {

double dist(const NodeSet& s, std::size_t a, std::span<const double> x) {
  double d2 = 0.0;
  for (int i = 0; i < s.dim; ++i) d2 += (s.point(a)[static_cast<std::size_t>(i)] - x[static_cast<std::size_t>(i)]) *
                                         (s.point(a)[static_cast<std::size_t>(i)] - x[static_cast<std::size_t>(i)]);
  return std::sqrt(d2);
}

class KdTreeDims : public ::testing::TestWithParam<int> {};

TEST_P(KdTreeDims, RadiusSearchMatchesBruteForce) {
  const int dim = GetParam();
  const NodeSet nodes(dim, test::random_points(dim, 700, 0.0, 1.0, 11u + static_cast<unsigned>(dim)));
  const KdTree tree(nodes);
  const auto queries = test::random_points(dim, 40, -0.1, 1.1, 5);
  for (std::size_t q = 0; q < 40; ++q) {
    const std::span<const double> x(queries.data() + q * static_cast<std::size_t>(dim), static_cast<std::size_t>(dim));
    for (const double r : {0.0, 0.05, 0.17, 0.4}) {
      std::vector<int> expect;
      for (std::size_t a = 0; a < nodes.size(); ++a)
        if (dist(nodes, a, x) <= r) expect.push_back(static_cast<int>(a));
      EXPECT_EQ(tree.radius_search(x, r), expect) << "dim " << dim << " r " << r;
    }
  }
}

TEST_P(KdTreeDims, KnnMatchesBruteForce) {
  const int dim = GetParam();
  const NodeSet nodes(dim, test::random_points(dim, 500, 0.0, 1.0, 21u + static_cast<unsigned>(dim)));
  const KdTree tree(nodes);
  const auto queries = test::random_points(dim, 30, 0.0, 1.0, 9);
  std::vector<int> got;
  std::vector<double> gd;
  for (std::size_t q = 0; q < 30; ++q) {
    const std::span<const double> x(queries.data() + q * static_cast<std::size_t>(dim), static_cast<std::size_t>(dim));
    std::vector<int> order(nodes.size());
    std::iota(order.begin(), order.end(), 0);
    std::sort(order.begin(), order.end(), [&](int u, int v) {
      const double du = dist(nodes, static_cast<std::size_t>(u), x), dv = dist(nodes, static_cast<std::size_t>(v), x);
      return du != dv ? du < dv : u < v;
    });
    for (const int k : {1, 4, 13}) {
      tree.knn(x, k, got, &gd);
      ASSERT_EQ(got.size(), static_cast<std::size_t>(k));
      for (int j = 0; j < k; ++j) {
        EXPECT_EQ(got[static_cast<std::size_t>(j)], order[static_cast<std::size_t>(j)]);
        EXPECT_NEAR(gd[static_cast<std::size_t>(j)], dist(nodes, static_cast<std::size_t>(order[static_cast<std::size_t>(j)]), x), 1e-14);
      }
    }
  }
}

INSTANTIATE_TEST_SUITE_P(Dims, KdTreeDims, ::testing::Values(1, 2, 3));

TEST(KdTree, RadiusIsInclusiveAndSquaredInternally) {
  // Grid step 0.25: the 4 axis neighbours of the centre sit exactly at r = 0.25. A radius passed
  // unsquared to nanoflann (0.25 treated as r^2 = 0.25, i.e. r = 0.5) would also return diagonals.
  const NodeSet nodes = test::grid(2, 5, 1.0);
  const KdTree tree(nodes);
  const std::vector<double> x = {0.5, 0.5};
  const auto hits = tree.radius_search(x, 0.25);
  EXPECT_EQ(hits.size(), 5u);
  EXPECT_EQ(tree.radius_search(x, 0.2499999).size(), 1u);
}

TEST(KdTree, KnnMoreThanSizeReturnsAll) {
  const NodeSet nodes(1, {0.0, 1.0, 3.0});
  const KdTree tree(nodes);
  std::vector<int> got;
  tree.knn(std::vector<double>{2.9}, 10, got);
  EXPECT_EQ(got, (std::vector<int>{2, 1, 0}));
}

TEST(NodalSpacing, RegularGridGivesStep) {
  for (int dim = 1; dim <= 3; ++dim) {
    const NodeSet nodes = test::grid(dim, 6, 1.0);
    const KdTree tree(nodes);
    const auto h = nodal_spacing(tree);
    // Interior nodes have 2*dim axis neighbours at the step; boundary nodes average in diagonals.
    for (std::size_t a = 0; a < nodes.size(); ++a) {
      bool interior = true;
      for (const double v : nodes.point(a)) interior = interior && v > 1e-12 && v < 1.0 - 1e-12;
      if (interior) {
        EXPECT_NEAR(h[a], 0.2, 1e-14) << "dim " << dim << " node " << a;
      }
      EXPECT_GE(h[a], 0.2 - 1e-14);
    }
  }
  const NodeSet line(1, {0.0, 1.0, 1.5, 4.0});
  const auto h = nodal_spacing(KdTree(line), 1);
  EXPECT_DOUBLE_EQ(h[0], 1.0);
  EXPECT_DOUBLE_EQ(h[1], 0.5);
  EXPECT_DOUBLE_EQ(h[3], 2.5);
  EXPECT_THROW((void)nodal_spacing(KdTree(NodeSet(1, {0.0, 0.0, 1.0})), 1), std::invalid_argument);
}

TEST(SupportRadius, CutoffOnGaussianFactor) {
  const double beta = 4.0 / (0.1 * 0.1);
  const double r = support_radius(beta, 1e-6);
  EXPECT_NEAR(std::exp(-beta * r * r), 1e-6, 1e-18);
  EXPECT_THROW((void)support_radius(0.0, 1e-6), std::invalid_argument);
  EXPECT_THROW((void)support_radius(1.0, 1.0), std::invalid_argument);
}

TEST(PrimalLists, PerNodeRadiiMatchBruteForce) {
  const NodeSet nodes(2, test::random_points(2, 400, 0.0, 1.0, 4));
  const KdTree tree(nodes);
  std::vector<double> radii(nodes.size());
  for (std::size_t a = 0; a < radii.size(); ++a) radii[a] = 0.03 + 0.12 * nodes.point(a)[0];
  const auto pts = test::random_points(2, 60, 0.0, 1.0, 8);
  const CsrLists lists = primal_lists(tree, pts, radii);
  ASSERT_EQ(lists.size(), 60u);
  lists.validate();
  for (std::size_t q = 0; q < 60; ++q) {
    const std::span<const double> x(pts.data() + 2 * q, 2);
    std::vector<int> expect;
    for (std::size_t a = 0; a < nodes.size(); ++a)
      if (dist(nodes, a, x) <= radii[a]) expect.push_back(static_cast<int>(a));
    const auto got = lists[q];
    EXPECT_EQ(std::vector<int>(got.begin(), got.end()), expect);
  }
  const CsrLists one = primal_lists(tree, pts, std::vector<double>{0.1});
  EXPECT_EQ(one[3].size(), tree.radius_search(std::span<const double>(pts.data() + 6, 2), 0.1).size());
}

TEST(PrimalLists, StronglyGradedRadiiIn3DMatchBruteForce) {
  // Radii from 0.02 to 0.32 (five classes of the search) and from 0.1 to 0.12 (one search); 400
  // points search by classes, the first 10 alone by one search: the lists are the same.
  const NodeSet nodes(3, test::random_points(3, 3000, 0.0, 1.0, 5));
  const KdTree tree(nodes);
  const auto pts = test::random_points(3, 400, 0.0, 1.0, 9);
  for (const auto& [lo, hi] : {std::pair{0.02, 0.32}, std::pair{0.1, 0.12}}) {
    std::vector<double> radii(nodes.size());
    for (std::size_t a = 0; a < radii.size(); ++a) radii[a] = lo + (hi - lo) * std::pow(nodes.point(a)[2], 2);
    const CsrLists lists = primal_lists(tree, pts, radii);
    const CsrLists few = primal_lists(tree, std::span<const double>(pts).first(30), radii);
    lists.validate();
    for (std::size_t q = 0; q < 10; ++q)
      EXPECT_TRUE(std::ranges::equal(few[q], lists[q])) << "radii " << lo << " to " << hi << ", point " << q;
    for (std::size_t q = 0; q < 400; ++q) {
      const std::span<const double> x(pts.data() + 3 * q, 3);
      std::vector<int> expect;
      for (std::size_t a = 0; a < nodes.size(); ++a)
        if (dist(nodes, a, x) <= radii[a]) expect.push_back(static_cast<int>(a));
      const auto got = lists[q];
      ASSERT_EQ(std::vector<int>(got.begin(), got.end()), expect) << "radii " << lo << " to " << hi << ", point " << q;
    }
  }
}

TEST(CsrLists, PushBackAndValidate) {
  CsrLists l;
  l.push_back(std::vector<int>{3, 1});
  l.push_back(std::vector<int>{});
  l.push_back(std::vector<int>{7});
  EXPECT_EQ(l.size(), 3u);
  EXPECT_EQ(l.total(), 3u);
  EXPECT_EQ(l[1].size(), 0u);
  EXPECT_EQ(l[2][0], 7);
  EXPECT_DOUBLE_EQ(l.mean_size(), 1.0);
  l.validate();
  l.offsets[1] = 5;
  EXPECT_THROW(l.validate(), std::invalid_argument);
}

}  // namespace
}  // namespace lmeform
