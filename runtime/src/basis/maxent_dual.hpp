// The dual problem every max-ent basis solves at a point: given, per neighbour a, a fixed exponent
// c_a and a vector of K constraint features phi_a (the first-order basis: phi_a = y_a; the
// second-order basis adds the second moments), find the multipliers mu minimising
//   ln Z(mu) = ln sum_a exp(c_a + mu . phi_a),
// whose gradient sum_a p_a phi_a vanishes exactly when the constraints hold. One implementation
// for both bases, so both get the same safeguards (log-sum-exp, descent checks, Armijo line
// search, polishing, the separating-plane certificate). Internal to lmeform_basis.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <iomanip>
#include <limits>
#include <span>
#include <sstream>
#include <string>
#include <type_traits>

#include <Eigen/Dense>

#include "lmeform/lme_basis.hpp"

namespace lmeform::detail {

inline constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();

template <int K>
struct MaxEntDual {
  using V = Eigen::Matrix<double, K, 1>;
  using M = Eigen::Matrix<double, K, K>;

  // ln Z at mu with a log-sum-exp shift; p and r = grad_mu ln Z = sum p_a phi_a as by-products.
  static double eval(int n, const double* phi, const double* c, const V& mu, double* p, V& r) {
    double fmax = -std::numeric_limits<double>::infinity();
    for (int a = 0; a < n; ++a) {
      const double f = c[a] + mu.dot(Eigen::Map<const V>(phi + a * K));
      p[a] = f;
      fmax = std::max(fmax, f);
    }
    double sum = 0.0;
    for (int a = 0; a < n; ++a) {
      p[a] = std::exp(p[a] - fmax);
      sum += p[a];
    }
    const double inv = 1.0 / sum;
    r.setZero();
    for (int a = 0; a < n; ++a) {
      p[a] *= inv;
      r += p[a] * Eigen::Map<const V>(phi + a * K);
    }
    return fmax + std::log(sum);
  }

  // Inverse of a symmetric matrix through LDLT with its reciprocal condition number; false when it
  // is not positive definite in floating point. (1x1 by hand: Eigen's LDLT trips gcc's -Warray-bounds.)
  static bool spd_inverse(const M& a, M& inv, double& rcond) {
    if constexpr (K == 1) {
      if (!(a(0, 0) > 0.0) || !std::isfinite(a(0, 0))) return false;
      inv(0, 0) = 1.0 / a(0, 0);
      rcond = 1.0;
      return true;
    } else {
      const Eigen::LDLT<M> ldlt(a);
      if (ldlt.info() != Eigen::Success || !ldlt.isPositive()) return false;
      inv = ldlt.solve(M::Identity());
      if constexpr (K <= 3) {
        rcond = ldlt.rcond();
      } else {
        // With the inverse at hand the L1 condition number is exact and cheap (and Eigen's
        // estimator trips gcc's -Wmaybe-uninitialized at these sizes).
        rcond = 1.0 / (a.cwiseAbs().colwise().sum().maxCoeff() * inv.cwiseAbs().colwise().sum().maxCoeff());
      }
      return inv.allFinite() && rcond > 0.0;
    }
  }

  // Largest u . phi_a over the neighbours for a unit direction u. If it is < -margin, no
  // non-negative weights can make sum p_a phi_a vanish: the constraints are infeasible (for
  // phi = y: every neighbour lies strictly on one side of a plane through x).
  static double max_projection(int n, const double* phi, const V& u) {
    double best = -std::numeric_limits<double>::infinity();
    for (int a = 0; a < n; ++a) best = std::max(best, u.dot(Eigen::Map<const V>(phi + a * K)));
    return best;
  }

  /// Safeguarded Newton on mu from mu = 0; leaves p at the solution. `infeasible(u, gnorm)` is
  /// called (and must throw) when a unit direction u certifies that the constraints cannot be met.
  template <class Infeasible>
  static V newton(std::span<const double> x, int n, const double* phi, const double* c, double* p,
                  const LmeOptions& opt, double& lnz, Infeasible&& infeasible) {
    const double tol = opt.newton_tolerance;
    V lam = V::Zero();
    V r;
    lnz = eval(n, phi, c, lam, p, r);
    double gnorm = r.norm();
    // Once ||r^|| <= tol, up to kPolish further Newton steps drive the error in lambda itself to
    // rounding: near the hull boundary J is nearly singular, and the derivative formulas (which
    // assume r = 0) amplify a residual r by J^-1, so a small gradient alone is not enough.
    constexpr int kPolish = 2;
    int polish = 0;
    for (int it = 0;; ++it) {
      const bool converged = gnorm <= tol;
      if (converged && polish >= kPolish) return lam;
      if (!converged && it >= opt.max_iterations) {
        std::ostringstream os;
        os << opt.max_iterations << " iterations, tolerance " << std::scientific << std::setprecision(1) << tol;
        throw LmeEvaluationError(LmeFailure::not_converged, x, static_cast<std::size_t>(n), gnorm, os.str());
      }
      if (!converged && it >= 2) {
        // A certificate, not a guess: all features strictly behind a hyperplane through 0.
        const double ln = lam.norm();
        if (ln > 0.0 && max_projection(n, phi, lam / ln) < -tol) infeasible(V(lam / ln), gnorm);
        if (max_projection(n, phi, -r / gnorm) < -tol) infeasible(V(-r / gnorm), gnorm);
      }
      M hess = -r * r.transpose();
      for (int a = 0; a < n; ++a) {
        const auto ya = Eigen::Map<const V>(phi + a * K);
        hess.noalias() += p[a] * ya * ya.transpose();
      }
      V dir;
      bool ok = false;
      {
        M inv = M::Zero();
        double rc = 0.0;
        if (spd_inverse(hess, inv, rc)) {
          dir = -(inv * r);
          ok = dir.allFinite() && r.dot(dir) < 0.0;
        }
      }
      if (converged) {
        if (!ok || dir.norm() <= 4.0 * std::numeric_limits<double>::epsilon() * (1.0 + lam.norm())) return lam;
        ++polish;
      }
      // J singular or indefinite in floating point (e.g. near a hull vertex): steepest descent,
      // which the line search below still globalises.
      if (!ok) dir = -r;
      bool accepted = false;
      V lam_t, r_t;
      double lnz_t = lnz;
      // A steepest-descent step (expand = true) that is accepted in full is doubled while ln Z keeps
      // falling: where one neighbour carries all the weight ln Z is linear in mu, J vanishes, and
      // unit steps of -r crawl (measured: a facet point collinear with a far and a near node of its
      // list, the dual Newton at 300 iterations with ||r|| stuck at 9.4e-2; with doubling, 13-15).
      auto line_search = [&](const V& d, bool expand) {
        const double slope = r.dot(d);
        double t = 1.0;
        for (int ls = 0; ls < 60; ++ls, t *= 0.5) {
          lam_t = lam + t * d;
          lnz_t = eval(n, phi, c, lam_t, p, r_t);
          if (lnz_t <= lnz + 1e-4 * t * slope) {
            if (!expand || ls > 0) return true;
            for (int grow = 0; grow < 60; ++grow) {
              const V lam_2 = lam + 2.0 * t * d;
              V r_2;
              const double lnz_2 = eval(n, phi, c, lam_2, p, r_2);
              if (!(lnz_2 < lnz_t && lnz_2 <= lnz + 2e-4 * t * slope)) break;
              t *= 2.0;
              lam_t = lam_2;
              lnz_t = lnz_2;
              r_t = r_2;
            }
            // p belongs to the last trial: evaluate the accepted point again.
            lnz_t = eval(n, phi, c, lam_t, p, r_t);
            return true;
          }
          // Near the minimum ln Z is flat to rounding: then the gradient norm decides.
          if (std::abs(lnz_t - lnz) <= 8.0 * std::numeric_limits<double>::epsilon() * (1.0 + std::abs(lnz)) &&
              r_t.norm() <= gnorm)
            return true;
          if (converged) return false;  // polishing is best effort: no backtracking
        }
        return false;
      };
      accepted = line_search(dir, !ok && !converged);
      // With the weight on one or two neighbours J is nearly singular and the rounding in
      // sum p_a y_a y_a^T - r r^T can spoil the Newton direction (measured: a point of a long cell
      // between a fine and a coarse node set); steepest descent still decreases ln Z.
      if (!accepted && ok && !converged) accepted = line_search(-r, true);
      if (!accepted) {
        if (converged) {
          // p was overwritten by the rejected trial: restore the converged state.
          lnz = eval(n, phi, c, lam, p, r);
          return lam;
        }
        throw LmeEvaluationError(LmeFailure::not_converged, x, static_cast<std::size_t>(n), gnorm,
                                 "line search stalled after " + std::to_string(it) + " iterations");
      }
      lam = lam_t;
      lnz = lnz_t;
      r = r_t;
      gnorm = r.norm();
    }
  }
};

// Scaled relative coordinates y^_a = (x - x_a)/l, beta^_a = beta_a l^2; returns l.
// coords / beta: of every node index the list may hold (nodes, then mirror images).
template <int D>
double scaled_neighbourhood(const double* coords, const double* beta, std::span<const double> x,
                            std::span<const int> nbrs, LmeWorkspace& ws) {
  const auto n = nbrs.size();
  ws.y.resize(n * D);
  ws.beta.resize(n);
  ws.c.resize(n);
  ws.p.resize(n);
  double sum2 = 0.0;
  for (std::size_t a = 0; a < n; ++a) {
    const auto b = static_cast<std::size_t>(nbrs[a]);
    for (int i = 0; i < D; ++i) {
      const double d = x[static_cast<std::size_t>(i)] - coords[b * D + static_cast<std::size_t>(i)];
      ws.y[a * D + static_cast<std::size_t>(i)] = d;
      sum2 += d * d;
    }
  }
  const double len = std::sqrt(sum2 / static_cast<double>(n));
  if (!(len > 0.0)) return 0.0;
  const double inv = 1.0 / len;
  for (std::size_t a = 0; a < n; ++a) {
    double r2 = 0.0;
    for (int i = 0; i < D; ++i) {
      double& v = ws.y[a * D + static_cast<std::size_t>(i)];
      v *= inv;
      r2 += v * v;
    }
    ws.beta[a] = beta[static_cast<std::size_t>(nbrs[a])] * len * len;
    ws.c[a] = -ws.beta[a] * r2;
  }
  return len;
}

// Refuses neighbourhoods with fewer than D + 1 nodes or affinely degenerate ones (collinear in 2D,
// coplanar in 3D), where no basis exists.
template <int D>
void check_affine_geometry(std::span<const double> x, int n, double len, const LmeWorkspace& ws,
                           const LmeOptions& opt) {
  using V = Eigen::Matrix<double, D, 1>;
  using M = Eigen::Matrix<double, D, D>;
  if (n < D + 1) {
    throw LmeEvaluationError(LmeFailure::too_few_neighbours, x, static_cast<std::size_t>(n), kNaN,
                             "got " + std::to_string(n) + ", need " + std::to_string(D + 1));
  }
  if (!(len > 0.0)) {
    throw LmeEvaluationError(LmeFailure::degenerate, x, static_cast<std::size_t>(n), kNaN,
                             "all neighbours coincide with x");
  }
  V mean = V::Zero();
  for (int a = 0; a < n; ++a) mean += Eigen::Map<const V>(ws.y.data() + a * D);
  mean /= n;
  M cov = M::Zero();
  for (int a = 0; a < n; ++a) {
    const V d = Eigen::Map<const V>(ws.y.data() + a * D) - mean;
    cov += d * d.transpose();
  }
  double lo = 0.0, hi = 0.0;
  if constexpr (D == 1) {
    lo = hi = cov(0, 0);
  } else {
    const Eigen::SelfAdjointEigenSolver<M> es(cov, Eigen::EigenvaluesOnly);
    lo = es.eigenvalues()(0);
    hi = es.eigenvalues()(D - 1);
  }
  const double tol = opt.degeneracy_tolerance;
  if (!(hi > 0.0) || !(lo > tol * tol * hi)) {
    std::ostringstream os;
    os.precision(3);
    os << "thickness/extent = " << std::scientific << std::sqrt(std::max(lo, 0.0) / std::max(hi, 1e-300))
       << " <= " << tol;
    throw LmeEvaluationError(LmeFailure::degenerate, x, static_cast<std::size_t>(n), kNaN, os.str());
  }
}

template <class F>
decltype(auto) dispatch(int dim, F&& f) {
  switch (dim) {
    case 1: return f(std::integral_constant<int, 1>{});
    case 2: return f(std::integral_constant<int, 2>{});
    default: return f(std::integral_constant<int, 3>{});
  }
}

}  // namespace lmeform::detail
