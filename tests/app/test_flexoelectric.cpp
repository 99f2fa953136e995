// Flexoelectricity end to end (forms/flexoelectric*.form, the saddle-point driver, equipotential
// parts): without flexoelectricity the enthalpy reproduces the elastic cantilever of
// demos/solids; the two enthalpies of seed Eqs. 5.15 and 5.16 agree once the boundary integral by
// which they differ is added, and not without it; a floating electrode is equipotential to
// round-off and its charge balances the grounded one's; the inertia of the saddle; and the
// messages of bad inputs. Every scene is written into a temp folder and run through the driver
// that `lmeform run` uses.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

#include "lmeform/assembler.hpp"
#include "lmeform/discretization.hpp"
#include "lmeform/form_registry.hpp"
#include "lmeform/node_sets.hpp"
#include "lmeform/petsc.hpp"
#include "lmeform/scene.hpp"
#include "problem_registry.hpp"

namespace {

using namespace lmeform;
namespace fs = std::filesystem;

fs::path folder() {
  const fs::path dir = fs::path(LMEFORM_TEST_TMPDIR) / "flexoelectric";
  fs::create_directories(dir);
  return dir;
}

problems::RunReport run(const std::string& name, const std::string& text) {
  const fs::path path = folder() / name;
  std::ofstream(path) << text;
  const Scene scene = load_scene(path, problems::driver_tables());
  problems::DriverContext ctx;
  ctx.comm = PETSC_COMM_WORLD;
  ctx.scene = &scene;
  return problems::driver_for(scene).run(ctx);
}

std::string read(const fs::path& p) {
  std::ifstream in(p);
  std::stringstream s;
  s << in.rdbuf();
  return s.str();
}

/// `text` with `from`, at the start of a line, replaced by `to`; `from` must occur there exactly
/// once (a demo that changed would otherwise make a test compare a scene with itself).
std::string replaced(std::string text, const std::string& from, const std::string& to) {
  const auto at = text.find("\n" + from);
  if (at == std::string::npos) throw std::runtime_error("test scene: no line starts with '" + from + "'");
  if (text.find("\n" + from, at + 1) != std::string::npos) throw std::runtime_error("test scene: several lines start with '" + from + "'");
  return text.replace(at + 1, from.size(), to);
}

/// The demo scene demos/<group>/<name>.toml, its output folder moved into the temp folder.
std::string demo(const std::string& group, const std::string& name) {
  const std::string text = read(fs::path(LMEFORM_DEMOS) / group / (name + ".toml"));
  const std::string prefix = group == "solids" ? "build/demo/solids/" : "build/demo/flexoelectric/";
  return replaced(text, "directory = \"" + prefix + name + "\"", "directory = \"" + (folder() / (name + "_out")).string() + "\"");
}

double quantity(const problems::RunReport& r, const std::string& name) {
  const auto& q = r.json.at("quantities");
  if (!q.contains(name)) throw std::runtime_error("no quantity '" + name + "' in " + q.dump());
  return q.at(name).get<double>();
}

void expect_error(const std::string& name, const std::string& text, const std::vector<std::string>& fragments) {
  try {
    (void)run(name, text);
    ADD_FAILURE() << name << ": no error";
  } catch (const std::exception& e) {
    const std::string message = e.what();
    std::printf("%s: %s\n", name.c_str(), message.c_str());
    for (const auto& f : fragments) EXPECT_NE(message.find(f), std::string::npos) << name << ": '" << f << "' not in: " << message;
  }
}

const std::string kElasticEnergy =
    "elastic_energy = { integral = \"E/(2*(1 + nu))*inner(sym(grad(u)), sym(grad(u))) + E*nu/(2*(1 + nu)*(1 - 2*nu))*tr(sym(grad(u)))^2\" }\n";

// Without flexoelectricity (mu = 0) the enthalpy of the saddle-point driver is the elastic energy
// and the potential decouples: the Timoshenko-Goodier cantilever of demos/solids (in plane strain,
// the enthalpy's 2D state) comes out as the elastic minimization gives it, to round-off, and so
// Y' (seed Eq. 5.17) is 1.
TEST(Flexoelectric, WithoutFlexoelectricityTheElasticCantilever) {
  std::string elastic = replaced(demo("solids", "cantilever"), "spacing = 0.125", "spacing = 0.25");
  elastic = replaced(elastic, "plane_stress = 1", "plane_stress = 0");
  elastic = replaced(elastic, "[output]", kElasticEnergy + "[output]");
  std::string flexo = replaced(elastic, "forms = [\"elasticity\", \"traction\"]",
                               "forms = [\"flexoelectric\", \"flexoelectric_loads\"]\nenergy = [\"enthalpy\", \"work\"]\nmaximize = [\"phi\"]");
  flexo = replaced(flexo, "plane_stress = 0", "mu_L = 0.0\nmu_T = 0.0");
  flexo = replaced(flexo, "[reference.solution]", "[[dirichlet]]\nboundary = \"hull\"\nunknown = \"phi\"\nvalue = 0.0\n\n[reference.solution]");
  const problems::RunReport a = run("elastic_cantilever.toml", elastic);
  const problems::RunReport b = run("saddle_cantilever.toml", flexo);
  ASSERT_TRUE(a.success) << a.status;
  ASSERT_TRUE(b.success) << b.status;
  EXPECT_EQ(b.problem, "saddle point");
  for (const std::string q : {"tip_deflection", "root_stress", "energy_error", "reaction[0]", "reaction[1]", "elastic_energy"}) {
    std::printf("%-16s elastic %.15g, saddle (mu = 0) %.15g\n", q.c_str(), quantity(a, q), quantity(b, q));
    EXPECT_NEAR(quantity(b, q), quantity(a, q), 1e-10 * std::max(1.0, std::abs(quantity(a, q)))) << q;
  }
  const double y_prime = quantity(a, "elastic_energy") / quantity(b, "elastic_energy");
  std::printf("Y' = %.15f\n", y_prime);
  EXPECT_NEAR(y_prime, 1.0, 1e-10);  // measured 3.4e-12: two factorizations of a matrix of condition ~1e8
  const double l2 = a.json.at("errors").at(0).at("l2").get<double>();
  EXPECT_NEAR(b.json.at("errors").at(0).at("l2").get<double>(), l2, 1e-10 * l2);
  EXPECT_EQ(b.json.at("negative_eigenvalues"), b.json.at("expected_negative_eigenvalues"));
}

/// The cantilever demo with a floating top electrode and a grounded bottom at spacing 0.125 (h' = 2).
std::string floating_cantilever() { return demo("flexoelectric", "cantilever_floating"); }

// Seed Eq. 5.15 (f and d) and Eq. 5.16 (mu = d - f) differ by a boundary integral: with it
// (flexoelectric_fd's natural_terms) they are the same functional and their solutions agree to
// the discretization's error (with f and d both non-zero: 0.2 % in the tip deflection, 3.4 % in
// the electrode's potential); without it they solve another problem (14 % and 34 %).
TEST(Flexoelectric, TheTwoEnthalpiesAgreeWithTheirBoundaryIntegral) {
  const std::string mu = floating_cantilever();
  std::string fd = replaced(mu, "forms = [\"flexoelectric\", \"flexoelectric_loads\"]", "forms = [\"flexoelectric_fd\", \"flexoelectric_loads\"]");
  fd = replaced(fd, "energy = [\"enthalpy\", \"work\"]", "energy = [\"enthalpy\", \"natural_terms\", \"work\"]");
  fd = replaced(fd, "mu_L = 0.5\nmu_T = 0.5\nmu_S = 0.0", "d_L = 0.2\nd_T = 0.3\nd_S = 0.1\nf_L = -0.3\nf_T = -0.2\nf_S = 0.1");
  const std::string fd_alone = replaced(fd, "energy = [\"enthalpy\", \"natural_terms\", \"work\"]", "energy = [\"enthalpy\", \"work\"]");
  const problems::RunReport a = run("enthalpy_mu.toml", mu), b = run("enthalpy_fd.toml", fd), c = run("enthalpy_fd_alone.toml", fd_alone);
  ASSERT_TRUE(a.success && b.success && c.success);
  const double tip = quantity(a, "tip_deflection"), tip_fd = quantity(b, "tip_deflection"), tip_alone = quantity(c, "tip_deflection");
  const double v = quantity(a, "top_potential"), v_fd = quantity(b, "top_potential"), v_alone = quantity(c, "top_potential");
  std::printf("tip deflection: Eq. 5.16 %.8f, Eq. 5.15 + boundary %.8f (%.2e), Eq. 5.15 alone %.8f (%.2e)\n", tip, tip_fd,
              (tip_fd - tip) / tip, tip_alone, (tip_alone - tip) / tip);
  std::printf("top potential:  Eq. 5.16 %.6e, Eq. 5.15 + boundary %.6e (%.2e), Eq. 5.15 alone %.6e\n", v, v_fd, (v_fd - v) / v, v_alone);
  EXPECT_LT(std::abs(tip_fd - tip), 0.01 * std::abs(tip));
  EXPECT_LT(std::abs(v_fd - v), 0.1 * std::abs(v));
  EXPECT_GT(std::abs(tip_alone - tip), 0.05 * std::abs(tip));
  EXPECT_GT(std::abs(v_alone - v), 0.2 * std::abs(v));
}

// The pyramid's floating bottom electrode: its potential is one value along the whole face (the
// LME functions on a hull edge are those of its nodes, which the elimination makes equal), and
// the charges balance: with a charge Q on it the grounded top carries -Q, with none neither carries
// any; the saddle has as many negative eigenvalues as free potential dofs.
TEST(Flexoelectric, AFloatingElectrodeIsEquipotentialAndBalancesTheGroundedCharge) {
  std::string s = replaced(demo("flexoelectric", "pyramid_rigid"), "spacing = 0.05", "spacing = 0.1");
  s = replaced(s, "[output]",
               "probe_a = { probe = [-0.95, 0.0], field = \"phi\" }\nprobe_b = { probe = [-0.31, 0.0], field = \"phi\" }\n"
               "probe_c = { probe = [0.47, 0.0], field = \"phi\" }\nprobe_d = { probe = [0.99, 0.0], field = \"phi\" }\n"
               "probe_inside = { probe = [0.0, 0.5], field = \"phi\" }\n[output]");
  for (const double charge : {0.0, 1e-6}) {
    const std::string text = charge == 0 ? s : replaced(s, "name = \"bottom\"", "name = \"bottom\"\ncharge = 1e-6");
    const problems::RunReport r = run(charge == 0 ? "pyramid_isolated.toml" : "pyramid_charged.toml", text);
    ASSERT_TRUE(r.success) << r.status;
    const double v = quantity(r, "bottom_potential");
    std::printf("Q = %g: bottom potential %.15e, probes %.15e %.15e %.15e %.15e (inside %.6e); charges bottom %.3e, top %.3e\n", charge, v,
                quantity(r, "probe_a"), quantity(r, "probe_b"), quantity(r, "probe_c"), quantity(r, "probe_d"), quantity(r, "probe_inside"),
                quantity(r, "bottom_charge"), -quantity(r, "top_reaction"));
    ASSERT_GT(std::abs(v), 1e-6);  // a potential, not a zero that any face would have
    for (const std::string p : {"probe_a", "probe_b", "probe_c", "probe_d"}) EXPECT_NEAR(quantity(r, p), v, 1e-12 * std::abs(v)) << p;
    EXPECT_GT(std::abs(quantity(r, "probe_inside") - v), 1e-3 * std::abs(v));
    // The charge scale: kappa V over the body, a thousand times the prescribed charge's round-off.
    const double scale = std::abs(v) + charge;
    EXPECT_NEAR(quantity(r, "bottom_charge"), charge, 1e-10 * scale);
    EXPECT_NEAR(-quantity(r, "top_reaction"), -charge, 1e-10 * scale);
    EXPECT_EQ(r.json.at("negative_eigenvalues"), r.json.at("expected_negative_eigenvalues"));
  }
}

TEST(BadInput, AFloatingElectrodeOnAPartThatDoesNotExist) {
  const std::string s = replaced(demo("flexoelectric", "pyramid_rigid"), "boundary = \"supported\"\nunknown = \"phi\"",
                                 "boundary = \"suported\"\nunknown = \"phi\"");
  expect_error("no_part.toml", s, {"no_part.toml:", "equipotential[0].boundary", "'suported'", "did you mean 'supported'?"});
}

TEST(BadInput, AnEquipotentialOfAVectorOrOutsideASaddlePoint) {
  const std::string pyramid = demo("flexoelectric", "pyramid_rigid");
  expect_error("vector.toml", replaced(pyramid, "boundary = \"supported\"\nunknown = \"phi\"\nname", "boundary = \"supported\"\nunknown = \"u\"\nname"),
               {"equipotential[0]", "'u' has 2 components"});
  const std::string minimization = replaced(pyramid, "maximize = [\"phi\"]", "");
  expect_error("not_saddle.toml", minimization, {"equipotential[0]", "saddle-point problems (model.maximize"});
  expect_error("maximize_residual.toml",
               replaced(replaced(pyramid, "energy = [\"enthalpy\", \"work\"]", "residual = \"R\""), "maximize = [\"phi\"]", "maximize = [\"phi\"]"),
               {"model.maximize", "belongs to an energy problem"});
  expect_error("shared_part.toml",
               replaced(pyramid, "[[equipotential]]                  # the floating bottom electrode\nboundary = \"supported\"",
                        "[[equipotential]]\nboundary = \"loaded\""),
               {"equipotential[0]", "part 'loaded' is also held by", "give one of them"});
}

// A singular saddle-point system is refused before its factorization, with what is free and the fix.
TEST(BadInput, ASingularSaddlePointIsNamedWithItsFix) {
  const std::string pyramid = replaced(demo("flexoelectric", "pyramid_rigid"), "spacing = 0.05", "spacing = 0.1");
  // No grounded part: the potential's constant is free (a floating electrode does not fix it).
  const std::string ungrounded = replaced(pyramid, "[[dirichlet]]                      # the grounded top electrode\nboundary = \"loaded\"\nunknown = \"phi\"\nvalue = 0.0", "");
  expect_error("ungrounded.toml", replaced(ungrounded, "top_reaction = ", "# "),
               {"singular", "a constant added to phi", "[[dirichlet]] entry: a grounded electrode", "model.zero_mean = [\"phi\"]"});
  // The bottom held vertically only, no foundation: the body slides.
  const std::string sliding = replaced(pyramid, "[[dirichlet]]                      # the rigid support\nboundary = \"supported\"\nunknown = \"u\"\nvalue = 0.0",
                                       "[[dirichlet]]\nboundary = \"supported\"\nunknown = \"u\"\ncomponents = [1]\nvalue = 0.0");
  expect_error("sliding.toml", sliding, {"singular", "a rigid translation of u along x", "hold u against rigid motion"});
  // With the level fixed by a zero mean instead, the same ungrounded pyramid solves.
  const problems::RunReport r = run("zero_mean.toml", replaced(replaced(ungrounded, "top_reaction = ", "# "), "maximize = [\"phi\"]",
                                                             "maximize = [\"phi\"]\nzero_mean = [\"phi\"]"));
  EXPECT_TRUE(r.success) << r.status;
  EXPECT_EQ(r.json.at("negative_eigenvalues"), r.json.at("expected_negative_eigenvalues"));
}

// The strain gradient needs the basis's second derivatives: a discretization tabulated to first
// derivatives only is refused when the enthalpy is assembled on it, naming the fix.
TEST(BadInput, AFlexoelectricFormOnABasisWithoutSecondDerivatives) {
  const NodeSet nodes = uniform_grid(Box{2, {0, 0, 0}, {1, 1, 0}}, {5, 5, 1});
  DiscretizationOptions options;
  options.basis_order = 1;
  const Discretization disc(PETSC_COMM_SELF, nodes, options);
  const FormModule& form = load_form("flexoelectric");
  try {
    Assembler a(disc, form.at("enthalpy", 2));
    ADD_FAILURE() << "no error";
  } catch (const std::invalid_argument& e) {
    const std::string message = e.what();
    std::printf("%s\n", message.c_str());
    EXPECT_NE(message.find("enthalpy"), std::string::npos) << message;
    EXPECT_NE(message.find("derivative order 2"), std::string::npos) << message;
    EXPECT_NE(message.find("basis_order = 2"), std::string::npos) << message;
  }
}

}  // namespace

int main(int argc, char** argv) {
  ::testing::InitGoogleTest(&argc, argv);
  lmeform::PetscSession petsc(&argc, &argv);
  return RUN_ALL_TESTS();
}
