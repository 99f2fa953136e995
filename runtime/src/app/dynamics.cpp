#include "dynamics.hpp"

#include <Eigen/Dense>

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <iostream>
#include <limits>
#include <memory>
#include <numeric>
#include <set>
#include <ostream>
#include <sstream>

#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include "lmeform/assembler.hpp"
#include "lmeform/constrained_minimizer.hpp"
#include "lmeform/cvt.hpp"
#include "lmeform/delaunay.hpp"
#include "lmeform/kernel.hpp"
#include "lmeform/node_sets.hpp"
#include "lmeform/output.hpp"
#include "lmeform/petsc.hpp"
#include "lmeform/scene_table.hpp"
#include "problem.hpp"

namespace lmeform::app {

namespace fs = std::filesystem;

/// One segment of a scheduled constant: a rate {rate, from, until} or a jump {at, value}. Messages
/// name the constant's key; the segment's line follows from the file. (External linkage: inlined,
/// GCC 12 reports a false -Wrestrict in SceneTable::table_of's message.)
ScheduledConstant read_schedule_segment(const SceneTable& sched, const std::string& name, const toml::node& segment,
                                        const DynamicsSettings& d) {
  const auto e = sched.table_of(name, segment, {"rate", "from", "until", "at", "value"});
  ScheduledConstant c;
  c.name = name;
  c.where = sched.where(name);
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
  return c;
}

std::optional<DynamicsSettings> read_dynamics(const Scene& s) {
  const auto t = extension_table(
      s, kDynamicsExtension,
      {"method", "deformation", "dissipation", "time_unit", "t_start", "t_end", "dt", "adaptive", "dt_max",
       "dt_min", "growth", "energy_decrement", "target_newton", "max_steps", "max_retries", "hessian", "min_jacobian",
       "output_every", "checkpoint_every", "report_times", "schedule", "reset_every", "reset_distortion", "require_decrease", "remesh_every", "remesh_factor",
       "remesh_iterations", "remesh_field", "remesh_fit_iterations", "remesh_projection", "remesh_gradient_length", "remesh_nodes"});
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
  d.require_decrease = t->boolean("require_decrease", d.require_decrease);
  d.remesh_every = t->at_least("remesh_every", t->integer("remesh_every", d.remesh_every), 0);
  d.remesh_factor = t->non_negative("remesh_factor", t->number("remesh_factor", d.remesh_factor));
  d.remesh_iterations = t->at_least("remesh_iterations", t->integer("remesh_iterations", d.remesh_iterations), 0);
  if (t->has("remesh_field")) d.remesh_field = t->string("remesh_field");
  d.remesh_nodes = std::size_t(t->at_least("remesh_nodes", t->integer("remesh_nodes", 0), 0));
  d.remesh_projection = t->choice_of("remesh_projection", t->optional_string("remesh_projection").value_or("points"), {"points", "nodes"}) == "points"
                            ? DynamicsSettings::Projection::points
                            : DynamicsSettings::Projection::nodes;
  d.remesh_fit_iterations = t->at_least("remesh_fit_iterations", t->integer("remesh_fit_iterations", d.remesh_fit_iterations), 0);
  d.remesh_gradient_length = t->non_negative("remesh_gradient_length", t->number("remesh_gradient_length", 0.0));
  d.reset_every = t->at_least("reset_every", t->integer("reset_every", d.reset_every), 0);
  d.reset_distortion = t->non_negative("reset_distortion", t->number("reset_distortion", 0.0));
  if (d.reset_distortion > 0 && d.reset_distortion <= 1)
    t->fail_key("reset_distortion", fmt::format("= {} must exceed 1 (the ratio of F's singular values; 1 is no distortion)", d.reset_distortion));
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
      // One segment ({...}) or a history of segments in time order ([{...}, {...}]).
      std::vector<const toml::node*> segments;
      if (const auto* list = node.as_array()) {
        if (list->empty()) sched->fail_key(name, "is an empty list: give at least one segment {rate, from, until} or {at, value}");
        for (const auto& seg : *list) segments.push_back(&seg);
      } else {
        segments.push_back(&node);
      }
      double previous_time = -std::numeric_limits<double>::infinity();
      for (const toml::node* segment : segments) {
        ScheduledConstant c = read_schedule_segment(*sched, name, *segment, d);
        const double begins = c.kind == ScheduledConstant::Kind::rate ? c.from : c.at;
        if (begins < previous_time)
          sched->fail_key(name, fmt::format("has a segment starting at {} before the previous one's start ({}): list the "
                                            "segments in time order",
                                            begins, previous_time));
        previous_time = begins;
        d.schedule.push_back(c);
      }
    }
  }
  return d;
}

namespace {

double seconds_since(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

nlohmann::json number(double v) { return std::isfinite(v) ? nlohmann::json(v) : nlohmann::json(nullptr); }

/// Measures of the deformation over the quadrature points: the smallest det F (and where), and
/// the largest distortion, the ratio of F's extreme singular values. Axisymmetric: F of the body
/// of revolution, whose hoop stretch y_r / R joins the (r, z) block, so that a map carrying points
/// across the axis counts as folded.
struct DeformationMeasures {
  double min_jacobian = std::numeric_limits<double>::infinity();
  int point = -1;
  double max_distortion = 1;
};

/// The current position y(X), F and ∂²y/∂X∂X at each quadrature point of this rank's owned
/// elements (`tab` the element's tabulation at `order`, 1 or 2).
template <class PerPoint>
void for_each_point_kinematics(const Discretization& disc, const std::vector<double>& y_original, int bs, int offset,
                               int order, PerPoint&& per_point) {
  const int dim = disc.dim();
  const int J = kernel::jet_size(dim, order);
  std::vector<double> tab(static_cast<std::size_t>(disc.max_element_points() * J * disc.max_element_nodes()));
  LmeWorkspace ws;
  const auto original = disc.original_index();
  std::array<double, 3> position{};
  std::array<double, 9> F{};
  std::array<double, 27> H{};  // H[(k*dim + I)*dim + J] = ∂²y_k / ∂X_I ∂X_J
  for (int e = 0; e < disc.n_elements(); ++e) {
    if (!disc.element_owned(e)) continue;
    const auto nodes = disc.element_nodes(e);
    const auto n = nodes.size();
    disc.tabulate(e, order, tab, ws);
    for (int q = 0; q < disc.element_point_count(e); ++q) {
      auto y = [&](std::size_t a, int k) {
        return y_original[std::size_t(original[std::size_t(nodes[a])]) * std::size_t(bs) + std::size_t(offset + k)];
      };
      for (int k = 0; k < dim; ++k) {
        double x = 0;
        for (std::size_t a = 0; a < n; ++a) x += tab[std::size_t(q * J) * n + a] * y(a, k);
        position[std::size_t(k)] = x;
        for (int I = 0; I < dim; ++I) {
          double f = 0;
          for (std::size_t a = 0; a < n; ++a) f += tab[std::size_t(q * J + 1 + I) * n + a] * y(a, k);
          F[std::size_t(k * dim + I)] = f;
          if (order < 2) continue;
          for (int K = I; K < dim; ++K) {
            const auto slot = std::size_t(kernel::hessian_slot(I, K, dim));
            double h = 0;
            for (std::size_t a = 0; a < n; ++a) h += tab[(std::size_t(q * J) + slot) * n + a] * y(a, k);
            H[std::size_t((k * dim + I) * dim + K)] = H[std::size_t((k * dim + K) * dim + I)] = h;
          }
        }
      }
      per_point(disc.element_first_point(e) + q, position, F, H);
    }
  }
}

DeformationMeasures deformation_measures(const Discretization& disc, const std::vector<double>& y_original, int bs, int offset,
                                         bool axisymmetric) {
  const int dim = disc.dim();
  DeformationMeasures local;
  const CellQuadrature& quad = disc.quadrature();
  for_each_point_kinematics(disc, y_original, bs, offset, 1,
                            [&](int point, const std::array<double, 3>& y, const std::array<double, 9>& F,
                                const std::array<double, 27>&) {
                              Eigen::MatrixXd M(dim, dim);
                              for (int i = 0; i < dim; ++i)
                                for (int j = 0; j < dim; ++j) M(i, j) = F[std::size_t(i * dim + j)];
                              double det = M.determinant();
                              const Eigen::VectorXd sv = Eigen::JacobiSVD<Eigen::MatrixXd>(M).singularValues();
                              double largest = sv.maxCoeff(), smallest = sv.minCoeff();
                              const double R = quad.point(std::size_t(point))[0];
                              if (axisymmetric && R > 0) {
                                const double hoop = y[0] / R;
                                det *= hoop;
                                largest = std::max(largest, std::abs(hoop));
                                smallest = std::min(smallest, std::abs(hoop));
                              }
                              if (det < local.min_jacobian) {
                                local.min_jacobian = det;
                                local.point = point;
                              }
                              if (smallest > 0) local.max_distortion = std::max(local.max_distortion, largest / smallest);
                            });
  struct {
    double value;
    int point;
  } in{local.min_jacobian, local.point}, out{};
  MPI_Allreduce(&in, &out, 1, MPI_DOUBLE_INT, MPI_MINLOC, disc.comm());
  double distortion = local.max_distortion;
  MPI_Allreduce(MPI_IN_PLACE, &distortion, 1, MPI_DOUBLE, MPI_MAX, disc.comm());
  return {out.value, out.point, distortion};
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

namespace {

/// One reference configuration: its discretization and assemblers, the minimizer of a time step,
/// the vectors of a step. Rebuilt by a reset of the reference configuration.
struct Reference {
  ProblemSpace space;
  std::unique_ptr<ConstrainedMinimizer> minimizer;
  PetscVector u, yn, trial, gradient, w;
  std::vector<PetscVector> G, Z;
  PetscMatrix K;
  PetscLinearSolver euler_ksp;
  NodeSet nodes;                        ///< the reference nodes (original order)
};

/// ∂φ/∂y = F⁻ᵀ ∂φ0/∂X at quadrature point p: a reference gradient jet carried to the current
/// configuration (Fi = F⁻¹).
Eigen::VectorXd pushed_forward_gradient(const Eigen::MatrixXd& Fi, const std::vector<double>& reference_gradients, std::size_t p, int dim) {
  Eigen::VectorXd G0(dim);
  for (int I = 0; I < dim; ++I) G0[I] = reference_gradients[p * std::size_t(dim) + std::size_t(I)];
  return Fi.transpose() * G0;
}

/// The scene's quadrature data that are jets of a nodal field, by field: value, gradient, Hessian names.
struct FieldJets {
  std::string value, gradient, hessian;
};

std::map<std::string, FieldJets> field_jets(const Scene& scene) {
  std::map<std::string, FieldJets> jets;
  for (const auto& q : scene.qdata) {
    if (q.provider != "field") continue;
    FieldJets& j = jets[q.field];
    (q.derivative == 0 ? j.value : q.derivative == 1 ? j.gradient : j.hessian) = q.name;
  }
  return jets;
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
  const int offset = deformation->offset;
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
  const std::map<std::string, FieldJets> jets = field_jets(scene);
  if (settings.remesh_every > 0 &&
      std::none_of(b.coefficients.begin(), b.coefficients.end(), [&](const UnknownField& c) { return c.name == settings.remesh_field && c.components == 1; }))
    throw SceneError(fmt::format("{}: key 'dynamics.remesh_field': '{}' is no scalar field of [coefficients] (the re-mesh "
                                 "adapts the nodes to its gradient)",
                                 scene.source, settings.remesh_field));
  const bool resets = settings.reset_every > 0 || settings.reset_distortion > 0;
  if (resets)
    for (const auto& [field, j] : jets)
      if (!j.hessian.empty() && j.gradient.empty())
        throw SceneError(fmt::format("{}: a reset pushes the Hessian of '{}' forward with its gradient: give [qdata] "
                                     "{{ field = \"{}\", jet = \"gradient\" }} too",
                                     scene.source, field, field));

  const bool euler = settings.method == DynamicsSettings::Method::forward_euler;
  NodeSet material_nodes = initial_nodes(scene, log);  // the nodes' identities (a re-mesh makes new ones)
  run.cells = delaunay(material_nodes);
  // The material boundary: found once on the material nodes and kept by resets (a node's
  // coefficient may leave the box, LME not being interpolating; it stays free).
  std::vector<std::vector<int>> dirichlet_sets = dirichlet_nodes(scene, material_nodes);
  std::size_t n_nodes = material_nodes.size();
  const int bs = b.dofs_per_node;
  std::size_t k = 0;
  std::vector<double> targets;  // the current constraint targets (schedules move them)
  std::vector<double> scales;   // the constraint scales of the start (the multipliers nu are scaled by them)

  auto build = [&](const NodeSet& nodes, const std::vector<double>& state, std::optional<CarriedQuadrature> carried,
                   std::map<std::string, std::vector<double>, std::less<>> qdata, bool keep_targets,
                   std::map<std::string, std::vector<double>, std::less<>> coefficients = {}) {
    auto r = std::make_unique<Reference>();
    ProblemInput input;
    input.nodes = nodes;
    input.lme.spacing_smoothing = scene.nodes.spacing_smoothing;
    input.initial = state;
    input.log = nullptr;
    input.carried = std::move(carried);
    input.qdata_values = std::move(qdata);
    input.coefficient_values = std::move(coefficients);
    input.dirichlet_nodes = dirichlet_sets;
    if (keep_targets)
      for (std::size_t i = 0; i < b.constraints.size(); ++i) {
        input.targets[b.constraints[i].name] = targets[i];
        input.scales[b.constraints[i].name] = scales[i];
      }
    r->space = build_problem_space(comm, b, input);
    r->nodes = nodes;
    ConstrainedMinimizerOptions options;
    options.kkt_first = true;             // yⁿ satisfies the constraints: Newton on the KKT system from there
    options.augmented_fallback = false;   // a step Newton cannot take is retried shorter, not minimized at length
    options.refresh_hessian_every_iteration = settings.hessian_every_iteration;
    options.newton_tolerance = scene.solver.newton_tolerance;
    options.constraint_tolerance = scene.solver.constraint_tolerance;
    options.max_newton_iterations = scene.solver.max_newton_iterations;
    options.penalty = scene.solver.penalty;
    if (scene.solver.monitor) options.log = out;
    r->minimizer = std::make_unique<ConstrainedMinimizer>(r->space.energy_terms, r->space.constraints, options);
    r->minimizer->set_fixed_dofs(r->space.fixed);
    Assembler& primary = *r->space.primary;
    r->u = primary.create_vector();
    r->yn = primary.create_vector();
    r->trial = primary.create_vector();
    r->gradient = primary.create_vector();
    r->w = primary.create_vector();
    for (std::size_t i = 0; i < r->space.constraints.size(); ++i) {
      r->G.push_back(primary.create_vector());
      r->Z.push_back(primary.create_vector());
    }
    set_from_original(*r->space.disc, r->space.state, bs, r->u);
    r->K = r->space.auxiliary.front()->create_matrix();
    if (euler) {
      LMEFORM_PETSC_CHECK(KSPCreate(comm, r->euler_ksp.out()));
      LMEFORM_PETSC_CHECK(KSPSetType(r->euler_ksp, KSPPREONLY));
      PC pc = nullptr;
      LMEFORM_PETSC_CHECK(KSPGetPC(r->euler_ksp, &pc));
      LMEFORM_PETSC_CHECK(PCSetType(pc, PCLU));
      LMEFORM_PETSC_CHECK(PCFactorSetMatSolverType(pc, MATSOLVERMUMPS));
    }
    return r;
  };

  std::unique_ptr<Reference> ref = build(material_nodes, settings.start_state, std::nullopt, {}, false);
  k = ref->space.constraints.size();
  for (const auto& c : ref->space.constraints) {
    run.constraint_names.push_back(c.name);
    targets.push_back(c.target);
    scales.push_back(c.scale);
  }
  {
    const auto h = ref->space.disc->basis().spacing();
    run.h_min = *std::min_element(h.begin(), h.end());
  }
  run.reference_nodes = material_nodes;

  auto energy_of = [&](Vec state) {
    double e = 0;
    for (Assembler* term : ref->space.energy_terms) e += term->value(state);
    return e;
  };
  auto constraint_values = [&](Vec state) {
    std::vector<double> v;
    for (const auto& c : ref->space.constraints) v.push_back(c.functional->value(state));
    return v;
  };

  // Scheduled constants start from their values at the start (a target given "initial" included).
  const std::vector<double> start_constraints = constraint_values(ref->u);
  const std::vector<double> base_targets = targets;
  // A constant's value at t: the last jump at or before t (else its start value), plus the rates'
  // changes relative to the start value, each rate acting over its own interval.
  auto apply_schedule = [&](double t) {
    std::set<std::string> done;
    for (const auto& first : settings.schedule) {
      if (!done.insert(first.name).second) continue;
      const auto target_of = std::find_if(b.constraints.begin(), b.constraints.end(),
                                          [&](const BoundConstraint& bc) { return bc.target_constant == first.name; });
      const std::size_t ci = static_cast<std::size_t>(target_of - b.constraints.begin());
      const double base = target_of != b.constraints.end() ? base_targets[ci] : ref->space.constants.at(first.name);
      double value = base, change = 0;
      for (const auto& c : settings.schedule) {
        if (c.name != first.name) continue;
        if (c.kind == ScheduledConstant::Kind::rate) {
          if (t > c.from) change += base * c.rate * (std::min(t, c.until) - c.from);
        } else if (t >= c.at) {
          value = c.value;
        }
      }
      value += change;
      if (target_of != b.constraints.end()) {
        targets[ci] = value;
        ref->minimizer->set_target(ci, value);
        continue;
      }
      for (auto& a : ref->space.assemblers)
        for (int i = 0; i < a->form().n_constants; ++i)
          if (a->form().constants[i] == first.name) a->set_constant(first.name, value);
    }
  };

  auto assemble_dissipation = [&](Vec state) {
    const double t0 = MPI_Wtime();
    Assembler& dissipation = *ref->space.auxiliary.front();
    Vec coefficients = ref->space.coefficient_vectors.back();
    {
      const VecReadView y(state);
      VecWriteView c(coefficients);
      const PetscInt owned = y.size() / bs;
      for (PetscInt a = 0; a < owned; ++a)
        for (int i = 0; i < dim; ++i) c[a * coefficients_per_node + coefficient_offset + i] = y[a * bs + offset + i];
    }
    dissipation.set_coefficients(coefficients);  // the assembler keeps a ghosted copy
    dissipation.matrix(state, ref->K);
    run.seconds_dissipation += MPI_Wtime() - t0;
  };

  std::vector<double> nu(k, 0.0);  // scaled multipliers
  if (!settings.start_multipliers.empty()) {
    if (settings.start_multipliers.size() != k) throw std::invalid_argument("run_dynamics: wrong number of starting multipliers");
    for (std::size_t i = 0; i < k; ++i) nu[i] = settings.start_multipliers[i] * ref->space.constraints[i].scale;
  }

  double t = settings.t_start;
  double dt = settings.dt;
  double target_decrement = settings.energy_decrement;
  int step = 0;
  int steps_since_reset = 0;
  int steps_since_remesh = 0;
  std::vector<TimeSeriesStep> series;
  std::vector<double> velocity(n_nodes * std::size_t(bs), 0.0);
  const fs::path checkpoint_path = output != nullptr ? output->directory / (output->name + "_checkpoint.h5") : fs::path();
  const fs::path quadrature_path = output != nullptr ? output->directory / (output->name + "_checkpoint_quadrature.h5") : fs::path();
  const fs::path history_path = output != nullptr ? output->directory / (output->name + "_history.json") : fs::path();

  // `measures`: those of `state` when the caller has them (an accepted step was just checked).
  auto record = [&](Vec state, double energy, int newton, int rejected, double dt_taken,
                    std::optional<DeformationMeasures> measures = std::nullopt) {
    DynamicsStep s;
    s.step = step;
    s.t_star = t;
    s.dt_star = dt_taken;
    s.energy = energy;
    s.constraints = constraint_values(state);
    for (std::size_t i = 0; i < k; ++i) s.multipliers.push_back(nu[i] / ref->space.constraints[i].scale);
    s.newton_iterations = newton;
    s.rejected = rejected;
    const DeformationMeasures m =
        measures ? *measures : deformation_measures(*ref->space.disc, to_original(*ref->space.disc, state, bs), bs, offset, scene.axisymmetric());
    s.min_jacobian = m.min_jacobian;
    s.distortion = m.max_distortion;
    s.resets = run.resets;
    s.wall_s = seconds_since(t_begin);
    run.history.push_back(s);
    if (out != nullptr) {
      std::string drift;
      for (std::size_t i = 0; i < k; ++i)
        drift += fmt::format("  {} {:+.1e}", ref->space.constraints[i].name,
                             (s.constraints[i] - start_constraints[i]) / std::max(std::abs(start_constraints[i]), 1e-300));
      *out << fmt::format("step {:5d}  t* {:.4e}  dt* {:.3e}  E {:.8f}  Newton {:2d}  rejected {}  resets {}{}  det F {:.3f}  {:.1f} s",
                          s.step, s.t_star, s.dt_star, s.energy, newton, rejected, run.resets, drift, s.min_jacobian, s.wall_s)
           << std::endl;
    }
  };

  // Scalar coefficient fields (the reference phase field) go to every time-series file: material
  // values, carried by the nodes.
  std::vector<std::pair<std::string, std::vector<double>>> scalar_fields;
  for (const auto& c : b.coefficients)
    if (c.components == 1) scalar_fields.emplace_back(c.name, coefficient_values(b, c.name, 1, material_nodes));

  auto write_series = [&](Vec state) {
    if (output == nullptr) return;
    const std::vector<double> y = to_original(*ref->space.disc, state, bs);
    if (rank != 0) return;
    std::vector<double> positions(n_nodes * std::size_t(dim)), displacement(n_nodes * std::size_t(dim)), v(n_nodes * std::size_t(dim));
    for (std::size_t a = 0; a < n_nodes; ++a)
      for (int i = 0; i < dim; ++i) {
        const std::size_t s = a * std::size_t(bs) + std::size_t(offset + i);
        positions[a * std::size_t(dim) + std::size_t(i)] = y[s];
        displacement[a * std::size_t(dim) + std::size_t(i)] = y[s] - material_nodes.point(a)[std::size_t(i)];
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
    entry.nodes = n_nodes;
    entry.cells = run.cells.size();
    for (const auto& [name, view] : fields) entry.fields.emplace_back(name, view.components);
    series.push_back(entry);
    if (dim >= 2) write_xdmf_time_series(output->directory / (output->name + ".xmf"), series);
  };

  auto history_json = [&]() {
    nlohmann::json js;
    js["scene"] = scene.name;
    js["method"] = euler ? "forward_euler" : "vti";
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
                             {"distortion", number(s.distortion)},
                             {"resets", s.resets},
                             {"wall_s", s.wall_s}});
    js["series"] = nlohmann::json::array();
    for (const auto& s : series)
      js["series"].push_back({{"time", s.time}, {"file", s.h5_file.generic_string()}, {"nodes", s.nodes}, {"cells", s.cells}});
    return js;
  };

  // The reference configuration's quadrature (points, weights) and its field jets: what a reset
  // changes, written with a checkpoint so that a restart continues on the same reference.
  auto write_checkpoint = [&]() {
    if (output == nullptr) return;
    const std::vector<double> y = to_original(*ref->space.disc, ref->u, bs);
    if (rank != 0) return;
    OutputAttributes attributes{{"step", static_cast<std::int64_t>(step)},
                                {"t_star", t},
                                {"dt_star", dt},
                                {"target_decrement", target_decrement},
                                {"accepted", static_cast<std::int64_t>(run.accepted)},
                                {"rejected", static_cast<std::int64_t>(run.rejected)},
                                {"gradient_evaluations", static_cast<std::int64_t>(run.gradient_evaluations)},
                                {"hessian_evaluations", static_cast<std::int64_t>(run.hessian_evaluations)},
                                {"resets", static_cast<std::int64_t>(run.resets)},
                                {"steps_since_reset", static_cast<std::int64_t>(steps_since_reset)},
                                {"remeshes", static_cast<std::int64_t>(run.remeshes)},
                                {"steps_since_remesh", static_cast<std::int64_t>(steps_since_remesh)},
                                {"scene", scene.source}};
    for (std::size_t i = 0; i < run.remesh_changes.size(); ++i) attributes.emplace(fmt::format("remesh_change_{}", i), run.remesh_changes[i]);
    for (std::size_t i = 0; i < k; ++i) {
      attributes.emplace(fmt::format("multiplier_{}", i), nu[i]);
      attributes.emplace(fmt::format("target_{}", i), targets[i]);
    }
    if (run.resets > 0 || run.remeshes > 0) {
      // The quadrature as a point set (no cells) with its weights and jets as point data.
      const CellQuadrature& quad = ref->space.disc->quadrature();
      FieldViews qfields;
      qfields.emplace("weight", FieldView{quad.weights, 1});
      for (const auto& [name, values] : ref->space.qdata) {
        const int size = static_cast<int>(values.size() / quad.size());
        qfields.emplace("qdata_" + name, FieldView{values, size});
      }
      BackgroundCells none;
      none.dim = dim;
      none.vertices_per_cell = dim + 1;
      write_field_hdf5(quadrature_path, NodeSet(dim, quad.points), none, qfields,
                       {{"step", static_cast<std::int64_t>(step)}, {"points_per_cell", static_cast<std::int64_t>(quad.points_per_cell)}});
    }
    write_text_atomically(history_path, history_json().dump(1) + "\n");
    // After a re-mesh the material nodes, their triangulation and the projected nodal fields are new.
    FieldViews fields{{"state", FieldView{y, bs}}, {"velocity", FieldView{velocity, bs}}, {"material_nodes", FieldView{material_nodes.coords, dim}}};
    for (const auto& [name, values] : scalar_fields) fields.emplace("field_" + name, FieldView{values, 1});
    write_field_hdf5(checkpoint_path, ref->nodes, run.cells, fields, attributes);
  };

  // Reset of the reference configuration (seed Fig. 3.8): the current positions become the nodes,
  // the quadrature points are carried (x̂ → y(x̂), w → w det F), the field values at the points are
  // kept, their gradients and Hessians pushed forward, the basis rebuilt; nothing is projected.
  auto relative = [](double after, double before) { return (after - before) / std::max(std::abs(before), 1e-300); };
  auto material_fields = [&]() {
    std::map<std::string, std::vector<double>, std::less<>> values;
    for (const auto& [name, v] : scalar_fields) values[name] = v;
    return values;
  };
  // Where the material points of the nodes went, y(X_a), not the coefficients y_a: LME is not
  // interpolating, and a free node's coefficient can leave the domain (measured: r = -0.11 beside
  // the axis of a compressed graded grid). Nodes held in every component of y keep their
  // prescribed place (on hull vertices the map's value is the coefficient anyway). Returns the
  // positions and the state y with those positions as its coefficients (the identity on them).
  auto material_node_positions = [&](const std::vector<double>& y) {
    std::vector<int> held(n_nodes, 0);
    for (const auto& [node, dof] : ref->space.fixed_pairs)
      if (dof >= offset && dof < offset + dim) ++held[std::size_t(node)];
    std::vector<double> positions(n_nodes * std::size_t(dim));
    std::vector<double> state = y;
    LmeOptions lme;
    lme.spacing_smoothing = scene.nodes.spacing_smoothing;
    const LmeBasis basis(ref->nodes, std::vector<double>(n_nodes, scene.nodes.gamma), lme);
    for (std::size_t a = 0; a < n_nodes; ++a) {
      std::array<double, 3> x{};
      for (int i = 0; i < dim; ++i) x[std::size_t(i)] = y[a * std::size_t(bs) + std::size_t(offset + i)];
      if (held[a] < dim) {
        const auto X = ref->nodes.point(a);
        const auto list = basis.neighbours(X);
        const auto p = basis.evaluate(X, list, 0);
        for (int i = 0; i < dim; ++i) {
          double v = 0;
          for (std::size_t m = 0; m < list.size(); ++m) v += p[m] * y[std::size_t(list[m]) * std::size_t(bs) + std::size_t(offset + i)];
          x[std::size_t(i)] = v;
        }
      }
      for (int i = 0; i < dim; ++i) {
        positions[a * std::size_t(dim) + std::size_t(i)] = x[std::size_t(i)];
        state[a * std::size_t(bs) + std::size_t(offset + i)] = x[std::size_t(i)];
      }
    }
    return std::pair{positions, state};
  };
  auto reset_reference = [&]() {
    const double t0 = MPI_Wtime();
    apply_schedule(t);  // before and after at the same constants (a folding attempt set those of t + dt)
    const double energy_before = energy_of(ref->u);
    const std::vector<double> constraints_before = constraint_values(ref->u);
    const Discretization& disc = *ref->space.disc;
    const std::vector<double> y = to_original(disc, ref->u, bs);
    const CellQuadrature& quad = disc.quadrature();
    const std::size_t Q = quad.size();
    CarriedQuadrature carried;
    carried.cells = run.cells;
    carried.quadrature.dim = dim;
    carried.quadrature.points_per_cell = quad.points_per_cell;
    carried.quadrature.points.assign(Q * std::size_t(dim), 0.0);
    carried.quadrature.weights.assign(Q, 0.0);
    std::map<std::string, std::vector<double>, std::less<>> pushed;
    // Jets no assembler reads are not carried (a field's Hessian needs its gradient: checked at the start).
    std::map<std::string, FieldJets> carried_jets;
    for (const auto& [field, j] : jets) {
      FieldJets c;
      if (ref->space.qdata.contains(j.value)) c.value = j.value;
      if (ref->space.qdata.contains(j.gradient)) c.gradient = j.gradient;
      if (ref->space.qdata.contains(j.hessian) && !c.gradient.empty()) c.hessian = j.hessian;
      carried_jets[field] = c;
    }
    for (const auto& [field, j] : carried_jets) {
      if (!j.value.empty()) pushed[j.value] = ref->space.qdata.at(j.value);  // material: unchanged
      if (!j.gradient.empty()) pushed[j.gradient].assign(Q * std::size_t(dim), 0.0);
      if (!j.hessian.empty()) pushed[j.hessian].assign(Q * std::size_t(dim * dim), 0.0);
    }
    for_each_point_kinematics(
        disc, y, bs, offset, 2,
        [&](int point, const std::array<double, 3>& position, const std::array<double, 9>& F, const std::array<double, 27>& H) {
          const auto p = std::size_t(point);
          for (int i = 0; i < dim; ++i) carried.quadrature.points[p * std::size_t(dim) + std::size_t(i)] = position[std::size_t(i)];
          Eigen::MatrixXd Fm(dim, dim);
          for (int i = 0; i < dim; ++i)
            for (int I = 0; I < dim; ++I) Fm(i, I) = F[std::size_t(i * dim + I)];
          carried.quadrature.weights[p] = quad.weights[p] * Fm.determinant();
          const Eigen::MatrixXd Fi = Fm.inverse();  // Fi(I, i) = ∂X_I / ∂y_i
          for (const auto& [field, j] : carried_jets) {
            if (j.gradient.empty()) continue;
            const Eigen::VectorXd g = pushed_forward_gradient(Fi, ref->space.qdata.at(j.gradient), p, dim);
            for (int i = 0; i < dim; ++i) pushed[j.gradient][p * std::size_t(dim) + std::size_t(i)] = g[i];
            if (j.hessian.empty()) continue;
            // ∂²φ/∂y_i∂y_j = Fi_Ii Fi_Jj (∂²φ0/∂X_I∂X_J − Σ_k ∂φ/∂y_k ∂²y_k/∂X_I∂X_J)
            const auto& h0 = ref->space.qdata.at(j.hessian);
            Eigen::MatrixXd M(dim, dim);
            for (int I = 0; I < dim; ++I)
              for (int K = 0; K < dim; ++K) {
                double m = h0[p * std::size_t(dim * dim) + std::size_t(I * dim + K)];
                for (int kk = 0; kk < dim; ++kk) m -= g[kk] * H[std::size_t((kk * dim + I) * dim + K)];
                M(I, K) = m;
              }
            const Eigen::MatrixXd h = Fi.transpose() * M * Fi;
            for (int i = 0; i < dim; ++i)
              for (int jj = 0; jj < dim; ++jj) pushed[j.hessian][p * std::size_t(dim * dim) + std::size_t(i * dim + jj)] = h(i, jj);
          }
        });
    // Each point was computed on the rank owning its element.
    auto sum = [&](std::vector<double>& v) {
      MPI_Allreduce(MPI_IN_PLACE, v.data(), static_cast<int>(v.size()), MPI_DOUBLE, MPI_SUM, comm);
    };
    sum(carried.quadrature.points);
    sum(carried.quadrature.weights);
    for (const auto& [field, j] : carried_jets) {
      if (!j.gradient.empty()) sum(pushed[j.gradient]);
      if (!j.hessian.empty()) sum(pushed[j.hessian]);
    }
    auto carried_nodes = material_node_positions(y);
    const std::vector<double> state = std::move(carried_nodes.second);
    NodeSet nodes(dim, std::move(carried_nodes.first));
    ref = build(nodes, state, std::move(carried), std::move(pushed), true, material_fields());
    apply_schedule(t);
    // The same physical state: energy and constraints unchanged up to the basis' consistency error.
    ResetChange change;
    change.energy = relative(energy_of(ref->u), energy_before);
    for_each_point_kinematics(*ref->space.disc, state, bs, offset, 2,
                              [&](int, const std::array<double, 3>&, const std::array<double, 9>& F, const std::array<double, 27>& H) {
                                for (int i = 0; i < dim; ++i)
                                  for (int I = 0; I < dim; ++I)
                                    change.gradient_consistency =
                                        std::max(change.gradient_consistency, std::abs(F[std::size_t(i * dim + I)] - (i == I ? 1.0 : 0.0)));
                                for (int s = 0; s < dim * dim * dim; ++s)
                                  change.hessian_consistency = std::max(change.hessian_consistency, std::abs(H[std::size_t(s)]));
                              });
    MPI_Allreduce(MPI_IN_PLACE, &change.gradient_consistency, 1, MPI_DOUBLE, MPI_MAX, comm);
    MPI_Allreduce(MPI_IN_PLACE, &change.hessian_consistency, 1, MPI_DOUBLE, MPI_MAX, comm);
    const std::vector<double> constraints_after = constraint_values(ref->u);
    for (std::size_t i = 0; i < k; ++i)
      change.constraints.push_back(relative(constraints_after[i], constraints_before[i]));
    run.reset_changes.push_back(change);
    if (out != nullptr) {
      std::string c;
      for (std::size_t i = 0; i < k; ++i) c += fmt::format(", {} {:+.1e}", run.constraint_names[i], change.constraints[i]);
      const std::size_t outside = ref->space.disc->points_outside_carried_cells();
      *out << fmt::format("  reset {} of the reference configuration at step {}: relative change of E {:+.1e}{}; "
                          "identity reproduced to |F - I| {:.1e}, |D2 y| {:.1e}{}\n",
                          run.resets + 1, step, change.energy, c, change.gradient_consistency, change.hessian_consistency,
                          outside == 0 ? std::string()
                                       : fmt::format("; {} points carried out of their cells took an enclosing cell's vertices", outside))
           << std::flush;
    }
    ++run.resets;
    steps_since_reset = 0;
    run.seconds_reset += MPI_Wtime() - t0;
  };

  // A full re-mesh (the cases resets cannot help: nodes accumulated or spread too thin): new nodes
  // by CVT for the density 1 + f |∇φ| of the current field, every scalar nodal field interpolated
  // onto them (a projection: it changes E, and the change is reported), the motion restarted from
  // the identity on a new triangulation and quadrature.
  auto remesh = [&]() {
    const double t0 = MPI_Wtime();
    apply_schedule(t);
    const double energy_before = energy_of(ref->u);
    // The current node positions start the CVT, carry the density |∇φ| and, for fields without
    // point values, the interpolated field: the coefficients y_a, where the new basis reproduces the
    // first moments the old one does through the map (on the test box, with nodes at y(X_a) the
    // step after a `nodes` re-mesh raised E). A coefficient that left the box takes y(X_a) instead,
    // which stays inside.
    const std::vector<double> y = to_original(*ref->space.disc, ref->u, bs);
    const std::vector<double> inside = material_node_positions(y).first;
    std::vector<double> positions(n_nodes * std::size_t(dim));
    for (std::size_t a = 0; a < n_nodes; ++a) {
      bool out_of_box = false;
      for (int i = 0; i < dim; ++i) {
        const double x = y[a * std::size_t(bs) + std::size_t(offset + i)];
        out_of_box = out_of_box || x < scene.domain.lo[std::size_t(i)] || x > scene.domain.hi[std::size_t(i)];
      }
      for (int i = 0; i < dim; ++i)
        positions[a * std::size_t(dim) + std::size_t(i)] =
            out_of_box ? inside[a * std::size_t(dim) + std::size_t(i)] : y[a * std::size_t(bs) + std::size_t(offset + i)];
    }
    const NodeSet current(dim, positions);
    LmeOptions lme;
    lme.spacing_smoothing = scene.nodes.spacing_smoothing;
    if (scene.axisymmetric()) {  // scalar fields are even in r
      lme.mirror_axis = 0;
      lme.mirror_position = 0.0;
    }
    const auto field = std::find_if(scalar_fields.begin(), scalar_fields.end(),
                                    [&](const auto& f) { return f.first == settings.remesh_field; });
    std::vector<double> grad_norm(n_nodes, 0.0);
    std::vector<std::size_t> undefined_gradient;
    {
      const LmeBasis basis(current, std::vector<double>(n_nodes, scene.nodes.gamma), lme);
      const Box& box = scene.domain;
      for (std::size_t a = 0; a < n_nodes; ++a) {
        const auto x = current.point(a);
        // On the walls (fixed, the field is at its far value there) derivatives at hull vertices are undefined.
        bool on_wall = false;
        for (int i = 0; i < dim; ++i) {
          const double tol = 1e-9 * (box.hi[std::size_t(i)] - box.lo[std::size_t(i)]);
          on_wall = on_wall || x[std::size_t(i)] <= box.lo[std::size_t(i)] + tol || x[std::size_t(i)] >= box.hi[std::size_t(i)] - tol;
        }
        if (on_wall) continue;
        const auto list = basis.neighbours(x);
        std::vector<double> jet;
        try {
          jet = basis.evaluate(x, list, 1);
        } catch (const LmeEvaluationError&) {
          // The motion can leave a node at a vertex of its neighbours' hull (measured: beside the
          // waist of the eps = 0.01 prolate at step 150), where derivatives are undefined: the
          // density there takes the largest of its neighbours' values below.
          undefined_gradient.push_back(a);
          continue;
        }
        double g2 = 0;
        for (int i = 0; i < dim; ++i) {
          double g = 0;
          for (std::size_t m = 0; m < list.size(); ++m) g += jet[std::size_t(1 + i) * list.size() + m] * field->second[std::size_t(list[m])];
          g2 += g * g;
        }
        grad_norm[a] = std::sqrt(g2);
      }
      std::vector<double> filled = grad_norm;
      for (const std::size_t a : undefined_gradient)
        for (const int neighbour : basis.neighbours(current.point(a))) filled[a] = std::max(filled[a], grad_norm[std::size_t(neighbour)]);
      grad_norm.swap(filled);
    }
    CvtOptions cvt;
    cvt.iterations = settings.remesh_iterations;
    NodeSet start = current;
    const Density density = phase_field_density(settings.remesh_factor, current, grad_norm);
    if (settings.remesh_nodes > 0 && settings.remesh_nodes != n_nodes) {
      if (settings.remesh_nodes < n_nodes)
        throw std::runtime_error(fmt::format("{}: [dynamics] remesh_nodes = {} is below the {} nodes of the run: a re-mesh adds "
                                             "nodes, it does not remove them",
                                             scene.source, settings.remesh_nodes, n_nodes));
      // More nodes: the current ones keep their places (a good start for Lloyd), and one is added
      // at the centroid of each of the cells that hold most of a CVT's nodes for their size, the
      // measure times ρ^(dim/(dim+2)) (the node density of a CVT with density ρ).
      const BackgroundCells cells = delaunay(current);
      std::vector<std::pair<double, std::size_t>> share(cells.size());
      std::vector<double> centroids(cells.size() * std::size_t(dim), 0.0);
      for (std::size_t c = 0; c < cells.size(); ++c) {
        const std::span<double> x(centroids.data() + c * std::size_t(dim), std::size_t(dim));
        for (const int v : cells.cell(c))
          for (int i = 0; i < dim; ++i) x[std::size_t(i)] += current.point(std::size_t(v))[std::size_t(i)] / double(dim + 1);
        share[c] = {cells.measures[c] * std::pow(density(x), double(dim) / double(dim + 2)), c};
      }
      const std::size_t added = settings.remesh_nodes - n_nodes;
      if (added > cells.size())
        throw std::runtime_error(fmt::format("{}: [dynamics] remesh_nodes = {}: a re-mesh adds at most one node per cell, {} to the {} "
                                             "nodes of the run",
                                             scene.source, settings.remesh_nodes, cells.size(), n_nodes));
      std::partial_sort(share.begin(), share.begin() + std::ptrdiff_t(added), share.end(), std::greater<>());
      std::vector<double> coords = current.coords;
      for (std::size_t pick = 0; pick < added; ++pick) {
        const std::size_t c = share[pick].second;
        coords.insert(coords.end(), centroids.begin() + std::ptrdiff_t(c * std::size_t(dim)),
                      centroids.begin() + std::ptrdiff_t((c + 1) * std::size_t(dim)));
      }
      start = NodeSet(dim, std::move(coords));
    }
    const NodeSet nodes = cvt_relocate(start, scene.domain, density, cvt);
    // A field with a value jet is known exactly at the current quadrature points (a material field,
    // carried): its L2 projection onto the new space depends on no node positions. Otherwise the new
    // nodal values make the new LME field take the old field's values at the new nodes.
    std::vector<double> points, weights;
    std::map<std::string, std::vector<double>, std::less<>> point_gradients;  // by field, at the current points
    auto from_points = [&](const std::string& name) {
      const auto j = jets.find(name);
      return settings.remesh_projection == DynamicsSettings::Projection::points && j != jets.end() &&
             ref->space.qdata.contains(j->second.value);
    };
    if (std::any_of(scalar_fields.begin(), scalar_fields.end(), [&](const auto& f) { return from_points(f.first); })) {
      const Discretization& disc = *ref->space.disc;
      const CellQuadrature& quad = disc.quadrature();
      points.assign(quad.size() * std::size_t(dim), 0.0);
      weights.assign(quad.size(), 0.0);
      if (settings.remesh_gradient_length > 0)
        for (const auto& [name, values] : scalar_fields)
          if (from_points(name) && ref->space.qdata.contains(jets.at(name).gradient))
            point_gradients[name].assign(quad.size() * std::size_t(dim), 0.0);
      for_each_point_kinematics(disc, y, bs, offset, 1,
                                [&](int point, const std::array<double, 3>& position, const std::array<double, 9>& F, const std::array<double, 27>&) {
                                  const auto p = std::size_t(point);
                                  for (int i = 0; i < dim; ++i) points[p * std::size_t(dim) + std::size_t(i)] = position[std::size_t(i)];
                                  Eigen::MatrixXd Fm(dim, dim);
                                  for (int i = 0; i < dim; ++i)
                                    for (int I = 0; I < dim; ++I) Fm(i, I) = F[std::size_t(i * dim + I)];
                                  weights[p] = quad.weights[p] * Fm.determinant();
                                  if (point_gradients.empty()) return;
                                  const Eigen::MatrixXd Fi = Fm.inverse();
                                  for (auto& [name, g] : point_gradients) {
                                    const Eigen::VectorXd current_gradient =
                                        pushed_forward_gradient(Fi, ref->space.qdata.at(jets.at(name).gradient), p, dim);
                                    for (int i = 0; i < dim; ++i) g[p * std::size_t(dim) + std::size_t(i)] = current_gradient[i];
                                  }
                                });
      MPI_Allreduce(MPI_IN_PLACE, points.data(), static_cast<int>(points.size()), MPI_DOUBLE, MPI_SUM, comm);
      MPI_Allreduce(MPI_IN_PLACE, weights.data(), static_cast<int>(weights.size()), MPI_DOUBLE, MPI_SUM, comm);
      for (auto& [name, g] : point_gradients)
        MPI_Allreduce(MPI_IN_PLACE, g.data(), static_cast<int>(g.size()), MPI_DOUBLE, MPI_SUM, comm);
    }
    std::string projections;
    if (!undefined_gradient.empty())
      projections += fmt::format("; the density took a neighbour's |grad {}| at {} nodes where the gradient is undefined",
                                 settings.remesh_field, undefined_gradient.size());
    // The new values are gathered first and replace the old ones only when every field is carried.
    std::map<std::string, std::vector<double>, std::less<>> projected;
    for (const auto& [name, values] : scalar_fields) {
      // From the points, the old field at the new nodes only starts the CG iteration: where the
      // motion tore the old nodes apart and their basis cannot be evaluated, the nearest old value
      // does. Fitted to the old field, it must be evaluated everywhere.
      std::size_t fallbacks = 0;
      const std::vector<double> interpolated =
          interpolate_nodal_field(current, values, scene.nodes.gamma, lme, nodes, from_points(name) ? &fallbacks : nullptr);
      if (fallbacks > 0) projections += fmt::format("; the CG start took the nearest old value at {} new nodes", fallbacks);
      if (!from_points(name)) {
        projected[name] = fit_nodal_values(nodes, interpolated, scene.nodes.gamma, lme, settings.remesh_fit_iterations);
        continue;
      }
      const auto g = point_gradients.find(name);
      const bool h1 = g != point_gradients.end();
      PointProjection fit;
      try {
        fit = project_point_values(nodes, scene.nodes.gamma, lme, points, weights, ref->space.qdata.at(jets.at(name).value), interpolated,
                                   1e-8, 5000, h1 ? PointGradients{g->second, settings.remesh_gradient_length} : PointGradients{});
      } catch (const LmeEvaluationError& e) {
        // Measured on the eps = 0.01 prolate at step 120 (f = 1000 and 300): a carried quadrature
        // point beside the waist lay outside the hull of its new neighbours, whether the CVT started
        // from the coefficients y_a or from y(X_a). The run stops here, before anything is replaced.
        throw std::runtime_error(fmt::format("re-mesh {} at step {} (t* = {:.6e}, remesh_factor = {}, remesh_iterations = {}): a carried "
                                             "quadrature point cannot be evaluated on the new nodes: {}",
                                             run.remeshes + 1, step, t, settings.remesh_factor, settings.remesh_iterations, e.what()));
      }
      projected[name] = std::move(fit.values);
      projections += fmt::format("; '{}' {}-projected from the points ({} CG iterations, relative residual {:.1e})", name, h1 ? "H1" : "L2",
                                 fit.iterations, fit.relative_residual);
    }
    for (auto& [name, values] : scalar_fields) values = projected.at(name);
    material_nodes = nodes;
    dirichlet_sets = dirichlet_nodes(scene, material_nodes);
    n_nodes = nodes.size();
    run.cells = delaunay(nodes);
    velocity.assign(n_nodes * std::size_t(bs), 0.0);
    std::vector<double> identity(n_nodes * std::size_t(bs), 0.0);
    for (std::size_t a = 0; a < n_nodes; ++a)
      for (int i = 0; i < dim; ++i) identity[a * std::size_t(bs) + std::size_t(offset + i)] = nodes.point(a)[std::size_t(i)];
    ref = build(nodes, identity, std::nullopt, {}, true, std::move(projected));
    apply_schedule(t);
    run.reference_nodes = material_nodes;
    ++run.remeshes;
    steps_since_remesh = steps_since_reset = 0;
    const double energy_after = energy_of(ref->u);
    run.remesh_changes.push_back(relative(energy_after, energy_before));
    if (out != nullptr)
      *out << fmt::format("  re-mesh {} at step {}: {} nodes, the projection changed E by {:+.2e} (relative){}\n", run.remeshes, step,
                          n_nodes, run.remesh_changes.back(), projections)
           << std::flush;
    run.seconds_reset += MPI_Wtime() - t0;
  };

  bool resumed = false;
  if (output != nullptr && output->restart) {
    if (!fs::exists(checkpoint_path) || !fs::exists(history_path))
      throw std::runtime_error(fmt::format("--restart: no checkpoint in {} (expected {} and {})", output->directory.string(),
                                           checkpoint_path.filename().string(), history_path.filename().string()));
    const FieldFile cp = read_field_hdf5(checkpoint_path);
    auto attr = [&](const FieldFile& f, const fs::path& path, const std::string& name) -> const OutputAttribute& {
      const auto it = f.attributes.find(name);
      if (it == f.attributes.end()) throw std::runtime_error(fmt::format("--restart: {} has no attribute '{}'", path.string(), name));
      return it->second;
    };
    auto field = [&](const std::string& name) -> const std::vector<double>& {
      const auto it = cp.fields.find(name);
      if (it == cp.fields.end()) throw std::runtime_error(fmt::format("--restart: {} has no field '{}'", checkpoint_path.string(), name));
      return it->second.values;
    };
    step = static_cast<int>(std::get<std::int64_t>(attr(cp, checkpoint_path, "step")));
    run.resets = static_cast<int>(std::get<std::int64_t>(attr(cp, checkpoint_path, "resets")));
    // Checkpoints written before re-meshes were checkpointed have neither count: none had happened.
    auto count_or = [&](const char* name, int fallback) {
      const auto it = cp.attributes.find(name);
      return it == cp.attributes.end() ? fallback : static_cast<int>(std::get<std::int64_t>(it->second));
    };
    run.remeshes = count_or("remeshes", 0);
    steps_since_remesh = count_or("steps_since_remesh", step);
    if (run.remeshes == 0) {
      if (field("material_nodes") != material_nodes.coords)
        throw std::runtime_error(fmt::format("--restart: {} was written for other nodes than the scene's", checkpoint_path.string()));
    } else {  // the nodes, triangulation, boundary sets and nodal fields of the last re-mesh
      material_nodes = NodeSet(dim, field("material_nodes"));
      n_nodes = material_nodes.size();
      run.cells = cp.cells;
      run.reference_nodes = material_nodes;
      dirichlet_sets = dirichlet_nodes(scene, material_nodes);
      for (auto& [name, values] : scalar_fields) values = field("field_" + name);
      for (int i = 0; i < run.remeshes; ++i)
        run.remesh_changes.push_back(std::get<double>(attr(cp, checkpoint_path, fmt::format("remesh_change_{}", i))));
    }
    if (run.resets > 0 || run.remeshes > 0) {
      const FieldFile qf = read_field_hdf5(quadrature_path);
      if (std::get<std::int64_t>(attr(qf, quadrature_path, "step")) != step)
        throw std::runtime_error(fmt::format("--restart: {} belongs to another step than {}", quadrature_path.string(), checkpoint_path.string()));
      CarriedQuadrature carried;
      carried.cells = run.cells;
      carried.quadrature.dim = dim;
      carried.quadrature.points_per_cell = static_cast<int>(std::get<std::int64_t>(attr(qf, quadrature_path, "points_per_cell")));
      carried.quadrature.points = qf.nodes.coords;
      carried.quadrature.weights = qf.fields.at("weight").values;
      std::map<std::string, std::vector<double>, std::less<>> qdata;
      for (const auto& [name, f] : qf.fields)
        if (name.starts_with("qdata_")) qdata[name.substr(6)] = f.values;
      for (std::size_t i = 0; i < k; ++i) targets[i] = std::get<double>(attr(cp, checkpoint_path, fmt::format("target_{}", i)));
      ref = build(cp.nodes, field("state"), std::move(carried), std::move(qdata), true, material_fields());
    } else {
      for (std::size_t i = 0; i < k; ++i) targets[i] = std::get<double>(attr(cp, checkpoint_path, fmt::format("target_{}", i)));
      set_from_original(*ref->space.disc, field("state"), bs, ref->u);
    }
    velocity = field("velocity");
    t = std::get<double>(attr(cp, checkpoint_path, "t_star"));
    dt = std::get<double>(attr(cp, checkpoint_path, "dt_star"));
    // A target the scene states is the same at every step of an uninterrupted run: the scene's
    // wins (a restart with a new target applies it); only the automatic one (the first step's
    // decrement) is the checkpoint's.
    if (settings.energy_decrement <= 0) target_decrement = std::get<double>(attr(cp, checkpoint_path, "target_decrement"));
    run.accepted = static_cast<int>(std::get<std::int64_t>(attr(cp, checkpoint_path, "accepted")));
    run.rejected = static_cast<int>(std::get<std::int64_t>(attr(cp, checkpoint_path, "rejected")));
    // The evaluation counts carry on from the checkpoint (checkpoints written before they were
    // stored restart them from 0).
    for (auto [name, count] : {std::pair{"gradient_evaluations", &run.gradient_evaluations},
                               std::pair{"hessian_evaluations", &run.hessian_evaluations}})
      if (const auto it = cp.attributes.find(name); it != cp.attributes.end())
        *count = static_cast<int>(std::get<std::int64_t>(it->second));
    steps_since_reset = static_cast<int>(std::get<std::int64_t>(attr(cp, checkpoint_path, "steps_since_reset")));
    for (std::size_t i = 0; i < k; ++i) nu[i] = std::get<double>(attr(cp, checkpoint_path, fmt::format("multiplier_{}", i)));
    std::ifstream in(history_path);
    const nlohmann::json js = nlohmann::json::parse(in);
    auto number_or_nan = [](const nlohmann::json& v) { return v.is_null() ? std::nan("") : v.get<double>(); };
    for (const auto& s : js.at("steps")) {
      if (s.at("step").get<int>() > step) break;
      DynamicsStep d;
      d.step = s.at("step");
      d.t_star = s.at("t_star");
      d.dt_star = s.at("dt_star");
      d.energy = number_or_nan(s.at("energy"));
      d.constraints = s.at("constraints").get<std::vector<double>>();
      d.multipliers = s.at("multipliers").get<std::vector<double>>();
      d.newton_iterations = s.at("newton_iterations");
      d.rejected = s.at("rejected");
      d.min_jacobian = number_or_nan(s.at("min_jacobian"));
      d.distortion = number_or_nan(s.at("distortion"));
      d.resets = s.at("resets");
      d.wall_s = s.at("wall_s");
      run.history.push_back(d);
    }
    for (const auto& s : js.at("series")) {
      if (s.at("time").get<double>() > t) break;
      TimeSeriesStep e;
      e.time = s.at("time");
      e.h5_file = s.at("file").get<std::string>();
      e.dim = dim;
      e.nodes = s.value("nodes", n_nodes);  // a re-mesh changes the triangulation
      e.cells = s.value("cells", run.cells.size());
      e.fields = {{"displacement", dim}, {"velocity", dim}};
      for (const auto& [name, values] : scalar_fields) e.fields.emplace_back(name, 1);
      std::sort(e.fields.begin(), e.fields.end());
      series.push_back(e);
    }
    resumed = true;
    if (out != nullptr) *out << fmt::format("resumed from {} at step {}, t* {:.6e}, {} resets\n", checkpoint_path.string(), step, t, run.resets) << std::flush;
  }
  run.seconds_setup = seconds_since(t_begin);
  if (!resumed) {
    apply_schedule(t);
    record(ref->u, energy_of(ref->u), 0, 0, 0.0);
    write_series(ref->u);
  }

  const double real_time = settings.time_unit;  // Δt = Δt* · time_unit
  const double dt_min = settings.dt_min > 0 ? settings.dt_min : settings.dt * std::pow(2.0, -20);
  std::size_t next_report = 0;
  const double t_tolerance = 1e-12 * std::max(std::abs(settings.t_end), 1.0);
  while (next_report < settings.report_times.size() && settings.report_times[next_report] <= t + t_tolerance) {
    // Report times already passed (a restart): their energies from the history.
    for (const auto& h : run.history)
      if (std::abs(h.t_star - settings.report_times[next_report]) <= t_tolerance) run.energy_at[settings.report_times[next_report]] = h.energy;
    ++next_report;
  }
  while (t < settings.t_end - t_tolerance) {
    bool at_report_time = false;
    if (step >= settings.max_steps) {
      run.failure = fmt::format("stopped after max_steps = {} steps at t* = {:.6e}", settings.max_steps, t);
      break;
    }
    double energy_before = run.history.back().energy;
    bool new_reference = false;  // the recorded distortion belongs to the previous reference
    if (settings.remesh_every > 0 && steps_since_remesh >= settings.remesh_every) {
      remesh();
      energy_before = energy_of(ref->u);  // a projection changes E: the next decrement is measured from here
      new_reference = true;
    }
    // A reset every N steps, or when F is too distorted.
    if (resets && ((settings.reset_every > 0 && steps_since_reset >= settings.reset_every) ||
                   (!new_reference && settings.reset_distortion > 0 && run.history.back().distortion > settings.reset_distortion))) {
      reset_reference();
    }
    double dt_try = dt;
    int rejected = 0;
    bool accepted = false, reset_for_this_step = false;
    ConstrainedResult last;
    std::string why;
    double dt_attempted = dt_try;
    DeformationMeasures accepted_measures;
    while (!accepted) {
      double dt_step = std::min(dt_try, settings.t_end - t);
      dt_attempted = dt_step;
      if (next_report < settings.report_times.size()) dt_step = std::min(dt_step, settings.report_times[next_report] - t);
      apply_schedule(t + dt_step);
      Reference& r = *ref;
      LMEFORM_PETSC_CHECK(VecCopy(r.u, r.yn));
      assemble_dissipation(r.yn);
      bool ok = true, folded = false;
      if (!euler) {
        LMEFORM_PETSC_CHECK(VecCopy(r.yn, r.trial));
        r.minimizer->set_proximal_term({r.K, r.yn, 1.0 / (dt_step * real_time)});
        std::vector<double> nu_trial = nu;
        last = r.minimizer->minimize(r.trial, nu_trial);
        run.gradient_evaluations += last.gradient_evaluations;
        run.hessian_evaluations += last.hessian_evaluations;
        run.seconds_hessian += last.seconds_hessian;
        run.seconds_solve += last.seconds_factor;
        ok = last.converged;
        if (!ok) why = last.message;
      } else {
        // [K G; Gᵀ 0][ẏ; σ] = [−∇E; 0] by the Schur complement on σ, one factorization of K.
        const double t0 = MPI_Wtime();
        LMEFORM_PETSC_CHECK(MatZeroRowsColumns(r.K, static_cast<PetscInt>(r.space.fixed.size()), r.space.fixed.data(), 1.0, nullptr, nullptr));
        LMEFORM_PETSC_CHECK(KSPSetOperators(r.euler_ksp, r.K, r.K));
        LMEFORM_PETSC_CHECK(KSPSetUp(r.euler_ksp));
        LMEFORM_PETSC_CHECK(VecSet(r.gradient, 0.0));
        for (Assembler* term : r.space.energy_terms) (void)term->add_value_and_vector(r.yn, r.gradient, -1.0);
        zero_dofs(r.gradient, r.space.fixed);
        for (std::size_t i = 0; i < k; ++i) {
          (void)r.space.constraints[i].functional->value_and_vector(r.yn, r.G[i]);
          zero_dofs(r.G[i], r.space.fixed);
        }
        ++run.gradient_evaluations;
        LMEFORM_PETSC_CHECK(KSPSolve(r.euler_ksp, r.gradient, r.w));
        Eigen::MatrixXd S(static_cast<Eigen::Index>(k), static_cast<Eigen::Index>(k));
        Eigen::VectorXd rhs(static_cast<Eigen::Index>(k));
        for (std::size_t i = 0; i < k; ++i) LMEFORM_PETSC_CHECK(KSPSolve(r.euler_ksp, r.G[i], r.Z[i]));
        for (std::size_t i = 0; i < k; ++i) {
          rhs[Eigen::Index(i)] = dot(r.G[i], r.w);
          for (std::size_t j = 0; j < k; ++j) S(Eigen::Index(i), Eigen::Index(j)) = dot(r.G[i], r.Z[j]);
        }
        const Eigen::VectorXd sigma = k > 0 ? Eigen::VectorXd(S.fullPivLu().solve(rhs)) : Eigen::VectorXd();
        for (std::size_t i = 0; i < k; ++i) LMEFORM_PETSC_CHECK(VecAXPY(r.w, -sigma[Eigen::Index(i)], r.Z[i]));
        LMEFORM_PETSC_CHECK(VecWAXPY(r.trial, dt_step * real_time, r.w, r.yn));
        run.seconds_solve += MPI_Wtime() - t0;
        last = ConstrainedResult{};
        last.energy = energy_of(r.trial);
        last.converged = std::isfinite(last.energy);
        for (std::size_t i = 0; i < k; ++i) last.multipliers.push_back(-sigma[Eigen::Index(i)]);
        ok = last.converged;
        if (!ok) why = "the energy is not finite";
      }
      if (ok && settings.require_decrease && !(last.energy <= energy_before + 1e-10 * std::abs(energy_before))) {
        ok = false;
        why = fmt::format("the energy rose from {:.10g} to {:.10g}", energy_before, last.energy);
      }
      if (ok) {
        const DeformationMeasures m = deformation_measures(*r.space.disc, to_original(*r.space.disc, r.trial, bs), bs, offset, scene.axisymmetric());
        accepted_measures = m;
        if (!(m.min_jacobian > settings.min_jacobian)) {
          ok = false;
          folded = true;
          const auto x = r.space.disc->quadrature().point(std::size_t(m.point));
          why = fmt::format("det F = {:.3e} at quadrature point {} (reference position ({:.4g}, {:.4g}){})", m.min_jacobian, m.point,
                            x[0], dim > 1 ? x[1] : 0.0, run.resets > 0 ? fmt::format(", reference {}", run.resets) : "");
        }
      }
      if (ok) {
        accepted = true;
        for (std::size_t i = 0; i < k; ++i) nu[i] = last.multipliers[i] * r.space.constraints[i].scale;
        {
          const std::vector<double> y1 = to_original(*r.space.disc, r.trial, bs), y0 = to_original(*r.space.disc, r.yn, bs);
          for (std::size_t i = 0; i < velocity.size(); ++i) velocity[i] = (y1[i] - y0[i]) / (dt_step * real_time);
        }
        LMEFORM_PETSC_CHECK(VecCopy(r.trial, r.u));
        t += dt_step;
        ++step;
        ++steps_since_reset;
        ++steps_since_remesh;
        ++run.accepted;
        while (next_report < settings.report_times.size() && settings.report_times[next_report] <= t + t_tolerance) {
          run.energy_at[settings.report_times[next_report]] = last.energy;
          at_report_time = true;
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
      if (folded && resets && !reset_for_this_step) {
        // The map folds from this reference: reset it to the current state and try again.
        if (out != nullptr) *out << fmt::format("  step {} rejected at dt* {:.3e}: {}; resetting the reference\n", step + 1, dt_step, why);
        reset_reference();
        reset_for_this_step = true;
        continue;
      }
      if (out != nullptr) *out << fmt::format("  step {} rejected at dt* {:.3e}: {}; retrying with dt* {:.3e}\n", step + 1, dt_step, why, dt_step / 2);
      dt_try = dt_step / 2;
      if (rejected > settings.max_retries || dt_try < dt_min) break;
    }
    if (!accepted) {
      run.failure = fmt::format("step {} failed {} times down to dt* = {:.3e}: {}", step + 1, rejected, dt_attempted, why);
      apply_schedule(t);
      break;
    }
    record(ref->u, last.energy, euler ? 0 : last.newton_iterations, rejected, dt_try, accepted_measures);
    const bool finished = t >= settings.t_end - t_tolerance;
    // A report time gets its fields too: the shape at a scheduled event (the end of a deflation).
    if ((settings.output_every > 0 && step % settings.output_every == 0) || finished || at_report_time) write_series(ref->u);
    if (settings.checkpoint_every > 0 && step % settings.checkpoint_every == 0) write_checkpoint();
  }
  if (!run.failure.empty() && settings.checkpoint_every > 0) write_checkpoint();
  if (output != nullptr && rank == 0) write_text_atomically(history_path, history_json().dump(1) + "\n");
  run.final_state = to_original(*ref->space.disc, ref->u, bs);
  for (std::size_t i = 0; i < k; ++i) run.final_multipliers.push_back(nu[i] / ref->space.constraints[i].scale);
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
    if (run.resets > 0) {
      double worst = 0;
      for (const auto& c : run.reset_changes) {
        worst = std::max(worst, std::abs(c.energy));
        for (const double v : c.constraints) worst = std::max(worst, std::abs(v));
      }
      std::printf("%-26s %d (largest relative change of E, area, volume by a reset %.1e)\n", "resets", run.resets, worst);
    }
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
      js["resets"] = run.resets;
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
