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

void ConstrainedMinimizer::set_fixed_dofs(std::vector<PetscInt> dofs) {
  fixed_ = std::move(dofs);
  if (energy_ == nullptr) return;
  std::vector<int> coupled = coupled_components(energy_->discretization(), energy_->block_size(), fixed_);
  if (coupled == coupled_) return;
  // Another structure (fewer components, or all again): a new matrix, analysed afresh.
  coupled_ = std::move(coupled);
  factorization_.forget_matrix();
  hessian_ = energy_->create_matrix(Assembler::MatrixInsertion::Direct, coupled_);
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

double ConstrainedMinimizer::factor_with_inertia_correction(const std::function<bool(bool shifted)>& inertia_acceptable) {
  // A factorization that failed (an exactly singular H) is shifted like one of the wrong inertia.
  bool shifted = false;
  auto acceptable = [&] {
    return !factorization_.failed() && (factorization_.negative_eigenvalues() < 0 || inertia_acceptable(shifted));
  };
  factor(hessian_);
  // Without the correction the inertia is still judged: the predicate reports it (a plain
  // Newton iteration that converges to a saddle says so) and its product is needed for the step.
  if (!options_.inertia_correction) {
    (void)acceptable();
    return 0;
  }
  if (acceptable()) return 0;
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
  shifted = true;
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

// ---- One minimize(): its state and its stages ------------------------------------------------------

struct ConstrainedMinimizer::Run {
  Vec u = nullptr;
  std::vector<double> nu;          // multipliers of the scaled constraints
  double mu = 0;                   // augmented Lagrangian penalty
  double al_tolerance = 0;         // the augmented Lagrangian's constraint tolerance of this attempt
  int attempt = 0;                 // 0, then each resumption of the augmented Lagrangian
  Evaluation ev;                   // at u
  Evaluation trial_ev;             // the line search evaluates value and gradients at once: the accepted trial is the next state
  PetscVector step, rhs, trial, u_saved;
  std::vector<PetscVector> Z, Zt;  // H⁻¹∇C_i at the iterate and (for corrections) at a trial point
  std::vector<double> sigma;
  double seconds_newton = 0;
  ConstrainedResult result;
};

/// How the KKT stage ended when it did not converge.
struct ConstrainedMinimizer::KktOutcome {
  bool diverged = false;   // hand over to the augmented Lagrangian
  bool restore = false;    // the state turned non-finite: roll back to the stage's start
  std::string divergence;  // why, for the message
};

/// What a KKT Newton iteration carries to the next.
struct ConstrainedMinimizer::KktState {
  double proximal_noise = 0;     // rounding floor of the proximal gradient under |∇L|
  int damped_steps = 0;          // consecutive steps the line search shortened
  double merit_penalty = 0;      // ρ of the penalty merit of shifted steps, raised as needed
  bool have_factor = false;      // a factorization of this minimize() exists
  bool hessian_current = false;  // ... and it is the Hessian at u
  bool stale_failed = false;     // a step with a reused Hessian failed: refresh it
  double previous_merit = 0, first_merit = 0, first_scale = 1;
};

namespace {

double norm(Vec v) {
  PetscReal n = 0;
  LMEFORM_PETSC_CHECK(VecNorm(v, NORM_2, &n));
  return static_cast<double>(n);
}

double dot(Vec a, Vec b) {
  PetscScalar d = 0;
  LMEFORM_PETSC_CHECK(VecDot(a, b, &d));
  return static_cast<double>(d);
}

Eigen::Index index(std::size_t i) { return static_cast<Eigen::Index>(i); }

}  // namespace

double ConstrainedMinimizer::relative_residual(const Evaluation& e) const {
  double m = 0;
  for (std::size_t i = 0; i < constraints_.size(); ++i) m = std::max(m, std::abs(e.residuals[i]));
  return m;
}

void ConstrainedMinimizer::lagrangian_gradient(const Evaluation& e, const std::vector<double>& sigma, Vec out) const {
  LMEFORM_PETSC_CHECK(VecCopy(e.energy_gradient, out));
  for (std::size_t i = 0; i < constraints_.size(); ++i) LMEFORM_PETSC_CHECK(VecAXPY(out, -sigma[i], e.gradients[i]));
}

// Z_i = H⁻¹ g_i with the current factorization, and the k×k matrix (g_i · Z_j): the Schur
// complement Gᵀ H⁻¹ G of the KKT system, and μ times the Woodbury capacitance less I.
Eigen::MatrixXd ConstrainedMinimizer::inverse_gram(const std::vector<PetscVector>& g, std::vector<PetscVector>& z) {
  const std::size_t k = constraints_.size();
  for (std::size_t i = z.size(); i < k; ++i) z.push_back(energy_->create_vector());
  Eigen::MatrixXd S(index(k), index(k));
  // One solve for all k right-hand sides: MUMPS reads its factors once, not k times.
  std::vector<Vec> rhs(k), solutions(k);
  for (std::size_t i = 0; i < k; ++i) {
    rhs[i] = g[i];
    solutions[i] = z[i];
  }
  const double t0 = MPI_Wtime();
  factorization_.solve(rhs, solutions);
  if (counters_ != nullptr) counters_->seconds_factor += MPI_Wtime() - t0;
  for (std::size_t i = 0; i < k; ++i)
    for (std::size_t j = 0; j < k; ++j) S(index(i), index(j)) = dot(g[i], z[j]);
  return S;
}

// L_A at an evaluated state (its residuals are already scaled).
double ConstrainedMinimizer::augmented_value(const Run& run, const Evaluation& e) const {
  double value = e.energy;
  for (std::size_t i = 0; i < constraints_.size(); ++i)
    value += -run.nu[i] * e.residuals[i] + e.residuals[i] * e.residuals[i] / (2 * run.mu);
  return value;
}

void ConstrainedMinimizer::record(Run& run, const char* stage, int iteration, const Evaluation& e, double gradient_norm) {
  ConstrainedIterate it{stage, iteration, e.energy, gradient_norm, relative_residual(e), MPI_Wtime() - start_time_};
  run.result.history.push_back(it);
  log_iterate(it);
}

// No estimate given. KKT-first starts from the least-squares multipliers of the start,
// argmin |∇E − Σ ν_i ∇C_i|, which enter its first Hessian ∇²E − Σ ν_i ∇²C_i. The augmented
// Lagrangian keeps ν = 0: its inner minimizations at a poor fixed estimate took 37 steps on the
// 6124-node discocyte start (round 1, from zero: 17).
void ConstrainedMinimizer::start_multipliers(Run& run) {
  const std::size_t k = constraints_.size();
  run.nu.assign(k, 0.0);
  if (k == 0 || !options_.kkt_first) return;
  evaluate(run.u, run.nu, false, run.ev);
  Eigen::MatrixXd M(index(k), index(k));
  Eigen::VectorXd b(index(k));
  for (std::size_t i = 0; i < k; ++i) {
    b[index(i)] = dot(run.ev.gradients[i], run.ev.energy_gradient);
    for (std::size_t j = 0; j < k; ++j) M(index(i), index(j)) = dot(run.ev.gradients[i], run.ev.gradients[j]);
  }
  const Eigen::VectorXd x = M.completeOrthogonalDecomposition().solve(b);
  for (std::size_t i = 0; i < k; ++i)
    if (std::isfinite(x[index(i)])) run.nu[i] = x[index(i)];
}

// One Newton step on L_A at fixed multipliers, line-searched on L_A; false when no step decreases
// it (at the inner minimum to round-off). run.rhs holds ∇L_A.
bool ConstrainedMinimizer::augmented_newton_step(Run& run) {
  const std::size_t k = constraints_.size();
  Evaluation& ev = run.ev;
  assemble_hessian(run.u, run.sigma);
  // Woodbury: (H + U Uᵀ)⁻¹ b with U_i = ∇C_i/√μ and the capacitance M = I + Uᵀ H⁻¹ U. By the
  // Haynsworth inertia formula H + U Uᵀ has neg(H) − neg(M) negative eigenvalues: the Newton
  // step minimizes L_A only when neg(M) = neg(H).
  Eigen::MatrixXd M;
  bool capacitance_current = false;
  auto capacitance = [&](bool /*shifted*/ = true) {
    M = Eigen::MatrixXd::Identity(index(k), index(k)) + inverse_gram(ev.gradients, run.Z) / run.mu;
    capacitance_current = true;
    return negative_count(M) == factorization_.negative_eigenvalues();
  };
  if (factor_with_inertia_correction(capacitance) > 0) ++run.result.corrected_steps;
  if (!capacitance_current) capacitance();
  LMEFORM_PETSC_CHECK(VecScale(run.rhs, -1.0));
  solve(run.rhs, run.step);
  Eigen::VectorXd uty(index(k));
  for (std::size_t i = 0; i < k; ++i) uty[index(i)] = dot(ev.gradients[i], run.step) / run.mu;
  const Eigen::VectorXd coeff = M.lu().solve(uty);
  for (std::size_t i = 0; i < k; ++i) LMEFORM_PETSC_CHECK(VecAXPY(run.step, -coeff[index(i)], run.Z[i]));
  double slope = -dot(run.rhs, run.step);  // rhs holds −∇L_A
  if (!(slope < 0)) {
    // Not a descent direction (the Hessian is indefinite here): take steepest descent.
    LMEFORM_PETSC_CHECK(VecCopy(run.rhs, run.step));
    slope = -dot(run.rhs, run.rhs);
  }
  const double base = augmented_value(run, ev);
  double alpha = 1.0;
  bool accepted = false;
  for (int backtrack = 0; backtrack < 30; ++backtrack, alpha *= 0.5) {
    LMEFORM_PETSC_CHECK(VecWAXPY(run.trial, alpha, run.step, run.u));
    evaluate(run.trial, run.sigma, false, run.trial_ev);
    const double value = augmented_value(run, run.trial_ev);
    if (std::isfinite(value) && value <= base + 1e-4 * alpha * slope) {
      accepted = true;
      break;
    }
  }
  ++run.result.augmented_iterations;
  if (!accepted) return false;
  LMEFORM_PETSC_CHECK(VecCopy(run.trial, run.u));
  std::swap(ev, run.trial_ev);  // ev is the evaluation at u again
  return true;
}

// Stage 1: the augmented Lagrangian, multiplier updates until the constraints hold to
// al_tolerance. Keeps run.ev the evaluation at u (the multipliers do not enter it).
bool ConstrainedMinimizer::augmented_stage(Run& run) {
  const std::size_t k = constraints_.size();
  double previous_residual = std::numeric_limits<double>::infinity();
  evaluate(run.u, run.sigma, false, run.ev);
  for (int outer = 0; outer < options_.max_outer_iterations; ++outer) {
    ++run.result.outer_iterations;
    for (int inner = 0; inner < options_.max_inner_iterations; ++inner) {
      for (std::size_t i = 0; i < k; ++i) run.sigma[i] = run.nu[i] - run.ev.residuals[i] / run.mu;
      lagrangian_gradient(run.ev, run.sigma, run.rhs);
      const double gnorm = norm(run.rhs);
      record(run, "AL", run.result.augmented_iterations, run.ev, gnorm);
      const double inner_target = std::max(options_.inner_tolerance, options_.inexact_inner * relative_residual(run.ev));
      if (gnorm <= inner_target * std::max(1.0, norm(run.ev.energy_gradient))) break;
      if (!augmented_newton_step(run)) break;
    }
    for (std::size_t i = 0; i < k; ++i) run.nu[i] -= run.ev.residuals[i] / run.mu;
    const double residual = relative_residual(run.ev);
    // Multiplier updates converge linearly at a rate set by μ: when the constraints stall,
    // stiffen the penalty (the Woodbury solve keeps the rank-k term exact however large 1/μ).
    if (residual > 0.25 * previous_residual) run.mu = std::max(run.mu * 0.1, 1e-12);
    previous_residual = residual;
    if (residual < run.al_tolerance) return true;
  }
  return false;
}

// The proximal gradient s K (u − c) is computed from positions of size |u|: its rounding error,
// about eps · s · |K|∞ · |u|∞ per entry, is a floor under the attainable |∇L| (it dominates for
// small time steps, s = 1/Δt large).
double ConstrainedMinimizer::proximal_noise(Vec u) const {
  if (proximal_.K == nullptr) return 0;
  PetscReal k_inf = 0, u_inf = 0;
  PetscInt n = 0;
  LMEFORM_PETSC_CHECK(MatNorm(proximal_.K, NORM_INFINITY, &k_inf));
  LMEFORM_PETSC_CHECK(VecNorm(u, NORM_INFINITY, &u_inf));
  LMEFORM_PETSC_CHECK(VecGetSize(u, &n));
  return 1e-15 * proximal_.weight * static_cast<double>(k_inf) * static_cast<double>(u_inf) * std::sqrt(static_cast<double>(n));
}

// The KKT step by the Schur complement on the multipliers: dφ = H⁻¹(−r1 + G dν),
// (Gᵀ H⁻¹ G) dν = −r + Gᵀ H⁻¹ r1. The Hessian is badly scaled (ε/h⁴, 1/r near the axis), so the
// step is refined against the true residual of the KKT system with the same factorization:
// without it Newton stalls at a linear rate set by the solve error. Solves H dφ − G dν = −f1,
// Gᵀ dφ = −f2 for (dφ, dν) into (run.step, dnu); run.rhs holds ∇L.
Eigen::VectorXd ConstrainedMinimizer::kkt_step(Run& run, const Eigen::MatrixXd& S) {
  const std::size_t k = constraints_.size();
  const Evaluation& ev = run.ev;
  const auto S_lu = S.fullPivLu();
  LMEFORM_PETSC_CHECK(VecZeroEntries(run.step));
  Eigen::VectorXd dnu = Eigen::VectorXd::Zero(index(k));
  PetscVector f1 = energy_->create_vector(), a = energy_->create_vector(), Hstep = energy_->create_vector();
  LMEFORM_PETSC_CHECK(VecCopy(run.rhs, f1));
  Eigen::VectorXd f2(index(k));
  for (std::size_t i = 0; i < k; ++i) f2[index(i)] = ev.residuals[i];
  for (int refinement = 0; refinement < 3; ++refinement) {
    solve(f1, a);
    Eigen::VectorXd b(index(k));
    for (std::size_t i = 0; i < k; ++i) b[index(i)] = -f2[index(i)] + dot(ev.gradients[i], a);
    const Eigen::VectorXd delta_nu = k > 0 ? Eigen::VectorXd(S_lu.solve(b)) : Eigen::VectorXd();
    LMEFORM_PETSC_CHECK(VecAXPY(run.step, -1.0, a));
    for (std::size_t i = 0; i < k; ++i) LMEFORM_PETSC_CHECK(VecAXPY(run.step, delta_nu[index(i)], run.Z[i]));
    dnu += delta_nu;
    // Residual of the linear system at (step, dnu): f1 = r1 + H step − G dnu, f2 = r + Gᵀ step.
    LMEFORM_PETSC_CHECK(MatMult(hessian_, run.step, Hstep));
    LMEFORM_PETSC_CHECK(VecWAXPY(f1, 1.0, run.rhs, Hstep));
    for (std::size_t i = 0; i < k; ++i) LMEFORM_PETSC_CHECK(VecAXPY(f1, -dnu[index(i)], ev.gradients[i]));
    for (std::size_t i = 0; i < k; ++i) f2[index(i)] = ev.residuals[i] + dot(ev.gradients[i], run.step);
    if (norm(f1) <= 1e-14 * std::max(norm(run.rhs), 1e-300)) break;
  }
  return dnu;
}

// Damped Newton: the full step unless it fails to reduce the weighted KKT residual
// m = (|∇L| / scale)² + Σ r_i², for which the Newton direction is a descent direction
// (d/dα m = −2m). Without it, a nearly singular KKT matrix made Newton cycle between two states
// (measured: a 1500-node discocyte at eps = 0.08, 25 steps without converging). Returns whether a
// step was accepted (run.trial, nu_trial, run.trial_ev hold it) and its length.
bool ConstrainedMinimizer::residual_line_search(Run& run, const Eigen::VectorXd& dnu, double gnorm, double scale, int tries,
                                                std::vector<double>& nu_trial, double& alpha) {
  const std::size_t k = constraints_.size();
  PetscVector scratch = energy_->create_vector();
  auto kkt_merit = [&](const Evaluation& e, const std::vector<double>& sigma_trial) {
    lagrangian_gradient(e, sigma_trial, scratch);
    const double g = norm(scratch) / scale;
    double m = g * g;
    for (const double r : e.residuals) m += r * r;
    return m;
  };
  double m0 = (gnorm / scale) * (gnorm / scale);
  for (const double r : run.ev.residuals) m0 += r * r;
  alpha = 1.0;
  for (int backtrack = 0; backtrack < tries; ++backtrack, alpha *= 0.5) {
    LMEFORM_PETSC_CHECK(VecWAXPY(run.trial, alpha, run.step, run.u));
    for (std::size_t i = 0; i < k; ++i) nu_trial[i] = run.nu[i] + alpha * dnu[index(i)];
    evaluate(run.trial, nu_trial, false, run.trial_ev);
    const double m = kkt_merit(run.trial_ev, nu_trial);
    if (std::isfinite(run.trial_ev.energy) && std::isfinite(m) && m <= (1.0 - 1e-4 * alpha) * m0) return true;
  }
  return false;
}

// With the inertia checked, the Newton step is a descent direction of the penalty merit
// P = E − ν⁺ᵀc + ρ/2 |c|² (ν⁺ = ν + dν) for ρ large enough: dP = ∇Eᵀd − ν⁺ᵀGᵀd + ρ cᵀGᵀd, with
// Gᵀd = −c. ρ as in Nocedal & Wright (18.36): the merit must fall by at least half the step's
// curvature and half its penalty decrease, dP ≤ −dᵀHd/2 + ρ cᵀGᵀd/2, so that the constraints are
// not traded for energy.
bool ConstrainedMinimizer::penalty_line_search(Run& run, KktState& kkt, const Eigen::VectorXd& dnu, double shift,
                                               std::vector<double>& nu_trial, double& alpha) {
  const std::size_t k = constraints_.size();
  const Evaluation& ev = run.ev;
  if (shift > 0) ++run.result.corrected_steps;
  std::vector<double> nu_plus(k);
  for (std::size_t i = 0; i < k; ++i) nu_plus[i] = run.nu[i] + dnu[index(i)];
  double slope_energy = dot(ev.energy_gradient, run.step), slope_penalty = 0;
  for (std::size_t i = 0; i < k; ++i) {
    const double Gd = dot(ev.gradients[i], run.step);
    slope_energy -= nu_plus[i] * Gd;
    slope_penalty += ev.residuals[i] * Gd;
  }
  PetscVector Hstep = energy_->create_vector();
  LMEFORM_PETSC_CHECK(MatMult(hessian_, run.step, Hstep));
  const double curvature = std::max(0.0, dot(run.step, Hstep));
  if (slope_penalty < 0) kkt.merit_penalty = std::max(kkt.merit_penalty, (slope_energy + 0.5 * curvature) / (-0.5 * slope_penalty));
  const double slope = slope_energy + kkt.merit_penalty * slope_penalty;
  auto penalty_merit = [&](const Evaluation& e) {
    double value = e.energy;
    for (std::size_t i = 0; i < k; ++i) value += -nu_plus[i] * e.residuals[i] + 0.5 * kkt.merit_penalty * e.residuals[i] * e.residuals[i];
    return value;
  };
  const double p0 = penalty_merit(ev);
  bool accepted = false;
  alpha = 1.0;
  for (int backtrack = 0; slope < 0 && backtrack < 30; ++backtrack, alpha *= 0.5) {
    LMEFORM_PETSC_CHECK(VecWAXPY(run.trial, alpha, run.step, run.u));
    for (std::size_t i = 0; i < k; ++i) nu_trial[i] = run.nu[i] + alpha * dnu[index(i)];
    evaluate(run.trial, nu_trial, false, run.trial_ev);
    const double p = penalty_merit(run.trial_ev);
    if (std::isfinite(p) && p <= p0 + 1e-4 * alpha * slope) {
      accepted = true;
      break;
    }
  }
  if (options_.log != nullptr && energy_->discretization().rank() == 0) {
    std::ostringstream line;
    line << "           penalty merit (rho " << std::setprecision(3) << kkt.merit_penalty << "): step " << alpha;
    if (shift > 0) line << ", Hessian shifted by " << shift << " |diag H| for the right inertia";
    if (!accepted) line << ", no decrease";
    *options_.log << line.str() << std::endl;
  }
  return accepted;
}

// A step that raised the constraint residual (the constraints curve away from their
// linearization) gets second-order corrections back onto them from the trial point t,
// d₂ = −H⁻¹G_t (G_tᵀH⁻¹G_t)⁻¹ c(t): the least change in the metric of H with G_tᵀd₂ = −c(t),
// with the factorization at hand (k solves and one evaluation each).
void ConstrainedMinimizer::second_order_corrections(Run& run, const std::vector<double>& nu_trial) {
  const std::size_t k = constraints_.size();
  PetscVector corrected_state = energy_->create_vector();
  for (int correction = 0; correction < 3 && k > 0; ++correction) {
    const double before = relative_residual(run.ev), after = relative_residual(run.trial_ev);
    if (after <= std::max(before, options_.constraint_tolerance)) break;
    const Eigen::MatrixXd St = inverse_gram(run.trial_ev.gradients, run.Zt);
    Eigen::VectorXd r(index(k));
    for (std::size_t i = 0; i < k; ++i) r[index(i)] = run.trial_ev.residuals[i];
    const Eigen::VectorXd y = St.fullPivLu().solve(r);
    LMEFORM_PETSC_CHECK(VecCopy(run.trial, corrected_state));
    for (std::size_t j = 0; j < k; ++j) LMEFORM_PETSC_CHECK(VecAXPY(corrected_state, -y[index(j)], run.Zt[j]));
    Evaluation corrected;
    evaluate(corrected_state, nu_trial, false, corrected);
    if (!std::isfinite(corrected.energy) || relative_residual(corrected) >= after) break;
    LMEFORM_PETSC_CHECK(VecCopy(corrected_state, run.trial));
    std::swap(run.trial_ev, corrected);
    ++run.result.constraint_corrections;
  }
}

// Why the KKT iteration at `merit` (relative to |∇E| = scale) is diverging, or "" when it is not.
// The merit is relative to |∇E|, which itself explodes where the iterate folds a map (det F → 0 in
// a Lagrangian energy): measured on prolate time steps, |∇L| and |∇E| grew to 6e6 and 1e8 (about
// 1e2 in the converged steps) and each step ran all 25 iterations, 200 s, before it was rejected.
// Such growth of |∇E| ends the iteration as a divergence.
std::string ConstrainedMinimizer::kkt_divergence(const Run& run, const KktState& kkt, int it, double gnorm, double merit,
                                                 double scale) const {
  if (!std::isfinite(run.ev.energy) || !std::isfinite(gnorm)) return "a non-finite energy or gradient at iteration " + std::to_string(it);
  if (scale > 1e4 * kkt.first_scale)
    return "|grad E| grew from " + scientific(kkt.first_scale) + " to " + scientific(scale) + " by iteration " + std::to_string(it);
  if (it > 0 && merit > 1e3 * std::max(kkt.first_merit, 1e-12)) return "the KKT residual grew 1000-fold by iteration " + std::to_string(it);
  return {};
}

// Stage 2: Newton on the KKT system, damped by a line search on its residual (or the penalty
// merit), the Hessian refreshed every iteration or reused as a chord method.
ConstrainedMinimizer::KktOutcome ConstrainedMinimizer::kkt_stage(Run& run) {
  const std::size_t k = constraints_.size();
  KktOutcome out;
  KktState kkt;
  Evaluation& ev = run.ev;
  evaluate(run.u, run.nu, false, ev);  // then kept current by the line search
  kkt.proximal_noise = proximal_noise(run.u);
  for (int it = 0; it <= options_.max_newton_iterations; ++it) {
    lagrangian_gradient(ev, run.nu, run.rhs);
    const double gnorm = norm(run.rhs);
    record(run, "KKT", it, ev, gnorm);
    const double scale = std::max(1.0, norm(ev.energy_gradient));
    // Divergence is judged on the whole KKT residual: a Newton step that restores the
    // constraints typically raises |∇L| for a step while the residual as a whole falls.
    const double merit = std::max(gnorm / scale, relative_residual(ev));
    if (it == 0) kkt.first_merit = merit, kkt.first_scale = scale;
    // A chord step (reused Hessian) that contracted slowly: measured on a prolate time step at
    // eps = 0.01, 25 chord iterations ended at |grad L| = 1e-6 against a tolerance of 2e-7 and
    // the step was rejected.
    if (it > 0 && kkt.have_factor && !kkt.hessian_current && merit > options_.stale_hessian_rate * kkt.previous_merit)
      kkt.stale_failed = true;
    kkt.previous_merit = merit;
    if (const std::string why = kkt_divergence(run, kkt, it, gnorm, merit, scale); !why.empty()) {
      out.diverged = out.restore = true;
      out.divergence = why;
      return out;
    }
    if (gnorm <= options_.newton_tolerance * scale + kkt.proximal_noise && relative_residual(ev) <= options_.constraint_tolerance) {
      run.result.converged = true;
      run.result.message = "converged";
      return out;
    }
    if (it == options_.max_newton_iterations) {
      run.result.message = "KKT Newton did not converge in " + std::to_string(options_.max_newton_iterations) +
                           " iterations (|grad L| = " + scientific(gnorm) + ", tolerance " +
                           scientific(options_.newton_tolerance * scale + kkt.proximal_noise) + ")";
      // Started without the augmented Lagrangian from a poor start: let it take over from here.
      out.diverged = run.attempt == 0 && options_.kkt_first && options_.augmented_fallback;
      return out;
    }
    // By the Haynsworth inertia formula the KKT matrix has neg(H) + pos(S) negative eigenvalues,
    // S = Gᵀ H⁻¹ G; the step heads for a minimum (a positive definite reduced Hessian) only when
    // that is k.
    Eigen::MatrixXd S(index(k), index(k));
    bool schur_current = false;
    auto schur = [&](bool shifted = true) {
      S = inverse_gram(ev.gradients, run.Z);
      schur_current = true;
      // neg(H) − neg(S) is the number of negative eigenvalues of H on the constraints' tangent space.
      const PetscInt tangent_negative = factorization_.negative_eigenvalues() - negative_count(S);
      if (!shifted) run.result.negative_curvature_directions = static_cast<int>(std::max<PetscInt>(tangent_negative, 0));
      return tangent_negative == 0;
    };
    double shift = 0;
    if (!kkt.have_factor || kkt.stale_failed || options_.refresh_hessian_every_iteration) {
      assemble_hessian(run.u, run.nu);
      run.result.negative_curvature_directions = -1;  // unknown unless the factorization counts its pivots
      shift = factor_with_inertia_correction(schur);
      kkt.have_factor = kkt.hessian_current = true;
      kkt.stale_failed = false;
    } else {
      kkt.hessian_current = false;
    }
    if (shift < 0) {
      // No shift up to 1e11 |diag H| gave the right inertia: hand over to the augmented Lagrangian.
      out.diverged = true;
      out.divergence = factorization_.failed() ? "the Hessian's factorization failed, shifted or not (" + factorization_.failure() + ")"
                                               : "no diagonal shift gave the Hessian the inertia of a minimum (" +
                                                     std::to_string(factorization_.negative_eigenvalues()) + " negative pivots)";
      out.divergence += " at iteration " + std::to_string(it);
      return out;
    }
    if (!schur_current) schur();
    const Eigen::VectorXd dnu = kkt_step(run, S);
    std::vector<double> nu_trial(k);
    double alpha = 1.0;
    bool accepted = false;
    // The KKT residual merit, which accepts the full steps that restore the constraints at the
    // energy's expense, can stall where the KKT matrix is nearly singular (measured: an oblate
    // start at v = 0.7 stalled at |∇L| = 0.06, E = 11.45, a saddle above the minimum at 10.86); a
    // shifted step need not reduce it at all. So the residual merit judges the full step, and the
    // penalty merit, when the step was shifted or the full step failed, the backtracking.
    const bool inertia_checked = kkt.hessian_current && factorization_.negative_eigenvalues() >= 0 && options_.inertia_correction;
    bool penalty_search = shift > 0;
    if (!penalty_search) {
      accepted = residual_line_search(run, dnu, gnorm, scale, inertia_checked ? 1 : 8, nu_trial, alpha);
      penalty_search = !accepted && inertia_checked;
    }
    if (penalty_search) accepted = penalty_line_search(run, kkt, dnu, shift, nu_trial, alpha);
    kkt.damped_steps = accepted && alpha < 1.0 && shift == 0 ? kkt.damped_steps + 1 : 0;
    if ((!accepted || kkt.damped_steps >= 3) && !kkt.hessian_current) {
      // The reused Hessian is too far from the current one: refresh it and try again from here.
      kkt.stale_failed = true;
      kkt.damped_steps = 0;
      if (accepted) {
        LMEFORM_PETSC_CHECK(VecCopy(run.trial, run.u));
        run.nu = nu_trial;
        std::swap(ev, run.trial_ev);
        ++run.result.newton_iterations;
      }
      continue;
    }
    // Newton first is damped for many steps while the merit falls (measured: 6124 nodes, an
    // ellipsoid start, the augmented Lagrangian took over after three damped steps and needed 17
    // more; a dumbbell continuation stage at eps = 0.015 handed over after three damped steps,
    // and the augmented Lagrangian raised the constraint residual from 1e-4 to 4e-3 in 40 steps):
    // only a failed line search or max_newton_iterations ends it.
    const bool patient = run.attempt == 0 && options_.kkt_first && options_.augmented_fallback;
    if (!accepted || (kkt.damped_steps >= 3 && !patient)) {
      // No step along the Newton direction reduces the residual, or only short ones, three times
      // in a row: far from the quadratic regime. Back to the augmented Lagrangian.
      out.diverged = true;
      out.divergence = !accepted ? "no step along the Newton direction decreased the merit at iteration " + std::to_string(it) +
                                       (inertia_checked ? "" : " (inertia unknown)")
                                 : "three damped steps in a row at iteration " + std::to_string(it);
      return out;
    }
    second_order_corrections(run, nu_trial);
    LMEFORM_PETSC_CHECK(VecCopy(run.trial, run.u));
    run.nu = nu_trial;
    std::swap(ev, run.trial_ev);
    ++run.result.newton_iterations;
  }
  return out;
}

ConstrainedResult ConstrainedMinimizer::minimize(Vec u, std::vector<double> multipliers) {
  const std::size_t k = constraints_.size();
  if (!multipliers.empty() && multipliers.size() != k)
    throw std::invalid_argument("constrained minimizer: wrong number of starting multipliers");
  start_time_ = MPI_Wtime();
  last_shift_ = 0;
  Run run;
  struct CountersScope {
    ConstrainedResult*& slot;
    ~CountersScope() { slot = nullptr; }
  } counters_scope{counters_};
  counters_ = &run.result;
  run.u = u;
  run.nu = std::move(multipliers);
  run.mu = options_.penalty;
  if (run.nu.empty()) start_multipliers(run);
  run.step = energy_->create_vector();
  run.rhs = energy_->create_vector();
  run.trial = energy_->create_vector();
  run.u_saved = energy_->create_vector();
  run.sigma = run.nu;
  run.al_tolerance = options_.augmented_tolerance;

  // Newton on the KKT system is damped by a line search on its residual; when that stalls (or
  // the state turns non-finite, which is then rolled back), the augmented Lagrangian resumes with
  // a 100x tighter tolerance (twice at most) and hands over to Newton again.
  ConstrainedResult& result = run.result;
  for (run.attempt = 0; run.attempt < 3; ++run.attempt) {
    const bool stage1_done = (run.attempt == 0 && options_.kkt_first) || augmented_stage(run);
    result.seconds_augmented = MPI_Wtime() - start_time_ - run.seconds_newton;
    if (!stage1_done) {
      result.message = "augmented Lagrangian stage did not reach the constraint tolerance " + scientific(run.al_tolerance) + " in " +
                       std::to_string(options_.max_outer_iterations) + " multiplier updates";
      break;
    }
    LMEFORM_PETSC_CHECK(VecCopy(u, run.u_saved));
    const std::vector<double> nu_saved = run.nu;
    const double stage2_start = MPI_Wtime();
    const KktOutcome kkt = kkt_stage(run);
    run.seconds_newton += MPI_Wtime() - stage2_start;
    if (!kkt.diverged) break;
    // The line search keeps the KKT residual decreasing, so the state reached is kept (it holds the
    // constraints better, with better multipliers); only a non-finite one is rolled back.
    if (kkt.restore) {
      LMEFORM_PETSC_CHECK(VecCopy(run.u_saved, u));
      run.nu = nu_saved;
    }
    run.sigma = run.nu;
    evaluate(u, run.nu, false, run.ev);
    // A state whose energy or gradient is not finite (a kink evaluated on it, 0/0) gives the
    // augmented Lagrangian nothing to factor either: a failed solve, for the caller to handle.
    if (!std::isfinite(run.ev.energy) || !std::isfinite(norm(run.ev.energy_gradient))) {
      result.message = "the energy or its gradient is not finite at the state Newton started from (" + kkt.divergence + ")";
      break;
    }
    if (!options_.augmented_fallback) {
      result.message = "KKT Newton diverged or stalled: " + kkt.divergence;
      break;
    }
    run.al_tolerance *= 0.01;
    // Resumed from a nearly feasible KKT state, a penalty as soft as the cold start's lets the
    // constraints drift far beyond where they were (measured: 6e-15 → 3.8e-6 in five steps on a
    // prolate v = 0.7 at eps = 0.01): stiffen it with the tolerance.
    run.mu = std::min(run.mu, options_.penalty * run.al_tolerance / options_.augmented_tolerance);
    result.message = "KKT Newton diverged or stalled from the augmented Lagrangian's state: " + kkt.divergence;
    if (options_.log != nullptr && energy_->discretization().rank() == 0)
      *options_.log << "KKT Newton diverged or stalled: back to the augmented Lagrangian with tolerance " << run.al_tolerance << std::endl;
  }
  result.seconds_newton = run.seconds_newton;
  result.energy = run.ev.model_energy;
  result.objective = run.ev.energy;
  result.constraint_values = run.ev.values;
  result.multipliers.resize(k);
  result.relative_residuals.resize(k);
  for (std::size_t i = 0; i < k; ++i) {
    result.multipliers[i] = run.nu[i] / constraints_[i].scale;  // back to physical units
    result.relative_residuals[i] = std::abs(run.ev.residuals[i]);
  }
  return std::move(result);
}

}  // namespace lmeform
