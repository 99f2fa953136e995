#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <iostream>
#include <random>
#include <string>
#include <vector>

#include "lme_test_util.hpp"
#include "lmeform/kernel.hpp"
#include "lmeform/lme_basis.hpp"

#ifndef FDSTEP
#define FDSTEP 1e-5
#endif
namespace lmeform {
namespace {

using kernel::hessian_slot;
using kernel::jet_size;

struct Sums {
  double value = 0, first = 0, grad = 0, grad_x = 0, hess = 0, hess_x = 0;  // errors / scale
  double min_p = 1.0;
};

// Consistency identities of a point's order-2 jet, each error divided by the magnitude of the
// terms summed (sum_a |term_a|, at least 1) so that "1e-12" means 1e-12 relative to rounding-free
// cancellation of the individual contributions.
Sums consistency(const LmeBasis& basis, std::span<const double> x, std::span<const int> nbrs,
                 const std::vector<double>& jet) {
  const int d = basis.dim();
  const std::size_t n = nbrs.size();
  Sums s;
  double sum_p = 0.0;
  for (std::size_t a = 0; a < n; ++a) {
    sum_p += jet[a];
    s.min_p = std::min(s.min_p, jet[a]);
  }
  s.value = std::abs(sum_p - 1.0);
  for (int i = 0; i < d; ++i) {
    double first = -x[static_cast<std::size_t>(i)], scale = std::abs(x[static_cast<std::size_t>(i)]);
    for (std::size_t a = 0; a < n; ++a) {
      const double xa = basis.nodes().point(static_cast<std::size_t>(nbrs[a]))[static_cast<std::size_t>(i)];
      first += jet[a] * xa;
      scale += std::abs(jet[a] * xa);
    }
    s.first = std::max(s.first, std::abs(first) / std::max(1.0, scale));
    for (int j = 0; j < d; ++j) {
      const auto gj = static_cast<std::size_t>(1 + j) * n;
      const auto hij = static_cast<std::size_t>(hessian_slot(i, j, d)) * n;
      double g = 0, gs = 0, gx = (i == j ? -1.0 : 0.0), gxs = 1.0, h = 0, hs = 0, hx = 0, hxs = 0;
      for (std::size_t a = 0; a < n; ++a) {
        const double xa = basis.nodes().point(static_cast<std::size_t>(nbrs[a]))[static_cast<std::size_t>(i)];
        if (i == 0) {  // sum_a grad p_a and sum_a H p_a: once per j (and (i,j) below)
          g += jet[gj + a];
          gs += std::abs(jet[gj + a]);
        }
        gx += xa * jet[gj + a];
        gxs += std::abs(xa * jet[gj + a]);
        h += jet[hij + a];
        hs += std::abs(jet[hij + a]);
        // sum_a x_a (x) H p_a: component (i, j, k) with k looped below via hx2
      }
      s.grad = std::max(s.grad, std::abs(g) / std::max(1.0, gs));
      s.grad_x = std::max(s.grad_x, std::abs(gx) / std::max(1.0, gxs));
      s.hess = std::max(s.hess, std::abs(h) / std::max(1.0, hs));
      for (int k = 0; k < d; ++k) {
        const auto hjk = static_cast<std::size_t>(hessian_slot(j, k, d)) * n;
        hx = 0;
        hxs = 0;
        for (std::size_t a = 0; a < n; ++a) {
          const double xa = basis.nodes().point(static_cast<std::size_t>(nbrs[a]))[static_cast<std::size_t>(i)];
          hx += xa * jet[hjk + a];
          hxs += std::abs(xa * jet[hjk + a]);
        }
        s.hess_x = std::max(s.hess_x, std::abs(hx) / std::max(1.0, hxs));
      }
    }
  }
  return s;
}

void expect_consistent(const LmeBasis& basis, std::span<const double> x, std::span<const int> nbrs,
                       const std::vector<double>& jet, const std::string& what) {
  const Sums s = consistency(basis, x, nbrs, jet);
  EXPECT_LE(s.value, 1e-12) << what;
  EXPECT_LE(s.first, 1e-12) << what;
  EXPECT_LE(s.grad, 1e-12) << what;
  EXPECT_LE(s.grad_x, 1e-12) << what;
  EXPECT_LE(s.hess, 1e-12) << what;
  EXPECT_LE(s.hess_x, 1e-12) << what;
  EXPECT_GE(s.min_p, 0.0) << what;
}

struct FdErrors {
  double grad = 0, hess = 0;
};

// Central differences of values (-> gradient) and of gradients (-> Hessian) along `dirs` with the
// neighbour list frozen at x, relative to the largest exact entry of that order.
FdErrors finite_differences(const LmeBasis& basis, std::span<const double> x, std::span<const int> nbrs, double step,
                            std::vector<int> dirs = {}) {
  const int d = basis.dim();
  const std::size_t n = nbrs.size();
  if (dirs.empty())
    for (int i = 0; i < d; ++i) dirs.push_back(i);
  const auto exact = basis.evaluate(x, nbrs, 2);
  std::vector<double> fd_g, ex_g, fd_h, ex_h;
  for (const int i : dirs) {
    std::vector<double> xp(x.begin(), x.end()), xm(x.begin(), x.end());
    xp[static_cast<std::size_t>(i)] += step;
    xm[static_cast<std::size_t>(i)] -= step;
    const auto jp = basis.evaluate(xp, nbrs, 1);
    const auto jm = basis.evaluate(xm, nbrs, 1);
    for (std::size_t a = 0; a < n; ++a) {
      fd_g.push_back((jp[a] - jm[a]) / (2 * step));
      ex_g.push_back(exact[static_cast<std::size_t>(1 + i) * n + a]);
      for (int j = 0; j < d; ++j) {
        const auto gj = static_cast<std::size_t>(1 + j) * n + a;
        fd_h.push_back((jp[gj] - jm[gj]) / (2 * step));
        ex_h.push_back(exact[static_cast<std::size_t>(hessian_slot(i, j, d)) * n + a]);
      }
    }
  }
  return {test::rel_err(fd_g, ex_g), test::rel_err(fd_h, ex_h)};
}

NodeSet set_for(int dim) {
  return dim == 1 ? test::grid(1, 21, 1.0, 0.25) : dim == 2 ? test::grid(2, 11, 1.0, 0.2) : test::grid(3, 7, 1.0, 0.2);
}

double min_spacing(const LmeBasis& basis, std::span<const int> nbrs) {
  double h = 1e300;
  for (const int a : nbrs) h = std::min(h, basis.spacing()[static_cast<std::size_t>(a)]);
  return h;
}

struct GammaCase {
  int dim;
  double gamma;  // <= 0: non-uniform gamma_a in [0.6, 6]
};

std::string name(const GammaCase& c) {
  return std::to_string(c.dim) + "D gamma " + (c.gamma > 0 ? std::to_string(c.gamma) : std::string("non-uniform"));
}

std::vector<double> gammas_for(const GammaCase& c, const NodeSet& nodes) {
  if (c.gamma > 0) return {c.gamma};
  std::mt19937 rng(17);
  std::uniform_real_distribution<double> u(0.6, 6.0);
  std::vector<double> g(nodes.size());
  for (double& v : g) v = u(rng);
  return g;
}

class LmeGamma : public ::testing::TestWithParam<GammaCase> {};

TEST_P(LmeGamma, ConsistencyAndFiniteDifferences) {
  const GammaCase c = GetParam();
  const NodeSet nodes = set_for(c.dim);
  const LmeBasis basis(nodes, gammas_for(c, nodes));
  const auto pts = test::random_points(c.dim, 4, 0.2, 0.8, 100u + static_cast<unsigned>(c.dim));
  for (int q = 0; q < 4; ++q) {
    const std::span<const double> x(pts.data() + q * c.dim, static_cast<std::size_t>(c.dim));
    const auto nbrs = basis.neighbours(x);
    ASSERT_GE(nbrs.size(), static_cast<std::size_t>(c.dim + 1));
    const auto jet = basis.evaluate(x, nbrs, 2);
    expect_consistent(basis, x, nbrs, jet, name(c));
    const FdErrors e = finite_differences(basis, x, nbrs, FDSTEP * min_spacing(basis, nbrs));
    EXPECT_LT(e.grad, 1e-6) << name(c) << " point " << q;
    EXPECT_LT(e.hess, 1e-6) << name(c) << " point " << q;
  }
}

std::vector<GammaCase> all_cases() {
  std::vector<GammaCase> v;
  for (int d = 1; d <= 3; ++d) {
    for (const double g : {0.6, 0.8, 1.6, 4.0, 6.0}) v.push_back({d, g});
    v.push_back({d, -1.0});
  }
  return v;
}

INSTANTIATE_TEST_SUITE_P(AllDimsAndGammas, LmeGamma, ::testing::ValuesIn(all_cases()));

TEST(LmeBasis, LowerOrdersArePrefixesOfTheJet) {
  const NodeSet nodes = set_for(2);
  const LmeBasis basis(nodes, std::vector<double>{1.6});
  const std::vector<double> x = {0.41, 0.57};
  const auto nbrs = basis.neighbours(x);
  const auto j2 = basis.evaluate(x, nbrs, 2);
  const auto j1 = basis.evaluate(x, nbrs, 1);
  const auto j0 = basis.evaluate(x, nbrs, 0);
  ASSERT_EQ(j0.size(), nbrs.size());
  ASSERT_EQ(j1.size(), 3 * nbrs.size());
  ASSERT_EQ(j2.size(), 6 * nbrs.size());
  for (std::size_t k = 0; k < j1.size(); ++k) EXPECT_NEAR(j1[k], j2[k], 1e-13 * (1 + std::abs(j2[k])));
  for (std::size_t k = 0; k < j0.size(); ++k) EXPECT_NEAR(j0[k], j2[k], 1e-15);
  EXPECT_THROW((void)basis.evaluate(x, nbrs, 3), std::invalid_argument);
}

TEST(LmeBasis, UnitsDoNotChangeTheBasis) {
  // Same geometry in metres and in micrometres: identical p, gradients scaled by 1e6.
  const NodeSet a = set_for(2);
  std::vector<double> c = a.coords;
  for (double& v : c) v *= 1e-6;
  const NodeSet b(2, c);
  const LmeBasis ba(a, std::vector<double>{0.8}), bb(b, std::vector<double>{0.8});
  const std::vector<double> xa = {0.33, 0.61}, xb = {0.33e-6, 0.61e-6};
  const auto na = ba.neighbours(xa), nb = bb.neighbours(xb);
  ASSERT_EQ(na, nb);
  const auto ja = ba.evaluate(xa, na, 2), jb = bb.evaluate(xb, nb, 2);
  const std::size_t n = na.size();
  for (std::size_t k = 0; k < n; ++k) EXPECT_NEAR(jb[k], ja[k], 1e-12);
  for (std::size_t k = n; k < 3 * n; ++k) EXPECT_NEAR(jb[k] * 1e-6, ja[k], 1e-10 * (1 + std::abs(ja[k])));
  for (std::size_t k = 3 * n; k < 6 * n; ++k) EXPECT_NEAR(jb[k] * 1e-12, ja[k], 1e-9 * (1 + std::abs(ja[k])));
}

// ---- weak Kronecker delta on the hull boundary ---------------------------------------------------

TEST(WeakKronecker, InteriorFunctionsVanishOnTheBoundaryEdge) {
  const NodeSet nodes = set_for(2);  // jittered inside, boundary nodes on the box
  const LmeBasis basis(nodes, std::vector<double>{0.8});
  for (const double s : {0.37, 0.5, 0.81}) {
    const std::vector<double> x = {s, 0.0};
    const auto nbrs = basis.neighbours(x);
    const auto p = basis.evaluate(x, nbrs, 0);
    // The 1D LME of the edge nodes with the same beta is what remains on the edge.
    std::vector<double> edge_x, edge_h;
    std::vector<int> edge_local;
    double interior = 0.0;
    for (std::size_t k = 0; k < nbrs.size(); ++k) {
      const auto xa = nodes.point(static_cast<std::size_t>(nbrs[k]));
      if (xa[1] == 0.0) {
        edge_x.push_back(xa[0]);
        edge_h.push_back(basis.spacing()[static_cast<std::size_t>(nbrs[k])]);
        edge_local.push_back(static_cast<int>(k));
      } else {
        interior = std::max(interior, p[k]);
      }
    }
    EXPECT_LT(interior, 1e-10) << "s = " << s;
    const LmeBasis edge(NodeSet(1, edge_x), std::vector<double>{0.8}, edge_h);
    std::vector<int> all(edge_x.size());
    for (std::size_t k = 0; k < all.size(); ++k) all[k] = static_cast<int>(k);
    const auto p1 = edge.evaluate(std::vector<double>{s}, all, 0);
    for (std::size_t k = 0; k < all.size(); ++k)
      EXPECT_NEAR(p[static_cast<std::size_t>(edge_local[k])], p1[k], 1e-10) << "s = " << s;
  }
}

TEST(WeakKronecker, VertexFunctionIsOneAtItsVertex) {
  for (int dim = 1; dim <= 3; ++dim) {
    const NodeSet nodes = set_for(dim);
    for (const double g : {0.6, 1.6, 6.0}) {
      const LmeBasis basis(nodes, std::vector<double>{g});
      std::vector<double> corner(static_cast<std::size_t>(dim), 1.0);  // the (1, ..., 1) vertex
      const auto nbrs = basis.neighbours(corner);
      const auto p = basis.evaluate(corner, nbrs, 0);
      for (std::size_t k = 0; k < nbrs.size(); ++k) {
        const auto xa = nodes.point(static_cast<std::size_t>(nbrs[k]));
        const bool is_vertex = std::all_of(xa.begin(), xa.end(), [](double v) { return v == 1.0; });
        if (is_vertex) {
          EXPECT_NEAR(p[k], 1.0, 1e-10) << dim << "D gamma " << g;
        } else {
          EXPECT_LT(p[k], 1e-10) << dim << "D gamma " << g;
        }
      }
    }
  }
}

// Derivatives at a vertex of the hull are undefined (J vanishes there): an error, never garbage.
TEST(WeakKronecker, DerivativesAtAVertexAreAClearError) {
  for (int dim = 1; dim <= 3; ++dim) {
    const NodeSet nodes = set_for(dim);
    const LmeBasis basis(nodes, std::vector<double>{0.8});
    std::vector<double> corner(static_cast<std::size_t>(dim), 1.0);
    const auto nbrs = basis.neighbours(corner);
    for (const int order : {1, 2}) {
      try {
        (void)basis.evaluate(corner, nbrs, order);
        FAIL() << dim << "D order " << order << ": expected an error at the vertex";
      } catch (const LmeEvaluationError& e) {
        EXPECT_EQ(e.reason(), LmeFailure::singular_jacobian) << e.what();
        EXPECT_NE(std::string(e.what()).find("vertex of the convex hull"), std::string::npos) << e.what();
      }
    }
    // Slightly inside, derivatives are defined again.
    std::vector<double> inside(static_cast<std::size_t>(dim), 1.0 - 1e-3);
    EXPECT_NO_THROW((void)basis.evaluate(inside, basis.neighbours(inside), 2)) << dim << "D";
  }
}

// ---- hard cases -------------------------------------------------------------------------------

TEST(HardCases, StronglyGradedNodeSet) {
  const NodeSet nodes = test::graded_disc();
  for (const double g : {0.8, 1.6, 4.0}) {
    const LmeBasis basis(nodes, std::vector<double>{g});
    const auto h = basis.spacing();
    EXPECT_GE(*std::max_element(h.begin(), h.end()) / *std::min_element(h.begin(), h.end()), 10.0);
    std::mt19937 rng(5);
    std::uniform_real_distribution<double> u(0.0, 1.0);
    for (int q = 0; q < 12; ++q) {
      // Sample radii uniformly so that fine and coarse regions are both hit.
      const double r = 0.5 * u(rng), t = 6.283185307179586 * u(rng);
      const std::vector<double> x = {r * std::cos(t), r * std::sin(t)};
      const auto nbrs = basis.neighbours(x);
      const auto jet = basis.evaluate(x, nbrs, 2);
      expect_consistent(basis, x, nbrs, jet, "graded, gamma " + std::to_string(g));
      const FdErrors e = finite_differences(basis, x, nbrs, FDSTEP * min_spacing(basis, nbrs));
      EXPECT_LT(e.grad, 1e-6) << "graded r = " << r << " gamma " << g;
      EXPECT_LT(e.hess, 1e-6) << "graded r = " << r << " gamma " << g;
    }
  }
}

// Near the hull boundary (distance delta = 1e-8 h) the functions of interior nodes are O(delta) and
// their log-gradients O(1/delta): H p_a = p_a (g g^T + H ln p_a) then cancels terms of size
// p_a/delta^2 down to O(1/h^2), so Hessians carry a relative rounding error ~ eps * h/delta (~1e-8
// here; see docs/lme_basis.md). Values and gradients have no such cancellation and keep 1e-12.
TEST(HardCases, PointsWithin1e8OfTheHullBoundary) {
  const NodeSet nodes = set_for(2);
  double worst_hess = 0.0;
  for (const double g : {0.8, 4.0, 6.0}) {
    const LmeBasis basis(nodes, std::vector<double>{g});
    for (const double s : {0.13, 0.5, 0.77}) {
      for (const auto& x : {std::vector<double>{s, 1e-8}, std::vector<double>{1.0 - 1e-8, s},
                            std::vector<double>{1e-8, 1e-8}}) {
        const auto nbrs = basis.neighbours(x);
        const auto jet = basis.evaluate(x, nbrs, 2);
        const Sums c = consistency(basis, x, nbrs, jet);
        const std::string what = "x = (" + std::to_string(x[0]) + ", " + std::to_string(x[1]) + ") gamma " +
                                 std::to_string(g);
        EXPECT_LE(c.value, 1e-12) << what;
        EXPECT_LE(c.first, 1e-12) << what;
        EXPECT_LE(c.grad, 1e-12) << what;
        EXPECT_LE(c.grad_x, 1e-12) << what;
        EXPECT_LE(c.hess, 1e-6) << what;
        EXPECT_LE(c.hess_x, 1e-6) << what;
        EXPECT_GE(c.min_p, 0.0) << what;
        worst_hess = std::max({worst_hess, c.hess, c.hess_x});
        // Differences along the edge stay at the same distance from it.
        if (x[0] != x[1]) {
          const int along = x[1] == 1e-8 ? 0 : 1;
          const FdErrors e = finite_differences(basis, x, nbrs, 1e-4 * min_spacing(basis, nbrs), {along});
          EXPECT_LT(e.grad, 1e-6) << what;
          EXPECT_LT(e.hess, 1e-4) << what;
        }
      }
    }
  }
  std::cout << "[ info ] worst near-boundary Hessian consistency error: " << worst_hess << "\n";
  // 3D: near a face and near an edge.
  const NodeSet n3 = set_for(3);
  const LmeBasis b3(n3, std::vector<double>{1.6});
  for (const auto& x : {std::vector<double>{0.4, 0.6, 1e-8}, std::vector<double>{1e-8, 0.3, 1e-8}}) {
    const auto nbrs = b3.neighbours(x);
    const Sums c = consistency(b3, x, nbrs, b3.evaluate(x, nbrs, 2));
    EXPECT_LE(std::max({c.value, c.first, c.grad, c.grad_x}), 1e-12) << "3D near boundary";
    EXPECT_LE(std::max(c.hess, c.hess_x), 1e-6) << "3D near boundary";
  }
}

bool contains(const std::string& s, const std::string& part) { return s.find(part) != std::string::npos; }

TEST(HardCases, CollinearNeighbourhoodThrowsClearly) {
  std::vector<double> c;
  for (int k = 0; k <= 10; ++k) {
    c.push_back(0.1 * k);
    c.push_back(0.05 * k + 0.1);
  }
  const LmeBasis basis(NodeSet(2, c), std::vector<double>{0.8});
  const std::vector<double> x = {0.3, 0.25};
  const auto nbrs = basis.neighbours(x);
  try {
    (void)basis.evaluate(x, nbrs, 0);
    FAIL() << "collinear neighbourhood evaluated";
  } catch (const LmeEvaluationError& e) {
    EXPECT_EQ(e.reason(), LmeFailure::degenerate);
    EXPECT_EQ(e.neighbour_count(), nbrs.size());
    const std::string msg = e.what();
    EXPECT_TRUE(contains(msg, "x = (0.3, 0.25)")) << msg;
    EXPECT_TRUE(contains(msg, std::to_string(nbrs.size()) + " neighbours")) << msg;
    EXPECT_TRUE(contains(msg, "degenerate")) << msg;
  }
  // A single grid row as the list of a 2D point on it: the same, inside an otherwise fine set.
  const NodeSet grid = test::grid(2, 6, 1.0);
  const LmeBasis gb(grid, std::vector<double>{1.6});
  EXPECT_THROW((void)gb.evaluate(std::vector<double>{0.5, 0.4}, std::vector<int>{12, 13, 14, 15}, 1),
               LmeEvaluationError);
  try {
    (void)gb.evaluate(std::vector<double>{0.5, 0.4}, std::vector<int>{12, 13}, 1);
    FAIL() << "two neighbours in 2D evaluated";
  } catch (const LmeEvaluationError& e) {
    EXPECT_EQ(e.reason(), LmeFailure::too_few_neighbours);
    EXPECT_TRUE(contains(e.what(), "2 neighbours")) << e.what();
    EXPECT_TRUE(contains(e.what(), "too few")) << e.what();
  }
}

TEST(HardCases, PointOutsideTheHullThrowsClearly) {
  for (int dim = 1; dim <= 3; ++dim) {
    const NodeSet nodes = set_for(dim);
    const LmeBasis basis(nodes, std::vector<double>{0.8});
    for (const double off : {0.05, 1e-6}) {
      std::vector<double> x(static_cast<std::size_t>(dim), 0.5);
      x[0] = 1.0 + off;
      const auto nbrs = basis.neighbours(x);
      ASSERT_GE(nbrs.size(), static_cast<std::size_t>(dim + 1));
      try {
        (void)basis.evaluate(x, nbrs, 2);
        FAIL() << "outside point evaluated, " << dim << "D offset " << off;
      } catch (const LmeEvaluationError& e) {
        EXPECT_EQ(e.reason(), LmeFailure::outside_hull) << e.what();
        const std::string msg = e.what();
        EXPECT_TRUE(contains(msg, "outside the convex hull")) << msg;
        EXPECT_TRUE(contains(msg, std::to_string(nbrs.size()) + " neighbours")) << msg;
        EXPECT_TRUE(contains(msg, "x = (" + std::string(off == 0.05 ? "1.05" : "1.000001"))) << msg;
      }
    }
  }
}

TEST(HardCases, NonConvergenceReportsTheGradientNorm) {
  LmeOptions opt;
  opt.max_iterations = 1;
  const LmeBasis basis(set_for(2), std::vector<double>{0.8}, opt);
  const std::vector<double> x = {0.21, 0.33};
  try {
    (void)basis.evaluate(x, basis.neighbours(x), 0);
    FAIL() << "one Newton iteration converged to 1e-12";
  } catch (const LmeEvaluationError& e) {
    EXPECT_EQ(e.reason(), LmeFailure::not_converged);
    EXPECT_GT(e.gradient_norm(), opt.newton_tolerance);
    EXPECT_TRUE(contains(e.what(), "||grad ln Z|| = ")) << e.what();
    EXPECT_TRUE(contains(e.what(), "did not converge")) << e.what();
  }
}

TEST(HardCases, DerivativesOnTheBoundaryNeedAWellConditionedJ) {
  LmeOptions opt;
  opt.min_rcond = 1e-6;  // stricter than the default, so that a point on an edge trips it
  const LmeBasis basis(set_for(2), std::vector<double>{0.8}, opt);
  const std::vector<double> x = {0.4, 0.0};
  const auto nbrs = basis.neighbours(x);
  EXPECT_NO_THROW((void)basis.evaluate(x, nbrs, 0));
  try {
    (void)basis.evaluate(x, nbrs, 1);
    FAIL() << "derivatives on the boundary with min_rcond 1e-6";
  } catch (const LmeEvaluationError& e) {
    EXPECT_EQ(e.reason(), LmeFailure::singular_jacobian);
    EXPECT_TRUE(contains(e.what(), "rcond(J)")) << e.what();
  }
}

TEST(HardCases, APointCollinearWithAFarFineAndANearCoarseNode) {
  // The neighbourhood of a consistent-integration facet point of SENS on nodes that follow the crack
  // (l = 0.0075, support_tolerance 1e-3): x lies on the segment from a far node of fine spacing
  // (weight e^-152 at mu = 0) to a near coarse one, three further nodes around. The minimizer puts
  // 11 % and 89 % on those two and e^-53 or less on the rest; on the way the dual Newton reaches
  // iterates where one node carries all the weight (ln Z linear, J = 0), where unit steps of -r
  // had crawled to the 300-iteration cap with ||r|| = 9.4e-2. Units: x at the origin, the RMS
  // distance 1, gamma 1 and each node's spacing set to give its exponent.
  const std::vector<std::array<double, 3>> neighbourhood = {
      // exponent -beta_a |x - x_a|^2, then x - x_a
      {-151.83285343791596, 0.73042931258103216, 0.12264472186948568},
      {-0.80153606612543205, -0.092776687116058673, -0.015577922177184147},
      {-4.462831279007542, -1.0855044902583331, -0.042295478057688358},
      {-3.7891878440175017, -0.57093653158914104, -0.65004938880089025},
      {-6.1074930061077719, -1.3453079097544807, -0.83909838357716715}};
  std::vector<double> coords, spacing;
  for (const auto& [exponent, dx, dy] : neighbourhood) {
    coords.insert(coords.end(), {-dx, -dy});
    spacing.push_back(std::sqrt((dx * dx + dy * dy) / -exponent));
  }
  LmeOptions opt;
  opt.max_iterations = 20;  // measured: 13-15 iterations (12 fail); 300 did not suffice before
  const LmeBasis basis(NodeSet(2, coords), std::vector<double>{1.0}, spacing, opt);
  const std::vector<double> x = {0.0, 0.0};
  const std::vector<int> nbrs = {0, 1, 2, 3, 4};
  std::vector<double> p;
  ASSERT_NO_THROW(p = basis.evaluate(x, nbrs, 0));
  double sum = 0, first = 0, second = 0;
  for (std::size_t a = 0; a < nbrs.size(); ++a) {
    EXPECT_GE(p[a], 0.0);
    sum += p[a];
    first += p[a] * coords[2 * a];
    second += p[a] * coords[2 * a + 1];
  }
  EXPECT_NEAR(sum, 1.0, 1e-14);
  EXPECT_NEAR(first, 0.0, 1e-12);
  EXPECT_NEAR(second, 0.0, 1e-12);
  // On the segment: the weights of linear interpolation between its two ends.
  EXPECT_NEAR(p[0], 0.092776687116058673 / (0.73042931258103216 + 0.092776687116058673), 1e-9);
  EXPECT_NEAR(p[1], 0.73042931258103216 / (0.73042931258103216 + 0.092776687116058673), 1e-9);
}

TEST(HardCases, Gamma6NearTheDelaunayLimit) {
  // gamma = 6 on a regular 2D grid: at a node's own position its function dominates.
  const NodeSet nodes = test::grid(2, 11, 1.0);
  const LmeBasis basis(nodes, std::vector<double>{6.0});
  const std::vector<double> x = {0.5, 0.5};
  const auto nbrs = basis.neighbours(x);
  const auto jet = basis.evaluate(x, nbrs, 2);
  expect_consistent(basis, x, nbrs, jet, "gamma 6 at a node");
  const auto self = std::find(nbrs.begin(), nbrs.end(), 60) - nbrs.begin();
  EXPECT_GT(jet[static_cast<std::size_t>(self)], 0.9);
}

}  // namespace
}  // namespace lmeform

namespace lmeform {
namespace {

// A jittered grid on [0, 1]^2 whose left edge x = 0 is the mirror plane (the axis r = 0 of an
// axisymmetric problem).
LmeBasis mirrored_basis(const NodeSet& nodes, double gamma = 0.8) {
  LmeOptions o;
  o.mirrors = {MirrorPlane{0, 0.0}};
  return LmeBasis(nodes, std::vector<double>{gamma}, o);
}

TEST(MirrorSymmetry, NormalDerivativeVanishesOnThePlane) {
  const NodeSet nodes = test::grid(2, 13, 1.0, 0.25);
  const LmeBasis basis = mirrored_basis(nodes);
  ASSERT_GT(basis.image_count(), 0u);
  for (const double y : {0.2, 0.37, 0.5, 0.81}) {
    const std::array<double, 2> x{0.0, y};
    const auto nbrs = basis.neighbours(x);
    const auto jet = basis.evaluate(x, nbrs, 2);
    const std::size_t n = nbrs.size();
    double dx = 0, dy = 0, sum = 0, sum_y = 0;
    for (std::size_t a = 0; a < n; ++a) {
      dx = std::max(dx, std::abs(jet[1 * n + a]));  // each function is even: d/dx = 0 on the plane
      dy = std::max(dy, std::abs(jet[2 * n + a]));
      sum += jet[a];
      sum_y += jet[a] * nodes.point(static_cast<std::size_t>(nbrs[a]))[1];
    }
    EXPECT_LT(dx, 1e-10 * dy) << "y = " << y;
    EXPECT_NEAR(sum, 1.0, 1e-12);   // partition of unity
    EXPECT_NEAR(sum_y, y, 1e-12);   // consistency along the plane
  }
}

TEST(MirrorSymmetry, AwayFromThePlaneTheBasisIsUnchanged) {
  // Points farther from the plane than every support radius see no image.
  const NodeSet nodes = test::grid(2, 13, 1.0, 0.25);
  const LmeBasis plain(nodes, std::vector<double>{0.8});
  const LmeBasis mirrored = mirrored_basis(nodes);
  const std::array<double, 2> x{0.8, 0.45};
  const auto nbrs = plain.neighbours(x);
  EXPECT_EQ(mirrored.neighbours(x), nbrs);
  const auto a = plain.evaluate(x, nbrs, 2), b = mirrored.evaluate(x, nbrs, 2);
  EXPECT_LE(test::rel_err(b, a), 1e-14);
}

TEST(MirrorSymmetry, DerivativesMatchFiniteDifferencesNearThePlane) {
  const NodeSet nodes = test::grid(2, 13, 1.0, 0.25);
  const LmeBasis basis = mirrored_basis(nodes);
  for (const double r : {0.004, 0.03, 0.09}) {
    const std::array<double, 2> x{r, 0.43};
    const auto nbrs = basis.neighbours(x);
    const FdErrors e = finite_differences(basis, x, nbrs, 1e-6);
    EXPECT_LT(e.grad, 1e-7) << "r = " << r;
    EXPECT_LT(e.hess, 1e-6) << "r = " << r;
  }
}

TEST(MirrorSymmetry, CompressedRecordReconstructsTheSameJet) {
  const NodeSet nodes = test::grid(2, 11, 1.0, 0.2);
  const LmeBasis basis = mirrored_basis(nodes);
  const std::array<double, 2> x{0.02, 0.61};
  const auto nbrs = basis.neighbours(x);
  const auto direct = basis.evaluate(x, nbrs, 2);
  LmeWorkspace ws;
  std::vector<double> record(static_cast<std::size_t>(lme_record_size(2, 2)));
  basis.solve_record(x, nbrs, 2, record, ws);
  std::vector<double> rebuilt(direct.size(), -7.0);
  basis.reconstruct(x, nbrs, 2, record, 2, rebuilt, nbrs.size(), {}, ws);
  EXPECT_LE(test::rel_err(rebuilt, direct), 1e-12);
}

TEST(MirrorSymmetry, NodesOnBothSidesAreRefused) {
  NodeSet nodes = test::grid(2, 6, 1.0);
  for (std::size_t a = 0; a < nodes.size(); ++a) nodes.coords[2 * a] -= 0.5;  // straddles x = 0
  try {
    (void)mirrored_basis(nodes);
    FAIL() << "accepted nodes on both sides of the mirror plane";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("one side of the plane"), std::string::npos) << e.what();
  }
}

// Three planes of symmetry: the octant's basis at x is the basis of the whole symmetric node set
// at x with each node's images added to it (the same LME problem on the same nodes), for the
// values, gradients and Hessians, at points near one, two and three planes.
void expect_octant_equals_folded_full_basis(LmeConsistency consistency, double gamma) {
  const int m = 6;
  const double h = 0.1;
  std::vector<double> octant, full;
  std::vector<std::size_t> folded;  // full node -> octant node
  for (int k = -m; k <= m; ++k)
    for (int j = -m; j <= m; ++j)
      for (int i = -m; i <= m; ++i) {
        full.insert(full.end(), {i * h, j * h, k * h});
        folded.push_back(std::size_t((std::abs(k) * (m + 1) + std::abs(j)) * (m + 1) + std::abs(i)));
      }
  for (int k = 0; k <= m; ++k)
    for (int j = 0; j <= m; ++j)
      for (int i = 0; i <= m; ++i) octant.insert(octant.end(), {i * h, j * h, k * h});
  LmeOptions o;
  o.consistency = consistency;
  const LmeBasis whole(NodeSet(3, full), std::vector<double>{gamma}, std::vector<double>(full.size() / 3, h), o);
  o.mirrors = {MirrorPlane{0, 0.0}, MirrorPlane{1, 0.0}, MirrorPlane{2, 0.0}};
  const LmeBasis part(NodeSet(3, octant), std::vector<double>{gamma}, std::vector<double>(octant.size() / 3, h), o);
  ASSERT_GT(part.image_count(), 0u);
  const int rows = 1 + 3 + 6;
  for (const std::array<double, 3> x : {std::array<double, 3>{0.013, 0.21, 0.33}, {0.02, 0.031, 0.25}, {0.011, 0.024, 0.017},
                                        {0.0, 0.0, 0.0}, {0.27, 0.31, 0.29}}) {
    const auto nf = whole.neighbours(x), np = part.neighbours(x);
    const auto jf = whole.evaluate(x, nf, 2), jp = part.evaluate(x, np, 2);
    std::vector<double> expected(std::size_t(rows) * np.size(), 0.0);
    for (std::size_t b = 0; b < nf.size(); ++b) {
      const auto a = std::find(np.begin(), np.end(), int(folded[std::size_t(nf[b])]));
      ASSERT_NE(a, np.end()) << "a full-grid neighbour's octant node is no neighbour of the mirrored basis";
      for (int r = 0; r < rows; ++r) expected[std::size_t(r) * np.size() + std::size_t(a - np.begin())] += jf[std::size_t(r) * nf.size() + b];
    }
    EXPECT_LE(test::rel_err(jp, expected), 1e-9) << "at (" << x[0] << ", " << x[1] << ", " << x[2] << ")";
  }
}

TEST(MirrorSymmetry, ThreePlanesGiveTheFoldedBasisOfTheWholeSymmetricNodeSet) {
  expect_octant_equals_folded_full_basis(LmeConsistency::first, 0.8);
  expect_octant_equals_folded_full_basis(LmeConsistency::second, 0.8);
}

TEST(MirrorSymmetry, TwoPlanesOnOneAxisAreRefused) {
  LmeOptions o;
  o.mirrors = {MirrorPlane{0, 0.0}, MirrorPlane{0, 0.0}};
  EXPECT_THROW((void)LmeBasis(test::grid(2, 6, 1.0), std::vector<double>{0.8}, o), std::invalid_argument);
}

TEST(SpacingSmoothing, ConstantSpacingIsKeptAndScatterIsDamped) {
  // Interior nodes of a grid, farther from the edge than the smoothing reaches (edge nodes have
  // other nearest distances), keep the grid step.
  const NodeSet uniform = test::grid(2, 31, 1.0);
  const KdTree tree(uniform);
  const std::vector<double> h = nodal_spacing(tree);
  const std::vector<double> s = smooth_spacing(tree, h, 5);
  const double step = 1.0 / 30.0;
  for (std::size_t a = 0; a < uniform.size(); ++a) {
    const auto x = uniform.point(a);
    if (std::min({x[0], x[1], 1 - x[0], 1 - x[1]}) < 12 * step) continue;
    EXPECT_NEAR(s[a], step, 1e-13);
  }
  const NodeSet jittered = test::grid(2, 15, 1.0, 0.3);
  const KdTree jt(jittered);
  const std::vector<double> raw = nodal_spacing(jt);
  const std::vector<double> smooth = smooth_spacing(jt, raw, 5);
  auto spread = [](const std::vector<double>& v) {
    double mean = 0, var = 0;
    for (const double x : v) mean += x / static_cast<double>(v.size());
    for (const double x : v) var += (x - mean) * (x - mean) / static_cast<double>(v.size());
    return std::sqrt(var) / mean;
  };
  EXPECT_LT(spread(smooth), 0.5 * spread(raw));
  EXPECT_THROW((void)smooth_spacing(jt, std::vector<double>(3, 1.0), 1), std::invalid_argument);
  EXPECT_THROW((void)smooth_spacing(jt, raw, 1, -1.0), std::invalid_argument);
}

}  // namespace
}  // namespace lmeform
