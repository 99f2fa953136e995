// `lmeform check FORM.form`: the derivative check of a form module as a user command.
//
// For every output (energy, constraint, residual, bilinear, linear; each of its kernels, one per
// integration domain; point outputs are evaluated) in every declared dimension,
// on a few cells of a small graded LME node set (Cartesian, or axisymmetric with the basis mirrored
// across the axis) with smooth random states, coefficients, quadrature data and constants: the
// derivatives against finite differences, Hessian symmetry, Taylor remainder slopes, linearity in
// the test functions; kinks of non-smooth integrands are reported, not failed. Prints a table (one
// row per kernel and dimension, then flops and compile time per kernel) and optionally writes the
// records as JSON. Exit code 0 when every check passes, 1 on any failure, 2 when the form cannot be
// loaded or an option is wrong.
#pragma once

#include <cstdint>
#include <iosfwd>
#include <string>
#include <vector>

#include <CLI/CLI.hpp>

#include "lmeform/kernel.hpp"

namespace lmeform {

struct CheckCommandOptions {
  std::string form;                        ///< built-in module name or path of a .form file
  std::vector<int> dims;                   ///< --dim: only these dimensions
  std::string coordinates = "auto";        ///< --coordinates auto|cartesian|axisymmetric
  std::string basis = "first";             ///< --basis first|second: the max-ent basis of the check cells
  std::vector<std::string> sets;           ///< --set NAME=VALUE: constant values
  std::uint64_t seed = 1;                  ///< --seed: random states and constants
  std::string json;                        ///< --json OUT: write the records
  std::vector<std::string> outputs;        ///< --output NAME: only these outputs
  std::vector<std::string> include_dirs;   ///< -I DIR: include directories of the form
  bool rebuild = false;                    ///< --rebuild: recompile a JIT form even when cached
  double perturbation = 0.1;               ///< --perturbation: vector fields, size of grad y - I
  double interface_width = 0.0;            ///< --interface-width: scalar fields' tanh width (0: 2 h_min)

  // Not on the command line (tests, embedding):
  /// Check this module table instead of loading `form`.
  const kernel::ModuleTable* module = nullptr;
  /// Where the table and messages go (nullptr: std::cout and std::cerr).
  std::ostream* out = nullptr;
  std::ostream* err = nullptr;
};

/// Adds the `check` subcommand to `app`, parsing into `options`.
CLI::App* add_check_subcommand(CLI::App& app, CheckCommandOptions& options);

/// Runs the check; returns the process exit code (0 pass, 1 a check failed, 2 usage or load error).
int run_check_command(const CheckCommandOptions& options);

}  // namespace lmeform
