// lmeform — run a scene.
//
//   lmeform run SCENE.toml [--json OUT.json] [--output DIR]
//
// Reads the scene, builds the node set (uniform, from a file, or adapted by CVT stages),
// minimizes the phase-field Helfrich energy under the scene's constraints, prints progress and a
// closing table, and writes HDF5 + XDMF, a PNG and (with --json) the run's figures.
#include <CLI/CLI.hpp>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <iostream>
#include <numeric>
#include <sstream>
#include <string>

#include "lmeform/cvt.hpp"
#include "lmeform/lme_basis.hpp"
#include "lmeform/node_sets.hpp"
#include "lmeform/output.hpp"
#include "lmeform/petsc.hpp"
#include "lmeform/scene.hpp"
#include "vesicle.hpp"

namespace {

using namespace lmeform;

struct StageRecord {
  double eps = 0;
  std::string grid;   ///< "uniform" / "file", then "cvt-1", "cvt-2", ... per relocation
  int generation = 0; ///< relocations along the chain of stages that led here
  int stage = 0;
  std::string label;  ///< " (branch)" for a side solve
  int nodes = 0;
  double h_min = 0;
  app::VesicleResult result;
  double wall_s = 0;
  double adapt_s = 0;
};

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

app::VesicleSetup setup_from(const Scene& scene, const NodeSet& nodes, double eps) {
  app::VesicleSetup s;
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

std::string json_number(double v) {
  if (!std::isfinite(v)) return "null";
  std::ostringstream os;
  os.precision(12);
  os << v;
  return os.str();
}

int run(const std::string& scene_path, const std::string& json_path, const std::string& output_override) {
  const int rank = PetscSession::rank();
  std::ostream* log = rank == 0 ? &std::cout : nullptr;
  const auto t_start = std::chrono::steady_clock::now();
  const Scene scene = load_scene(scene_path);
  if (!scene.axisymmetric() || scene.dim() != 2) {
    throw SceneError(scene.source + ": coordinates = \"" + to_string(scene.coordinates) +
                     "\" is accepted by the scene format, but lmeform run solves axisymmetric (r, z) vesicles only so far");
  }
  if (scene.model.form != "helfrich_axisymmetric") {
    throw SceneError(scene.source + ": model.form = \"" + scene.model.form +
                     "\": lmeform run knows the energy \"helfrich_axisymmetric\" only");
  }
  std::filesystem::path out_dir = !output_override.empty() ? std::filesystem::path(output_override)
                                  : scene.output ? scene.output->directory
                                                 : std::filesystem::path("out") / scene.name;
  const bool write_hdf5 = !scene.output || scene.output->hdf5;
  const bool write_png = !scene.output || scene.output->png;
  if (rank == 0) std::filesystem::create_directories(out_dir);

  // The schedule: the scene's ε on the initial grid, then each adaptivity stage.
  std::vector<StageRecord> stages;
  NodeSet nodes = initial_nodes(scene, log);
  // A stage continues from the previous one, except that a stage which is not a branch continues
  // from the last stage that is not one (AdaptivityStage::branch).
  std::size_t main_stage = 0;
  const int n_stages = 1 + (scene.adaptivity ? static_cast<int>(scene.adaptivity->stages.size()) : 0);
  // A stage that cannot run (an under-resolved eps on an adapted grid, an LME evaluation or a
  // linear solve that fails) ends the schedule; the last finished stage is still written.
  std::string failure;
  for (int stage = 0; stage < n_stages; ++stage) {
   try {
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
        nodes = app::adapt_nodes(stages[from].result, {scene.domain.lo[0], scene.domain.lo[1]},
                                 {scene.domain.hi[0], scene.domain.hi[1]}, st.f, cvt, &report);
        if (log != nullptr) {
          *log << "CVT with rho = 1 + " << st.f << " |grad phi|: " << report.iterations.size() << " Lloyd iterations"
               << (cvt.start == CvtStart::density ? " from the density's node placement" : " from the current nodes")
               << ", " << report.samples << (cvt.centroids == CvtCentroids::voronoi ? " density evaluations per iteration" : " samples")
               << ", h_min " << spacing_summary(nodes).h_min << "\n";
        }
      }
      rec.adapt_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    }
    const SpacingSummary spacing = spacing_summary(nodes);
    rec.h_min = spacing.h_min;
    // An under-resolved interface is refused before any work (seed App. B: ε ≥ 2 h_min).
    check_resolution(rec.eps, spacing, scene.nodes.resolution_factor, rec.grid + " grid");
    rec.stage = stage;
    app::VesicleSetup setup = setup_from(scene, nodes, rec.eps);
    if (stage > 0) {
      setup.initial_phi = app::transfer_phi(stages[from].result.nodes, stages[from].result.phi, scene.nodes.gamma,
                                            scene.nodes.spacing_smoothing, nodes);
      // A narrower interface: start from the same level sets with the new width.
      if (rec.eps < stages[from].eps) setup.initial_phi = app::rescale_interface(setup.initial_phi, stages[from].eps, rec.eps);
      // The multipliers (tension, pressure) change little between stages: start from the last ones.
      if (stages[from].result.solve.converged) setup.initial_multipliers = stages[from].result.solve.multipliers;
    }
    setup.solver.log = log;
    if (log != nullptr) {
      *log << "== stage " << stage << " (" << rec.grid << rec.label << "): " << nodes.size() << " nodes, eps " << rec.eps
           << ", h_min " << rec.h_min << "\n";
    }
    rec.result = app::solve_vesicle(PETSC_COMM_WORLD, setup);
    rec.nodes = rec.result.nodes_count;
    rec.wall_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    const bool branch = stage > 0 && scene.adaptivity->stages[static_cast<std::size_t>(stage - 1)].branch;
    stages.push_back(std::move(rec));
    if (!branch) main_stage = stages.size() - 1;
    if (!stages.back().result.solve.converged) break;
   } catch (const std::exception& e) {
    if (stages.empty()) throw;  // nothing to write
    failure = "stage " + std::to_string(stage) + ": " + e.what();
    if (log != nullptr) *log << "lmeform: " << failure << "\nlmeform: writing the last finished stage\n";
    break;
   }
  }

  const StageRecord& last = stages.back();
  const auto& r = last.result;
  const bool converged = failure.empty() && r.solve.converged;
  const std::string status = !failure.empty()        ? "FAILED: " + failure
                             : r.solve.converged ? std::string("converged")
                                                 : "FAILED: " + r.solve.message;
  const double reference = scene.reference_energy.value_or(std::nan(""));
  const double rel_error = scene.reference_energy ? (r.solve.energy - reference) / reference : std::nan("");

  // Outputs: the final (or last) state, atomically.
  std::string h5_name, png_name;
  if (rank == 0 && write_hdf5) {
    const auto h5 = out_dir / (scene.name + ".h5");
    FieldViews fields;
    fields.emplace("phi", FieldView{r.phi, 1});
    fields.emplace("grad_phi_norm", FieldView{r.grad_phi_norm, 1});
    OutputAttributes attributes;
    attributes.emplace("energy", r.solve.energy);
    attributes.emplace("eps", last.eps);
    attributes.emplace("converged", static_cast<std::int64_t>(converged ? 1 : 0));
    attributes.emplace("status", status);
    attributes.emplace("scene", scene.source);
    write_field_hdf5(h5, r.nodes, r.cells, fields, attributes);
    h5_name = h5.string();
    if (write_png) {
      const auto png = out_dir / (scene.name + ".png");
      const std::string command = "/usr/bin/python3 " LMEFORM_SOURCE_DIR "/scripts/plot_vesicle.py '" + h5.string() +
                                  "' '" + png.string() + "' --mirror > /dev/null";
      if (std::system(command.c_str()) == 0) png_name = png.string();
      else std::cerr << "lmeform: warning: the plot script failed (" << command << ")\n";
    }
  }

  const double total_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t_start).count();
  if (rank == 0) {
    std::printf("\n%-26s %s\n", "scene", scene.source.c_str());
    std::printf("%-26s %s\n", "status", status.c_str());
    std::printf("%-26s %.6f\n", "energy", r.solve.energy);
    if (scene.reference_energy) {
      std::printf("%-26s %.6f (relative error %+.3f %%)\n", "sharp-interface reference", reference, 100 * rel_error);
    }
    for (std::size_t i = 0; i < r.constraint_names.size(); ++i) {
      std::printf("%-26s %.6g (relative residual %.1e), multiplier %.6g\n", (r.constraint_names[i] + " constraint").c_str(),
                  r.solve.constraint_values[i], r.solve.relative_residuals[i], r.solve.multipliers[i]);
    }
    std::printf("%-26s %d (h_min %.4g, h_mean %.4g)\n", "nodes", last.nodes, r.h_min, r.h_mean);
    std::printf("%-26s %g\n", "eps", last.eps);
    std::printf("%-26s %d augmented Lagrangian + %d KKT\n", "Newton iterations", r.solve.augmented_iterations,
                r.solve.newton_iterations);
    std::printf("\n%-20s %8s %8s %9s %10s %12s %8s %10s %9s %9s %9s\n", "stage", "nodes", "eps", "h_min", "energy",
                "rel. error", "AL+KKT", "adapt s", "setup s", "AL s", "KKT s");
    for (const auto& s : stages) {
      const double e = s.result.solve.energy;
      const std::string its = std::to_string(s.result.solve.augmented_iterations) + "+" +
                              std::to_string(s.result.solve.newton_iterations);
      char error[32] = "-";
      if (scene.reference_energy) std::snprintf(error, sizeof error, "%+.3f%%", 100 * (e - reference) / reference);
      const std::string name = std::to_string(s.stage) + " " + s.grid + s.label;
      std::printf("%-20s %8d %8g %9.4g %10.5f %12s %8s %10.2f %9.2f %9.2f %9.2f\n", name.c_str(), s.nodes, s.eps,
                  s.h_min, e, error, its.c_str(), s.adapt_s, s.result.seconds_setup, s.result.solve.seconds_augmented,
                  s.result.solve.seconds_newton);
    }
    std::printf("%-26s %.1f s\n", "total wall time", total_s);
    if (!h5_name.empty()) std::printf("%-26s %s (+ .xmf for ParaView)\n", "fields", h5_name.c_str());
    if (!png_name.empty()) std::printf("%-26s %s\n", "figure", png_name.c_str());
    if (!json_path.empty()) {
      std::ostringstream js;
      std::string message;  // JSON-escaped status
      for (const char c : status) {
        if (c == '"' || c == '\\') message += '\\';
        message += c == '\n' ? ' ' : c;
      }
      js << "{\n  \"scene\": \"" << scene.name << "\",\n  \"converged\": " << (converged ? "true" : "false")
         << ",\n  \"status\": \"" << message << "\""
         << ",\n  \"eps\": " << json_number(last.eps) << ",\n  \"grid\": \""
         << (stages.size() > 1 ? "adapted" : "uniform") << "\",\n  \"nodes\": " << last.nodes
         << ",\n  \"energy\": " << json_number(r.solve.energy)
         << ",\n  \"relative_error_sharp\": " << json_number(rel_error) << ",\n  \"wall_s\": " << json_number(total_s)
         << ",\n  \"newton_iterations\": " << r.solve.newton_iterations
         << ",\n  \"augmented_iterations\": " << r.solve.augmented_iterations << ",\n  \"stages\": [";
      for (std::size_t i = 0; i < stages.size(); ++i) {
        const double e = stages[i].result.solve.energy;
        js << (i ? ",\n    " : "\n    ") << "{\"stage\": " << stages[i].stage << ", \"grid\": \"" << stages[i].grid << "\", \"branch\": "
           << (stages[i].label.empty() ? "false" : "true") << ", \"eps\": " << json_number(stages[i].eps)
           << ", \"nodes\": " << stages[i].nodes << ", \"h_min\": " << json_number(stages[i].h_min)
           << ", \"energy\": " << json_number(e) << ", \"relative_error_sharp\": "
           << json_number(scene.reference_energy ? (e - reference) / reference : std::nan(""))
           << ", \"augmented_iterations\": " << stages[i].result.solve.augmented_iterations
           << ", \"newton_iterations\": " << stages[i].result.solve.newton_iterations
           << ", \"adapt_s\": " << json_number(stages[i].adapt_s) << ", \"wall_s\": " << json_number(stages[i].wall_s) << "}";
      }
      js << "]\n}\n";
      write_text_atomically(json_path, js.str());
    }
  }
  return converged ? 0 : 2;
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App cli{"lmeform: phase-field vesicles on local maximum-entropy meshfree discretizations"};
  cli.require_subcommand(1);
  auto* run_cmd = cli.add_subcommand("run", "Minimize the energy of a scene (TOML) and write its results");
  std::string scene_path, json_path, output_dir;
  run_cmd->add_option("scene", scene_path, "scene file (.toml)")->required()->check(CLI::ExistingFile);
  run_cmd->add_option("--json", json_path, "write the run's figures (eps, grid, nodes, energy, relative_error_sharp, wall_s)");
  run_cmd->add_option("--output", output_dir, "output directory (default: the scene's [output] directory)");
  run_cmd->allow_extras();  // PETSc options (-constrained_pc_factor_mat_solver_type ...) pass through
  try {
    cli.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    return cli.exit(e);
  }
  try {
    PetscSession session(&argc, &argv);
    return run(scene_path, json_path, output_dir);
  } catch (const SceneError& e) {
    std::cerr << "lmeform: scene error: " << e.what() << "\n";
    return 1;
  } catch (const std::exception& e) {
    std::cerr << "lmeform: error: " << e.what() << "\n";
    return 1;
  }
}
