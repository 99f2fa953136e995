// lmeform — run any model from its .form files and a scene, and check forms.
//
//   lmeform run SCENE.toml [--json OUT.json] [--output DIR] [PETSc options]
//   lmeform check FORM.form [--dim D] [--set NAME=VALUE] [--json OUT.json] ...
//
// `run` reads the scene, loads its forms (built-in or compiled at run time), builds the node set,
// solves the problem the scene's outputs describe (constrained minimization, a residual, or a
// linear problem), prints progress and a closing table, and writes HDF5 + XDMF (ParaView), a PNG
// and (with --json) the run's figures.
#include <CLI/CLI.hpp>

#include <unistd.h>

#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <iostream>
#include <limits>
#include <optional>
#include <string>
#include <string_view>

#include <fmt/format.h>
#include <nlohmann/json.hpp>

#if __has_include("check_command.hpp")
#include "check_command.hpp"
#define LMEFORM_HAVE_CHECK 1
#endif
#include "lmeform/form_registry.hpp"
#include "lmeform/output.hpp"
#include "lmeform/petsc.hpp"
#include "lmeform/scene.hpp"
#include "dynamics.hpp"
#include "run_scene.hpp"

namespace {

using namespace lmeform;
namespace fs = std::filesystem;

/// A JSON number, or null for NaN / infinity (JSON has neither).
nlohmann::json number(double v) { return std::isfinite(v) ? nlohmann::json(v) : nlohmann::json(nullptr); }

/// Refuses, before any work, an output that could not be written at the end.
void check_writable(const fs::path& json_path, const fs::path& out_dir, bool writes_files) {
  if (!json_path.empty()) {
    const fs::path dir = json_path.parent_path().empty() ? fs::path(".") : json_path.parent_path();
    if (fs::is_directory(json_path)) throw std::runtime_error(fmt::format("--json {}: is a directory", json_path.string()));
    if (!fs::is_directory(dir)) throw std::runtime_error(fmt::format("--json {}: the folder {} does not exist", json_path.string(), dir.string()));
    if (::access(dir.c_str(), W_OK) != 0) throw std::runtime_error(fmt::format("--json {}: the folder {} is not writable", json_path.string(), dir.string()));
  }
  if (writes_files) {
    std::error_code ec;
    fs::create_directories(out_dir, ec);
    if (ec || !fs::is_directory(out_dir) || ::access(out_dir.c_str(), W_OK) != 0)
      throw std::runtime_error(fmt::format("the output directory {} cannot be created or written{}", out_dir.string(),
                                           ec ? " (" + ec.message() + ")" : ""));
  }
}

/// NAME=VALUE of a --set option.
std::pair<std::string, double> parse_constant_setting(const std::string& text) {
  const auto eq = text.find('=');
  if (eq == std::string::npos || eq == 0)
    throw SceneError(fmt::format("--set {}: expected NAME=VALUE (e.g. --set C=0.5)", text));
  const std::string value = text.substr(eq + 1);
  char* end = nullptr;
  const double v = std::strtod(value.c_str(), &end);
  if (value.empty() || end == nullptr || *end != '\0') throw SceneError(fmt::format("--set {}: '{}' is not a number", text, value));
  return {text.substr(0, eq), v};
}

int run(const std::string& scene_path, const std::string& json_path, const std::string& output_override,
        const std::vector<std::string>& settings, bool restart) {
  const int rank = PetscSession::rank();
  std::ostream* log = rank == 0 ? &std::cout : nullptr;
  const auto t_start = std::chrono::steady_clock::now();
  Scene loaded = load_scene(scene_path, app::model_extensions());
  for (const auto& setting : settings) {  // the command line wins over [constants]
    const auto [name, value] = parse_constant_setting(setting);
    loaded.constants[name] = value;
    loaded.constant_where[name] = "command line: --set " + setting;
  }
  const Scene& scene = loaded;
  const fs::path out_dir = !output_override.empty() ? fs::path(output_override)
                           : scene.output         ? scene.output->directory
                                                  : fs::path("out") / scene.name;
  const bool write_hdf5 = !scene.output || scene.output->hdf5;
  const bool write_png = write_hdf5 && (!scene.output || scene.output->png) && scene.dim() == 2;
  int ok = 1;
  std::string why;
  if (rank == 0) {
    try {
      check_writable(json_path, out_dir, write_hdf5);
    } catch (const std::exception& e) {
      ok = 0;
      why = e.what();
    }
  }
  MPI_Bcast(&ok, 1, MPI_INT, 0, PETSC_COMM_WORLD);
  if (ok == 0) throw std::runtime_error(rank == 0 ? why : "an output cannot be written");

  if (scene.has_extension(app::kDynamicsExtension)) return app::run_dynamics_command(PETSC_COMM_WORLD, scene, out_dir, json_path, restart);
  if (restart) throw SceneError(fmt::format("{}: --restart resumes a run with [dynamics]; this scene has none", scene.source));
  const app::SceneRun run = app::run_scene(PETSC_COMM_WORLD, scene, log);
  const auto& stages = run.stages;
  const app::StageRecord& last = stages.back();
  const app::ProblemResult& r = last.result;
  const bool converged = run.failure.empty() && r.converged;
  const std::string status = !run.failure.empty() ? "FAILED: " + run.failure
                             : r.converged       ? std::string("converged")
                                                 : "FAILED: " + r.message;
  const double reference = scene.reference.energy.value_or(std::nan(""));
  auto rel_error = [&](double e) { return scene.reference.energy ? (e - reference) / reference : std::nan(""); };
  const bool minimization = scene.model.kind == ProblemKind::minimization;

  // Outputs: the final (or last) state, atomically.
  std::string h5_name, png_name;
  if (rank == 0 && write_hdf5) {
    const auto h5 = out_dir / (scene.name + ".h5");
    // One field per unknown (its components), |∇u| of the first scalar unknown.
    std::map<std::string, std::vector<double>, std::less<>> storage;
    FieldViews fields;
    const std::size_t n = r.nodes.size();
    const std::size_t bs = n == 0 ? 0 : r.state.size() / n;
    std::size_t offset = 0;
    for (const auto& u : run.unknowns) {
      auto& values = storage[u.name];
      values.resize(n * std::size_t(u.components));
      for (std::size_t a = 0; a < n; ++a)
        for (int c = 0; c < u.components; ++c) values[a * std::size_t(u.components) + std::size_t(c)] = r.state[a * bs + offset + std::size_t(c)];
      offset += std::size_t(u.components);
      fields.emplace(u.name, FieldView{values, u.components});
    }
    if (!r.gradient_norm.empty()) fields.emplace("grad_" + run.unknowns.front().name + "_norm", FieldView{r.gradient_norm, 1});
    OutputAttributes attributes;
    if (minimization) attributes.emplace("energy", r.energy);
    if (!run.parameter.empty()) attributes.emplace(run.parameter, last.parameter);
    attributes.emplace("converged", static_cast<std::int64_t>(converged ? 1 : 0));
    attributes.emplace("status", status);
    attributes.emplace("scene", scene.source);
    write_field_hdf5(h5, r.nodes, r.cells, fields, attributes);
    h5_name = h5.string();
    if (write_png && !run.unknowns.empty() && run.unknowns.front().components == 1) {
      const auto png = out_dir / (scene.name + ".png");
      const std::string command = fmt::format("/usr/bin/python3 {}/scripts/plot_vesicle.py '{}' '{}' --field '{}'{} > /dev/null",
                                              LMEFORM_SOURCE_DIR, h5.string(), png.string(), run.unknowns.front().name,
                                              scene.axisymmetric() ? " --mirror" : "");
      if (std::system(command.c_str()) == 0) png_name = png.string();
      else std::cerr << "lmeform: warning: the plot script failed (" << command << ")\n";
    }
  }

  const double total_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t_start).count();
  if (rank == 0) {
    std::printf("\n%-26s %s\n", "scene", scene.source.c_str());
    std::printf("%-26s %s\n", "status", status.c_str());
    if (minimization) {
      std::printf("%-26s %.6f\n", "energy", r.energy);
      if (scene.reference.energy)
        std::printf("%-26s %.6f (relative error %+.3f %%)\n", "reference energy", reference, 100 * rel_error(r.energy));
      for (std::size_t i = 0; i < r.constraint_names.size(); ++i) {
        const std::string& c = r.constraint_names[i];
        const auto named = run.multiplier_meanings.find(c);
        const std::string meaning = named == run.multiplier_meanings.end() ? "" : " (" + named->second + ")";
        std::printf("%-26s %.6g (relative residual %.1e), multiplier%s %.6g\n", (c + " constraint").c_str(),
                    r.minimization.constraint_values[i], r.minimization.relative_residuals[i], meaning.c_str(),
                    r.minimization.multipliers[i]);
      }
    } else {
      std::printf("%-26s %s\n", "solver", r.message.c_str());
    }
    for (const auto& e : r.errors)
      std::printf("%-26s L2 %.6e, H1 semi-norm %.6e\n", ("error of " + e.unknown).c_str(), e.l2, e.h1);
    std::printf("%-26s %d (h_min %.4g, h_mean %.4g)\n", "nodes", last.nodes, r.h_min, r.h_mean);
    if (!run.parameter.empty()) std::printf("%-26s %g\n", run.parameter.c_str(), last.parameter);
    if (minimization)
      std::printf("%-26s %d augmented Lagrangian + %d KKT\n", "Newton iterations", r.minimization.augmented_iterations,
                  r.minimization.newton_iterations);
    if (!run.parameter.empty()) {
      std::printf("\n%-20s %8s %8s %9s %10s %12s %8s %10s %9s %9s %9s\n", "stage", "nodes", run.parameter.c_str(), "h_min", "energy",
                  "rel. error", "AL+KKT", "adapt s", "setup s", "AL s", "KKT s");
      for (const auto& s : stages) {
        const std::string its = std::to_string(s.result.minimization.augmented_iterations) + "+" +
                                std::to_string(s.result.minimization.newton_iterations);
        const std::string error = scene.reference.energy ? fmt::format("{:+.3f}%", 100 * rel_error(s.result.energy)) : "-";
        const std::string name = std::to_string(s.stage) + " " + s.grid + s.label;
        std::printf("%-20s %8d %8g %9.4g %10.5f %12s %8s %10.2f %9.2f %9.2f %9.2f\n", name.c_str(), s.nodes, s.parameter, s.h_min,
                    s.result.energy, error.c_str(), its.c_str(), s.adapt_s, s.result.seconds_setup,
                    s.result.minimization.seconds_augmented, s.result.minimization.seconds_newton);
      }
    } else {
      std::printf("%-26s setup %.2f s, solve %.2f s\n", "times", r.seconds_setup, r.seconds_solve);
    }
    std::printf("%-26s %.1f s\n", "total wall time", total_s);
    if (!h5_name.empty()) std::printf("%-26s %s (+ .xmf for ParaView)\n", "fields", h5_name.c_str());
    if (!png_name.empty()) std::printf("%-26s %s\n", "figure", png_name.c_str());
    if (!json_path.empty()) {
      nlohmann::json js;
      js["scene"] = scene.name;
      js["problem"] = minimization ? "minimization" : scene.model.kind == ProblemKind::residual ? "residual" : "linear";
      js["converged"] = converged;
      js["status"] = status;
      js["nodes"] = last.nodes;
      js["h_min"] = number(r.h_min);
      js["energy"] = number(r.energy);
      js["relative_error_reference"] = number(rel_error(r.energy));
      js["wall_s"] = number(total_s);
      js["setup_s"] = number(r.seconds_setup);
      js["solve_s"] = number(r.seconds_solve);
      js["iterations"] = r.iterations;
      js["residual_norm"] = number(r.residual_norm);
      js["errors"] = nlohmann::json::array();
      for (const auto& e : r.errors) js["errors"].push_back({{"unknown", e.unknown}, {"l2", number(e.l2)}, {"h1", number(e.h1)}});
      if (minimization) {
        js["newton_iterations"] = r.minimization.newton_iterations;
        js["augmented_iterations"] = r.minimization.augmented_iterations;
        js["multipliers"] = nlohmann::json::object();
        js["constraint_residuals"] = nlohmann::json::object();
        for (std::size_t i = 0; i < r.constraint_names.size(); ++i) {
          js["multipliers"][r.constraint_names[i]] = number(r.minimization.multipliers[i]);
          js["constraint_residuals"][r.constraint_names[i]] = number(r.minimization.relative_residuals[i]);
        }
      }
      if (!run.parameter.empty()) {
        js[run.parameter] = number(last.parameter);
        js["grid"] = stages.size() > 1 ? "adapted" : "uniform";
        js["relative_error_sharp"] = number(rel_error(r.energy));
      }
      js["stages"] = nlohmann::json::array();
      for (const auto& s : stages) {
        js["stages"].push_back({{"stage", s.stage},
                                {"grid", s.grid},
                                {"branch", !s.label.empty()},
                                {run.parameter.empty() ? "parameter" : run.parameter, number(s.parameter)},
                                {"nodes", s.nodes},
                                {"h_min", number(s.h_min)},
                                {"energy", number(s.result.energy)},
                                {"relative_error_sharp", number(rel_error(s.result.energy))},
                                {"augmented_iterations", s.result.minimization.augmented_iterations},
                                {"newton_iterations", s.result.minimization.newton_iterations},
                                {"gradient_evaluations", s.result.minimization.gradient_evaluations},
                                {"hessian_evaluations", s.result.minimization.hessian_evaluations},
                                {"shifted_steps", s.result.minimization.corrected_steps},
                                {"inertia_corrections", s.result.minimization.inertia_corrections},
                                {"constraint_corrections", s.result.minimization.constraint_corrections},
                                {"adapt_s", number(s.adapt_s)},
                                {"setup_s", number(s.result.seconds_setup)},
                                {"hessian_s", number(s.result.minimization.seconds_hessian)},
                                {"factor_solve_s", number(s.result.minimization.seconds_factor)},
                                {"wall_s", number(s.wall_s)}});
      }
      write_text_atomically(json_path, js.dump(2) + "\n");
    }
  }
  return converged ? 0 : 2;
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App cli{"lmeform: models from .form files on local maximum-entropy meshfree discretizations"};
  cli.require_subcommand(1);
  auto* run_cmd = cli.add_subcommand("run", "Solve the problem of a scene (TOML) and write its results");
  std::string scene_path, json_path, output_dir;
  std::vector<std::string> settings;
  run_cmd->add_option("scene", scene_path, "scene file (.toml)")->required()->check(CLI::ExistingFile);
  run_cmd->add_option("--json", json_path, "write the run's figures (energy, errors, iterations, stages, wall_s)");
  run_cmd->add_option("--output", output_dir, "output directory (default: the scene's [output] directory)");
  run_cmd->add_option("--set", settings, "set a constant, NAME=VALUE (repeatable; wins over the scene's [constants])");
  bool restart = false;
  run_cmd->add_flag("--restart", restart, "resume a run with [dynamics] from its last checkpoint in the output directory");
  run_cmd->allow_extras();  // PETSc options (-ksp_type gmres, -snes_monitor, ...) pass through
#ifdef LMEFORM_HAVE_CHECK
  CheckCommandOptions check_options;
  auto* check_cmd = add_check_subcommand(cli, check_options);
#endif
  try {
    cli.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    return cli.exit(e);
  }
  // The session outlives the handlers: an error thrown on one rank only (an LME evaluation, a
  // re-mesh) is printed and then aborts the job, where finalizing would wait for the other ranks
  // forever and swallow the message.
  std::optional<PetscSession> session;
  auto fail = [&](std::string_view kind, const char* what) {
    std::cerr << fmt::format("lmeform: {}: {}\n", kind, what) << std::flush;  // one write: ranks do not interleave
    if (session && PetscSession::size() > 1) MPI_Abort(PETSC_COMM_WORLD, 1);
    return 1;
  };
  try {
    session.emplace(&argc, &argv);
#ifdef LMEFORM_HAVE_CHECK
    if (check_cmd->parsed()) return run_check_command(check_options);
#endif
    for (const auto& extra : run_cmd->remaining())
      if (extra.starts_with("--"))
        throw SceneError(fmt::format("unknown option '{}' of 'lmeform run' (PETSc options take one dash: -ksp_type ...)", extra));
    return run(scene_path, json_path, output_dir, settings, restart);
  } catch (const SceneError& e) {
    return fail("scene error", e.what());
  } catch (const FormLoadError& e) {
    return fail("form error", e.what());
  } catch (const std::exception& e) {
    return fail("error", e.what());
  }
}
