// A vesicle schedule writes a checkpoint after every converged stage and resumes from it: the
// resumed schedule ends where the uninterrupted one does, and a checkpoint that is missing, finished
// or written for another schedule is refused by name.
#include <gtest/gtest.h>

#include <filesystem>
#include <string>

#include "problem_registry.hpp"
#include "vesicle.hpp"
#include "vesicle_checkpoint.hpp"

namespace lmeform {
namespace {

namespace fs = std::filesystem;

/// A quadrant of an elliptic vesicle (two planes of symmetry), eps0 at the start, then CVT
/// relocations at eps = 0.1, `stages` of them.
Scene quadrant(int stages, double eps0 = 0.1) {
  std::string schedule;
  for (int k = 0; k < stages; ++k) schedule += std::string(k == 0 ? "" : ", ") + "{ eps = 0.1, f = 3 }";
  const std::string text = "[scene]\nname = \"quadrant\"\ncoordinates = \"cartesian\"\n"
                           "[domain]\nlower = [0.0, 0.0]\nupper = [1.0, 1.0]\nmirror = [\"x_min\", \"y_min\"]\n"
                           "[nodes]\ncounts = [21, 21]\n"
                           "[model]\nforms = [\"helfrich\", \"area\", \"volume\"]\n"
                           "[constants]\neps = " + std::to_string(eps0) + "\n"
                           "[constraints]\narea = {}\nvolume = {}\n"
                           "[[dirichlet]]\nboundary = [\"x_max\", \"y_max\"]\nunknown = \"phi\"\nvalue = -1.0\n"
                           "[vesicle]\nradius = 0.5\nreduced_volume = 0.9\n"
                           "[vesicle.initial]\nshape = \"ellipsoid\"\ncenter = [0.0, 0.0]\nsemi_axes = [0.6, 0.4]\n"
                           "[vesicle.adaptivity]\nstages = [" + schedule + "]\n";
  return parse_scene(text, "quadrant.toml", problems::driver_tables());
}

problems::VesicleRun run(const Scene& scene, const fs::path& dir, bool restart) {
  const problems::VesicleCheckpoint checkpoint{dir, scene.name, restart};
  return problems::run_vesicle(PETSC_COMM_SELF, scene, *problems::read_vesicle(scene), nullptr, &checkpoint);
}

std::string failure_of(const Scene& scene, const fs::path& dir) {
  try {
    (void)run(scene, dir, true);
  } catch (const std::exception& e) {
    return e.what();
  }
  return "";
}

TEST(VesicleCheckpoint, AResumedScheduleEndsWhereTheUninterruptedOneDoes) {
  const fs::path dir = fs::temp_directory_path() / "lmeform_vesicle_checkpoint";
  fs::remove_all(dir);
  fs::create_directories(dir / "whole");
  fs::create_directories(dir / "cut");
  const problems::VesicleRun whole = run(quadrant(2), dir / "whole", false);
  ASSERT_EQ(whole.stages.size(), 3u);
  ASSERT_TRUE(whole.failure.empty()) << whole.failure;
  EXPECT_TRUE(fs::exists(dir / "whole" / "quadrant_stage_2.h5"));

  // Interrupted after stage 1 (a schedule one stage shorter), then resumed with the full one.
  const problems::VesicleRun first = run(quadrant(1), dir / "cut", false);
  ASSERT_EQ(first.stages.size(), 2u);
  const problems::VesicleRun resumed = run(quadrant(2), dir / "cut", true);
  ASSERT_EQ(resumed.stages.size(), 3u);
  EXPECT_TRUE(resumed.failure.empty()) << resumed.failure;
  for (std::size_t k = 0; k < 3; ++k) {
    EXPECT_EQ(resumed.stages[k].nodes, whole.stages[k].nodes);
    EXPECT_NEAR(resumed.stages[k].result.energy, whole.stages[k].result.energy, 1e-12 * whole.stages[k].result.energy) << "stage " << k;
    EXPECT_EQ(resumed.stages[k].result.minimization.newton_iterations, whole.stages[k].result.minimization.newton_iterations);
  }
  // The resumed stage ran on the nodes the uninterrupted run relocated: its state is the same.
  ASSERT_EQ(resumed.stages[2].result.state.size(), whole.stages[2].result.state.size());
  for (std::size_t a = 0; a < whole.stages[2].result.state.size(); ++a)
    ASSERT_NEAR(resumed.stages[2].result.state[a], whole.stages[2].result.state[a], 1e-9) << "node " << a;
  ASSERT_TRUE(resumed.initial_topology && resumed.stages[1].topology);
  EXPECT_EQ(resumed.initial_topology->describe(), "1 closed curve");

  EXPECT_NE(failure_of(quadrant(2), dir / "nowhere").find("no checkpoint in"), std::string::npos);
  EXPECT_NE(failure_of(quadrant(2), dir / "whole").find("nothing to resume"), std::string::npos);
  EXPECT_NE(failure_of(quadrant(3, 0.12), dir / "cut").find("another schedule"), std::string::npos);
  // A folder that cannot take the checkpoint costs the restart, not the run: a warning.
  const problems::VesicleRun unwritten = run(quadrant(1), dir / "missing_folder", false);
  EXPECT_TRUE(unwritten.failure.empty()) << unwritten.failure;
  ASSERT_EQ(unwritten.stages.size(), 2u);
  ASSERT_EQ(unwritten.warnings.size(), 2u);
  EXPECT_NE(unwritten.warnings[0].find("no checkpoint after stage 0"), std::string::npos) << unwritten.warnings[0];
  fs::remove_all(dir);
}

}  // namespace
}  // namespace lmeform
