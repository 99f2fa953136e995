// Scene files (docs/scenes.md): a complete scene loads with every field, each broken scene gives its
// message (file, line, key path, reason, did-you-mean), the sections of any model ([model],
// [constants], [constraints], [[dirichlet]], [initial], [coefficients], [qdata], [solver], [reference], [output]),
// extension tables kept for their model, the demos, and the helpers (closest_name,
// ellipsoid_signed_distance). Names that refer to forms are checked by app::bind_scene, not here;
// the [vesicle] extension is tested in test_vesicle_scene.cpp.
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <initializer_list>
#include <map>
#include <numbers>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include "lmeform/scene.hpp"
#include "lmeform/scene_table.hpp"

using namespace lmeform;

namespace {

constexpr double pi = std::numbers::pi;
constexpr std::string_view kVesicleOnly[] = {"vesicle"};

// Every table and key of the reader. The constraints and initial fields are deliberately not in
// alphabetical order: the reader keeps the order of the file.
const std::string kFull = R"TOML(# a complete scene
[scene]
name = "full"
description = "every key of the reader"
coordinates = "axisymmetric"

[domain]
lower = [0.0, 0.0]
upper = [1.5, 2.0]

[nodes]
spacing = 0.024
gamma = 1.6
spacing_smoothing = 3
quadrature_points = 7

[model]
forms = ["helfrich_axisymmetric", "area_axisymmetric", "extra/volume.form", "../shared/moment.form", "/abs/m.form", "local.form"]
energy = ["bending", "helfrich_axisymmetric.bending"]

[constants]
k = 2
eps = 0.04
C0 = -0.5
zc = 1.0

[constraints]
volume = 0.2
area = { target = 2.0, scale = 0.5 }
moment = {}

[[dirichlet]]
boundary = ["r_max", "z_min", "z_max"]
unknown = "phi"
value = -1.0

[[dirichlet]]
boundary = "axis"
unknown = "psi"
components = [1]
value = "tanh((x[1] - zc)/eps)"

[initial]
psi = 0.5
phi = "tanh((0.3 - norm(x - [0, zc]))/eps)"

[qdata]
rho = "support_size"
reference = "zero"

[solver]
penalty = 1e-2
augmented_tolerance = 1e-3
inner_tolerance = 1e-7
max_outer_iterations = 30
max_inner_iterations = 15
newton_tolerance = 1e-10
constraint_tolerance = 1e-11
max_newton_iterations = 12
monitor = true
petsc_options = "-ksp_type gmres -pc_type ilu"

[reference]
energy = 9.12657

[reference.solution]
phi = "sin(pi*x[0])"
psi = "[x[0], x[1]]"

[output]
directory = "out/full"
hdf5 = false
)TOML";

// The least a scene needs: a 2D Cartesian Poisson problem as bilinear + linear.
const std::string kMinimal = R"([scene]
name = "plain"
coordinates = "cartesian"
[domain]
lower = [0.0, 0.0]
upper = [1.0, 1.0]
[nodes]
counts = [21, 21]
[model]
forms = "poisson.form"
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
  EXPECT_NE(pos, std::string::npos) << "test bug: '" << needle << "' not in the scene";
  if (pos == std::string::npos) return -1;
  return 1 + static_cast<int>(std::count(text.begin(), text.begin() + static_cast<long>(pos), '\n'));
}

/// "scenes/broken.toml:LINE: " for the line of `needle`.
std::string at_line(const std::string& text, const std::string& needle) {
  return "scenes/broken.toml:" + std::to_string(line_of(text, needle)) + ": ";
}

/// The SceneError message of parsing `text` as scenes/broken.toml; fails the test if it parses.
std::string error_of(const std::string& text, std::span<const std::string_view> extensions = {}) {
  try {
    (void)parse_scene(text, "scenes/broken.toml", extensions);
  } catch (const SceneError& e) {
    return e.what();
  }
  ADD_FAILURE() << "the scene was accepted:\n" << text;
  return {};
}

void expect_error(const std::string& text, std::initializer_list<std::string> parts,
                  std::span<const std::string_view> extensions = {}) {
  const std::string msg = error_of(text, extensions);
  for (const auto& p : parts) EXPECT_NE(msg.find(p), std::string::npos) << "'" << p << "' not in: " << msg;
}

Scene parse(const std::string& text, std::span<const std::string_view> extensions = {}) {
  return parse_scene(text, "scenes/ok.toml", extensions);
}

std::vector<std::string> constraint_names(const Scene& s) {
  std::vector<std::string> out;
  for (const auto& c : s.constraints) out.push_back(c.name);
  return out;
}

}  // namespace

// ---------------------------------------------------------------------------------------------
// Complete and minimal scenes

TEST(Scene, FullSceneLoadsEveryField) {
  const Scene s = parse_scene(kFull, "scenes/full.toml");
  EXPECT_EQ(s.source, "scenes/full.toml");
  EXPECT_EQ(s.folder, std::filesystem::path("scenes"));
  EXPECT_EQ(s.name, "full");
  EXPECT_EQ(s.coordinates, Coordinates::axisymmetric);
  EXPECT_TRUE(s.axisymmetric());
  EXPECT_STREQ(to_string(s.coordinates), "axisymmetric");
  EXPECT_EQ(s.dim(), 2);
  EXPECT_EQ(s.domain.lo[0], 0.0);
  EXPECT_EQ(s.domain.lo[1], 0.0);
  EXPECT_EQ(s.domain.hi[0], 1.5);
  EXPECT_EQ(s.domain.hi[1], 2.0);

  EXPECT_EQ(s.nodes.kind, SceneNodes::Kind::spacing);
  EXPECT_EQ(s.nodes.spacing, 0.024);
  EXPECT_EQ(s.nodes.gamma, 1.6);
  EXPECT_EQ(s.nodes.spacing_smoothing, 3);
  EXPECT_EQ(s.nodes.quadrature_points, 7);

  // [model]: built-in names as written, paths against the scene's folder.
  ASSERT_EQ(s.model.forms.size(), 6u);
  EXPECT_EQ(s.model.forms[0].name, "helfrich_axisymmetric");
  EXPECT_EQ(s.model.forms[1].name, "area_axisymmetric");
  EXPECT_EQ(s.model.forms[2].name, "scenes/extra/volume.form");
  EXPECT_EQ(s.model.forms[3].name, "shared/moment.form");
  EXPECT_EQ(s.model.forms[4].name, "/abs/m.form");
  EXPECT_EQ(s.model.forms[5].name, "scenes/local.form");  // a .form without '/' is a path too
  EXPECT_EQ(s.model.forms[2].where,
            "scenes/full.toml:" + std::to_string(line_of(kFull, "forms = [")) + ": key 'model.forms[2]'");
  ASSERT_EQ(s.model.energy.size(), 2u);
  EXPECT_EQ(s.model.energy[0].name, "bending");
  EXPECT_EQ(s.model.energy[1].name, "helfrich_axisymmetric.bending");
  EXPECT_EQ(s.model.energy[1].where,
            "scenes/full.toml:" + std::to_string(line_of(kFull, "energy = [")) + ": key 'model.energy[1]'");
  EXPECT_FALSE(s.model.residual);
  EXPECT_FALSE(s.model.bilinear);
  EXPECT_FALSE(s.model.linear);

  // [constants]: any names; integers are numbers.
  ASSERT_EQ(s.constants.size(), 4u);
  EXPECT_EQ(s.constants.at("k"), 2.0);
  EXPECT_EQ(s.constants.at("eps"), 0.04);
  EXPECT_EQ(s.constants.at("C0"), -0.5);
  EXPECT_EQ(s.constants.at("zc"), 1.0);
  EXPECT_EQ(s.where_constant("eps"),
            "scenes/full.toml:" + std::to_string(line_of(kFull, "eps = 0.04")) + ": key 'constants.eps'");
  EXPECT_EQ(s.where_constant("A0"), "scenes/full.toml: [constants]");  // absent: the file alone

  // [constraints] in the order of the file.
  ASSERT_EQ(s.constraints.size(), 3u);
  EXPECT_EQ(constraint_names(s), (std::vector<std::string>{"volume", "area", "moment"}));
  EXPECT_EQ(s.constraints[0].target, 0.2);
  EXPECT_FALSE(s.constraints[0].scale);
  EXPECT_EQ(s.constraints[1].target, 2.0);
  EXPECT_EQ(s.constraints[1].scale, 0.5);
  EXPECT_FALSE(s.constraints[2].target);  // {}: the form's target constant
  EXPECT_FALSE(s.constraints[2].scale);
  EXPECT_EQ(s.constraints[1].where,
            "scenes/full.toml:" + std::to_string(line_of(kFull, "area = {")) + ": key 'constraints.area'");

  // [[dirichlet]]
  ASSERT_EQ(s.dirichlet.size(), 2u);
  EXPECT_EQ(s.dirichlet[0].boundary, (std::vector<std::string>{"r_max", "z_min", "z_max"}));
  EXPECT_EQ(s.dirichlet[0].unknown, "phi");
  EXPECT_TRUE(s.dirichlet[0].components.empty());  // every component
  ASSERT_TRUE(s.dirichlet[0].value.is_number());
  EXPECT_EQ(s.dirichlet[0].value.number(), -1.0);
  EXPECT_EQ(s.dirichlet[1].boundary, (std::vector<std::string>{"axis"}));  // a string: one part
  EXPECT_EQ(s.dirichlet[1].unknown, "psi");
  EXPECT_EQ(s.dirichlet[1].components, (std::vector<int>{1}));
  ASSERT_FALSE(s.dirichlet[1].value.is_number());
  EXPECT_EQ(s.dirichlet[1].value.expression(), "tanh((x[1] - zc)/eps)");
  EXPECT_EQ(s.dirichlet[1].value.where,
            "scenes/full.toml:" + std::to_string(line_of(kFull, "value = \"tanh")) + ": key 'dirichlet[1].value'");

  // [initial] in the order of the file.
  ASSERT_EQ(s.initial.size(), 2u);
  EXPECT_EQ(s.initial[0].unknown, "psi");
  EXPECT_EQ(s.initial[0].kind, SceneInitialField::Kind::value);
  EXPECT_EQ(s.initial[0].value.number(), 0.5);
  EXPECT_EQ(s.initial[1].unknown, "phi");
  EXPECT_EQ(s.initial[1].kind, SceneInitialField::Kind::value);
  EXPECT_EQ(s.initial[1].value.expression(), "tanh((0.3 - norm(x - [0, zc]))/eps)");
  EXPECT_EQ(s.initial[1].where,
            "scenes/full.toml:" + std::to_string(line_of(kFull, "phi = \"tanh")) + ": key 'initial.phi'");

  // [qdata]
  ASSERT_EQ(s.qdata.size(), 2u);
  for (const auto& q : s.qdata) {
    if (q.name == "rho") EXPECT_EQ(q.source, SceneQdata::Source::support_size);
    else if (q.name == "reference") EXPECT_EQ(q.source, SceneQdata::Source::zero);
    else ADD_FAILURE() << "unexpected qdata " << q.name;
  }

  // [solver]
  EXPECT_EQ(s.solver.penalty, 1e-2);
  EXPECT_EQ(s.solver.augmented_tolerance, 1e-3);
  EXPECT_EQ(s.solver.inner_tolerance, 1e-7);
  EXPECT_EQ(s.solver.max_outer_iterations, 30);
  EXPECT_EQ(s.solver.max_inner_iterations, 15);
  EXPECT_EQ(s.solver.newton_tolerance, 1e-10);
  EXPECT_EQ(s.solver.constraint_tolerance, 1e-11);
  EXPECT_EQ(s.solver.max_newton_iterations, 12);
  EXPECT_TRUE(s.solver.monitor);
  EXPECT_EQ(s.solver.petsc_options, "-ksp_type gmres -pc_type ilu");

  // [reference]
  ASSERT_TRUE(s.reference.energy);
  EXPECT_EQ(*s.reference.energy, 9.12657);
  ASSERT_EQ(s.reference.solution.size(), 2u);
  std::map<std::string, std::string> solution;
  for (const auto& [name, value] : s.reference.solution) solution[name] = value.expression();
  EXPECT_EQ(solution.at("phi"), "sin(pi*x[0])");
  EXPECT_EQ(solution.at("psi"), "[x[0], x[1]]");

  // [output]
  ASSERT_TRUE(s.output);
  EXPECT_EQ(s.output->directory, "out/full");  // relative to the working directory, not the scene
  EXPECT_FALSE(s.output->hdf5);
  EXPECT_FALSE(s.output->png);  // a figure is drawn only where one is asked for

  EXPECT_TRUE(s.extensions.empty());
  EXPECT_TRUE(s.document);
}

TEST(Scene, AbsentSectionsTakeDefaults) {
  const Scene s = parse_scene(kMinimal, "minimal.toml");
  EXPECT_EQ(s.folder, std::filesystem::path());
  EXPECT_EQ(s.coordinates, Coordinates::cartesian);
  EXPECT_STREQ(to_string(s.coordinates), "cartesian");
  EXPECT_EQ(s.dim(), 2);
  EXPECT_EQ(s.nodes.kind, SceneNodes::Kind::counts);
  EXPECT_EQ(s.nodes.counts[0], 21);
  EXPECT_EQ(s.nodes.counts[1], 21);
  EXPECT_EQ(s.nodes.gamma, 0.8);
  EXPECT_EQ(s.nodes.spacing_smoothing, 5);
  EXPECT_EQ(s.nodes.quadrature_points, 6);
  ASSERT_EQ(s.model.forms.size(), 1u);  // a string: one form
  EXPECT_EQ(s.model.forms[0].name, "poisson.form");
  // No output named: minimization of every energy of the forms (bind_scene collects them).
  EXPECT_TRUE(s.model.energy.empty());
  EXPECT_FALSE(s.model.residual || s.model.bilinear || s.model.linear);
  EXPECT_TRUE(s.constants.empty());
  EXPECT_TRUE(s.constraints.empty());
  EXPECT_TRUE(s.dirichlet.empty());
  EXPECT_TRUE(s.initial.empty());
  EXPECT_TRUE(s.qdata.empty());
  const SceneSolver d;
  EXPECT_EQ(s.solver.penalty, 1e-3);
  EXPECT_EQ(s.solver.augmented_tolerance, 1e-4);
  EXPECT_EQ(s.solver.inner_tolerance, 1e-6);
  EXPECT_EQ(s.solver.max_outer_iterations, 40);
  EXPECT_EQ(s.solver.max_inner_iterations, 25);
  EXPECT_EQ(s.solver.newton_tolerance, 1e-9);
  EXPECT_EQ(s.solver.constraint_tolerance, 1e-10);
  EXPECT_EQ(s.solver.max_newton_iterations, 25);
  EXPECT_EQ(s.solver.penalty, d.penalty);
  EXPECT_TRUE(s.solver.petsc_options.empty());
  EXPECT_FALSE(s.reference.energy);
  EXPECT_TRUE(s.reference.solution.empty());
  EXPECT_FALSE(s.output);
  EXPECT_TRUE(s.extensions.empty());
  EXPECT_FALSE(s.has_extension("vesicle"));
  // An empty [solver] and an [output] with only a directory: the defaults.
  const Scene o = parse(kMinimal + "[solver]\n[output]\ndirectory = \"out\"\n");
  EXPECT_EQ(o.solver.max_newton_iterations, 25);
  EXPECT_FALSE(o.solver.monitor);
  ASSERT_TRUE(o.output);
  EXPECT_TRUE(o.output->hdf5);
  EXPECT_FALSE(o.output->png);
  expect_error(kMinimal + "[output]\nhdf5 = true\n", {"missing key 'output.directory' in [output]"});
}

// ---------------------------------------------------------------------------------------------
// [model]

TEST(SceneModel, TheOutputsAreReadByTheirKind) {
  const Scene e = parse(kMinimal + "energy = \"heat\"\n");
  EXPECT_FALSE(e.model.residual || e.model.bilinear || e.model.linear);
  ASSERT_EQ(e.model.energy.size(), 1u);
  EXPECT_EQ(e.model.energy[0].name, "heat");

  const Scene r = parse(kMinimal + "residual = \"R\"\n");
  ASSERT_TRUE(r.model.residual);
  EXPECT_EQ(r.model.residual->name, "R");
  EXPECT_EQ(r.model.residual->where, "scenes/ok.toml:11: key 'model.residual'");
  EXPECT_TRUE(r.model.energy.empty());

  const Scene l = parse(kMinimal + "bilinear = \"a\"\nlinear = \"l\"\n");
  EXPECT_TRUE(l.model.energy.empty() && !l.model.residual);
  ASSERT_TRUE(l.model.bilinear && l.model.linear);
  EXPECT_EQ(l.model.bilinear->name, "a");
  EXPECT_EQ(l.model.linear->name, "l");
  EXPECT_EQ(l.model.linear->where, "scenes/ok.toml:12: key 'model.linear'");
}

TEST(SceneModel, OneProblemPerScene) {
  std::string t = kMinimal + "residual = \"R\"\nenergy = \"heat\"\n";
  expect_error(t, {at_line(t, "residual ="), "key 'model.residual' cannot be combined with 'model.energy', 'model.bilinear' or "
                                             "'model.linear': a scene solves one problem"});
  t = kMinimal + "bilinear = \"a\"\nlinear = \"l\"\nresidual = \"R\"\n";
  expect_error(t, {at_line(t, "residual ="), "key 'model.residual' cannot be combined"});
  t = kMinimal + "energy = \"heat\"\nbilinear = \"a\"\nlinear = \"l\"\n";
  expect_error(t, {at_line(t, "bilinear ="), "key 'model.bilinear' cannot be combined with 'model.energy'"});
  t = kMinimal + "energy = \"heat\"\nlinear = \"l\"\n";
  expect_error(t, {at_line(t, "linear ="), "key 'model.linear' cannot be combined with 'model.energy'"});
  t = kMinimal + "bilinear = \"a\"\n";
  expect_error(t, {at_line(t, "bilinear ="), "key 'model.bilinear' needs 'model.linear' too: a linear problem is a(u, v) = l(v)"});
  t = kMinimal + "linear = \"l\"\n";
  expect_error(t, {at_line(t, "linear ="), "key 'model.linear' needs 'model.bilinear' too"});
}

TEST(SceneModel, BrokenModels) {
  std::string t = edit(kMinimal, "forms = \"poisson.form\"\n", "");
  expect_error(t, {at_line(t, "[model]"), "missing key 'model.forms' in [model]"});
  t = edit(kMinimal, "forms = \"poisson.form\"", "forms = []");
  expect_error(t, {at_line(t, "forms ="), "key 'model.forms' must name at least one entry"});
  t = edit(kMinimal, "forms = \"poisson.form\"", "forms = 3");
  expect_error(t, {at_line(t, "forms ="), "key 'model.forms' must be a string or an array of strings, found an integer"});
  t = edit(kMinimal, "forms = \"poisson.form\"", "forms = [\"poisson\", 2]");
  expect_error(t, {at_line(t, "forms ="), "key 'model.forms[1]' must be a string, found an integer"});
  t = edit(kMinimal, "forms = \"poisson.form\"", "forms = [\"poisson\", \"\"]");
  expect_error(t, {"key 'model.forms[1]' must not be empty"});
  t = kMinimal + "residual = 1\n";
  expect_error(t, {at_line(t, "residual ="), "key 'model.residual' must be a string, found an integer"});
  t = kMinimal + "energy = []\n";
  expect_error(t, {at_line(t, "energy ="), "key 'model.energy' must name at least one entry"});
  t = kMinimal + "enrgy = \"heat\"\n";
  expect_error(t, {at_line(t, "enrgy ="), "unknown key 'model.enrgy'; did you mean 'energy'?"});
  t = kMinimal + "form = \"poisson\"\n";
  expect_error(t, {at_line(t, "form = \"poisson\""), "unknown key 'model.form'; did you mean 'forms'?"});
  expect_error(edit(kMinimal, "[model]\nforms = \"poisson.form\"\n", ""), {"scenes/broken.toml", "missing table [model]"});
}

// ---------------------------------------------------------------------------------------------
// [constants], [constraints]

TEST(SceneConstants, NumbersByName) {
  const Scene s = parse(kMinimal + "[constants]\nkappa = 3\nf0 = -1.5e-2\n");
  ASSERT_EQ(s.constants.size(), 2u);
  EXPECT_EQ(s.constants.at("kappa"), 3.0);
  EXPECT_EQ(s.constants.at("f0"), -1.5e-2);
  EXPECT_EQ(s.where_constant("f0"), "scenes/ok.toml:13: key 'constants.f0'");
  // An empty table: no constants (the forms' defaults).
  EXPECT_TRUE(parse(kMinimal + "[constants]\n").constants.empty());
  std::string t = kMinimal + "[constants]\nkappa = \"3\"\n";
  expect_error(t, {at_line(t, "kappa ="), "key 'constants.kappa' must be a number, found a string"});
  t = kMinimal + "[constants]\nkappa = nan\n";
  expect_error(t, {at_line(t, "kappa ="), "key 'constants.kappa' must be finite"});
  t = kMinimal + "[constants]\nkappa = [1.0]\n";
  expect_error(t, {"key 'constants.kappa' must be a number, found an array"});
  t = "constants = 3\n" + kMinimal;
  expect_error(t, {"scenes/broken.toml:1: 'constants' must be a table ([constants]), found an integer"});
}

TEST(SceneConstraints, NumberOrTableInFileOrder) {
  const Scene s = parse(kMinimal + "[constraints]\nzeta = 1\nalpha = { scale = 2.5 }\nmid = { target = -3 }\nbeta = {}\n");
  EXPECT_EQ(constraint_names(s), (std::vector<std::string>{"zeta", "alpha", "mid", "beta"}));
  EXPECT_EQ(s.constraints[0].target, 1.0);
  EXPECT_FALSE(s.constraints[0].scale);
  EXPECT_FALSE(s.constraints[1].target);
  EXPECT_EQ(s.constraints[1].scale, 2.5);
  EXPECT_EQ(s.constraints[2].target, -3.0);  // any sign
  EXPECT_FALSE(s.constraints[3].target);
  EXPECT_EQ(s.constraints[3].where, "scenes/ok.toml:15: key 'constraints.beta'");
  // Sub-tables keep the order too.
  const Scene t = parse(kMinimal + "[constraints.volume]\ntarget = 0.2\n[constraints.area]\nscale = 1.0\n");
  EXPECT_EQ(constraint_names(t), (std::vector<std::string>{"volume", "area"}));
}

TEST(SceneConstraints, BrokenConstraints) {
  std::string t = kMinimal + "[constraints]\narea = \"A0\"\n";
  expect_error(t, {at_line(t, "area ="), "key 'constraints.area' must be a number (the target), \"initial\" (the value at "
                                         "the start) or a table { target = ..., scale = ... }, got 'A0'"});
  t = kMinimal + "[constraints]\narea = { taget = 1.0 }\n";
  expect_error(t, {at_line(t, "area ="), "unknown key 'constraints.area.taget'; did you mean 'target'?"});
  t = kMinimal + "[constraints]\narea = { target = 1.0, scale = 0 }\n";
  expect_error(t, {at_line(t, "area ="), "key 'constraints.area.scale' must be positive, got 0"});
  t = kMinimal + "[constraints]\narea = { target = \"x\" }\n";
  expect_error(t, {"key 'constraints.area.target' must be a number or \"initial\" (the value at the start), got 'x'"});
  // "initial": the value at the start state, in both spellings.
  const Scene u = parse(kMinimal + "[constraints]\narea = \"initial\"\nvolume = { target = \"initial\", scale = 2.0 }\n");
  ASSERT_EQ(u.constraints.size(), 2u);
  EXPECT_TRUE(u.constraints[0].initial);
  EXPECT_FALSE(u.constraints[0].target);
  EXPECT_TRUE(u.constraints[1].initial);
  EXPECT_EQ(u.constraints[1].scale, 2.0);
}

// ---------------------------------------------------------------------------------------------
// [[dirichlet]]

TEST(SceneDirichlet, BoundaryPartsOfEachGeometry) {
  const std::string dirichlet = "[[dirichlet]]\nboundary = [\"x_min\", \"x_max\", \"y_min\", \"y_max\", \"hull\"]\nunknown = \"u\"\n"
                                "value = 0\n";
  const Scene s = parse(kMinimal + dirichlet);
  ASSERT_EQ(s.dirichlet.size(), 1u);
  EXPECT_EQ(s.dirichlet[0].boundary, (std::vector<std::string>{"x_min", "x_max", "y_min", "y_max", "hull"}));
  EXPECT_EQ(s.dirichlet[0].value.number(), 0.0);  // an integer is a number
  // 3D: z_min, z_max.
  const std::string cube = edit(edit(edit(kMinimal, "lower = [0.0, 0.0]", "lower = [0.0, 0.0, 0.0]"), "upper = [1.0, 1.0]",
                                     "upper = [1.0, 1.0, 1.0]"),
                                "counts = [21, 21]", "counts = [5, 5, 5]\nquadrature_points = 4");
  const Scene c = parse(cube + "[[dirichlet]]\nboundary = [\"z_min\", \"z_max\"]\nunknown = \"u\"\ncomponents = [0, 2]\nvalue = 1.5\n");
  EXPECT_EQ(c.dim(), 3);
  EXPECT_EQ(c.dirichlet[0].components, (std::vector<int>{0, 2}));
  // 2D has no z.
  std::string t = kMinimal + "[[dirichlet]]\nboundary = [\"x_min\", \"z_max\"]\nunknown = \"u\"\nvalue = 0\n";
  expect_error(t, {at_line(t, "boundary ="), "key 'dirichlet[0].boundary' names 'z_max', which is no boundary part of this 2D scene",
                   "(parts: 'x_min', 'x_max', 'y_min', 'y_max', 'hull')"});
  // Axisymmetric: r_max, z_min, z_max, hull, axis; no r_min (the axis is r = 0).
  const std::string axi = edit(kMinimal, "coordinates = \"cartesian\"", "coordinates = \"axisymmetric\"");
  const Scene a = parse(axi + "[[dirichlet]]\nboundary = [\"r_max\", \"z_min\", \"z_max\", \"hull\", \"axis\"]\nunknown = \"u\"\n"
                              "value = -1.0\n");
  EXPECT_EQ(a.dirichlet[0].boundary.size(), 5u);
  t = axi + "[[dirichlet]]\nboundary = \"r_min\"\nunknown = \"u\"\nvalue = 0\n";
  expect_error(t, {at_line(t, "boundary ="), "names 'r_min', which is no boundary part of this axisymmetric scene",
                   "(parts: 'r_max', 'z_min', 'z_max', 'hull', 'axis')"});
  t = kMinimal + "[[dirichlet]]\nboundary = \"axis\"\nunknown = \"u\"\nvalue = 0\n";
  expect_error(t, {"names 'axis', which is no boundary part of this 2D scene"});
  // Did you mean.
  t = kMinimal + "[[dirichlet]]\nboundary = [\"x_min\", \"x_mx\"]\nunknown = \"u\"\nvalue = 0\n";
  expect_error(t, {at_line(t, "boundary ="), "names 'x_mx'", "did you mean 'x_max'?"});
  t = axi + "[[dirichlet]]\nboundary = \"axsi\"\nunknown = \"u\"\nvalue = 0\n";
  expect_error(t, {"names 'axsi'", "did you mean 'axis'?"});
}

TEST(SceneDirichlet, ValuesComponentsAndEntries) {
  const Scene s = parse(kMinimal +
                        "[[dirichlet]]\nboundary = \"hull\"\nunknown = \"u\"\nvalue = \"sin(pi*x[0])*sin(pi*x[1])\"\n"
                        "[[dirichlet]]\nboundary = \"x_min\"\nunknown = \"y\"\ncomponents = [1]\nvalue = \"[0, x[1]]\"\n");
  ASSERT_EQ(s.dirichlet.size(), 2u);
  EXPECT_EQ(s.dirichlet[0].value.expression(), "sin(pi*x[0])*sin(pi*x[1])");
  EXPECT_EQ(s.dirichlet[1].unknown, "y");
  EXPECT_EQ(s.dirichlet[1].components, (std::vector<int>{1}));
  EXPECT_EQ(s.dirichlet[1].value.expression(), "[0, x[1]]");
  EXPECT_EQ(s.dirichlet[1].value.where, "scenes/ok.toml:19: key 'dirichlet[1].value'");
  const std::string entry = "[[dirichlet]]\nboundary = \"hull\"\nunknown = \"u\"\nvalue = 0\n";
  std::string t = kMinimal + edit(entry, "value = 0", "value = true");
  expect_error(t, {at_line(t, "value = true"), "key 'dirichlet[0].value' must be a number or an expression string "
                                               "(e.g. \"sin(pi*x[0])\"), found a boolean"});
  t = kMinimal + edit(entry, "value = 0\n", "");
  expect_error(t, {"missing key 'dirichlet[0].value' in [dirichlet[0]]"});
  t = kMinimal + edit(entry, "unknown = \"u\"\n", "");
  expect_error(t, {"missing key 'dirichlet[0].unknown' in [dirichlet[0]]"});
  t = kMinimal + edit(entry, "boundary = \"hull\"\n", "");
  expect_error(t, {"missing key 'dirichlet[0].boundary' in [dirichlet[0]]"});
  t = kMinimal + edit(entry, "value = 0", "valeu = 0");
  expect_error(t, {at_line(t, "valeu"), "unknown key 'dirichlet[0].valeu'; did you mean 'value'?"});
  t = kMinimal + edit(entry, "value = 0", "value = 0\ncomponents = [2]");
  expect_error(t, {at_line(t, "components ="), "key 'dirichlet[0].components' has component 2, outside 0..1"});
  t = kMinimal + edit(entry, "value = 0", "value = 0\ncomponents = [-1]");
  expect_error(t, {"has component -1, outside 0..1"});
  t = kMinimal + edit(entry, "value = 0", "value = 0\ncomponents = 0");
  expect_error(t, {"key 'dirichlet[0].components' must be an array of component indices, found an integer"});
  t = kMinimal + edit(entry, "value = 0", "value = 0\ncomponents = [0.5]");
  expect_error(t, {"key 'dirichlet[0].components[0]' must be an integer, found a floating-point number"});
  t = kMinimal + "[dirichlet]\nboundary = \"hull\"\nunknown = \"u\"\nvalue = 0\n";
  expect_error(t, {at_line(t, "[dirichlet]"), "key 'dirichlet' must be an array of tables ([[dirichlet]]), found a table"});
  // The second entry's errors name it.
  t = kMinimal + entry + edit(entry, "value = 0", "value = [0]");
  expect_error(t, {"key 'dirichlet[1].value' must be a number or an expression string"});
}

// The prefix of an entry's messages (bind_scene: "'ph' is no unknown of the problem", "no node lies
// on the boundary parts") must point at that entry, not at the top of the file.
TEST(SceneDirichlet, EntryWhereNamesItsLine) {
  const std::string t = kMinimal + "[[dirichlet]]\nboundary = \"hull\"\nunknown = \"u\"\nvalue = 0\n" +
                        "[[dirichlet]]\nboundary = \"x_min\"\nunknown = \"u\"\nvalue = 1\n";
  const Scene s = parse(t);
  ASSERT_EQ(s.dirichlet.size(), 2u);
  EXPECT_NE(s.dirichlet[0].where.find("key 'dirichlet[0]'"), std::string::npos) << s.dirichlet[0].where;
  EXPECT_NE(s.dirichlet[1].where.find("key 'dirichlet[1]'"), std::string::npos) << s.dirichlet[1].where;
  // The entry's own lines: its header (TOML gives the table its first key's line or its header's).
  const int header0 = line_of(t, "[[dirichlet]]"), header1 = line_of(t, "boundary = \"x_min\"") - 1;
  auto line_in = [](const std::string& where) { return std::stoi(where.substr(where.find(':') + 1)); };
  const int l0 = line_in(s.dirichlet[0].where), l1 = line_in(s.dirichlet[1].where);
  EXPECT_TRUE(l0 >= header0 && l0 <= header0 + 3) << s.dirichlet[0].where << " (entry at lines " << header0 << "-" << header0 + 3 << ")";
  EXPECT_TRUE(l1 >= header1 && l1 <= header1 + 3) << s.dirichlet[1].where << " (entry at lines " << header1 << "-" << header1 + 3 << ")";
}

// ---------------------------------------------------------------------------------------------
// [initial], [qdata]

TEST(SceneInitial, NumberExpressionOrFile) {
  const std::filesystem::path dir = std::filesystem::path(LMEFORM_TEST_TMPDIR) / "scene_initial";
  std::filesystem::create_directories(dir / "runs");
  { std::ofstream(dir / "runs" / "previous.h5") << "not read by the scene reader"; }
  const std::string text = kMinimal + "[initial]\nu = { file = \"runs/previous.h5\" }\nw = 1\n"
                                      "v = { file = \"runs/previous.h5\", field = \"T\" }\ny = \"[x[1], -x[0]]\"\n";
  { std::ofstream(dir / "initial.toml") << text; }
  const Scene s = load_scene(dir / "initial.toml");
  ASSERT_EQ(s.initial.size(), 4u);
  EXPECT_EQ(s.initial[0].unknown, "u");  // the order of the file
  EXPECT_EQ(s.initial[0].kind, SceneInitialField::Kind::file);
  EXPECT_EQ(s.initial[0].file, dir / "runs" / "previous.h5");  // against the scene's folder
  EXPECT_EQ(s.initial[0].field, "u");                           // default: the unknown's name
  EXPECT_EQ(s.initial[1].unknown, "w");
  EXPECT_EQ(s.initial[1].kind, SceneInitialField::Kind::value);
  EXPECT_EQ(s.initial[1].value.number(), 1.0);
  EXPECT_EQ(s.initial[2].unknown, "v");
  EXPECT_EQ(s.initial[2].field, "T");
  EXPECT_EQ(s.initial[3].unknown, "y");
  EXPECT_EQ(s.initial[3].value.expression(), "[x[1], -x[0]]");

  std::string t = kMinimal + "[initial]\nu = { file = \"missing.h5\" }\n";
  expect_error(t, {at_line(t, "u = {"), "key 'initial.u.file' names a file that does not exist: scenes/missing.h5"});
  t = kMinimal + "[initial]\nu = { file = \"a.h5\", feld = \"T\" }\n";
  expect_error(t, {at_line(t, "u = {"), "unknown key 'initial.u.feld'; did you mean 'field'?"});
  t = kMinimal + "[initial]\nu = { field = \"T\" }\n";
  expect_error(t, {"missing key 'initial.u.file' in [initial.u]"});
  t = kMinimal + "[initial]\nu = false\n";
  expect_error(t, {at_line(t, "u = false"), "key 'initial.u' must be a number or an expression string", "found a boolean"});
  t = kMinimal + "[initial]\nu = [0.0, 1.0]\n";
  expect_error(t, {"key 'initial.u' must be a number or an expression string", "found an array"});
  t = kMinimal + "[initial]\nu = \"\"\n";
  expect_error(t, {"key 'initial.u' must not be empty"});
}

TEST(SceneQdata, Providers) {
  const Scene s = parse(kMinimal + "[qdata]\nrho = \"support_size\"\n");
  ASSERT_EQ(s.qdata.size(), 1u);
  EXPECT_EQ(s.qdata[0].name, "rho");
  EXPECT_EQ(s.qdata[0].source, SceneQdata::Source::support_size);
  EXPECT_EQ(s.qdata[0].where, "scenes/ok.toml:12: key 'qdata.rho'");
  std::string t = kMinimal + "[qdata]\nrho = \"support_sise\"\n";
  expect_error(t, {at_line(t, "rho ="), "key 'qdata.rho' must be one of 'support_size', 'zero', a number or an expression, "
                                        "got 'support_sise'; did you mean 'support_size'?"});
  // A number or any other string is a value for every quadrature point (an expression of x).
  t = kMinimal + "[qdata]\nrho = 0.5\nf = \"sin(pi*x[0])\"\n";
  const Scene values = parse_scene(t, "scenes/ok.toml");
  ASSERT_EQ(values.qdata.size(), 2u);
  for (const auto& q : values.qdata) {
    EXPECT_EQ(q.source, SceneQdata::Source::value) << q.name;
    if (q.name == "rho") EXPECT_EQ(q.value.number(), 0.5);
    else EXPECT_EQ(q.value.expression(), "sin(pi*x[0])");
  }
}

// ---------------------------------------------------------------------------------------------
// [solver], [reference], [output]

TEST(SceneSolver, PetscOptionsAndRanges) {
  const Scene s = parse(kMinimal + "[solver]\npetsc_options = \"-pc_type lu -pc_factor_mat_solver_type mumps\"\n");
  EXPECT_EQ(s.solver.petsc_options, "-pc_type lu -pc_factor_mat_solver_type mumps");
  std::string t = kMinimal + "[solver]\npetsc_options = [\"-ksp_type\", \"gmres\"]\n";
  expect_error(t, {at_line(t, "petsc_options"), "key 'solver.petsc_options' must be a string, found an array"});
  t = kMinimal + "[solver]\npetsc_options = \"\"\n";
  expect_error(t, {"key 'solver.petsc_options' must not be empty"});
  t = kMinimal + "[solver]\npetsc = \"-ksp_type gmres\"\n";
  expect_error(t, {at_line(t, "petsc ="), "unknown key 'solver.petsc'"});
  t = kMinimal + "[solver]\nnewton_tolerence = 1e-10\n";
  expect_error(t, {at_line(t, "newton_tolerence"), "unknown key 'solver.newton_tolerence'; did you mean 'newton_tolerance'?"});
  // Close to a word of several keys: all of them.
  t = kMinimal + "[solver]\ntolerence = 1e-2\n";
  expect_error(t, {"unknown key 'solver.tolerence'; did you mean one of 'augmented_tolerance', 'inner_tolerance', "
                   "'newton_tolerance', 'constraint_tolerance'?"});
  // Nothing close: the valid keys are listed.
  t = kMinimal + "[solver]\nspeed = 1e-2\n";
  expect_error(t, {"unknown key 'solver.speed'", "the keys of [solver] are 'start', 'penalty', 'augmented_tolerance'", "'petsc_options'"});
  t = kMinimal + "[solver]\nmax_outer_iterations = 30.5\n";
  expect_error(t, {"key 'solver.max_outer_iterations' must be an integer, found a floating-point number"});
  t = kMinimal + "[solver]\nmax_outer_iterations = 0\n";
  expect_error(t, {"key 'solver.max_outer_iterations' must be at least 1, got 0"});
  t = kMinimal + "[solver]\nmax_newton_iterations = -1\n";
  expect_error(t, {"key 'solver.max_newton_iterations' must be at least 0, got -1"});
  EXPECT_EQ(parse(kMinimal + "[solver]\nmax_newton_iterations = 0\n").solver.max_newton_iterations, 0);
  t = kMinimal + "[solver]\npenalty = -1e-3\n";
  expect_error(t, {at_line(t, "penalty"), "key 'solver.penalty' must be positive, got -0.001"});
  t = kMinimal + "[solver]\nnewton_tolerance = 0\n";
  expect_error(t, {"key 'solver.newton_tolerance' must be positive, got 0"});
}

TEST(SceneReference, EnergyAndExactSolution) {
  const Scene s = parse(kMinimal + "[reference]\nenergy = -0.25\n[reference.solution]\nu = \"sin(pi*x[0])*sin(pi*x[1])\"\n");
  ASSERT_TRUE(s.reference.energy);
  EXPECT_EQ(*s.reference.energy, -0.25);
  ASSERT_EQ(s.reference.solution.size(), 1u);
  EXPECT_EQ(s.reference.solution[0].first, "u");
  EXPECT_EQ(s.reference.solution[0].second.expression(), "sin(pi*x[0])*sin(pi*x[1])");
  EXPECT_EQ(s.reference.solution[0].second.where, "scenes/ok.toml:14: key 'reference.solution.u'");
  // Either alone.
  const Scene e = parse(kMinimal + "[reference]\nenergy = 1\n");
  EXPECT_EQ(e.reference.energy, 1.0);
  EXPECT_TRUE(e.reference.solution.empty());
  const Scene u = parse(kMinimal + "[reference.solution]\nu = \"x[0]\"\n");
  EXPECT_FALSE(u.reference.energy);
  EXPECT_EQ(u.reference.solution.size(), 1u);
  // A number is read here; bind_scene refuses it (an exact solution is an expression).
  EXPECT_TRUE(parse(kMinimal + "[reference.solution]\nu = 0\n").reference.solution[0].second.is_number());
  std::string t = kMinimal + "[reference]\nenrgy = 1\n";
  expect_error(t, {at_line(t, "enrgy"), "unknown key 'reference.enrgy'; did you mean 'energy'?"});
  t = kMinimal + "[reference]\nsolution = \"x[0]\"\n";
  expect_error(t, {at_line(t, "solution ="), "key 'reference.solution' must be a table, found a string"});
  t = kMinimal + "[reference]\nenergy = \"9.1\"\n";
  expect_error(t, {"key 'reference.energy' must be a number, found a string"});
  t = kMinimal + "[reference.solution]\nu = true\n";
  expect_error(t, {at_line(t, "u = true"), "key 'reference.solution.u' must be a number or an expression string"});
}

TEST(SceneOutput, Keys) {
  const Scene s = parse(kMinimal + "[output]\ndirectory = \"out/p\"\npng = true\n");
  ASSERT_TRUE(s.output);
  EXPECT_EQ(s.output->directory, "out/p");
  EXPECT_TRUE(s.output->hdf5);
  EXPECT_TRUE(s.output->png);
  std::string t = kMinimal + "[output]\ndirectory = \"out\"\nhdf5 = 0\n";
  expect_error(t, {at_line(t, "hdf5"), "key 'output.hdf5' must be a boolean (true or false), found an integer"});
  t = kMinimal + "[output]\ndirectory = \"out\"\npgn = false\n";
  expect_error(t, {at_line(t, "pgn"), "unknown key 'output.pgn'; did you mean 'png'?"});
}

// ---------------------------------------------------------------------------------------------
// Top-level tables and extensions

TEST(SceneTables, UnknownTableWithSuggestion) {
  std::string t = kMinimal + "[solvr]\npenalty = 1e-3\n";
  expect_error(t, {at_line(t, "[solvr]"), "unknown table [solvr]; did you mean [solver]?"});  // the table's header
  t = kMinimal + "[constant]\nk = 1\n";
  expect_error(t, {"unknown table [constant]; did you mean [constants]?"});
  t = kMinimal + "[[dirichet]]\nboundary = \"hull\"\n";
  expect_error(t, {"unknown table [dirichet]; did you mean [dirichlet]?"});
  // Nothing close: the tables are listed.
  t = kMinimal + "[mesh]\nsize = 3\n";
  expect_error(t, {"unknown table [mesh]; the tables of a scene are [scene], [domain], [nodes], [model], [constants], [parameters], "
                   "[constraints], [dirichlet], [equipotential], [initial], [coefficients], [qdata], [solver], [reference], [quantities], [bounds], [output]"});
  // The old format's [adaptivity] is no table of the reader.
  t = kMinimal + "[adaptivity]\nstages = []\n";
  expect_error(t, {"unknown table [adaptivity]"});
}

TEST(SceneTables, ExtensionTablesAreKeptUnread) {
  // [vesicle] is unknown to a reader that is not told about it...
  const std::string t = kMinimal + "[vesicle]\nradius = 0.4\nanything = \"goes\"\n[vesicle.initial]\nshape = \"sphere\"\n";
  expect_error(t, {at_line(t, "[vesicle]"), "unknown table [vesicle]"});
  // ...and kept, unread, for the model that owns it when the caller lists it.
  const Scene s = parse(t, kVesicleOnly);
  EXPECT_EQ(s.extensions, (std::vector<std::string>{"vesicle"}));
  EXPECT_TRUE(s.has_extension("vesicle"));
  EXPECT_FALSE(s.has_extension("membrane"));
  // The model reads it from the document with the scene's strictness.
  const auto v = extension_table(s, "vesicle", {"radius", "anything", "initial"});
  ASSERT_TRUE(v);
  EXPECT_EQ(v->number("radius"), 0.4);
  EXPECT_EQ(v->string("anything"), "goes");
  EXPECT_EQ(v->where("radius"), "scenes/ok.toml:" + std::to_string(line_of(t, "radius = 0.4")) + ": key 'vesicle.radius'");
  try {
    (void)extension_table(s, "vesicle", {"radius", "initial"});
    ADD_FAILURE() << "an unknown key of the extension was accepted";
  } catch (const SceneError& e) {
    EXPECT_NE(std::string(e.what()).find("unknown key 'vesicle.anything'"), std::string::npos) << e.what();
  }
  EXPECT_FALSE(extension_table(s, "membrane", {"radius"}));
  // Listed but absent: not among the scene's extensions.
  const Scene n = parse(kMinimal, kVesicleOnly);
  EXPECT_TRUE(n.extensions.empty());
  EXPECT_FALSE(n.has_extension("vesicle"));
  EXPECT_FALSE(extension_table(n, "vesicle", {"radius"}));
  // Several extensions: each present one is listed; an unlisted one is refused with a suggestion.
  constexpr std::string_view two[] = {"vesicle", "membrane"};
  const Scene m = parse(kMinimal + "[membrane]\nk = 1\n[vesicle]\nradius = 0.4\n", two);
  EXPECT_EQ(m.extensions, (std::vector<std::string>{"vesicle", "membrane"}));
  expect_error(kMinimal + "[vesicel]\nradius = 0.4\n", {"unknown table [vesicel]; did you mean [vesicle]?"}, kVesicleOnly);
  expect_error(kMinimal + "[membrane]\nk = 1\n", {"unknown table [membrane]"}, kVesicleOnly);
  // An extension that is no table.
  const Scene bad = parse("vesicle = 3\n" + kMinimal, kVesicleOnly);
  try {
    (void)extension_table(bad, "vesicle", {"radius"});
    ADD_FAILURE() << "a non-table extension was accepted";
  } catch (const SceneError& e) {
    EXPECT_NE(std::string(e.what()).find("scenes/ok.toml:1: 'vesicle' must be a table ([vesicle]), found an integer"),
              std::string::npos)
        << e.what();
  }
}

// ---------------------------------------------------------------------------------------------
// [scene], [domain], [nodes]: missing keys, wrong types, ranges

TEST(SceneBasics, MissingKeys) {
  std::string t = edit(kMinimal, "name = \"plain\"\n", "");
  expect_error(t, {at_line(t, "[scene]"), "missing key 'scene.name' in [scene]"});
  t = edit(kMinimal, "[domain]\nlower = [0.0, 0.0]\nupper = [1.0, 1.0]\n", "");
  expect_error(t, {"scenes/broken.toml", "missing table [domain]"});
  t = edit(kMinimal, "counts = [21, 21]\n", "");
  expect_error(t, {"scenes/broken.toml", "'nodes.spacing', 'nodes.counts', 'nodes.count' or 'nodes.file'"});
  t = edit(kMinimal, "upper = [1.0, 1.0]\n", "");
  expect_error(t, {"missing key 'domain.upper' in [domain]"});
}

TEST(SceneBasics, UnknownKeysAndChoices) {
  std::string t = edit(kMinimal, "counts = [21, 21]", "counts = [21, 21]\ngama = 0.8");
  expect_error(t, {at_line(t, "gama"), "unknown key 'nodes.gama'; did you mean 'gamma'?"});
  t = edit(kMinimal, "\"cartesian\"", "\"cartesain\"");
  expect_error(t, {at_line(t, "coordinates ="), "key 'scene.coordinates' must be one of 'axisymmetric', 'cartesian', got "
                                                "'cartesain'; did you mean 'cartesian'?"});
  t = edit(kMinimal, "name = \"plain\"", "name = \"plain\"\ntitle = \"x\"");
  expect_error(t, {"unknown key 'scene.title'", "the keys of [scene] are 'name', 'coordinates', 'description'"});
}

TEST(SceneBasics, WrongTypes) {
  std::string t = edit(kMinimal, "counts = [21, 21]", "spacing = \"0.05\"");
  expect_error(t, {at_line(t, "spacing ="), "key 'nodes.spacing' must be a number, found a string"});
  t = edit(kMinimal, "upper = [1.0, 1.0]", "upper = [1.0, 1.0, 3.0]");
  expect_error(t, {at_line(t, "upper ="), "key 'domain.upper' must be an array of 2 numbers, found 3 entries"});
  t = edit(kMinimal, "lower = [0.0, 0.0]", "lower = []");
  expect_error(t, {"key 'domain.lower' must be an array of 1, 2 or 3 numbers, found 0 entries"});
  t = edit(kMinimal, "upper = [1.0, 1.0]", "upper = [1.0, \"1\"]");
  expect_error(t, {"key 'domain.upper[1]' must be a number, found a string"});
  t = edit(kMinimal, "counts = [21, 21]", "counts = [21, 21.5]");
  expect_error(t, {"key 'nodes.counts[1]' must be an integer, found a floating-point number"});
  t = "solver = 3\n" + kMinimal;
  expect_error(t, {"scenes/broken.toml:1: 'solver' must be a table ([solver]), found an integer"});
  t = edit(kMinimal, "name = \"plain\"", "name = 7");
  expect_error(t, {"key 'scene.name' must be a string, found an integer"});
}

TEST(SceneBasics, OutOfRange) {
  std::string t = edit(kMinimal, "counts = [21, 21]", "spacing = -0.05");
  expect_error(t, {at_line(t, "spacing ="), "key 'nodes.spacing' must be positive, got -0.05"});
  t = edit(kMinimal, "counts = [21, 21]", "spacing = 1.5");
  expect_error(t, {"key 'nodes.spacing' = 1.5 exceeds the smallest extent of the domain (1)"});
  t = edit(kMinimal, "counts = [21, 21]", "counts = [21, 21]\ngamma = 0");
  expect_error(t, {"key 'nodes.gamma' must be positive, got 0"});
  t = edit(kMinimal, "counts = [21, 21]", "counts = [21, 21]\nquadrature_points = 5");
  expect_error(t, {"key 'nodes.quadrature_points' = 5 is not a triangle rule", "1, 3, 6, 7"});
  t = edit(kMinimal, "counts = [21, 21]", "counts = [21, 21]\nspacing_smoothing = -1");
  expect_error(t, {"key 'nodes.spacing_smoothing' must be at least 0, got -1"});
  t = edit(kMinimal, "counts = [21, 21]", "counts = [21, 1]");
  expect_error(t, {"key 'nodes.counts' must have at least 2 nodes per axis, got 1 on axis y"});
  t = edit(kMinimal, "upper = [1.0, 1.0]", "upper = [1.0, -1.0]");
  expect_error(t, {at_line(t, "upper ="), "key 'domain.upper' must exceed 'domain.lower' on every axis: axis y has lower 0, upper -1"});
  const std::string axi = edit(kMinimal, "coordinates = \"cartesian\"", "coordinates = \"axisymmetric\"");
  t = edit(axi, "lower = [0.0, 0.0]", "lower = [-0.5, 0.0]");
  expect_error(t, {"key 'domain.lower' must have r >= 0 in an axisymmetric scene"});
  t = edit(axi, "upper = [1.0, 1.0]", "upper = [1.0, 1.0, 1.0]");
  expect_error(t, {"key 'domain.upper' must be an array of 2 numbers"});
  // 3D: the tetrahedron rules.
  const std::string cube = edit(edit(edit(kMinimal, "lower = [0.0, 0.0]", "lower = [0.0, 0.0, 0.0]"), "upper = [1.0, 1.0]",
                                     "upper = [1.0, 1.0, 1.0]"),
                                "counts = [21, 21]", "counts = [5, 5, 5]\nquadrature_points = 6");
  expect_error(cube, {"key 'nodes.quadrature_points' = 6 is not a tetrahedron rule"});
  EXPECT_EQ(parse(edit(cube, "quadrature_points = 6", "quadrature_points = 4")).nodes.quadrature_points, 4);
}

TEST(SceneBasics, BasisOrder) {
  EXPECT_EQ(parse(kMinimal).nodes.basis, LmeConsistency::first);
  const Scene s = parse(edit(kMinimal, "counts = [21, 21]", "counts = [21, 21]\nbasis = \"second\"\ngamma = 0.5"));
  EXPECT_EQ(s.nodes.basis, LmeConsistency::second);
  std::string t = edit(kMinimal, "counts = [21, 21]", "counts = [21, 21]\nbasis = \"quadratic\"");
  expect_error(t, {at_line(t, "basis ="), "key 'nodes.basis'", "first", "second"});
  // The second-order basis needs its nodal gap h^2 / (2 gamma) wider than the holes between nodes.
  t = edit(kMinimal, "counts = [21, 21]", "counts = [21, 21]\nbasis = \"second\"\ngamma = 1.8");
  expect_error(t, {at_line(t, "gamma ="), "key 'nodes.gamma' = 1.8 is too large for nodes.basis = \"second\"", "at most 1"});
  EXPECT_EQ(parse(edit(kMinimal, "counts = [21, 21]", "counts = [21, 21]\nbasis = \"first\"\ngamma = 1.8")).nodes.gamma, 1.8);
}

TEST(SceneBasics, NodeKinds) {
  const Scene s = parse(edit(kMinimal, "counts = [21, 21]", "count = 500\nlloyd_iterations = 40"));
  EXPECT_EQ(s.nodes.kind, SceneNodes::Kind::count);
  EXPECT_EQ(s.nodes.count, 500);
  EXPECT_EQ(s.nodes.lloyd_iterations, 40);
  EXPECT_EQ(parse(edit(kMinimal, "counts = [21, 21]", "count = 500")).nodes.lloyd_iterations, 100);
  const Scene g = parse(edit(kMinimal, "counts = [21, 21]", "spacing = 0.05"));
  EXPECT_EQ(g.nodes.kind, SceneNodes::Kind::spacing);
  EXPECT_EQ(g.nodes.spacing, 0.05);
  std::string t = edit(kMinimal, "counts = [21, 21]", "counts = [21, 21]\ncount = 500");
  expect_error(t, {"key 'nodes.count' cannot be combined with 'nodes.counts'"});
  t = edit(kMinimal, "counts = [21, 21]", "count = 10");
  expect_error(t, {"key 'nodes.count' must be at least 16, got 10"});
  t = edit(kMinimal, "counts = [21, 21]", "count = 500.5");
  expect_error(t, {"key 'nodes.count' must be an integer"});
  t = edit(kMinimal, "counts = [21, 21]", "counts = [21, 21]\nlloyd_iterations = 5");
  expect_error(t, {at_line(t, "lloyd_iterations"), "key 'nodes.lloyd_iterations' belongs to 'nodes.count'"});
  const std::string cube = edit(edit(edit(kMinimal, "lower = [0.0, 0.0]", "lower = [0.0, 0.0, 0.0]"), "upper = [1.0, 1.0]",
                                     "upper = [1.0, 1.0, 1.0]"),
                                "counts = [21, 21]", "count = 500");
  expect_error(cube, {"key 'nodes.count' is a 2D node set (uniform CVT); this domain is 3D"});
}

TEST(SceneBasics, NodeFileRelativeToScene) {
  const std::filesystem::path dir = std::filesystem::path(LMEFORM_TEST_TMPDIR) / "scene_files";
  std::filesystem::create_directories(dir);
  { std::ofstream(dir / "nodes.csv") << "0,0\n1,0\n0,1\n1,1\n"; }
  const std::string text = edit(kMinimal, "counts = [21, 21]", "file = \"nodes.csv\"");
  { std::ofstream(dir / "with_file.toml") << text; }
  const Scene s = load_scene(dir / "with_file.toml");
  EXPECT_EQ(s.nodes.kind, SceneNodes::Kind::file);
  EXPECT_EQ(s.nodes.file, dir / "nodes.csv");
  EXPECT_EQ(s.folder, dir);
  EXPECT_EQ(s.model.forms[0].name, (dir / "poisson.form").string());  // a form path resolves the same way
  expect_error(edit(kMinimal, "counts = [21, 21]", "file = \"missing.csv\""),
               {"key 'nodes.file' names a file that does not exist: scenes/missing.csv"});
}

TEST(SceneBasics, SyntaxErrorAndMissingFile) {
  const std::string t = edit(kMinimal, "name = \"plain\"", "name = = \"plain\"");
  // TOML's own errors carry the column too.
  expect_error(t, {"scenes/broken.toml:" + std::to_string(line_of(t, "name = =")) + ":8: TOML syntax error"});
  try {
    (void)load_scene("/nonexistent/scene.toml");
    ADD_FAILURE() << "no error";
  } catch (const SceneError& e) {
    EXPECT_NE(std::string(e.what()).find("/nonexistent/scene.toml: cannot open the scene file"), std::string::npos) << e.what();
  }
}

// ---------------------------------------------------------------------------------------------
// The demos (their [vesicle] tables: test_vesicle_scene.cpp)

TEST(SceneDemos, LoadWithTheVesicleExtension) {
  for (const char* name : {"discocyte", "dumbbell"}) {
    SCOPED_TRACE(name);
    const std::filesystem::path path = std::filesystem::path(LMEFORM_SOURCE_DIR) / "demos" / (std::string(name) + ".toml");
    const Scene s = load_scene(path, kVesicleOnly);
    EXPECT_EQ(s.name, name);
    EXPECT_TRUE(s.axisymmetric());
    EXPECT_EQ(s.domain.hi[0], 1.5);
    EXPECT_EQ(s.domain.hi[1], 2.0);
    EXPECT_EQ(s.nodes.kind, SceneNodes::Kind::count);
    EXPECT_EQ(s.nodes.count, 6124);  // the seed's grid O1 / P1
    EXPECT_EQ(s.nodes.gamma, 0.5);
    ASSERT_EQ(s.model.forms.size(), 4u);
    EXPECT_EQ(s.model.forms[0].name, "helfrich_axisymmetric");
    ASSERT_EQ(s.model.energy.size(), 1u);
    EXPECT_EQ(s.model.energy[0].name, "bending");
    EXPECT_EQ(s.constants.at("k"), 1.0);
    EXPECT_EQ(s.constants.at("eps"), 0.04);
    EXPECT_EQ(s.constants.at("C0"), 0.0);
    EXPECT_EQ(constraint_names(s), (std::vector<std::string>{"area", "volume", "moment"}));
    EXPECT_FALSE(s.constraints[0].target);  // from [vesicle]
    EXPECT_FALSE(s.constraints[1].target);
    EXPECT_EQ(s.constraints[2].target, 0.0);
    ASSERT_EQ(s.dirichlet.size(), 1u);
    EXPECT_EQ(s.dirichlet[0].boundary, (std::vector<std::string>{"r_max", "z_min", "z_max"}));
    EXPECT_EQ(s.dirichlet[0].value.number(), -1.0);
    ASSERT_TRUE(s.reference.energy);
    EXPECT_EQ(*s.reference.energy, std::string(name) == "discocyte" ? 9.12657 : 8.71756);
    EXPECT_EQ(s.extensions, (std::vector<std::string>{"vesicle"}));
    // Without the extension list, [vesicle] is an unknown table.
    try {
      (void)load_scene(path);
      ADD_FAILURE() << "[vesicle] accepted without the extension";
    } catch (const SceneError& e) {
      EXPECT_NE(std::string(e.what()).find("unknown table [vesicle]"), std::string::npos) << e.what();
    }
  }
}

// ---------------------------------------------------------------------------------------------
// Helpers

TEST(SceneHelpers, ClosestName) {
  const std::vector<std::string> names{"eps", "k", "C0", "zc"};
  EXPECT_EQ(closest_name("esp", names), "eps");
  EXPECT_EQ(closest_name("c0", names), "C0");
  EXPECT_EQ(closest_name("bending_modulus", names), "");
  EXPECT_EQ(closest_name("x", std::vector<std::string>{}), "");
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
  // 3D: a sphere and a spheroid's pole; 1D: an interval.
  const std::array<double, 3> c3{0, 0, 0}, s3{1, 1, 1}, p3{0.3, 0.4, 0.0};
  EXPECT_NEAR(ellipsoid_signed_distance(p3, c3, s3), 0.5, 1e-12);
  const std::array<double, 3> e3{0.6, 0.6, 0.3}, q3{0.0, 0.0, 0.5};
  EXPECT_NEAR(ellipsoid_signed_distance(q3, c3, e3), -0.2, 1e-12);
  const std::array<double, 1> c1{1.0}, a1{0.5}, x1{1.2}, y1{2.0};
  EXPECT_NEAR(ellipsoid_signed_distance(x1, c1, a1), 0.3, 1e-14);
  EXPECT_NEAR(ellipsoid_signed_distance(y1, c1, a1), -0.5, 1e-14);
  // Mismatched dimensions.
  const std::array<double, 2> c2{0, 0};
  EXPECT_THROW((void)ellipsoid_signed_distance(p3, c2, s3), std::invalid_argument);
}
