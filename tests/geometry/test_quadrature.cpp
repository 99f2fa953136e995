// Quadrature rules: exactness up to the claimed degree (checked against closed-form simplex moments,
// independent of the library's own solve), tightness of the degree, weights, points inside the cell,
// and the mapping onto background cells.
#include <gtest/gtest.h>

#include <cmath>
#include <string>
#include <vector>

#include "lmeform/delaunay.hpp"
#include "lmeform/node_sets.hpp"
#include "lmeform/quadrature.hpp"

namespace {

using namespace lmeform;

double factorial(int n) {
  double f = 1;
  for (int i = 2; i <= n; ++i) f *= i;
  return f;
}

// Integral of x^i y^j z^k over the reference simplex of dimension dim (the unused exponents are zero).
double exact_moment(int dim, int i, int j, int k) {
  return factorial(i) * factorial(j) * factorial(k) / factorial(i + j + k + dim);
}

double rule_moment(const QuadratureRule& r, int i, int j, int k) {
  double s = 0;
  for (std::size_t q = 0; q < r.size(); ++q) {
    const auto x = r.point(q);
    double v = std::pow(x[0], i);
    if (r.dim >= 2) v *= std::pow(x[1], j);
    if (r.dim >= 3) v *= std::pow(x[2], k);
    s += r.weights[q] * v;
  }
  return s;
}

// Largest relative moment error over the monomials of total degree exactly `deg`.
double max_error_at_degree(const QuadratureRule& r, int deg) {
  double worst = 0;
  for (int i = 0; i <= deg; ++i)
    for (int j = 0; j <= (r.dim >= 2 ? deg - i : 0); ++j) {
      const int k = deg - i - j;
      if (r.dim == 1 && i != deg) continue;
      if (r.dim == 2 && k != 0) continue;
      const double e = exact_moment(r.dim, i, r.dim >= 2 ? j : 0, r.dim >= 3 ? k : 0);
      const double q = rule_moment(r, i, r.dim >= 2 ? j : 0, r.dim >= 3 ? k : 0);
      worst = std::max(worst, std::abs(q - e) / e);
    }
  return worst;
}

bool inside_reference(const QuadratureRule& r, std::size_t q) {
  const auto x = r.point(q);
  double s = 0;
  for (double xi : x) {
    if (xi < 0) return false;
    s += xi;
  }
  return r.dim == 1 ? x[0] <= 1 : s <= 1;
}

void check_rule(const QuadratureRule& r) {
  SCOPED_TRACE(r.name);
  ASSERT_EQ(r.points.size(), r.size() * static_cast<std::size_t>(r.dim));
  double wsum = 0;
  for (double w : r.weights) wsum += w;
  EXPECT_NEAR(wsum, reference_measure(r.dim), 1e-15);
  for (int deg = 0; deg <= r.degree; ++deg) EXPECT_LT(max_error_at_degree(r, deg), 1e-13) << "degree " << deg;
  // The claimed degree is tight: some polynomial of degree + 1 is integrated wrongly. In 1D the
  // monomial x^(2n) on [0, 1] is integrated too well to tell for large n; (2x - 1)^(2n) is not.
  if (r.dim == 1) {
    double q = 0;
    for (std::size_t i = 0; i < r.size(); ++i) q += r.weights[i] * std::pow(2 * r.points[i] - 1, r.degree + 1);
    const double exact = 1.0 / (r.degree + 2);
    EXPECT_GT(std::abs(q - exact) / exact, 1e-8) << "exact beyond the claimed degree " << r.degree;
  } else {
    EXPECT_GT(max_error_at_degree(r, r.degree + 1), 1e-8) << "exact beyond the claimed degree " << r.degree;
  }
  for (std::size_t q = 0; q < r.size(); ++q) EXPECT_TRUE(inside_reference(r, q)) << "point " << q << " outside the reference cell";
}

TEST(Quadrature, TriangleRulesExactAndTight) {
  const auto sizes = triangle_rule_sizes();
  EXPECT_EQ(sizes, (std::vector<int>{1, 3, 6, 7, 12, 16, 19}));
  const std::vector<int> degrees{1, 2, 4, 5, 6, 8, 9};
  for (std::size_t k = 0; k < sizes.size(); ++k) {
    const auto r = triangle_rule(sizes[k]);
    EXPECT_EQ(r.dim, 2);
    EXPECT_EQ(static_cast<int>(r.size()), sizes[k]);
    EXPECT_EQ(r.degree, degrees[k]);
    EXPECT_FALSE(r.has_negative_weights()) << r.name;
    check_rule(r);
  }
}

TEST(Quadrature, TetrahedronRulesExactAndTight) {
  const auto sizes = tetrahedron_rule_sizes();
  EXPECT_EQ(sizes, (std::vector<int>{1, 4, 5, 11, 14, 15, 24}));
  const std::vector<int> degrees{1, 2, 3, 4, 5, 5, 6};
  for (std::size_t k = 0; k < sizes.size(); ++k) {
    const auto r = tetrahedron_rule(sizes[k]);
    EXPECT_EQ(r.dim, 3);
    EXPECT_EQ(static_cast<int>(r.size()), sizes[k]);
    EXPECT_EQ(r.degree, degrees[k]);
    EXPECT_EQ(r.has_negative_weights(), sizes[k] == 5 || sizes[k] == 11) << r.name;
    check_rule(r);
  }
}

TEST(Quadrature, ClosedFormRulesAgree) {
  // Rules with closed forms (Hammer-Stroud): an independent check of the solved digits.
  const auto t7 = triangle_rule(7);
  const double s15 = std::sqrt(15.0);
  std::vector<double> expected_w{9.0 / 80.0, (155.0 - s15) / 2400.0, (155.0 + s15) / 2400.0};
  std::vector<double> got;
  for (double w : t7.weights) got.push_back(w);
  std::sort(got.begin(), got.end());
  std::sort(expected_w.begin(), expected_w.end());
  // Weights are 1 x w0, 3 x w1, 3 x w2: compare the distinct values.
  got.erase(std::unique(got.begin(), got.end(), [](double a, double b) { return std::abs(a - b) < 1e-14; }), got.end());
  ASSERT_EQ(got.size(), 3U);
  for (std::size_t i = 0; i < 3; ++i) EXPECT_NEAR(got[i], expected_w[i], 1e-15);
  const auto t4 = tetrahedron_rule(4);
  const double a = (5.0 - std::sqrt(5.0)) / 20.0;
  for (std::size_t q = 0; q < 4; ++q) {
    EXPECT_NEAR(t4.weights[q], 1.0 / 24.0, 1e-16);
    int near_a = 0;
    for (double x : t4.point(q)) near_a += std::abs(x - a) < 1e-15;
    EXPECT_GE(near_a, 2);
  }
}

TEST(Quadrature, GaussLegendreOnUnitInterval) {
  for (int n = 1; n <= 12; ++n) {
    const auto r = gauss_legendre(n);
    EXPECT_EQ(r.degree, 2 * n - 1);
    check_rule(r);
  }
  EXPECT_THROW((void)gauss_legendre(0), std::invalid_argument);
}

TEST(Quadrature, SimplexRuleSelection) {
  EXPECT_EQ(simplex_rule(2, 3).size(), 6U);
  EXPECT_EQ(simplex_rule(2, 0).size(), 1U);
  EXPECT_EQ(simplex_rule(3, 3).size(), 14U);         // positive weights only by default
  EXPECT_EQ(simplex_rule(3, 3, false).size(), 5U);
  EXPECT_EQ(simplex_rule(3, 6).size(), 24U);
  EXPECT_EQ(simplex_rule(1, 5).size(), 3U);
  EXPECT_THROW((void)simplex_rule(2, 10), std::invalid_argument);
  EXPECT_THROW((void)simplex_rule(3, 7), std::invalid_argument);
  try {
    (void)triangle_rule(5);
    FAIL() << "no 5-point triangle rule exists";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("available: 1, 3, 6, 7, 12, 16, 19"), std::string::npos) << e.what();
  }
}

double integrate(const CellQuadrature& cq, auto&& f) {
  double s = 0;
  for (std::size_t q = 0; q < cq.size(); ++q) s += cq.weights[q] * f(cq.point(q));
  return s;
}

TEST(Quadrature, MappedOntoCells2D) {
  const Box box{2, {0.0, 0.0, 0.0}, {2.0, 1.0, 0.0}};
  const auto nodes = jitter_interior(uniform_grid(box, std::array<int, 3>{13, 8, 1}), box, 0.04, 3);
  const auto cells = delaunay(nodes);
  const auto cq = map_to_cells(cells, nodes, triangle_rule(7));
  ASSERT_EQ(cq.cells(), cells.size());
  // Degree 5 on [0,2]x[0,1]: integral of x^2 y^3 = (8/3)(1/4).
  EXPECT_NEAR(integrate(cq, [](auto x) { return x[0] * x[0] * x[1] * x[1] * x[1]; }), 2.0 / 3.0, 1e-13);
  EXPECT_NEAR(integrate(cq, [](auto) { return 1.0; }), 2.0, 1e-13);
  // Points are grouped by cell.
  for (std::size_t c = 0; c < cells.size(); ++c)
    for (int q = 0; q < cq.points_per_cell; ++q) {
      const auto l = barycentric(cells, nodes, c, cq.point(c * static_cast<std::size_t>(cq.points_per_cell) + static_cast<std::size_t>(q)));
      for (int k = 0; k < 3; ++k) ASSERT_GT(l[static_cast<std::size_t>(k)], 0.0) << "cell " << c << " point " << q;
    }
}

TEST(Quadrature, MappedOntoCells3DAnd1D) {
  const Box box{3, {0.0, 0.0, 0.0}, {1.0, 2.0, 1.0}};
  const auto nodes = jitter_interior(uniform_grid(box, std::array<int, 3>{5, 7, 4}), box, 0.05, 5);
  const auto cells = delaunay(nodes);
  const auto cq = map_to_cells(cells, nodes, tetrahedron_rule(14));
  // Degree 5: integral of x y^2 z^2 over [0,1]x[0,2]x[0,1] = (1/2)(8/3)(1/3).
  EXPECT_NEAR(integrate(cq, [](auto x) { return x[0] * x[1] * x[1] * x[2] * x[2]; }), 4.0 / 9.0, 1e-13);

  const auto line = random_points(Box{1, {-1.0, 0.0, 0.0}, {2.0, 0.0, 0.0}}, 30, 11);
  const auto segs = delaunay(line);
  const auto cq1 = map_to_cells(segs, line, gauss_legendre(3));
  double lo = 1e9, hi = -1e9;
  for (double x : line.coords) {
    lo = std::min(lo, x);
    hi = std::max(hi, x);
  }
  EXPECT_NEAR(integrate(cq1, [](auto x) { return std::pow(x[0], 5); }), (std::pow(hi, 6) - std::pow(lo, 6)) / 6.0, 1e-13);
  EXPECT_THROW((void)map_to_cells(cells, nodes, triangle_rule(3)), std::invalid_argument);
}

}  // namespace

namespace {

// The example of docs/geometry.md, verbatim in substance.
TEST(Quadrature, DocsExample) {
  using namespace lmeform;
  const Box box{2, {0.0, 0.0, 0.0}, {2.0, 1.0, 0.0}};
  const NodeSet nodes = jitter_interior(uniform_grid(box, 0.1), box, 0.02, 1);
  const BackgroundCells cells = delaunay(nodes);
  const CellQuadrature cq = map_to_cells(cells, nodes, simplex_rule(2, 4));
  EXPECT_EQ(cq.points_per_cell, 6);
  double integral = 0;
  for (std::size_t q = 0; q < cq.size(); ++q) {
    const auto x = cq.point(q);
    integral += cq.weights[q] * x[0] * x[0] * x[1] * x[1];
  }
  EXPECT_NEAR(integral, 8.0 / 9.0, 1e-13);
}

}  // namespace
