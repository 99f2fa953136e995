// The stage loop of `lmeform run`: a scene's solve on its node set, then each adaptivity stage
// (CVT relocation, resolution check, continuation from the previous stage). Shared by the
// command and the statics benchmark, so both measure the same thing.
#pragma once

#include <mpi.h>

#include <ostream>
#include <string>
#include <vector>

#include "lmeform/scene.hpp"
#include "vesicle.hpp"

namespace lmeform::app {

struct StageRecord {
  int stage = 0;
  double eps = 0;
  std::string grid;    ///< "uniform" / "file", then "cvt-1", "cvt-2", ... per relocation
  int generation = 0;  ///< relocations along the chain of stages that led here
  std::string label;   ///< " (branch)" for a side solve
  int nodes = 0;
  double h_min = 0;    ///< SpacingSummary::h_min of the stage's grid
  VesicleResult result;
  double wall_s = 0;   ///< this stage: relocation + setup + solve
  double adapt_s = 0;  ///< of which the relocation
};

struct SceneRun {
  std::vector<StageRecord> stages;  ///< the finished stages, in order
  /// Empty when every stage ran; else "stage k: <why>" for the stage that could not run (an
  /// under-resolved eps, an LME evaluation or a linear solve that failed). A stage whose
  /// minimizer did not converge is the last one, with its result's message.
  std::string failure;
  double wall_s = 0;                ///< the whole run, node set generation included
};

/// Throws SceneError for a scene this runner cannot solve (not axisymmetric, another energy).
void check_runnable(const Scene& scene);

/// Runs an axisymmetric scene (model.form helfrich_axisymmetric). Collective over `comm`;
/// progress lines to `log` (nullptr: silent). Throws if not even the first stage finishes.
[[nodiscard]] SceneRun run_scene(MPI_Comm comm, const Scene& scene, std::ostream* log);

/// The scene's initial node set (uniform grid, uniform CVT of a node count, or a point file).
[[nodiscard]] NodeSet initial_nodes(const Scene& scene, std::ostream* log = nullptr);

/// The solve of `scene` at `eps` on `nodes`, from the scene's initial field.
[[nodiscard]] VesicleSetup setup_from(const Scene& scene, const NodeSet& nodes, double eps);

}  // namespace lmeform::app
