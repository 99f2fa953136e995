// Validates the derivative checker itself with hand-written kernels that follow kernel.hpp:
// correct kernels must pass with the expected Taylor slopes, and deliberately broken ones must fail.
#include "handwritten_integrands.hpp"
#include "jet_kernel.hpp"
#include "test_cells.hpp"

#include <lmeform/form_check.hpp>
#include <lmeform/form_check_setup.hpp>

#include <gtest/gtest.h>

#include <cstdio>

namespace fc = lmeform::formcheck;
namespace hand = lmeform::formcheck::hand;
namespace tc = lmeform::formcheck::testing;

namespace {

struct Fixture {
  const fc::CheckGeometry& geometry = tc::test_geometry();
  std::mt19937_64 rng{2024};
  [[nodiscard]] fc::Cell cell_at(double x, double y, int order) const { return tc::cell_at(geometry, x, y, order); }
};

fc::Report run(const lmeform::kernel::FormKernels& f, const fc::Cell& cell, const fc::State& s,
               const std::vector<double>& v, const fc::Options& o, const char* label) {
  fc::Report r = fc::check_form(f, cell, s, v, o);
  std::printf("%s\n", r.summary(label).c_str());
  return r;
}

}  // namespace

TEST(FormCheckHarness, PoissonIsQuadratic) {
  Fixture fx;
  const fc::Cell cell = fx.cell_at(0.3, 0.4, 1);
  fc::State s;
  s.unknowns = fc::random_vector(cell.n, 1.0, fx.rng);
  fc::Options o;
  o.expect_degree = fc::Degree::quadratic;
  const auto rep = run(fc::make_form<hand::Poisson<2>>("poisson"), cell, s, fc::random_vector(cell.n, 1.0, fx.rng),
                       o, "hand poisson");
  EXPECT_TRUE(rep.ok()) << rep.summary("poisson");
  EXPECT_NEAR(rep.r1.slope, 2.0, 0.05);
}

TEST(FormCheckHarness, LinearFunctionalIsExact) {
  Fixture fx;
  const fc::Cell cell = fx.geometry.cell(10, 0);
  fc::State s;
  s.unknowns = fc::random_vector(cell.n, 1.0, fx.rng);
  fc::Options o;
  o.expect_degree = fc::Degree::linear;
  const auto rep = run(fc::make_form<hand::HalfValue<2>>("half"), cell, s, fc::random_vector(cell.n, 1.0, fx.rng), o,
                       "hand volume-like");
  EXPECT_TRUE(rep.ok()) << rep.summary("half");
  // The same linear functional declared nonlinear must be flagged (no slope can be fitted).
  o.expect_degree = fc::Degree::nonlinear;
  EXPECT_FALSE(fc::check_form(fc::make_form<hand::HalfValue<2>>("half"), cell, s,
                              fc::random_vector(cell.n, 1.0, fx.rng), o).ok());
}

TEST(FormCheckHarness, HelfrichCartesianAndAxisymmetric) {
  Fixture fx;
  const double eps = 0.08;
  for (bool axi : {false, true}) {
    // Cells on the interface of a circle (Cartesian) / a sphere centred on the axis (axisymmetric).
    const double cx = axi ? 0.0 : 0.45, cy = 0.45, R = 0.3;
    const fc::Cell cell = fx.cell_at(cx + R * 0.8, cy + R * 0.6, 2);
    fc::State s;
    s.unknowns = tc::phase_field(cell, cx, cy, R, eps, 0.05, fx.rng);
    s.constants = {1.0, eps, 0.7};
    fc::Options o;
    o.taylor_h0 = 0.1;
    const auto v = fc::random_vector(cell.n, 1.0, fx.rng);
    const auto f = axi ? fc::make_form<hand::Helfrich<2, true>>("helfrich_axi")
                       : fc::make_form<hand::Helfrich<2, false>>("helfrich");
    const auto rep = run(f, cell, s, v, o, axi ? "hand helfrich axisymmetric" : "hand helfrich cartesian");
    EXPECT_TRUE(rep.ok()) << rep.summary("helfrich");
  }
}

TEST(FormCheckHarness, AreaNonlinear) {
  Fixture fx;
  const fc::Cell cell = fx.cell_at(0.6, 0.5, 1);
  fc::State s;
  s.unknowns = tc::phase_field(cell, 0.45, 0.45, 0.2, 0.08, 0.05, fx.rng);
  s.constants = {0.08, 1.0};
  const auto rep = run(fc::make_form<hand::Area<2>>("area"), cell, s, fc::random_vector(cell.n, 1.0, fx.rng),
                       fc::Options{}, "hand area");
  EXPECT_TRUE(rep.ok()) << rep.summary("area");
}

TEST(FormCheckHarness, VectorUnknownInterleaving) {
  Fixture fx;
  const fc::Cell cell = fx.cell_at(0.5, 0.5, 1);
  fc::State s;
  s.unknowns = tc::deformation(cell, fx.rng);
  s.constants = {1.0, 3.0};
  const double detF = fc::min_det_grad(cell, s.unknowns, 2, 0);
  std::printf("vector cell: n = %d, min det F = %.3f\n", cell.n, detF);
  ASSERT_GT(detF, 0.3);
  fc::Options o;
  o.taylor_h0 = 0.02;  // direction of size ~1 per dof: keep the map injective
  const auto rep = run(fc::make_form<hand::NeoHooke2>("neohooke"), cell, s, fc::random_vector(2 * cell.n, 1.0, fx.rng),
                       o, "hand neo-Hooke (vector)");
  EXPECT_TRUE(rep.ok()) << rep.summary("neohooke");
}

TEST(FormCheckHarness, DetectsWrongHessianAndGradient) {
  Fixture fx;
  const double eps = 0.08;
  const fc::Cell cell = fx.cell_at(0.69, 0.63, 2);
  fc::State s;
  s.unknowns = tc::phase_field(cell, 0.45, 0.45, 0.3, eps, 0.05, fx.rng);
  s.constants = {1.0, eps, 0.0};
  const auto v = fc::random_vector(cell.n, 1.0, fx.rng);
  fc::Options o;
  const auto bad_h = run(fc::make_form<hand::Helfrich<2, false, 1>>("bad_hessian"), cell, s, v, o, "broken Hessian");
  EXPECT_FALSE(bad_h.ok());
  EXPECT_GT(bad_h.hess_err, o.hess_tol);
  EXPECT_LT(bad_h.grad_err, o.grad_tol);              // the gradient is right
  EXPECT_NEAR(bad_h.r2.slope, 2.0, 0.3);              // the Hessian remainder degrades to order 2
  const auto bad_g = run(fc::make_form<hand::Helfrich<2, false, 2>>("bad_gradient"), cell, s, v, o, "broken gradient");
  EXPECT_FALSE(bad_g.ok());
  EXPECT_GT(bad_g.grad_err, o.grad_tol);
}
