// The run of a scene: bind it to its forms, then one solve on the scene's node set, or, for a
// model with a schedule of its own (the phase-field vesicle's adaptivity), one solve per stage.
// Shared by `lmeform run` and the statics benchmark, so both measure the same thing.
#pragma once

#include <mpi.h>

#include <optional>
#include <ostream>
#include <string>
#include <vector>

#include "lmeform/scene.hpp"
#include "problem.hpp"
#include "vesicle.hpp"

namespace lmeform::app {

struct StageRecord {
  int stage = 0;
  double eps = 0;      ///< the vesicle's interface width (0 for other models)
  std::string grid;    ///< "uniform" / "file", then "cvt-1", "cvt-2", ... per relocation
  int generation = 0;  ///< relocations along the chain of stages that led here
  std::string label;   ///< " (branch)" for a side solve
  int nodes = 0;
  double h_min = 0;    ///< SpacingSummary::h_min of the stage's grid
  ProblemResult result;
  double wall_s = 0;   ///< this stage: relocation + setup + solve
  double adapt_s = 0;  ///< of which the relocation
};

struct SceneRun {
  std::vector<StageRecord> stages;  ///< the finished stages, in order
  /// Empty when every stage ran; else "stage k: <why>" for the stage that could not run. A stage
  /// whose solver did not converge is the last one, with its result's message.
  std::string failure;
  double wall_s = 0;                ///< the whole run, node set generation included
  std::optional<VesicleModel> vesicle;
  std::vector<UnknownField> unknowns;  ///< the layout of every stage's state
};

/// The extension tables the models of `lmeform run` read (pass to load_scene).
[[nodiscard]] std::span<const std::string_view> model_extensions();

/// Loads, binds and runs a scene. Collective over `comm`; progress lines to `log` (nullptr: silent).
/// Throws SceneError / FormLoadError for a scene that cannot run, or if not even the first stage finishes.
[[nodiscard]] SceneRun run_scene(MPI_Comm comm, const Scene& scene, std::ostream* log);

}  // namespace lmeform::app
