#include "run_scene.hpp"

#include <chrono>
#include <stdexcept>
#include <string>
#include <utility>

#include "lmeform/cvt.hpp"
#include "lmeform/node_sets.hpp"

namespace lmeform::app {

NodeSet initial_nodes(const Scene& scene, std::ostream* log) {
  switch (scene.nodes.kind) {
    case SceneNodes::Kind::spacing: return uniform_grid(scene.domain, scene.nodes.spacing);
    case SceneNodes::Kind::counts: return uniform_grid(scene.domain, scene.nodes.counts);
    case SceneNodes::Kind::count: {
      const auto t0 = std::chrono::steady_clock::now();
      CvtOptions cvt;
      cvt.iterations = scene.nodes.lloyd_iterations;
      CvtReport report;
      NodeSet nodes = uniform_cvt(scene.domain, static_cast<std::size_t>(scene.nodes.count), cvt, &report);
      if (log != nullptr) {
        *log << "uniform CVT of " << nodes.size() << " nodes: " << report.iterations.size() << " Lloyd iterations"
             << (report.iterations.empty() ? std::string()
                                           : ", last mean move " + std::to_string(report.iterations.back().mean_displacement / report.h_bar) + " h")
             << ", " << std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count() << " s\n";
      }
      return nodes;
    }
    case SceneNodes::Kind::file: return read_points(scene.nodes.file, scene.dim());
  }
  throw std::logic_error("unknown node kind");
}

VesicleSetup setup_from(const Scene& scene, const NodeSet& nodes, double eps) {
  VesicleSetup s;
  s.lower = {scene.domain.lo[0], scene.domain.lo[1]};
  s.upper = {scene.domain.hi[0], scene.domain.hi[1]};
  s.nodes = nodes;
  s.gamma = scene.nodes.gamma;
  s.spacing_smoothing = scene.nodes.spacing_smoothing;
  s.quadrature_points = scene.nodes.quadrature_points;
  s.k = scene.model.k;
  s.eps = eps;
  s.C0 = scene.model.C0;
  s.area_target = scene.constraints.area;
  s.volume_target = scene.constraints.volume;
  if (scene.constraints.moment) {
    s.moment_target = scene.constraints.moment->target;
    s.z_center = scene.constraints.moment->z_center;
  } else {
    s.z_center = scene.initial.center[1];
  }
  s.initial_phi.resize(nodes.size());
  for (std::size_t a = 0; a < nodes.size(); ++a) s.initial_phi[a] = scene.initial_phi(nodes.point(a));
  s.solver.penalty = scene.solver.penalty;
  s.solver.augmented_tolerance = scene.solver.augmented_tolerance;
  s.solver.inner_tolerance = scene.solver.inner_tolerance;
  s.solver.max_outer_iterations = scene.solver.max_outer_iterations;
  s.solver.max_inner_iterations = scene.solver.max_inner_iterations;
  s.solver.newton_tolerance = scene.solver.newton_tolerance;
  s.solver.constraint_tolerance = scene.solver.constraint_tolerance;
  s.solver.max_newton_iterations = scene.solver.max_newton_iterations;
  return s;
}

void check_runnable(const Scene& scene) {
  if (!scene.axisymmetric() || scene.dim() != 2) {
    throw SceneError(scene.source + ": coordinates = \"" + to_string(scene.coordinates) +
                     "\" is accepted by the scene format, but lmeform run solves axisymmetric (r, z) vesicles only so far");
  }
  if (scene.model.form != "helfrich_axisymmetric") {
    throw SceneError(scene.source + ": model.form = \"" + scene.model.form +
                     "\": lmeform run knows the energy \"helfrich_axisymmetric\" only");
  }
}

namespace {

// One stage: the relocation (if any), the resolution check and the solve, starting from stage
// `from` of `stages` (none for stage 0). Throws when the stage cannot run.
StageRecord run_stage(MPI_Comm comm, const Scene& scene, std::ostream* log, int stage,
                      const std::vector<StageRecord>& stages, std::size_t main_stage, NodeSet& nodes) {
  StageRecord rec;
  const auto t0 = std::chrono::steady_clock::now();
  rec.eps = stage == 0 ? scene.model.eps : scene.adaptivity->stages[static_cast<std::size_t>(stage - 1)].eps;
  // Grids are named by generation: the scene's node set, then cvt-1, cvt-2, ... for each
  // relocation along the chain; a stage without relocation keeps its grid.
  rec.grid = scene.nodes.kind == SceneNodes::Kind::file ? "file" : "uniform";
  std::size_t from = 0;  // the finished stage this one starts from
  if (stage > 0) {
    const auto& st = scene.adaptivity->stages[static_cast<std::size_t>(stage - 1)];
    from = st.branch ? stages.size() - 1 : main_stage;
    nodes = stages[from].result.nodes;
    rec.generation = stages[from].generation + (st.lloyd_iterations > 0 ? 1 : 0);
    rec.grid = rec.generation == 0 ? stages[from].grid : "cvt-" + std::to_string(rec.generation);
    if (st.branch) rec.label = " (branch)";
    if (st.lloyd_iterations > 0) {
      CvtOptions cvt;
      cvt.iterations = st.lloyd_iterations;
      cvt.start = scene.adaptivity->start_from_density ? CvtStart::density : CvtStart::given;
      cvt.samples_per_node = scene.adaptivity->samples_per_node;
      CvtReport report;
      nodes = adapt_nodes(stages[from].result, {scene.domain.lo[0], scene.domain.lo[1]},
                          {scene.domain.hi[0], scene.domain.hi[1]}, st.f, cvt, &report);
      if (log != nullptr) {
        *log << "CVT with rho = 1 + " << st.f << " |grad phi|: " << report.iterations.size() << " Lloyd iterations"
             << (cvt.start == CvtStart::density ? " from the density's node placement" : " from the current nodes")
             << ", " << report.samples
             << (cvt.centroids == CvtCentroids::voronoi ? " density evaluations per iteration\n" : " samples\n");
      }
    }
    rec.adapt_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  }
  const SpacingSummary spacing = spacing_summary(nodes);
  rec.h_min = spacing.h_min;
  // An under-resolved interface is refused before any work (seed App. B: ε ≥ 2 h_min).
  check_resolution(rec.eps, spacing, scene.nodes.resolution_factor, rec.grid + " grid");
  rec.stage = stage;
  VesicleSetup setup = setup_from(scene, nodes, rec.eps);
  if (stage > 0) {
    // The previous field: as it is on the same grid (LME is not interpolating, so evaluating it at
    // its own nodes would smooth it), evaluated at the new nodes after a relocation.
    const auto& st = scene.adaptivity->stages[static_cast<std::size_t>(stage - 1)];
    setup.initial_phi = st.lloyd_iterations == 0
                            ? stages[from].result.phi
                            : transfer_phi(stages[from].result.nodes, stages[from].result.phi, scene.nodes.gamma,
                                           scene.nodes.spacing_smoothing, nodes);
    // A narrower interface: start from the same level sets with the new width.
    if (rec.eps < stages[from].eps) setup.initial_phi = rescale_interface(setup.initial_phi, stages[from].eps, rec.eps);
    // The multipliers (tension, pressure) change little between stages: start from the last ones.
    if (stages[from].result.solve.converged) setup.initial_multipliers = stages[from].result.solve.multipliers;
  }
  setup.solver.log = log;
  if (log != nullptr) {
    *log << "== stage " << stage << " (" << rec.grid << rec.label << "): " << nodes.size() << " nodes, eps " << rec.eps
         << ", h_min " << rec.h_min << "\n";
  }
  rec.result = solve_vesicle(comm, setup);
  rec.nodes = rec.result.nodes_count;
  rec.wall_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  return rec;
}

}  // namespace

SceneRun run_scene(MPI_Comm comm, const Scene& scene, std::ostream* log) {
  const auto t_start = std::chrono::steady_clock::now();
  check_runnable(scene);
  SceneRun run;
  std::vector<StageRecord>& stages = run.stages;
  std::string& failure = run.failure;
  // The schedule: the scene's ε on the initial grid, then each adaptivity stage.
  NodeSet nodes = initial_nodes(scene, log);
  // A stage continues from the previous one, except that a stage which is not a branch continues
  // from the last stage that is not one (AdaptivityStage::branch).
  std::size_t main_stage = 0;
  const int n_stages = 1 + (scene.adaptivity ? static_cast<int>(scene.adaptivity->stages.size()) : 0);
  for (int stage = 0; stage < n_stages; ++stage) {
    try {
      stages.push_back(run_stage(comm, scene, log, stage, stages, main_stage, nodes));
    } catch (const std::exception& e) {
      if (stages.empty()) throw;  // nothing to write
      failure = "stage " + std::to_string(stage) + ": " + e.what();
      if (log != nullptr) *log << "lmeform: " << failure << "\nlmeform: writing the last finished stage\n";
      break;
    }
    const bool branch = stage > 0 && scene.adaptivity->stages[static_cast<std::size_t>(stage - 1)].branch;
    if (!branch) main_stage = stages.size() - 1;
    if (!stages.back().result.solve.converged) break;
  }

  run.wall_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t_start).count();
  return run;
}

}  // namespace lmeform::app
