// The run of a scene: a model that owns an extension table of the scene runs it (its schedule of
// stages); otherwise the scene is bound to its forms and solved once on its node set.
// Shared by `lmeform run` and the statics benchmark, so both measure the same thing.
#pragma once

#include <mpi.h>

#include <ostream>
#include <string>
#include <vector>

#include "lmeform/scene.hpp"
#include "problem.hpp"

namespace lmeform::app {

/// The extension tables the models of `lmeform run` read (pass to load_scene).
[[nodiscard]] std::span<const std::string_view> model_extensions();

/// Loads, binds and runs a scene. Collective over `comm`; progress lines to `log` (nullptr: silent).
/// Throws SceneError / FormLoadError for a scene that cannot run, or if not even the first stage finishes.
[[nodiscard]] SceneRun run_scene(MPI_Comm comm, const Scene& scene, std::ostream* log);

}  // namespace lmeform::app
