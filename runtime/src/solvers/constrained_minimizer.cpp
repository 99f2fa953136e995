#include "lmeform/constrained_minimizer.hpp"

#include <Eigen/Dense>

#include <algorithm>
#include <cmath>
#include <iomanip>
#include <limits>
#include <ostream>
#include <sstream>
#include <stdexcept>
#include <string_view>

namespace lmeform {

namespace {

/// A residual or tolerance for a message: 3 significant digits at any magnitude.
std::string scientific(double v) {
  std::ostringstream o;
  o << std::setprecision(3) << std::scientific << v;
  return o.str();
}

// Negative eigenvalues of the symmetric part of a small dense matrix.
PetscInt negative_count(const Eigen::MatrixXd& A) {
  if (A.size() == 0) return 0;
  const Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> eig(0.5 * (A + A.transpose()), Eigen::EigenvaluesOnly);
  return static_cast<PetscInt>((eig.eigenvalues().array() < 0).count());
}

}  // namespace

struct ConstrainedMinimizer::Evaluation {
  double energy = 0;              // the objective
  double model_energy = 0;        // Σ energy terms
  std::vector<double> values;     // C_i
  std::vector<double> residuals;  // C_i − c_i
  PetscVector energy_gradient;
  std::vector<PetscVector> gradients;  // ∇C_i, fixed dofs zeroed
};

ConstrainedMinimizer::ConstrainedMinimizer(Assembler& energy, std::vector<ScalarConstraint> constraints,
                                           ConstrainedMinimizerOptions options)
    : ConstrainedMinimizer(std::vector<Assembler*>{&energy}, std::move(constraints), options) {}

ConstrainedMinimizer::ConstrainedMinimizer(std::vector<Assembler*> energy_terms, std::vector<ScalarConstraint> constraints,
                                           ConstrainedMinimizerOptions options)
    : energy_(energy_terms.empty() ? nullptr : energy_terms.front()), energy_terms_(std::move(energy_terms)),
      constraints_(std::move(constraints)), options_(options),
      factorization_(energy_ != nullptr ? energy_->discretization().comm() : MPI_COMM_SELF, "constrained_") {
  if (energy_ == nullptr) throw std::invalid_argument("constrained minimizer: no energy");
  Assembler& energy = *energy_;
  for (const Assembler* term : energy_terms_) {
    if (term->block_size() != energy.block_size() || &term->discretization() != &energy.discretization())
      throw std::invalid_argument("energy term " + term->describe() + " does not share the discretization and dofs of " +
                                  energy.describe());
  }
  for (const auto& c : constraints_) {
    if (c.functional == nullptr) throw std::invalid_argument("constraint '" + c.name + "' has no functional");
    if (c.functional->block_size() != energy.block_size()) {
      throw std::invalid_argument("constraint '" + c.name + "' has " + std::to_string(c.functional->block_size()) +
                                  " dofs per node, the energy " + std::to_string(energy.block_size()));
    }
    if (!(c.scale > 0)) throw std::invalid_argument("constraint '" + c.name + "' needs a positive scale");
  }
  if (!(options_.penalty > 0)) throw std::invalid_argument("augmented Lagrangian penalty must be positive");
  hessian_ = energy.create_matrix();
  factorization_.set_log(options_.log);
}

void ConstrainedMinimizer::zero_fixed(Vec v) {
  if (fixed_.empty()) return;
  std::vector<PetscScalar> zeros(fixed_.size(), 0.0);
  LMEFORM_PETSC_CHECK(VecSetValues(v, static_cast<PetscInt>(fixed_.size()), fixed_.data(), zeros.data(), INSERT_VALUES));
  LMEFORM_PETSC_CHECK(VecAssemblyBegin(v));
  LMEFORM_PETSC_CHECK(VecAssemblyEnd(v));
}

void ConstrainedMinimizer::evaluate(Vec u, const std::vector<double>& sigma, bool with_matrix, Evaluation& ev) {
  const std::size_t k = constraints_.size();
  if (!ev.energy_gradient) {
    ev.energy_gradient = energy_->create_vector();
    ev.gradients.clear();
    for (std::size_t i = 0; i < k; ++i) ev.gradients.push_back(energy_->create_vector());
  }
  ev.model_energy = energy_->value_and_vector(u, ev.energy_gradient);
  for (std::size_t t = 1; t < energy_terms_.size(); ++t)
    ev.model_energy += energy_terms_[t]->add_value_and_vector(u, ev.energy_gradient, 1.0);
  ev.energy = ev.model_energy;
  if (proximal_.K != nullptr) {
    // (s/2) dᵀKd + E, gradient s K d + ∇E, d = u − c.
    if (!proximal_difference_) {
      proximal_difference_ = energy_->create_vector();
      proximal_product_ = energy_->create_vector();
    }
    LMEFORM_PETSC_CHECK(VecWAXPY(proximal_difference_, -1.0, proximal_.center, u));
    LMEFORM_PETSC_CHECK(MatMult(proximal_.K, proximal_difference_, proximal_product_));
    PetscScalar dKd = 0;
    LMEFORM_PETSC_CHECK(VecDot(proximal_difference_, proximal_product_, &dKd));
    LMEFORM_PETSC_CHECK(VecAXPY(ev.energy_gradient, proximal_.weight, proximal_product_));
    ev.energy = ev.model_energy + 0.5 * proximal_.weight * static_cast<double>(dKd);
  }
  zero_fixed(ev.energy_gradient);
  if (counters_ != nullptr) ++counters_->gradient_evaluations;
  ev.values.resize(k);
  ev.residuals.resize(k);
  for (std::size_t i = 0; i < k; ++i) {
    // Constraints are solved in scaled form (C_i − c_i)/scale_i, so that one penalty μ fits
    // constraints of very different sizes (an area ~ 1, a volume ~ 0.1, a moment ~ 0).
    const double scale = constraints_[i].scale;
    ev.values[i] = constraints_[i].functional->value_and_vector(u, ev.gradients[i]);
    ev.residuals[i] = (ev.values[i] - constraints_[i].target) / scale;
    LMEFORM_PETSC_CHECK(VecScale(ev.gradients[i], 1.0 / scale));
    zero_fixed(ev.gradients[i]);
  }
  if (with_matrix) assemble_hessian(u, sigma);
}

void ConstrainedMinimizer::assemble_hessian(Vec u, const std::vector<double>& sigma) {
  const std::size_t k = constraints_.size();
  const double t0 = MPI_Wtime();
  {
    // ∇²E − Σ σ_i ∇²C_i (+ s K) in one pass (linear constraints such as the volume add nothing).
    std::vector<Assembler::MatrixTerm> terms;
    for (Assembler* term : energy_terms_) terms.push_back({term, 1.0});
    for (std::size_t i = 0; i < k; ++i) terms.push_back({constraints_[i].functional, -sigma[i] / constraints_[i].scale});
    energy_->matrix_sum(u, terms, hessian_);
    if (proximal_.K != nullptr) LMEFORM_PETSC_CHECK(MatAXPY(hessian_, proximal_.weight, proximal_.K, SAME_NONZERO_PATTERN));
    // Fixed dofs: identity rows and columns, so the Newton step leaves them alone.
    LMEFORM_PETSC_CHECK(MatZeroRowsColumns(hessian_, static_cast<PetscInt>(fixed_.size()), fixed_.data(), 1.0, nullptr, nullptr));
  }
  if (counters_ != nullptr) {
    ++counters_->hessian_evaluations;
    counters_->seconds_hessian += MPI_Wtime() - t0;
  }
}

void ConstrainedMinimizer::factor(Mat A) {
  const double t0 = MPI_Wtime();
  factorization_.factor(A);
  if (counters_ != nullptr) counters_->seconds_factor += MPI_Wtime() - t0;
}

double ConstrainedMinimizer::factor_with_inertia_correction(const std::function<bool()>& inertia_acceptable) {
  // A factorization that failed (an exactly singular H) is shifted like one of the wrong inertia.
  auto acceptable = [&] { return !factorization_.failed() && (factorization_.negative_eigenvalues() < 0 || inertia_acceptable()); };
  factor(hessian_);
  if (!options_.inertia_correction || acceptable()) return 0;
  // The shift follows the diagonal (Marquardt's scaling): the Hessian's diagonal spans orders of
  // magnitude (ε/h⁴ on fine cells, 1/r near the axis), so a multiple of the identity would either
  // not reach the fine cells or swamp the coarse ones.
  if (!shift_scale_) shift_scale_ = energy_->create_vector();
  LMEFORM_PETSC_CHECK(MatGetDiagonal(hessian_, shift_scale_));
  LMEFORM_PETSC_CHECK(VecAbs(shift_scale_));
  PetscReal largest = 0;
  LMEFORM_PETSC_CHECK(VecMax(shift_scale_, nullptr, &largest));
  {
    PetscInt n = 0;
    PetscScalar* d = nullptr;
    LMEFORM_PETSC_CHECK(VecGetLocalSize(shift_scale_, &n));
    LMEFORM_PETSC_CHECK(VecGetArray(shift_scale_, &d));
    for (PetscInt i = 0; i < n; ++i) d[i] = std::max(static_cast<double>(d[i]), 1e-8 * static_cast<double>(largest));
    LMEFORM_PETSC_CHECK(VecRestoreArray(shift_scale_, &d));
  }
  PetscVector increment = energy_->create_vector();
  double delta = last_shift_ > 0 ? std::max(1e-8, last_shift_ / 4) : 1e-4, applied = 0;
  for (int attempt = 0; attempt < 16; ++attempt, delta *= 10) {
    LMEFORM_PETSC_CHECK(VecCopy(shift_scale_, increment));
    LMEFORM_PETSC_CHECK(VecScale(increment, delta - applied));
    LMEFORM_PETSC_CHECK(MatDiagonalSet(hessian_, increment, ADD_VALUES));
    applied = delta;
    factor(hessian_);
    if (counters_ != nullptr) ++counters_->inertia_corrections;
    if (acceptable()) {
      last_shift_ = delta;
      return delta;
    }
  }
  return -1;
}

void ConstrainedMinimizer::solve(Vec b, Vec x) {
  const double t0 = MPI_Wtime();
  factorization_.solve(b, x);
  if (counters_ != nullptr) counters_->seconds_factor += MPI_Wtime() - t0;
}

void ConstrainedMinimizer::log_iterate(const ConstrainedIterate& it) {
  if (options_.log == nullptr || energy_->discretization().rank() != 0) return;
  std::ostringstream line;
  line << std::setw(4) << it.stage << std::setw(5) << it.iteration << "  E " << std::setprecision(10) << std::setw(16)
       << it.energy << "  |grad| " << std::setprecision(3) << std::scientific << it.gradient_norm << "  |C| "
       << it.constraint_norm << std::defaultfloat << "  t " << std::fixed << std::setprecision(2) << it.seconds << " s";
  *options_.log << line.str() << std::endl;
}

ConstrainedResult ConstrainedMinimizer::minimize(Vec u, std::vector<double> multipliers) {
  const std::size_t k = constraints_.size();
  if (!multipliers.empty() && multipliers.size() != k)
    throw std::invalid_argument("constrained minimizer: wrong number of starting multipliers");
  start_time_ = MPI_Wtime();
  last_shift_ = 0;
  ConstrainedResult result;
  struct CountersScope {
    ConstrainedResult*& slot;
    ~CountersScope() { slot = nullptr; }
  } counters_scope{counters_};
  counters_ = &result;
  std::vector<double>& nu = multipliers;
  double mu = options_.penalty;

  Evaluation ev;
  if (nu.empty()) {
    // No estimate given. KKT-first starts from the least-squares multipliers of the start,
    // argmin |∇E − Σ ν_i ∇C_i|, which enter its first Hessian ∇²E − Σ ν_i ∇²C_i. The augmented
    // Lagrangian keeps ν = 0: its inner minimizations at a poor fixed estimate took 37 steps on the
    // 6124-node discocyte start (round 1, from zero: 17).
    nu.assign(k, 0.0);
    if (k > 0 && options_.kkt_first) {
      evaluate(u, nu, false, ev);
      Eigen::MatrixXd M(static_cast<Eigen::Index>(k), static_cast<Eigen::Index>(k));
      Eigen::VectorXd b(static_cast<Eigen::Index>(k));
      for (std::size_t i = 0; i < k; ++i) {
        PetscScalar d = 0;
        LMEFORM_PETSC_CHECK(VecDot(ev.gradients[i], ev.energy_gradient, &d));
        b[static_cast<Eigen::Index>(i)] = static_cast<double>(d);
        for (std::size_t j = 0; j < k; ++j) {
          LMEFORM_PETSC_CHECK(VecDot(ev.gradients[i], ev.gradients[j], &d));
          M(static_cast<Eigen::Index>(i), static_cast<Eigen::Index>(j)) = static_cast<double>(d);
        }
      }
      const Eigen::VectorXd x = M.completeOrthogonalDecomposition().solve(b);
      for (std::size_t i = 0; i < k; ++i)
        if (std::isfinite(x[static_cast<Eigen::Index>(i)])) nu[i] = x[static_cast<Eigen::Index>(i)];
    }
  }
  PetscVector step = energy_->create_vector(), rhs = energy_->create_vector(), trial = energy_->create_vector();
  std::vector<PetscVector> Z, Zt;  // H⁻¹∇C_i at the iterate and (for corrections) at a trial point

  auto relative_residual = [&](const Evaluation& e) {
    double m = 0;
    for (std::size_t i = 0; i < k; ++i) m = std::max(m, std::abs(e.residuals[i]));
    return m;
  };
  auto lagrangian_gradient = [&](const Evaluation& e, const std::vector<double>& sigma, Vec out) {
    LMEFORM_PETSC_CHECK(VecCopy(e.energy_gradient, out));
    for (std::size_t i = 0; i < k; ++i) LMEFORM_PETSC_CHECK(VecAXPY(out, -sigma[i], e.gradients[i]));
  };
  auto norm = [](Vec v) {
    PetscReal n = 0;
    LMEFORM_PETSC_CHECK(VecNorm(v, NORM_2, &n));
    return static_cast<double>(n);
  };
  auto dot = [](Vec a, Vec b) {
    PetscScalar d = 0;
    LMEFORM_PETSC_CHECK(VecDot(a, b, &d));
    return static_cast<double>(d);
  };
  // Z_i = H⁻¹ g_i with the current factorization, and the k×k matrix (g_i · Z_j): the Schur
  // complement Gᵀ H⁻¹ G of the KKT system, and μ times the Woodbury capacitance less I.
  auto inverse_gram = [&](const std::vector<PetscVector>& g, std::vector<PetscVector>& z) {
    if (z.size() < k)
      for (std::size_t i = z.size(); i < k; ++i) z.push_back(energy_->create_vector());
    Eigen::MatrixXd S(static_cast<Eigen::Index>(k), static_cast<Eigen::Index>(k));
    for (std::size_t i = 0; i < k; ++i) solve(g[i], z[i]);
    for (std::size_t i = 0; i < k; ++i)
      for (std::size_t j = 0; j < k; ++j) S(static_cast<Eigen::Index>(i), static_cast<Eigen::Index>(j)) = dot(g[i], z[j]);
    return S;
  };
  // L_A at an evaluated state (its residuals are already scaled).
  auto augmented_value = [&](const Evaluation& e) {
    double value = e.energy;
    for (std::size_t i = 0; i < k; ++i) value += -nu[i] * e.residuals[i] + e.residuals[i] * e.residuals[i] / (2 * mu);
    return value;
  };
  Evaluation trial_ev;  // the line search evaluates value and gradients at once: the accepted trial is the next state
  auto record = [&](const char* stage, int iteration, const Evaluation& e, double gradient_norm) {
    ConstrainedIterate it{stage, iteration, e.energy, gradient_norm, relative_residual(e), MPI_Wtime() - start_time_};
    result.history.push_back(it);
    log_iterate(it);
  };

  // Newton on the KKT system is damped by a line search on its residual; when that stalls (or
  // the state turns non-finite, which is then rolled back), the augmented Lagrangian resumes with
  // a 100x tighter tolerance (twice at most) and hands over to Newton again.
  double al_tolerance = options_.augmented_tolerance;
  PetscVector u_saved = energy_->create_vector();
  std::vector<double> sigma(nu);
  double seconds_newton = 0;
  for (int attempt = 0; attempt < 3; ++attempt) {
  // ---- Stage 1: augmented Lagrangian --------------------------------------------------------
  bool stage1_done = attempt == 0 && options_.kkt_first;
  double previous_residual = std::numeric_limits<double>::infinity();
  // Stage 1 keeps ev the evaluation at u (the multipliers do not enter it).
  if (!stage1_done) evaluate(u, sigma, false, ev);
  for (int outer = 0; !stage1_done && outer < options_.max_outer_iterations; ++outer) {
    ++result.outer_iterations;
    for (int inner = 0; inner < options_.max_inner_iterations; ++inner) {
      for (std::size_t i = 0; i < k; ++i) sigma[i] = nu[i] - ev.residuals[i] / mu;
      lagrangian_gradient(ev, sigma, rhs);
      const double gnorm = norm(rhs);
      record("AL", result.augmented_iterations, ev, gnorm);
      const double inner_target = std::max(options_.inner_tolerance, options_.inexact_inner * relative_residual(ev));
      if (gnorm <= inner_target * std::max(1.0, norm(ev.energy_gradient))) break;
      assemble_hessian(u, sigma);
      // Woodbury: (H + U Uᵀ)⁻¹ b with U_i = ∇C_i/√μ and the capacitance M = I + Uᵀ H⁻¹ U. By the
      // Haynsworth inertia formula H + U Uᵀ has neg(H) − neg(M) negative eigenvalues: the Newton
      // step minimizes L_A only when neg(M) = neg(H).
      Eigen::MatrixXd M;
      bool capacitance_current = false;
      auto capacitance = [&] {
        M = Eigen::MatrixXd::Identity(static_cast<Eigen::Index>(k), static_cast<Eigen::Index>(k)) + inverse_gram(ev.gradients, Z) / mu;
        capacitance_current = true;
        return negative_count(M) == factorization_.negative_eigenvalues();
      };
      if (factor_with_inertia_correction(capacitance) > 0) ++result.corrected_steps;
      if (!capacitance_current) capacitance();
      LMEFORM_PETSC_CHECK(VecScale(rhs, -1.0));
      solve(rhs, step);
      Eigen::VectorXd uty(static_cast<Eigen::Index>(k));
      for (std::size_t i = 0; i < k; ++i) uty[static_cast<Eigen::Index>(i)] = dot(ev.gradients[i], step) / mu;
      const Eigen::VectorXd coeff = M.lu().solve(uty);
      for (std::size_t i = 0; i < k; ++i) LMEFORM_PETSC_CHECK(VecAXPY(step, -coeff[static_cast<Eigen::Index>(i)], Z[i]));
      double slope = -dot(rhs, step);  // rhs holds −∇L_A
      if (!(slope < 0)) {
        // Not a descent direction (the Hessian is indefinite here): take steepest descent.
        LMEFORM_PETSC_CHECK(VecCopy(rhs, step));
        slope = -dot(rhs, rhs);
      }
      const double base = augmented_value(ev);
      double alpha = 1.0;
      bool accepted = false;
      for (int backtrack = 0; backtrack < 30; ++backtrack, alpha *= 0.5) {
        LMEFORM_PETSC_CHECK(VecWAXPY(trial, alpha, step, u));
        evaluate(trial, sigma, false, trial_ev);
        const double value = augmented_value(trial_ev);
        if (std::isfinite(value) && value <= base + 1e-4 * alpha * slope) {
          accepted = true;
          break;
        }
      }
      ++result.augmented_iterations;
      if (!accepted) break;  // no decrease possible along the step: at the inner minimum to round-off
      LMEFORM_PETSC_CHECK(VecCopy(trial, u));
      std::swap(ev, trial_ev);  // ev is the evaluation at u again
    }
    for (std::size_t i = 0; i < k; ++i) nu[i] -= ev.residuals[i] / mu;
    const double residual = relative_residual(ev);
    if (residual < al_tolerance) stage1_done = true;
    // Multiplier updates converge linearly at a rate set by μ: when the constraints stall,
    // stiffen the penalty (the Woodbury solve keeps the rank-k term exact however large 1/μ).
    if (residual > 0.25 * previous_residual) mu = std::max(mu * 0.1, 1e-12);
    previous_residual = residual;
  }
  result.seconds_augmented = MPI_Wtime() - start_time_ - seconds_newton;
  if (!stage1_done) {
    result.message = "augmented Lagrangian stage did not reach the constraint tolerance " + scientific(al_tolerance) +
                     " in " + std::to_string(options_.max_outer_iterations) + " multiplier updates";
    break;
  }
  LMEFORM_PETSC_CHECK(VecCopy(u, u_saved));
  const std::vector<double> nu_saved = nu;
  bool diverged = false, restore = false;
  std::string divergence;  // why stage 2 gave up, for the message
  double first_merit = 0;

  // ---- Stage 2: Newton on the KKT system, Schur complement on the multipliers ------------------
  const double stage2_start = MPI_Wtime();
  {
    evaluate(u, nu, false, ev);  // then kept current by the line search
    // The proximal gradient s K (u − c) is computed from positions of size |u|: its rounding error,
    // about eps · s · |K|∞ · |u|∞ per entry, is a floor under the attainable |∇L| (it dominates for
    // small time steps, s = 1/Δt large).
    double proximal_noise = 0;
    if (proximal_.K != nullptr) {
      PetscReal k_inf = 0, u_inf = 0;
      PetscInt n = 0;
      LMEFORM_PETSC_CHECK(MatNorm(proximal_.K, NORM_INFINITY, &k_inf));
      LMEFORM_PETSC_CHECK(VecNorm(u, NORM_INFINITY, &u_inf));
      LMEFORM_PETSC_CHECK(VecGetSize(u, &n));
      proximal_noise = 1e-15 * proximal_.weight * static_cast<double>(k_inf) * static_cast<double>(u_inf) *
                       std::sqrt(static_cast<double>(n));
    }
    int damped_steps = 0;         // consecutive steps the line search shortened
    double merit_penalty = 0;     // ρ of the penalty merit of shifted steps, raised as needed
    bool have_factor = false;     // a factorization of this minimize() exists
    bool hessian_current = false; // ... and it is the Hessian at u
    bool stale_failed = false;    // a step with a reused Hessian failed: refresh it
    double previous_merit = 0, first_scale = 1;
    for (int it = 0; it <= options_.max_newton_iterations; ++it) {
      lagrangian_gradient(ev, nu, rhs);
      const double gnorm = norm(rhs);
      record("KKT", it, ev, gnorm);
      const double scale = std::max(1.0, norm(ev.energy_gradient));
      // Divergence is judged on the whole KKT residual: a Newton step that restores the
      // constraints typically raises |∇L| for a step while the residual as a whole falls.
      const double merit = std::max(gnorm / scale, relative_residual(ev));
      if (it == 0) first_merit = merit, first_scale = scale;
      // A chord step (reused Hessian) that contracted slowly: measured on a prolate time step at
      // eps = 0.01, 25 chord iterations ended at |grad L| = 1e-6 against a tolerance of 2e-7 and
      // the step was rejected.
      if (it > 0 && have_factor && !hessian_current && merit > options_.stale_hessian_rate * previous_merit)
        stale_failed = true;
      previous_merit = merit;
      // The merit is relative to |∇E|, which itself explodes where the iterate folds a map
      // (det F → 0 in a Lagrangian energy): measured on prolate time steps, |∇L| and |∇E| grew
      // to 6e6 and 1e8 (about 1e2 in the converged steps) and each step ran all 25 iterations,
      // 200 s, before it was rejected. Such growth of |∇E| ends the iteration as a divergence.
      if (!std::isfinite(ev.energy) || !std::isfinite(gnorm) || (it > 0 && merit > 1e3 * std::max(first_merit, 1e-12)) ||
          scale > 1e4 * first_scale) {
        diverged = true;
        restore = true;
        if (!std::isfinite(ev.energy) || !std::isfinite(gnorm))
          divergence = "a non-finite energy or gradient at iteration " + std::to_string(it);
        else if (scale > 1e4 * first_scale)
          divergence = "|grad E| grew from " + scientific(first_scale) + " to " + scientific(scale) + " by iteration " +
                       std::to_string(it);
        else
          divergence = "the KKT residual grew 1000-fold by iteration " + std::to_string(it);
        break;
      }
      if (gnorm <= options_.newton_tolerance * scale + proximal_noise && relative_residual(ev) <= options_.constraint_tolerance) {
        result.converged = true;
        result.message = "converged";
        break;
      }
      if (it == options_.max_newton_iterations) {
        result.message = "KKT Newton did not converge in " + std::to_string(options_.max_newton_iterations) +
                         " iterations (|grad L| = " + scientific(gnorm) + ", tolerance " +
                         scientific(options_.newton_tolerance * scale + proximal_noise) + ")";
        // Started without the augmented Lagrangian from a poor start: let it take over from here.
        diverged = attempt == 0 && options_.kkt_first && options_.augmented_fallback;
        break;
      }
      // Schur complement on the multipliers: dφ = H⁻¹(−r1 + G dν), (Gᵀ H⁻¹ G) dν = −r + Gᵀ H⁻¹ r1.
      // By the Haynsworth inertia formula the KKT matrix has neg(H) + pos(S) negative eigenvalues,
      // S = Gᵀ H⁻¹ G; the step heads for a minimum (a positive definite reduced Hessian) only when
      // that is k.
      Eigen::MatrixXd S(static_cast<Eigen::Index>(k), static_cast<Eigen::Index>(k));
      bool schur_current = false;
      auto schur = [&] {
        S = inverse_gram(ev.gradients, Z);
        schur_current = true;
        return factorization_.negative_eigenvalues() + (static_cast<PetscInt>(k) - negative_count(S)) == static_cast<PetscInt>(k);
      };
      double shift = 0;
      if (!have_factor || stale_failed || options_.refresh_hessian_every_iteration) {
        assemble_hessian(u, nu);
        shift = factor_with_inertia_correction(schur);
        have_factor = hessian_current = true;
        stale_failed = false;
      } else {
        hessian_current = false;
      }
      if (shift < 0) {
        // No shift up to 1e11 |diag H| gave the right inertia: hand over to the augmented Lagrangian.
        diverged = true;
        divergence = factorization_.failed()
                         ? "the Hessian's factorization failed, shifted or not (" + factorization_.failure() + ")"
                         : "no diagonal shift gave the Hessian the inertia of a minimum (" +
                               std::to_string(factorization_.negative_eigenvalues()) + " negative pivots)";
        divergence += " at iteration " + std::to_string(it);
        break;
      }
      if (!schur_current) schur();
      const auto S_lu = S.fullPivLu();
      // The Hessian is badly scaled (ε/h⁴, 1/r near the axis), so the step is refined against the
      // true residual of the KKT system with the same factorization: without it Newton stalls at
      // a linear rate set by the solve error.
      // Solves H dφ − G dν = −f1, Gᵀ dφ = −f2 for (dφ, dν), accumulating into (step, dnu).
      LMEFORM_PETSC_CHECK(VecZeroEntries(step));
      Eigen::VectorXd dnu = Eigen::VectorXd::Zero(static_cast<Eigen::Index>(k));
      PetscVector f1 = energy_->create_vector(), a = energy_->create_vector(), Hstep = energy_->create_vector();
      LMEFORM_PETSC_CHECK(VecCopy(rhs, f1));
      Eigen::VectorXd f2(static_cast<Eigen::Index>(k));
      for (std::size_t i = 0; i < k; ++i) f2[static_cast<Eigen::Index>(i)] = ev.residuals[i];
      for (int refinement = 0; refinement < 3; ++refinement) {
        solve(f1, a);
        Eigen::VectorXd b(static_cast<Eigen::Index>(k));
        for (std::size_t i = 0; i < k; ++i) b[static_cast<Eigen::Index>(i)] = -f2[static_cast<Eigen::Index>(i)] + dot(ev.gradients[i], a);
        const Eigen::VectorXd delta_nu = k > 0 ? Eigen::VectorXd(S_lu.solve(b)) : Eigen::VectorXd();
        LMEFORM_PETSC_CHECK(VecAXPY(step, -1.0, a));
        for (std::size_t i = 0; i < k; ++i) LMEFORM_PETSC_CHECK(VecAXPY(step, delta_nu[static_cast<Eigen::Index>(i)], Z[i]));
        dnu += delta_nu;
        // Residual of the linear system at (step, dnu): f1 = r1 + H step − G dnu, f2 = r + Gᵀ step.
        LMEFORM_PETSC_CHECK(MatMult(hessian_, step, Hstep));
        LMEFORM_PETSC_CHECK(VecWAXPY(f1, 1.0, rhs, Hstep));
        for (std::size_t i = 0; i < k; ++i) LMEFORM_PETSC_CHECK(VecAXPY(f1, -dnu[static_cast<Eigen::Index>(i)], ev.gradients[i]));
        for (std::size_t i = 0; i < k; ++i) f2[static_cast<Eigen::Index>(i)] = ev.residuals[i] + dot(ev.gradients[i], step);
        if (norm(f1) <= 1e-14 * std::max(norm(rhs), 1e-300)) break;
      }
      // Damped Newton: the full step unless it fails to reduce the weighted KKT residual
      // m = (|∇L| / scale)² + Σ r_i², for which the Newton direction is a descent direction
      // (d/dα m = −2m). Without it, a nearly singular KKT matrix made Newton cycle between two
      // states (measured: a 1500-node discocyte at eps = 0.08, 25 steps without converging).
      auto kkt_merit = [&](const Evaluation& e, const std::vector<double>& sigma_trial) {
        lagrangian_gradient(e, sigma_trial, f1);  // f1 as scratch
        const double g = norm(f1) / scale;
        double m = g * g;
        for (const double r : e.residuals) m += r * r;
        return m;
      };
      double m0 = (gnorm / scale) * (gnorm / scale);
      for (const double r : ev.residuals) m0 += r * r;
      std::vector<double> nu_trial(k);
      double alpha = 1.0;
      bool accepted = false;
      // With the inertia checked, the Newton step is a descent direction of the penalty merit
      // P = E − ν⁺ᵀc + ρ/2 |c|² (ν⁺ = ν + dν) for ρ large enough: dP = ∇Eᵀd − ν⁺ᵀGᵀd + ρ cᵀGᵀd,
      // with Gᵀd = −c. The KKT residual merit, which accepts the full steps that restore the
      // constraints at the energy's expense, can stall where the KKT matrix is nearly singular
      // (measured: an oblate start at v = 0.7 stalled at |∇L| = 0.06, E = 11.45, a saddle above the
      // minimum at 10.86); a shifted step need not reduce it at all. So the residual merit judges
      // the full step, and P, when the step was shifted or the full step failed, the backtracking.
      const bool inertia_checked = hessian_current && factorization_.negative_eigenvalues() >= 0 && options_.inertia_correction;
      bool penalty_search = shift > 0;
      if (!penalty_search) {
        for (int backtrack = 0; backtrack < (inertia_checked ? 1 : 8); ++backtrack, alpha *= 0.5) {
          LMEFORM_PETSC_CHECK(VecWAXPY(trial, alpha, step, u));
          for (std::size_t i = 0; i < k; ++i) nu_trial[i] = nu[i] + alpha * dnu[static_cast<Eigen::Index>(i)];
          evaluate(trial, nu_trial, false, trial_ev);
          const double m = kkt_merit(trial_ev, nu_trial);
          if (std::isfinite(trial_ev.energy) && std::isfinite(m) && m <= (1.0 - 1e-4 * alpha) * m0) {
            accepted = true;
            break;
          }
        }
        penalty_search = !accepted && inertia_checked;
      }
      if (penalty_search) {
        if (shift > 0) ++result.corrected_steps;
        std::vector<double> nu_plus(k);
        for (std::size_t i = 0; i < k; ++i) nu_plus[i] = nu[i] + dnu[static_cast<Eigen::Index>(i)];
        double slope_energy = dot(ev.energy_gradient, step), slope_penalty = 0;
        for (std::size_t i = 0; i < k; ++i) {
          const double Gd = dot(ev.gradients[i], step);
          slope_energy -= nu_plus[i] * Gd;
          slope_penalty += ev.residuals[i] * Gd;
        }
        // ρ as in Nocedal & Wright (18.36): the merit must fall by at least half the step's
        // curvature and half its penalty decrease, dP ≤ −dᵀHd/2 + ρ cᵀGᵀd/2, so that the
        // constraints are not traded for energy.
        LMEFORM_PETSC_CHECK(MatMult(hessian_, step, Hstep));
        const double curvature = std::max(0.0, dot(step, Hstep));
        if (slope_penalty < 0)
          merit_penalty = std::max(merit_penalty, (slope_energy + 0.5 * curvature) / (-0.5 * slope_penalty));
        const double slope = slope_energy + merit_penalty * slope_penalty;
        auto penalty_merit = [&](const Evaluation& e) {
          double value = e.energy;
          for (std::size_t i = 0; i < k; ++i) value += -nu_plus[i] * e.residuals[i] + 0.5 * merit_penalty * e.residuals[i] * e.residuals[i];
          return value;
        };
        const double p0 = penalty_merit(ev);
        alpha = 1.0;
        for (int backtrack = 0; slope < 0 && backtrack < 30; ++backtrack, alpha *= 0.5) {
          LMEFORM_PETSC_CHECK(VecWAXPY(trial, alpha, step, u));
          for (std::size_t i = 0; i < k; ++i) nu_trial[i] = nu[i] + alpha * dnu[static_cast<Eigen::Index>(i)];
          evaluate(trial, nu_trial, false, trial_ev);
          const double p = penalty_merit(trial_ev);
          if (std::isfinite(p) && p <= p0 + 1e-4 * alpha * slope) {
            accepted = true;
            break;
          }
        }
        if (options_.log != nullptr && energy_->discretization().rank() == 0) {
          std::ostringstream line;
          line << "           penalty merit (rho " << std::setprecision(3) << merit_penalty << "): step " << alpha;
          if (shift > 0) line << ", Hessian shifted by " << shift << " |diag H| for the right inertia";
          if (!accepted) line << ", no decrease";
          *options_.log << line.str() << std::endl;
        }
      }
      damped_steps = accepted && alpha < 1.0 && shift == 0 ? damped_steps + 1 : 0;
      if ((!accepted || damped_steps >= 3) && !hessian_current) {
        // The reused Hessian is too far from the current one: refresh it and try again from here.
        stale_failed = true;
        damped_steps = 0;
        if (accepted) {
          LMEFORM_PETSC_CHECK(VecCopy(trial, u));
          nu = nu_trial;
          std::swap(ev, trial_ev);
          ++result.newton_iterations;
        }
        continue;
      }
      // Newton first is damped for many steps while the merit falls (measured: 6124 nodes, an
      // ellipsoid start, the augmented Lagrangian took over after three damped steps and needed 17
      // more; a dumbbell continuation stage at eps = 0.015 handed over after three damped steps,
      // and the augmented Lagrangian raised the constraint residual from 1e-4 to 4e-3 in 40 steps):
      // only a failed line search or max_newton_iterations ends it.
      const bool patient = attempt == 0 && options_.kkt_first && options_.augmented_fallback;
      if (!accepted || (damped_steps >= 3 && !patient)) {
        // No step along the Newton direction reduces the residual, or only short ones, three times
        // in a row: far from the quadratic regime. Back to the augmented Lagrangian (below).
        diverged = true;
        divergence = !accepted ? "no step along the Newton direction decreased the merit at iteration " + std::to_string(it) +
                                     (inertia_checked ? "" : " (inertia unknown)")
                               : "three damped steps in a row at iteration " + std::to_string(it);
        break;
      }
      // A step that raised the constraint residual (the constraints curve away from their
      // linearization) gets second-order corrections back onto them from the trial point t,
      // d₂ = −H⁻¹G_t (G_tᵀH⁻¹G_t)⁻¹ c(t): the least change in the metric of H with G_tᵀd₂ = −c(t),
      // with the factorization at hand (k solves and one evaluation each).
      for (int correction = 0; correction < 3 && k > 0; ++correction) {
        const double before = relative_residual(ev), after = relative_residual(trial_ev);
        if (after <= std::max(before, options_.constraint_tolerance)) break;
        const Eigen::MatrixXd St = inverse_gram(trial_ev.gradients, Zt);
        Eigen::VectorXd r(static_cast<Eigen::Index>(k));
        for (std::size_t i = 0; i < k; ++i) r[static_cast<Eigen::Index>(i)] = trial_ev.residuals[i];
        const Eigen::VectorXd y = St.fullPivLu().solve(r);
        LMEFORM_PETSC_CHECK(VecCopy(trial, a));  // a as scratch: the corrected state
        for (std::size_t j = 0; j < k; ++j) LMEFORM_PETSC_CHECK(VecAXPY(a, -y[static_cast<Eigen::Index>(j)], Zt[j]));
        Evaluation corrected;
        evaluate(a, nu_trial, false, corrected);
        if (!std::isfinite(corrected.energy) || relative_residual(corrected) >= after) break;
        LMEFORM_PETSC_CHECK(VecCopy(a, trial));
        std::swap(trial_ev, corrected);
        ++result.constraint_corrections;
      }
      LMEFORM_PETSC_CHECK(VecCopy(trial, u));
      nu = nu_trial;
      std::swap(ev, trial_ev);
      ++result.newton_iterations;
    }
  }
  seconds_newton += MPI_Wtime() - stage2_start;
  if (!diverged) break;
  // The line search keeps the KKT residual decreasing, so the state reached is kept (it holds the
  // constraints better, with better multipliers); only a non-finite one is rolled back.
  if (restore) {
    LMEFORM_PETSC_CHECK(VecCopy(u_saved, u));
    nu = nu_saved;
  }
  sigma = nu;
  evaluate(u, nu, false, ev);
  if (!options_.augmented_fallback) {
    result.message = "KKT Newton diverged or stalled: " + divergence;
    break;
  }
  al_tolerance *= 0.01;
  // Resumed from a nearly feasible KKT state, a penalty as soft as the cold start's lets the
  // constraints drift far beyond where they were (measured: 6e-15 → 3.8e-6 in five steps on a
  // prolate v = 0.7 at eps = 0.01): stiffen it with the tolerance.
  mu = std::min(mu, options_.penalty * al_tolerance / options_.augmented_tolerance);
  result.message = "KKT Newton diverged or stalled from the augmented Lagrangian's state: " + divergence;
  if (options_.log != nullptr && energy_->discretization().rank() == 0) {
    *options_.log << "KKT Newton diverged or stalled: back to the augmented Lagrangian with tolerance " << al_tolerance
                  << std::endl;
  }
  }
  result.seconds_newton = seconds_newton;
  result.energy = ev.model_energy;
  result.objective = ev.energy;
  result.constraint_values = ev.values;
  result.multipliers.resize(k);
  result.relative_residuals.resize(k);
  for (std::size_t i = 0; i < k; ++i) {
    result.multipliers[i] = nu[i] / constraints_[i].scale;  // back to physical units
    result.relative_residuals[i] = std::abs(ev.residuals[i]);
  }
  return result;
}

}  // namespace lmeform
