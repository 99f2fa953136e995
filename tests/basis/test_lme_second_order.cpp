// The second-order max-ent basis (LmeConsistency::second): quadratic reproduction with the nodal
// gaps, derivatives against finite differences, non-negativity, the weak Kronecker property, mirror
// symmetry, storages and cell tabulation, refusals, and Hessians that converge where the
// first-order basis' do not.
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <numbers>
#include <set>
#include <string>
#include <vector>

#include "lme_test_util.hpp"
#include "lmeform/kernel.hpp"
#include "lmeform/lme_storage.hpp"
#include "lmeform/node_sets.hpp"

namespace lmeform {
namespace {

using kernel::hessian_slot;
using kernel::jet_size;

LmeBasis second_order(const NodeSet& nodes, double gamma, bool mirrored = false) {
  LmeOptions o;
  o.consistency = LmeConsistency::second;
  if (mirrored) o.mirrors = {MirrorPlane{0, 0.0}};
  return LmeBasis(nodes, std::vector<double>{gamma}, o);
}

NodeSet set_for(int dim) {
  return dim == 1 ? test::grid(1, 21, 1.0, 0.25) : dim == 2 ? test::grid(2, 13, 1.0, 0.25) : test::grid(3, 7, 1.0, 0.2);
}

NodeSet graded_box() {
  GradedGridOptions o;
  o.h_min = 0.03;
  o.h_max = 0.1;
  return graded_grid_2d(o);
}

int packed(int i, int j, int d) { return hessian_slot(i, j, d) - 1 - d; }

// Worst error of the reproduction identities of a point's order-2 jet, each divided by the
// magnitude of the terms summed (at least 1): sum p_a m_a = m(x) for m = 1, x_i and
// x_i x_j - G_ij (exact: x_i x_j), with their gradients and Hessians. `even_only`: with mirror
// symmetry only functions even in x_0 are reproduced (1, x_k for k > 0, x_i x_j with i, j both 0
// or both > 0).
double reproduction_error(const LmeBasis& basis, std::span<const double> x, std::span<const int> nbrs,
                          const std::vector<double>& jet, bool even_only = false) {
  const int d = basis.dim();
  const std::size_t n = nbrs.size();
  const auto gaps = basis.gaps();
  const auto s = static_cast<std::size_t>(d * (d + 1) / 2);
  double worst = 0.0;
  // A monomial by the exponents of x_i, x_j (-1: none): its value at node a (gap-corrected) and its
  // exact jet at x.
  auto check = [&](int i, int j) {
    std::array<double, 10> exact{};  // jet_size(3, 2) slots at most
    auto xi = [&](int k) { return x[static_cast<std::size_t>(k)]; };
    if (i < 0) {
      exact[0] = 1.0;
    } else if (j < 0) {
      exact[0] = xi(i);
      exact[static_cast<std::size_t>(1 + i)] = 1.0;
    } else {
      exact[0] = xi(i) * xi(j);
      exact[static_cast<std::size_t>(1 + i)] += xi(j);
      exact[static_cast<std::size_t>(1 + j)] += xi(i);
      exact[static_cast<std::size_t>(hessian_slot(i, j, d))] = i == j ? 2.0 : 1.0;
    }
    for (int slot = 0; slot < jet_size(d, 2); ++slot) {
      double sum = 0.0, scale = 1.0;
      for (std::size_t a = 0; a < n; ++a) {
        const auto b = static_cast<std::size_t>(nbrs[a]);
        const auto xa = basis.nodes().point(b);
        double m = 1.0;
        if (i >= 0) m = xa[static_cast<std::size_t>(i)];
        if (j >= 0) m = m * xa[static_cast<std::size_t>(j)] - gaps[b * s + static_cast<std::size_t>(packed(i, j, d))];
        const double t = jet[static_cast<std::size_t>(slot) * n + a] * m;
        sum += t;
        scale += std::abs(t);
      }
      worst = std::max(worst, std::abs(sum - exact[static_cast<std::size_t>(slot)]) / scale);
    }
  };
  check(-1, -1);
  for (int i = 0; i < d; ++i) {
    if (!even_only || i > 0) check(i, -1);
    for (int j = i; j < d; ++j)
      if (!even_only || (i == 0) == (j == 0)) check(i, j);
  }
  return worst;
}

// Points of the unit box: inside, and `delta` * h from a face, an edge and a corner.
std::vector<std::vector<double>> probe_points(int dim, double h, std::initializer_list<double> deltas) {
  std::vector<std::vector<double>> pts;
  const auto inner = test::random_points(dim, 6, 0.15, 0.85, 5u + static_cast<unsigned>(dim));
  for (int q = 0; q < 6; ++q) pts.emplace_back(inner.begin() + q * dim, inner.begin() + (q + 1) * dim);
  for (const double delta : deltas) {
    std::vector<double> face(static_cast<std::size_t>(dim), 0.43), corner(static_cast<std::size_t>(dim), delta * h);
    face[0] = delta * h;
    pts.push_back(face);
    pts.push_back(corner);
    if (dim == 3) pts.push_back({delta * h, 1.0 - delta * h, 0.61});  // near an edge
  }
  return pts;
}

TEST(SecondOrder, ReproducesQuadraticsToRoundOffInEveryDimension) {
  for (int dim = 1; dim <= 3; ++dim) {
    const NodeSet nodes = set_for(dim);
    for (const double gamma : {0.5, 0.8, 1.0}) {
      const LmeBasis basis = second_order(nodes, gamma);
      const double h = basis.spacing()[0];
      for (const auto& x : probe_points(dim, h, {1e-3, 0.05, 0.5})) {
        const auto nbrs = basis.neighbours(x);
        const auto jet = basis.evaluate(x, nbrs, 2);
        EXPECT_LE(reproduction_error(basis, x, nbrs, jet), 1e-11)
            << dim << "D gamma " << gamma << " at " << x[0] << ", " << x.back();
        EXPECT_GE(*std::min_element(jet.begin(), jet.begin() + static_cast<std::ptrdiff_t>(nbrs.size())), 0.0);
      }
    }
  }
}

TEST(SecondOrder, ReproducesQuadraticsOnAGradedSetAndVeryNearTheHull) {
  const NodeSet nodes = graded_box();
  const LmeBasis basis = second_order(nodes, 0.8);
  const auto inner = test::random_points(2, 20, 0.0, 1.0, 77);
  std::vector<std::vector<double>> pts;
  for (int q = 0; q < 20; ++q) pts.push_back({inner[2 * q], inner[2 * q + 1]});
  for (const double delta : {1e-6, 1e-4, 1e-2, 0.3}) {
    pts.push_back({0.37, delta});
    pts.push_back({1.0 - delta, 0.71});
    pts.push_back({delta, delta});
  }
  for (const auto& x : pts) {
    const auto nbrs = basis.neighbours(x);
    const auto jet = basis.evaluate(x, nbrs, 2);
    // Within delta of the hull Hessians carry a rounding error ~ eps h / delta (as the first-order
    // basis' do, docs/lme_basis.md); 1e-6 h from it that is 1e-10.
    const double tol = std::min(x[0], x[1]) < 1e-5 || std::max(x[0], x[1]) > 1 - 1e-5 ? 1e-8 : 1e-11;
    EXPECT_LE(reproduction_error(basis, x, nbrs, jet), tol) << "at " << x[0] << ", " << x[1];
  }
}

double fd_error(const LmeBasis& basis, std::span<const double> x, std::span<const int> nbrs, double step) {
  const int d = basis.dim();
  const std::size_t n = nbrs.size();
  const auto exact = basis.evaluate(x, nbrs, 2);
  std::vector<double> fd, ex;
  for (int i = 0; i < d; ++i) {
    std::vector<double> xp(x.begin(), x.end()), xm(x.begin(), x.end());
    xp[static_cast<std::size_t>(i)] += step;
    xm[static_cast<std::size_t>(i)] -= step;
    const auto jp = basis.evaluate(xp, nbrs, 1), jm = basis.evaluate(xm, nbrs, 1);
    for (std::size_t a = 0; a < n; ++a)
      for (int j = 0; j < d; ++j) {
        const auto gj = static_cast<std::size_t>(1 + j) * n + a;
        fd.push_back((jp[gj] - jm[gj]) / (2 * step));  // Hessian from gradients
        ex.push_back(exact[static_cast<std::size_t>(hessian_slot(i, j, d)) * n + a]);
      }
    std::vector<double> fdv, exv;
    for (std::size_t a = 0; a < n; ++a) {
      fdv.push_back((jp[a] - jm[a]) / (2 * step));  // gradient from values
      exv.push_back(exact[static_cast<std::size_t>(1 + i) * n + a]);
    }
    fd.insert(fd.end(), fdv.begin(), fdv.end());
    ex.insert(ex.end(), exv.begin(), exv.end());
  }
  return test::rel_err(fd, ex);
}

TEST(SecondOrder, DerivativesMatchFiniteDifferences) {
  for (int dim = 1; dim <= 3; ++dim) {
    const NodeSet nodes = set_for(dim);
    const LmeBasis basis = second_order(nodes, 0.8);
    const double h = basis.spacing()[0];
    for (const auto& x : probe_points(dim, h, {0.05, 0.5})) {
      const auto nbrs = basis.neighbours(x);
      EXPECT_LT(fd_error(basis, x, nbrs, 1e-5 * h), 1e-6) << dim << "D at " << x[0] << ", " << x.back();
    }
  }
}

TEST(SecondOrder, WeakKroneckerOnTheHull) {
  const NodeSet nodes = set_for(2);
  const LmeBasis basis = second_order(nodes, 0.8);
  for (const double s : {0.37, 0.5, 0.81}) {
    const std::vector<double> x = {s, 0.0};
    const auto nbrs = basis.neighbours(x);
    const auto p = basis.evaluate(x, nbrs, 0);
    double interior = 0.0, sum = 0.0;
    for (std::size_t k = 0; k < nbrs.size(); ++k) {
      sum += p[k];
      if (nodes.point(static_cast<std::size_t>(nbrs[k]))[1] != 0.0) interior = std::max(interior, p[k]);
    }
    EXPECT_LT(interior, 1e-10) << "s = " << s;  // so w = 0 on the hull by zero hull coefficients
    EXPECT_NEAR(sum, 1.0, 1e-12);
  }
  const std::vector<double> corner = {1.0, 1.0};
  const auto nbrs = basis.neighbours(corner);
  const auto p = basis.evaluate(corner, nbrs, 0);
  for (std::size_t k = 0; k < nbrs.size(); ++k) {
    const auto xa = nodes.point(static_cast<std::size_t>(nbrs[k]));
    EXPECT_NEAR(p[k], xa[0] == 1.0 && xa[1] == 1.0 ? 1.0 : 0.0, 1e-10);
  }
}

TEST(SecondOrder, GapsAreProjectedOntoTheHullAndWidenedBesideIt) {
  const NodeSet nodes = test::grid(2, 11, 1.0);  // h = 0.1
  const LmeBasis basis = second_order(nodes, 0.8);
  const auto g = basis.gaps();
  // The gap entry (i, j) of the node at (x, y), and that node's h^2 / (2 gamma).
  auto gap = [&](double x, double y, int i, int j, double* g0 = nullptr) {
    for (std::size_t a = 0; a < nodes.size(); ++a)
      if (std::abs(nodes.coords[2 * a] - x) < 1e-12 && std::abs(nodes.coords[2 * a + 1] - y) < 1e-12) {
        if (g0) *g0 = basis.spacing()[a] * basis.spacing()[a] / 1.6;
        return g[3 * a + static_cast<std::size_t>(packed(i, j, 2))];
      }
    return -1.0;
  };
  double g0 = 0.0;
  const double interior = gap(0.5, 0.5, 0, 0, &g0);
  EXPECT_NEAR(interior, g0, 1e-15);  // interior: h^2 / (2 gamma) I
  EXPECT_NEAR(g0, 0.01 / 1.6, 1e-15);
  EXPECT_NEAR(gap(0.5, 0.5, 0, 1), 0.0, 1e-15);
  EXPECT_NEAR(gap(0.5, 0.0, 1, 1), 0.0, 1e-15);  // on the edge y = 0: nothing across it
  const double along = gap(0.5, 0.0, 0, 0, &g0);
  EXPECT_NEAR(along, g0, 1e-15);
  EXPECT_NEAR(gap(0.0, 0.0, 0, 0), 0.0, 1e-15);  // a corner: nothing at all
  EXPECT_NEAR(gap(0.0, 0.0, 1, 1), 0.0, 1e-15);
  EXPECT_NEAR(gap(0.5, 0.1, 1, 1), 1.5 * 0.01, 1e-15);  // first row: 1.5 times its squared distance
  const double second_row = gap(0.5, 0.2, 1, 1, &g0);
  EXPECT_NEAR(second_row, g0, 1e-15);  // beyond 1.5 h: unchanged
}

TEST(SecondOrder, NodalCoefficientsOfAQuadraticReproduceIt) {
  const NodeSet nodes = graded_box();
  const LmeBasis basis = second_order(nodes, 0.5);
  // q = 1 + 2x - y + 1.5 x^2 - 0.4 x y + 0.7 y^2, Hessian (3, -0.4; -0.4, 1.4).
  auto q = [](double x, double y) { return 1 + 2 * x - y + 1.5 * x * x - 0.4 * x * y + 0.7 * y * y; };
  std::vector<double> values(nodes.size()), hessians(3 * nodes.size());
  for (std::size_t a = 0; a < nodes.size(); ++a) {
    values[a] = q(nodes.coords[2 * a], nodes.coords[2 * a + 1]);
    hessians[3 * a] = 3.0;
    hessians[3 * a + 1] = -0.4;
    hessians[3 * a + 2] = 1.4;
  }
  const std::vector<double> c = basis.gap_corrected(values, hessians);
  for (const auto& x : std::vector<std::vector<double>>{{0.31, 0.64}, {0.02, 0.5}, {0.97, 0.99}}) {
    const auto nbrs = basis.neighbours(x);
    const auto jet = basis.evaluate(x, nbrs, 2);
    const std::size_t n = nbrs.size();
    double v[6] = {};
    for (std::size_t s = 0; s < 6; ++s)
      for (std::size_t a = 0; a < n; ++a) v[s] += jet[s * n + a] * c[static_cast<std::size_t>(nbrs[a])];
    EXPECT_NEAR(v[0], q(x[0], x[1]), 1e-12);
    EXPECT_NEAR(v[1], 2 + 3 * x[0] - 0.4 * x[1], 1e-10);
    EXPECT_NEAR(v[2], -1 - 0.4 * x[0] + 1.4 * x[1], 1e-10);
    EXPECT_NEAR(v[3], 3.0, 1e-8);
    EXPECT_NEAR(v[4], -0.4, 1e-8);
    EXPECT_NEAR(v[5], 1.4, 1e-8);
  }
  // The first-order basis keeps the values: its coefficients are nodal values.
  const LmeBasis first(nodes, std::vector<double>{0.5});
  EXPECT_EQ(first.gap_corrected(values, hessians), values);
  EXPECT_THROW((void)basis.gap_corrected(values, values), std::invalid_argument);
}

// ---- mirror symmetry ----------------------------------------------------------------------------

TEST(SecondOrderMirror, EvenQuadraticsAreReproducedAndTheNormalDerivativeVanishesOnThePlane) {
  const NodeSet nodes = test::grid(2, 13, 1.0, 0.25);
  const LmeBasis basis = second_order(nodes, 0.8, true);
  ASSERT_GT(basis.image_count(), 0u);
  for (const double r : {0.0, 1e-4, 0.01, 0.05, 0.2}) {
    for (const double y : {0.02, 0.37, 0.81}) {
      const std::vector<double> x = {r, y};
      const auto nbrs = basis.neighbours(x);
      const auto jet = basis.evaluate(x, nbrs, 2);
      EXPECT_LE(reproduction_error(basis, x, nbrs, jet, true), 1e-11) << "r = " << r << " y = " << y;
      if (r == 0.0) {
        const std::size_t n = nbrs.size();
        double dx = 0, dy = 0;
        for (std::size_t a = 0; a < n; ++a) {
          dx = std::max(dx, std::abs(jet[n + a]));
          dy = std::max(dy, std::abs(jet[2 * n + a]));
        }
        EXPECT_LT(dx, 1e-10 * dy) << "y = " << y;
      }
    }
  }
  // Nodes on the plane are no hull nodes: their gaps keep the direction across it.
  const auto g = basis.gaps();
  for (std::size_t a = 0; a < nodes.size(); ++a) {
    if (nodes.coords[2 * a] == 0.0 && nodes.coords[2 * a + 1] > 0.0 && nodes.coords[2 * a + 1] < 1.0) {
      EXPECT_GT(g[3 * a], 0.0) << "node " << a;
    }
  }
}

TEST(SecondOrderMirror, DerivativesMatchFiniteDifferencesNearThePlane) {
  const NodeSet nodes = test::grid(2, 13, 1.0, 0.25);
  const LmeBasis basis = second_order(nodes, 0.8, true);
  for (const double r : {0.004, 0.03, 0.09}) {
    const std::vector<double> x = {r, 0.43};
    EXPECT_LT(fd_error(basis, x, basis.neighbours(x), 1e-6), 1e-6) << "r = " << r;
  }
}

// ---- storages and cell tabulation ------------------------------------------------------------

void expect_close(const std::vector<double>& a, const std::vector<double>& b, const std::string& what) {
  EXPECT_LE(test::rel_err(a, b), 1e-12) << what;
}

TEST(SecondOrderStorage, FullCompressedAndDirectAgree) {
  for (int dim = 1; dim <= 3; ++dim) {
    for (const bool mirrored : {false, true}) {
      const NodeSet nodes = set_for(dim);
      const LmeBasis basis = second_order(nodes, 0.8, mirrored);
      const int nq = 12;
      const auto pts = test::random_points(dim, nq, 0.01, 0.99, 61);
      const CsrLists lists = basis.neighbour_lists(pts);
      LmeWorkspace ws;
      for (int order = 0; order <= 2; ++order) {
        const LmeFullStorage full(basis, pts, lists, order);
        const LmeCompressedStorage comp(basis, pts, lists, order);
        EXPECT_EQ(comp.doubles(), static_cast<std::size_t>(nq * lme_second_order_record_size(dim, order)));
        EXPECT_EQ(basis.record_size(order), lme_second_order_record_size(dim, order));
        for (std::size_t q = 0; q < lists.size(); ++q) {
          const auto x = std::span<const double>(pts).subspan(q * static_cast<std::size_t>(dim), static_cast<std::size_t>(dim));
          const auto direct = basis.evaluate(x, lists[q], order);
          std::vector<double> f(direct.size()), c(direct.size(), -7.0);
          full.point_jet(q, order, f);
          comp.point_jet(basis, q, order, c, ws);
          const std::string what = std::to_string(dim) + "D order " + std::to_string(order) + (mirrored ? " mirrored" : "");
          EXPECT_EQ(f, direct) << what;
          expect_close(c, direct, what + " compressed");
          if (order < 2) continue;
          std::vector<double> lower(static_cast<std::size_t>(jet_size(dim, 1)) * lists[q].size());
          comp.point_jet(basis, q, 1, lower, ws);  // a lower order from an order-2 record
          expect_close(lower, std::vector<double>(direct.begin(), direct.begin() + static_cast<std::ptrdiff_t>(lower.size())),
                       what + " order 1 from the order-2 record");
        }
      }
    }
  }
}

TEST(SecondOrderStorage, CellTabulationEqualsPerPointEvaluation) {
  const NodeSet nodes = set_for(2);
  const LmeBasis basis = second_order(nodes, 0.8);
  const int nq = 6;
  const auto pts = test::random_points(2, nq, 0.3, 0.6, 41);
  const CsrLists lists = basis.neighbour_lists(pts);
  std::set<int> uni(lists.indices.begin(), lists.indices.end());
  const std::vector<int> cell(uni.begin(), uni.end());
  const std::size_t n = cell.size(), jn = 6;
  std::vector<double> tab(nq * jn * n, -7.0);
  LmeWorkspace ws;
  basis.tabulate_cell(pts, cell, 2, tab, ws);
  for (int q = 0; q < nq; ++q) {
    const auto ref = basis.evaluate(std::span<const double>(pts).subspan(static_cast<std::size_t>(2 * q), 2), cell, 2);
    EXPECT_EQ(std::vector<double>(tab.begin() + static_cast<std::ptrdiff_t>(q * jn * n),
                                  tab.begin() + static_cast<std::ptrdiff_t>((q + 1) * jn * n)),
              ref);
  }
  // The compressed storage refuses a basis of the other order.
  const LmeCompressedStorage comp(basis, pts, lists, 2);
  const LmeBasis first(nodes, std::vector<double>{0.8});
  std::vector<double> out(jn * lists[0].size());
  EXPECT_THROW(comp.point_jet(first, 0, 2, out, ws), std::invalid_argument);
}

// ---- refusals ---------------------------------------------------------------------------------

TEST(SecondOrderRefusals, GammaOutOfRangeNamesTheNodeAndTheFix) {
  const NodeSet nodes = set_for(2);
  std::vector<double> gamma(nodes.size(), 0.8);
  gamma[17] = 1.8;
  LmeOptions o;
  o.consistency = LmeConsistency::second;
  try {
    (void)LmeBasis(nodes, gamma, o);
    FAIL() << "accepted gamma 1.8";
  } catch (const std::invalid_argument& e) {
    const std::string what = e.what();
    EXPECT_NE(what.find("node 17"), std::string::npos) << what;
    EXPECT_NE(what.find("gamma <= 1"), std::string::npos) << what;
    EXPECT_NE(what.find("first-order basis"), std::string::npos) << what;
  }
  EXPECT_NO_THROW((void)LmeBasis(nodes, gamma));  // the first-order basis takes it
}

TEST(SecondOrderRefusals, InfeasibleSecondMomentsNameThePointAndTheFix) {
  // Only nodes 2h or farther from x: x is inside their hull, but no weights on them have a second
  // moment as small as the gap.
  const NodeSet nodes = test::grid(2, 11, 1.0);
  const LmeBasis basis = second_order(nodes, 0.8);
  const std::vector<double> x = {0.5, 0.5};
  std::vector<int> far;
  for (const int a : basis.neighbours(x)) {
    const auto xa = nodes.point(static_cast<std::size_t>(a));
    if (std::hypot(xa[0] - 0.5, xa[1] - 0.5) > 0.19) far.push_back(a);
  }
  try {
    (void)basis.evaluate(x, far, 0);
    FAIL() << "no error";
  } catch (const LmeEvaluationError& e) {
    const std::string what = e.what();
    EXPECT_EQ(e.reason(), LmeFailure::infeasible_second_moment) << what;
    EXPECT_NE(what.find("x = (0.5, 0.5)"), std::string::npos) << what;
    EXPECT_NE(what.find("smaller gamma"), std::string::npos) << what;
  }
}

TEST(SecondOrderRefusals, NeighboursOnOneCircleAreNamedAsSuch) {
  // Sixteen nodes on one circle round x: their second moments are dependent (every node has the
  // same |x - x_a|² and the same gap), so no second-order basis exists there. The geometry is
  // checked only when the solve fails, and the message names the conic, not the failed solve.
  std::vector<double> coords;
  const double pi = std::numbers::pi;
  for (int k = 0; k < 16; ++k) {
    coords.push_back(0.5 + 0.3 * std::cos(2 * pi * k / 16));
    coords.push_back(0.5 + 0.3 * std::sin(2 * pi * k / 16));
  }
  const NodeSet nodes(2, coords);
  const LmeBasis basis = second_order(nodes, 0.8);
  std::vector<int> all(16);
  for (int a = 0; a < 16; ++a) all[static_cast<std::size_t>(a)] = a;
  const std::vector<double> x = {0.5, 0.5};
  for (const int order : {0, 2}) {
    try {
      (void)basis.evaluate(x, all, order);
      FAIL() << "no error at order " << order;
    } catch (const LmeEvaluationError& e) {
      EXPECT_EQ(e.reason(), LmeFailure::degenerate) << e.what();
      EXPECT_NE(std::string(e.what()).find("one conic"), std::string::npos) << e.what();
    }
  }
}

TEST(SecondOrderRefusals, TooFewNeighboursForTheQuadraticConstraints) {
  const NodeSet nodes = test::grid(2, 11, 1.0);
  const LmeBasis basis = second_order(nodes, 0.8);
  const std::vector<double> x = {0.52, 0.47};
  const std::vector<int> five = {48, 49, 59, 60, 61};
  try {
    (void)basis.evaluate(x, five, 0);
    FAIL() << "no error";
  } catch (const LmeEvaluationError& e) {
    EXPECT_EQ(e.reason(), LmeFailure::too_few_neighbours) << e.what();
    EXPECT_NE(std::string(e.what()).find("needs 6"), std::string::npos) << e.what();
  }
}

TEST(SecondOrderRefusals, ConsistencyNames) {
  EXPECT_EQ(parse_lme_consistency("first"), LmeConsistency::first);
  EXPECT_EQ(parse_lme_consistency("second"), LmeConsistency::second);
  EXPECT_EQ(parse_lme_consistency(to_string(LmeConsistency::second)), LmeConsistency::second);
  try {
    (void)parse_lme_consistency("third");
    FAIL() << "accepted \"third\"";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("\"second\""), std::string::npos) << e.what();
  }
}

// ---- what it is for: Hessians that converge ---------------------------------------------------

// Max Hessian error of sum_a p_a c_a for sin(pi x) sin(pi y) at points of [0.25, 0.75]^2, with
// c_a = f(x_a) (gap-corrected for the second order).
double hessian_error(const NodeSet& nodes, LmeConsistency consistency, double gamma) {
  const double pi = std::numbers::pi;
  LmeOptions o;
  o.consistency = consistency;
  const LmeBasis basis(nodes, std::vector<double>{gamma}, o);
  std::vector<double> v(nodes.size()), hf(3 * nodes.size());
  for (std::size_t a = 0; a < nodes.size(); ++a) {
    const double x = nodes.coords[2 * a], y = nodes.coords[2 * a + 1];
    v[a] = std::sin(pi * x) * std::sin(pi * y);
    hf[3 * a] = hf[3 * a + 2] = -pi * pi * v[a];
    hf[3 * a + 1] = pi * pi * std::cos(pi * x) * std::cos(pi * y);
  }
  const auto c = basis.gap_corrected(v, hf);
  const auto pts = test::random_points(2, 40, 0.25, 0.75, 3);
  double worst = 0.0;
  for (int q = 0; q < 40; ++q) {
    const std::vector<double> x = {pts[2 * q], pts[2 * q + 1]};
    const auto nbrs = basis.neighbours(x);
    const auto jet = basis.evaluate(x, nbrs, 2);
    const std::size_t n = nbrs.size();
    double hxx = 0, hxy = 0;
    for (std::size_t a = 0; a < n; ++a) {
      hxx += jet[3 * n + a] * c[static_cast<std::size_t>(nbrs[a])];
      hxy += jet[4 * n + a] * c[static_cast<std::size_t>(nbrs[a])];
    }
    const double sx = std::sin(pi * x[0]), sy = std::sin(pi * x[1]);
    worst = std::max({worst, std::abs(hxx + pi * pi * sx * sy),
                      std::abs(hxy - pi * pi * std::cos(pi * x[0]) * std::cos(pi * x[1]))});
  }
  return worst / (pi * pi);
}

TEST(SecondOrder, HessiansConvergeWhereTheFirstOrderOnesStall) {
  // A jittered grid (0.3 h), gamma 0.8, h = 0.1, 0.05, 0.025 (bench_basis_approximation has the tables).
  std::vector<double> first, second;
  for (const double h : {0.1, 0.05, 0.025}) {
    const Box box = Box::unit(2);
    const NodeSet nodes = jitter_interior(uniform_grid(box, h), box, 0.3 * h, 11);
    first.push_back(hessian_error(nodes, LmeConsistency::first, 0.8));
    second.push_back(hessian_error(nodes, LmeConsistency::second, 0.8));
  }
  EXPECT_GT(first.back(), 0.2) << "the first-order floor";
  EXPECT_GT(first.back(), 0.5 * first.front());
  EXPECT_LT(second.back(), 0.5 * second.front());
  EXPECT_LT(second.back(), 0.05);
}

}  // namespace
}  // namespace lmeform
