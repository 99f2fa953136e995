// Scene files: good scenes load with every field, each broken scene gives its message (file, key path,
// line, reason), the demos load, and the geometric helpers (feasibility, resolution, ellipsoid distance).
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <initializer_list>
#include <numbers>
#include <string>
#include <vector>

#include "lmeform/scene.hpp"

using namespace lmeform;

namespace {

constexpr double pi = std::numbers::pi;

const std::string kFull = R"(# a complete scene
[scene]
name = "discocyte"
coordinates = "axisymmetric"

[domain]
lower = [0.0, 0.0]
upper = [1.5, 2.0]

[nodes]
spacing = 0.024
gamma = 1.6
quadrature_points = 7
resolution_factor = 1.5

[initial]
shape = "ellipsoid"
center = [0.0, 1.0]
semi_axes = [0.5, 0.2]
eps = 0.06

[model]
form = "helfrich_axisymmetric"
k = 2
eps = 0.04
C0 = 0.5
boundary_phi = -1.0

[constraints]
area = { target = 2.0106192982974678 }
volume = { reduced_volume = 0.8, radius = 0.4 }
moment = { target = 0.25, z_center = 1.1 }

[solver]
penalty = 1e-2
augmented_tolerance = 1e-3
inner_tolerance = 1e-7
max_outer_iterations = 30
max_inner_iterations = 15
newton_tolerance = 1e-10
constraint_tolerance = 1e-11
max_newton_iterations = 12

[adaptivity]
lloyd_iterations = 30
stages = [ { eps = 0.04, f = 10.0 }, { eps = 0.03, f = 100.0, lloyd_iterations = 50 } ]

[reference]
energy = 9.12657

[output]
directory = "out/discocyte"
hdf5 = false
)";

const std::string kMinimal = R"([scene]
name = "plain"
coordinates = "cartesian"
[domain]
lower = [-1.0, -1.0]
upper = [1.0, 1.0]
[nodes]
counts = [41, 41]
[initial]
shape = "sphere"
center = [0.0, 0.0]
radius = 0.5
[model]
eps = 0.1
)";

/// text with the first occurrence of `from` replaced by `to` (which must exist).
std::string edit(const std::string& text, const std::string& from, const std::string& to) {
  const auto pos = text.find(from);
  EXPECT_NE(pos, std::string::npos) << "test bug: '" << from << "' not in the scene";
  if (pos == std::string::npos) return text;
  std::string out = text;
  out.replace(pos, from.size(), to);
  return out;
}

/// 1-based line of the first occurrence of `needle` in text.
int line_of(const std::string& text, const std::string& needle) {
  const auto pos = text.find(needle);
  EXPECT_NE(pos, std::string::npos);
  return 1 + static_cast<int>(std::count(text.begin(), text.begin() + static_cast<long>(pos), '\n'));
}

/// The SceneError message of parsing `text` as broken.toml; fails the test if it parses.
std::string error_of(const std::string& text) {
  try {
    (void)parse_scene(text, "scenes/broken.toml");
  } catch (const SceneError& e) {
    return e.what();
  }
  ADD_FAILURE() << "the scene was accepted:\n" << text;
  return {};
}

void expect_error(const std::string& text, std::initializer_list<std::string> parts) {
  const std::string msg = error_of(text);
  for (const auto& p : parts) EXPECT_NE(msg.find(p), std::string::npos) << "'" << p << "' not in: " << msg;
}

}  // namespace

TEST(Scene, FullSceneLoadsEveryField) {
  const Scene s = parse_scene(kFull, "full.toml");
  EXPECT_EQ(s.source, "full.toml");
  EXPECT_EQ(s.name, "discocyte");
  EXPECT_EQ(s.coordinates, Coordinates::axisymmetric);
  EXPECT_TRUE(s.axisymmetric());
  EXPECT_EQ(s.dim(), 2);
  EXPECT_EQ(s.domain.lo[0], 0.0);
  EXPECT_EQ(s.domain.lo[1], 0.0);
  EXPECT_EQ(s.domain.hi[0], 1.5);
  EXPECT_EQ(s.domain.hi[1], 2.0);
  EXPECT_EQ(s.nodes.kind, SceneNodes::Kind::spacing);
  EXPECT_EQ(s.nodes.spacing, 0.024);
  EXPECT_EQ(s.nodes.gamma, 1.6);
  EXPECT_EQ(s.nodes.quadrature_points, 7);
  EXPECT_EQ(s.nodes.resolution_factor, 1.5);
  EXPECT_EQ(s.initial.shape, SceneInitial::Shape::ellipsoid);
  EXPECT_EQ(s.initial.center[1], 1.0);
  EXPECT_EQ(s.initial.semi_axes[0], 0.5);
  EXPECT_EQ(s.initial.semi_axes[1], 0.2);
  EXPECT_EQ(s.initial.eps, 0.06);
  EXPECT_EQ(s.model.form, "helfrich_axisymmetric");
  EXPECT_EQ(s.model.k, 2.0);  // an integer is accepted for a number
  EXPECT_EQ(s.model.eps, 0.04);
  EXPECT_EQ(s.model.C0, 0.5);
  EXPECT_EQ(s.model.boundary_phi, -1.0);
  ASSERT_TRUE(s.constraints.area && s.constraints.volume && s.constraints.moment);
  EXPECT_DOUBLE_EQ(*s.constraints.area, 0.64 * pi);
  EXPECT_NEAR(*s.constraints.volume, 0.8 * 4.0 / 3.0 * pi * 0.064, 1e-15);
  EXPECT_NEAR(*s.constraints.reduced_volume, 0.8, 1e-12);
  EXPECT_EQ(s.constraints.moment->target, 0.25);
  EXPECT_EQ(s.constraints.moment->z_center, 1.1);
  EXPECT_EQ(s.solver.penalty, 1e-2);
  EXPECT_EQ(s.solver.augmented_tolerance, 1e-3);
  EXPECT_EQ(s.solver.inner_tolerance, 1e-7);
  EXPECT_EQ(s.solver.max_outer_iterations, 30);
  EXPECT_EQ(s.solver.max_inner_iterations, 15);
  EXPECT_EQ(s.solver.newton_tolerance, 1e-10);
  EXPECT_EQ(s.solver.constraint_tolerance, 1e-11);
  EXPECT_EQ(s.solver.max_newton_iterations, 12);
  ASSERT_TRUE(s.adaptivity);
  ASSERT_EQ(s.adaptivity->stages.size(), 2u);
  EXPECT_EQ(s.adaptivity->stages[0].eps, 0.04);
  EXPECT_EQ(s.adaptivity->stages[0].f, 10.0);
  EXPECT_EQ(s.adaptivity->stages[0].lloyd_iterations, 30);  // the section's default
  EXPECT_EQ(s.adaptivity->stages[1].eps, 0.03);
  EXPECT_EQ(s.adaptivity->stages[1].f, 100.0);
  EXPECT_EQ(s.adaptivity->stages[1].lloyd_iterations, 50);
  EXPECT_EQ(s.final_eps(), 0.03);
  // A continuation stage: no relocation, f may be left out.
  const Scene c = parse_scene(edit(kFull, "lloyd_iterations = 50 }", "lloyd_iterations = 50 }, { eps = 0.02, lloyd_iterations = 0 }"),
                              "continuation.toml");
  ASSERT_EQ(c.adaptivity->stages.size(), 3u);
  EXPECT_EQ(c.adaptivity->stages[2].lloyd_iterations, 0);
  EXPECT_EQ(c.adaptivity->stages[2].f, 0.0);
  EXPECT_EQ(c.final_eps(), 0.02);
  // A branch: the next stage that is not one continues from stage 1 (eps 0.04), not from 0.02.
  const Scene b = parse_scene(edit(kFull, "{ eps = 0.04, f = 10.0 }, ", "{ eps = 0.04, f = 10.0 }, { eps = 0.02, lloyd_iterations = 0, branch = true }, "),
                              "branch.toml");
  ASSERT_EQ(b.adaptivity->stages.size(), 3u);
  EXPECT_TRUE(b.adaptivity->stages[1].branch);
  EXPECT_FALSE(b.adaptivity->stages[2].branch);
  expect_error(edit(kFull, "{ eps = 0.04, f = 10.0 }, ", "{ eps = 0.04, f = 10.0 }, { eps = 0.02, lloyd_iterations = 0 }, "),
               {"key 'adaptivity.stages[2].eps' = 0.03 exceeds the previous eps (0.02)"});
  expect_error(edit(kFull, "{ eps = 0.04, f = 10.0 }", "{ eps = 0.04, f = 10.0, branch = 1 }"),
               {"key 'adaptivity.stages[0].branch' must be a boolean"});
  expect_error(edit(kFull, "{ eps = 0.04, f = 10.0 }", "{ eps = 0.04 }"),
               {"missing key 'adaptivity.stages[0].f' in [adaptivity.stages[0]]"});
  EXPECT_EQ(s.reference_energy, 9.12657);
  ASSERT_TRUE(s.output);
  EXPECT_EQ(s.output->directory, "out/discocyte");
  EXPECT_FALSE(s.output->hdf5);
  EXPECT_TRUE(s.output->png);
  // round(1.5 / 0.024) = 63 intervals in r, round(2 / 0.024) = 83 in z.
  EXPECT_NEAR(*s.uniform_min_spacing(), 1.5 / 63, 1e-15);
}

TEST(Scene, UniformCvtNodeCountAndAdaptivityStart) {
  const Scene s = parse_scene(edit(kFull, "spacing = 0.024", "count = 6124\nlloyd_iterations = 40"), "cvt.toml");
  EXPECT_EQ(s.nodes.kind, SceneNodes::Kind::count);
  EXPECT_EQ(s.nodes.count, 6124);
  EXPECT_EQ(s.nodes.lloyd_iterations, 40);
  EXPECT_FALSE(s.uniform_min_spacing());  // checked by the run once the CVT exists
  EXPECT_FALSE(s.adaptivity->start_from_density);
  EXPECT_EQ(s.adaptivity->samples_per_node, 64);
  const Scene d = parse_scene(edit(kFull, "lloyd_iterations = 30\n", "lloyd_iterations = 30\nstart = \"density\"\nsamples_per_node = 16\n"),
                              "density.toml");
  EXPECT_TRUE(d.adaptivity->start_from_density);
  EXPECT_EQ(d.adaptivity->samples_per_node, 16);
  expect_error(edit(kFull, "spacing = 0.024", "spacing = 0.024\ncount = 6124"),
               {"key 'nodes.count' cannot be combined with 'nodes.spacing'"});
  expect_error(edit(kFull, "spacing = 0.024", "count = 10"), {"key 'nodes.count' must be at least 16"});
  expect_error(edit(kFull, "spacing = 0.024", "count = 6124.5"), {"key 'nodes.count' must be an integer"});
  expect_error(edit(kFull, "spacing = 0.024", "spacing = 0.024\nlloyd_iterations = 5"),
               {"key 'nodes.lloyd_iterations' belongs to 'nodes.count'"});
  expect_error(edit(kFull, "lloyd_iterations = 30\n", "lloyd_iterations = 30\nstart = \"densty\"\n"),
               {"key 'adaptivity.start' must be one of", "did you mean 'density'?"});
}

TEST(Scene, AbsentSectionsMeanNotUsed) {
  const Scene s = parse_scene(kMinimal, "minimal.toml");
  EXPECT_EQ(s.coordinates, Coordinates::cartesian);
  EXPECT_EQ(s.dim(), 2);
  EXPECT_EQ(s.nodes.kind, SceneNodes::Kind::counts);
  EXPECT_EQ(s.nodes.counts[0], 41);
  EXPECT_NEAR(*s.uniform_min_spacing(), 0.05, 1e-15);
  EXPECT_EQ(s.nodes.gamma, 0.8);
  EXPECT_EQ(s.nodes.quadrature_points, 6);
  EXPECT_EQ(s.nodes.resolution_factor, 2.0);
  EXPECT_EQ(s.initial.shape, SceneInitial::Shape::sphere);
  EXPECT_EQ(s.initial.semi_axes[0], 0.5);
  EXPECT_EQ(s.initial.semi_axes[1], 0.5);
  EXPECT_FALSE(s.initial.eps);
  EXPECT_EQ(s.model.form, "helfrich");
  EXPECT_EQ(s.model.k, 1.0);
  EXPECT_EQ(s.model.C0, 0.0);
  EXPECT_FALSE(s.constraints.area);
  EXPECT_FALSE(s.constraints.volume);
  EXPECT_FALSE(s.constraints.moment);
  EXPECT_FALSE(s.adaptivity);
  EXPECT_FALSE(s.reference_energy);
  EXPECT_FALSE(s.output);
  EXPECT_EQ(s.solver.penalty, SceneSolver{}.penalty);
  EXPECT_EQ(s.final_eps(), 0.1);
  // The initial profile: +1 inside, -1 outside, 0 on the circle.
  const std::array<double, 2> c{0.0, 0.0}, on{0.5, 0.0}, out{0.9, 0.9};
  EXPECT_GT(s.initial_phi(c), 0.99);
  EXPECT_NEAR(s.initial_phi(on), 0.0, 1e-14);
  EXPECT_LT(s.initial_phi(out), -0.99);
}

TEST(Scene, DerivedTargets) {
  // area from a radius, volume from the area's radius, moment centre from the initial shape.
  const std::string text = edit(edit(edit(kFull, "area = { target = 2.0106192982974678 }", "area = { radius = 0.4 }"),
                                     "volume = { reduced_volume = 0.8, radius = 0.4 }",
                                     "volume = { reduced_volume = 0.8 }"),
                                "moment = { target = 0.25, z_center = 1.1 }", "moment = {}");
  const Scene s = parse_scene(text, "derived.toml");
  EXPECT_NEAR(*s.constraints.area, 0.64 * pi, 1e-14);
  EXPECT_NEAR(*s.constraints.volume, 0.8 * 4.0 / 3.0 * pi * 0.064, 1e-15);
  EXPECT_EQ(s.constraints.moment->target, 0.0);
  EXPECT_EQ(s.constraints.moment->z_center, 1.0);
}

TEST(Scene, MissingKey) {
  const std::string text = edit(kFull, "eps = 0.04\n", "");
  expect_error(text, {"scenes/broken.toml:" + std::to_string(line_of(text, "[model]")) + ": ",
                      "missing key 'model.eps' in [model]"});
  expect_error(edit(kMinimal, "[model]\neps = 0.1\n", ""), {"scenes/broken.toml", "missing table [model]"});
  expect_error(edit(kMinimal, "counts = [41, 41]\n", ""),
               {"broken.toml", "'nodes.spacing', 'nodes.counts', 'nodes.count' or 'nodes.file'"});
  expect_error(edit(kFull, "area = { target = 2.0106192982974678 }", "area = {}"),
               {"broken.toml", "missing key in 'constraints.area'", "'target'", "'radius'"});
}

TEST(Scene, UnknownKeyWithSuggestion) {
  const std::string text = edit(kFull, "newton_tolerance = 1e-10", "newton_tolerence = 1e-10");
  expect_error(text, {"scenes/broken.toml:" + std::to_string(line_of(text, "newton_tolerence")) + ": ",
                      "unknown key 'solver.newton_tolerence'; did you mean 'newton_tolerance'?"});
  expect_error(edit(kFull, "[solver]", "[solvr]"), {"broken.toml", "unknown table [solvr]; did you mean 'solver'?"});
  // Close to a word of several keys: all of them.
  expect_error(edit(kFull, "penalty = 1e-2", "tolerence = 1e-2"),
               {"unknown key 'solver.tolerence'; did you mean one of 'augmented_tolerance', 'inner_tolerance', "
                "'newton_tolerance', 'constraint_tolerance'?"});
  // Nothing close: the valid keys are listed.
  expect_error(edit(kFull, "penalty = 1e-2", "speed = 1e-2"),
               {"unknown key 'solver.speed'", "the keys of [solver] are 'penalty', 'augmented_tolerance'"});
  expect_error(edit(kFull, "f = 10.0", "factor = 10.0"),
               {"unknown key 'adaptivity.stages[0].factor'", "the keys of [adaptivity.stages[0]] are 'eps', 'f'"});
  expect_error(edit(kFull, "\"axisymmetric\"", "\"axisymetric\""),
               {"key 'scene.coordinates' must be one of 'axisymmetric', 'cartesian', got 'axisymetric'; did you mean "
                "'axisymmetric'?"});
}

TEST(Scene, WrongType) {
  const std::string text = edit(kFull, "spacing = 0.024", "spacing = \"0.024\"");
  expect_error(text, {"scenes/broken.toml:" + std::to_string(line_of(text, "spacing =")) + ": ",
                      "key 'nodes.spacing' must be a number, found a string"});
  expect_error(edit(kFull, "max_outer_iterations = 30", "max_outer_iterations = 30.5"),
               {"key 'solver.max_outer_iterations' must be an integer, found a floating-point number"});
  expect_error(edit(kFull, "hdf5 = false", "hdf5 = 0"), {"key 'output.hdf5' must be a boolean", "found an integer"});
  expect_error(edit(kFull, "upper = [1.5, 2.0]", "upper = [1.5, 2.0, 3.0]"),
               {"key 'domain.upper' must be an array of 2 numbers, found 3 entries"});
  expect_error(edit(kFull, "center = [0.0, 1.0]", "center = [0.0, \"1\"]"),
               {"key 'initial.center[1]' must be a number, found a string"});
  expect_error("solver = 3\n" + kMinimal, {"broken.toml:1: 'solver' must be a table ([solver]), found an integer"});
  expect_error(edit(kFull, "lloyd_iterations = 30\n", "lloyd_iterations = 30\nstages = 5\n#"),
               {"key 'adaptivity.stages' must be an array of tables, found an integer"});
}

TEST(Scene, OutOfRange) {
  const std::string text = edit(kFull, "spacing = 0.024", "spacing = -0.024");
  expect_error(text, {"scenes/broken.toml:" + std::to_string(line_of(text, "spacing =")) + ": ",
                      "key 'nodes.spacing' must be positive, got -0.024"});
  expect_error(edit(kFull, "gamma = 1.6", "gamma = 0"), {"key 'nodes.gamma' must be positive, got 0"});
  expect_error(edit(kFull, "k = 2", "k = -1"), {"key 'model.k' must be positive"});
  expect_error(edit(kFull, "quadrature_points = 7", "quadrature_points = 5"),
               {"key 'nodes.quadrature_points' = 5 is not a triangle rule", "1, 3, 6, 7"});
  expect_error(edit(kMinimal, "counts = [41, 41]", "counts = [41, 1]"),
               {"key 'nodes.counts' must have at least 2 nodes per axis, got 1 on axis y"});
  expect_error(edit(kFull, "upper = [1.5, 2.0]", "upper = [1.5, -2.0]"), {"key 'domain.upper' must exceed"});
  expect_error(edit(kFull, "lower = [0.0, 0.0]", "lower = [-0.5, 0.0]"),
               {"key 'domain.lower' must have r >= 0 in an axisymmetric scene"});
  expect_error(edit(kFull, "center = [0.0, 1.0]", "center = [0.1, 1.0]"),
               {"key 'initial.center' must lie on the axis (r = 0)"});
  expect_error(edit(kFull, "semi_axes = [0.5, 0.2]", "semi_axes = [0.5, 1.2]"),
               {"key 'initial.semi_axes' puts the initial shape outside the domain: it reaches z = 2.2 > upper bound 2"});
  expect_error(edit(kFull, "eps = 0.03", "eps = 0.045"),
               {"key 'adaptivity.stages[1].eps' = 0.045 exceeds the previous eps (0.04)"});
  expect_error(edit(kFull, "boundary_phi = -1.0", "boundary_phi = -2.0"),
               {"key 'model.boundary_phi' must lie in [-1, 1]"});
  expect_error(edit(kFull, "form = \"helfrich_axisymmetric\"", "form = \"helfrich\""),
               {"key 'model.form' = 'helfrich' does not match scene.coordinates = 'axisymmetric'"});
}

TEST(Scene, UnderResolvedEps) {
  // h_min = 1.5 / 63 = 0.0238...; with the default factor 2, eps = 0.04 needs h_min <= 0.02.
  const std::string text = edit(kFull, "resolution_factor = 1.5\n", "");
  expect_error(text, {"scenes/broken.toml:" + std::to_string(line_of(text, "eps = 0.04")) + ": ",
                      "key 'model.eps': eps = 0.04 is under-resolved", "h_min = 0.0238095",
                      "the smallest admissible eps is 2 h_min = 0.047619"});
}

TEST(Scene, InfeasibleTargets) {
  // The sphere of area 0.64 pi holds 4/3 pi 0.4^3 = 0.2680825731.
  const std::string text = edit(kFull, "volume = { reduced_volume = 0.8, radius = 0.4 }", "volume = { target = 0.3 }");
  expect_error(text, {"scenes/broken.toml:" + std::to_string(line_of(text, "volume = {")) + ": ",
                      "infeasible targets: volume V0 = 0.3 exceeds V_max = 0.2680825731",
                      "area A0 = 2.010619298", "reduced volume 1.119058"});
  expect_error(edit(kFull, "reduced_volume = 0.8", "reduced_volume = 1.2"),
               {"key 'constraints.volume.reduced_volume' = 1.2 must not exceed 1"});
  // A radius larger than the area's sphere makes V0 > V_max even with v <= 1.
  expect_error(edit(kFull, "reduced_volume = 0.8, radius = 0.4", "reduced_volume = 0.95, radius = 0.45"),
               {"infeasible targets"});
  expect_error(edit(kFull, "volume = { reduced_volume = 0.8, radius = 0.4 }", "volume = { target = 0.1, radius = 0.4 }"),
               {"key 'constraints.volume.radius' cannot be combined with 'constraints.volume.target'"});
}

TEST(Scene, SyntaxErrorAndMissingFile) {
  expect_error(edit(kFull, "k = 2", "k = = 2"), {"scenes/broken.toml:" + std::to_string(line_of(kFull, "k = 2")) + ":",
                                                 "TOML syntax error"});
  try {
    (void)load_scene("/nonexistent/scene.toml");
    ADD_FAILURE() << "no error";
  } catch (const SceneError& e) {
    EXPECT_NE(std::string(e.what()).find("/nonexistent/scene.toml: cannot open the scene file"), std::string::npos);
  }
}

TEST(Scene, NodeFileRelativeToScene) {
  const std::filesystem::path dir = std::filesystem::path(LMEFORM_TEST_TMPDIR) / "scene_files";
  std::filesystem::create_directories(dir);
  { std::ofstream(dir / "nodes.csv") << "0,0\n1,0\n0,1\n1,1\n"; }
  const std::string text = edit(kMinimal, "counts = [41, 41]", "file = \"nodes.csv\"");
  { std::ofstream(dir / "with_file.toml") << text; }
  const Scene s = load_scene(dir / "with_file.toml");
  EXPECT_EQ(s.nodes.kind, SceneNodes::Kind::file);
  EXPECT_EQ(s.nodes.file, dir / "nodes.csv");
  EXPECT_FALSE(s.uniform_min_spacing());
  expect_error(edit(kMinimal, "counts = [41, 41]", "file = \"missing.csv\""),
               {"key 'nodes.file' names a file that does not exist"});
  expect_error(edit(kMinimal, "counts = [41, 41]", "counts = [41, 41]\nspacing = 0.1"),
               {"key 'nodes.counts' cannot be combined with 'nodes.spacing'"});
}

TEST(Scene, Demos) {
  for (const char* name : {"discocyte", "dumbbell"}) {
    SCOPED_TRACE(name);
    const Scene s = load_scene(std::filesystem::path(LMEFORM_SOURCE_DIR) / "demos" / (std::string(name) + ".toml"));
    EXPECT_EQ(s.name, name);
    EXPECT_TRUE(s.axisymmetric());
    EXPECT_EQ(s.domain.hi[0], 1.5);
    EXPECT_EQ(s.domain.hi[1], 2.0);
    EXPECT_EQ(s.model.k, 1.0);
    EXPECT_EQ(s.model.C0, 0.0);
    EXPECT_NEAR(*s.constraints.area, 0.64 * pi, 1e-14);
    EXPECT_NEAR(*s.constraints.volume, 0.8 * 4.0 / 3.0 * pi * 0.064, 1e-14);
    EXPECT_NEAR(*s.constraints.reduced_volume, 0.8, 1e-12);
    ASSERT_TRUE(s.constraints.moment);
    ASSERT_TRUE(s.reference_energy);
    EXPECT_EQ(*s.reference_energy, std::string(name) == "discocyte" ? 9.12657 : 8.71756);
    // The initial spheroid already encloses V0 (to the rounding of its semi-axes).
    const double a = s.initial.semi_axes[0], c = s.initial.semi_axes[1];
    EXPECT_NEAR(4.0 / 3.0 * pi * a * a * c / *s.constraints.volume, 1.0, 2e-3);
    EXPECT_EQ(std::string(name) == "discocyte", a > c);  // oblate vs prolate
    // The seed's grid O1 / P1 and the Table B.6 schedule down to eps = 0.01.
    EXPECT_EQ(s.nodes.kind, SceneNodes::Kind::count);
    EXPECT_EQ(s.nodes.count, 6124);
    ASSERT_TRUE(s.adaptivity);
    EXPECT_EQ(s.final_eps(), 0.01);
    int relocations = 0;
    for (const auto& st : s.adaptivity->stages) relocations += st.lloyd_iterations > 0 ? 1 : 0;
    EXPECT_EQ(relocations, 3);  // f = 10, 100, 1000
  }
}

TEST(SceneHelpers, Feasibility) {
  const double A0 = 0.64 * pi;
  EXPECT_NEAR(max_volume_for_area(A0), 4.0 / 3.0 * pi * 0.064, 1e-15);
  EXPECT_NEAR(max_volume_for_area(2 * pi * 0.5, 2), pi * 0.25, 1e-15);
  EXPECT_NO_THROW(check_feasible(A0, 0.8 * max_volume_for_area(A0)));
  EXPECT_NO_THROW(check_feasible(A0, max_volume_for_area(A0)));  // the sphere itself
  try {
    check_feasible(A0, 1.1 * max_volume_for_area(A0));
    ADD_FAILURE() << "no error";
  } catch (const SceneError& e) {
    const std::string m = e.what();
    EXPECT_NE(m.find("V0 = 0.2948908304"), std::string::npos) << m;
    EXPECT_NE(m.find("V_max = 0.2680825731"), std::string::npos) << m;
    EXPECT_NE(m.find("reduced volume 1.1 > 1"), std::string::npos) << m;
  }
  EXPECT_THROW(check_feasible(A0, -1.0), SceneError);
}

TEST(SceneHelpers, EllipsoidDistance) {
  const std::array<double, 2> c{0.0, 1.0}, e{0.5, 0.2};
  auto d = [&](double x, double y) {
    const std::array<double, 2> p{x, y};
    return ellipsoid_signed_distance(p, c, e);
  };
  EXPECT_NEAR(d(0.0, 1.0), 0.2, 1e-14);    // centre: the nearer pole
  EXPECT_NEAR(d(0.0, 1.5), -0.3, 1e-12);   // above the pole
  EXPECT_NEAR(d(0.8, 1.0), -0.3, 1e-12);   // beyond the rim
  EXPECT_NEAR(d(0.45, 1.0), 0.05, 1e-12);  // inside near the rim
  EXPECT_NEAR(d(0.0, 0.9), 0.1, 1e-12);    // inside below the centre: the lower pole
  // Against a brute-force minimum over the boundary.
  for (double x : {-0.7, -0.3, 0.0, 0.1, 0.33, 0.49, 0.6}) {
    for (double y : {0.6, 0.85, 0.95, 1.0, 1.07, 1.19, 1.4}) {
      double best = 1e300;
      const int n = 200000;
      for (int k = 0; k < n; ++k) {
        const double t = 2 * pi * k / n;
        best = std::min(best, std::hypot(x - 0.5 * std::cos(t), y - 1.0 - 0.2 * std::sin(t)));
      }
      const bool inside = (x / 0.5) * (x / 0.5) + ((y - 1) / 0.2) * ((y - 1) / 0.2) < 1;
      EXPECT_NEAR(d(x, y), inside ? best : -best, 1e-6) << x << ", " << y;
    }
  }
  // 3D: a sphere and a spheroid's pole.
  const std::array<double, 3> c3{0, 0, 0}, s3{1, 1, 1}, p3{0.3, 0.4, 0.0};
  EXPECT_NEAR(ellipsoid_signed_distance(p3, c3, s3), 0.5, 1e-12);
  const std::array<double, 3> e3{0.6, 0.6, 0.3}, q3{0.0, 0.0, 0.5};
  EXPECT_NEAR(ellipsoid_signed_distance(q3, c3, e3), -0.2, 1e-12);
}
