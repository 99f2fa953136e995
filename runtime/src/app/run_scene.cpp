#include "run_scene.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <stdexcept>
#include <string>
#include <utility>

#include <fmt/format.h>

#include "lmeform/cvt.hpp"
#include "lmeform/node_sets.hpp"

namespace lmeform::app {

std::span<const std::string_view> model_extensions() {
  static const std::string_view extensions[] = {kVesicleExtension};
  return extensions;
}

namespace {

double seconds_since(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

/// One stage of the vesicle schedule: the relocation (if any), the resolution check and the solve,
/// starting from stage `from` of `stages` (none for stage 0). Throws when the stage cannot run.
StageRecord run_vesicle_stage(MPI_Comm comm, const BoundScene& bound, const VesicleModel& model, std::ostream* log,
                              int stage, const std::vector<StageRecord>& stages, std::size_t main_stage, NodeSet& nodes) {
  const Scene& scene = *bound.scene;
  StageRecord rec;
  const auto t0 = std::chrono::steady_clock::now();
  rec.eps = stage == 0 ? model.eps : model.adaptivity->stages[static_cast<std::size_t>(stage - 1)].eps;
  rec.grid = scene.nodes.kind == SceneNodes::Kind::file ? "file" : "uniform";
  const LmeOptions lme = vesicle_lme_options(scene);
  std::size_t from = 0;
  if (stage > 0) {
    const auto& st = model.adaptivity->stages[static_cast<std::size_t>(stage - 1)];
    from = st.branch ? stages.size() - 1 : main_stage;
    nodes = stages[from].result.nodes;
    rec.generation = stages[from].generation + (st.lloyd_iterations > 0 ? 1 : 0);
    rec.grid = rec.generation == 0 ? stages[from].grid : "cvt-" + std::to_string(rec.generation);
    if (st.branch) rec.label = " (branch)";
    if (st.lloyd_iterations > 0) {
      CvtOptions cvt;
      cvt.iterations = st.lloyd_iterations;
      cvt.start = model.adaptivity->start_from_density ? CvtStart::density : CvtStart::given;
      cvt.samples_per_node = model.adaptivity->samples_per_node;
      CvtReport report;
      nodes = adapt_nodes(stages[from].result, scene.domain, st.f, cvt, &report);
      if (log != nullptr) {
        *log << "CVT with rho = 1 + " << st.f << " |grad phi|: " << report.iterations.size() << " Lloyd iterations"
             << (cvt.start == CvtStart::density ? " from the density's node placement" : " from the current nodes")
             << ", " << report.samples
             << (cvt.centroids == CvtCentroids::voronoi ? " density evaluations per iteration\n" : " samples\n");
      }
    }
    rec.adapt_s = seconds_since(t0);
  }
  const SpacingSummary spacing = spacing_summary(nodes);
  rec.h_min = spacing.h_min;
  // An under-resolved interface is refused before any work (seed App. B: ε ≥ 2 h_min).
  check_resolution(rec.eps, spacing, model.resolution_factor, rec.grid + " grid");
  rec.stage = stage;

  ProblemInput input;
  input.nodes = nodes;
  input.lme = lme;
  input.log = log;
  input.constants[model.width] = rec.eps;
  if (stage == 0) {
    input.initial = initial_state(bound, nodes);
    const bool given = std::any_of(scene.initial.begin(), scene.initial.end(),
                                   [&](const SceneInitialField& f) { return f.unknown == model.field; });
    if (!given)
      for (std::size_t a = 0; a < nodes.size(); ++a) input.initial[a] = initial_profile(model, nodes.point(a), scene.dim());
  } else {
    // The previous field: as it is on the same grid (LME is not interpolating, so evaluating it at
    // its own nodes would smooth it), evaluated at the new nodes after a relocation.
    const auto& st = model.adaptivity->stages[static_cast<std::size_t>(stage - 1)];
    input.initial = st.lloyd_iterations == 0
                        ? stages[from].result.state
                        : transfer_phi(stages[from].result.nodes, stages[from].result.state, scene.nodes.gamma, lme, nodes);
    // A narrower interface: start from the same level sets with the new width.
    if (rec.eps < stages[from].eps) input.initial = rescale_interface(input.initial, stages[from].eps, rec.eps);
    // The multipliers (tension, pressure) change little between stages: start from the last ones.
    if (stages[from].result.converged) input.initial_multipliers = stages[from].result.minimization.multipliers;
  }
  if (log != nullptr) {
    *log << "== stage " << stage << " (" << rec.grid << rec.label << "): " << nodes.size() << " nodes, eps " << rec.eps
         << ", h_min " << rec.h_min << "\n";
  }
  rec.result = solve_problem(comm, bound, input);
  rec.nodes = static_cast<int>(nodes.size());
  rec.wall_s = seconds_since(t0);
  return rec;
}

SceneRun run_vesicle(MPI_Comm comm, const BoundScene& bound, const VesicleModel& model, std::ostream* log) {
  const Scene& scene = *bound.scene;
  if (bound.kind != ProblemKind::minimization || bound.unknowns.size() != 1 || bound.unknowns.front().components != 1 ||
      bound.unknowns.front().name != model.field)
    throw SceneError(fmt::format("{}: [vesicle] minimizes an energy of one scalar phase field '{}'; the scene's problem "
                                 "has other unknowns",
                                 scene.source, model.field));
  SceneRun run;
  run.vesicle = model;
  NodeSet nodes = initial_nodes(scene, log);
  std::size_t main_stage = 0;
  const int n_stages = 1 + (model.adaptivity ? static_cast<int>(model.adaptivity->stages.size()) : 0);
  for (int stage = 0; stage < n_stages; ++stage) {
    try {
      run.stages.push_back(run_vesicle_stage(comm, bound, model, log, stage, run.stages, main_stage, nodes));
    } catch (const std::exception& e) {
      if (run.stages.empty()) throw;  // nothing to write
      run.failure = "stage " + std::to_string(stage) + ": " + e.what();
      if (log != nullptr) *log << "lmeform: " << run.failure << "\nlmeform: writing the last finished stage\n";
      break;
    }
    const bool branch = stage > 0 && model.adaptivity->stages[static_cast<std::size_t>(stage - 1)].branch;
    if (!branch) main_stage = run.stages.size() - 1;
    if (!run.stages.back().result.converged) break;
  }
  return run;
}

}  // namespace

SceneRun run_scene(MPI_Comm comm, const Scene& scene, std::ostream* log) {
  const auto t_start = std::chrono::steady_clock::now();
  const std::optional<VesicleModel> vesicle = read_vesicle(scene);
  // The vesicle fills in what it derives: the area and volume targets of its sphere, and the
  // moment's natural size (the volume times the vesicle's half-height, ~ V0).
  Scene completed = scene;
  std::vector<std::string> provided_constants;
  if (vesicle) {
    provided_constants = {vesicle->width};
    for (auto& c : completed.constraints) {
      if (c.name == "area" && vesicle->area) c.target = *vesicle->area;
      if (c.name == "volume" && vesicle->volume) c.target = *vesicle->volume;
      if (c.name == "moment" && vesicle->volume && !c.scale) c.scale = std::abs(*vesicle->volume);
    }
  }
  const BoundScene bound = bind_scene(completed, comm, log, provided_constants);
  SceneRun run;
  if (vesicle) {
    run = run_vesicle(comm, bound, *vesicle, log);
  } else {
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
  }
  run.unknowns = bound.unknowns;
  run.wall_s = seconds_since(t_start);
  return run;
}

}  // namespace lmeform::app
