// Expressions of the coordinates in scenes ("sin(pi*x[0])", "tanh((0.3 - norm(x))/eps)"), compiled
// by lmeformc like any form: the runtime never includes the parser. A scene's point expressions
// become the `point` outputs of one generated module, evaluated at a one-point "cell" without
// nodes: the point of interest.
// Errors against an exact solution are the `energy` outputs of a second generated module,
// (u − u_exact)² and |∇u − ∇u_exact|² integrated with the run's quadrature.
#pragma once

#include <mpi.h>

#include <filesystem>
#include <map>
#include <span>
#include <string>
#include <vector>

#include "lmeform/form_registry.hpp"

namespace lmeform::problems {

/// Point expressions of one scene, compiled together (one JIT module, cached).
class PointExpressions {
 public:
  /// dim: the spatial dimension; constants: names usable in the expressions (with their values).
  PointExpressions(int dim, std::map<std::string, double, std::less<>> constants);
  /// Registers an expression with `components` values (1: scalar, dim: vector); `where` prefixes
  /// errors ("scene.toml:12: key 'initial.phi'"). Returns its handle.
  /// `scalar_allowed`: a scalar expression is accepted for several components and gives each the
  /// same value (a Dirichlet entry of one listed component); otherwise a scalar for a vector is
  /// refused, never spread over components the user meant differently.
  int add(const std::string& expression, int components, std::string where, bool scalar_allowed = false);
  /// Compiles every registered expression (collective over comm). A compile error names the
  /// expression's key and carries lmeformc's message.
  void compile(MPI_Comm comm, std::ostream* log);
  /// Values of expression `handle` at x (components values).
  void evaluate(int handle, std::span<const double> x, std::span<double> out) const;
  /// Changes a constant's value for later evaluations (a load step's imposed displacement).
  void set_constant(const std::string& name, double value);
  [[nodiscard]] int components(int handle) const { return items_[static_cast<std::size_t>(handle)].components; }
  [[nodiscard]] bool empty() const noexcept { return items_.empty(); }

 private:
  struct Item {
    std::string expression;
    int components;
    std::string where;
    bool scalar_allowed = false;
  };
  int dim_;
  std::map<std::string, double, std::less<>> constants_;
  std::vector<Item> items_;
  const FormModule* module_ = nullptr;
  std::vector<double> constant_values_;
};

/// The generated form of errors of `unknown` (components 1 or dim) against `exact`: outputs
/// "l2" = ∫ |u − u_exact|² and "h1" = ∫ |∇u − ∇u_exact|² (dx, no axisymmetric weight).
[[nodiscard]] const FormModule& compile_error_form(int dim, const std::string& unknown, int components,
                                                   const std::string& exact,
                                                   const std::map<std::string, double, std::less<>>& constants,
                                                   const std::string& where, MPI_Comm comm, std::ostream* log);

/// An integral of a scene quantity: ∫ expression dx, or ds(part) when part is given.
struct QuantityIntegral {
  std::string expression;
  std::string part;       ///< "" : dx
  bool boundary = false;  ///< ds(part) ("" part: the whole boundary)
};

/// The generated form of the scene's integral quantities: outputs "q0", "q1", ... (energies, in
/// the order given), reading the problem's unknowns (names and shapes in order), x and the
/// constants. An expression that does not compile throws SceneError naming `where[i]`.
[[nodiscard]] const FormModule& compile_quantity_form(int dim, const std::vector<std::pair<std::string, int>>& unknowns,
                                                      const std::map<std::string, double, std::less<>>& constants,
                                                      const std::vector<QuantityIntegral>& integrals, const std::vector<std::string>& where,
                                                      MPI_Comm comm, std::ostream* log);

/// The generated form of a motion's kinematics at a point: point outputs "position" (y), "F"
/// (grad y) and "H" (hess y) of the vector unknown `deformation`.
[[nodiscard]] const FormModule& compile_kinematics_form(int dim, const std::string& deformation, MPI_Comm comm, std::ostream* log);

/// The generated form of the mean of a scalar field: output "integral" = ∫ u dx (dx, no
/// axisymmetric weight); its gradient is ∫ N_a dx.
[[nodiscard]] const FormModule& compile_integral_form(int dim, MPI_Comm comm, std::ostream* log);

}  // namespace lmeform::problems
