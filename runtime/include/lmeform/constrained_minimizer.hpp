// Minimize an energy E(u) subject to scalar constraints C_i(u) = c_i and Dirichlet values
// (seed 3.9–3.12): Newton on the KKT system from the start (kkt_first), or first an augmented Lagrangian
//     L_A(u; ν) = E − Σ ν_i (C_i − c_i) + 1/(2μ) Σ (C_i − c_i)²
// minimized in u by Newton with a backtracking line search for frozen ν, with explicit
// multiplier updates ν_i ← ν_i − (C_i − c_i)/μ, to a coarse tolerance; then Newton on the KKT
// system in (u, ν). The dense rank-k terms are never assembled: the penalty's Σ ∇C_i ∇C_iᵀ/μ
// is handled by the Woodbury identity and the KKT system by a Schur complement on the k×k
// multiplier block, both reusing one sparse LU factorization of ∇²E − Σ σ_i ∇²C_i per iteration.
#pragma once

#include <Eigen/Core>

#include <functional>
#include <iosfwd>
#include <string>
#include <vector>

#include "lmeform/assembler.hpp"
#include "lmeform/petsc.hpp"
#include "lmeform/symmetric_factorization.hpp"

namespace lmeform {

struct ScalarConstraint {
  std::string name;        ///< e.g. "area"
  Assembler* functional;   ///< value / gradient / Hessian of C_i(u)
  double target = 0;       ///< c_i
  double scale = 1;        ///< |C_i − c_i| / scale is the relative residual
};

struct ConstrainedMinimizerOptions {
  double penalty = 1e-3;                ///< initial μ of the augmented Lagrangian (lowered ×0.1 when constraints stall)
  double augmented_tolerance = 1e-3;    ///< stage 1 ends when every relative constraint residual is below
  double inner_tolerance = 1e-6;        ///< stage 1 inner Newton: relative gradient norm of L_A
  /// Inexact inner solves: the inner Newton also stops once |∇L_A| / max(1, |∇E|) is below
  /// inexact_inner · max_i |r_i| — solving the inner problem more accurately than the constraints
  /// currently hold is wasted, and the bound tightens as they converge. 0: always inner_tolerance.
  double inexact_inner = 0.1;
  int max_outer_iterations = 40;
  int max_inner_iterations = 25;
  double newton_tolerance = 1e-9;       ///< stage 2: |∇L| / max(1, |∇E|)
  double constraint_tolerance = 1e-10;  ///< stage 2: relative constraint residuals
  int max_newton_iterations = 25;
  /// Newton on the KKT system from the first step, damped by the KKT-residual merit line search;
  /// the augmented Lagrangian only when that diverges, stalls or runs out of iterations. false:
  /// the augmented Lagrangian first, to augmented_tolerance, then KKT Newton. From an ellipsoid
  /// start (1500 nodes, v = 0.7, ε = 0.081) KKT-first took 14 Newton steps with a constraint
  /// residual falling at every step, against 24 + 2 with the residual rising from 8e-3 to 2.6e-2.
  bool kkt_first = true;
  /// When KKT Newton diverges or stalls (or, started first, runs out of iterations), resume the
  /// augmented Lagrangian (up to twice, 100x tighter each time). false: stop and report (a time
  /// step is cheaper to retry with a shorter step).
  bool augmented_fallback = true;
  /// KKT Newton: false assembles and factors the Hessian once per minimize() and reuses it (a
  /// chord method: cheaper iterations, linear convergence), refreshing it only when a step fails.
  bool refresh_hessian_every_iteration = true;
  /// With a reused Hessian: refresh it when a step shrank the KKT residual by less than this
  /// factor (the chord method's linear rate is then too slow to be cheaper than one assembly).
  /// 1 or more: refresh only on a failed step.
  double stale_hessian_rate = 0.5;
  /// Inertia-controlled Newton: the Hessian is factored as LDLᵀ, whose inertia says whether the
  /// Newton step heads for a minimum. When it does not (the KKT matrix must have exactly k negative
  /// eigenvalues; L_A's Hessian none), H + δ·|diag H| is factored instead, δ raised tenfold until
  /// the inertia is right, and the step is damped on the penalty merit E − νᵀc + ρ/2 |c|², for
  /// which it is then a descent direction. false: Newton steps on H as it is (round 1's solver).
  bool inertia_correction = true;
  std::ostream* log = nullptr;          ///< progress lines (rank 0); nullptr: silent
};

/// An added quadratic (s/2) (u − c)ᵀ K (u − c) with a fixed symmetric positive semi-definite K,
/// centre c and weight s: with s = 1/Δt, the objective of a variational time step
/// ½ (y − yⁿ)ᵀ K(yⁿ) (y − yⁿ) + Δt E(y), divided by Δt so that gradients and multipliers keep the
/// units of the energy. K must come from an Assembler of the energy's discretization and block
/// size (the same nonzero pattern). Both objects stay owned by the caller.
struct ProximalTerm {
  Mat K = nullptr;
  Vec center = nullptr;
  double weight = 1;
};

struct ConstrainedIterate {
  std::string stage;        ///< "AL" or "KKT"
  int iteration = 0;
  double energy = 0;            ///< the objective (with a proximal term: (s/2) dᵀKd + E)
  double gradient_norm = 0;     ///< of L_A (AL) or of the KKT residual (KKT)
  double constraint_norm = 0;   ///< max relative constraint residual
  double seconds = 0;           ///< since the start
};

struct ConstrainedResult {
  bool converged = false;
  std::string message;                  ///< why it stopped
  double energy = 0;                    ///< Σ energy terms at the result (without the proximal term)
  double objective = 0;                 ///< what was minimized (= energy without a proximal term)
  std::vector<double> multipliers;      ///< ν_i (e.g. tension for area, pressure for volume)
  std::vector<double> constraint_values;
  std::vector<double> relative_residuals;
  int augmented_iterations = 0;         ///< Newton steps in stage 1
  int outer_iterations = 0;             ///< multiplier updates
  int newton_iterations = 0;            ///< KKT steps
  int gradient_evaluations = 0;         ///< value + gradient passes (line-search trials included)
  int hessian_evaluations = 0;          ///< Hessian assemblies (each followed by one factorization)
  int inertia_corrections = 0;          ///< extra factorizations of H + δ·|diag H| (wrong inertia)
  int corrected_steps = 0;              ///< Newton steps taken with a shifted Hessian
  int constraint_corrections = 0;       ///< second-order corrections of steps that raised |c|
  /// Negative eigenvalues of the Lagrangian's Hessian on the constraints' tangent space, from the
  /// inertia of the last KKT Newton Hessian before any shift (the Hessian at the last iterate but
  /// one): 0 where the result is a minimum, > 0 at a saddle (a start that has the symmetry of the
  /// domain keeps it, and can converge to the symmetric saddle); -1 unknown (no KKT step, or no
  /// inertia from the factorization).
  int negative_curvature_directions = -1;
  double seconds_hessian = 0;           ///< of the total: Hessian assembly
  double seconds_factor = 0;            ///< of the total: factorizations and solves
  std::vector<ConstrainedIterate> history;
  double seconds_augmented = 0, seconds_newton = 0;
};

class ConstrainedMinimizer {
 public:
  ConstrainedMinimizer(Assembler& energy, std::vector<ScalarConstraint> constraints,
                       ConstrainedMinimizerOptions options = {});
  /// E = Σ terms (e.g. bending + adhesion), assembled term by term into one gradient and, in one
  /// pass, one Hessian; the terms share one discretization and dof layout.
  ConstrainedMinimizer(std::vector<Assembler*> energy_terms, std::vector<ScalarConstraint> constraints,
                       ConstrainedMinimizerOptions options = {});

  /// Dofs held at their current values in u (owned, global, renumbered).
  /// Components whose dofs are all fixed keep only their diagonal in the Hessian (create_matrix).
  void set_fixed_dofs(std::vector<PetscInt> dofs);
  /// Changes the target c_i of constraint i (a prescribed history such as a deflation).
  void set_target(std::size_t i, double target) { constraints_.at(i).target = target; }
  /// Adds (s/2) (u − c)ᵀ K (u − c) to the objective (see ProximalTerm); {} removes it.
  void set_proximal_term(ProximalTerm term) { proximal_ = term; }

  /// Minimizes from the state in u (which also holds the Dirichlet values); u is overwritten.
  /// `multipliers` (optional) are the starting ν, in the scaled units ν_i·scale_i. Never throws for non-convergence: the result
  /// says what failed and u holds the last state.
  ConstrainedResult minimize(Vec u, std::vector<double> multipliers = {});

 private:
  struct Evaluation;
  void evaluate(Vec u, const std::vector<double>& sigma, bool with_matrix, Evaluation& ev);
  void assemble_hessian(Vec u, const std::vector<double>& sigma);
  void factor(Mat A);
  double factor_with_inertia_correction(const std::function<bool(bool shifted)>& inertia_acceptable);
  void solve(Vec b, Vec x);
  void zero_fixed(Vec v);
  void log_iterate(const ConstrainedIterate& it);

  // One minimize(): its state, the augmented Lagrangian stage and the KKT Newton stage.
  struct Run;
  struct KktOutcome;
  struct KktState;
  [[nodiscard]] double relative_residual(const Evaluation& e) const;
  void lagrangian_gradient(const Evaluation& e, const std::vector<double>& sigma, Vec out) const;
  [[nodiscard]] Eigen::MatrixXd inverse_gram(const std::vector<PetscVector>& g, std::vector<PetscVector>& z);
  [[nodiscard]] double augmented_value(const Run& run, const Evaluation& e) const;
  void record(Run& run, const char* stage, int iteration, const Evaluation& e, double gradient_norm);
  void start_multipliers(Run& run);
  [[nodiscard]] bool augmented_newton_step(Run& run);
  [[nodiscard]] bool augmented_stage(Run& run);
  [[nodiscard]] double proximal_noise(Vec u) const;
  [[nodiscard]] Eigen::VectorXd kkt_step(Run& run, const Eigen::MatrixXd& S);
  [[nodiscard]] bool residual_line_search(Run& run, const Eigen::VectorXd& dnu, double gnorm, double scale, int tries,
                                          std::vector<double>& nu_trial, double& alpha);
  [[nodiscard]] bool penalty_line_search(Run& run, KktState& kkt, const Eigen::VectorXd& dnu, double shift, std::vector<double>& nu_trial,
                                         double& alpha);
  void second_order_corrections(Run& run, const std::vector<double>& nu_trial);
  [[nodiscard]] std::string kkt_divergence(const Run& run, const KktState& kkt, int it, double gnorm, double merit, double scale) const;
  [[nodiscard]] KktOutcome kkt_stage(Run& run);

  Assembler* energy_;                   // the first term: owns the layout (vectors, matrix)
  std::vector<Assembler*> energy_terms_;
  std::vector<ScalarConstraint> constraints_;
  ConstrainedMinimizerOptions options_;
  std::vector<PetscInt> fixed_;
  std::vector<int> coupled_;  ///< the Hessian's coupled components (empty: all)
  ProximalTerm proximal_;
  PetscVector proximal_difference_, proximal_product_;
  ConstrainedResult* counters_ = nullptr;  // the result being filled (evaluation counts and times)
  PetscMatrix hessian_;
  SymmetricFactorization factorization_;
  double last_shift_ = 0;               // δ of the last corrected factorization in this minimize()
  PetscVector shift_scale_;
  double start_time_ = 0;
};

}  // namespace lmeform
