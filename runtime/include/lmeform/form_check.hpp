// The derivative checker of form kernels (generated or hand-written), on one background cell.
//
// Given a `kernel::FormKernels` descriptor, one cell (quadrature points, weights and a basis
// tabulation in the kernel jet layout) and a state (nodal unknowns, coefficients, quadrature data,
// constants), check_form measures what applies to the functional's kind:
//
//   energy, constraint (value E, gradient g, Hessian H):
//     (a) g against central differences of E;
//     (b) H against central differences of g, and the symmetry of H;
//     (c) Taylor remainders along a direction v over a geometric range of steps h:
//           r1(h) = |E(u+hv) - E(u) - h g.v|                 ~ h^2
//           r2(h) = |E(u+hv) - E(u) - h g.v - h^2/2 v.Hv|    ~ h^3
//           r3(h) = |g(u+hv) - g(u) - h H v|                 ~ h^2
//   residual (vector R(u; every test dof), Jacobian J):
//     (b) J against central differences of R; (c) r3 with R and J;
//     (d) linearity in the test function (below);
//   bilinear (matrix A), linear (vector l):
//     (d) linearity in the test (and trial) functions, (e) independence of the unknowns;
//   point outputs (values at the points, no derivatives):
//     (f) the kernel writes n_values finite values per point, and nothing beyond them.
//
// Boundary kernels (FormKernels::domain) are checked like cell kernels on a cell whose points carry
// outward normals (Cell::normals): derivatives with respect to nodal values hold for any unit
// vectors there, so the cell's own quadrature points serve.
//
// Slopes are least-squares fits of log r against log h over the smallest steps whose remainder
// stands clear of the round-off floor; a remainder at the floor for every step is "exact" (the
// functional is a polynomial of that degree along v).
//
// Linearity (d) is tested through the basis: scaling the basis column of node a by s while dividing
// the nodal values of node a (unknowns, coefficients) by s leaves every interpolated field unchanged,
// so a form linear in its test function must scale the entries of node a by s, and leave the others.
//
// Non-smooth integrands (abs, sign, min/max, if) have kinks: a perturbation that crosses one makes
// differences disagree with derivatives although the kernels are right. The checker scans every
// perturbation whose check fails (and the Taylor direction always) for a kink, by second differences
// of the kernel outputs that stay O(1) under refinement instead of decaying as the square of the
// spacing, and then re-checks on the kink-free side of it: a kink is reported, not a failure.
#pragma once

#include <lmeform/kernel.hpp>

#include <limits>
#include <string>
#include <vector>

namespace lmeform::formcheck {

/// One background cell: what the runtime hands a kernel, owned.
struct Cell {
  int dim = 0;
  int n = 0;             ///< nodes of the cell neighbourhood
  int nq = 0;            ///< quadrature points
  int basis_order = 0;   ///< derivative order present in `basis`
  std::vector<double> nodes;    ///< [n * dim]
  std::vector<double> weights;  ///< [nq]
  std::vector<double> points;   ///< [nq * dim]
  std::vector<double> basis;    ///< [nq * jet_size(dim, basis_order) * n]
  std::vector<double> normals;  ///< [nq * dim] unit normals for boundary kernels (empty: none)

  /// The same tabulation restricted to a lower derivative order (re-laid out per point).
  [[nodiscard]] Cell restricted(int order) const;
  /// Jet slot `slot` at point q of the nodal field f: sum_a B[q, slot, a] * nodal[a * stride + c].
  [[nodiscard]] double jet(int q, int slot, const double* nodal, int stride, int c) const;
};

/// Values that the kernels read besides the basis.
struct State {
  std::vector<double> unknowns;      ///< [n * dofs_per_node]
  std::vector<double> coefficients;  ///< [n * coefficient_components_per_node]
  std::vector<double> qdata;         ///< [nq * qdata_per_point]
  std::vector<double> constants;     ///< [n_constants]
};

/// Polynomial degree of the functional in its unknowns, when the caller knows it.
enum class Degree {
  detect,     ///< unknown: exact remainders are accepted (and must be mutually consistent)
  linear,     ///< every remainder must be exact
  quadratic,  ///< r1 must show slope 2, r2 and r3 must be exact
  nonlinear,  ///< every remainder must show its slope
};

struct Options {
  double fd_step = 1e-6;         ///< central-difference step, times dof_scales[i] for dof i
  std::vector<double> dof_scales;///< per-dof length scale of the unknowns (empty: 1 for every dof)
  double grad_tol = 1e-6;        ///< max |g - g_fd| / max|g|
  double hess_tol = 1e-6;        ///< max |H - H_fd| / max|H|
  double sym_tol = 1e-12;        ///< max |H - H^T| / max|H|
  double linearity_tol = 1e-10;  ///< linearity and state independence, relative to the output's size
  double taylor_h0 = 1e-1;       ///< largest Taylor step (the direction is given by the caller)
  int taylor_levels = 12;        ///< steps h0 * 2^-k, k = 0 .. levels-1
  double slope_tol = 0.2;        ///< a fitted slope may fall this far below the expected one
  Degree expect_degree = Degree::detect;
  bool detect_kinks = true;      ///< explain failures by kinks crossed (non-smooth integrands)
};

struct Remainder {
  std::vector<double> h;
  std::vector<double> r;
  std::vector<double> floor;  ///< round-off floor estimate at each h
  double slope = std::numeric_limits<double>::quiet_NaN();  ///< over the 5 smallest fitted h
  int points_used = 0;
  bool exact = false;         ///< r below 100*floor at every fitted h
  /// Steps >= h_limit cross a kink of a non-smooth integrand and are left out (infinity: none).
  double h_limit = std::numeric_limits<double>::infinity();
  [[nodiscard]] bool computed() const { return !h.empty(); }
};

/// A kink (or jump) of a non-smooth integrand crossed by a perturbation of the check.
struct Kink {
  std::string perturbation;  ///< "Taylor direction", "FD of the value", "FD of the gradient", ...
  int dof = -1;              ///< the dof a finite difference perturbs (-1: not a single dof)
  double t = 0.0;            ///< position along the perturbation (unknowns + t * direction)
  double jump = 0.0;         ///< size of the jump in the second differences of the outputs
  /// Relative error of the entry re-differenced on the kink-free side (NaN: not re-differenced).
  double recheck_error = std::numeric_limits<double>::quiet_NaN();
  std::string effect;        ///< what the checker did about it
};

/// One line per perturbation kind: finite differences of many dofs crossing kinks are summarised.
[[nodiscard]] std::vector<std::string> describe_kinks(const std::vector<Kink>& kinks);

struct Report {
  kernel::FunctionalKind kind = kernel::FunctionalKind::Energy;
  static constexpr double kNotApplicable = std::numeric_limits<double>::quiet_NaN();
  double value = kNotApplicable;                            ///< E(u) (energy, constraint)
  double grad_max = 0.0, grad_err = kNotApplicable;         ///< max |g|, max |g - g_fd| / max|g|
  double hess_max = 0.0, hess_err = kNotApplicable;         ///< max |H|, max |H - H_fd| / max|H|
  double hess_asym = kNotApplicable;                        ///< energy/constraint Hessians only
  double linearity_err = kNotApplicable;                    ///< residual, bilinear, linear
  double state_dependence = kNotApplicable;                 ///< bilinear, linear
  bool has_hessian = false;
  Remainder r1, r2, r3;  ///< r3 of a residual: |R(u+hv) - R(u) - h J v|
  std::vector<Kink> kinks;
  std::vector<std::string> notes;     ///< how a check was done where it deviated from the plan
  std::vector<std::string> failures;  ///< empty when every check passed
  [[nodiscard]] bool ok() const { return failures.empty(); }
  [[nodiscard]] std::string summary(const std::string& label) const;
};

/// Kernel calls on one cell (they allocate the workspace and zero the outputs). `vector` is the
/// gradient of an energy or constraint, the residual, or the linear form; `matrix` the Hessian,
/// the Jacobian or the bilinear form (row-major).
class Evaluator {
 public:
  Evaluator(const kernel::FormKernels& form, const Cell& cell, const State& state);
  [[nodiscard]] int ndofs() const { return ndofs_; }
  [[nodiscard]] double value(const std::vector<double>& u);
  [[nodiscard]] std::vector<double> vector(const std::vector<double>& u);
  [[nodiscard]] std::vector<double> matrix(const std::vector<double>& u);
  /// A point kernel's values, [nq * n_values]; throws std::runtime_error if it writes beyond them.
  [[nodiscard]] std::vector<double> point(const std::vector<double>& u);
  [[nodiscard]] const Cell& cell() const { return cell_; }
  [[nodiscard]] const kernel::FormKernels& form() const { return form_; }

 private:
  kernel::CellInputs inputs(const std::vector<double>& u);
  const kernel::FormKernels& form_;
  Cell cell_;
  State state_;
  std::vector<double> spacing_;  ///< per point, for a kernel that reads the node spacing
  std::vector<double> workspace_;
  int ndofs_ = 0;
};

/// Runs the checks that apply to form.kind at u = state.unknowns, Taylor remainders along
/// `direction` (ignored for bilinear and linear forms).
Report check_form(const kernel::FormKernels& form, const Cell& cell, const State& state,
                  const std::vector<double>& direction, const Options& options);

/// Least-squares slope of log(r) against log(h).
double fitted_slope(const std::vector<double>& h, const std::vector<double>& r);

}  // namespace lmeform::formcheck
