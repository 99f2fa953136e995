// Generic derivative checker for generated (or hand-written) form kernels.
//
// Given a `lmeform::kernel::FormKernels` descriptor, one background cell (quadrature points,
// weights and a basis tabulation in the kernel jet layout) and a state (nodal unknowns,
// coefficients, quadrature data, constants), the checker measures:
//   (a) the kernel gradient against central finite differences of the kernel value;
//   (b) the kernel Hessian against central finite differences of the kernel gradient,
//       and its symmetry;
//   (c) Taylor remainders along a direction v over a geometric range of steps h:
//         r1(h) = |E(u+hv) - E(u) - h g.v|                 ~ h^2
//         r2(h) = |E(u+hv) - E(u) - h g.v - h^2/2 v.Hv|    ~ h^3
//         r3(h) = |g(u+hv) - g(u) - h H v|                 ~ h^2
//       as least-squares slopes of log r against log h over the steps where r stands
//       clear of the round-off floor. A remainder that stays at the round-off floor over the
//       whole range is reported as "exact" (the functional is a polynomial of that degree).
#pragma once

#include <lmeform/kernel.hpp>

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

  /// The same tabulation restricted to a lower derivative order (re-laid out per point).
  [[nodiscard]] Cell restricted(int order) const;
  /// Value (slot 0), gradient (1..dim) or Hessian slot s of sum_a B[q,s,a] * f[a*stride + c].
  [[nodiscard]] double jet(int q, int slot, const double* nodal, int stride, int c) const;
};

/// Values that the kernels read besides the basis.
struct State {
  std::vector<double> unknowns;      ///< [n * dofs_per_node]
  std::vector<double> coefficients;  ///< [n * coefficient_components_per_node]
  std::vector<double> qdata;         ///< [nq * qdata_per_point]
  std::vector<double> constants;     ///< [n_constants]
};

struct Options {
  double fd_step = 1e-6;        ///< central-difference step (absolute, in units of the unknowns)
  double grad_tol = 1e-6;       ///< max |g - g_fd| / max|g|
  double hess_tol = 1e-6;       ///< max |H - H_fd| / max|H|
  double sym_tol = 1e-12;       ///< max |H - H^T| / max|H|
  double taylor_h0 = 1e-1;      ///< largest Taylor step (the direction is given by the caller)
  int taylor_levels = 12;       ///< steps h0 * 2^-k, k = 0 .. levels-1
  double slope_tol = 0.2;       ///< |fitted slope - expected| allowed
  /// Polynomial degree of the functional in the unknowns: 1 (linear), 2 (quadratic), or 0 for
  /// genuinely nonlinear. Selects which remainders must be exact and which must show slopes.
  int expect_degree = 0;
};

struct Remainder {
  std::vector<double> h;
  std::vector<double> r;
  std::vector<double> floor;  ///< round-off floor estimate at each h
  double slope = 0.0;         ///< fitted over the 5 smallest h with r > 100*floor
  int points_used = 0;
  bool exact = false;         ///< r below 100*floor at every h
};

struct Report {
  double energy = 0.0;
  double grad_max = 0.0, grad_err = 0.0;  ///< max |g|, max |g - g_fd| / max|g|
  double hess_max = 0.0, hess_err = 0.0;  ///< max |H|, max |H - H_fd| / max|H|
  double hess_asym = 0.0;
  bool has_hessian = false;
  Remainder r1, r2, r3;
  std::vector<std::string> failures;  ///< empty when every check passed
  [[nodiscard]] bool ok() const { return failures.empty(); }
  [[nodiscard]] std::string summary(const std::string& label) const;
};

/// Kernel calls on one cell (they allocate the workspace, zero the outputs).
class Evaluator {
 public:
  Evaluator(const kernel::FormKernels& form, const Cell& cell, const State& state);
  [[nodiscard]] int ndofs() const { return ndofs_; }
  [[nodiscard]] double value(const std::vector<double>& u);
  [[nodiscard]] std::vector<double> gradient(const std::vector<double>& u);
  [[nodiscard]] std::vector<double> hessian(const std::vector<double>& u);  ///< row-major
  [[nodiscard]] const Cell& cell() const { return cell_; }

 private:
  kernel::CellInputs inputs(const std::vector<double>& u);
  const kernel::FormKernels& form_;
  Cell cell_;
  State state_;
  std::vector<double> workspace_;
  int ndofs_ = 0;
};

/// Runs (a), (b), (c) at u = state.unknowns along `direction`.
Report check_form(const kernel::FormKernels& form, const Cell& cell, const State& state,
                  const std::vector<double>& direction, const Options& options);

/// Least-squares slope of log(r) against log(h).
double fitted_slope(const std::vector<double>& h, const std::vector<double>& r);

}  // namespace lmeform::formcheck
