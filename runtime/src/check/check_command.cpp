#include "check_command.hpp"

#include <mpi.h>

#include <cstdlib>
#include <filesystem>
#include <iostream>
#include <span>
#include <stdexcept>

#include <fmt/format.h>

#include "lmeform/form_registry.hpp"
#include "lmeform/module_check.hpp"
#include "lmeform/output.hpp"

namespace lmeform {

namespace fs = std::filesystem;

CLI::App* add_check_subcommand(CLI::App& app, CheckCommandOptions& options) {
  CLI::App* cmd = app.add_subcommand(
      "check", "Check a form's kernels: derivatives against finite differences, Taylor remainder slopes, symmetry, "
               "linearity; exit code 1 on any failure");
  cmd->add_option("form", options.form, "built-in module name or .form file")->required();
  // One value per flag: `--dim 2 helfrich` must not read the form name as a dimension.
  cmd->add_option("--dim", options.dims, "check only this dimension (repeatable)")
      ->check(CLI::Range(1, 3))
      ->allow_extra_args(false);
  cmd->add_option("--coordinates", options.coordinates,
                  "cartesian or axisymmetric (r = x[0] > 0, basis mirrored across the axis); default: axisymmetric "
                  "when the module name ends in _axisymmetric or its source includes axisymmetric.inc")
      ->check(CLI::IsMember({"auto", "cartesian", "axisymmetric"}));
  cmd->add_option("--basis", options.basis,
                  "basis of the check cells: first (LME) or second (second-order max-ent, as nodes.basis in a scene)")
      ->check(CLI::IsMember({"first", "second"}));
  cmd->add_option("--set", options.sets, "constant value NAME=VALUE (repeatable); default: the form's default, else "
                                         "1 +- 20 % at random")
      ->allow_extra_args(false);
  cmd->add_option("--seed", options.seed, "seed of the random states and constants");
  cmd->add_option("--json", options.json, "write the records (one per output and dimension) as JSON");
  cmd->add_option("--output", options.outputs, "check only this output (repeatable)")->allow_extra_args(false);
  cmd->add_option("-I", options.include_dirs, "include directory of the form (repeatable)")->allow_extra_args(false);
  cmd->add_flag("--rebuild", options.rebuild, "recompile the form even when the JIT cache holds it");
  cmd->add_option("--perturbation", options.perturbation,
                  "vector fields (deformations, velocities) are x + a smooth field whose gradient is this large; "
                  "halved until det grad y >= 0.5 on every check cell")
      ->check(CLI::PositiveNumber);
  cmd->add_option("--interface-width", options.interface_width,
                  "width of the tanh profile of scalar fields (default: twice the finest nodal spacing)")
      ->check(CLI::NonNegativeNumber);
  return cmd;
}

namespace {

/// `lmeform check` may run before (or without) the PETSc session of other commands; loading a
/// form by path talks MPI. Initialised once, finalised at exit if this code started it.
void ensure_mpi() {
  struct Guard {
    bool started = false;
    Guard() {
      int initialized = 0;
      MPI_Initialized(&initialized);
      if (!initialized) {
        MPI_Init(nullptr, nullptr);
        started = true;
      }
    }
    ~Guard() {
      int finalized = 0;
      MPI_Finalized(&finalized);
      if (started && !finalized) MPI_Finalize();
    }
  };
  static const Guard guard;
}

std::pair<std::string, double> parse_set(const std::string& text) {
  const auto eq = text.find('=');
  if (eq == std::string::npos || eq == 0)
    throw std::invalid_argument(fmt::format("--set {}: expected NAME=VALUE", text));
  const std::string name = text.substr(0, eq), value = text.substr(eq + 1);
  std::size_t used = 0;
  double v = 0.0;
  try {
    v = std::stod(value, &used);
  } catch (const std::exception&) {
    used = 0;
  }
  if (used == 0 || used != value.size())
    throw std::invalid_argument(fmt::format("--set {}: '{}' is not a number", text, value));
  return {name, v};
}

}  // namespace

int run_check_command(const CheckCommandOptions& options) {
  std::ostream& out = options.out ? *options.out : std::cout;
  std::ostream& err = options.err ? *options.err : std::cerr;
  formcheck::ModuleCheck check;
  try {
    formcheck::ModuleCheckOptions mo;
    mo.dims = options.dims;
    mo.outputs = options.outputs;
    mo.seed = options.seed;
    mo.basis = parse_lme_consistency(options.basis);
    mo.states.perturbation = options.perturbation;
    mo.states.width = options.interface_width;
    if (options.coordinates == "cartesian") mo.coordinates = formcheck::Coordinates::cartesian;
    else if (options.coordinates == "axisymmetric") mo.coordinates = formcheck::Coordinates::axisymmetric;
    else if (options.coordinates != "auto")
      throw std::invalid_argument(fmt::format("--coordinates {}: expected auto, cartesian or axisymmetric", options.coordinates));
    for (const auto& s : options.sets) mo.constants.push_back(parse_set(s));
    std::vector<fs::path> include_dirs(options.include_dirs.begin(), options.include_dirs.end());

    if (options.module) {
      const kernel::ModuleTable& table = *options.module;
      check = formcheck::check_module(table.module, table.source,
                                      std::span<const kernel::FormKernels* const>(table.kernels,
                                                                                  static_cast<std::size_t>(table.n_kernels)),
                                      mo, include_dirs);
      check.provenance = "given module table";
    } else {
      if (fs::path(options.form).extension() == ".toml")
        throw std::invalid_argument(fmt::format("{} is a scene (TOML); check takes a .form file or a built-in module name. "
                                                "`lmeform run {}` reads the scene and reports its errors",
                                                options.form, options.form));
      ensure_mpi();
      FormLoadOptions lo;
      lo.include_dirs = include_dirs;
      lo.rebuild = options.rebuild;
      lo.log = &out;
      const FormModule& module = load_form(options.form, lo);
      check = formcheck::check_module(module.name, module.source, module.kernels, mo, include_dirs);
      check.builtin = module.builtin;
      check.cache_hit = module.cache_hit;
      check.compile_seconds = module.builtin || module.cache_hit ? 0.0 : module.generate_seconds + module.compile_seconds;
      check.provenance = module.builtin ? "built-in"
                         : module.cache_hit
                             ? fmt::format("JIT cache hit ({:.3f} s)", module.load_seconds)
                             : fmt::format("JIT: lmeformc {:.2f} s + C++ compile {:.2f} s", module.generate_seconds,
                                           module.compile_seconds);
    }
  } catch (const std::exception& e) {
    err << "lmeform check: " << e.what() << "\n";
    return 2;
  }
  out << formcheck::format_table(check);
  if (!options.json.empty()) {
    try {
      write_text_atomically(options.json, formcheck::records_json({check}));
    } catch (const std::exception& e) {
      err << "lmeform check: " << e.what() << "\n";
      return 2;
    }
  }
  if (!check.passed()) {
    std::string failed;
    for (const auto& r : check.records)
      if (!r.passed) failed += fmt::format("{}{} ({}d)", failed.empty() ? "" : ", ", formcheck::kernel_label(r), r.dim);
    err << fmt::format("lmeform check: {} failed: {}\n", check.module, failed);
    return 1;
  }
  return 0;
}

}  // namespace lmeform
