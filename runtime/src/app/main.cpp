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
#include "run_scene.hpp"
#include "vesicle.hpp"

namespace {

using namespace lmeform;

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
  app::check_runnable(scene);  // before any directory is made
  std::filesystem::path out_dir = !output_override.empty() ? std::filesystem::path(output_override)
                                  : scene.output ? scene.output->directory
                                                 : std::filesystem::path("out") / scene.name;
  const bool write_hdf5 = !scene.output || scene.output->hdf5;
  const bool write_png = !scene.output || scene.output->png;
  if (rank == 0) std::filesystem::create_directories(out_dir);

  const app::SceneRun run = app::run_scene(PETSC_COMM_WORLD, scene, log);
  const std::vector<app::StageRecord>& stages = run.stages;
  const std::string& failure = run.failure;
  const app::StageRecord& last = stages.back();
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
      // The area multiplier is the membrane tension, the volume multiplier the pressure difference.
      const std::string& c = r.constraint_names[i];
      const char* meaning = c == "area" ? " (tension)" : c == "volume" ? " (pressure)" : "";
      std::printf("%-26s %.6g (relative residual %.1e), multiplier%s %.6g\n", (c + " constraint").c_str(),
                  r.solve.constraint_values[i], r.solve.relative_residuals[i], meaning, r.solve.multipliers[i]);
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
         << ",\n  \"augmented_iterations\": " << r.solve.augmented_iterations << ",\n  \"multipliers\": {";
      for (std::size_t i = 0; i < r.constraint_names.size(); ++i) {
        js << (i ? ", " : "") << "\"" << r.constraint_names[i] << "\": " << json_number(r.solve.multipliers[i]);
      }
      js << "},\n  \"constraint_residuals\": {";
      for (std::size_t i = 0; i < r.constraint_names.size(); ++i) {
        js << (i ? ", " : "") << "\"" << r.constraint_names[i] << "\": " << json_number(r.solve.relative_residuals[i]);
      }
      js << "},\n  \"stages\": [";
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
