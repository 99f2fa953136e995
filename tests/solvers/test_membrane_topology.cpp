// The membrane's topology in phase-field runs: the zero level set of an LME field (tanh profiles of
// a sphere, a torus and two spheres as surfaces of revolution), its JSON, the warning when it
// changes, and a vesicle run whose start has a hole the phase field closes: warned of, and stopped
// by the topology guard.
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <functional>
#include <numbers>
#include <string>

#include "lmeform/delaunay.hpp"
#include "membrane_topology.hpp"
#include "problem_registry.hpp"
#include "vesicle.hpp"
#include "vesicle_checkpoint.hpp"

namespace lmeform {
namespace {

using Profile = std::function<double(double r, double z)>;

/// A uniform (r, z) grid over [0, 0.8] x [0, 1.2] with spacing h.
NodeSet half_plane_grid(double h) {
  std::vector<double> coords;
  const int nr = static_cast<int>(std::lround(0.8 / h)), nz = static_cast<int>(std::lround(1.2 / h));
  for (int j = 0; j <= nz; ++j)
    for (int i = 0; i <= nr; ++i) {
      coords.push_back(i * h);
      coords.push_back(j * h);
    }
  return NodeSet(2, coords);
}

/// tanh(d / (√2 ε)) of a signed distance d (> 0 inside) as LME coefficients at the nodes.
std::vector<double> tanh_profile(const NodeSet& nodes, const Profile& distance, double eps) {
  std::vector<double> c(nodes.size());
  for (std::size_t a = 0; a < nodes.size(); ++a) c[a] = std::tanh(distance(nodes.point(a)[0], nodes.point(a)[1]) / (std::numbers::sqrt2 * eps));
  return c;
}

LevelSetTopology lme_topology(const Profile& distance) {
  const NodeSet nodes = half_plane_grid(0.04);
  const BackgroundCells cells = delaunay(nodes);
  LmeOptions lme;
  lme.mirrors = {MirrorPlane{0, 0.0}};  // the axisymmetric basis, mirrored across r = 0
  return problems::field_topology(MPI_COMM_WORLD, nodes, cells, tanh_profile(nodes, distance, 0.05), 0.8, lme, LevelSetGeometry::axisymmetric);
}

const Profile sphere = [](double r, double z) { return 0.3 - std::hypot(r, z - 0.6); };
const Profile torus = [](double r, double z) { return 0.12 - std::hypot(r - 0.35, z - 0.6); };
const Profile two_spheres = [](double r, double z) { return std::max(0.18 - std::hypot(r, z - 0.35), 0.18 - std::hypot(r, z - 0.85)); };

TEST(MembraneTopology, TanhProfilesOfASphereATorusAndTwoSpheres) {
  EXPECT_EQ(lme_topology(sphere).describe(), "1 component, genus 0 (a sphere)");
  EXPECT_EQ(lme_topology(torus).describe(), "1 component, genus 1 (a torus)");
  EXPECT_EQ(lme_topology(two_spheres).describe(), "2 components, genus 0, 0 (2 spheres)");
  // The level set is that of the LME field, not of its coefficients: at the torus' outer equator
  // the crossing lies within one spacing of the sharp radius 0.47.
  const LevelSetTopology t = lme_topology(torus);
  EXPECT_NEAR(t.components[0].hi[0], 0.47, 0.04);
  EXPECT_NEAR(t.components[0].lo[0], 0.23, 0.04);
}

TEST(MembraneTopology, AChangeFromTheStartIsWarnedOfAndNamed) {
  const LevelSetTopology s = lme_topology(sphere), t = lme_topology(torus), two = lme_topology(two_spheres);
  EXPECT_EQ(problems::topology_change_warning(s, s, "stage 2"), "");
  EXPECT_EQ(problems::topology_change_warning(s, lme_topology(sphere), "stage 2"), "");
  EXPECT_EQ(problems::topology_change_warning(s, t, "stage 3"),
            "the membrane's topology changed at stage 3: 1 component, genus 0 (a sphere) -> 1 component, genus 1 (a torus)");
  EXPECT_EQ(problems::topology_change_warning(s, two, "step 40"),
            "the membrane's topology changed at step 40: 1 component, genus 0 (a sphere) -> 2 components, genus 0, 0 (2 spheres)");
}

TEST(MembraneTopology, JsonNamesComponentsAndGenusAndReadsBack) {
  const LevelSetTopology t = lme_topology(two_spheres);
  const nlohmann::json js = problems::topology_json(t);
  EXPECT_EQ(js["components"], 2);
  EXPECT_EQ(js["genus"], nlohmann::json::array({0, 0}));
  EXPECT_EQ(js["closed"], nlohmann::json::array({true, true}));
  EXPECT_EQ(js["summary"], "2 components, genus 0, 0 (2 spheres)");
  EXPECT_TRUE(problems::topology_from_json(js, LevelSetGeometry::axisymmetric).same_as(t));
  EXPECT_FALSE(problems::topology_from_json(problems::topology_json(lme_topology(torus)), LevelSetGeometry::axisymmetric).same_as(t));
}

/// A uniform grid over [0, L]^dim with n intervals per side.
NodeSet corner_grid(int dim, double L, int n) {
  std::vector<double> coords;
  const int nz = dim == 3 ? n : 0;
  for (int k = 0; k <= nz; ++k)
    for (int j = 0; j <= n; ++j)
      for (int i = 0; i <= n; ++i) {
        coords.push_back(L * i / n);
        coords.push_back(L * j / n);
        if (dim == 3) coords.push_back(L * k / n);
      }
  return NodeSet(dim, coords);
}

std::vector<double> sampled(const NodeSet& nodes, const std::function<double(std::span<const double>)>& f) {
  std::vector<double> v(nodes.size());
  for (std::size_t a = 0; a < nodes.size(); ++a) v[a] = f(nodes.point(a));
  return v;
}

// One part of a symmetric body: the level set in the part has boundary on the planes; with its
// mirror images it is the closed surface of the whole.
TEST(MembraneTopology, APartOfASymmetricBodyIsCountedWithItsImages) {
  const NodeSet octant = corner_grid(3, 0.8, 12);
  const std::vector<MirrorPlane> planes = {{0, 0.0}, {1, 0.0}, {2, 0.0}};
  const auto topology = [&](const std::function<double(std::span<const double>)>& f, std::span<const MirrorPlane> p) {
    return problems::symmetric_level_set_topology(octant, sampled(octant, f), p, LevelSetGeometry::spatial).describe();
  };
  const auto centred_sphere = [](std::span<const double> x) { return 0.5 - std::hypot(x[0], x[1], x[2]); };
  const auto flat_torus = [](std::span<const double> x) { return 0.16 - std::hypot(std::hypot(x[0], x[1]) - 0.45, x[2]); };
  const auto sphere_pair = [](std::span<const double> x) { return 0.22 - std::hypot(x[0] - 0.45, x[1], x[2]); };
  const auto off_plane = [](std::span<const double> x) { return 0.2 - std::hypot(x[0] - 0.4, x[1] - 0.4, x[2] - 0.4); };
  EXPECT_EQ(topology(centred_sphere, planes), "1 component, genus 0 (a sphere)");
  EXPECT_EQ(topology(flat_torus, planes), "1 component, genus 1 (a torus)");
  EXPECT_EQ(topology(sphere_pair, planes), "2 components, genus 0, 0 (2 spheres)");
  EXPECT_EQ(topology(off_plane, planes), "8 components, genus 0, 0, 0, 0, 0, 0, 0, 0 (8 spheres)");
  // The torus mirrored across z = 0 only is a quarter of it cut by the planes x = 0 and y = 0: open.
  EXPECT_EQ(topology(flat_torus, std::span(planes).subspan(2)).find("1 component"), 0u);
  EXPECT_EQ(problems::symmetric_level_set_topology(octant, sampled(octant, flat_torus), std::span(planes).subspan(2), LevelSetGeometry::spatial)
                .components[0]
                .closed,
            false);

  // A meridian half-plane mirrored across z = 0 (an equatorial plane): a sphere and a torus.
  const NodeSet quarter = corner_grid(2, 0.8, 20);
  const std::vector<MirrorPlane> equator = {{1, 0.0}};
  const auto meridian = [&](const Profile& d) {
    return problems::symmetric_level_set_topology(quarter, sampled(quarter, [&](std::span<const double> x) { return d(x[0], x[1]); }), equator,
                                                  LevelSetGeometry::axisymmetric)
        .describe();
  };
  EXPECT_EQ(meridian([](double r, double z) { return 0.5 - std::hypot(r, z); }), "1 component, genus 0 (a sphere)");
  EXPECT_EQ(meridian([](double r, double z) { return 0.12 - std::hypot(r - 0.4, z); }), "1 component, genus 1 (a torus)");
  // Planar: a quadrant of a circle.
  const std::vector<MirrorPlane> two = {{0, 0.0}, {1, 0.0}};
  EXPECT_EQ(problems::symmetric_level_set_topology(quarter, sampled(quarter, [](std::span<const double> x) { return 0.5 - std::hypot(x[0], x[1]); }),
                                                   two, LevelSetGeometry::planar)
                .describe(),
            "1 closed curve");
  EXPECT_THROW((void)problems::symmetric_level_set_topology(quarter, std::vector<double>(3, 1.0), two, LevelSetGeometry::planar),
               std::invalid_argument);
  EXPECT_THROW((void)problems::symmetric_level_set_topology(quarter, sampled(quarter, centred_sphere), planes, LevelSetGeometry::planar),
               std::invalid_argument);
}

// A vesicle solved on a quadrant of its domain reports the topology of the whole membrane.
TEST(MembraneTopology, AVesicleOnAQuadrantReportsTheWholeMembrane) {
  const std::string text =
      "[scene]\nname = \"quadrant\"\ncoordinates = \"cartesian\"\n"
      "[domain]\nlower = [0.0, 0.0]\nupper = [1.0, 1.0]\nmirror = [\"x_min\", \"y_min\"]\n"
      "[nodes]\ncounts = [21, 21]\n"
      "[model]\nforms = [\"helfrich\", \"area\", \"volume\"]\n"
      "[constants]\neps = 0.1\n"
      "[constraints]\narea = {}\nvolume = {}\n"
      "[[dirichlet]]\nboundary = [\"x_max\", \"y_max\"]\nunknown = \"phi\"\nvalue = -1.0\n"
      "[solver]\naugmented_tolerance = 1e-2\n"
      "[vesicle]\nradius = 0.5\nreduced_volume = 0.9\n"
      "[vesicle.initial]\nshape = \"ellipsoid\"\ncenter = [0.0, 0.0]\nsemi_axes = [0.6, 0.4]\n";
  const Scene scene = parse_scene(text, "quadrant.toml", problems::driver_tables());
  const problems::VesicleRun run = problems::run_vesicle(PETSC_COMM_SELF, scene, *problems::read_vesicle(scene), nullptr);
  ASSERT_TRUE(run.initial_topology.has_value());
  EXPECT_EQ(run.initial_topology->describe(), "1 closed curve");
  ASSERT_EQ(run.stages.size(), 1u);
  ASSERT_TRUE(run.stages[0].topology.has_value());
  EXPECT_EQ(run.stages[0].topology->describe(), "1 closed curve");
  EXPECT_GT(run.stages[0].peak_rss_mb, 1.0);  // the process' peak, MPI and PETSc included
  EXPECT_TRUE(run.warnings.empty());
  EXPECT_TRUE(run.failure.empty()) << run.failure;
}

/// A small vesicle whose start is a torus with a hole narrower than the interface width: the
/// phase field closes it (a sphere bends less than any torus).
Scene torus_start(bool guard, const std::string& schedule = "") {
  const std::string text =
      "[scene]\nname = \"hole\"\ncoordinates = \"axisymmetric\"\n"
      "[domain]\nlower = [0.0, 0.0]\nupper = [1.0, 1.2]\n"
      "[nodes]\nspacing = 0.06\n"
      "[model]\nforms = [\"helfrich_axisymmetric\", \"area_axisymmetric\", \"volume_axisymmetric\"]\n"
      "[constants]\neps = 0.14\n"
      "[constraints]\narea = {}\nvolume = {}\n"
      "[[dirichlet]]\nboundary = [\"r_max\", \"z_min\", \"z_max\"]\nunknown = \"phi\"\nvalue = -1.0\n"
      "[solver]\naugmented_tolerance = 1e-2\n"
      "[initial]\nphi = \"tanh((0.22 - sqrt((x[0] - 0.3)^2 + (x[1] - 0.6)^2)) / (sqrt(2) * eps))\"\n"
      "[vesicle]\nradius = 0.35\nreduced_volume = 0.9\n" +
      std::string(guard ? "topology_guard = true\n" : "") + schedule;
  return parse_scene(text, "hole.toml", problems::driver_tables());
}

TEST(MembraneTopology, AVesicleWhoseHoleClosesIsWarnedOfAndTheGuardStopsIt) {
  const Scene warned = torus_start(false);
  const problems::VesicleRun run = problems::run_vesicle(PETSC_COMM_SELF, warned, *problems::read_vesicle(warned), nullptr);
  ASSERT_TRUE(run.initial_topology.has_value());
  EXPECT_EQ(run.initial_topology->describe(), "1 component, genus 1 (a torus)");
  ASSERT_EQ(run.stages.size(), 1u);
  ASSERT_TRUE(run.stages[0].topology.has_value());
  EXPECT_EQ(run.stages[0].topology->describe(), "1 component, genus 0 (a sphere)");
  ASSERT_EQ(run.warnings.size(), 1u);
  EXPECT_NE(run.warnings[0].find("the membrane's topology changed at stage 0: 1 component, genus 1 (a torus) -> 1 component, genus 0 (a sphere)"),
            std::string::npos)
      << run.warnings[0];
  EXPECT_TRUE(run.failure.empty()) << run.failure;

  const Scene guarded = torus_start(true);
  const problems::VesicleRun stopped = problems::run_vesicle(PETSC_COMM_SELF, guarded, *problems::read_vesicle(guarded), nullptr);
  EXPECT_TRUE(stopped.stages.empty());
  ASSERT_TRUE(stopped.rejected.has_value());
  EXPECT_EQ(stopped.rejected->result.energy, run.stages[0].result.energy);
  EXPECT_NE(stopped.failure.find("stage 0: the membrane's topology changed"), std::string::npos) << stopped.failure;
  EXPECT_NE(stopped.failure.find("vesicle.topology_guard"), std::string::npos) << stopped.failure;
}

// The warning of a stage before a stop is in the report of the run resumed after it.
TEST(MembraneTopology, AWarningBeforeARestartIsReportedAfterIt) {
  const std::filesystem::path dir = std::filesystem::temp_directory_path() / "lmeform_topology_restart";
  std::filesystem::remove_all(dir);
  std::filesystem::create_directories(dir);
  const Scene first = torus_start(false);
  const problems::VesicleCheckpoint written{dir, first.name, false};
  const problems::VesicleRun stopped = problems::run_vesicle(PETSC_COMM_SELF, first, *problems::read_vesicle(first), nullptr, &written);
  ASSERT_EQ(stopped.warnings.size(), 1u);
  const Scene whole = torus_start(false, "[vesicle.adaptivity]\nstages = [ { eps = 0.14, f = 3.0 } ]\n");
  const problems::VesicleCheckpoint resume{dir, whole.name, true};
  const problems::VesicleRun resumed = problems::run_vesicle(PETSC_COMM_SELF, whole, *problems::read_vesicle(whole), nullptr, &resume);
  ASSERT_EQ(resumed.stages.size(), 2u);
  EXPECT_TRUE(resumed.failure.empty()) << resumed.failure;
  ASSERT_FALSE(resumed.warnings.empty());
  EXPECT_EQ(resumed.warnings[0], stopped.warnings[0]);
  std::filesystem::remove_all(dir);
}

}  // namespace
}  // namespace lmeform
