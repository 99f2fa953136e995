#include "dynamics_integrator.hpp"

#include <Eigen/Dense>

#include <algorithm>
#include <cmath>
#include <limits>
#include <set>

#include <fmt/format.h>

#include "dynamics_reference.hpp"
#include "lmeform/constrained_minimizer.hpp"
#include "membrane_topology.hpp"
#include "vesicle.hpp"
#include "lmeform/delaunay.hpp"
#include "lmeform/petsc.hpp"

namespace lmeform::problems {

namespace {

void zero_dofs(Vec v, const std::vector<PetscInt>& dofs) {
  std::vector<PetscScalar> zeros(dofs.size(), 0.0);
  if (!dofs.empty())
    LMEFORM_PETSC_CHECK(VecSetValues(v, static_cast<PetscInt>(dofs.size()), dofs.data(), zeros.data(), INSERT_VALUES));
  LMEFORM_PETSC_CHECK(VecAssemblyBegin(v));
  LMEFORM_PETSC_CHECK(VecAssemblyEnd(v));
}

double dot(Vec a, Vec b) {
  PetscScalar d = 0;
  LMEFORM_PETSC_CHECK(VecDot(a, b, &d));
  return static_cast<double>(d);
}

std::map<std::string, FieldJets> field_jets(const BoundScene& b) {
  std::map<std::string, FieldJets> jets;
  for (const auto& q : b.qdata) {
    if (q.source != SceneQdata::Source::field) continue;
    FieldJets& j = jets[q.field];
    (q.derivative == 0 ? j.value : q.derivative == 1 ? j.gradient : j.hessian) = q.name;
  }
  return jets;
}

}  // namespace

struct DynamicsIntegrator::Attempt {
  bool ok = false;
  bool folded = false;
  std::string why;
  ConstrainedResult result;
  DeformationMeasures measures;
};

DynamicsIntegrator::DynamicsIntegrator(MPI_Comm comm, const Scene& scene, const DynamicsSettings& settings, const DynamicsOutput* output,
                                       std::ostream* log)
    : comm_(comm), scene_(scene), settings_(settings), output_(output), log_(log) {
  MPI_Comm_rank(comm, &rank_);
  out_ = rank_ == 0 ? log : nullptr;
  OutputRoles extra;
  extra.auxiliary = {settings.dissipation};
  bound_ = bind_scene(scene, comm, log, extra);
  dim_ = scene.dim();
  bs_ = bound_.layout.dofs_per_node;
  euler_ = settings.method == DynamicsSettings::Method::forward_euler;
  resets_ = settings.reset_every > 0 || settings.reset_distortion > 0;
  jets_ = field_jets(bound_);
  check_scene(scene, settings, bound_);
  if (output != nullptr) {
    checkpoint_path_ = output->directory / (output->name + "_checkpoint.h5");
    quadrature_path_ = output->directory / (output->name + "_checkpoint_quadrature.h5");
    history_path_ = output->directory / (output->name + "_history.json");
    series_.emplace(output->directory, output->name);
  }
}

DynamicsIntegrator::~DynamicsIntegrator() = default;

/// What the integrator needs of the bound scene: energies, a vector deformation as the only
/// unknown, a dissipation reading it, schedules of known constants, jets a reset can push forward.
void DynamicsIntegrator::check_scene(const Scene& scene, const DynamicsSettings& settings, const BoundScene& bound) {
  const int dim = scene.dim();
  if (bound.energy.empty())
    throw SceneError(fmt::format("{}: [dynamics] moves the minimizer of energies: name energies in model.energy", scene.source));
  const auto& fields = bound.layout.fields;
  if (fields.size() != 1 || fields.front().name != settings.deformation || fields.front().components != dim)
    throw SceneError(fmt::format("{}: key 'dynamics.deformation': '{}' must be the problem's only unknown, a vector of {} components (the "
                                 "current positions y of the reference points)",
                                 scene.source, settings.deformation, dim));
  const kernel::FormKernels& dissipation = bound.auxiliary.front().first();
  bool reads_deformation = false;
  for (int i = 0; i < dissipation.n_coefficients; ++i) reads_deformation |= dissipation.coefficients[i].name == settings.deformation;
  if (!reads_deformation)
    throw SceneError(fmt::format("{}: the dissipation {}.{} does not read the deformation as `coefficient {} : vector`",
                                 settings.dissipation.where, dissipation.module, dissipation.name, settings.deformation));
  std::vector<std::string> names;
  for (const auto& [n, v] : bound.constants) names.push_back(n);
  for (const auto& c : settings.schedule)
    if (!bound.constants.contains(c.name))
      throw SceneError(fmt::format("{}: '{}' is no constant of the forms{}", c.where, c.name, did_you_mean(c.name, names)));
  if (settings.remesh_every > 0 &&
      std::none_of(bound.coefficient_fields.begin(), bound.coefficient_fields.end(),
                   [&](const UnknownField& c) { return c.name == settings.remesh_field && c.components == 1; }))
    throw SceneError(fmt::format("{}: key 'dynamics.remesh_field': '{}' is no scalar field of [coefficients] (the re-mesh adapts the "
                                 "nodes to its gradient)",
                                 scene.source, settings.remesh_field));
  const bool has_topology_field = std::any_of(bound.coefficient_fields.begin(), bound.coefficient_fields.end(), [&](const UnknownField& c) {
    return c.name == settings.topology_field && c.components == 1;
  });
  if (settings.topology_field_given && !has_topology_field)
    throw SceneError(fmt::format("{}: key 'dynamics.topology_field': '{}' is no scalar field of [coefficients] (the membrane is its "
                                 "zero level set)",
                                 scene.source, settings.topology_field));
  if (settings.topology_guard && !has_topology_field)
    throw SceneError(fmt::format("{}: key 'dynamics.topology_guard' watches the membrane phi = 0 of a scalar [coefficients] field: "
                                 "the scene has no field '{}'; name one with dynamics.topology_field",
                                 scene.source, settings.topology_field));
  if (settings.reset_every > 0 || settings.reset_distortion > 0)
    for (const auto& [field, j] : field_jets(bound))
      if (!j.hessian.empty() && j.gradient.empty())
        throw SceneError(fmt::format("{}: a reset pushes the Hessian of '{}' forward with its gradient: give [qdata] {{ field = \"{}\", jet = "
                                     "\"gradient\" }} too",
                                     scene.source, field, field));
}

std::unique_ptr<ReferenceConfiguration> DynamicsIntegrator::build_reference(
    const NodeSet& nodes, const std::vector<double>& state, std::optional<CarriedQuadrature> carried,
    std::map<std::string, std::vector<double>, std::less<>> qdata, bool keep_targets,
    std::map<std::string, std::vector<double>, std::less<>> coefficients) {
  ProblemInput input;
  input.nodes = nodes;
  input.lme = bound_.lme(AxisParity::odd);  // y_r is odd in r: no mirror
  input.initial = state;
  input.carried = std::move(carried);
  input.qdata_values = std::move(qdata);
  input.coefficient_values = std::move(coefficients);
  input.dirichlet_nodes = dirichlet_sets_;
  if (keep_targets)
    for (std::size_t i = 0; i < bound_.constraints.size(); ++i) {
      input.targets[bound_.constraints[i].name] = targets_[i];
      input.scales[bound_.constraints[i].name] = scales_[i];
    }
  ConstrainedMinimizerOptions options = minimizer_options(scene_.solver, scene_.solver.monitor ? out_ : nullptr);
  options.kkt_first = true;            // yⁿ satisfies the constraints: Newton on the KKT system from there
  options.augmented_fallback = false;  // a step Newton cannot take is retried shorter, not minimized at length
  options.refresh_hessian_every_iteration = settings_.hessian_every_iteration;
  return std::make_unique<ReferenceConfiguration>(comm_, bound_, input, options, euler_, settings_.deformation);
}

double DynamicsIntegrator::energy_of(Vec state) const { return ref_->space.energy(state); }

std::vector<double> DynamicsIntegrator::constraint_values(Vec state) const { return ref_->space.constraint_values(state); }

// A constant's value at t: the last jump at or before t (else its start value), plus the rates'
// changes relative to the start value, each rate acting over its own interval. A constraint's
// target constant moves the constraint's target.
double DynamicsIntegrator::scheduled_value(const std::string& name, double base, double t) const {
  double value = base, change = 0;
  for (const auto& c : settings_.schedule) {
    if (c.name != name) continue;
    if (c.kind == ScheduledConstant::Kind::rate) {
      if (t > c.from) change += base * c.rate * (std::min(t, c.until) - c.from);
    } else if (t >= c.at) {
      value = c.value;
    }
  }
  return value + change;
}

// The largest value each scheduled constraint target reaches (at a time where its schedule turns),
// checked by the model's rules for targets (vesicle.hpp) when the run starts: a target given
// "initial" is known only then.
void DynamicsIntegrator::check_scheduled_targets() const {
  std::vector<ScheduledTarget> peaks;
  for (std::size_t ci = 0; ci < bound_.constraints.size(); ++ci) {
    const BoundConstraint& c = bound_.constraints[ci];
    const auto first = std::find_if(settings_.schedule.begin(), settings_.schedule.end(),
                                    [&](const ScheduledConstant& s) { return !c.target_constant.empty() && s.name == c.target_constant; });
    if (first == settings_.schedule.end()) continue;
    std::vector<double> times{settings_.t_start, settings_.t_end};
    for (const auto& s : settings_.schedule)
      if (s.name == c.target_constant) times.insert(times.end(), {s.from, s.until, s.at});
    double peak = -std::numeric_limits<double>::infinity();
    for (const double t : times)
      if (t >= settings_.t_start && t <= settings_.t_end) peak = std::max(peak, scheduled_value(c.target_constant, base_targets_[ci], t));
    peaks.push_back({c.name, peak, first->where});
  }
  check_vesicle_targets(bound_, ref_->space.constants, peaks);
}

void DynamicsIntegrator::apply_schedule(double t) {
  std::set<std::string> done;
  for (const auto& first : settings_.schedule) {
    if (!done.insert(first.name).second) continue;
    const auto target_of = std::find_if(bound_.constraints.begin(), bound_.constraints.end(),
                                        [&](const BoundConstraint& bc) { return bc.target_constant == first.name; });
    const auto ci = static_cast<std::size_t>(target_of - bound_.constraints.begin());
    const double base = target_of != bound_.constraints.end() ? base_targets_[ci] : ref_->space.constants.at(first.name);
    const double value = scheduled_value(first.name, base, t);
    if (target_of != bound_.constraints.end()) {
      targets_[ci] = value;
      ref_->minimizer->set_target(ci, value);
      continue;
    }
    for (auto& [label, a] : ref_->space.assemblers)
      for (int i = 0; i < a->form().n_constants; ++i)
        if (a->form().constants[i] == first.name) a->set_constant(first.name, value);
  }
}

void DynamicsIntegrator::assemble_dissipation(Vec state) {
  const double t0 = MPI_Wtime();
  Assembler& dissipation = *ref_->space.auxiliary.front();
  Vec coefficients = ref_->dissipation_coefficients;
  {
    const VecReadView y(state);
    VecWriteView c(coefficients);
    const PetscInt owned = y.size() / bs_;
    for (PetscInt a = 0; a < owned; ++a)
      for (int i = 0; i < dim_; ++i) c[a * ref_->coefficients_per_node + ref_->coefficient_offset + i] = y[a * bs_ + offset_ + i];
  }
  dissipation.set_coefficients(coefficients);  // the assembler keeps a ghosted copy
  dissipation.matrix(state, ref_->K);
  run_.seconds_dissipation += MPI_Wtime() - t0;
}

DeformationMeasures DynamicsIntegrator::measures_of(Vec state) const {
  return deformation_measures(*ref_, to_original(*ref_->space.disc, state, bs_), scene_.axisymmetric());
}

void DynamicsIntegrator::start() {
  apply_schedule(t_);
  record(ref_->u, energy_of(ref_->u), 0, 0, 0.0);
  write_series(ref_->u);
}

/// A VTI step: y^{n+1} = argmin ½ (y − yⁿ)ᵀ K(yⁿ) (y − yⁿ) + Δt E(y) s.t. C(y) = c.
DynamicsIntegrator::Attempt DynamicsIntegrator::vti_attempt(double dt_step) {
  ReferenceConfiguration& r = *ref_;
  Attempt a;
  LMEFORM_PETSC_CHECK(VecCopy(r.yn, r.trial));
  r.minimizer->set_proximal_term({r.K, r.yn, 1.0 / (dt_step * settings_.time_unit)});
  std::vector<double> nu_trial = nu_;
  a.result = r.minimizer->minimize(r.trial, nu_trial);
  run_.gradient_evaluations += a.result.gradient_evaluations;
  run_.hessian_evaluations += a.result.hessian_evaluations;
  run_.seconds_hessian += a.result.seconds_hessian;
  run_.seconds_solve += a.result.seconds_factor;
  a.ok = a.result.converged;
  if (!a.ok) a.why = a.result.message;
  return a;
}

/// A forward Euler step: [K G; Gᵀ 0][ẏ; σ] = [−∇E; 0] by the Schur complement on σ, one
/// factorization of K; y^{n+1} = yⁿ + Δt ẏ.
DynamicsIntegrator::Attempt DynamicsIntegrator::euler_attempt(double dt_step) {
  ReferenceConfiguration& r = *ref_;
  const double t0 = MPI_Wtime();
  LMEFORM_PETSC_CHECK(MatZeroRowsColumns(r.K, static_cast<PetscInt>(r.space.fixed.size()), r.space.fixed.data(), 1.0, nullptr, nullptr));
  LMEFORM_PETSC_CHECK(KSPSetOperators(r.euler_ksp, r.K, r.K));
  LMEFORM_PETSC_CHECK(KSPSetUp(r.euler_ksp));
  LMEFORM_PETSC_CHECK(VecSet(r.gradient, 0.0));
  for (Assembler* term : r.space.energy_terms) (void)term->add_value_and_vector(r.yn, r.gradient, -1.0);
  zero_dofs(r.gradient, r.space.fixed);
  for (std::size_t i = 0; i < k_; ++i) {
    (void)r.space.constraints[i].functional->value_and_vector(r.yn, r.G[i]);
    zero_dofs(r.G[i], r.space.fixed);
  }
  ++run_.gradient_evaluations;
  LMEFORM_PETSC_CHECK(KSPSolve(r.euler_ksp, r.gradient, r.w));
  const auto k = static_cast<Eigen::Index>(k_);
  Eigen::MatrixXd S(k, k);
  Eigen::VectorXd rhs(k);
  for (std::size_t i = 0; i < k_; ++i) LMEFORM_PETSC_CHECK(KSPSolve(r.euler_ksp, r.G[i], r.Z[i]));
  for (std::size_t i = 0; i < k_; ++i) {
    rhs[Eigen::Index(i)] = dot(r.G[i], r.w);
    for (std::size_t j = 0; j < k_; ++j) S(Eigen::Index(i), Eigen::Index(j)) = dot(r.G[i], r.Z[j]);
  }
  const Eigen::VectorXd sigma = k > 0 ? Eigen::VectorXd(S.fullPivLu().solve(rhs)) : Eigen::VectorXd();
  for (std::size_t i = 0; i < k_; ++i) LMEFORM_PETSC_CHECK(VecAXPY(r.w, -sigma[Eigen::Index(i)], r.Z[i]));
  LMEFORM_PETSC_CHECK(VecWAXPY(r.trial, dt_step * settings_.time_unit, r.w, r.yn));
  run_.seconds_solve += MPI_Wtime() - t0;
  Attempt a;
  a.result.energy = energy_of(r.trial);
  a.result.converged = std::isfinite(a.result.energy);
  for (std::size_t i = 0; i < k_; ++i) a.result.multipliers.push_back(-sigma[Eigen::Index(i)]);
  a.ok = a.result.converged;
  if (!a.ok) a.why = "the energy is not finite";
  return a;
}

/// One attempt at a step of dt_step from the accepted state, which it leaves untouched: the trial
/// state, and whether it is acceptable (converged, the energy fell when required, the map unfolded).
DynamicsIntegrator::Attempt DynamicsIntegrator::attempt(double dt_step) {
  apply_schedule(t_ + dt_step);
  ReferenceConfiguration& r = *ref_;
  LMEFORM_PETSC_CHECK(VecCopy(r.u, r.yn));
  assemble_dissipation(r.yn);
  return euler_ ? euler_attempt(dt_step) : vti_attempt(dt_step);
}

void DynamicsIntegrator::accept(const Attempt& a, double dt_step, double dt_try, double energy_before) {
  ReferenceConfiguration& r = *ref_;
  for (std::size_t i = 0; i < k_; ++i) nu_[i] = a.result.multipliers[i] * r.space.constraints[i].scale;
  const std::vector<double> y1 = to_original(*r.space.disc, r.trial, bs_), y0 = to_original(*r.space.disc, r.yn, bs_);
  for (std::size_t i = 0; i < velocity_.size(); ++i) velocity_[i] = (y1[i] - y0[i]) / (dt_step * settings_.time_unit);
  LMEFORM_PETSC_CHECK(VecCopy(r.trial, r.u));
  t_ += dt_step;
  ++step_;
  ++steps_since_reset_;
  ++steps_since_remesh_;
  ++run_.accepted;
  // Δt for the next step: the energy decrement per step near its target, bounded growth, shorter
  // when Newton needed many iterations.
  if (!settings_.adaptive) {
    dt_ = dt_try;
    return;
  }
  const double decrement = std::abs(energy_before - a.result.energy);
  if (target_decrement_ <= 0 && decrement > 0) target_decrement_ = decrement;
  // The decrement per unit time is decrement / dt_step; the step that meets the target:
  double next = decrement > 0 ? target_decrement_ * dt_step / decrement : settings_.growth * dt_try;
  next = std::clamp(next, 0.5 * dt_try, settings_.growth * dt_try);
  if (a.result.newton_iterations > settings_.target_newton) next = std::min(next, 0.5 * dt_try);
  const double dt_min = settings_.dt_min > 0 ? settings_.dt_min : settings_.dt * std::pow(2.0, -20);
  dt_ = std::max(next, dt_min);
  if (settings_.dt_max > 0) dt_ = std::min(dt_, settings_.dt_max);
}

/// One accepted step, retried with halved Δt (or after a reset of the reference configuration,
/// when the map folds) until it is acceptable; false when it never is (run_.failure says why).
bool DynamicsIntegrator::advance() {
  const double t_tolerance = 1e-12 * std::max(std::abs(settings_.t_end), 1.0);
  const double dt_min = settings_.dt_min > 0 ? settings_.dt_min : settings_.dt * std::pow(2.0, -20);
  double energy_before = run_.history.back().energy;
  bool new_reference = false;  // the recorded distortion belongs to the previous reference
  if (settings_.remesh_every > 0 && steps_since_remesh_ >= settings_.remesh_every) {
    if (!remesh()) return false;
    energy_before = energy_of(ref_->u);  // a projection changes E: the next decrement is measured from here
    new_reference = true;
  }
  if (resets_ && ((settings_.reset_every > 0 && steps_since_reset_ >= settings_.reset_every) ||
                  (!new_reference && settings_.reset_distortion > 0 && run_.history.back().distortion > settings_.reset_distortion)))
    reset_reference();
  double dt_try = dt_;
  int rejected = 0;
  bool reset_for_this_step = false;
  for (;;) {
    double dt_step = std::min(dt_try, settings_.t_end - t_);
    const double dt_attempted = dt_step;
    if (next_report_ < settings_.report_times.size()) dt_step = std::min(dt_step, settings_.report_times[next_report_] - t_);
    Attempt a = attempt(dt_step);
    if (a.ok && settings_.require_decrease && !(a.result.energy <= energy_before + 1e-10 * std::abs(energy_before))) {
      a.ok = false;
      a.why = fmt::format("the energy rose from {:.10g} to {:.10g}", energy_before, a.result.energy);
    }
    if (a.ok) {
      a.measures = measures_of(ref_->trial);
      if (!(a.measures.min_jacobian > settings_.min_jacobian)) {
        a.ok = false;
        a.folded = true;
        const auto& x = a.measures.position;
        a.why = fmt::format("det F = {:.3e} at quadrature point {} (reference position ({:.4g}, {:.4g}){})", a.measures.min_jacobian,
                            a.measures.point, x[0], dim_ > 1 ? x[1] : 0.0, run_.resets > 0 ? fmt::format(", reference {}", run_.resets) : "");
      }
    }
    if (a.ok) {
      accept(a, dt_step, dt_try, energy_before);
      bool at_report_time = false;
      while (next_report_ < settings_.report_times.size() && settings_.report_times[next_report_] <= t_ + t_tolerance) {
        run_.energy_at[settings_.report_times[next_report_]] = a.result.energy;
        at_report_time = true;
        ++next_report_;
      }
      record(ref_->u, a.result.energy, euler_ ? 0 : a.result.newton_iterations, rejected, dt_step, a.measures);
      const bool finished = t_ >= settings_.t_end - t_tolerance;
      // A report time gets its fields too: the shape at a scheduled event (the end of a deflation).
      if ((settings_.output_every > 0 && step_ % settings_.output_every == 0) || finished || at_report_time) write_series(ref_->u);
      if (settings_.checkpoint_every > 0 && step_ % settings_.checkpoint_every == 0) write_checkpoint();
      return true;
    }
    ++rejected;
    ++run_.rejected;
    if (a.folded && resets_ && !reset_for_this_step) {
      // The map folds from this reference: reset it to the current state and try again.
      if (out_ != nullptr) *out_ << fmt::format("  step {} rejected at dt* {:.3e}: {}; resetting the reference\n", step_ + 1, dt_step, a.why);
      reset_reference();
      reset_for_this_step = true;
      continue;
    }
    if (out_ != nullptr)
      *out_ << fmt::format("  step {} rejected at dt* {:.3e}: {}; retrying with dt* {:.3e}\n", step_ + 1, dt_step, a.why, dt_step / 2);
    dt_try = dt_step / 2;
    if (rejected > settings_.max_retries || dt_try < dt_min) {
      run_.failure = fmt::format("step {} failed {} times down to dt* = {:.3e}: {}", step_ + 1, rejected, dt_attempted, a.why);
      apply_schedule(t_);
      return false;
    }
  }
}

DynamicsRun DynamicsIntegrator::run() {
  material_nodes_ = initial_nodes(scene_, comm_, log_);
  run_.cells = delaunay(material_nodes_);
  // The material boundary: found once on the material nodes and kept by resets (a node's
  // coefficient may leave the box, LME not being interpolating; it stays free).
  dirichlet_sets_ = dirichlet_nodes(bound_, material_nodes_);
  n_nodes_ = material_nodes_.size();
  ref_ = build_reference(material_nodes_, settings_.start_state, std::nullopt, {}, false);
  k_ = ref_->space.constraints.size();
  for (const auto& c : ref_->space.constraints) {
    run_.constraint_names.push_back(c.name);
    targets_.push_back(c.target);
    scales_.push_back(c.scale);
  }
  const auto h = ref_->space.disc->basis().spacing();
  run_.h_min = *std::min_element(h.begin(), h.end());
  run_.reference_nodes = material_nodes_;
  // Scheduled constants start from their values at the start (a target given "initial" included).
  start_constraints_ = constraint_values(ref_->u);
  base_targets_ = targets_;
  check_scheduled_targets();
  nu_.assign(k_, 0.0);
  if (!settings_.start_multipliers.empty()) {
    if (settings_.start_multipliers.size() != k_) throw std::invalid_argument("run_dynamics: wrong number of starting multipliers");
    for (std::size_t i = 0; i < k_; ++i) nu_[i] = settings_.start_multipliers[i] * ref_->space.constraints[i].scale;
  }
  t_ = settings_.t_start;
  dt_ = settings_.dt;
  target_decrement_ = settings_.energy_decrement;
  velocity_.assign(n_nodes_ * std::size_t(bs_), 0.0);
  // Scalar coefficient fields (the reference phase field) go to every time-series file: material
  // values, carried by the nodes.
  for (const auto& c : bound_.coefficient_fields)
    if (c.components == 1) scalar_fields_.emplace_back(c.name, coefficient_values(bound_, c.name, 1, material_nodes_));
  if (const auto* field = topology_values()) topology_ = run_.initial_topology = membrane_topology(material_nodes_, run_.cells, *field);

  if (output_ != nullptr && output_->restart) resume();
  run_.seconds_setup = clock_.seconds();
  if (!(output_ != nullptr && output_->restart)) start();

  const double t_tolerance = 1e-12 * std::max(std::abs(settings_.t_end), 1.0);
  while (next_report_ < settings_.report_times.size() && settings_.report_times[next_report_] <= t_ + t_tolerance) {
    // Report times already passed (a restart): their energies from the history.
    for (const auto& s : run_.history)
      if (std::abs(s.t_star - settings_.report_times[next_report_]) <= t_tolerance) run_.energy_at[settings_.report_times[next_report_]] = s.energy;
    ++next_report_;
  }
  while (t_ < settings_.t_end - t_tolerance) {
    if (step_ >= settings_.max_steps) {
      run_.failure = fmt::format("stopped after max_steps = {} steps at t* = {:.6e}", settings_.max_steps, t_);
      break;
    }
    if (!advance()) break;
  }
  if (!run_.failure.empty() && settings_.checkpoint_every > 0) write_checkpoint();
  if (output_ != nullptr && rank_ == 0) write_text_atomically(history_path_, history_json().dump(1) + "\n");
  run_.final_state = to_original(*ref_->space.disc, ref_->u, bs_);
  for (std::size_t i = 0; i < k_; ++i) run_.final_multipliers.push_back(nu_[i] / ref_->space.constraints[i].scale);
  run_.wall_s = clock_.seconds();
  return std::move(run_);
}

const std::vector<double>* DynamicsIntegrator::topology_values() const {
  for (const auto& [name, values] : scalar_fields_)
    if (name == settings_.topology_field) return &values;
  return nullptr;
}

// The material field on the material nodes: the motion maps it to the current configuration
// without changing its topology while det F > 0.
std::optional<LevelSetTopology> DynamicsIntegrator::membrane_topology(const NodeSet& nodes, const BackgroundCells& cells,
                                                                      const std::vector<double>& field) const {
  try {
    return field_topology(comm_, nodes, cells, field, bound_.discretization.gamma, bound_.lme(AxisParity::even), level_set_geometry(dim_, scene_.axisymmetric()));
  } catch (const std::exception& e) {
    if (out_ != nullptr) *out_ << "the membrane's topology could not be evaluated: " << e.what() << "\n";
    return std::nullopt;
  }
}

DynamicsRun run_dynamics(MPI_Comm comm, const Scene& scene, const DynamicsSettings& settings, const DynamicsOutput* output,
                         std::ostream* log) {
  DynamicsIntegrator integrator(comm, scene, settings, output, log);
  return integrator.run();
}

}  // namespace lmeform::problems
