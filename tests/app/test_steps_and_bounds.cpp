// The generic problem drivers and solves of load-stepped, bounded and staggered problems, and the
// quantities they report: a load-stepped Poisson problem restarted mid-way equals the uninterrupted
// run; a reaction balances the source; bounds give a known active set; alternate minimization of
// two coupled fields reaches the monolithic minimizer.
#include <fmt/format.h>
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>

#include "../assembly/assembly_fixtures.hpp"
#include "lmeform/form_registry.hpp"
#include "lmeform/node_sets.hpp"
#include "lmeform/petsc.hpp"
#include "lmeform/scene.hpp"
#include "problem_registry.hpp"
#include "stationary.hpp"

namespace {

using namespace lmeform;
namespace fs = std::filesystem;

fs::path folder() {
  const fs::path dir = fs::path(LMEFORM_TEST_TMPDIR) / "steps_and_bounds";
  fs::create_directories(dir);
  for (const char* form : {"poisson_mms.form"}) fs::copy_file(fs::path(LMEFORM_DEMOS) / "poisson" / form, dir / form, fs::copy_options::overwrite_existing);
  for (const char* form : {"two_fields.form", "kinked_spring.form"})
    fs::copy_file(fs::path(LMEFORM_TEST_DATA) / form, dir / form, fs::copy_options::overwrite_existing);
  return dir;
}

/// The manufactured Poisson problem of the demos on 11 x 11 nodes: u = c sin(πx) sin(πy).
std::string poisson(const std::string& extra) {
  return "[scene]\nname = \"p\"\ncoordinates = \"cartesian\"\n[domain]\nlower = [0.0, 0.0]\nupper = [1.0, 1.0]\n"
         "[nodes]\nspacing = 0.1\n[model]\nforms = [\"poisson_mms.form\"]\nbilinear = \"a\"\nlinear = \"l\"\n"
         "[[dirichlet]]\nboundary = [\"hull\"]\nunknown = \"u\"\nvalue = \"c*sin(pi*x[0])*sin(pi*x[1])\"\n" + extra;
}

problems::RunReport run(const std::string& name, const std::string& text, const fs::path& output, bool restart = false) {
  const fs::path path = folder() / name;
  std::ofstream(path) << text;
  const Scene scene = load_scene(path, problems::driver_tables());
  problems::DriverContext ctx;
  ctx.comm = PETSC_COMM_WORLD;
  ctx.scene = &scene;
  ctx.output_directory = output;
  ctx.restart = restart;
  return problems::driver_for(scene).run(ctx);
}

std::string read(const fs::path& p) {
  std::ifstream in(p);
  std::stringstream s;
  s << in.rdbuf();
  return s.str();
}

const std::string kQuantities = "[quantities]\nflux = { reaction = \"hull\", unknown = \"u\" }\ncentre = { probe = [0.5, 0.5], field = \"u\" }\n";

TEST(Quantities, TheReactionBalancesTheSource) {
  const problems::RunReport r = run("flux.toml", poisson(kQuantities), "");
  ASSERT_TRUE(r.success) << r.status;
  // -Δu = f with f = 2π² sin sin: Σ over the hull of (A u − b) = −Σ_a b_a = −∫ f dx by the basis'
  // partition of unity, −8 up to the quadrature's error in ∫ f (measured: 1.7e-9 relative).
  EXPECT_NEAR(r.json["quantities"]["flux"].get<double>(), -8.0, 1e-7);
  EXPECT_NEAR(r.json["quantities"]["centre"].get<double>(), 1.0, 1e-3);
}

TEST(LoadSteps, ARestartMidwayEqualsTheUninterruptedRun) {
  const std::string steps = "[steps]\ncount = 4\nramp = { c = [0.0, 1.0] }\n";
  const fs::path whole = folder() / "whole", parts = folder() / "parts";
  fs::remove_all(whole);
  fs::remove_all(parts);
  const problems::RunReport a = run("whole.toml", poisson(kQuantities + steps), whole);
  ASSERT_TRUE(a.success) << a.status;
  const problems::RunReport first = run("first.toml", poisson(kQuantities + steps + "until = 2\n"), parts);
  ASSERT_TRUE(first.success) << first.status;
  EXPECT_NE(first.status.find("steps.until"), std::string::npos) << first.status;
  const problems::RunReport rest = run("rest.toml", poisson(kQuantities + steps), parts, /*restart=*/true);
  ASSERT_TRUE(rest.success) << rest.status;
  // The columns but the wall time agree to every digit.
  auto strip_times = [](const std::string& csv) {
    std::string out;
    std::istringstream in(csv);
    for (std::string line; std::getline(in, line);) out += line.substr(0, line.rfind(',')) + "\n";
    return out;
  };
  EXPECT_EQ(strip_times(read(whole / "history.csv")), strip_times(read(parts / "history.csv")));
  // The load is linear in c: the flux at step k is −8 k/4.
  const auto& last = a.json["steps"].back();
  EXPECT_EQ(last["step"].get<int>(), 4);
  EXPECT_NEAR(last["quantities"]["flux"].get<double>(), -8.0, 1e-7);
  EXPECT_NEAR(a.json["steps"][2]["quantities"]["flux"].get<double>(), 0.5 * last["quantities"]["flux"].get<double>(), 1e-12);
}

TEST(Bounds, KnownActiveSets) {
  // The unbounded solution peaks at 1: a bound of 2 holds nowhere, a bound of 0 everywhere (the
  // source pushes every free dof up), and 0.5 clips the peak.
  const problems::RunReport none = run("high.toml", poisson(kQuantities + "[bounds]\nu = { upper = 2.0 }\n"), "");
  const problems::RunReport all = run("zero.toml", poisson(kQuantities + "[bounds]\nu = { upper = 0.0 }\n"), "");
  const problems::RunReport some = run("half.toml", poisson(kQuantities + "[bounds]\nu = { upper = 0.5 }\n"), "");
  for (const auto* r : {&none, &all, &some}) ASSERT_TRUE(r->success) << r->status;
  EXPECT_EQ(none.json["active_set"]["upper"].get<long>(), 0);
  EXPECT_EQ(all.json["active_set"]["upper"].get<long>(), 81);  // every interior node of 11 x 11
  const long clipped = some.json["active_set"]["upper"].get<long>();
  EXPECT_GT(clipped, 0);
  EXPECT_LT(clipped, 81);
  // The LME field is a convex combination of its coefficients: at most the bound.
  EXPECT_LE(some.json["quantities"]["centre"].get<double>(), 0.5 + 1e-12);
  EXPECT_GT(some.json["quantities"]["centre"].get<double>(), 0.499);
  // Where the bound is active the problem pushes against it: the flux is weaker than unbounded.
  EXPECT_GT(some.json["quantities"]["flux"].get<double>(), -8.0);
}

TEST(Bounds, AStartOutsideTheBoundsAndCrossedBoundsAreRefused) {
  try {
    (void)run("outside.toml", poisson("[initial]\nu = 1.0\n[bounds]\nu = { upper = 0.5 }\n"), "");
    ADD_FAILURE() << "a start above the upper bound was accepted";
  } catch (const SceneError& e) {
    EXPECT_NE(std::string(e.what()).find("the start violates the bounds"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("key 'bounds.u'"), std::string::npos) << e.what();
  }
  try {
    (void)run("crossed.toml", poisson("[bounds]\nu = { lower = 1.0, upper = 0.5 }\n"), "");
    ADD_FAILURE() << "crossed bounds were accepted";
  } catch (const SceneError& e) {
    EXPECT_NE(std::string(e.what()).find("lies above upper"), std::string::npos) << e.what();
  }
}

TEST(Dirichlet, TwoEntriesThatDisagreeAtACornerAreRefused) {
  const std::string scene = "[scene]\nname = \"p\"\ncoordinates = \"cartesian\"\n[domain]\nlower = [0.0, 0.0]\nupper = [1.0, 1.0]\n"
                            "[nodes]\nspacing = 0.1\n[model]\nforms = [\"poisson_mms.form\"]\nbilinear = \"a\"\nlinear = \"l\"\n"
                            "[[dirichlet]]\nboundary = \"x_min\"\nunknown = \"u\"\nvalue = 0.0\n"
                            "[[dirichlet]]\nboundary = \"y_min\"\nunknown = \"u\"\nvalue = \"x[0]\"\n"
                            "[[dirichlet]]\nboundary = [\"x_max\", \"y_max\"]\nunknown = \"u\"\nvalue = 0.0\n";
  // (0, 0) gets 0 from both: accepted; (1, 0) gets 1 from y_min and 0 from x_max: refused.
  try {
    (void)run("corner.toml", scene, "");
    ADD_FAILURE() << "conflicting corner values were accepted";
  } catch (const SceneError& e) {
    const std::string m = e.what();
    EXPECT_NE(m.find("key 'dirichlet[1]'"), std::string::npos) << m;
    EXPECT_NE(m.find("key 'dirichlet[2]'"), std::string::npos) << m;
    EXPECT_NE(m.find("(1, 0)"), std::string::npos) << m;
  }
}

std::string two_fields(const std::string& extra, const std::string& model = "") {
  return "[scene]\nname = \"two\"\ncoordinates = \"cartesian\"\n[domain]\nlower = [0.0, 0.0]\nupper = [1.0, 1.0]\n"
         "[nodes]\nspacing = 0.1\n[model]\nforms = [\"two_fields.form\"]\n" + model +
         "[[dirichlet]]\nboundary = [\"hull\"]\nunknown = \"u\"\nvalue = 0.0\n"
         "[[dirichlet]]\nboundary = [\"hull\"]\nunknown = \"v\"\nvalue = 0.0\n"
         "[quantities]\nmean_v = { integral = \"v\" }\n" + extra;
}

TEST(Staggered, AlternateMinimizationReachesTheMonolithicMinimizer) {
  const problems::RunReport mono = run("mono.toml", two_fields(""), "");
  const problems::RunReport alternate = run("alternate.toml", two_fields("[staggered]\ngroups = [[\"u\"], [\"v\"]]\ntolerance = 1e-10\n"), "");
  ASSERT_TRUE(mono.success) << mono.status;
  ASSERT_TRUE(alternate.success) << alternate.status;
  EXPECT_NEAR(alternate.json["energy"].get<double>(), mono.json["energy"].get<double>(), 1e-12);
  EXPECT_NEAR(alternate.json["quantities"]["mean_v"].get<double>(), mono.json["quantities"]["mean_v"].get<double>(), 1e-8);
  try {
    (void)run("groups.toml", two_fields("[staggered]\ngroups = [[\"u\"], [\"w\"]]\n"), "");
    ADD_FAILURE() << "a group naming no unknown was accepted";
  } catch (const SceneError& e) {
    EXPECT_NE(std::string(e.what()).find("'w' is no unknown"), std::string::npos) << e.what();
  }
}

/// How many times PETSc has run `event` so far (logging started by the caller).
int petsc_event_count(const char* event) {
  PetscLogEvent id = 0;
  LMEFORM_PETSC_CHECK(PetscLogEventGetId(event, &id));
  PetscEventPerfInfo info{};
  LMEFORM_PETSC_CHECK(PetscLogEventGetPerfInfo(PETSC_DETERMINE, id, &info));
  return info.count;
}

// Every group of a staggered solve is solved again each round: its Newton solver (matrix
// structure, SNES, the direct solver's analysis) is kept in the problem space, so a residual
// problem with two groups analyses two matrices however many rounds it takes, and gets the
// monolithic solution.
TEST(Staggered, EachGroupAnalysesItsMatrixOnceOverAllRounds) {
  const problems::RunReport mono = run("residual_mono.toml", two_fields("", "residual = \"R\"\n"), "");
  LMEFORM_PETSC_CHECK(PetscLogDefaultBegin());
  const int analyses_before = petsc_event_count("MatLUFactorSym");
  const problems::RunReport alternate =
      run("residual_alternate.toml", two_fields("[staggered]\ngroups = [[\"u\"], [\"v\"]]\ntolerance = 1e-10\n", "residual = \"R\"\n"), "");
  const int analyses = petsc_event_count("MatLUFactorSym") - analyses_before;
  ASSERT_TRUE(alternate.success) << alternate.status;
  const int alternations = alternate.json["staggered"]["alternations"].get<int>();
  EXPECT_GT(alternations, 5);
  EXPECT_EQ(analyses, 2) << "after " << alternations << " rounds";
  ASSERT_TRUE(mono.success) << mono.status;
  EXPECT_NEAR(alternate.json["quantities"]["mean_v"].get<double>(), mono.json["quantities"]["mean_v"].get<double>(), 1e-8);
}

// Each group's Newton solves read PETSc options under its own prefix: an iterative solver given
// to the group ["v"] alone leaves the group ["u"] its direct one (one LU analysis, not two), and the
// alternation reaches the same solution.
TEST(Staggered, EachGroupReadsPetscOptionsUnderItsOwnPrefix) {
  const problems::RunReport mono = run("residual_mono.toml", two_fields("", "residual = \"R\"\n"), "");
  LMEFORM_PETSC_CHECK(PetscLogDefaultBegin());
  const int analyses_before = petsc_event_count("MatLUFactorSym");
  const problems::RunReport alternate =
      run("residual_prefixed.toml",
          two_fields("[staggered]\ngroups = [[\"u\"], [\"v\"]]\ntolerance = 1e-10\n"
                     "[solver]\npetsc_options = \"-v_ksp_type gmres -v_pc_type jacobi -v_ksp_rtol 1e-13\"\n",
                     "residual = \"R\"\n"),
          "");
  const int analyses = petsc_event_count("MatLUFactorSym") - analyses_before;
  ASSERT_TRUE(alternate.success) << alternate.status;
  EXPECT_EQ(analyses, 1) << "the group v's options did not reach its solver alone";
  ASSERT_TRUE(mono.success) << mono.status;
  EXPECT_NEAR(alternate.json["quantities"]["mean_v"].get<double>(), mono.json["quantities"]["mean_v"].get<double>(), 1e-8);
}

// The fracture tests' graded node set (spacings 0.03 to 0.15 on the unit square) and its basis.
struct GradedFractureSetup {
  NodeSet nodes;
  Discretization disc;
  GradedFractureSetup() : nodes(graded_nodes()), disc(PETSC_COMM_WORLD, nodes, discretization_options()) {}
  static NodeSet graded_nodes() {
    GradedGridOptions graded;
    graded.h_min = 0.03;
    graded.h_max = 0.15;
    return graded_grid_2d(graded);
  }
  static DiscretizationOptions discretization_options() {
    DiscretizationOptions options;
    options.gamma = {1.6};
    options.quadrature_points = 3;
    return options;
  }
};

// Sets those of `constants` that the kernels declare (a form need not use every one).
void set_declared_constants(Assembler& assembler, const kernel::FormKernels& kernels,
                            const std::vector<std::pair<std::string, double>>& constants) {
  for (int i = 0; i < kernels.n_constants; ++i)
    for (const auto& [name, value] : constants)
      if (name == kernels.constants[i]) assembler.set_constant(name, value);
}

// A staggered group's Hessian couples only its own components: the generated kernel skips the
// other component blocks and the matrix keeps only their diagonal. On the fracture form (u, v)
// with the split's non-smooth energy, on a graded node set, it equals the full Hessian once the
// other group's rows and columns are the identity.
TEST(Staggered, AGroupsHessianFromTheGeneratedKernelEqualsTheFullOne) {
  const GradedFractureSetup setup;
  const NodeSet& nodes = setup.nodes;
  const Discretization& disc = setup.disc;
  const kernel::FormKernels* energy = load_form("fracture_at2").find("elastic", 2);
  ASSERT_NE(energy, nullptr);
  Assembler assembler(disc, *energy);
  set_declared_constants(assembler, *energy, {{"lambda", 121.15}, {"mu", 80.77}, {"Gc", 2.7e-3}, {"l", 0.015}, {"k", 1e-6}, {"split", 1.0}, {"split_width", 0.0}});
  std::vector<double> state(nodes.size() * 3);
  for (std::size_t a = 0; a < nodes.size(); ++a) {
    const double x = nodes.coords[2 * a], y = nodes.coords[2 * a + 1];
    state[3 * a] = 1e-3 * x * y;
    state[3 * a + 1] = 2e-3 * y - 1e-3 * x * x;
    state[3 * a + 2] = 0.2 + 0.8 * x;  // damage across the square
  }
  PetscVector u = assembler.create_vector();
  set_from_original(disc, state, 3, u);
  lmeform::testing::expect_coupled_hessian_equals_full(assembler, u, {0, 1});
  lmeform::testing::expect_coupled_hessian_equals_full(assembler, u, {2});
}

/// The string on a kinked foundation (data/kinked_spring.form, k = 1, kink width w) loaded to f in
/// one step from u = 0, where the exact kink's gradient is 0/0: `extra` adds to [steps].
std::string kinked(double f, double w, const std::string& extra, const std::string& initial = "") {
  return fmt::format(
      "[scene]\nname = \"kinked\"\ncoordinates = \"cartesian\"\n[domain]\nlower = [0.0]\nupper = [1.0]\n[nodes]\nspacing = 0.05\n"
      "[model]\nforms = [\"kinked_spring.form\"]\n[constants]\nk = 1.0\nw = {}\n{}[[dirichlet]]\nboundary = [\"hull\"]\nunknown = \"u\"\n"
      "value = 0.0\n[steps]\ncount = 1\nsolve_start = false\nmax_cuts = 1\nramp = {{ f = [0.0, {}] }}\n{}"
      "[quantities]\ncentre = {{ probe = [0.5], field = \"u\" }}\n",
      w, initial.empty() ? "" : "[initial]\nu = \"" + initial + "\"\n", f, extra);
}

double last(const problems::RunReport& r, const std::string& quantity) { return r.json.at("quantities").at(quantity).get<double>(); }

bool has_warning(const problems::RunReport& r, const std::string& text) {
  return std::any_of(r.warnings.begin(), r.warnings.end(), [&](const std::string& w) { return w.find(text) != std::string::npos; });
}

// Without a fallback the step stops at the kink's 0/0 with a message; with one it is solved with
// the kink smoothed and then again with the exact kink from there: for f = 2 > k the solution
// u = (f - k) x (1 - x)/2 lies off the kink and the run ends on it, the same state as a run of the
// exact model started off the kink, not on the smoothed model's.
TEST(LoadSteps, AFallbackModelLeadsAStepThatFailsAtEveryCutToTheScenesSolution) {
  const problems::RunReport stopped = run("kinked_stops.toml", kinked(2.0, 0.0, ""), "");
  EXPECT_FALSE(stopped.success);
  EXPECT_NE(stopped.status.find("step 1 did not converge"), std::string::npos) << stopped.status;
  EXPECT_NE(stopped.status.find("not finite"), std::string::npos) << stopped.status;

  const fs::path out = folder() / "kinked_fallback";
  fs::remove_all(out);
  const problems::RunReport r = run("kinked_fallback.toml", kinked(2.0, 0.0, "fallback = { w = 0.1 }\n"), out);
  ASSERT_TRUE(r.success) << r.status;
  EXPECT_EQ(r.status, "every step converged");
  EXPECT_EQ(last(r, "fallback"), 1.0);
  EXPECT_TRUE(r.warnings.empty());
  const problems::RunReport off_kink = run("kinked_off.toml", kinked(2.0, 0.0, "", "0.1*x[0]*(1 - x[0])"), "");
  ASSERT_TRUE(off_kink.success) << off_kink.status;
  EXPECT_NEAR(last(r, "centre"), last(off_kink, "centre"), 1e-10);
  EXPECT_NEAR(last(r, "centre"), 0.125, 1e-5);  // (f - k)/8
  const problems::RunReport smoothed = run("kinked_smoothed.toml", kinked(2.0, 0.1, ""), "");
  ASSERT_TRUE(smoothed.success) << smoothed.status;
  EXPECT_GT(std::abs(last(smoothed, "centre") - 0.125), 1e-3) << "the smoothed model's solution is not told apart from the exact one";
  // The history says which steps needed the fallback.
  const std::string csv = read(out / "history.csv");
  EXPECT_NE(csv.find(",fallback,"), std::string::npos) << csv;
}

// For f = 0.5 < k the exact solution is u = 0, on the kink, where the exact model's Newton cannot
// go: the step keeps the smoothed model's solution, and the status, a warning and the history say so.
TEST(LoadSteps, AStepTheScenesModelCannotSolveFromTheFallbacksSolutionKeepsItAndSaysSo) {
  const problems::RunReport r = run("kinked_kept.toml", kinked(0.5, 0.0, "fallback = { w = 0.1 }\n"), "");
  ASSERT_TRUE(r.success) << r.status;
  EXPECT_NE(r.status.find("only with the fallback constants"), std::string::npos) << r.status;
  EXPECT_TRUE(has_warning(r, "step 1 keeps the solution of the fallback constants w = 0.1")) << r.status;
  EXPECT_EQ(last(r, "fallback"), 2.0);
  const problems::RunReport smoothed = run("kinked_smoothed_low.toml", kinked(0.5, 0.1, ""), "");
  ASSERT_TRUE(smoothed.success) << smoothed.status;
  EXPECT_NEAR(last(r, "centre"), last(smoothed, "centre"), 1e-10);
  EXPECT_GT(last(r, "centre"), 1e-3);
}

// A run stopped after a step that kept the fallback's solution and then restarted still says so
// at its end: the warning comes back from history.json, the status names the step.
TEST(LoadSteps, ARestartWarnsAgainOfAStepThatKeptTheFallbacksSolution) {
  const fs::path out = folder() / "kinked_kept_restart";
  fs::remove_all(out);
  const std::string whole = kinked(0.5, 0.0, "fallback = { w = 0.1 }\n");
  std::string part = whole;
  part.replace(part.find("count = 1"), 9, "count = 2\nuntil = 1");
  std::string rest = whole;
  rest.replace(rest.find("count = 1"), 9, "count = 2");
  const problems::RunReport first = run("kinked_kept_part.toml", part, out);
  ASSERT_TRUE(first.success) << first.status;
  ASSERT_TRUE(has_warning(first, "step 1 keeps the solution of the fallback constants w = 0.1")) << first.status;
  const problems::RunReport resumed = run("kinked_kept_rest.toml", rest, out, /*restart=*/true);
  ASSERT_TRUE(resumed.success) << resumed.status;
  EXPECT_TRUE(has_warning(resumed, "step 1 keeps the solution of the fallback constants w = 0.1")) << resumed.status;
  EXPECT_NE(resumed.status.find("step(s) 1"), std::string::npos) << resumed.status;
}

TEST(LoadSteps, AFallbackNamingNoConstantOrASteppedOneIsRefused) {
  for (const auto& [fallback, expected] : std::vector<std::pair<std::string, std::string>>{
           {"fallback = { width = 0.1 }\n", "key 'steps.fallback.width': 'width' is no constant of the forms"},
           {"fallback = { f = 1.0 }\n", "is a stepped constant"},
           {"fallback = {}\n", "key 'steps.fallback' is empty"}}) {
    try {
      const problems::RunReport r = run("kinked_bad.toml", kinked(2.0, 0.0, fallback), "");
      ADD_FAILURE() << fallback << " was accepted: " << r.status;
    } catch (const SceneError& e) {
      EXPECT_NE(std::string(e.what()).find(expected), std::string::npos) << e.what();
      EXPECT_NE(std::string(e.what()).find("kinked_bad.toml"), std::string::npos) << e.what();
    }
  }
}

// The smoothed volumetric-deviatoric split (split_width w > 0): intact material keeps the energy of
// the unsplit model exactly (the smoothed parts sum to tr(eps)^2), and where damage degrades the
// tension part the energy moves from the exact split's by at most K w^2/8 per unit volume, and does
// move. The strain field's trace changes sign at x = 0.4, so the kink lies inside the square.
TEST(Fracture, TheSmoothedSplitKeepsTheIntactEnergyAndMovesTheDamagedOneByLessThanKw2Over8) {
  const GradedFractureSetup setup;
  const NodeSet& nodes = setup.nodes;
  const Discretization& disc = setup.disc;
  const kernel::FormKernels* energy = load_form("fracture_at2").find("elastic", 2);
  ASSERT_NE(energy, nullptr);
  const double lambda = 121.15, mu = 80.77, width = 1e-3;
  const double bulk = lambda + 2 * mu / 3;
  auto elastic_energy = [&](double split, double split_width, bool damaged) {
    Assembler assembler(disc, *energy);
    set_declared_constants(assembler, *energy,
                           {{"lambda", lambda}, {"mu", mu}, {"Gc", 2.7e-3}, {"l", 0.015}, {"k", 1e-6}, {"split", split}, {"split_width", split_width}});
    std::vector<double> state(nodes.size() * 3);
    for (std::size_t a = 0; a < nodes.size(); ++a) {
      const double x = nodes.coords[2 * a], y = nodes.coords[2 * a + 1];
      state[3 * a] = 1e-3 * (x * x - x);  // tr eps = 1e-3 (2.5 x - 1)
      state[3 * a + 1] = 0.5e-3 * x * y;
      state[3 * a + 2] = damaged ? 0.2 + 0.8 * y : 1.0;
    }
    PetscVector u = assembler.create_vector();
    set_from_original(disc, state, 3, u);
    return assembler.value(u);
  };
  const double unsplit = elastic_energy(0, 0, false);
  EXPECT_NEAR(elastic_energy(1, width, false), unsplit, 1e-13 * unsplit);
  EXPECT_NEAR(elastic_energy(1, 0, false), unsplit, 1e-13 * unsplit);
  const double exact = elastic_energy(1, 0, true);
  const double change = std::abs(elastic_energy(1, width, true) - exact);
  const double bound = bulk * width * width / 8;  // per unit volume, the unit square
  EXPECT_LT(change, bound);
  EXPECT_GT(change, 1e-3 * bound) << "the smoothing width did not reach the energy";
}

}  // namespace

int main(int argc, char** argv) {
  ::testing::InitGoogleTest(&argc, argv);
  lmeform::PetscSession session(&argc, &argv);
  return RUN_ALL_TESTS();
}
