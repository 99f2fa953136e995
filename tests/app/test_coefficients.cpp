// Known nodal fields (`coefficient` in a form) set by a scene's [coefficients] table: a Poisson
// problem whose source is a coefficient converges to the manufactured solution, the coefficient is
// interpolated by the basis like an unknown (2D and 3D), and missing or misspelt coefficients are
// named.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <string>

#include "lmeform/petsc.hpp"
#include "lmeform/scene.hpp"
#include "stationary.hpp"

namespace {

using namespace lmeform;
namespace fs = std::filesystem;

fs::path write_scene(const std::string& name, const std::string& text) {
  const fs::path dir = fs::path(LMEFORM_TEST_TMPDIR) / "coefficients";
  fs::create_directories(dir);
  fs::copy_file(fs::path(LMEFORM_TEST_DATA) / "source_poisson.form", dir / "source_poisson.form",
                fs::copy_options::overwrite_existing);
  std::ofstream(dir / name) << text;
  return dir / name;
}

std::string scene(int n, const std::string& coefficients) {
  return "[scene]\nname = \"source\"\ncoordinates = \"cartesian\"\n[domain]\nlower = [0.0, 0.0]\nupper = [1.0, 1.0]\n"
         "[nodes]\ncounts = [" + std::to_string(n) + ", " + std::to_string(n) + "]\ngamma = 0.8\nquadrature_points = 6\n"
         "[model]\nforms = [\"source_poisson.form\"]\n" + coefficients +
         "[[dirichlet]]\nboundary = [\"hull\"]\nunknown = \"u\"\nvalue = 0.0\n"
         "[reference.solution]\nu = \"sin(pi*x[0])*sin(pi*x[1])\"\n";
}

problems::ProblemResult solve(const fs::path& path) {
  const Scene s = load_scene(path);
  const problems::BoundScene bound = problems::bind_scene(s, PETSC_COMM_WORLD, nullptr);
  problems::ProblemInput input;
  input.nodes = problems::initial_nodes(s, PETSC_COMM_WORLD);
  return problems::solve_problem(PETSC_COMM_WORLD, bound, input);
}

TEST(SceneCoefficients, SourceAsCoefficientConverges) {
  const std::string f = "[coefficients]\nf = \"2*pi^2*sin(pi*x[0])*sin(pi*x[1])\"\n";
  const auto coarse = solve(write_scene("coarse.toml", scene(9, f)));
  const auto fine = solve(write_scene("fine.toml", scene(17, f)));
  ASSERT_TRUE(coarse.converged) << coarse.message;
  ASSERT_TRUE(fine.converged) << fine.message;
  ASSERT_EQ(fine.errors.size(), 1u);
  // Second order in L2 (h halves): the coefficient is interpolated, not exact, and still converges.
  // Measured (gamma 0.8): L2 4.68e-2 on 9^2 nodes, 1.19e-2 on 17^2, rate 1.97.
  const double rate = std::log(coarse.errors[0].l2 / fine.errors[0].l2) / std::log(2.0);
  std::printf("source as coefficient: L2 %.3e -> %.3e, rate %.2f\n", coarse.errors[0].l2, fine.errors[0].l2, rate);
  EXPECT_LT(fine.errors[0].l2, 2e-2);
  EXPECT_GT(rate, 1.8);
}

// A constant source given as a number: the energy at u = 0 is zero and the minimizer moves against
// the source (u > 0 inside for f > 0).
TEST(SceneCoefficients, NumberAndExpressionGiveTheSameField) {
  const auto number = solve(write_scene("number.toml", scene(9, "[coefficients]\nf = 3.0\n")));
  const auto expression = solve(write_scene("expression.toml", scene(9, "[coefficients]\nf = \"3 + 0*x[0]\"\n")));
  ASSERT_TRUE(number.converged);
  ASSERT_TRUE(expression.converged);
  ASSERT_EQ(number.state.size(), expression.state.size());
  double biggest = 0;
  for (std::size_t i = 0; i < number.state.size(); ++i) {
    EXPECT_NEAR(number.state[i], expression.state[i], 1e-12);
    biggest = std::max(biggest, number.state[i]);
  }
  EXPECT_GT(biggest, 0.1);
}

// The start of a scene of initial_misfit.form on the unit square (nodes 0.1 apart), evaluated only:
// its energies and its state (the coefficients), with the nodes.
struct EvaluatedStart {
  problems::ProblemResult result;
  NodeSet nodes;
};
EvaluatedStart evaluate_start(const std::string& name, const std::string& basis, const std::string& fields) {
  const fs::path dir = fs::path(LMEFORM_TEST_TMPDIR) / "coefficients";
  fs::create_directories(dir);
  fs::copy_file(fs::path(LMEFORM_TEST_DATA) / "initial_misfit.form", dir / "initial_misfit.form", fs::copy_options::overwrite_existing);
  const fs::path path = dir / (name + ".toml");
  std::ofstream(path) << "[scene]\nname = \"" << name << "\"\ncoordinates = \"cartesian\"\n[domain]\nlower = [0.0, 0.0]\nupper = [1.0, 1.0]\n"
                      << "[nodes]\nspacing = 0.1\ngamma = 0.8\nbasis = \"" << basis << "\"\n[model]\nforms = [\"initial_misfit.form\"]\n" << fields;
  const Scene s = load_scene(path);
  const problems::BoundScene bound = problems::bind_scene(s, PETSC_COMM_WORLD, nullptr);
  problems::ProblemInput input;
  input.nodes = problems::initial_nodes(s, PETSC_COMM_WORLD);
  input.evaluate_only = true;
  input.lme = bound.lme(problems::AxisParity::even);
  return {problems::solve_problem(PETSC_COMM_WORLD, bound, input), input.nodes};
}

// With the second-order basis a coefficient is not a nodal value: an [initial] or [coefficients]
// expression is taken as g(x_a) - G_a : Hg(x_a) / 2, and a quadratic field is then represented
// exactly (misfit at round-off); the first-order basis cannot (misfit O(h^4)).
TEST(SceneCoefficients, QuadraticInitialAndCoefficientAreExactWithTheSecondOrderBasis) {
  auto misfit = [&](const std::string& basis) {
    const auto values = evaluate_start("initial_" + basis, basis,
                                       "[initial]\nu = \"x[0]^2 + 3*x[0]*x[1] - x[1]^2\"\n[coefficients]\nf = \"x[0]^2 + 3*x[0]*x[1] - x[1]^2\"\n")
                            .result.values;
    return std::pair{values.at("initial_misfit.misfit"), values.at("initial_misfit.coefficient_misfit")};
  };
  const auto second = misfit("second"), first = misfit("first");
  std::printf("misfit of the quadratic start: %.3e (second order), %.3e (first order); of the coefficient: %.3e, %.3e\n",
              second.first, first.first, second.second, first.second);
  EXPECT_LT(second.first, 1e-20);
  EXPECT_GT(first.first, 1e-10);
  EXPECT_LT(second.second, 1e-20);
  EXPECT_GT(first.second, 1e-10);
}

// A profile narrower than the node spacing (a crack's band, l = 0.02 on nodes 0.1 apart): its
// gap correction G_a : Hg / 2 is not small: without a limit the coefficients ran from 0.593 to 1.257
// here, the field's values from 0.777 to 1. They stay within the values the field takes.
TEST(SceneCoefficients, SecondOrderStartOfANarrowProfileStaysWithinItsValues) {
  const auto [result, nodes] = evaluate_start("narrow", "second", "[initial]\nu = \"1 - exp(-abs(x[1] - 0.53)/0.02)\"\n[coefficients]\nf = 0.0\n");
  ASSERT_EQ(result.state.size(), nodes.size());
  double low = 1, high = 0, lowest_given = 1;
  for (std::size_t a = 0; a < nodes.size(); ++a) {
    low = std::min(low, result.state[a]), high = std::max(high, result.state[a]);
    lowest_given = std::min(lowest_given, 1 - std::exp(-std::abs(nodes.point(a)[1] - 0.53) / 0.02));
  }
  std::printf("narrow profile: coefficients in [%.6f, %.6f], the field's values from %.6f\n", low, high, lowest_given);
  EXPECT_GE(low, lowest_given - 1e-15);
  EXPECT_LE(high, 1.0);
  // Corrected, not merely the nodal values: somewhere the coefficient differs from g(x_a).
  double moved = 0;
  for (std::size_t a = 0; a < nodes.size(); ++a)
    moved = std::max(moved, std::abs(result.state[a] - (1 - std::exp(-std::abs(nodes.point(a)[1] - 0.53) / 0.02))));
  EXPECT_GT(moved, 1e-3);
}

TEST(SceneCoefficients, MissingAndMisspeltAreNamed) {
  try {
    (void)solve(write_scene("missing.toml", scene(5, "")));
    ADD_FAILURE() << "a scene without the coefficient was accepted";
  } catch (const SceneError& e) {
    EXPECT_NE(std::string(e.what()).find("missing key 'coefficients.f'"), std::string::npos) << e.what();
  }
  try {
    (void)solve(write_scene("typo.toml", scene(5, "[coefficients]\nf = 1.0\nff = 2.0\n")));
    ADD_FAILURE() << "an unknown coefficient was accepted";
  } catch (const SceneError& e) {
    EXPECT_NE(std::string(e.what()).find("'ff' is no coefficient field of the forms; did you mean 'f'?"), std::string::npos)
        << e.what();
  }
}

}  // namespace

int main(int argc, char** argv) {
  ::testing::InitGoogleTest(&argc, argv);
  lmeform::PetscSession session(&argc, &argv);
  return RUN_ALL_TESTS();
}
