// FD / Taylor checks of every generated form (project rule, issue 3): on cells of a graded 2D
// node set with the real LME basis (tests/forms/test_cells.hpp), random states (phase fields near
// +-1 with a tanh interface plus noise; non-identity deformations with det F well away from 0),
// the generated gradient matches central differences of the value, the Hessian matches central
// differences of the gradient, and the Taylor remainders fall at orders 2 and 3.
// Cross-checks: generated kernels against the hand-written integrands; Lagrangian forms at y = x
// against their Eulerian counterparts; the dissipation Hessian against the seed's K(y) formula.
#include "handwritten_integrands.hpp"
#include "jet_kernel.hpp"
#include "test_cells.hpp"

#include <lmeform/form_check.hpp>
#include <lmeform/form_check_setup.hpp>

#include <area_axisymmetric_kernels.hpp>
#include <area_kernels.hpp>
#include <area_lagrangian_axisymmetric_kernels.hpp>
#include <area_lagrangian_kernels.hpp>
#include <dissipation_axisymmetric_kernels.hpp>
#include <dissipation_kernels.hpp>
#include <helfrich_axisymmetric_kernels.hpp>
#include <helfrich_kernels.hpp>
#include <helfrich_lagrangian_axisymmetric_kernels.hpp>
#include <helfrich_lagrangian_kernels.hpp>
#include <moment_axisymmetric_kernels.hpp>
#include <moment_kernels.hpp>
#include <poisson_kernels.hpp>
#include <volume_axisymmetric_kernels.hpp>
#include <volume_kernels.hpp>
#include <volume_lagrangian_axisymmetric_kernels.hpp>
#include <volume_lagrangian_kernels.hpp>

#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <map>
#include <string>

namespace fc = lmeform::formcheck;
namespace hand = lmeform::formcheck::hand;
namespace tc = lmeform::formcheck::testing;
using lmeform::kernel::FormKernels;

namespace {

constexpr double kEps = 0.08;  // interface width of the test phase fields (>= 2 h_min)
constexpr double kR = 0.3;     // circle / sphere radius
constexpr double kCy = 0.45;

bool axisymmetric(const FormKernels& f) { return std::string(f.module).find("axisymmetric") != std::string::npos; }

double constant_value(const std::string& name) {
  static const std::map<std::string, double> values = {
      {"k", 1.0}, {"eps", kEps}, {"C0", 0.6}, {"A0", 1.0}, {"V0", 0.5}, {"M0", 0.0},
      {"zc", 0.4}, {"mu", 1.0}, {"lambda", 2.5}};
  const auto it = values.find(name);
  if (it == values.end()) throw std::invalid_argument("test_forms: no test value for constant '" + name + "'");
  return it->second;
}

/// Polynomial degree of each functional in its unknown.
fc::Degree degree(const FormKernels& f) {
  const std::string m = f.module;
  if (m == "poisson" || m == "dissipation" || m == "dissipation_axisymmetric") return fc::Degree::quadratic;
  if (m == "volume" || m == "volume_axisymmetric" || m == "moment" || m == "moment_axisymmetric") return fc::Degree::linear;
  if (m == "volume_lagrangian") return fc::Degree::quadratic;  // (1+phi0)/2 det F: det of a 2x2 F is quadratic in y
  return fc::Degree::nonlinear;
}

struct Case {
  fc::Cell cell;
  fc::State state;
  std::vector<double> direction;
  fc::Options options;
};

/// State for form f on cell `cell`: unknowns, coefficients, qdata and constants by their names.
Case make_case(const FormKernels& f, const fc::Cell& cell, std::mt19937_64& rng) {
  Case c;
  c.cell = cell;
  const double cx = axisymmetric(f) ? 0.0 : 0.45;
  for (int i = 0; i < f.n_constants; ++i) c.state.constants.push_back(constant_value(f.constants[i]));
  const int ndof = cell.n * f.dofs_per_node;
  if (f.dofs_per_node == 1) {
    // phase field (or temperature) near +-1 with a tanh interface plus noise
    c.state.unknowns = tc::phase_field(cell, cx, kCy, kR, kEps, 0.05, rng);
    c.direction = fc::random_vector(static_cast<std::size_t>(ndof), 1.0, rng);
    c.options.taylor_h0 = 0.05;
  } else if (f.coefficient_components_per_node == 2) {
    // dissipation: unknown velocity v, coefficient deformation y
    c.state.unknowns = fc::random_vector(static_cast<std::size_t>(ndof), 1.0, rng);
    c.state.coefficients = tc::deformation(cell, rng);
    c.direction = fc::random_vector(static_cast<std::size_t>(ndof), 1.0, rng);
    c.options.taylor_h0 = 0.5;
  } else {
    // Lagrangian: unknown deformation y, reference phase field data at the quadrature points
    c.state.unknowns = tc::deformation(cell, rng);
    c.state.qdata = fc::reference_qdata(cell, tc::phase_field(cell, cx, kCy, kR, kEps, 0.02, rng));
    c.direction = fc::random_vector(static_cast<std::size_t>(ndof), 0.03, rng);  // ~ nodal spacing
    c.options.taylor_h0 = 0.1;
    c.options.fd_step = 1e-7;
  }
  c.options.expect_degree = degree(f);
  return c;
}

struct Setups {
  const fc::CheckGeometry& cartesian = tc::test_geometry(0.45, kCy, kR);
  const fc::CheckGeometry& axi = tc::test_geometry(0.0, kCy, kR);
};
Setups& setups() {
  static Setups s;
  return s;
}

/// Two cells per form: on the interface, and (axisymmetric) near the axis / (Cartesian) inside.
std::vector<fc::Cell> cells_for(const FormKernels& f) {
  const fc::CheckGeometry& s = axisymmetric(f) ? setups().axi : setups().cartesian;
  const double cx = axisymmetric(f) ? 0.0 : 0.45;
  std::vector<std::array<double, 2>> at = {{cx + kR * 0.8, kCy + kR * 0.6}};
  at.push_back(axisymmetric(f) ? std::array<double, 2>{0.06, kCy + kR} : std::array<double, 2>{0.5, 0.4});
  std::vector<fc::Cell> cells;
  for (const auto& p : at)
    cells.push_back(tc::cell_at(s, p[0], p[1], 2));
  return cells;
}

std::vector<const FormKernels*> all_2d() {
  std::vector<const FormKernels*> v;
  auto add = [&](const FormKernels* const* ks, int n) {
    for (int i = 0; i < n; ++i)
      if (ks[i]->dim == 2) v.push_back(ks[i]);
  };
  add(poisson_all_kernels, poisson_n_kernels);
  add(helfrich_all_kernels, helfrich_n_kernels);
  add(helfrich_axisymmetric_all_kernels, helfrich_axisymmetric_n_kernels);
  add(area_all_kernels, area_n_kernels);
  add(area_axisymmetric_all_kernels, area_axisymmetric_n_kernels);
  add(volume_all_kernels, volume_n_kernels);
  add(volume_axisymmetric_all_kernels, volume_axisymmetric_n_kernels);
  add(moment_all_kernels, moment_n_kernels);
  add(moment_axisymmetric_all_kernels, moment_axisymmetric_n_kernels);
  add(helfrich_lagrangian_all_kernels, helfrich_lagrangian_n_kernels);
  add(helfrich_lagrangian_axisymmetric_all_kernels, helfrich_lagrangian_axisymmetric_n_kernels);
  add(area_lagrangian_all_kernels, area_lagrangian_n_kernels);
  add(area_lagrangian_axisymmetric_all_kernels, area_lagrangian_axisymmetric_n_kernels);
  add(volume_lagrangian_all_kernels, volume_lagrangian_n_kernels);
  add(volume_lagrangian_axisymmetric_all_kernels, volume_lagrangian_axisymmetric_n_kernels);
  add(dissipation_all_kernels, dissipation_n_kernels);
  add(dissipation_axisymmetric_all_kernels, dissipation_axisymmetric_n_kernels);
  return v;
}

class GeneratedForm : public ::testing::TestWithParam<const FormKernels*> {};

}  // namespace

TEST_P(GeneratedForm, DerivativesMatchFiniteDifferencesAndTaylorOrders) {
  const FormKernels& f = *GetParam();
  ASSERT_TRUE(f.value && f.vector) << f.module << "::" << f.name << " lacks value/gradient kernels";
  if (f.kind == lmeform::kernel::FunctionalKind::Energy) {
    ASSERT_TRUE(f.matrix) << "energy without Hessian";
  }
  std::mt19937_64 rng(12345);
  int k = 0;
  for (const fc::Cell& cell : cells_for(f)) {
    Case c = make_case(f, cell, rng);
    const std::string label = std::string(f.module) + "::" + f.name + " cell " + std::to_string(k++) +
                              " (n=" + std::to_string(cell.n) + ")";
    if (f.dofs_per_node == 2) {
      const auto& y = f.coefficient_components_per_node == 2 ? c.state.coefficients : c.state.unknowns;
      const double detF = fc::min_det_grad(cell, y, 2, 0);
      std::printf("%s: min det F = %.3f\n", label.c_str(), detF);
      ASSERT_GT(detF, 0.5) << "test deformation too close to singular";
    }
    const fc::Report rep = fc::check_form(f, c.cell, c.state, c.direction, c.options);
    std::printf("%s\n", rep.summary(label).c_str());
    EXPECT_TRUE(rep.ok()) << rep.summary(label);
  }
}

TEST_P(GeneratedForm, StructurallyZeroFlagMatchesTheHessian) {
  // The runtime skips assembling a matrix flagged structurally zero, so the flag must be exact:
  // set exactly when the Hessian vanishes identically (a functional linear in its unknowns).
  const FormKernels& f = *GetParam();
  if (!f.matrix) GTEST_SKIP() << "no matrix kernel";
  std::mt19937_64 rng(777);
  double largest = 0;
  for (const fc::Cell& cell : cells_for(f)) {
    Case c = make_case(f, cell, rng);
    fc::Evaluator e(f, c.cell, c.state);
    for (const double h : e.matrix(c.state.unknowns)) largest = std::max(largest, std::abs(h));
  }
  if (f.matrix_structurally_zero) {
    EXPECT_EQ(largest, 0.0) << f.module << "::" << f.name << " is flagged structurally zero";
  } else {
    EXPECT_GT(largest, 0.0) << f.module << "::" << f.name << " has a zero Hessian but is not flagged";
  }
}

INSTANTIATE_TEST_SUITE_P(AllForms, GeneratedForm, ::testing::ValuesIn(all_2d()),
                         [](const ::testing::TestParamInfo<const FormKernels*>& p) {
                           return std::string(p.param->module) + "_" + p.param->name;
                         });

namespace {

/// Value, gradient and Hessian of two descriptors agree on one state (relative to their size).
void expect_same(const FormKernels& gen, const FormKernels& ref, const fc::Cell& cell, const fc::State& s,
                 double tol, const char* what) {
  fc::Evaluator a(gen, cell, s), b(ref, cell, s);
  const double Ea = a.value(s.unknowns), Eb = b.value(s.unknowns);
  EXPECT_NEAR(Ea, Eb, tol * std::max(1.0, std::abs(Eb))) << what << ": value";
  auto cmp = [&](const std::vector<double>& x, const std::vector<double>& y, const char* k) {
    double m = 0, e = 0;
    for (std::size_t i = 0; i < x.size(); ++i) { m = std::max(m, std::abs(y[i])); e = std::max(e, std::abs(x[i] - y[i])); }
    EXPECT_LE(e, tol * std::max(m, 1e-300)) << what << ": " << k << " max diff " << e << " of " << m;
  };
  cmp(a.vector(s.unknowns), b.vector(s.unknowns), "gradient");
  if (gen.matrix && ref.matrix) cmp(a.matrix(s.unknowns), b.matrix(s.unknowns), "Hessian");
}

}  // namespace

TEST(GeneratedForms, AgreeWithHandWrittenIntegrands) {
  std::mt19937_64 rng(99);
  const auto& cs = setups().cartesian;
  const auto& as = setups().axi;
  const fc::Cell cc = tc::cell_at(cs, 0.69, 0.63, 2);
  const fc::Cell ca = tc::cell_at(as, 0.24, 0.63, 2);
  fc::State s;
  s.unknowns = tc::phase_field(cc, 0.45, kCy, kR, kEps, 0.05, rng);
  expect_same(poisson_heat_2d, fc::make_form<hand::Poisson<2>>("p"), cc, s, 1e-12, "poisson");
  s.constants = {1.0, kEps, 0.6};
  expect_same(helfrich_bending_2d, fc::make_form<hand::Helfrich<2>>("h"), cc, s, 1e-12, "helfrich");
  fc::State sa = s;
  sa.constants = {kEps, 1.0};
  expect_same(area_area_2d, fc::make_form<hand::Area<2>>("a"), cc, sa, 1e-12, "area");
  fc::State sx;
  sx.unknowns = tc::phase_field(ca, 0.0, kCy, kR, kEps, 0.05, rng);
  sx.constants = {1.0, kEps, 0.6};
  expect_same(helfrich_axisymmetric_bending_2d, fc::make_form<hand::Helfrich<2, true>>("ha"), ca, sx, 1e-12,
              "helfrich_axisymmetric");
}

TEST(GeneratedForms, LagrangianAtIdentityEqualsEulerian) {
  // y = x (LME reproduces linear fields, so F = I and hess y = 0 up to the Newton tolerance) with
  // reference data interpolated by the same basis: E[y], A[y], V[y] equal E[phi0], A[phi0], V[phi0].
  std::mt19937_64 rng(5);
  for (bool axi : {false, true}) {
    const auto& st = axi ? setups().axi : setups().cartesian;
    const double cx = axi ? 0.0 : 0.45;
    const fc::Cell cell = tc::cell_at(st, cx + 0.24, 0.63, 2);
    const std::vector<double> phi0 = tc::phase_field(cell, cx, kCy, kR, kEps, 0.05, rng);
    fc::State lag, eul;
    lag.unknowns = cell.nodes;  // y_a = x_a
    lag.qdata = fc::reference_qdata(cell, phi0);
    eul.unknowns = phi0;
    const struct { const FormKernels* l; const FormKernels* e; std::vector<double> k; const char* name; } pairs[] = {
        {axi ? &helfrich_lagrangian_axisymmetric_bending_2d : &helfrich_lagrangian_bending_2d,
         axi ? &helfrich_axisymmetric_bending_2d : &helfrich_bending_2d, {1.0, kEps, 0.6}, "helfrich"},
        {axi ? &area_lagrangian_axisymmetric_area_2d : &area_lagrangian_area_2d,
         axi ? &area_axisymmetric_area_2d : &area_area_2d, {kEps, 1.0}, "area"},
        {axi ? &volume_lagrangian_axisymmetric_volume_2d : &volume_lagrangian_volume_2d,
         axi ? &volume_axisymmetric_volume_2d : &volume_volume_2d, {0.5}, "volume"}};
    for (const auto& p : pairs) {
      lag.constants = eul.constants = p.k;
      fc::Evaluator el(*p.l, cell, lag), ee(*p.e, cell, eul);
      const double a = el.value(lag.unknowns), b = ee.value(eul.unknowns);
      std::printf("%s%s: Lagrangian(y = x) %.15e  Eulerian %.15e\n", p.name, axi ? " (axisymmetric)" : "", a, b);
      EXPECT_NEAR(a, b, 1e-9 * std::max(1.0, std::abs(b))) << p.name << (axi ? " axisymmetric" : "");
    }
  }
}

TEST(GeneratedForms, DissipationHessianIsTheSeedMatrixK) {
  // K_{ai,bj} = int [mu (delta_ij Fi_Ik d_I p_a Fi_Jk d_J p_b + Fi_Ij d_I p_a Fi_Ji d_J p_b)
  //                  + lambda Fi_Ii d_I p_a Fi_Jj d_J p_b] det F     (seed 1807-1830)
  std::mt19937_64 rng(8);
  const auto& st = setups().cartesian;
  const fc::Cell cell = tc::cell_at(st, 0.6, 0.5, 2);
  fc::State s;
  s.unknowns = fc::random_vector(static_cast<std::size_t>(2 * cell.n), 1.0, rng);
  s.coefficients = tc::deformation(cell, rng);
  const double mu = 1.3, lam = 2.5;
  s.constants = {mu, lam};
  fc::Evaluator ev(dissipation_dissipation_2d, cell, s);
  const std::vector<double> H = ev.matrix(s.unknowns);
  const int n = cell.n, N = 2 * n, Js = lmeform::kernel::jet_size(2, cell.basis_order);
  std::vector<double> K(static_cast<std::size_t>(N) * N, 0.0);
  for (int q = 0; q < cell.nq; ++q) {
    double F[2][2];
    for (int i = 0; i < 2; ++i)
      for (int I = 0; I < 2; ++I) F[i][I] = cell.jet(q, 1 + I, s.coefficients.data(), 2, i);
    const double det = F[0][0] * F[1][1] - F[0][1] * F[1][0];
    const double Fi[2][2] = {{F[1][1] / det, -F[0][1] / det}, {-F[1][0] / det, F[0][0] / det}};
    auto gp = [&](int a, int I) { return cell.basis[(static_cast<std::size_t>(q) * Js + 1 + I) * n + a]; };
    for (int a = 0; a < n; ++a)
      for (int b = 0; b < n; ++b) {
        double ga[2] = {0, 0}, gb[2] = {0, 0};  // (grad p F^-1)_k = d_I p Fi_Ik
        for (int k = 0; k < 2; ++k)
          for (int I = 0; I < 2; ++I) { ga[k] += gp(a, I) * Fi[I][k]; gb[k] += gp(b, I) * Fi[I][k]; }
        for (int i = 0; i < 2; ++i)
          for (int j = 0; j < 2; ++j) {
            const double Kmu = (i == j ? ga[0] * gb[0] + ga[1] * gb[1] : 0.0) + ga[j] * gb[i];
            const double Klam = ga[i] * gb[j];
            K[static_cast<std::size_t>(2 * a + i) * N + 2 * b + j] += cell.weights[q] * (mu * Kmu + lam * Klam) * det;
          }
      }
  }
  double e = 0, m = 0;
  for (std::size_t i = 0; i < K.size(); ++i) { m = std::max(m, std::abs(K[i])); e = std::max(e, std::abs(K[i] - H[i])); }
  std::printf("dissipation: max |H - K(y)| = %.3e (max |K| = %.3e)\n", e, m);
  EXPECT_LE(e, 1e-12 * m);
}

#include "../bench/naive_kernels.hpp"

TEST(GeneratedForms, NaiveThesisStyleHessiansAgree) {
  // The hand-written per-node-pair Hessians of bench_kernels (App. A / App. B formulas) against
  // the generated kernels: same cell, same inputs, agreement to 1e-10 (relative to max |H|).
  std::mt19937_64 rng(17);
  struct Item { const FormKernels* gen; lmeform::kernel::MatrixKernel naive; bool axi; };
  const Item items[] = {{&helfrich_axisymmetric_bending_2d, &lmeform::naive::helfrich_axisymmetric_hessian, true},
                        {&helfrich_lagrangian_bending_2d, &lmeform::naive::helfrich_lagrangian_hessian, false}};
  for (const Item& it : items) {
    const auto& st = it.axi ? setups().axi : setups().cartesian;
    const double cx = it.axi ? 0.0 : 0.45;
    const fc::Cell cell = tc::cell_at(st, cx + 0.24, 0.63, 2);
    Case c = make_case(*it.gen, cell, rng);
    FormKernels naive = *it.gen;
    naive.matrix = it.naive;
    fc::Evaluator eg(*it.gen, cell, c.state), en(naive, cell, c.state);
    const auto Hg = eg.matrix(c.state.unknowns), Hn = en.matrix(c.state.unknowns);
    double e = 0, m = 0;
    for (std::size_t i = 0; i < Hg.size(); ++i) { m = std::max(m, std::abs(Hg[i])); e = std::max(e, std::abs(Hg[i] - Hn[i])); }
    std::printf("%s: max |H_generated - H_naive| = %.3e of max |H| = %.3e\n", it.gen->module, e, m);
    EXPECT_LE(e, 1e-10 * m) << it.gen->module;
  }
}
