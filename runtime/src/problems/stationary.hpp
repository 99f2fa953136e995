// One stationary solve of a bound problem on a node set: the problem space is built, the bound
// scene's stationary driver solves it (the constrained minimizer, SNES or KSP), and the errors
// against the scene's exact solutions are measured.
#pragma once

#include <mpi.h>

#include <limits>
#include <map>
#include <memory>
#include <string>
#include <vector>

#include "bound_scene.hpp"
#include "lmeform/constrained_minimizer.hpp"
#include "lmeform/delaunay.hpp"
#include "problem_space.hpp"
#include "report.hpp"

namespace lmeform::problems {

/// Error of one unknown against the scene's exact solution.
struct FieldError {
  std::string unknown;
  double l2 = 0;
  double h1 = 0;                             ///< semi-norm |∇(u − u_exact)|
  double h2 = std::numeric_limits<double>::quiet_NaN();  ///< semi-norm |∇∇(u − u_exact)|, when the basis has Hessians
};

struct ProblemResult {
  bool converged = false;
  std::string message;
  ConstrainedResult minimization;            ///< minimization problems (energy, multipliers, ...)
  double energy = 0;                         ///< Σ energies at the solution (NaN for other problems)
  double residual_norm = 0;                  ///< final |R| (residual problems) or |Au − b| / |b| (linear)
  int iterations = 0;                        ///< Newton / Krylov iterations
  NodeSet nodes;                             ///< original order
  BackgroundCells cells;                     ///< original numbering
  std::vector<double> state;                 ///< original order, dofs interleaved
  std::vector<double> gradient_norm;         ///< |∇u| of the first scalar unknown at the nodes (0 where fixed)
  std::vector<ReportField> point_fields;     ///< the point outputs at the nodes (when the scene writes fields)
  std::vector<std::string> constraint_names;
  std::vector<FieldError> errors;
  /// Bounded problems: the free dofs at their lower and upper bounds at the end (-1: no bounds).
  long active_lower = -1, active_upper = -1;
  /// A driver's own figures of the solve, by column (a staggered solve: alternations, and per group
  /// its Newton steps, assembly and solve seconds): a load-stepped run adds them to every step's row.
  std::vector<std::pair<std::string, double>> solver_figures;
  /// The scene's [quantities] at the solution, by column.
  std::vector<std::pair<std::string, double>> quantities;
  /// Each energy term ("module.output") and constraint (by name) at the state: filled by
  /// evaluate_only, and after a solve whose energy has several terms.
  std::map<std::string, double, std::less<>> values;
  double h_min = 0, h_mean = 0;
  double seconds_setup = 0, seconds_solve = 0;
  double seconds_assembly = 0;               ///< linear problems: assembly of A and b; saddle points: gradients and Hessians (in seconds_solve)
  long long matrix_nonzeros = 0;             ///< linear problems: non-zeros of the assembled matrix (all ranks)
  double seconds_factorization = 0;          ///< saddle points: the LDLᵀ factorizations and solves (in seconds_solve)
  /// Linear problems with zero-mean unknowns: how the level was fixed ("constraint": a bordered
  /// system, "null space": the Krylov method's null space + the mean removed afterwards).
  std::string zero_mean_method;
  /// Saddle points: negative eigenvalues of the last factored (reduced) Hessian, and how many a
  /// saddle that is a minimum in the other unknowns and a maximum in the maximized ones has (-1: unknown).
  long negative_eigenvalues = -1, expected_negative_eigenvalues = -1;
  /// The solve's discretization, for a later solve on the same nodes (ProblemInput::discretization).
  std::shared_ptr<Discretization> discretization;
};

/// One solve on input.nodes. Collective over comm. Throws for what cannot run (an LME evaluation
/// that fails, a linear solve that breaks down); a solver that does not converge is reported in the
/// result instead.
[[nodiscard]] ProblemResult solve_problem(MPI_Comm comm, const BoundScene& bound, const ProblemInput& input);

/// The fields of a solved state for output: each unknown, and |∇u| of the first scalar unknown;
/// a figure of that unknown when it is scalar.
[[nodiscard]] ReportFields state_fields(const StateLayout& layout, bool axisymmetric, const ProblemResult& result);

/// A nonlinear solve's outcome in a result.
void take_nonlinear_solve(const struct NonlinearSolve& solve, ProblemResult& result);

/// The closing rows and JSON keys of a solve of equations (residual, linear): the solver's message,
/// iterations and residual.
void describe_equation_solve(const ProblemResult& result, RunReport& report);

/// The closing row and JSON keys of the basis: its order, gamma, quadrature points per cell.
void describe_basis(const SceneNodes& nodes, RunReport& report);

/// The closing rows and JSON keys of the errors against exact solutions.
void describe_errors(const ProblemResult& result, RunReport& report);

}  // namespace lmeform::problems
