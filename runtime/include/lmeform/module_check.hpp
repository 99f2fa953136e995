// The derivative check of a whole form module (`lmeform check`): every output in every declared
// dimension, on the graded LME cells of form_check_setup.hpp with generic random states, one record
// per kernel (an output has one per integration domain) and dimension; the table printed by the
// command and the JSON records of --json.
#pragma once

#include <cstdint>
#include <filesystem>
#include <optional>
#include <span>
#include <string>
#include <utility>
#include <vector>

#include "lmeform/form_check.hpp"
#include "lmeform/form_check_setup.hpp"
#include "lmeform/form_registry.hpp"
#include "lmeform/kernel.hpp"

namespace lmeform::formcheck {

/// A constant's value in the check and where it came from: "--set", "default" (the form's), or
/// "random" (1 +- 20 %, for a constant without a default).
struct ConstantChoice {
  std::string name;
  double value = 0.0;
  std::string origin;
};

struct ModuleCheckOptions {
  std::vector<int> dims;                 ///< only these dimensions (empty: every declared one)
  std::vector<std::string> outputs;      ///< only these outputs (empty: all)
  std::optional<Coordinates> coordinates;  ///< empty: default_coordinates()
  std::vector<std::pair<std::string, double>> constants;  ///< user values (--set NAME=VALUE)
  std::uint64_t seed = 1;
  LmeConsistency basis = LmeConsistency::first;  ///< the basis of the check cells
  StateOptions states;
  /// Tolerances and steps; fd_step and the Taylor steps apply to directions scaled per dof
  /// (1 for scalar fields, h_min for vector fields).
  Options checks;
};

/// A Taylor slope as reported: fitted, exact (a polynomial along the direction), cut short by a
/// kink, or not applicable to the output's kind.
struct SlopeResult {
  enum class Kind { not_applicable, fitted, exact, kink };
  Kind kind = Kind::not_applicable;
  double value = 0.0;
  [[nodiscard]] std::string text() const;  ///< "2.00", "exact", "kink", "n/a"
};

/// One row of the table: one kernel of an output (an output has one per integration domain) in
/// one dimension, worst case over the check cells.
struct CheckRecord {
  std::string form;
  std::string output;
  std::string kind;                      ///< energy, constraint, residual, bilinear, linear, point
  std::string domain = "cells";          ///< cells or boundary
  std::string boundary_part;             ///< the boundary part ("" for the whole boundary, ds)
  std::string measure;                   ///< dx, ds, ds(top); empty for a point output
  int dim = 0;
  std::string coordinates;
  int cells = 0;
  int max_nodes = 0;                     ///< largest cell neighbourhood
  int points = 0;                        ///< quadrature points per cell
  // NaN where the check does not apply to the kind.
  double gradient_rel_error = std::numeric_limits<double>::quiet_NaN();
  double hessian_rel_error = std::numeric_limits<double>::quiet_NaN();  ///< Hessian or Jacobian
  double symmetry_error = std::numeric_limits<double>::quiet_NaN();
  double linearity_error = std::numeric_limits<double>::quiet_NaN();    ///< in the test (and trial) functions
  double state_dependence_error = std::numeric_limits<double>::quiet_NaN();
  SlopeResult taylor_slope_gradient;      ///< |E(u+hv) - E - h g.v|, expected 2
  SlopeResult taylor_slope_second_order;  ///< |E(u+hv) - E - h g.v - h^2/2 vHv|, expected 3
  SlopeResult taylor_slope_hessian;       ///< |g(u+hv) - g - h H v| (residual: R, J), expected 2
  double min_det = std::numeric_limits<double>::quiet_NaN();  ///< of the vector fields' gradients
  /// Flops of each kernel for the largest cell (NaN: no such kernel).
  double flops_value = std::numeric_limits<double>::quiet_NaN();
  double flops_vector = std::numeric_limits<double>::quiet_NaN();
  double flops_matrix = std::numeric_limits<double>::quiet_NaN();
  double seconds = 0.0;
  std::vector<std::string> notes;        ///< how the check was set up where it deviates from the rule
  std::vector<std::string> kinks;        ///< kinks crossed (non-smooth integrands), and what was done
  std::vector<std::string> failures;
  bool passed = true;
  std::string status;                    ///< "pass", "kink" (passed; a kink was crossed), "fail"
};

/// A module's check: its records and how the module was obtained.
struct ModuleCheck {
  std::string module;
  std::filesystem::path source;
  Coordinates coordinates = Coordinates::cartesian;
  std::string coordinates_reason;        ///< why these coordinates ("--coordinates", "includes axisymmetric.inc", ...)
  LmeConsistency basis = LmeConsistency::first;  ///< the basis of the check cells
  std::vector<ConstantChoice> constants;
  std::vector<CheckRecord> records;
  std::string provenance;                ///< "built-in", "JIT: compiled in 3.1 s", "JIT: cache hit"
  double compile_seconds = 0.0;          ///< lmeformc + C++ compiler (0 for built-ins and cache hits)
  bool cache_hit = false;
  bool builtin = false;
  double seconds = 0.0;                  ///< the whole check
  [[nodiscard]] bool passed() const;
};

/// "E" for a kernel over the cells (or a point output), "E [ds(top)]" for one over the boundary.
[[nodiscard]] std::string kernel_label(const CheckRecord& record);

/// Axisymmetric when the module's name ends in `_axisymmetric` or its source (or a file it
/// includes, searched next to the including file and in include_dirs) includes `axisymmetric.inc`;
/// Cartesian otherwise. `reason` receives the rule that decided.
[[nodiscard]] Coordinates default_coordinates(const std::string& module, const std::filesystem::path& source,
                                              const std::vector<std::filesystem::path>& include_dirs,
                                              std::string* reason = nullptr);

/// One value per constant used by the kernels: the user's, else the form's default, else 1 +- 20 %.
/// Throws std::invalid_argument for a user name that no kernel uses, listing the module's constants.
[[nodiscard]] std::vector<ConstantChoice> resolve_constants(std::span<const kernel::FormKernels* const> kernels,
                                                            const std::vector<std::pair<std::string, double>>& user,
                                                            std::uint64_t seed);

/// Checks one output in one dimension on the check cells of its geometry.
[[nodiscard]] CheckRecord check_kernels(const kernel::FormKernels& form, const std::vector<ConstantChoice>& constants,
                                        Coordinates coordinates, const ModuleCheckOptions& options);

/// Checks every selected output and dimension of a module. Throws std::invalid_argument when the
/// selection (--dim, --output) matches nothing, naming what the module has.
[[nodiscard]] ModuleCheck check_module(const std::string& module, const std::filesystem::path& source,
                                       std::span<const kernel::FormKernels* const> kernels,
                                       const ModuleCheckOptions& options,
                                       const std::vector<std::filesystem::path>& include_dirs = {});

/// The table of a module's check: one row per output and dimension, then kinks and failures,
/// then per kernel its flops and the module's compile time.
[[nodiscard]] std::string format_table(const ModuleCheck& check);

/// The records of the checks as a JSON list (one object per output and dimension).
[[nodiscard]] std::string records_json(const std::vector<ModuleCheck>& checks);

using lmeform::to_string;  // the output kind's keyword (form_registry.hpp)

}  // namespace lmeform::formcheck
