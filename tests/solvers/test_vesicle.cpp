// The axisymmetric phase-field vesicle through the generic path (a scene bound to the built-in
// forms, solve_problem), with the vesicle model's helpers.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <iostream>
#include <numbers>
#include <string>

#include "stationary.hpp"
#include "problem_registry.hpp"
#include "vesicle.hpp"
#include "vesicle.hpp"

namespace lmeform {
namespace {

constexpr double pi = std::numbers::pi;
constexpr double kR = 0.4;

std::string num(double v) {
  char buffer[32];
  std::snprintf(buffer, sizeof buffer, "%.17g", v);
  return buffer;
}

// A vesicle in the box [0, 0.8] x [0, 1.2] (centre z = 0.6), gamma 0.8, phi = -1 on the outer
// boundary; `constraints` is the [constraints] table.
struct SphereBox {
  double eps = 0.08;
  double spacing = 0.04;
  std::array<double, 2> semi_axes{kR, kR};
  std::string constraints;  // "" : none (the forms are still loaded, for their values)
  bool outer_boundary_fixed = true;  // phi = -1 on r_max, z_min, z_max
  std::string start = "kkt";         // [solver] start
  bool inertia_correction = true;    // [solver] inertia_correction

  [[nodiscard]] Scene scene() const {
    const std::string text = fmt_scene();
    return parse_scene(text, "sphere_box.toml", problems::driver_tables());
  }
  [[nodiscard]] std::string fmt_scene() const {
    return "[scene]\nname = \"sphere\"\ncoordinates = \"axisymmetric\"\n"
           "[domain]\nlower = [0.0, 0.0]\nupper = [0.8, 1.2]\n"
           "[nodes]\nspacing = " + num(spacing) + "\ngamma = 0.8\n"
           "[model]\nforms = [\"helfrich_axisymmetric\", \"area_axisymmetric\", \"volume_axisymmetric\", \"moment_axisymmetric\"]\n"
           "energy = \"bending\"\n"
           "[constants]\neps = " + num(eps) + "\n" +
           (constraints.empty() || constraints.find("moment") != std::string::npos ? "zc = 0.6\n" : "") +
           "[solver]\naugmented_tolerance = 1e-3\nstart = \"" + start + "\"\ninertia_correction = " +
           (inertia_correction ? "true" : "false") + "\n" +
           (constraints.empty() ? std::string() : "[constraints]\n" + constraints) +
           (outer_boundary_fixed ? "[[dirichlet]]\nboundary = [\"r_max\", \"z_min\", \"z_max\"]\nunknown = \"phi\"\nvalue = -1.0\n"
                                 : "");
  }
};

/// An ellipsoid start with semi-axes (a, c)·R in the box, eps 0.1, h 0.045, constrained to the
/// sphere's area, v times its volume, and zero moment.
SphereBox constrained_ellipsoid(double a, double c, double v) {
  SphereBox s;
  s.eps = 0.1;
  s.spacing = 0.045;
  s.semi_axes = {a * kR, c * kR};
  const double V0 = v * 4.0 / 3 * pi * kR * kR * kR;
  s.constraints = "area = " + num(4 * pi * kR * kR) + "\nvolume = " + num(V0) + "\nmoment = { target = 0.0, scale = " + num(V0) +
                  " }\n";
  return s;
}

/// The bound scene and the vesicle's initial profile for it.
struct Problem {
  Scene scene;
  problems::BoundScene bound;
  explicit Problem(const SphereBox& box) : scene(box.scene()), bound(problems::bind_scene(scene, PETSC_COMM_SELF, nullptr)) {}
  [[nodiscard]] problems::ProblemInput input(const SphereBox& box) const {
    problems::ProblemInput in;
    in.nodes = problems::initial_nodes(scene, PETSC_COMM_SELF);
    problems::VesicleModel model;
    model.eps = box.eps;
    model.center = {0.0, 0.6, 0.0};
    model.semi_axes = {box.semi_axes[0], box.semi_axes[1], 0.0};
    for (std::size_t a = 0; a < in.nodes.size(); ++a) in.initial.push_back(problems::initial_profile(model, in.nodes.point(a), 2));
    in.lme = problems::lme_options(scene, problems::AxisParity::even);
    return in;
  }
};

/// Energy, area, volume and moment of the initial tanh profile as it is (no solve, no boundary values).
struct Functionals {
  double energy, area, volume, moment;
};
Functionals evaluate(const SphereBox& box) {
  SphereBox all = box;
  all.outer_boundary_fixed = false;
  all.constraints = "area = 0.0\nvolume = 0.0\nmoment = 0.0\n";  // only to load and evaluate them
  const Problem p(all);
  problems::ProblemInput in = p.input(all);
  in.evaluate_only = true;
  const auto r = problems::solve_problem(PETSC_COMM_SELF, p.bound, in);
  return {r.values.at("helfrich_axisymmetric.bending"), r.values.at("area"), r.values.at("volume"), r.values.at("moment")};
}

// With the smooth γ = 0.8 basis the energy of a prescribed tanh sphere tends to 2π as h → 0 at
// fixed ε (larger γ has inconsistent basis Hessians: the energy plateaus above 2π), and area and
// volume differ from the sharp values by the diffuse interface's O(ε²) terms.
TEST(Vesicle, PrescribedTanhSphereMatchesSharpInterfaceValues) {
  SphereBox s;
  const double R = kR;
  double previous_error = 1e300;
  for (const double ratio : {2.0, 4.0}) {
    s.spacing = s.eps / ratio;
    const auto f = evaluate(s);
    const double error = std::abs(f.energy / (2 * pi) - 1);
    std::printf("tanh sphere eps %.3f h %.3f: E %.5f (2pi, rel %.2e)  A %.5f (sharp %.5f)  V %.5f (sharp %.5f)  M %.1e\n",
                s.eps, s.spacing, f.energy, error, f.area, 4 * pi * R * R, f.volume, 4.0 / 3 * pi * R * R * R, f.moment);
    EXPECT_LT(error, 0.5 * previous_error);  // converges in h
    // O(ε²/R²) diffuse-interface corrections (ε/R = 0.2 here).
    EXPECT_NEAR(f.area, 4 * pi * R * R, 0.05 * 4 * pi * R * R);
    EXPECT_NEAR(f.volume, 4.0 / 3 * pi * R * R * R, 0.25 * 4.0 / 3 * pi * R * R * R);
    EXPECT_NEAR(f.moment, 0.0, 1e-8);  // symmetric about z_c
    previous_error = error;
  }
  EXPECT_LT(previous_error, 0.01);
}

// v = 1 in the phase-field sense: the targets are the diffuse sphere's own area and volume. (The
// sharp values A = 4πR², V = 4πR³/3 are not jointly reachable by a diffuse sphere: its volume
// ½(|Ω| + ∫φ) exceeds the sharp one by ≈ 3.1 (ε/R)², so sharp targets force a deflated,
// non-spherical minimizer — the modelling error of ε, not a solver error.)
TEST(Vesicle, SphereConvergesToTwoPiWithinTheModellingError) {
  SphereBox s;
  const double R = kR;
  const auto diffuse = evaluate(s);
  s.constraints = "area = " + num(diffuse.area) + "\nvolume = " + num(diffuse.volume) +
                  "\nmoment = { target = 0.0, scale = " + num(diffuse.volume) + " }\n";
  s.semi_axes = {1.1 * R, 0.85 * R};  // start away from the sphere: the constraints must bring it back
  const Problem p(s);
  problems::ProblemInput in = p.input(s);
  in.log = &std::cout;
  const auto r = problems::solve_problem(PETSC_COMM_SELF, p.bound, in);
  const auto& result = r.minimization;
  const double error = result.energy / (2 * pi) - 1;
  std::printf("sphere: E = %.6f (2 pi = %.6f, rel %.3e; prescribed tanh profile %.6f), %zu nodes, AL %d, KKT %d, %.1f s, %s\n",
              result.energy, 2 * pi, error, diffuse.energy, r.nodes.size(), result.augmented_iterations,
              result.newton_iterations, r.seconds_solve, result.message.c_str());
  EXPECT_TRUE(result.converged) << result.message;
  for (const double residual : result.relative_residuals) EXPECT_LT(residual, 1e-8);
  // The minimizer does at least as well as the prescribed profile, and lands within the
  // discretization error of this coarse grid (ε/h = 2) from 2π.
  EXPECT_LT(result.energy, diffuse.energy * (1 + 1e-6));
  EXPECT_LT(std::abs(error), 0.06);
  // Newton on the KKT system converges superlinearly: the residual ratios shrink.
  std::vector<double> kkt;
  for (const auto& it : result.history) {
    if (it.stage == "KKT" && it.gradient_norm > 1e-11) kkt.push_back(it.gradient_norm);
  }
  ASSERT_GE(kkt.size(), 3u);
  const std::size_t m = kkt.size();
  const double last_ratio = kkt[m - 1] / kkt[m - 2], previous_ratio = kkt[m - 2] / kkt[m - 3];
  std::printf("KKT residual ratios: %.2e then %.2e\n", previous_ratio, last_ratio);
  EXPECT_LT(last_ratio, previous_ratio);
  EXPECT_LT(last_ratio, 1e-2);
}

TEST(Vesicle, RescaledInterfaceIsTheTanhProfileOfTheNewWidth) {
  // tanh(d / (sqrt2 eps_from)) re-profiled to eps_to is tanh(d / (sqrt2 eps_to)).
  std::vector<double> d, from;
  for (double x = -0.3; x <= 0.3; x += 0.01) {
    d.push_back(x);
    from.push_back(std::tanh(x / (std::sqrt(2.0) * 0.04)));
  }
  from.push_back(-1.0);  // a Dirichlet value stays -1
  d.push_back(-1.0);
  const auto to = problems::rescale_interface(from, 0.04, 0.025);
  for (std::size_t i = 0; i + 1 < d.size(); ++i) EXPECT_NEAR(to[i], std::tanh(d[i] / (std::sqrt(2.0) * 0.025)), 1e-12);
  EXPECT_EQ(to.back(), -1.0);
  EXPECT_THROW((void)problems::rescale_interface(from, 0.0, 0.025), std::invalid_argument);
}

TEST(Vesicle, WarmStartedMultipliersSaveIterations) {
  // A continuation (eps 0.1 -> 0.09 on the same grid) from the previous solution, augmented
  // Lagrangian first: starting from the previous multipliers converges in fewer augmented-Lagrangian
  // steps than starting from zero.
  SphereBox s = constrained_ellipsoid(1.1, 0.85, 0.95);
  s.start = "augmented";
  const Problem p(s);
  problems::ProblemInput in = p.input(s);
  const auto first = problems::solve_problem(PETSC_COMM_SELF, p.bound, in);
  ASSERT_TRUE(first.converged) << first.message;
  in.constants["eps"] = 0.09;
  in.nodes = first.nodes;
  in.initial = problems::rescale_interface(first.state, 0.1, 0.09);
  in.initial_multipliers.assign(first.minimization.multipliers.size(), 0.0);
  const auto cold = problems::solve_problem(PETSC_COMM_SELF, p.bound, in);
  in.initial_multipliers = first.minimization.multipliers;
  const auto warm = problems::solve_problem(PETSC_COMM_SELF, p.bound, in);
  std::printf("continuation: cold start %d AL + %d KKT, warm start %d AL + %d KKT; E %.8f vs %.8f\n",
              cold.minimization.augmented_iterations, cold.minimization.newton_iterations,
              warm.minimization.augmented_iterations, warm.minimization.newton_iterations, cold.energy, warm.energy);
  ASSERT_TRUE(cold.converged && warm.converged);
  EXPECT_LT(warm.minimization.augmented_iterations, cold.minimization.augmented_iterations);
  EXPECT_NEAR(warm.energy, cold.energy, 1e-6 * cold.energy);  // the same minimizer
  in.initial_multipliers = {1.0};
  EXPECT_THROW((void)problems::solve_problem(PETSC_COMM_SELF, p.bound, in), std::invalid_argument);
}

TEST(Vesicle, AContinuationStageReusesTheDiscretization) {
  // A stage that only lowers eps keeps the nodes: the previous solve's discretization is reused
  // (the same object), and the solve gives what a rebuilt one gives.
  const SphereBox s = constrained_ellipsoid(1.1, 0.85, 0.95);
  const Problem p(s);
  problems::ProblemInput in = p.input(s);
  const auto first = problems::solve_problem(PETSC_COMM_SELF, p.bound, in);
  ASSERT_TRUE(first.converged) << first.message;
  ASSERT_TRUE(first.discretization);
  in.constants["eps"] = 0.09;
  in.nodes = first.nodes;
  in.initial = problems::rescale_interface(first.state, 0.1, 0.09);
  in.initial_multipliers = first.minimization.multipliers;
  const auto rebuilt = problems::solve_problem(PETSC_COMM_SELF, p.bound, in);
  in.discretization = first.discretization;
  const auto reused = problems::solve_problem(PETSC_COMM_SELF, p.bound, in);
  ASSERT_TRUE(rebuilt.converged && reused.converged);
  EXPECT_EQ(reused.discretization.get(), first.discretization.get());
  EXPECT_NE(rebuilt.discretization.get(), first.discretization.get());
  EXPECT_NEAR(reused.energy, rebuilt.energy, 1e-12 * rebuilt.energy);
  EXPECT_EQ(reused.minimization.newton_iterations, rebuilt.minimization.newton_iterations);
  // Another node set is refused.
  const NodeSet fewer(2, std::vector<double>(first.nodes.coords.begin(), first.nodes.coords.end() - 2));
  in.nodes = fewer;
  in.initial.resize(fewer.size());
  EXPECT_THROW((void)problems::solve_problem(PETSC_COMM_SELF, p.bound, in), std::invalid_argument);
}

TEST(Vesicle, KktFirstFromAnEllipsoidStartNeverRaisesTheConstraintResidual) {
  // The default start: Newton on the KKT system from the tanh profile of an ellipsoid whose sharp
  // area and volume are not the targets. Its merit line search makes the constraint residual fall
  // (or hold) at every step, it needs no augmented-Lagrangian step, and it reaches the minimizer the
  // augmented-Lagrangian start reaches.
  SphereBox s = constrained_ellipsoid(1.2, 0.7, 0.85);
  const Problem kkt(s);
  const auto a = problems::solve_problem(PETSC_COMM_SELF, kkt.bound, kkt.input(s));
  s.start = "augmented";
  const Problem augmented(s);
  const auto b = problems::solve_problem(PETSC_COMM_SELF, augmented.bound, augmented.input(s));
  ASSERT_TRUE(a.converged) << a.message;
  ASSERT_TRUE(b.converged) << b.message;
  std::printf("ellipsoid start: KKT first %d AL + %d KKT, augmented first %d AL + %d KKT; E %.10f vs %.10f\n",
              a.minimization.augmented_iterations, a.minimization.newton_iterations, b.minimization.augmented_iterations,
              b.minimization.newton_iterations, a.energy, b.energy);
  EXPECT_EQ(a.minimization.augmented_iterations, 0);
  EXPECT_GT(a.minimization.history.front().constraint_norm, 1e-3);  // a start off the constraints
  for (std::size_t i = 1; i < a.minimization.history.size(); ++i)
    EXPECT_LE(a.minimization.history[i].constraint_norm, a.minimization.history[i - 1].constraint_norm * (1 + 1e-12) + 1e-14)
        << "step " << i;
  EXPECT_NEAR(a.energy, b.energy, 1e-8 * b.energy);
}

TEST(Vesicle, InertiaControlLeavesTheSaddlePlainNewtonConvergesTo) {
  // Without a moment constraint the vesicle may move along the axis; the box's walls (phi = -1)
  // make the centred state a saddle of the discrete energy: moving towards a wall lowers it. Plain
  // Newton on the KKT system converges to that saddle; the inertia-controlled Newton sees the
  // wrong inertia, shifts the Hessian, and goes down to a lower minimum.
  SphereBox s;
  s.eps = 0.14;
  s.spacing = 0.06;
  s.semi_axes = {0.35, 0.35};
  s.constraints = "area = " + num(4 * pi * 0.35 * 0.35) + "\nvolume = " + num(0.98 * 4.0 / 3 * pi * std::pow(0.35, 3)) + "\n";
  const Problem controlled(s);
  const auto a = problems::solve_problem(PETSC_COMM_SELF, controlled.bound, controlled.input(s));
  s.inertia_correction = false;
  const Problem plain(s);
  const auto b = problems::solve_problem(PETSC_COMM_SELF, plain.bound, plain.input(s));
  ASSERT_TRUE(a.converged) << a.message;
  ASSERT_TRUE(b.converged) << b.message;
  std::printf("inertia-controlled: E %.8f (%d shifted steps), plain Newton: E %.8f\n", a.energy,
              a.minimization.corrected_steps, b.energy);
  EXPECT_GT(a.minimization.corrected_steps, 0);
  EXPECT_EQ(b.minimization.corrected_steps, 0);
  EXPECT_LT(a.energy, b.energy * (1 - 1e-3));
  // The second-order check tells the two apart: plain Newton's result is the saddle.
  EXPECT_EQ(a.minimization.negative_curvature_directions, 0);
  EXPECT_GE(b.minimization.negative_curvature_directions, 1);
  // The augmented Lagrangian's inner Newton checks the inertia of H + U Uᵀ through the Woodbury
  // capacitance: it also leaves the saddle (for either wall: the box is symmetric about z = 0.6).
  s.inertia_correction = true;
  s.start = "augmented";
  const Problem augmented(s);
  const auto c = problems::solve_problem(PETSC_COMM_SELF, augmented.bound, augmented.input(s));
  ASSERT_TRUE(c.converged) << c.message;
  std::printf("augmented Lagrangian first, inertia-controlled: E %.8f (%d AL steps, %d shifted)\n", c.energy,
              c.minimization.augmented_iterations, c.minimization.corrected_steps);
  EXPECT_GT(c.minimization.augmented_iterations, 0);
  EXPECT_NEAR(c.energy, a.energy, 1e-6 * a.energy);
  EXPECT_EQ(c.minimization.negative_curvature_directions, 0);
}

}  // namespace
}  // namespace lmeform

namespace lmeform {
namespace {

TEST(Vesicle, InterfaceResolvingScheduleLowersTheEnergyAtEveryStage) {
  // The whole vesicle schedule with `resolve` stages, small: a uniform start at eps = 0.1, then a
  // grid resolving eps >= 0.07 around that solution, on which eps falls to 0.07. Every stage must
  // converge, hold eps >= 2 h_min, and lower the energy (the phase-field energy falls towards the
  // sharp one as eps falls when the grid resolves the interface).
  const std::string text =
      "[scene]\nname = \"resolved\"\ncoordinates = \"axisymmetric\"\n"
      "[domain]\nlower = [0.0, 0.0]\nupper = [0.8, 1.2]\n"
      "[nodes]\nspacing = 0.045\ngamma = 0.8\n"
      "[model]\nforms = [\"helfrich_axisymmetric\", \"area_axisymmetric\", \"volume_axisymmetric\", \"moment_axisymmetric\"]\n"
      "energy = \"bending\"\n"
      "[constants]\neps = 0.1\nzc = 0.6\n"
      "[constraints]\narea = {}\nvolume = {}\nmoment = 0.0\n"
      "[[dirichlet]]\nboundary = [\"r_max\", \"z_min\", \"z_max\"]\nunknown = \"phi\"\nvalue = -1.0\n"
      "[vesicle]\nradius = 0.3\nreduced_volume = 0.95\nresolution_factor = 2.0\n"
      "[vesicle.initial]\nshape = \"oblate\"\ncenter = [0.0, 0.6]\n"
      "[vesicle.adaptivity]\nlloyd_iterations = 10\nstages = [\n"
      "  { eps = 0.09, resolve = 0.07 },\n  { eps = 0.08, lloyd_iterations = 0 },\n  { eps = 0.07, lloyd_iterations = 0 },\n]\n";
  const Scene scene = parse_scene(text, "resolved.toml", problems::driver_tables());
  const problems::VesicleRun run = problems::run_vesicle(PETSC_COMM_SELF, scene, *problems::read_vesicle(scene), nullptr);
  ASSERT_TRUE(run.failure.empty()) << run.failure;
  ASSERT_EQ(run.stages.size(), 4u);
  ASSERT_TRUE(run.initial_topology.has_value());
  EXPECT_EQ(run.initial_topology->describe(), "1 component, genus 0 (a sphere)");
  EXPECT_TRUE(run.warnings.empty());
  for (std::size_t i = 0; i < run.stages.size(); ++i) {
    const auto& st = run.stages[i];
    SCOPED_TRACE("stage " + std::to_string(i));
    EXPECT_TRUE(st.result.converged) << st.result.message;
    EXPECT_GE(st.eps, 2.0 * st.h_min);
    // The membrane stays one sphere through the new grid and the lower eps.
    ASSERT_TRUE(st.topology.has_value());
    EXPECT_EQ(st.topology->describe(), "1 component, genus 0 (a sphere)");
    if (i > 0) {
      EXPECT_LT(st.result.energy, run.stages[i - 1].result.energy);
    }
  }
  // The resolving grid is new (and graded: finer than the uniform start where it matters); the
  // stages after it keep it.
  EXPECT_EQ(run.stages[1].grid, "cvt-1");
  EXPECT_LE(run.stages[1].h_min, 0.07 / 2.0);
  EXPECT_LT(run.stages[1].h_min, 0.8 * run.stages[0].h_min);
  EXPECT_EQ(run.stages[2].nodes, run.stages[1].nodes);
  EXPECT_EQ(run.stages[3].result.nodes.coords, run.stages[1].result.nodes.coords);
}

}  // namespace
}  // namespace lmeform
