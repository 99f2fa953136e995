#include "load_steps.hpp"

#include <algorithm>
#include <cmath>
#include <fstream>
#include <map>
#include <sstream>

#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include "lmeform/delaunay.hpp"
#include "lmeform/domain.hpp"
#include "lmeform/output.hpp"
#include "lmeform/scene_table.hpp"
#include "lmeform/stopwatch.hpp"
#include "node_adaptation.hpp"
#include "quantities.hpp"
#include "requirements.hpp"
#include "stationary.hpp"

namespace lmeform::problems {

namespace fs = std::filesystem;

double SteppedConstant::at(double lambda) const {
  const auto last = static_cast<double>(values.size() - 1);
  const double l = std::clamp(lambda, 0.0, last);
  const auto k = static_cast<std::size_t>(std::min(std::floor(l), last - 1));
  return values[k] + (l - double(k)) * (values[k + 1] - values[k]);
}

namespace {

std::vector<double> numbers_of(const SceneTable& t, const std::string& name, const toml::node& node) {
  const auto* a = node.as_array();
  if (a == nullptr) t.wrong_type(name, node, "an array of numbers");
  std::vector<double> v;
  for (std::size_t i = 0; i < a->size(); ++i) v.push_back(t.number_of(name + "[" + std::to_string(i) + "]", (*a)[i]));
  return v;
}

}  // namespace

LoadStepSettings read_steps(const Scene& scene) {
  const auto t = extension_table(scene, kStepsTable, {"count", "ramp", "values", "cut", "max_cuts", "solve_start", "checkpoint_every", "until", "fallback"});
  LoadStepSettings s;
  s.count = t->at_least("count", t->integer_of("count", t->require("count")), 1);
  if (s.count > 100000) t->fail_key("count", "= " + std::to_string(s.count) + " is more steps than a run can write (at most 100000)");
  if (const auto ramp = t->optional_any_table("ramp"))
    for (const auto& [name, node] : scene_detail::in_file_order(ramp->entries())) {
      const std::vector<double> ends = numbers_of(*ramp, name, *node);
      if (ends.size() != 2) ramp->fail_key(name, "must be [from, to], got " + std::to_string(ends.size()) + " values");
      SteppedConstant c{name, {}, ramp->where(name)};
      for (int k = 0; k <= s.count; ++k) c.values.push_back(ends[0] + (ends[1] - ends[0]) * k / s.count);
      s.constants.push_back(std::move(c));
    }
  if (const auto values = t->optional_any_table("values"))
    for (const auto& [name, node] : scene_detail::in_file_order(values->entries())) {
      SteppedConstant c{name, numbers_of(*values, name, *node), values->where(name)};
      if (c.values.size() != std::size_t(s.count) + 1)
        values->fail_key(name, "must give count + 1 = " + std::to_string(s.count + 1) + " values (step 0 first), got " + std::to_string(c.values.size()));
      if (std::any_of(s.constants.begin(), s.constants.end(), [&](const SteppedConstant& o) { return o.name == name; }))
        values->fail_key(name, "is ramped already in steps.ramp: give it once");
      s.constants.push_back(std::move(c));
    }
  if (s.constants.empty()) t->fail_key("ramp", "is missing: [steps] ramps constants (ramp = { NAME = [from, to] } or values = { NAME = [...] })");
  s.cut = t->number("cut", s.cut);
  if (!(s.cut > 0 && s.cut < 1)) t->fail_key("cut", "must lie in (0, 1): the factor of a failed increment, got " + std::to_string(s.cut));
  s.max_cuts = t->at_least("max_cuts", t->integer("max_cuts", s.max_cuts), 0);
  s.solve_start = t->boolean("solve_start", s.solve_start);
  s.checkpoint_every = t->at_least("checkpoint_every", t->integer("checkpoint_every", s.checkpoint_every), 0);
  s.until = t->at_least("until", t->integer("until", s.count), 0);
  if (s.until > s.count) t->fail_key("until", "= " + std::to_string(s.until) + " exceeds count = " + std::to_string(s.count));
  if (s.until < s.count && s.checkpoint_every == 0) t->fail_key("until", "stops before the last step: it needs checkpoints to continue from");
  if (const auto fallback = t->optional_any_table("fallback")) {
    for (const auto& [name, node] : scene_detail::in_file_order(fallback->entries())) {
      if (std::any_of(s.constants.begin(), s.constants.end(), [&](const SteppedConstant& c) { return c.name == name; }))
        fallback->fail_key(name, "is a stepped constant: the fallback changes the model's constants, not the load");
      s.fallback.emplace_back(name, fallback->number_of(name, *node));
      s.fallback_where.push_back(fallback->where(name));
    }
    if (s.fallback.empty()) t->fail_key("fallback", "is empty: give the regularized model's constants, { NAME = value, ... }");
  }
  return s;
}

namespace {

const StepHistoryFormat kHistoryFormat{"load", {"iterations", "cuts"}};

/// The ramped constants are the driver's: no value needed in [constants].
OutputRoles ramped(const LoadStepSettings& settings) {
  OutputRoles roles;
  for (const SteppedConstant& c : settings.constants) roles.provided_constants.push_back(c.name);
  return roles;
}

/// The stepping of one run: the problem space built once, the state carried from step to step.
class LoadStepper {
 public:
  LoadStepper(const DriverContext& ctx, const LoadStepSettings& settings)
      : ctx_(ctx), settings_(settings), bound_(bind_scene(*ctx.scene, ctx.comm, ctx.log, ramped(settings))) {
    MPI_Comm_rank(ctx.comm, &rank_);
    const auto require_constant = [this](const std::string& where, const std::string& name) {
      if (bound_.constants.contains(name)) return;
      std::vector<std::string> names;
      for (const auto& [n, v] : bound_.constants) names.push_back(n);
      throw SceneError(fmt::format("{}: '{}' is no constant of the forms{}", where, name, did_you_mean(name, names)));
    };
    for (const SteppedConstant& c : settings.constants) require_constant(c.where, c.name);
    for (std::size_t i = 0; i < settings.fallback.size(); ++i) require_constant(settings.fallback_where[i], settings.fallback[i].first);
    if (const auto& adapt = ctx.scene->nodes.adapt) {
      std::vector<std::string> names;
      for (const auto& f : bound_.layout.fields) names.push_back(f.name);
      if (!bound_.layout.has(adapt->field))
        throw SceneError(fmt::format("{}: key 'nodes.adapt.field': '{}' is no unknown of the forms{}", adapt->where, adapt->field,
                                     did_you_mean(adapt->field, names)));
      if (bound_.layout.field(adapt->field).components != 1)
        throw SceneError(fmt::format("{}: key 'nodes.adapt.field': '{}' has {} components; the nodes follow a scalar field", adapt->where,
                                     adapt->field, bound_.layout.field(adapt->field).components));
    }
  }

  LoadStepRun run();
  [[nodiscard]] const BoundScene& bound() const noexcept { return bound_; }
  [[nodiscard]] ReportFields final_fields() const;

 private:
  void setup();
  void set_load(double lambda);
  [[nodiscard]] bool attempt(double lambda, ProblemResult& result);
  [[nodiscard]] bool advance(int step);
  [[nodiscard]] bool ramp_to(int step, ProblemResult& result, int& cuts, std::string& failure);
  [[nodiscard]] bool solve_with_fallback(int step, ProblemResult& result, int& cuts, FallbackUse& use, std::string& failure);
  void set_constants(const std::vector<std::pair<std::string, double>>& values);
  void record(int step, double lambda, const ProblemResult& result, int cuts, FallbackUse fallback = FallbackUse::none);
  void write_outputs(int step);
  void check_state_requirements(int step);
  [[nodiscard]] bool adapting() const noexcept { return ctx_.scene->nodes.adapt.has_value(); }
  void rebuild(NodeSet nodes, std::vector<double> start);
  void refine_start();
  [[nodiscard]] bool follow_field(int step, std::vector<double> before, double lambda_before);
  void write_history() const;
  void resume();
  [[nodiscard]] fs::path path(const std::string& suffix) const { return ctx_.output_directory / (ctx_.scene->name + suffix); }

  const DriverContext& ctx_;
  const LoadStepSettings& settings_;
  BoundScene bound_;
  int rank_ = 0;
  Stopwatch clock_;
  ProblemInput input_;
  ProblemSpace space_;
  BackgroundCells cells_;
  PetscVector u_, trial_;
  double lambda_ = 0;           ///< the converged load
  int first_step_ = 0;
  std::vector<double> multipliers_;
  std::optional<TimeSeriesWriter> series_;  ///< with an output folder
  LoadStepRun run_;
  std::map<std::string, std::size_t> requirement_failures_;  ///< condition -> failing nodes when last warned
  int fallback_step_ = -1;      ///< the last step a fallback solve took part in
};

/// Refinements of one step before the run goes on with nodes still too coarse (and says so).
constexpr int kMaxRefinementsPerStep = 4;

void LoadStepper::setup() {
  input_.lme = bound_.lme(AxisParity::even);
  set_load(0.0);  // the expressions of the start and the Dirichlet values at step 0
  // Nodes that follow a field are judged (the forms' requirements) once they have followed it.
  input_.log = adapting() ? nullptr : ctx_.log;
  rebuild(initial_nodes(*ctx_.scene, ctx_.comm, ctx_.log), {});
  input_.log = ctx_.log;
  if (!ctx_.output_directory.empty()) series_.emplace(ctx_.output_directory, ctx_.scene->name);
  // A restart takes the checkpoint's nodes and state: the scene's unrefined start, built here only
  // to be replaced, is not judged (its warnings would name nodes the run no longer has).
  if (adapting() && !ctx_.restart) {
    refine_start();
    check_requirements(bound_, space_, ctx_.log);
  }
}

/// The problem on other nodes, from `start` (original order; empty: the scene's [initial]). A
/// carried start may overshoot a bound by the transfer's error: it is moved onto it.
void LoadStepper::rebuild(NodeSet nodes, std::vector<double> start) {
  input_.nodes = std::move(nodes);
  input_.initial = std::move(start);
  input_.clamp_start_to_bounds = !input_.initial.empty();
  space_ = build_problem_space(ctx_.comm, bound_, input_);
  input_.initial.clear();
  cells_ = delaunay(input_.nodes);
  u_ = space_.primary->create_vector();
  trial_ = space_.primary->create_vector();
  set_from_original(*space_.disc, space_.state, bound_.layout.dofs_per_node, u_);
}

/// An initial field (a notch) already below the threshold gets its refinement before any solve.
/// Silent about the forms' requirements: the caller checks them on the nodes it ends with.
void LoadStepper::refine_start() {
  const SceneAdaptation& adapt = *ctx_.scene->nodes.adapt;
  for (int round = 0; round < kMaxRefinementsPerStep; ++round) {
    const NodeSet marked = marked_nodes(adapt, bound_.layout, input_.nodes, space_.state);
    const CoarseNodes coarse = coarse_nodes(*ctx_.scene, input_.nodes, marked);
    if (coarse.count == 0) return;
    const Stopwatch clock;
    const std::size_t before = input_.nodes.size();
    NodeSet nodes = refined_nodes(*ctx_.scene, input_.nodes, marked);
    if (nodes.coords == input_.nodes.coords) return;
    input_.log = nullptr;
    rebuild(std::move(nodes), {});
    input_.log = ctx_.log;
    if (ctx_.log != nullptr)
      *ctx_.log << fmt::format("start: {}: {} -> {} nodes, {:.2f} s\n", describe(*ctx_.scene, coarse), before, input_.nodes.size(), clock.seconds());
  }
}

/// After a converged step: where the followed field fell below its threshold near nodes too coarse
/// for it, new nodes, both the state before the step (the irreversibility bound) and the step's
/// solution (the start) carried to them, and the step solved again — until the nodes suffice.
bool LoadStepper::follow_field(int step, std::vector<double> before, double lambda_before) {
  const SceneAdaptation& adapt = *ctx_.scene->nodes.adapt;
  const int bs = bound_.layout.dofs_per_node;
  const double gamma = bound_.discretization.gamma;
  for (int round = 0;; ++round) {
    const std::vector<double> state = to_original(*space_.disc, u_, bs);
    const NodeSet marked = marked_nodes(adapt, bound_.layout, input_.nodes, state);
    const CoarseNodes coarse = coarse_nodes(*ctx_.scene, input_.nodes, marked);
    if (coarse.count == 0) return true;
    if (round == kMaxRefinementsPerStep) {
      const std::string message = fmt::format("step {}: {}, still after {} refinements", step, describe(*ctx_.scene, coarse), round);
      run_.warnings.push_back(message);
      if (ctx_.log != nullptr) *ctx_.log << "lmeform: warning: " << message << std::endl;
      return true;
    }
    const Stopwatch clock;
    const NodeSet old_nodes = input_.nodes;
    const double energy_before = space_.energy(u_);
    NodeSet nodes = refined_nodes(*ctx_.scene, old_nodes, marked);
    if (nodes.coords == old_nodes.coords) return true;  // the sample cannot do better there
    std::size_t kept = 0;
    std::vector<double> start, solution;
    try {
      start = transfer_state(old_nodes, before, bs, gamma, input_.lme, nodes, adapt.fit_iterations, &kept);
      solution = transfer_state(old_nodes, state, bs, gamma, input_.lme, nodes, adapt.fit_iterations);
    } catch (const std::exception& e) {
      // The last converged step is on disk already; say where the run stopped.
      throw std::runtime_error(fmt::format("step {}: carrying the state to {} refined nodes (refinement {} of the step, key 'nodes.adapt'): {}",
                                           step, nodes.size(), round + 1, e.what()));
    }
    rebuild(std::move(nodes), start);  // at the step's load: the bound "previous" is the state before the step
    before = to_original(*space_.disc, u_, bs);
    set_from_original(*space_.disc, solution, bs, u_);
    if (space_.bounded()) {
      LMEFORM_PETSC_CHECK(VecPointwiseMax(u_, u_, space_.lower_bound));
      LMEFORM_PETSC_CHECK(VecPointwiseMin(u_, u_, space_.upper_bound));
    }
    space_.impose_dirichlet_values(bound_, u_);
    const double energy_after = space_.energy(u_);
    ++run_.refinements;
    if (ctx_.log != nullptr)
      *ctx_.log << fmt::format("  step {}: {}: {} -> {} nodes ({} kept), energy carried {:+.2e} (relative), {:.2f} s; solving the step again\n", step,
                               describe(*ctx_.scene, coarse), old_nodes.size(), input_.nodes.size(), kept,
                               (energy_after - energy_before) / std::max(std::abs(energy_before), 1e-300), clock.seconds());
    set_load(lambda_before);
    lambda_ = lambda_before;
    run_.history.pop_back();
    if (!advance(step)) return false;
  }
}

void LoadStepper::set_load(double lambda) {
  for (const SteppedConstant& c : settings_.constants) {
    const double v = c.at(lambda);
    bound_.expressions->set_constant(c.name, v);
    if (space_.disc) space_.set_constant(c.name, v);
    input_.constants[c.name] = v;
  }
}

/// A solve at load λ from the converged state; the state moves only when it converges.
bool LoadStepper::attempt(double lambda, ProblemResult& result) {
  set_load(lambda);
  LMEFORM_PETSC_CHECK(VecCopy(u_, trial_));
  space_.impose_dirichlet_values(bound_, trial_);
  result = ProblemResult{};
  input_.initial_multipliers = multipliers_;
  bound_.solver->solve(ctx_.comm, bound_, space_, input_, trial_, result);
  if (!result.converged) return false;
  LMEFORM_PETSC_CHECK(VecCopy(trial_, u_));
  space_.update_previous_bounds(bound_, u_);  // irreversibility: the next step starts from here
  lambda_ = lambda;
  if (!result.minimization.multipliers.empty()) multipliers_ = result.minimization.multipliers;
  return true;
}

/// From the converged load to `step`: the whole increment, else cut increments. False (with the
/// reason in `failure`) when the smallest increment fails; the state is then the last converged one.
bool LoadStepper::ramp_to(int step, ProblemResult& result, int& cuts, std::string& failure) {
  const double target = step;
  double increment = target - lambda_;
  int cut_here = 0;
  while (lambda_ < target - 1e-12) {
    const double next = std::min(target, lambda_ + increment);
    if (attempt(next, result)) continue;
    ++cuts;
    if (++cut_here > settings_.max_cuts) {
      failure = fmt::format("step {} did not converge from load {:.6g} with increments down to {:.3g} of a step ({} cuts): {}", step, lambda_,
                            increment, settings_.max_cuts, result.message);
      set_load(lambda_);
      return false;
    }
    increment *= settings_.cut;
    if (ctx_.log != nullptr)
      *ctx_.log << fmt::format("  step {} at load {:.6g}: {}; retrying with an increment of {:.3g} step\n", step, next, result.message, increment);
  }
  return true;
}

void LoadStepper::set_constants(const std::vector<std::pair<std::string, double>>& values) {
  for (const auto& [name, v] : values) {
    bound_.expressions->set_constant(name, v);
    if (space_.disc) space_.set_constant(name, v);
    input_.constants[name] = v;
  }
}

namespace {

std::string listed(const std::vector<std::pair<std::string, double>>& values) {
  std::string s;
  for (const auto& [name, v] : values) s += fmt::format("{}{} = {:.6g}", s.empty() ? "" : ", ", name, v);
  return s;
}

/// How a recorded step used the fallback (its history quantity "fallback"; none without one).
FallbackUse fallback_use(const StepRow& row) {
  for (const auto& [name, v] : row.quantities)
    if (name == "fallback") return static_cast<FallbackUse>(static_cast<int>(v));
  return FallbackUse::none;
}

}  // namespace

/// The step with the fallback constants, then again with the scene's from that solution. The
/// second solve keeps the bounds of the step's start (irreversibility against the state before
/// the step, not against the regularized solution). On failure of the fallback itself the state,
/// the load and the bounds are those of before.
bool LoadStepper::solve_with_fallback(int step, ProblemResult& result, int& cuts, FallbackUse& use, std::string& failure) {
  std::vector<std::pair<std::string, double>> scene_values;
  for (const auto& [name, v] : settings_.fallback) scene_values.emplace_back(name, space_.constants.at(name));
  const double lambda_start = lambda_;
  PetscVector start = space_.primary->create_vector();
  LMEFORM_PETSC_CHECK(VecCopy(u_, start));
  if (ctx_.log != nullptr)
    *ctx_.log << fmt::format("  step {}: solving it from load {:.6g} with the fallback constants {} (steps.fallback)\n", step, lambda_start,
                             listed(settings_.fallback));
  set_constants(settings_.fallback);
  std::string fallback_failure;
  const bool regularized = ramp_to(step, result, cuts, fallback_failure);
  set_constants(scene_values);
  if (!regularized) {
    LMEFORM_PETSC_CHECK(VecCopy(start, u_));
    lambda_ = lambda_start;
    set_load(lambda_);
    space_.update_previous_bounds(bound_, u_);
    failure += fmt::format("; with the fallback constants {} too: {}", listed(settings_.fallback), fallback_failure);
    return false;
  }
  const ProblemResult regularized_result = result;
  space_.update_previous_bounds(bound_, start);
  if (attempt(lambda_, result)) {
    use = FallbackUse::resolved;
    if (ctx_.log != nullptr)
      *ctx_.log << fmt::format("  step {}: converged with the fallback constants, then with the scene's ({}) from that solution\n", step,
                               listed(scene_values));
    return true;
  }
  const std::string message =
      fmt::format("step {} keeps the solution of the fallback constants {}: the scene's constants ({}) did not converge from it ({})", step,
                  listed(settings_.fallback), listed(scene_values), result.message);
  result = regularized_result;
  space_.update_previous_bounds(bound_, u_);
  use = FallbackUse::kept;
  run_.fallback_kept[step] = message;  // a warning unless a later solve of the step (refined nodes) converges
  if (ctx_.log != nullptr) *ctx_.log << "  " << message << std::endl;
  return true;
}

/// Step `step` (from λ = step − 1, or the start), with the fallback constants when every cut fails.
bool LoadStepper::advance(int step) {
  int cuts = 0;
  ProblemResult result;
  std::string failure;
  FallbackUse fallback = FallbackUse::none;
  if (!ramp_to(step, result, cuts, failure) && (settings_.fallback.empty() || !solve_with_fallback(step, result, cuts, fallback, failure))) {
    run_.failure = failure;
    return false;
  }
  // A step solved again on refined nodes starts from its earlier solution: if that came through
  // the fallback, so does this one.
  if (fallback != FallbackUse::none) fallback_step_ = step;
  if (fallback == FallbackUse::none && fallback_step_ == step) fallback = FallbackUse::resolved;
  if (fallback != FallbackUse::kept) run_.fallback_kept.erase(step);
  if (step == 0 && !attempt(0.0, result)) {
    run_.failure = "the start (step 0) did not converge: " + result.message;
    return false;
  }
  record(step, lambda_, result, cuts, fallback);
  return true;
}

void LoadStepper::record(int step, double lambda, const ProblemResult& result, int cuts, FallbackUse fallback) {
  StepRow s;
  s.step = step;
  s.position = lambda;
  for (const SteppedConstant& c : settings_.constants) s.constants.emplace_back(c.name, c.at(lambda));
  s.quantities = evaluate_quantities(bound_, space_, u_, result);
  // A bounded problem's active set per step (a contact that closes, damage that saturates).
  if (result.active_lower >= 0) {
    s.quantities.emplace_back("active_lower", double(result.active_lower));
    s.quantities.emplace_back("active_upper", double(result.active_upper));
  }
  s.quantities.insert(s.quantities.end(), result.solver_figures.begin(), result.solver_figures.end());
  if (adapting()) s.quantities.emplace_back("nodes", double(input_.nodes.size()));
  if (!settings_.fallback.empty()) s.quantities.emplace_back("fallback", double(static_cast<int>(fallback)));
  s.counts = {{"iterations", result.iterations}, {"cuts", cuts}};
  s.wall_s = clock_.seconds();
  run_.history.push_back(s);
  if (ctx_.log == nullptr) return;
  std::string values;
  for (const auto& [name, v] : s.constants) values += fmt::format("  {} {:.6g}", name, v);
  for (const auto& [name, v] : s.quantities) values += fmt::format("  {} {:.6g}", name, v);
  *ctx_.log << fmt::format("step {:4d}/{}{}  iterations {}  cuts {}  {:.1f} s", step, settings_.count, values, result.iterations, cuts, s.wall_s)
            << std::endl;
}

/// A requirement on the state that held at the start can fail later (a crack grown into nodes too
/// coarse for its band): warned when it first fails and whenever more nodes fail, not refused —
/// the step itself converged.
void LoadStepper::check_state_requirements(int step) {
  const std::vector<double> state = to_original(*space_.disc, u_, bound_.layout.dofs_per_node);
  for (const RequirementFailure& f : failed_state_requirements(bound_, space_, state, fmt::format("step {}", step))) {
    std::size_t& warned = requirement_failures_[f.condition];
    if (f.nodes <= warned) continue;
    warned = f.nodes;
    run_.warnings.push_back(f.message);
    if (ctx_.log != nullptr) *ctx_.log << "lmeform: warning: " << f.message << std::endl;
  }
}

void LoadStepper::write_history() const {
  write_step_history(ctx_.output_directory, ctx_.scene->name, kHistoryFormat, run_.history);
}

void LoadStepper::write_outputs(int step) {
  if (ctx_.output_directory.empty()) return;
  // Every rank writes the rows it owns into the files (collective HDF5): nothing is gathered.
  const OwnedRows owned = owned_original(*space_.disc, u_, bound_.layout.dofs_per_node);
  std::vector<std::vector<double>> values;
  values.reserve(bound_.layout.fields.size());  // the views below point into it
  FieldViews fields;
  for (const auto& f : bound_.layout.fields) {
    values.push_back(bound_.layout.values(owned.values, f));
    fields.emplace(f.name, FieldView{values.back(), f.components});
  }
  const OutputAttributes attributes{{"step", static_cast<std::int64_t>(step)}, {"load", lambda_}};
  const MPI_Comm comm = space_.disc->comm();
  series_->write(comm, lambda_, step, input_.nodes, cells_, DistributedFields{owned.rows, fields}, attributes);
  if (rank_ == 0) write_history();
  if (settings_.checkpoint_every > 0 && (step % settings_.checkpoint_every == 0 || step == settings_.until))
    write_field_hdf5(comm, path("_checkpoint.h5"), input_.nodes, cells_,
                     DistributedFields{owned.rows, {{"state", FieldView{owned.values, bound_.layout.dofs_per_node}}}}, attributes);
}

void LoadStepper::resume() {
  const fs::path checkpoint = path("_checkpoint.h5"), history = ctx_.output_directory / "history.json";
  if (!fs::exists(checkpoint) || !fs::exists(history))
    throw std::runtime_error(fmt::format("--restart: no checkpoint in {} (expected {} and history.json)", ctx_.output_directory.string(),
                                         checkpoint.filename().string()));
  const FieldFile cp = read_field_hdf5(checkpoint, ctx_.comm);
  const int step = static_cast<int>(std::get<std::int64_t>(cp.attributes.at("step")));
  lambda_ = std::get<double>(cp.attributes.at("load"));
  set_load(lambda_);
  if (cp.nodes.coords != input_.nodes.coords) {
    // Nodes that followed a field are the checkpoint's own; any other scene's nodes are fixed.
    if (!adapting()) throw std::runtime_error(fmt::format("--restart: {} was written for other nodes than the scene's", checkpoint.string()));
    rebuild(cp.nodes, cp.fields.at("state").values);
  }
  set_from_original(*space_.disc, cp.fields.at("state").values, bound_.layout.dofs_per_node, u_);
  space_.update_previous_bounds(bound_, u_);  // irreversibility continues from the checkpoint, not from the start
  run_.history = read_step_history(ctx_.output_directory, kHistoryFormat, step);
  // The steps that kept a fallback solution before the restart are warned of again at its end.
  for (const StepRow& row : run_.history)
    if (fallback_use(row) == FallbackUse::kept)
      run_.fallback_kept[row.step] = fmt::format("step {} keeps the solution of the fallback constants {} (before the restart: history.json)",
                                                 row.step, listed(settings_.fallback));
  series_->restore(restored_series(ctx_.comm, *series_, ctx_.output_directory, run_.history, bound_.layout, bound_.dim));
  first_step_ = step + 1;
  if (ctx_.log != nullptr) *ctx_.log << fmt::format("resumed from {} at step {} (load {:.6g})\n", checkpoint.string(), step, lambda_);
}

LoadStepRun LoadStepper::run() {
  setup();
  const ScopedPetscOptions petsc_options(ctx_.scene->solver.petsc_options);
  if (ctx_.restart) resume();
  // The start's failures were warned of when the problem was built.
  for (const RequirementFailure& f : failed_state_requirements(bound_, space_, to_original(*space_.disc, u_, bound_.layout.dofs_per_node), "the start"))
    requirement_failures_[f.condition] = f.nodes;
  for (int step = first_step_; step <= settings_.until; ++step) {
    if (step == 0 && !settings_.solve_start) {
      ProblemResult none;
      none.converged = true;
      record(0, 0.0, none, 0);
    } else {
      const double lambda_before = lambda_;
      std::vector<double> before;
      if (adapting()) before = to_original(*space_.disc, u_, bound_.layout.dofs_per_node);
      if (!advance(step) || (adapting() && !follow_field(step, std::move(before), lambda_before))) break;
    }
    check_state_requirements(step);
    write_outputs(step);
  }
  run_.wall_s = clock_.seconds();
  return std::move(run_);
}

ReportFields LoadStepper::final_fields() const {
  ProblemResult r;
  r.nodes = input_.nodes;
  r.cells = cells_;
  r.state = to_original(*space_.disc, u_, bound_.layout.dofs_per_node);
  ReportFields f = state_fields(bound_.layout, bound_.axisymmetric, r);
  f.attributes.emplace("load", lambda_);
  return f;
}

/// The steps whose history row has this fallback use, "" when none.
std::string steps_with(const std::vector<StepRow>& history, FallbackUse use) {
  std::string steps;
  for (const StepRow& s : history)
    if (fallback_use(s) == use) steps += fmt::format("{}{}", steps.empty() ? "" : " ", s.step);
  return steps;
}

void describe_steps(const LoadStepSettings& settings, const LoadStepRun& run, RunReport& report) {
  const StepRow& last = run.history.back();
  report.row("steps", fmt::format("{} of {} (load {:.6g}), {} increments cut", last.step, settings.count, last.position,
                                  [&] { long c = 0; for (const auto& s : run.history) c += s.count("cuts"); return c; }()));
  for (const auto& [name, v] : last.constants) report.row(name, fmt::format("{:.10g}", v));
  describe_quantities(last.quantities, report);
  if (run.refinements > 0) report.row("refinements", fmt::format("{} (the nodes followed the field: steps solved again)", run.refinements));
  if (!settings.fallback.empty()) {
    const std::string resolved = steps_with(run.history, FallbackUse::resolved), kept = steps_with(run.history, FallbackUse::kept);
    report.row("fallback constants", fmt::format("{}: steps solved again from it: {}; steps that kept its solution: {}", listed(settings.fallback),
                                                 resolved.empty() ? "none" : resolved, kept.empty() ? "none" : kept));
  }
}

class LoadStepsDriver final : public ProblemDriver {
 public:
  [[nodiscard]] std::string_view name() const override { return "load steps"; }
  [[nodiscard]] std::string_view table() const override { return kStepsTable; }
  [[nodiscard]] bool claims(const Scene& scene) const override { return scene.has_extension(kStepsTable); }
  [[nodiscard]] bool restartable() const override { return true; }
  void check(const DriverContext& ctx) const override {
    const LoadStepSettings settings = read_steps(*ctx.scene);
    const LoadStepper stepper(ctx, settings);
  }
  [[nodiscard]] RunReport run(const DriverContext& ctx) const override {
    const LoadStepSettings settings = read_steps(*ctx.scene);
    LoadStepper stepper(ctx, settings);
    const LoadStepRun run = stepper.run();
    RunReport report;
    report.problem = std::string(stepper.bound().solver->name());
    report.success = run.failure.empty();
    const std::string kept = steps_with(run.history, FallbackUse::kept);
    report.status = !run.failure.empty()            ? "STOPPED: " + run.failure
                    : settings.until < settings.count ? fmt::format("stopped after step {} as asked (steps.until): --restart continues", settings.until)
                    : !kept.empty() ? "every step converged, step(s) " + kept + " only with the fallback constants (steps.fallback)"
                                    : std::string("every step converged");
    if (run.history.empty()) throw std::runtime_error(report.status);
    describe_steps(settings, run, report);
    report.warnings.insert(report.warnings.end(), run.warnings.begin(), run.warnings.end());
    for (const auto& [step, message] : run.fallback_kept) report.warnings.push_back(message);
    report.fields = stepper.final_fields();
    report_step_history(kHistoryFormat, run.history, ctx.output_directory, ctx.scene->name, report);
    return report;
  }
};

}  // namespace

const ProblemDriver& load_steps_driver() {
  static const LoadStepsDriver driver;
  return driver;
}

}  // namespace lmeform::problems
