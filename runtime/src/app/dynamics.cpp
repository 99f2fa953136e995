#include "dynamics.hpp"

#include <Eigen/Dense>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <iostream>
#include <limits>
#include <numeric>
#include <ostream>
#include <sstream>

#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include "lmeform/assembler.hpp"
#include "lmeform/constrained_minimizer.hpp"
#include "lmeform/delaunay.hpp"
#include "lmeform/kernel.hpp"
#include "lmeform/node_sets.hpp"
#include "lmeform/output.hpp"
#include "lmeform/petsc.hpp"
#include "lmeform/scene_table.hpp"
#include "problem.hpp"

namespace lmeform::app {

namespace fs = std::filesystem;

std::optional<DynamicsSettings> read_dynamics(const Scene& s) {
  const auto t = extension_table(
      s, kDynamicsExtension,
      {"method", "deformation", "dissipation", "time_unit", "t_start", "t_end", "dt", "adaptive", "dt_max",
       "dt_min", "growth", "energy_decrement", "target_newton", "max_steps", "max_retries", "hessian", "min_jacobian",
       "output_every", "checkpoint_every", "report_times", "schedule"});
  if (!t) return std::nullopt;
  DynamicsSettings d;
  const std::string method = t->choice_of("method", t->optional_string("method").value_or("vti"), {"vti", "forward_euler"});
  d.method = method == "vti" ? DynamicsSettings::Method::vti : DynamicsSettings::Method::forward_euler;
  d.deformation = t->optional_string("deformation").value_or(d.deformation);
  d.dissipation = {t->string("dissipation"), t->where("dissipation")};
  d.time_unit = t->positive("time_unit", t->number("time_unit", d.time_unit));
  d.t_start = t->non_negative("t_start", t->number("t_start", 0.0));
  d.t_end = t->positive("t_end", t->number("t_end"));
  if (!(d.t_end > d.t_start)) t->fail_key("t_end", fmt::format("= {} must exceed t_start = {}", d.t_end, d.t_start));
  d.dt = t->positive("dt", t->number("dt"));
  d.adaptive = t->boolean("adaptive", d.adaptive);
  d.dt_max = t->non_negative("dt_max", t->number("dt_max", 0.0));
  d.dt_min = t->non_negative("dt_min", t->number("dt_min", 0.0));
  d.growth = t->number("growth", d.growth);
  if (!(d.growth >= 1)) t->fail_key("growth", fmt::format("must be at least 1, got {}", d.growth));
  d.energy_decrement = t->non_negative("energy_decrement", t->number("energy_decrement", 0.0));
  d.target_newton = t->at_least("target_newton", t->integer("target_newton", d.target_newton), 1);
  d.max_steps = t->at_least("max_steps", t->integer("max_steps", d.max_steps), 1);
  d.max_retries = t->at_least("max_retries", t->integer("max_retries", d.max_retries), 0);
  d.hessian_every_iteration =
      t->choice_of("hessian", t->optional_string("hessian").value_or("step"), {"step", "iteration"}) == "iteration";
  d.min_jacobian = t->non_negative("min_jacobian", t->number("min_jacobian", 0.0));
  d.output_every = t->at_least("output_every", t->integer("output_every", d.output_every), 0);
  d.checkpoint_every = t->at_least("checkpoint_every", t->integer("checkpoint_every", d.checkpoint_every), 0);
  if (t->has("report_times")) {
    const toml::node& n = t->require("report_times");
    const auto* a = n.as_array();
    if (a == nullptr) t->wrong_type("report_times", n, "an array of times");
    for (std::size_t i = 0; i < a->size(); ++i) {
      const double r = t->number_of("report_times[" + std::to_string(i) + "]", (*a)[i]);
      if (!(r > d.t_start && r <= d.t_end))
        t->fail_key("report_times", fmt::format("has {}, outside (t_start, t_end] = ({}, {}]", r, d.t_start, d.t_end));
      d.report_times.push_back(r);
    }
    std::sort(d.report_times.begin(), d.report_times.end());
  }
  if (const auto sched = t->optional_any_table("schedule")) {
    for (const auto& [key, node] : sched->entries()) {
      const std::string name(key.str());
      const auto e = sched->table_of(name, node, {"rate", "from", "until", "at", "value"});
      ScheduledConstant c;
      c.name = name;
      c.where = sched->where(name);
      if (e.has("rate")) {
        if (e.has("at") || e.has("value")) e.fail_key("rate", "a schedule is a rate (rate, from, until) or a jump (at, value), not both");
        c.kind = ScheduledConstant::Kind::rate;
        c.rate = e.number("rate");
        c.from = e.number("from", d.t_start);
        c.until = e.number("until", d.t_end);
        if (!(c.until > c.from)) e.fail_key("until", fmt::format("= {} must exceed from = {}", c.until, c.from));
      } else {
        c.kind = ScheduledConstant::Kind::jump;
        c.at = e.number("at");
        c.value = e.number("value");
      }
      d.schedule.push_back(c);
    }
  }
  return d;
}

namespace {

double seconds_since(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

nlohmann::json number(double v) { return std::isfinite(v) ? nlohmann::json(v) : nlohmann::json(nullptr); }

/// The smallest det F = det(∂y/∂X) over the quadrature points, and where.
struct JacobianMinimum {
  double value = std::numeric_limits<double>::infinity();
  int point = -1;
};

JacobianMinimum min_jacobian(const Discretization& disc, const std::vector<double>& y_original, int bs, int offset) {
  const int dim = disc.dim();
  const int J = kernel::jet_size(dim, 1);
  std::vector<double> tab(static_cast<std::size_t>(disc.max_element_points() * J * disc.max_element_nodes()));
  LmeWorkspace ws;
  const auto original = disc.original_index();
  JacobianMinimum local;
  double F[9];
  for (int e = 0; e < disc.n_elements(); ++e) {
    const auto nodes = disc.element_nodes(e);
    const auto n = nodes.size();
    disc.tabulate(e, 1, tab, ws);
    for (int q = 0; q < disc.element_point_count(e); ++q) {
      for (int i = 0; i < dim; ++i)
        for (int j = 0; j < dim; ++j) {
          double f = 0;
          for (std::size_t a = 0; a < n; ++a)
            f += tab[(std::size_t(q * J + 1 + j)) * n + a] *
                 y_original[std::size_t(original[std::size_t(nodes[a])]) * std::size_t(bs) + std::size_t(offset + i)];
          F[i * dim + j] = f;
        }
      const double det = dim == 1 ? F[0]
                         : dim == 2 ? F[0] * F[3] - F[1] * F[2]
                                    : F[0] * (F[4] * F[8] - F[5] * F[7]) - F[1] * (F[3] * F[8] - F[5] * F[6]) +
                                          F[2] * (F[3] * F[7] - F[4] * F[6]);
      if (det < local.value) local = {det, disc.element_first_point(e) + q};
    }
  }
  struct {
    double value;
    int point;
  } in{local.value, local.point}, out{};
  MPI_Allreduce(&in, &out, 1, MPI_DOUBLE_INT, MPI_MINLOC, disc.comm());
  return {out.value, out.point};
}

void zero_dofs(Vec v, const std::vector<PetscInt>& dofs) {
  if (dofs.empty()) {
    LMEFORM_PETSC_CHECK(VecAssemblyBegin(v));
    LMEFORM_PETSC_CHECK(VecAssemblyEnd(v));
    return;
  }
  std::vector<PetscScalar> zeros(dofs.size(), 0.0);
  LMEFORM_PETSC_CHECK(VecSetValues(v, static_cast<PetscInt>(dofs.size()), dofs.data(), zeros.data(), INSERT_VALUES));
  LMEFORM_PETSC_CHECK(VecAssemblyBegin(v));
  LMEFORM_PETSC_CHECK(VecAssemblyEnd(v));
}

double dot(Vec a, Vec b) {
  PetscScalar d = 0;
  LMEFORM_PETSC_CHECK(VecDot(a, b, &d));
  return static_cast<double>(d);
}

}  // namespace

DynamicsRun run_dynamics(MPI_Comm comm, const Scene& scene, const DynamicsSettings& settings, const DynamicsOutput* output,
                         std::ostream* log) {
  const auto t_begin = std::chrono::steady_clock::now();
  int rank = 0;
  MPI_Comm_rank(comm, &rank);
  std::ostream* out = rank == 0 ? log : nullptr;
  DynamicsRun run;
  const BoundScene b = bind_scene(scene, comm, log, {}, {}, {settings.dissipation});
  if (b.kind != ProblemKind::minimization)
    throw SceneError(fmt::format("{}: [dynamics] moves the minimizer of energies: name energies in model.energy", scene.source));
  const int dim = scene.dim();
  const auto deformation = std::find_if(b.unknowns.begin(), b.unknowns.end(), [&](const UnknownField& u) { return u.name == settings.deformation; });
  if (deformation == b.unknowns.end() || deformation->components != dim || b.unknowns.size() != 1)
    throw SceneError(fmt::format("{}: key 'dynamics.deformation': '{}' must be the problem's only unknown, a vector of {} "
                                 "components (the current positions y of the reference points)",
                                 scene.source, settings.deformation, dim));
  const kernel::FormKernels& dissipation_kernel = *b.auxiliary.front();
  int coefficient_offset = -1, coefficients_per_node = 0;
  for (int i = 0; i < dissipation_kernel.n_coefficients; ++i) {
    if (dissipation_kernel.coefficients[i].name == settings.deformation) coefficient_offset = coefficients_per_node;
    coefficients_per_node += dissipation_kernel.coefficients[i].components;
  }
  if (coefficient_offset < 0)
    throw SceneError(fmt::format("{}: the dissipation {}.{} does not read the deformation as `coefficient {} : vector`",
                                 settings.dissipation.where, dissipation_kernel.module, dissipation_kernel.name,
                                 settings.deformation));
  for (const auto& c : settings.schedule)
    if (!b.constants.contains(c.name)) {
      std::vector<std::string> names;
      for (const auto& [n, v] : b.constants) names.push_back(n);
      throw SceneError(fmt::format("{}: '{}' is no constant of the forms{}", c.where, c.name, did_you_mean(c.name, names)));
    }

  ProblemInput input;
  input.nodes = initial_nodes(scene, log);
  input.lme.spacing_smoothing = scene.nodes.spacing_smoothing;
  input.initial = settings.start_state;
  input.log = log;
  ProblemSpace space = build_problem_space(comm, b, input);
  const Discretization& disc = *space.disc;
  const int bs = b.dofs_per_node;
  Assembler& dissipation = *space.auxiliary.front();
  Vec dissipation_coefficients = space.coefficient_vectors.back();
  run.reference_nodes = input.nodes;
  run.cells = delaunay(input.nodes);
  {
    const auto h = disc.basis().spacing();
    run.h_min = *std::min_element(h.begin(), h.end());
  }
  for (const auto& c : space.constraints) run.constraint_names.push_back(c.name);
  const std::size_t k = space.constraints.size();

  ConstrainedMinimizerOptions options;
  options.skip_augmented_stage = true;  // yⁿ satisfies the constraints: Newton on the KKT system from there
  options.refresh_hessian_every_iteration = settings.hessian_every_iteration;
  options.newton_tolerance = scene.solver.newton_tolerance;
  options.constraint_tolerance = scene.solver.constraint_tolerance;
  options.max_newton_iterations = scene.solver.max_newton_iterations;
  options.penalty = scene.solver.penalty;
  ConstrainedMinimizer minimizer(space.energy_terms, space.constraints, options);
  minimizer.set_fixed_dofs(space.fixed);

  PetscVector u = space.primary->create_vector(), yn = space.primary->create_vector(), trial = space.primary->create_vector();
  PetscVector gradient = space.primary->create_vector(), w = space.primary->create_vector();
  std::vector<PetscVector> G, Z;
  for (std::size_t i = 0; i < k; ++i) {
    G.push_back(space.primary->create_vector());
    Z.push_back(space.primary->create_vector());
  }
  set_from_original(disc, space.state, bs, u);
  PetscMatrix K = dissipation.create_matrix();
  PetscLinearSolver euler_ksp;
  if (settings.method == DynamicsSettings::Method::forward_euler) {
    LMEFORM_PETSC_CHECK(KSPCreate(comm, euler_ksp.out()));
    LMEFORM_PETSC_CHECK(KSPSetType(euler_ksp, KSPPREONLY));
    PC pc = nullptr;
    LMEFORM_PETSC_CHECK(KSPGetPC(euler_ksp, &pc));
    LMEFORM_PETSC_CHECK(PCSetType(pc, PCLU));
    LMEFORM_PETSC_CHECK(PCFactorSetMatSolverType(pc, MATSOLVERMUMPS));
  }

  auto energy_of = [&](Vec state) {
    double e = 0;
    for (Assembler* term : space.energy_terms) e += term->value(state);
    return e;
  };
  auto constraint_values = [&](Vec state) {
    std::vector<double> v;
    for (const auto& c : space.constraints) v.push_back(c.functional->value(state));
    return v;
  };

  // Scheduled constants start from their values at the start (a target given "initial" included).
  const std::vector<double> start_constraints = constraint_values(u);
  std::vector<double> base_targets;
  for (std::size_t i = 0; i < k; ++i) base_targets.push_back(space.constraints[i].target);
  auto apply_schedule = [&](double t) {
    for (const auto& c : settings.schedule) {
      const auto target_of = std::find_if(b.constraints.begin(), b.constraints.end(),
                                          [&](const BoundConstraint& bc) { return bc.target_constant == c.name; });
      const std::size_t ci = static_cast<std::size_t>(target_of - b.constraints.begin());
      const double base = target_of != b.constraints.end() ? base_targets[ci] : space.constants.at(c.name);
      double value = base;
      if (c.kind == ScheduledConstant::Kind::rate) {
        if (t > c.from) value = base * (1 + c.rate * (std::min(t, c.until) - c.from));
      } else if (t >= c.at) {
        value = c.value;
      }
      if (target_of != b.constraints.end()) {
        minimizer.set_target(ci, value);
        continue;
      }
      for (auto& a : space.assemblers)
        for (int i = 0; i < a->form().n_constants; ++i)
          if (a->form().constants[i] == c.name) a->set_constant(c.name, value);
    }
  };

  auto set_dissipation_state = [&](Vec state) {
    {
      const VecReadView y(state);
      VecWriteView c(dissipation_coefficients);
      const PetscInt owned = y.size() / bs;
      for (PetscInt a = 0; a < owned; ++a)
        for (int i = 0; i < dim; ++i)
          c[a * coefficients_per_node + coefficient_offset + i] = y[a * bs + deformation->offset + i];
    }
    dissipation.set_coefficients(dissipation_coefficients);  // the assembler keeps a ghosted copy
  };

  std::vector<double> nu(k, 0.0);  // scaled multipliers
  if (!settings.start_multipliers.empty()) {
    if (settings.start_multipliers.size() != k) throw std::invalid_argument("run_dynamics: wrong number of starting multipliers");
    for (std::size_t i = 0; i < k; ++i) nu[i] = settings.start_multipliers[i] * space.constraints[i].scale;
  }

  double t = settings.t_start;
  double dt = settings.dt;
  double target_decrement = settings.energy_decrement;
  int step = 0;
  std::vector<TimeSeriesStep> series;
  std::vector<double> velocity(input.nodes.size() * std::size_t(bs), 0.0);
  const fs::path checkpoint_path = output != nullptr ? output->directory / (output->name + "_checkpoint.h5") : fs::path();
  const fs::path history_path = output != nullptr ? output->directory / (output->name + "_history.json") : fs::path();

  auto record = [&](Vec state, double energy, int newton, int rejected, double dt_taken) {
    DynamicsStep s;
    s.step = step;
    s.t_star = t;
    s.dt_star = dt_taken;
    s.energy = energy;
    s.constraints = constraint_values(state);
    for (std::size_t i = 0; i < k; ++i) s.multipliers.push_back(nu[i] / space.constraints[i].scale);
    s.newton_iterations = newton;
    s.rejected = rejected;
    s.min_jacobian = min_jacobian(disc, to_original(disc, state, bs), bs, deformation->offset).value;
    s.wall_s = seconds_since(t_begin);
    run.history.push_back(s);
    if (out != nullptr) {
      std::string drift;
      for (std::size_t i = 0; i < k; ++i)
        drift += fmt::format("  {} {:+.1e}", space.constraints[i].name,
                             (s.constraints[i] - start_constraints[i]) / std::max(std::abs(start_constraints[i]), 1e-300));
      *out << fmt::format("step {:5d}  t* {:.4e}  dt* {:.3e}  E {:.8f}  Newton {:2d}  rejected {}{}  det F {:.3f}  {:.1f} s",
                          s.step, s.t_star, s.dt_star, s.energy, newton, rejected, drift, s.min_jacobian, s.wall_s)
           << std::endl;
    }
  };

  // Scalar coefficient fields (the reference phase field) go to every time-series file.
  std::vector<std::pair<std::string, std::vector<double>>> scalar_fields;
  for (const auto& c : b.coefficients)
    if (c.components == 1) scalar_fields.emplace_back(c.name, coefficient_values(b, c.name, 1, input.nodes));

  auto write_series = [&](Vec state) {
    if (output == nullptr) return;
    const std::vector<double> y = to_original(disc, state, bs);
    if (rank != 0) return;
    const std::size_t n = input.nodes.size();
    std::vector<double> positions(n * std::size_t(dim)), displacement(n * std::size_t(dim)), v(n * std::size_t(dim));
    for (std::size_t a = 0; a < n; ++a)
      for (int i = 0; i < dim; ++i) {
        const std::size_t s = a * std::size_t(bs) + std::size_t(deformation->offset + i);
        positions[a * std::size_t(dim) + std::size_t(i)] = y[s];
        displacement[a * std::size_t(dim) + std::size_t(i)] = y[s] - input.nodes.point(a)[std::size_t(i)];
        v[a * std::size_t(dim) + std::size_t(i)] = velocity[s];
      }
    FieldViews fields;
    fields.emplace("displacement", FieldView{displacement, dim});
    fields.emplace("velocity", FieldView{v, dim});
    for (const auto& [name, values] : scalar_fields) fields.emplace(name, FieldView{values, 1});
    const std::string file = fmt::format("series/{}_{:06d}.h5", output->name, step);
    fs::create_directories(output->directory / "series");
    write_field_hdf5(output->directory / file, NodeSet(dim, positions), run.cells, fields,
                     {{"t_star", t}, {"step", static_cast<std::int64_t>(step)}, {"energy", run.history.back().energy}});
    TimeSeriesStep entry;
    entry.time = t;
    entry.h5_file = file;
    entry.dim = dim;
    entry.nodes = n;
    entry.cells = run.cells.size();
    for (const auto& [name, view] : fields) entry.fields.emplace_back(name, view.components);
    series.push_back(entry);
    if (dim >= 2) write_xdmf_time_series(output->directory / (output->name + ".xmf"), series);
  };

  auto history_json = [&]() {
    nlohmann::json js;
    js["scene"] = scene.name;
    js["method"] = settings.method == DynamicsSettings::Method::vti ? "vti" : "forward_euler";
    js["time_unit"] = settings.time_unit;
    js["constraints"] = run.constraint_names;
    js["steps"] = nlohmann::json::array();
    for (const auto& s : run.history)
      js["steps"].push_back({{"step", s.step},
                             {"t_star", s.t_star},
                             {"dt_star", s.dt_star},
                             {"energy", number(s.energy)},
                             {"constraints", s.constraints},
                             {"multipliers", s.multipliers},
                             {"newton_iterations", s.newton_iterations},
                             {"rejected", s.rejected},
                             {"min_jacobian", number(s.min_jacobian)},
                             {"wall_s", s.wall_s}});
    js["series"] = nlohmann::json::array();
    for (const auto& s : series) js["series"].push_back({{"time", s.time}, {"file", s.h5_file.generic_string()}});
    return js;
  };

  auto write_checkpoint = [&]() {
    if (output == nullptr) return;
    const std::vector<double> y = to_original(disc, u, bs);
    if (rank != 0) return;
    OutputAttributes attributes{{"step", static_cast<std::int64_t>(step)},
                                {"t_star", t},
                                {"dt_star", dt},
                                {"target_decrement", target_decrement},
                                {"accepted", static_cast<std::int64_t>(run.accepted)},
                                {"rejected", static_cast<std::int64_t>(run.rejected)},
                                {"scene", scene.source}};
    for (std::size_t i = 0; i < k; ++i) attributes.emplace(fmt::format("multiplier_{}", i), nu[i]);
    write_text_atomically(history_path, history_json().dump(1) + "\n");
    write_field_hdf5(checkpoint_path, input.nodes, run.cells, {{"state", FieldView{y, bs}}, {"velocity", FieldView{velocity, bs}}},
                     attributes);
  };

  bool resumed = false;
  if (output != nullptr && output->restart) {
    if (!fs::exists(checkpoint_path) || !fs::exists(history_path))
      throw std::runtime_error(fmt::format("--restart: no checkpoint in {} (expected {} and {})", output->directory.string(),
                                           checkpoint_path.filename().string(), history_path.filename().string()));
    const FieldFile cp = read_field_hdf5(checkpoint_path);
    if (cp.nodes.coords != input.nodes.coords)
      throw std::runtime_error(fmt::format("--restart: {} was written for other nodes than the scene's", checkpoint_path.string()));
    auto attr = [&](const char* name) -> const OutputAttribute& {
      const auto it = cp.attributes.find(name);
      if (it == cp.attributes.end()) throw std::runtime_error(fmt::format("--restart: {} has no attribute '{}'", checkpoint_path.string(), name));
      return it->second;
    };
    set_from_original(disc, cp.fields.at("state").values, bs, u);
    velocity = cp.fields.at("velocity").values;
    step = static_cast<int>(std::get<std::int64_t>(attr("step")));
    t = std::get<double>(attr("t_star"));
    dt = std::get<double>(attr("dt_star"));
    target_decrement = std::get<double>(attr("target_decrement"));
    run.accepted = static_cast<int>(std::get<std::int64_t>(attr("accepted")));
    run.rejected = static_cast<int>(std::get<std::int64_t>(attr("rejected")));
    for (std::size_t i = 0; i < k; ++i) nu[i] = std::get<double>(attr(fmt::format("multiplier_{}", i).c_str()));
    std::ifstream in(history_path);
    const nlohmann::json js = nlohmann::json::parse(in);
    for (const auto& s : js.at("steps")) {
      if (s.at("step").get<int>() > step) break;
      DynamicsStep d;
      d.step = s.at("step");
      d.t_star = s.at("t_star");
      d.dt_star = s.at("dt_star");
      d.energy = s.at("energy").is_null() ? std::nan("") : s.at("energy").get<double>();
      d.constraints = s.at("constraints").get<std::vector<double>>();
      d.multipliers = s.at("multipliers").get<std::vector<double>>();
      d.newton_iterations = s.at("newton_iterations");
      d.rejected = s.at("rejected");
      d.min_jacobian = s.at("min_jacobian").is_null() ? std::nan("") : s.at("min_jacobian").get<double>();
      d.wall_s = s.at("wall_s");
      run.history.push_back(d);
    }
    for (const auto& s : js.at("series")) {
      if (s.at("time").get<double>() > t) break;
      TimeSeriesStep e;
      e.time = s.at("time");
      e.h5_file = s.at("file").get<std::string>();
      e.dim = dim;
      e.nodes = input.nodes.size();
      e.cells = run.cells.size();
      e.fields = {{"displacement", dim}, {"velocity", dim}};
      for (const auto& [name, values] : scalar_fields) e.fields.emplace_back(name, 1);
      std::sort(e.fields.begin(), e.fields.end());
      series.push_back(e);
    }
    resumed = true;
    if (out != nullptr) *out << fmt::format("resumed from {} at step {}, t* {:.6e}\n", checkpoint_path.string(), step, t);
  }
  run.seconds_setup = seconds_since(t_begin);
  if (!resumed) {
    apply_schedule(t);
    record(u, energy_of(u), 0, 0, 0.0);
    write_series(u);
  }

  const double real_time = settings.time_unit;  // Δt = Δt* · time_unit
  const double dt_min = settings.dt_min > 0 ? settings.dt_min : settings.dt * std::pow(2.0, -20);
  std::size_t next_report = 0;
  while (next_report < settings.report_times.size() && settings.report_times[next_report] <= t * (1 + 1e-12)) ++next_report;
  const double t_tolerance = 1e-12 * std::max(std::abs(settings.t_end), 1.0);
  while (t < settings.t_end - t_tolerance) {
    if (step >= settings.max_steps) {
      run.failure = fmt::format("stopped after max_steps = {} steps at t* = {:.6e}", settings.max_steps, t);
      break;
    }
    const double energy_before = run.history.back().energy;
    double dt_try = dt;
    int rejected = 0;
    bool accepted = false;
    ConstrainedResult last;
    std::string why;
    while (!accepted) {
      double dt_step = std::min(dt_try, settings.t_end - t);
      if (next_report < settings.report_times.size()) dt_step = std::min(dt_step, settings.report_times[next_report] - t);
      apply_schedule(t + dt_step);
      LMEFORM_PETSC_CHECK(VecCopy(u, yn));
      {
        const double t0 = MPI_Wtime();
        set_dissipation_state(yn);
        dissipation.matrix(yn, K);
        run.seconds_dissipation += MPI_Wtime() - t0;
      }
      bool ok = true;
      if (settings.method == DynamicsSettings::Method::vti) {
        LMEFORM_PETSC_CHECK(VecCopy(yn, trial));
        minimizer.set_proximal_term({K, yn, 1.0 / (dt_step * real_time)});
        std::vector<double> nu_trial = nu;
        last = minimizer.minimize(trial, nu_trial);
        run.gradient_evaluations += last.gradient_evaluations;
        run.hessian_evaluations += last.hessian_evaluations;
        run.seconds_hessian += last.seconds_hessian;
        run.seconds_solve += last.seconds_factor;
        ok = last.converged;
        if (!ok) why = last.message;
      } else {
        // [K G; Gᵀ 0][ẏ; σ] = [−∇E; 0] by the Schur complement on σ, one factorization of K.
        const double t0 = MPI_Wtime();
        LMEFORM_PETSC_CHECK(MatZeroRowsColumns(K, static_cast<PetscInt>(space.fixed.size()), space.fixed.data(), 1.0, nullptr, nullptr));
        LMEFORM_PETSC_CHECK(KSPSetOperators(euler_ksp, K, K));
        LMEFORM_PETSC_CHECK(KSPSetUp(euler_ksp));
        LMEFORM_PETSC_CHECK(VecSet(gradient, 0.0));
        double e = 0;
        for (Assembler* term : space.energy_terms) e += term->add_value_and_vector(yn, gradient, -1.0);
        (void)e;
        zero_dofs(gradient, space.fixed);
        for (std::size_t i = 0; i < k; ++i) {
          (void)space.constraints[i].functional->value_and_vector(yn, G[i]);
          zero_dofs(G[i], space.fixed);
        }
        ++run.gradient_evaluations;
        LMEFORM_PETSC_CHECK(KSPSolve(euler_ksp, gradient, w));
        Eigen::MatrixXd S(static_cast<Eigen::Index>(k), static_cast<Eigen::Index>(k));
        Eigen::VectorXd rhs(static_cast<Eigen::Index>(k));
        for (std::size_t i = 0; i < k; ++i) LMEFORM_PETSC_CHECK(KSPSolve(euler_ksp, G[i], Z[i]));
        for (std::size_t i = 0; i < k; ++i) {
          rhs[Eigen::Index(i)] = dot(G[i], w);
          for (std::size_t j = 0; j < k; ++j) S(Eigen::Index(i), Eigen::Index(j)) = dot(G[i], Z[j]);
        }
        const Eigen::VectorXd sigma = k > 0 ? Eigen::VectorXd(S.fullPivLu().solve(rhs)) : Eigen::VectorXd();
        for (std::size_t i = 0; i < k; ++i) LMEFORM_PETSC_CHECK(VecAXPY(w, -sigma[Eigen::Index(i)], Z[i]));
        LMEFORM_PETSC_CHECK(VecWAXPY(trial, dt_step * real_time, w, yn));
        for (std::size_t i = 0; i < k; ++i) nu[i] = -sigma[Eigen::Index(i)] * space.constraints[i].scale;
        run.seconds_solve += MPI_Wtime() - t0;
        last = ConstrainedResult{};
        last.energy = energy_of(trial);
        last.converged = std::isfinite(last.energy);
        ok = last.converged;
        if (!ok) why = "the energy is not finite";
      }
      if (ok) {
        const JacobianMinimum jm = min_jacobian(disc, to_original(disc, trial, bs), bs, deformation->offset);
        if (!(jm.value > settings.min_jacobian)) {
          ok = false;
          const auto x = disc.quadrature().point(std::size_t(jm.point));
          why = fmt::format("det F = {:.3e} at quadrature point {} (reference position ({:.4g}, {:.4g}))", jm.value, jm.point, x[0],
                            dim > 1 ? x[1] : 0.0);
        }
      }
      if (ok) {
        accepted = true;
        if (settings.method == DynamicsSettings::Method::vti) {
          nu = std::vector<double>(k);
          for (std::size_t i = 0; i < k; ++i) nu[i] = last.multipliers[i] * space.constraints[i].scale;
        }
        {
          const std::vector<double> y1 = to_original(disc, trial, bs), y0 = to_original(disc, yn, bs);
          for (std::size_t i = 0; i < velocity.size(); ++i) velocity[i] = (y1[i] - y0[i]) / (dt_step * real_time);
        }
        LMEFORM_PETSC_CHECK(VecCopy(trial, u));
        t += dt_step;
        ++step;
        ++run.accepted;
        while (next_report < settings.report_times.size() && settings.report_times[next_report] <= t + t_tolerance) {
          run.energy_at[settings.report_times[next_report]] = last.energy;
          ++next_report;
        }
        const double shortened = dt_step;  // the step taken (report times and t_end shorten it)
        // Δt for the next step: the energy decrement per step near its target, bounded growth,
        // shorter when Newton needed many iterations.
        if (settings.adaptive) {
          const double decrement = std::abs(energy_before - last.energy);
          if (target_decrement <= 0 && decrement > 0) target_decrement = decrement;
          // The decrement per unit time is decrement / shortened; the step that meets the target:
          double next = decrement > 0 ? target_decrement * shortened / decrement : settings.growth * dt_try;
          next = std::clamp(next, 0.5 * dt_try, settings.growth * dt_try);
          if (last.newton_iterations > settings.target_newton) next = std::min(next, 0.5 * dt_try);
          dt = std::max(next, dt_min);
          if (settings.dt_max > 0) dt = std::min(dt, settings.dt_max);
        } else {
          dt = dt_try;
        }
        dt_try = shortened;
        break;
      }
      ++rejected;
      ++run.rejected;
      if (out != nullptr) *out << fmt::format("  step {} rejected at dt* {:.3e}: {}; retrying with dt* {:.3e}\n", step + 1, dt_step, why, dt_step / 2);
      dt_try = dt_step / 2;
      if (rejected > settings.max_retries || dt_try < dt_min) break;
    }
    if (!accepted) {
      run.failure = fmt::format("step {} failed {} times down to dt* = {:.3e}: {}", step + 1, rejected, dt_try, why);
      apply_schedule(t);
      break;
    }
    record(u, last.energy, settings.method == DynamicsSettings::Method::vti ? last.newton_iterations : 0, rejected, dt_try);
    const bool finished = t >= settings.t_end - t_tolerance;
    if (settings.output_every > 0 && (step % settings.output_every == 0 || finished)) write_series(u);
    else if (finished) write_series(u);
    if (settings.checkpoint_every > 0 && step % settings.checkpoint_every == 0) write_checkpoint();
  }
  if (!run.failure.empty() && settings.checkpoint_every > 0) write_checkpoint();
  if (output != nullptr && rank == 0) write_text_atomically(history_path, history_json().dump(1) + "\n");
  run.final_state = to_original(disc, u, bs);
  for (std::size_t i = 0; i < k; ++i) run.final_multipliers.push_back(nu[i] / space.constraints[i].scale);
  run.wall_s = seconds_since(t_begin);
  return run;
}

int run_dynamics_command(MPI_Comm comm, const Scene& scene, const fs::path& out_dir, const std::string& json_path, bool restart) {
  int rank = 0;
  MPI_Comm_rank(comm, &rank);
  std::ostream* log = rank == 0 ? &std::cout : nullptr;
  const DynamicsSettings settings = *read_dynamics(scene);
  DynamicsOutput output{out_dir, scene.name, restart};
  const DynamicsRun run = run_dynamics(comm, scene, settings, &output, log);
  if (rank == 0) {
    const auto& first = run.history.front();
    const auto& last = run.history.back();
    double dt_lo = std::numeric_limits<double>::infinity(), dt_hi = 0;
    std::vector<double> max_drift(run.constraint_names.size(), 0.0);
    for (std::size_t s = 1; s < run.history.size(); ++s) {
      dt_lo = std::min(dt_lo, run.history[s].dt_star);
      dt_hi = std::max(dt_hi, run.history[s].dt_star);
      for (std::size_t i = 0; i < max_drift.size(); ++i)
        max_drift[i] = std::max(max_drift[i], std::abs(run.history[s].constraints[i] - first.constraints[i]) /
                                                  std::max(std::abs(first.constraints[i]), 1e-300));
    }
    std::printf("\n%-26s %s\n", "scene", scene.source.c_str());
    std::printf("%-26s %s\n", "status", run.failure.empty() ? "reached t_end" : ("STOPPED: " + run.failure).c_str());
    std::printf("%-26s %s\n", "method", settings.method == DynamicsSettings::Method::vti ? "variational (VTI)" : "forward Euler");
    std::printf("%-26s %.6e -> %.6e\n", "t*", first.t_star, last.t_star);
    std::printf("%-26s %.8f -> %.8f\n", "energy", first.energy, last.energy);
    if (scene.reference.energy)
      std::printf("%-26s %.6f (final relative difference %+.3f %%)\n", "reference energy", *scene.reference.energy,
                  100 * (last.energy - *scene.reference.energy) / *scene.reference.energy);
    for (std::size_t i = 0; i < max_drift.size(); ++i)
      std::printf("%-26s %.3e (final multiplier %.6g)\n", ("max drift of " + run.constraint_names[i]).c_str(), max_drift[i],
                  last.multipliers.empty() ? 0.0 : last.multipliers[i]);
    std::printf("%-26s %d accepted, %d rejected\n", "steps", run.accepted, run.rejected);
    if (run.history.size() > 1) std::printf("%-26s %.3e .. %.3e (ratio %.0f)\n", "dt*", dt_lo, dt_hi, dt_hi / dt_lo);
    std::printf("%-26s %d gradient, %d Hessian\n", "evaluations", run.gradient_evaluations, run.hessian_evaluations);
    std::printf("%-26s setup %.2f, dissipation K %.2f, Hessian of E %.2f, factor+solve %.2f, resets %.2f\n", "times (s)",
                run.seconds_setup, run.seconds_dissipation, run.seconds_hessian, run.seconds_solve, run.seconds_reset);
    std::printf("%-26s %.1f s\n", "total wall time", run.wall_s);
    std::printf("%-26s %s (ParaView), %s\n", "time series", (out_dir / (scene.name + ".xmf")).string().c_str(),
                (out_dir / (scene.name + "_history.json")).string().c_str());
    if (!json_path.empty()) {
      nlohmann::json js;
      js["scene"] = scene.name;
      js["problem"] = "dynamics";
      js["method"] = settings.method == DynamicsSettings::Method::vti ? "vti" : "forward_euler";
      js["status"] = run.failure.empty() ? "reached t_end" : run.failure;
      js["energy_start"] = number(first.energy);
      js["energy"] = number(last.energy);
      js["t_star"] = last.t_star;
      js["steps"] = run.accepted;
      js["rejected"] = run.rejected;
      js["gradient_evaluations"] = run.gradient_evaluations;
      js["hessian_evaluations"] = run.hessian_evaluations;
      js["dt_min"] = number(dt_lo);
      js["dt_max"] = number(dt_hi);
      js["max_relative_drift"] = nlohmann::json::object();
      for (std::size_t i = 0; i < max_drift.size(); ++i) js["max_relative_drift"][run.constraint_names[i]] = max_drift[i];
      js["wall_s"] = run.wall_s;
      write_text_atomically(json_path, js.dump(2) + "\n");
    }
  }
  return run.failure.empty() ? 0 : 2;
}

}  // namespace lmeform::app
