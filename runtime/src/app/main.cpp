// lmeform — run any model from its .form files and a scene, check forms, draw field files.
//
//   lmeform run SCENE.toml [--json OUT.json] [--output DIR] [--set NAME=VALUE] [--restart] [--check] [PETSc options]
//   lmeform check FORM.form [--dim D] [--set NAME=VALUE] [--json OUT.json] ...
//   lmeform plot FIELDS.h5 [OUT.png] [--field NAME] [--mirror]
//
// `run` reads the scene and hands it to the problem driver that claims it (run_command.hpp).
#include <CLI/CLI.hpp>

#include <filesystem>
#include <iostream>
#include <optional>
#include <string>
#include <string_view>

#include <fmt/format.h>

#if __has_include("check_command.hpp")
#include "check_command.hpp"
#define LMEFORM_HAVE_CHECK 1
#endif
#include "lmeform/form_registry.hpp"
#include "lmeform/petsc.hpp"
#include "lmeform/scene.hpp"
#include "figures.hpp"
#include "run_command.hpp"

using namespace lmeform;

int main(int argc, char** argv) {
  CLI::App cli{"lmeform: models from .form files on local maximum-entropy meshfree discretizations"};
  cli.require_subcommand(1);
  auto* run_cmd = cli.add_subcommand("run", "Solve the problem of a scene (TOML) and write its results");
  app::RunOptions run_options;
  run_cmd->add_option("scene", run_options.scene, "scene file (.toml)")->required()->check(CLI::ExistingFile);
  run_cmd->add_option("--json", run_options.json, "write the run's figures (energy, errors, iterations, stages, wall_s)");
  run_cmd->add_option("--output", run_options.output, "output directory (default: the scene's [output] directory)");
  run_cmd->add_option("--set", run_options.settings, "set a constant, NAME=VALUE (repeatable; wins over the scene's [constants])");
  run_cmd->add_flag("--restart", run_options.restart, "resume a run that writes checkpoints from the last one in the output directory");
  run_cmd->add_flag("--check", run_options.check, "bind the scene to its forms and check it, without solving");
  run_cmd->allow_extras();  // PETSc options (-ksp_type gmres, -snes_monitor, ...) pass through
  auto* plot_cmd = cli.add_subcommand("plot", "Draw a field file (.h5) or columns of a history (.csv) as a PNG (needs python3-matplotlib)");
  std::string plot_file, plot_png, plot_field_name = "phi", plot_x;
  std::vector<std::string> plot_y;
  bool plot_mirror = false;
  plot_cmd->add_option("file", plot_file, "field file (.h5) or history.csv written by lmeform run")->required()->check(CLI::ExistingFile);
  plot_cmd->add_option("png", plot_png, "the figure (default: the file with .png)");
  plot_cmd->add_option("--field", plot_field_name, "field file: the scalar field to draw (default: phi)");
  plot_cmd->add_flag("--mirror", plot_mirror, "field file: reflect r -> -r, the full cross-section of an axisymmetric field");
  plot_cmd->add_option("--x", plot_x, "history: the column on the horizontal axis");
  plot_cmd->add_option("--y", plot_y, "history: a column on the vertical axis (repeatable)");
#ifdef LMEFORM_HAVE_CHECK
  CheckCommandOptions check_options;
  auto* check_cmd = add_check_subcommand(cli, check_options);
#endif
  try {
    cli.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    return cli.exit(e);
  }
  if (plot_cmd->parsed()) {
    const std::string png = plot_png.empty() ? std::filesystem::path(plot_file).replace_extension(".png").string() : plot_png;
    const bool history = plot_file.ends_with(".csv");
    if (history && (plot_x.empty() || plot_y.empty())) {
      std::cerr << "lmeform plot: a history needs --x COLUMN and --y COLUMN\n";
      return 1;
    }
    const app::FigureResult r = history ? app::plot_history(plot_file, png, plot_x, plot_y)
                                        : app::plot_field(plot_file, png, plot_field_name, plot_mirror);
    if (r.written) std::cout << png << "\n";
    else std::cerr << "lmeform plot: " << r.warning << "\n";
    return r.written ? 0 : 1;
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
    return app::run_command(run_options);
  } catch (const SceneError& e) {
    return fail("scene error", e.what());
  } catch (const FormLoadError& e) {
    return fail("form error", e.what());
  } catch (const std::exception& e) {
    return fail("error", e.what());
  }
}
