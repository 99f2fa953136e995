// Vesicle dynamics through the scene path ([dynamics], app/dynamics.cpp) on a coarse axisymmetric
// box: the variational integrator decreases the energy step by step and keeps area and volume to
// round-off; forward Euler at small steps agrees with it; a step whose map would fold is rejected
// and retried with a shorter step, and one that cannot be taken names the quadrature point; a run
// stopped at a checkpoint and resumed ends where the uninterrupted run ends; a scheduled deflation
// moves the volume target; scene errors name the key.
#include <gtest/gtest.h>

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <set>
#include <span>
#include <string>
#include <utility>

#include <unistd.h>

#include "dynamics.hpp"
#include "stationary.hpp"
#include "field_transfer.hpp"
#include "point_values.hpp"
#include "lmeform/delaunay.hpp"
#include "lmeform/lme_basis.hpp"
#include "lmeform/quadrature.hpp"
#include "lmeform/node_sets.hpp"
#include "lmeform/petsc.hpp"
#include "lmeform/scene.hpp"

namespace {

using namespace lmeform;
using problems::DynamicsRun;
using problems::DynamicsSettings;

// An oblate vesicle (v = 0.9, R0 = 0.4) in the box [0, 1] x [0, 1.5], h = 1/16, eps = 2h.
std::string scene_text(const std::string& dynamics, const std::string& constraints = "area = \"initial\"\nvolume = \"initial\"\n") {
  return R"scene(
[scene]
name = "dynamics_test"
coordinates = "axisymmetric"
[domain]
lower = [0.0, 0.0]
upper = [1.0, 1.5]
[nodes]
spacing = 0.0625
gamma = 0.8
[model]
forms = ["helfrich_lagrangian_axisymmetric", "area_lagrangian_axisymmetric", "volume_lagrangian_axisymmetric",
         "dissipation_axisymmetric"]
energy = "bending"
[constants]
k = 1.0
eps = 0.125
C0 = 0.0
mu = 1.0
lambda = 0.0
[constraints]
)scene" + constraints + R"scene(
[coefficients]
phi = "tanh((1 - (x[0]/0.4732)^2 - ((x[1] - 0.75)/0.2573)^2) / (2*sqrt(x[0]^2/0.4732^4 + (x[1] - 0.75)^2/0.2573^4 + 1e-12)) / (sqrt(2)*eps))"
[qdata]
phi0 = { field = "phi", jet = "value" }
gphi0 = { field = "phi", jet = "gradient" }
hphi0 = { field = "phi", jet = "hessian" }
[initial]
y = "x[0]*e(0) + x[1]*e(1)"
[[dirichlet]]
boundary = ["r_max", "z_min", "z_max"]
unknown = "y"
value = "x[0]*e(0) + x[1]*e(1)"
[[dirichlet]]
boundary = ["axis"]
unknown = "y"
components = [0]
value = 0.0
[dynamics]
dissipation = "dissipation"
time_unit = 0.064
)scene" + dynamics;
}

struct Case {
  Scene scene;
  DynamicsSettings settings;
};

Case make(const std::string& dynamics, const std::string& constraints = "area = \"initial\"\nvolume = \"initial\"\n") {
  const std::string_view extensions[] = {problems::kDynamicsExtension};
  Case r{parse_scene(scene_text(dynamics, constraints), "dynamics_test.toml", extensions), {}};
  r.settings = *problems::read_dynamics(r.scene);
  return r;
}

double relative_drift(const DynamicsRun& run, std::size_t constraint) {
  double drift = 0;
  const double c0 = run.history.front().constraints[constraint];
  for (const auto& s : run.history) drift = std::max(drift, std::abs(s.constraints[constraint] - c0) / std::abs(c0));
  return drift;
}

TEST(Dynamics, VariationalIntegratorDecreasesTheEnergyAndKeepsAreaAndVolume) {
  const Case r = make("t_end = 0.03\ndt = 1e-3\n");
  const DynamicsRun run = problems::run_dynamics(PETSC_COMM_WORLD, r.scene, r.settings, nullptr, nullptr);
  ASSERT_TRUE(run.failure.empty()) << run.failure;
  ASSERT_GT(run.history.size(), 5u);
  for (std::size_t s = 1; s < run.history.size(); ++s)
    EXPECT_LT(run.history[s].energy, run.history[s - 1].energy) << "step " << s;
  EXPECT_LT(run.history.back().energy, 0.97 * run.history.front().energy);
  EXPECT_NEAR(run.history.back().t_star, 0.03, 1e-12);
  EXPECT_LT(relative_drift(run, 0), 1e-10);
  EXPECT_LT(relative_drift(run, 1), 1e-10);
  // The Hessian of E once per step (the seed's saving): fewer Hessians than gradients.
  EXPECT_EQ(run.hessian_evaluations, run.accepted);
  EXPECT_GT(run.gradient_evaluations, run.hessian_evaluations);
  // Area and volume conserved by a tension and a pressure.
  EXPECT_GT(std::abs(run.final_multipliers[0]), 0.0);
}

TEST(Dynamics, ForwardEulerAgreesWithTheVariationalIntegratorAtSmallSteps) {
  Case vti = make("t_end = 0.002\ndt = 1e-4\nadaptive = false\n");
  Case euler = make("method = \"forward_euler\"\nt_end = 0.002\ndt = 2e-5\nadaptive = false\n");
  const DynamicsRun a = problems::run_dynamics(PETSC_COMM_WORLD, vti.scene, vti.settings, nullptr, nullptr);
  const DynamicsRun b = problems::run_dynamics(PETSC_COMM_WORLD, euler.scene, euler.settings, nullptr, nullptr);
  ASSERT_TRUE(a.failure.empty() && b.failure.empty()) << a.failure << b.failure;
  EXPECT_EQ(a.accepted, 20);
  EXPECT_EQ(b.accepted, 100);
  EXPECT_EQ(b.hessian_evaluations, 0);
  const double e0 = a.history.front().energy;
  const double ea = a.history.back().energy, eb = b.history.back().energy;
  EXPECT_LT(ea, e0);
  // Both first order in dt; over this interval they agree to 1e-5 of the energy and to 1 % of its decrease.
  EXPECT_LT(std::abs(ea - eb), 1e-5 * e0);
  EXPECT_LT(std::abs(ea - eb), 0.01 * (e0 - ea));
  // Forward Euler linearizes the constraints: it drifts, the integrator does not.
  EXPECT_GT(relative_drift(b, 0), 1e-12);
  EXPECT_LT(relative_drift(a, 0), 1e-10);
}

TEST(Dynamics, StepsAThousandTimesForwardEulersStableStep) {
  // Forward Euler's largest stable constant step on this grid lies in [4e-3, 8e-3): at 4e-3 the
  // energy falls for 50 steps, at 8e-3 it rises within 50.
  auto euler = [](const std::string& dt) {
    const Case c = make("method = \"forward_euler\"\nt_end = " + std::to_string(50 * std::stod(dt)) + "\ndt = " + dt +
                        "\nadaptive = false\nrequire_decrease = false\n");
    return problems::run_dynamics(PETSC_COMM_WORLD, c.scene, c.settings, nullptr, nullptr);
  };
  auto rises = [](const DynamicsRun& run) {
    if (!run.failure.empty()) return true;
    for (std::size_t s = 1; s < run.history.size(); ++s)
      if (!(run.history[s].energy < run.history[s - 1].energy)) return true;
    return false;
  };
  const DynamicsRun stable = euler("4e-3");
  EXPECT_FALSE(rises(stable));
  EXPECT_TRUE(rises(euler("8e-3")));
  // The integrator takes two steps of dt* = 8, at least 1000 times Euler's largest stable step:
  // with the Hessian of E refreshed every Newton iteration each converges (11 and 5 iterations
  // measured), lowers the energy, keeps area and volume and leaves det F > 0; the first already
  // lands below where Euler's 50 stable steps (to t* = 0.2) got.
  const Case big = make("t_end = 16.0\ndt = 8.0\nadaptive = false\nhessian = \"iteration\"\n");
  const DynamicsRun run = problems::run_dynamics(PETSC_COMM_WORLD, big.scene, big.settings, nullptr, nullptr);
  ASSERT_TRUE(run.failure.empty()) << run.failure;
  ASSERT_EQ(run.accepted, 2);
  EXPECT_EQ(run.rejected, 0);
  EXPECT_LT(run.history[1].energy, stable.history.back().energy);
  EXPECT_LT(run.history[2].energy, run.history[1].energy);
  EXPECT_LT(relative_drift(run, 0), 1e-10);
  EXPECT_LT(relative_drift(run, 1), 1e-10);
  for (const auto& step : run.history) EXPECT_GT(step.min_jacobian, 0.05);
  // With the seed's saving (the Hessian of E once per step) Newton on a step of 8 is damped three
  // times in a row: the step is rejected and the run goes on at 4 (21 and 22 iterations measured),
  // to the same end time, its energy still falling.
  const Case saving = make("t_end = 8.0\ndt = 8.0\nadaptive = false\n");
  const DynamicsRun halved = problems::run_dynamics(PETSC_COMM_WORLD, saving.scene, saving.settings, nullptr, nullptr);
  ASSERT_TRUE(halved.failure.empty()) << halved.failure;
  EXPECT_EQ(halved.rejected, 1);
  ASSERT_EQ(halved.accepted, 2);
  EXPECT_NEAR(halved.history.back().t_star, 8.0, 1e-12);
  EXPECT_LT(halved.history[1].energy, stable.history.back().energy);
  EXPECT_LT(halved.history[2].energy, halved.history[1].energy);
  EXPECT_LT(relative_drift(halved, 0), 1e-10);
  EXPECT_LT(relative_drift(halved, 1), 1e-10);
}

TEST(Dynamics, AStepWhoseNewtonFailsIsRejectedAndRetried) {
  // At most 4 Newton iterations: the first step at dt* = 0.02 needs more, is rejected, and is
  // retried with halved steps until Newton converges; the run then reaches t_end.
  Case r = make("t_end = 0.03\ndt = 0.02\n");
  r.scene.solver.max_newton_iterations = 4;
  const DynamicsRun run = problems::run_dynamics(PETSC_COMM_WORLD, r.scene, r.settings, nullptr, nullptr);
  ASSERT_TRUE(run.failure.empty()) << run.failure;
  EXPECT_GT(run.rejected, 0);
  EXPECT_GT(run.history[1].rejected, 0);
  EXPECT_LT(run.history[1].dt_star, 0.02);
  for (std::size_t s = 1; s < run.history.size(); ++s) {
    EXPECT_LE(run.history[s].newton_iterations, 4) << "step " << s;
    EXPECT_LT(run.history[s].energy, run.history[s - 1].energy) << "step " << s;
  }
  EXPECT_NEAR(run.history.back().t_star, 0.03, 1e-12);
}

TEST(Dynamics, TinyStepsConvergeDespiteRounding) {
  // dt* = 1e-7: the proximal term is 1e7 times the energy's; Newton still meets its tolerance.
  const Case r = make("t_end = 3e-7\ndt = 1e-7\nadaptive = false\n");
  const DynamicsRun run = problems::run_dynamics(PETSC_COMM_WORLD, r.scene, r.settings, nullptr, nullptr);
  ASSERT_TRUE(run.failure.empty()) << run.failure;
  EXPECT_EQ(run.accepted, 3);
  EXPECT_EQ(run.rejected, 0);
  EXPECT_LT(run.history.back().energy, run.history.front().energy);
}

TEST(Dynamics, AStepThatCannotBeTakenNamesTheQuadraturePointAndLeavesTheState) {
  const Case r = make("t_end = 0.01\ndt = 0.01\nmin_jacobian = 1.5\nmax_retries = 3\n");
  const DynamicsRun run = problems::run_dynamics(PETSC_COMM_WORLD, r.scene, r.settings, nullptr, nullptr);
  EXPECT_NE(run.failure.find("det F"), std::string::npos) << run.failure;
  EXPECT_NE(run.failure.find("quadrature point"), std::string::npos) << run.failure;
  EXPECT_NE(run.failure.find("failed 4 times"), std::string::npos) << run.failure;
  ASSERT_EQ(run.history.size(), 1u);
  // The accepted state (the start, y = X) is untouched.
  const auto& X = run.reference_nodes.coords;
  ASSERT_EQ(run.final_state.size(), X.size());
  for (std::size_t i = 0; i < X.size(); ++i) EXPECT_EQ(run.final_state[i], X[i]);
}

TEST(Dynamics, AResetOfTheReferenceChangesNothingAndTheRunContinuesTheSame) {
  const Case plain = make("t_end = 0.012\ndt = 1e-3\n");
  const Case with_resets = make("t_end = 0.012\ndt = 1e-3\nreset_every = 3\n");
  const DynamicsRun a = problems::run_dynamics(PETSC_COMM_WORLD, plain.scene, plain.settings, nullptr, nullptr);
  const DynamicsRun b = problems::run_dynamics(PETSC_COMM_WORLD, with_resets.scene, with_resets.settings, nullptr, nullptr);
  ASSERT_TRUE(a.failure.empty() && b.failure.empty()) << a.failure << b.failure;
  EXPECT_EQ(a.resets, 0);
  ASSERT_GE(b.resets, 3);
  ASSERT_EQ(b.reset_changes.size(), std::size_t(b.resets));
  for (const auto& c : b.reset_changes) {
    // The same physical state described from a new reference: E, area and volume to round-off.
    EXPECT_LT(std::abs(c.energy), 1e-12);
    for (const double v : c.constraints) EXPECT_LT(std::abs(v), 1e-12);
  }
  // After a reset det F restarts from 1.
  EXPECT_GT(b.history.back().min_jacobian, a.history.back().min_jacobian);
  // The motion is the same to the discretization error of the new basis.
  const double ea = a.history.back().energy, eb = b.history.back().energy;
  EXPECT_LT(std::abs(ea - eb), 1e-4 * ea) << ea << " vs " << eb;
  EXPECT_LT(relative_drift(b, 0), 1e-10);
  EXPECT_LT(relative_drift(b, 1), 1e-10);
}

TEST(Dynamics, AResetKeepsTheMaterialBoundaryWhereACoefficientLeavesTheBox) {
  // LME is not interpolating: after a large motion the coefficient y_a of a free node can lie
  // outside the box while the map stays inside (measured: a node near the axis at r = -0.11). The
  // reset's new node set then has that node outside Ω; found by position it would join a boundary
  // part and be held (on the axis, with y_r = 0: the state changed). The Dirichlet node sets of the
  // material nodes are carried instead. Here a free node of the top row is moved onto z_max.
  const Case r = make("t_end = 0.01\ndt = 0.01\n");
  problems::OutputRoles dissipation;
  dissipation.auxiliary = {r.settings.dissipation};
  const problems::BoundScene b = problems::bind_scene(r.scene, PETSC_COMM_WORLD, nullptr, dissipation);
  const NodeSet material = problems::initial_nodes(r.scene, PETSC_COMM_WORLD);
  const std::vector<std::vector<int>> sets = problems::dirichlet_nodes(b, material);
  ASSERT_EQ(sets.size(), 2u);
  std::vector<double> coords = material.coords;
  int moved = -1;
  for (std::size_t a = 0; a < material.size(); ++a)
    if (std::abs(material.point(a)[0] - 0.5) < 1e-12 && std::abs(material.point(a)[1] - 1.4375) < 1e-12) moved = int(a);
  ASSERT_GE(moved, 0);
  coords[std::size_t(moved) * 2] = 0.53125;  // between two wall nodes
  coords[std::size_t(moved) * 2 + 1] = 1.5;
  problems::ProblemInput input;
  input.nodes = NodeSet(2, coords);
  input.initial = coords;  // y = the new node positions, as after a reset
  auto held = [&](const problems::ProblemSpace& space) {
    return std::count(space.fixed_pairs.begin(), space.fixed_pairs.end(), std::pair<int, int>{moved, 1}) > 0;
  };
  EXPECT_TRUE(held(problems::build_problem_space(PETSC_COMM_WORLD, b, input)));  // the failure mode
  input.dirichlet_nodes = sets;
  const problems::ProblemSpace carried = problems::build_problem_space(PETSC_COMM_WORLD, b, input);
  EXPECT_FALSE(held(carried));
  // Walls: both components; axis: y_r; a corner on both holds its y_r once.
  std::set<std::pair<int, int>> expected;
  for (const int n : sets[0]) expected.insert({{n, 0}, {n, 1}});
  for (const int n : sets[1]) expected.insert({n, 0});
  EXPECT_EQ(carried.fixed_pairs.size(), expected.size());
  const std::set<std::pair<int, int>> held_pairs(carried.fixed_pairs.begin(), carried.fixed_pairs.end());
  EXPECT_EQ(held_pairs, expected);
  input.dirichlet_nodes.pop_back();
  EXPECT_THROW((void)problems::build_problem_space(PETSC_COMM_WORLD, b, input), std::invalid_argument);
}

TEST(Dynamics, AFoldingStepResetsTheReferenceWhenResetsAreOn) {
  // det F may not fall below 0.995 from a reference: with resets on, a step that would cross it
  // resets the reference instead of shrinking the step forever.
  const Case r = make("t_end = 0.02\ndt = 0.002\nmin_jacobian = 0.995\nreset_distortion = 100.0\n");
  const DynamicsRun run = problems::run_dynamics(PETSC_COMM_WORLD, r.scene, r.settings, nullptr, nullptr);
  ASSERT_TRUE(run.failure.empty()) << run.failure;
  EXPECT_GT(run.resets, 0);
  EXPECT_NEAR(run.history.back().t_star, 0.02, 1e-12);
}

// Plain, with a reset every 3 steps (the checkpoint at step 4 holds a carried quadrature), and with
// a re-mesh every 3 steps (the checkpoint holds new nodes, cells and projected fields).
struct RestartCase {
  std::string name;
  std::string keys;
};

class DynamicsRestart : public ::testing::TestWithParam<RestartCase> {};

TEST_P(DynamicsRestart, ARunResumedFromItsCheckpointEndsLikeTheUninterruptedRun) {
  const std::filesystem::path dir = std::filesystem::temp_directory_path() / fmt::format("lmeform_test_dynamics_restart_{}_{}", GetParam().name, ::getpid());
  std::filesystem::remove_all(dir);
  std::filesystem::create_directories(dir);
  const std::string dynamics = "t_end = 0.012\ndt = 1e-3\ncheckpoint_every = 4\noutput_every = 2\n" + GetParam().keys;
  const Case whole = make(dynamics);
  problems::DynamicsOutput out_whole{dir / "whole", "run", false};
  std::filesystem::create_directories(out_whole.directory);
  const DynamicsRun a = problems::run_dynamics(PETSC_COMM_WORLD, whole.scene, whole.settings, &out_whole, nullptr);
  ASSERT_TRUE(a.failure.empty()) << a.failure;

  Case stopped = make(dynamics + "max_steps = 4\n");
  problems::DynamicsOutput out_parts{dir / "parts", "run", false};
  std::filesystem::create_directories(out_parts.directory);
  const DynamicsRun b = problems::run_dynamics(PETSC_COMM_WORLD, stopped.scene, stopped.settings, &out_parts, nullptr);
  EXPECT_NE(b.failure.find("max_steps"), std::string::npos) << b.failure;
  EXPECT_TRUE(std::filesystem::exists(out_parts.directory / "run_checkpoint.h5"));
  out_parts.restart = true;
  const DynamicsRun c = problems::run_dynamics(PETSC_COMM_WORLD, whole.scene, whole.settings, &out_parts, nullptr);
  ASSERT_TRUE(c.failure.empty()) << c.failure;
  ASSERT_EQ(c.history.size(), a.history.size());
  for (std::size_t s = 0; s < a.history.size(); ++s) {
    EXPECT_EQ(c.history[s].t_star, a.history[s].t_star) << "step " << s;
    EXPECT_NEAR(c.history[s].energy, a.history[s].energy, 1e-12 * std::abs(a.history[s].energy)) << "step " << s;
  }
  ASSERT_EQ(c.final_state.size(), a.final_state.size());
  double diff = 0;
  for (std::size_t i = 0; i < a.final_state.size(); ++i) diff = std::max(diff, std::abs(c.final_state[i] - a.final_state[i]));
  EXPECT_LT(diff, 1e-12);
  // The time series of the resumed run lists the steps of both parts.
  EXPECT_TRUE(std::filesystem::exists(out_parts.directory / "run.xmf"));
  EXPECT_TRUE(std::filesystem::exists(out_parts.directory / "series" / "run_000012.h5"));
  EXPECT_TRUE(std::filesystem::exists(out_parts.directory / "series" / "run_000002.h5"));
  if (!GetParam().keys.empty()) {
    EXPECT_TRUE(std::filesystem::exists(out_parts.directory / "run_checkpoint_quadrature.h5"));
  }
  EXPECT_EQ(c.resets, a.resets);
  EXPECT_EQ(c.gradient_evaluations, a.gradient_evaluations);
  EXPECT_EQ(c.hessian_evaluations, a.hessian_evaluations);
  EXPECT_EQ(c.remeshes, a.remeshes);
  EXPECT_EQ(c.remesh_changes, a.remesh_changes);
  // The membrane's topology of every step, the start's among them, read back from the history.
  ASSERT_TRUE(a.initial_topology.has_value() && c.initial_topology.has_value());
  EXPECT_TRUE(c.initial_topology->same_as(*a.initial_topology));
  for (std::size_t s = 0; s < a.history.size(); ++s) {
    ASSERT_TRUE(c.history[s].topology.has_value()) << "step " << s;
    EXPECT_TRUE(c.history[s].topology->same_as(*a.history[s].topology)) << "step " << s;
  }
  if (GetParam().name == "remesh") {
    EXPECT_GE(a.remeshes, 3);  // every 3 steps: the checkpoint at step 4 follows the first
    EXPECT_EQ(b.remeshes, 1);
  }
  std::filesystem::remove_all(dir);
}

INSTANTIATE_TEST_SUITE_P(PlainResetsAndReMeshes, DynamicsRestart,
                         ::testing::Values(RestartCase{"plain", ""}, RestartCase{"reset", "reset_every = 3\n"},
                                           RestartCase{"remesh", "remesh_every = 3\nremesh_factor = 10.0\n"}),
                         [](const ::testing::TestParamInfo<RestartCase>& param) { return param.param.name; });

TEST(Dynamics, ARestartAppliesTheScenesEnergyDecrementTarget) {
  // Without energy_decrement the target is the first step's decrement, carried by the checkpoint;
  // a scene that states one (here four times that) has it applied after the restart too.
  const std::filesystem::path dir = std::filesystem::temp_directory_path() / fmt::format("lmeform_test_dynamics_restart_target_{}", ::getpid());
  std::filesystem::remove_all(dir);
  std::filesystem::create_directories(dir);
  const std::string dynamics = "t_end = 0.03\ndt = 1e-3\ncheckpoint_every = 4\noutput_every = 0\n";
  const Case whole = make(dynamics);
  const DynamicsRun a = problems::run_dynamics(PETSC_COMM_WORLD, whole.scene, whole.settings, nullptr, nullptr);
  ASSERT_TRUE(a.failure.empty()) << a.failure;
  const Case stopped = make(dynamics + "max_steps = 4\n");
  problems::DynamicsOutput out{dir, "run", false};
  const DynamicsRun b = problems::run_dynamics(PETSC_COMM_WORLD, stopped.scene, stopped.settings, &out, nullptr);
  ASSERT_NE(b.failure.find("max_steps"), std::string::npos) << b.failure;
  const double first = a.history[0].energy - a.history[1].energy;
  ASSERT_GT(first, 0.0);
  const Case larger = make(dynamics + fmt::format("energy_decrement = {:.17g}\n", 4 * first));
  out.restart = true;
  const DynamicsRun c = problems::run_dynamics(PETSC_COMM_WORLD, larger.scene, larger.settings, &out, nullptr);
  ASSERT_TRUE(c.failure.empty()) << c.failure;
  ASSERT_GT(c.history.size(), 6u);
  for (std::size_t s = 0; s <= 4; ++s) EXPECT_EQ(c.history[s].t_star, a.history[s].t_star) << "step " << s;
  EXPECT_GT(c.history[6].t_star, a.history[6].t_star);
  EXPECT_LT(c.history.size(), a.history.size());
  std::filesystem::remove_all(dir);
}

TEST(Dynamics, AScheduledDeflationMovesTheVolumeTarget) {
  // V0(t) = V0(0) (1 - 2 t*) for t* <= 0.01: 2 % less volume at the end, area kept.
  const Case r = make("t_end = 0.01\ndt = 1e-3\nadaptive = false\n[dynamics.schedule]\nV0 = { rate = -2.0, until = 0.01 }\n",
                     "area = \"initial\"\nvolume = \"initial\"\n");
  const DynamicsRun run = problems::run_dynamics(PETSC_COMM_WORLD, r.scene, r.settings, nullptr, nullptr);
  ASSERT_TRUE(run.failure.empty()) << run.failure;
  const double v0 = run.history.front().constraints[1], v1 = run.history.back().constraints[1];
  EXPECT_NEAR(v1 / v0, 0.98, 1e-9);
  EXPECT_LT(relative_drift(run, 0), 1e-10);
}

TEST(Dynamics, AReportTimeIsLandedOnAndWritesTheFieldsThere) {
  // Constant steps of 1e-3 and a report time between steps: the step that lands on it writes a
  // time-series file although output_every writes none (the shape at the end of a deflation).
  const std::filesystem::path dir = std::filesystem::temp_directory_path() / "lmeform_test_dynamics_report_time";
  std::filesystem::remove_all(dir);
  std::filesystem::create_directories(dir);
  const Case r = make("t_end = 0.006\ndt = 1e-3\nadaptive = false\noutput_every = 0\nreport_times = [0.0035]\n"
                      "[dynamics.schedule]\nV0 = { rate = -2.0, until = 0.0035 }\n");
  problems::DynamicsOutput out{dir, "run", false};
  const DynamicsRun run = problems::run_dynamics(PETSC_COMM_WORLD, r.scene, r.settings, &out, nullptr);
  ASSERT_TRUE(run.failure.empty()) << run.failure;
  ASSERT_GE(run.history.size(), 5u);
  EXPECT_NEAR(run.history[4].t_star, 0.0035, 1e-14);
  ASSERT_EQ(run.energy_at.count(0.0035), 1u);
  EXPECT_EQ(run.energy_at.at(0.0035), run.history[4].energy);
  EXPECT_TRUE(std::filesystem::exists(dir / "series" / "run_000004.h5"));
  EXPECT_FALSE(std::filesystem::exists(dir / "series" / "run_000003.h5"));
  EXPECT_TRUE(std::filesystem::exists(dir / "series" / "run_000000.h5"));
  char last[32];
  std::snprintf(last, sizeof last, "run_%06zu.h5", run.history.size() - 1);  // the end is always written
  EXPECT_TRUE(std::filesystem::exists(dir / "series" / last));
}

TEST(Dynamics, AScheduleHistoryDeflatesThenReinflatesAndAPulseOfCurvatureEnds) {
  // V0 falls by 2 %/t* over [0, 0.005] and rises back over [0.005, 0.01]; C0 = 3 on [0.001, 0.003).
  const Case r = make("t_end = 0.01\ndt = 1e-3\nadaptive = false\n[dynamics.schedule]\n"
                      "V0 = [ { rate = -2.0, from = 0.0, until = 0.005 }, { rate = 2.0, from = 0.005, until = 0.01 } ]\n"
                      "C0 = [ { at = 0.001, value = 3.0 }, { at = 0.003, value = 0.0 } ]\n",
                      "area = \"initial\"\nvolume = \"initial\"\n");
  const DynamicsRun run = problems::run_dynamics(PETSC_COMM_WORLD, r.scene, r.settings, nullptr, nullptr);
  ASSERT_TRUE(run.failure.empty()) << run.failure;
  ASSERT_EQ(run.history.size(), 11u);
  const double v0 = run.history.front().constraints[1];
  EXPECT_NEAR(run.history[5].constraints[1] / v0, 0.99, 1e-9);
  EXPECT_NEAR(run.history.back().constraints[1] / v0, 1.0, 1e-9);
  EXPECT_LT(relative_drift(run, 0), 1e-10);
  // The pulse changes the energy while it acts, and nothing before it.
  const Case plain = make("t_end = 0.01\ndt = 1e-3\nadaptive = false\n[dynamics.schedule]\n"
                          "V0 = [ { rate = -2.0, from = 0.0, until = 0.005 }, { rate = 2.0, from = 0.005, until = 0.01 } ]\n",
                          "area = \"initial\"\nvolume = \"initial\"\n");
  const DynamicsRun without = problems::run_dynamics(PETSC_COMM_WORLD, plain.scene, plain.settings, nullptr, nullptr);
  ASSERT_TRUE(without.failure.empty()) << without.failure;
  EXPECT_NEAR(run.history[0].energy, without.history[0].energy, 1e-12 * without.history[0].energy);
  for (std::size_t s = 1; s < 3; ++s) EXPECT_GT(std::abs(run.history[s].energy - without.history[s].energy), 1e-3) << "step " << s;
  // After it C0 = 0 again: the energy differs only through the state the pulse left.
  EXPECT_LT(std::abs(run.history.back().energy - without.history.back().energy), 0.05 * without.history.back().energy);
}

// Cartesian scenes: an elliptic vesicle in the unit square (2D) or an ellipsoid in the unit cube
// (3D, coarse), fixed walls, the Lagrangian forms of plain coordinates.
std::string cartesian_scene(int dim) {
  const bool three = dim == 3;
  const std::string phi =
      three ? "tanh((1 - ((x[0]-0.5)/0.32)^2 - ((x[1]-0.5)/0.28)^2 - ((x[2]-0.5)/0.22)^2) / "
              "(2*sqrt((x[0]-0.5)^2/0.32^4 + (x[1]-0.5)^2/0.28^4 + (x[2]-0.5)^2/0.22^4 + 1e-12)) / (sqrt(2)*eps))"
            : "tanh((1 - ((x[0]-0.5)/0.32)^2 - ((x[1]-0.5)/0.2)^2) / "
              "(2*sqrt((x[0]-0.5)^2/0.32^4 + (x[1]-0.5)^2/0.2^4 + 1e-12)) / (sqrt(2)*eps))";
  const std::string identity = three ? "x[0]*e(0) + x[1]*e(1) + x[2]*e(2)" : "x[0]*e(0) + x[1]*e(1)";
  return std::string(R"scene(
[scene]
name = "dynamics_cartesian"
coordinates = "cartesian"
[domain]
)scene") + (three ? "lower = [0.0, 0.0, 0.0]\nupper = [1.0, 1.0, 1.0]\n" : "lower = [0.0, 0.0]\nupper = [1.0, 1.0]\n") +
         "[nodes]\n" + (three ? "counts = [7, 7, 7]\nquadrature_points = 4\n" : "counts = [17, 17]\n") + R"scene(gamma = 0.8
[model]
forms = ["helfrich_lagrangian", "area_lagrangian", "volume_lagrangian", "dissipation"]
energy = "bending"
[constants]
k = 1.0
mu = 1.0
lambda = 0.0
)scene" + (three ? "eps = 0.25\n" : "eps = 0.125\n") + R"scene(
[constraints]
area = "initial"
volume = "initial"
[coefficients]
)scene" + "phi = \"" + phi + "\"\n" + R"scene(
[qdata]
phi0 = { field = "phi", jet = "value" }
gphi0 = { field = "phi", jet = "gradient" }
hphi0 = { field = "phi", jet = "hessian" }
[initial]
)scene" + "y = \"" + identity + "\"\n[[dirichlet]]\nboundary = [\"hull\"]\nunknown = \"y\"\nvalue = \"" + identity + "\"\n" + R"scene(
[dynamics]
dissipation = "dissipation"
t_end = 0.004
dt = 1e-3
adaptive = false
reset_every = 2
)scene";
}

class DynamicsCartesian : public ::testing::TestWithParam<int> {};

TEST_P(DynamicsCartesian, TheEnergyFallsAndAreaAndVolumeHold) {
  const std::string_view extensions[] = {problems::kDynamicsExtension};
  const Scene scene = parse_scene(cartesian_scene(GetParam()), "dynamics_cartesian.toml", extensions);
  const DynamicsRun run = problems::run_dynamics(PETSC_COMM_WORLD, scene, *problems::read_dynamics(scene), nullptr, nullptr);
  ASSERT_TRUE(run.failure.empty()) << run.failure;
  EXPECT_EQ(run.accepted, 4);
  EXPECT_EQ(run.resets, 1);
  for (std::size_t s = 1; s < run.history.size(); ++s) EXPECT_LT(run.history[s].energy, run.history[s - 1].energy) << "step " << s;
  EXPECT_LT(relative_drift(run, 0), 1e-10);
  EXPECT_LT(relative_drift(run, 1), 1e-10);
  for (const auto& c : run.reset_changes) EXPECT_LT(std::abs(c.energy), 1e-12);
}

INSTANTIATE_TEST_SUITE_P(TwoAndThreeDimensions, DynamicsCartesian, ::testing::Values(2, 3));

TEST(Dynamics, AReMeshProjectsTheFieldOntoAnAdaptedGridAndTheRunGoesOn) {
  const std::string keys = "t_end = 0.006\ndt = 1e-3\nadaptive = false\nremesh_every = 4\nremesh_factor = 10.0\n";
  const Case fitted = make(keys + "remesh_projection = \"nodes\"\n");
  const Case copied = make(keys + "remesh_projection = \"nodes\"\nremesh_fit_iterations = 0\n");
  const Case projected = make(keys);
  const DynamicsRun a = problems::run_dynamics(PETSC_COMM_WORLD, fitted.scene, fitted.settings, nullptr, nullptr);
  const DynamicsRun b = problems::run_dynamics(PETSC_COMM_WORLD, copied.scene, copied.settings, nullptr, nullptr);
  const DynamicsRun c = problems::run_dynamics(PETSC_COMM_WORLD, projected.scene, projected.settings, nullptr, nullptr);
  ASSERT_TRUE(a.failure.empty() && b.failure.empty() && c.failure.empty()) << a.failure << b.failure << c.failure;
  std::printf("re-mesh: relative change of E fitted %+.2e, copied %+.2e, L2-projected from the points %+.2e\n", a.remesh_changes[0],
              b.remesh_changes[0], c.remesh_changes[0]);
  ASSERT_EQ(a.remeshes, 1);
  ASSERT_EQ(a.remesh_changes.size(), 1u);
  // The projection changes E (it is one), by little when the new field is fitted to the old one or
  // L2-projected from the points: measured +1.1e-3 fitted, +9.5e-4 projected, -5.7e-2 copied (LME
  // smooths the copied values a second time).
  EXPECT_LT(std::abs(a.remesh_changes[0]), 5e-3);
  EXPECT_LT(std::abs(c.remesh_changes[0]), 5e-3);
  EXPECT_GT(std::abs(b.remesh_changes[0]), 10 * std::abs(a.remesh_changes[0]));
  for (std::size_t s = 5; s < c.history.size(); ++s) EXPECT_LT(c.history[s].energy, c.history[s - 1].energy) << "step " << s;
  // Area and volume keep their targets, and the motion goes on downhill from the projected state.
  EXPECT_LT(relative_drift(a, 0), 1e-10);
  EXPECT_LT(relative_drift(a, 1), 1e-10);
  for (std::size_t s = 5; s < a.history.size(); ++s) EXPECT_LT(a.history[s].energy, a.history[s - 1].energy) << "step " << s;
  // The membrane (phi = 0 of the material field) is one sphere at every step, the re-mesh's
  // projection included.
  ASSERT_TRUE(c.initial_topology.has_value());
  EXPECT_EQ(c.initial_topology->describe(), "1 component, genus 0 (a sphere)");
  for (const auto& s : c.history) {
    ASSERT_TRUE(s.topology.has_value()) << "step " << s.step;
    EXPECT_TRUE(s.topology->same_as(*c.initial_topology)) << "step " << s.step << ": " << s.topology->describe();
  }
  EXPECT_TRUE(c.warnings.empty());
}

// Two spheres 0.06 apart (about one spacing; eps = 2h): a re-mesh whose projection copies the nodal
// values (LME smooths them a second time) joins them. The change is warned of; the guard stops
// the run at the step before that re-mesh instead.
TEST(Dynamics, AReMeshThatJoinsTwoSpheresIsWarnedOfAndTheGuardStopsBeforeIt) {
  auto two_spheres = [](const std::string& keys) {
    std::string text = scene_text("t_end = 0.003\ndt = 1e-3\nadaptive = false\nremesh_every = 1\nremesh_factor = 10.0\n"
                                  "remesh_projection = \"nodes\"\nremesh_fit_iterations = 0\n" + keys);
    const auto from = text.find("phi = \"tanh("), to = text.find('\n', from);
    text.replace(from, to - from,
                 "phi = \"max(tanh((0.2 - sqrt(x[0]^2 + (x[1] - 0.52)^2)) / (sqrt(2)*eps)), "
                 "tanh((0.2 - sqrt(x[0]^2 + (x[1] - 0.98)^2)) / (sqrt(2)*eps)))\"");
    const std::string_view extensions[] = {problems::kDynamicsExtension};
    Case r{parse_scene(text, "two_spheres.toml", extensions), {}};
    r.settings = *problems::read_dynamics(r.scene);
    return r;
  };
  const Case warned = two_spheres("");
  const DynamicsRun a = problems::run_dynamics(PETSC_COMM_WORLD, warned.scene, warned.settings, nullptr, nullptr);
  ASSERT_TRUE(a.failure.empty()) << a.failure;
  ASSERT_TRUE(a.initial_topology.has_value());
  EXPECT_EQ(a.initial_topology->describe(), "2 components, genus 0, 0 (2 spheres)");
  ASSERT_EQ(a.history.size(), 4u);
  EXPECT_TRUE(a.history[1].topology->same_as(*a.initial_topology));  // the motion keeps it
  EXPECT_EQ(a.history[2].topology->describe(), "1 component, genus 0 (a sphere)");
  ASSERT_GE(a.warnings.size(), 1u);
  EXPECT_NE(a.warnings[0].find("the membrane's topology changed at re-mesh 1 (step 1): 2 components, genus 0, 0 (2 spheres) -> "
                               "1 component, genus 0 (a sphere)"),
            std::string::npos)
      << a.warnings[0];

  const Case guarded = two_spheres("topology_guard = true\n");
  const DynamicsRun b = problems::run_dynamics(PETSC_COMM_WORLD, guarded.scene, guarded.settings, nullptr, nullptr);
  EXPECT_NE(b.failure.find("dynamics.topology_guard rejects the re-mesh"), std::string::npos) << b.failure;
  EXPECT_EQ(b.remeshes, 0);
  ASSERT_EQ(b.history.size(), 2u);  // the start and step 1, as in the warned run
  EXPECT_EQ(b.history[1].energy, a.history[1].energy);
  EXPECT_TRUE(b.history[1].topology->same_as(*a.initial_topology));
  EXPECT_TRUE(b.warnings.empty());
}

TEST(Dynamics, AReMeshCanChangeTheNodeCount) {
  const std::string keys = "t_end = 0.006\ndt = 1e-3\nadaptive = false\nremesh_every = 4\nremesh_factor = 10.0\n";
  const Case same = make(keys);
  const DynamicsRun a = problems::run_dynamics(PETSC_COMM_WORLD, same.scene, same.settings, nullptr, nullptr);
  ASSERT_TRUE(a.failure.empty()) << a.failure;
  const std::size_t n = a.reference_nodes.size(), more = n + n / 2;
  const Case grown = make(keys + "remesh_nodes = " + std::to_string(more) + "\n");
  const DynamicsRun b = problems::run_dynamics(PETSC_COMM_WORLD, grown.scene, grown.settings, nullptr, nullptr);
  ASSERT_TRUE(b.failure.empty()) << b.failure;
  ASSERT_EQ(b.remeshes, 1);
  EXPECT_EQ(b.reference_nodes.size(), more);
  std::printf("re-mesh to %zu nodes (from %zu): relative change of E %+.2e (same count %+.2e)\n", more, n, b.remesh_changes[0],
              a.remesh_changes[0]);
  EXPECT_LT(std::abs(b.remesh_changes[0]), 5e-3);
  // The walls keep their nodes: the box is still held, and the motion goes on downhill.
  EXPECT_LT(relative_drift(b, 0), 1e-10);
  EXPECT_LT(relative_drift(b, 1), 1e-10);
  for (std::size_t s = 5; s < b.history.size(); ++s) EXPECT_LT(b.history[s].energy, b.history[s - 1].energy) << "step " << s;
  // Fewer nodes than the walls hold is refused with the key's name.
  const Case tiny = make(keys + "remesh_nodes = 5\n");
  try {
    const DynamicsRun c = problems::run_dynamics(PETSC_COMM_WORLD, tiny.scene, tiny.settings, nullptr, nullptr);
    EXPECT_NE(c.failure.find("remesh_nodes"), std::string::npos) << c.failure;
  } catch (const std::exception& e) {
    EXPECT_NE(std::string(e.what()).find("remesh_nodes = 5"), std::string::npos) << e.what();
  }
}

TEST(Dynamics, CarryingAFieldToPointsOutsideTheOldHullFailsOrFallsBackToTheNearestValue) {
  // Old nodes on [0, 0.5] x [0, 1]; new points inside and one at x = 0.9, outside their hull.
  const NodeSet old_nodes = uniform_grid(Box{2, {0.0, 0.0, 0.0}, {0.5, 1.0, 0.0}}, std::array<int, 3>{6, 11, 1});
  std::vector<double> values(old_nodes.size());
  for (std::size_t a = 0; a < old_nodes.size(); ++a) values[a] = 1.0 + 2.0 * old_nodes.point(a)[0] + old_nodes.point(a)[1];
  const NodeSet new_nodes(2, {0.25, 0.5, 0.9, 0.5});
  EXPECT_THROW((void)problems::interpolate_nodal_field(old_nodes, values, 0.8, LmeOptions{}, new_nodes), LmeEvaluationError);
  std::size_t fallbacks = 0;
  const std::vector<double> carried = problems::interpolate_nodal_field(old_nodes, values, 0.8, LmeOptions{}, new_nodes, &fallbacks);
  EXPECT_EQ(fallbacks, 1u);
  EXPECT_NEAR(carried[0], 1.0 + 0.5 + 0.5, 1e-8);  // affine: reproduced inside
  EXPECT_NEAR(carried[1], 1.0 + 1.0 + 0.5, 1e-12);  // the nearest old node, (0.5, 0.5)
}

TEST(Dynamics, NodalFitsAndPointValuesWorkAtABoundaryRefinedMoreFinelyThanTheNodesBesideIt) {
  // Nodes every 0.01 along the edge x = 1 and along x = 0.9, every 0.1 on [0, 0.5] x [0, 1]: at
  // gamma = 1.4 no support reaches an edge node from inside (radii 0.031 and 0.31), so its list
  // holds only edge nodes, a flat neighbourhood (as a crack reaching the edge of a SENS specimen
  // made one). Its Delaunay cell's vertices join, and an affine field's values are its coefficients.
  std::vector<double> coords;
  for (int j = 0; j <= 100; ++j) coords.insert(coords.end(), {1.0, 0.01 * j, 0.9, 0.01 * j});
  for (int i = 0; i <= 5; ++i)
    for (int j = 0; j <= 10; ++j) coords.insert(coords.end(), {0.1 * i, 0.1 * j});
  const NodeSet nodes(2, std::move(coords));
  const LmeBasis basis(nodes, std::vector<double>(nodes.size(), 1.4), LmeOptions{});
  const auto edge_node = nodes.point(2 * 37);  // (1, 0.37)
  EXPECT_THROW((void)basis.evaluate(edge_node, basis.neighbours(edge_node), 0), LmeEvaluationError);
  auto affine = [](std::span<const double> x) { return 0.3 + 2.0 * x[0] - 1.5 * x[1]; };
  std::vector<double> values;
  for (std::size_t a = 0; a < nodes.size(); ++a) values.push_back(affine(nodes.point(a)));
  const std::vector<double> fitted = problems::fit_nodal_values(nodes, values, 1.4, LmeOptions{}, 10);
  double error = 0;
  for (std::size_t a = 0; a < nodes.size(); ++a) error = std::max(error, std::abs(fitted[a] - values[a]));
  EXPECT_LT(error, 1e-10);
  // A point output evaluated there (a requirement checked at the nodes) takes nodes off the edge.
  std::vector<int> list = basis.neighbours(edge_node);
  const std::size_t own = list.size();
  const std::vector<double> p = problems::evaluate_with_nearest_nodes(basis, edge_node, list, 0);
  EXPECT_GT(list.size(), own);
  double value = 0;
  for (std::size_t m = 0; m < list.size(); ++m) value += p[m] * values[std::size_t(list[m])];
  EXPECT_NEAR(value, affine(edge_node), 1e-12);
}

TEST(Dynamics, TheL2ProjectionFromPointsReproducesAFieldOfTheSpace) {
  // LME reproduces affine fields: their coefficients are their nodal values, so the projection of an
  // affine field's point values must return exactly those, on a strongly graded node set.
  const NodeSet nodes = graded_grid_2d();  // h from 0.01 on a circle to 0.12
  auto affine = [](double x, double y) { return 0.3 + 2.0 * x - 1.5 * y; };
  const NodeSet cloud = random_points(Box::unit(2), 20000, 7);
  SplitMix64 random(11);
  std::vector<double> points = cloud.coords, weights, values;
  for (std::size_t q = 0; q < cloud.size(); ++q) {
    weights.push_back(q % 7 == 0 ? 0.0 : 0.5 + random.uniform());  // some points skipped
    values.push_back(affine(cloud.point(q)[0], cloud.point(q)[1]));
  }
  const std::vector<double> start(nodes.size(), 0.0);
  const problems::PointProjection l2 = problems::project_point_values(nodes, 0.8, LmeOptions{}, points, weights, values, start, 1e-12);
  EXPECT_LT(l2.relative_residual, 1e-12);
  double error = 0;
  for (std::size_t a = 0; a < nodes.size(); ++a) error = std::max(error, std::abs(l2.values[a] - affine(nodes.point(a)[0], nodes.point(a)[1])));
  EXPECT_LT(error, 1e-6);  // measured 2.2e-8: the mass matrix of a smooth basis is ill-conditioned
  // A node with no point in its support is an error, not a silent zero.
  std::vector<double> far_points, far_weights, far_values;
  for (std::size_t q = 0; q < weights.size(); ++q)
    if (points[2 * q] < 0.5) {
      far_points.insert(far_points.end(), {points[2 * q], points[2 * q + 1]});
      far_weights.push_back(weights[q]);
      far_values.push_back(values[q]);
    }
  EXPECT_THROW((void)problems::project_point_values(nodes, 0.8, LmeOptions{}, far_points, far_weights, far_values, start), std::runtime_error);
}

TEST(Dynamics, TheProjectionEvaluatesPointsOutsideTheHullOfTheirSupportsThroughTheirCell) {
  // On a strongly graded node set some points of long cells lie outside the hull of the nodes whose
  // supports reach them (as carried quadrature points did at a re-mesh of the eps = 0.01 prolate).
  // The projection adds the enclosing Delaunay cell's vertices there and still reproduces an
  // affine field.
  // A fine strip (h = 0.02, x <= 0.1) beside coarse nodes (h = 0.2, x >= 0.3): in the gap the fine
  // supports (radius 0.037 at gamma = 4) end short, and the coarse nodes reaching there all lie on
  // one side.
  const NodeSet nodes = fine_strip_beside_coarse_nodes();
  const double gamma = 4.0;
  const CellQuadrature cloud = map_to_cells(delaunay(nodes), nodes, triangle_rule(6));
  const LmeBasis basis(nodes, std::vector<double>(nodes.size(), gamma), LmeOptions{});
  std::size_t unevaluable = 0;
  for (std::size_t q = 0; q < cloud.size(); ++q) {
    try {
      (void)basis.evaluate(cloud.point(q), basis.neighbours(cloud.point(q)), 0);
    } catch (const LmeEvaluationError&) {
      ++unevaluable;
    }
  }
  std::printf("%zu of %zu points cannot be evaluated on their own neighbours\n", unevaluable, cloud.size());
  ASSERT_GT(unevaluable, 0u);

  auto affine = [](double x, double y) { return 0.3 + 2.0 * x - 1.5 * y; };
  std::vector<double> values;
  for (std::size_t q = 0; q < cloud.size(); ++q) values.push_back(affine(cloud.point(q)[0], cloud.point(q)[1]));
  const std::vector<double> start(nodes.size(), 0.0);
  const problems::PointProjection l2 = problems::project_point_values(nodes, gamma, LmeOptions{}, cloud.points, cloud.weights, values, start, 1e-12);
  EXPECT_LT(l2.relative_residual, 1e-12);
  double error = 0;
  for (std::size_t a = 0; a < nodes.size(); ++a) error = std::max(error, std::abs(l2.values[a] - affine(nodes.point(a)[0], nodes.point(a)[1])));
  EXPECT_LT(error, 1e-6);
}

TEST(Dynamics, TheH1ProjectionFromPointsFitsGradientsBetterThanL2) {
  // With the gradients at the points and a length l, the fit minimizes Σ w [(φ − v)² + l² |∇φ − g|²].
  // An affine field is still reproduced exactly; a steep tanh profile, which the space cannot hold,
  // gets a gradient error no larger than the L2 fit's (the H1 minimizer trades value error for it).
  const NodeSet nodes = graded_grid_2d();
  const NodeSet cloud = random_points(Box::unit(2), 20000, 5);
  const std::size_t Q = cloud.size();
  const std::vector<double> weights(Q, 1.0 / double(Q));
  const std::vector<double> start(nodes.size(), 0.0);
  std::vector<double> affine_values, affine_gradients;
  for (std::size_t q = 0; q < Q; ++q) {
    affine_values.push_back(0.3 + 2.0 * cloud.point(q)[0] - 1.5 * cloud.point(q)[1]);
    affine_gradients.insert(affine_gradients.end(), {2.0, -1.5});
  }
  const problems::PointProjection affine = problems::project_point_values(nodes, 0.8, LmeOptions{}, cloud.coords, weights, affine_values, start,
                                                                1e-12, 5000, {affine_gradients, 0.05});
  double error = 0;
  for (std::size_t a = 0; a < nodes.size(); ++a)
    error = std::max(error, std::abs(affine.values[a] - (0.3 + 2.0 * nodes.point(a)[0] - 1.5 * nodes.point(a)[1])));
  EXPECT_LT(error, 1e-6);

  const double width = 0.02;  // the grid's h is 0.01 only on its circle: the profile is under-resolved elsewhere
  std::vector<double> values, gradients;
  for (std::size_t q = 0; q < Q; ++q) {
    const double x = cloud.point(q)[0] - 0.5, t = std::tanh(x / width);
    values.push_back(t);
    gradients.insert(gradients.end(), {(1 - t * t) / width, 0.0});
  }
  const problems::PointProjection l2 = problems::project_point_values(nodes, 0.8, LmeOptions{}, cloud.coords, weights, values, start, 1e-10);
  const problems::PointProjection h1 =
      problems::project_point_values(nodes, 0.8, LmeOptions{}, cloud.coords, weights, values, start, 1e-10, 5000, {gradients, width});
  auto errors = [&](const std::vector<double>& c) {
    const LmeBasis basis(nodes, std::vector<double>(nodes.size(), 0.8), LmeOptions{});
    double value_error = 0, gradient_error = 0;
    for (std::size_t q = 0; q < Q; ++q) {
      const auto list = basis.neighbours(cloud.point(q));
      const auto jet = basis.evaluate(cloud.point(q), list, 1);
      double v = 0, gx = 0, gy = 0;
      for (std::size_t m = 0; m < list.size(); ++m) {
        v += jet[m] * c[std::size_t(list[m])];
        gx += jet[list.size() + m] * c[std::size_t(list[m])];
        gy += jet[2 * list.size() + m] * c[std::size_t(list[m])];
      }
      value_error += weights[q] * (v - values[q]) * (v - values[q]);
      gradient_error += weights[q] * ((gx - gradients[2 * q]) * (gx - gradients[2 * q]) + gy * gy);
    }
    return std::pair{value_error, gradient_error};
  };
  const auto [l2_value, l2_gradient] = errors(l2.values);
  const auto [h1_value, h1_gradient] = errors(h1.values);
  std::printf("tanh profile: value error L2 fit %.3e, H1 fit %.3e; gradient error L2 fit %.3e, H1 fit %.3e\n", l2_value, h1_value,
              l2_gradient, h1_gradient);
  EXPECT_LE(l2_value, h1_value * (1 + 1e-6));        // L2 minimizes the value error
  EXPECT_LT(h1_gradient, l2_gradient);               // H1 trades some of it for the gradient
  EXPECT_LT(h1_gradient, 0.9 * l2_gradient) << "L2 " << l2_gradient << ", H1 " << h1_gradient;
  // Gradients that do not match the points are an error.
  EXPECT_THROW((void)problems::project_point_values(nodes, 0.8, LmeOptions{}, cloud.coords, weights, values, start, 1e-8, 10,
                                               {std::span<const double>(gradients).first(10), width}),
               std::invalid_argument);
}

TEST(Dynamics, AJumpOfSpontaneousCurvatureActsFromItsTime) {
  const Case plain = make("t_end = 0.004\ndt = 1e-3\nadaptive = false\n");
  const Case jump = make("t_end = 0.004\ndt = 1e-3\nadaptive = false\n[dynamics.schedule]\nC0 = { at = 0.002, value = 3.0 }\n");
  const DynamicsRun a = problems::run_dynamics(PETSC_COMM_WORLD, plain.scene, plain.settings, nullptr, nullptr);
  const DynamicsRun b = problems::run_dynamics(PETSC_COMM_WORLD, jump.scene, jump.settings, nullptr, nullptr);
  ASSERT_TRUE(a.failure.empty() && b.failure.empty()) << a.failure << b.failure;
  ASSERT_EQ(a.history.size(), 5u);
  ASSERT_EQ(b.history.size(), 5u);
  // Steps ending before t* = 0.002 are the same; the step ending at 0.002 and later ones see C0 = 3.
  EXPECT_NEAR(b.history[1].energy, a.history[1].energy, 1e-12 * a.history[1].energy);
  for (std::size_t s = 2; s < 5; ++s) EXPECT_GT(std::abs(b.history[s].energy - a.history[s].energy), 1e-3) << "step " << s;
}

TEST(Dynamics, BadScenesNameTheKey) {
  auto error_of = [](const std::string& dynamics) {
    try {
      const Case r = make(dynamics);
      (void)problems::run_dynamics(PETSC_COMM_WORLD, r.scene, r.settings, nullptr, nullptr);
    } catch (const SceneError& e) {
      return std::string(e.what());
    }
    return std::string("accepted");
  };
  EXPECT_NE(error_of("t_end = 0.01\ndt = 1e-3\nmethod = \"forward-euler\"\n").find("did you mean"), std::string::npos);
  std::string msg = error_of("t_end = 0.01\ndt = 1e-3\n[dynamics.schedule]\nC1 = { at = 0.0, value = 1.0 }\n");
  EXPECT_NE(msg.find("'C1' is no constant of the forms; did you mean 'C0'?"), std::string::npos) << msg;
  {
    std::string text = scene_text("t_end = 0.01\ndt = 1e-3\n");
    text.replace(text.find("dissipation = \"dissipation\""), 27, "dissipation = \"disipation\"");
    const std::string_view extensions[] = {problems::kDynamicsExtension};
    const Scene scene = parse_scene(text, "dynamics_test.toml", extensions);
    try {
      (void)problems::run_dynamics(PETSC_COMM_WORLD, scene, *problems::read_dynamics(scene), nullptr, nullptr);
      ADD_FAILURE() << "a misspelt dissipation output was accepted";
    } catch (const SceneError& e) {
      EXPECT_NE(std::string(e.what()).find("disipation"), std::string::npos) << e.what();
      EXPECT_NE(std::string(e.what()).find("dissipation"), std::string::npos) << e.what();
    }
  }
  msg = error_of("t_end = 0.01\ndt = 1e-3\n[dynamics.schedule]\nC0 = [ { at = 0.005, value = 1.0 }, { at = 0.002, value = 0.0 } ]\n");
  EXPECT_NE(msg.find("time order"), std::string::npos) << msg;
  msg = error_of("t_end = 0.01\ndt = -1.0\n");
  EXPECT_NE(msg.find("dynamics.dt"), std::string::npos) << msg;
  EXPECT_NE(error_of("t_end = 0.01\ndt = 1e-3\nadaptive = false\nreport_times = [0.5]\n").find("outside"), std::string::npos);
  msg = error_of("t_end = 0.01\ndt = 1e-3\ntopology_field = \"psi\"\n");
  EXPECT_NE(msg.find("'dynamics.topology_field': 'psi' is no scalar field of [coefficients]"), std::string::npos) << msg;
  msg = error_of("t_end = 0.01\ndt = 1e-3\nremesh_field = \"psi\"\ntopology_guard = true\n");
  EXPECT_NE(msg.find("'dynamics.topology_guard'"), std::string::npos) << msg;
}

}  // namespace

int main(int argc, char** argv) {
  ::testing::InitGoogleTest(&argc, argv);
  lmeform::PetscSession session(&argc, &argv);
  return RUN_ALL_TESTS();
}
