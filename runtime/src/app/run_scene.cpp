#include "run_scene.hpp"

#include <chrono>
#include <optional>
#include <utility>

#include <fmt/format.h>

#include "lmeform/cvt.hpp"
#include "lmeform/node_sets.hpp"
#include "dynamics.hpp"
#include "vesicle.hpp"

namespace lmeform::app {

std::span<const std::string_view> model_extensions() {
  static const std::string_view extensions[] = {kVesicleExtension, kDynamicsExtension};
  return extensions;
}

namespace {

double seconds_since(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

}  // namespace

SceneRun run_scene(MPI_Comm comm, const Scene& scene, std::ostream* log) {
  const auto t_start = std::chrono::steady_clock::now();
  if (const std::optional<VesicleModel> vesicle = read_vesicle(scene)) return run_vesicle(comm, scene, *vesicle, log);
  const BoundScene bound = bind_scene(scene, comm, log);
  SceneRun run;
  StageRecord rec;
  rec.grid = scene.nodes.kind == SceneNodes::Kind::file ? "file" : "uniform";
  ProblemInput input;
  input.nodes = initial_nodes(scene, log);
  input.log = log;
  input.lme.spacing_smoothing = scene.nodes.spacing_smoothing;
  if (scene.axisymmetric()) {
    input.lme.mirror_axis = 0;  // axisymmetric fields are even in r: no hull boundary on the axis
    input.lme.mirror_position = 0.0;
  }
  rec.h_min = spacing_summary(input.nodes).h_min;
  rec.nodes = static_cast<int>(input.nodes.size());
  if (log != nullptr) *log << "== solve: " << rec.nodes << " nodes, h_min " << rec.h_min << "\n";
  rec.result = solve_problem(comm, bound, input);
  rec.wall_s = seconds_since(t_start);
  run.stages.push_back(std::move(rec));
  run.unknowns = bound.unknowns;
  run.wall_s = seconds_since(t_start);
  return run;
}

}  // namespace lmeform::app
