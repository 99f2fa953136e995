#include "flow_steps.hpp"

#include <algorithm>
#include <cmath>
#include <fstream>
#include <limits>
#include <set>
#include <sstream>

#include <Eigen/Dense>
#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include "lmeform/convex_hull.hpp"
#include "lmeform/delaunay.hpp"
#include "lmeform/output.hpp"
#include "lmeform/scene_table.hpp"
#include "lmeform/stopwatch.hpp"
#include "quantities.hpp"
#include "stationary.hpp"
#include "step_history.hpp"
#include "toolkit.hpp"

namespace lmeform::problems {

namespace fs = std::filesystem;

FlowSettings read_flow(const Scene& scene) {
  const auto t = extension_table(scene, kFlowTable,
                                 {"velocity", "time_step", "count", "until", "checkpoint_every", "max_motion", "max_substeps",
                                  "contact_tolerance", "plates", "integrator", "continuation", "continuation_stages", "sliver_tolerance", "redistribute_anisotropy"});
  FlowSettings s;
  s.where = t->where("velocity");
  s.velocity = t->string("velocity");
  s.time_step = t->positive("time_step", t->number("time_step"));
  s.count = t->at_least("count", t->integer_of("count", t->require("count")), 1);
  if (s.count > 100000) t->fail_key("count", "= " + std::to_string(s.count) + " is more steps than a run can write (at most 100000)");
  s.checkpoint_every = t->at_least("checkpoint_every", t->integer("checkpoint_every", s.checkpoint_every), 0);
  s.until = t->at_least("until", t->integer("until", s.count), 0);
  if (s.until > s.count) t->fail_key("until", "= " + std::to_string(s.until) + " exceeds count = " + std::to_string(s.count));
  if (s.until < s.count && s.checkpoint_every == 0) t->fail_key("until", "stops before the last step: it needs checkpoints to continue from");
  s.max_motion = t->positive("max_motion", t->number("max_motion", s.max_motion));
  s.max_substeps = t->at_least("max_substeps", t->integer("max_substeps", s.max_substeps), 1);
  s.contact_tolerance = t->non_negative("contact_tolerance", t->number("contact_tolerance", s.contact_tolerance));
  if (const auto integrator = t->optional_string("integrator"))
    s.midpoint = t->choice_of("integrator", *integrator, {"midpoint", "euler"}) == "midpoint";
  if (const auto c = t->optional_any_table("continuation"))
    for (const auto& [name, node] : scene_detail::in_file_order(c->entries())) s.continuation.emplace_back(name, c->number_of(name, *node));
  s.sliver_tolerance = t->non_negative("sliver_tolerance", t->number("sliver_tolerance", s.sliver_tolerance));
  if (s.sliver_tolerance >= 0.25) t->fail_key("sliver_tolerance", "must be below 0.25 (an equilateral triangle has 0.43): it drops flat cells only");
  s.redistribute_anisotropy = t->non_negative("redistribute_anisotropy", t->number("redistribute_anisotropy", s.redistribute_anisotropy));
  if (s.redistribute_anisotropy > 0 && s.redistribute_anisotropy < 1.5)
    t->fail_key("redistribute_anisotropy", "must be 0 (never) or at least 1.5: a regular grid has about 1 (its boundary rows up to 1.4)");
  s.continuation_stages = t->at_least("continuation_stages", t->integer("continuation_stages", s.continuation_stages), 1);
  if (const toml::node* n = t->node("plates")) {
    const auto* a = n->as_array();
    if (a == nullptr) t->wrong_type("plates", *n, "an array of tables { part = \"top\", axis = 1, side = \"upper\" }");
    for (std::size_t i = 0; i < a->size(); ++i) {
      const std::string key = "plates[" + std::to_string(i) + "]";
      const SceneTable p = t->table_of(key, (*a)[i], {"part", "axis", "side"});
      FlowPlate plate;
      plate.where = p.where("part");
      plate.part = p.string("part");
      plate.axis = p.at_least("axis", p.integer_of("axis", p.require("axis")), 0);
      if (plate.axis >= scene.domain.dim) p.fail_key("axis", fmt::format("= {} is no axis of a {}D domain (0 .. {})", plate.axis, scene.domain.dim, scene.domain.dim - 1));
      plate.side = p.choice_of("side", p.string("side"), {"upper", "lower"}) == "upper" ? 1 : -1;
      s.plates.push_back(std::move(plate));
    }
  }
  return s;
}

namespace {

// At most 3 x 3 and on the stack: the spread and moment matrices of a node's neighbourhood.
using SmallMatrix = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, 0, 3, 3>;

const StepHistoryFormat kHistoryFormat{"time", {"iterations", "substeps"}};

/// A node within this fraction of the bounding-box diagonal of a hull face is on the surface: a
/// surface moved by a flow is never flat to round-off (measured: 1e-7 of a spacing per step on a
/// straight free surface), so nodes a little inside it still see their neighbours on one side.
constexpr double kSurfaceTolerance = 1e-3;

/// Node-distribution quality of a node set: how far the motion took it from a regular one.
struct NodeQuality {
  double spacing_ratio = 1;  ///< largest / smallest nodal spacing
  double anisotropy = 1;     ///< largest ratio of the principal spreads of an interior node's nearest neighbours
  /// LME conditioning: the largest condition number, over interior nodes, of the basis' Jacobian
  /// J = Σ_b p_b(x_a) (x_a − x_b)(x_a − x_b)ᵀ at the node (the covariance its Newton solve inverts;
  /// a regular grid has about 1, a node set squeezed flat diverges).
  double lme_condition = 1;
};

NodeQuality node_quality(const LmeBasis& basis) {
  NodeQuality q;
  const auto h = basis.spacing();
  if (h.empty()) return q;
  const auto [lo, hi] = std::minmax_element(h.begin(), h.end());
  q.spacing_ratio = *hi / std::max(*lo, std::numeric_limits<double>::min());
  const NodeSet& nodes = basis.nodes();
  const int d = nodes.dim;
  const std::size_t k = d == 2 ? 8 : 18;  // the first ring of a regular grid
  // A node on the hull sees its neighbours on one side only: a spread that says nothing of the motion.
  std::vector<char> on_hull(nodes.size(), 0);
  for (const int a : hull_boundary_nodes(nodes, kSurfaceTolerance)) on_hull[std::size_t(a)] = 1;
  for (std::size_t a = 0; a < nodes.size(); ++a) {
    if (on_hull[a] != 0) continue;
    const auto x = nodes.point(a);
    std::vector<std::pair<double, std::size_t>> near;
    for (const int b : basis.neighbours(x)) {
      if (std::size_t(b) == a || std::size_t(b) >= nodes.size()) continue;
      double r2 = 0;
      for (int i = 0; i < d; ++i) r2 += std::pow(nodes.point(std::size_t(b))[std::size_t(i)] - x[std::size_t(i)], 2);
      near.emplace_back(r2, std::size_t(b));
    }
    if (near.size() < std::size_t(d) + 1) continue;
    std::partial_sort(near.begin(), near.begin() + std::ptrdiff_t(std::min(k, near.size())), near.end());
    near.resize(std::min(k, near.size()));
    SmallMatrix spread = SmallMatrix::Zero(d, d);
    for (const auto& [r2, b] : near)
      for (int i = 0; i < d; ++i)
        for (int j = 0; j < d; ++j)
          spread(i, j) += (nodes.point(b)[std::size_t(i)] - x[std::size_t(i)]) * (nodes.point(b)[std::size_t(j)] - x[std::size_t(j)]);
    const auto ev = Eigen::SelfAdjointEigenSolver<SmallMatrix>(spread).eigenvalues();
    if (ev(0) > 0) q.anisotropy = std::max(q.anisotropy, std::sqrt(ev(d - 1) / ev(0)));
    try {
      const std::vector<int> list = basis.neighbours(x);
      const std::vector<double> p = basis.evaluate(x, list, 0);
      SmallMatrix J = SmallMatrix::Zero(d, d);
      for (std::size_t m = 0; m < list.size(); ++m) {
        if (std::size_t(list[m]) >= nodes.size()) continue;  // a mirror image (the flow's basis has none)
        const auto xb = nodes.point(std::size_t(list[m]));
        for (int i = 0; i < d; ++i)
          for (int j = 0; j < d; ++j) J(i, j) += p[m] * (x[std::size_t(i)] - xb[std::size_t(i)]) * (x[std::size_t(j)] - xb[std::size_t(j)]);
      }
      const auto jv = Eigen::SelfAdjointEigenSolver<SmallMatrix>(J).eigenvalues();
      q.lme_condition = std::max(q.lme_condition, jv(0) > 0 ? jv(d - 1) / jv(0) : std::numeric_limits<double>::infinity());
    } catch (const LmeEvaluationError&) {
      q.lme_condition = std::numeric_limits<double>::infinity();
    }
  }
  return q;
}

class FlowStepper {
 public:
  FlowStepper(const DriverContext& ctx, const FlowSettings& settings)
      : ctx_(ctx), settings_(settings), bound_(bind_scene(*ctx.scene, ctx.comm, ctx.log)) {
    MPI_Comm_rank(ctx.comm, &rank_);
    const auto it = std::find_if(bound_.layout.fields.begin(), bound_.layout.fields.end(), [&](const auto& f) { return f.name == settings.velocity; });
    if (it == bound_.layout.fields.end()) {
      std::vector<std::string> names;
      for (const auto& f : bound_.layout.fields) names.push_back(f.name);
      throw SceneError(fmt::format("{}: key 'flow.velocity': '{}' is no unknown of the model{}", settings.where, settings.velocity,
                                   did_you_mean(settings.velocity, names)));
    }
    if (it->components != bound_.dim)
      throw SceneError(fmt::format("{}: key 'flow.velocity': '{}' has {} component(s); the nodes move with a vector unknown of {}", settings.where,
                                   settings.velocity, it->components, bound_.dim));
    velocity_offset_ = it->offset;
    for (const auto& [name, value] : settings.continuation)
      if (!bound_.constants.contains(name)) {
        std::vector<std::string> names;
        for (const auto& [n, v] : bound_.constants) names.push_back(n);
        throw SceneError(fmt::format("{}: key 'flow.continuation': '{}' is no constant of the forms{}", settings.where, name, did_you_mean(name, names)));
      }
    for (const FlowPlate& p : settings.plates) {
      if (p.part != "hull" && !bound_.geometry.has_part(p.part))
        throw SceneError(fmt::format("{}: plate part '{}' is no boundary part of the domain{}", p.where, p.part,
                                     did_you_mean(p.part, bound_.geometry.part_names())));
      const bool held = std::any_of(bound_.dirichlet.begin(), bound_.dirichlet.end(), [&](const BoundDirichlet& d) {
        return d.field.name == settings.velocity && std::count(d.parts.begin(), d.parts.end(), p.part) > 0 &&
               std::count(d.components.begin(), d.components.end(), p.axis) > 0;
      });
      if (!held)
        throw SceneError(fmt::format("{}: plate '{}' moves with its prescribed velocity, but no [[dirichlet]] entry on '{}' prescribes "
                                     "{}[{}] (the component along the plate's axis)",
                                     p.where, p.part, p.part, settings.velocity, p.axis));
    }
  }

  [[nodiscard]] const BoundScene& bound() const noexcept { return bound_; }
  struct Run {
    std::vector<StepRow> history;  ///< position: the time; counts: iterations, substeps
    std::string failure;
    double wall_s = 0;
  };
  Run run();
  [[nodiscard]] ReportFields final_fields() const;

 private:
  void setup();
  void check_stroke();
  [[nodiscard]] bool solve_here(ProblemResult& result, std::string& failure);
  [[nodiscard]] std::vector<double> nodal_velocities() const;
  [[nodiscard]] double allowed_time(const std::vector<double>& velocity) const;
  void move(const std::vector<double>& velocity, double dt);
  void redistribute();
  [[nodiscard]] bool advance(int step);
  void record(int step, const ProblemResult& result, int substeps);
  void write_outputs(int step);
  void write_history() const;
  void resume();
  [[nodiscard]] fs::path path(const std::string& suffix) const { return ctx_.output_directory / (ctx_.scene->name + suffix); }
  [[nodiscard]] double plate_velocity(const FlowPlate& p) const;

  const DriverContext& ctx_;
  const FlowSettings& settings_;
  BoundScene bound_;
  int rank_ = 0;
  int velocity_offset_ = 0;
  Stopwatch clock_;
  ProblemInput input_;
  ProblemSpace space_;
  PetscVector u_;
  std::vector<double> state_;           ///< the converged state on input_.nodes (original order)
  std::vector<double> plate_position_;  ///< per plate
  double time_ = 0;
  int first_step_ = 0;
  long clamped_ = 0;                    ///< nodes put back onto a plate they crossed, in the whole run
  long continuations_ = 0;              ///< solves that needed the continuation, in the whole run
  long redistributions_ = 0;            ///< interior node sets replaced, in the whole run
  double initial_spacing_ = 0;          ///< median nodal spacing of the initial nodes
  double anisotropy_ = 1;               ///< of the last solved node set
  double rebuild_s_ = 0, assembly_s_ = 0, solve_s_ = 0;  ///< of the current step
  std::optional<TimeSeriesWriter> series_;
  Run run_;
};

void FlowStepper::setup() {
  input_.nodes = initial_nodes(*ctx_.scene, ctx_.comm, ctx_.log);
  input_.log = nullptr;  // a rebuild per step: its lines would drown the step lines
  input_.lme = bound_.lme(AxisParity::odd);  // a velocity is odd in r: no mirror across the axis
  input_.flat_cell_tolerance = settings_.sliver_tolerance;
  // Every part that a Dirichlet entry or a reaction names follows its nodes from now on.
  std::set<std::string> parts;
  for (const BoundDirichlet& d : bound_.dirichlet) parts.insert(d.parts.begin(), d.parts.end());
  for (const BoundQuantity& q : bound_.quantities)
    if (q.scene.kind == SceneQuantity::Kind::reaction) parts.insert(q.scene.part);
  for (const FlowPlate& p : settings_.plates) parts.insert(p.part);
  for (const std::string& part : parts) input_.part_nodes[part] = boundary_nodes(bound_.geometry, input_.nodes, part);
  for (const FlowPlate& p : settings_.plates) {
    const std::vector<int>& on = input_.part_nodes.at(p.part);
    if (on.empty()) throw SceneError(fmt::format("{}: no node lies on plate part '{}'", p.where, p.part));
    double x = 0;
    for (const int n : on) x += input_.nodes.point(std::size_t(n))[std::size_t(p.axis)];
    plate_position_.push_back(x / double(on.size()));
  }
  if (!ctx_.output_directory.empty()) series_.emplace(ctx_.output_directory, ctx_.scene->name);
}

double FlowStepper::plate_velocity(const FlowPlate& p) const {
  const int bs = bound_.layout.dofs_per_node;
  const int n = input_.part_nodes.at(p.part).front();
  return space_.state[std::size_t(n) * std::size_t(bs) + std::size_t(velocity_offset_ + p.axis)];
}

/// A plate that would run through the whole body before the last step: refused before a solve.
void FlowStepper::check_stroke() {
  for (std::size_t i = 0; i < settings_.plates.size(); ++i) {
    const FlowPlate& p = settings_.plates[i];
    const double v = plate_velocity(p);
    double far = plate_position_[i];
    for (std::size_t a = 0; a < input_.nodes.size(); ++a) {
      const double x = input_.nodes.point(a)[std::size_t(p.axis)];
      far = p.side > 0 ? std::min(far, x) : std::max(far, x);
    }
    const double gap = std::abs(plate_position_[i] - far);
    const double stroke = -p.side * v * settings_.time_step * (settings_.until - first_step_);
    if (stroke >= gap)
      throw SceneError(fmt::format("{}: plate '{}' moves at {} along axis {}: in {} steps of {} it travels {:.6g}, through the whole body "
                                   "({:.6g} thick along that axis from the plate): fewer steps, a smaller time_step or a slower plate",
                                   p.where, p.part, v, p.axis, settings_.until - first_step_, settings_.time_step, stroke, gap));
  }
}

/// Builds the problem on the current nodes and solves it from the carried state.
bool FlowStepper::solve_here(ProblemResult& result, std::string& failure) {
  Stopwatch rebuild;
  input_.initial = state_;
  try {
    space_ = build_problem_space(ctx_.comm, bound_, input_);
  } catch (const LmeEvaluationError& e) {
    failure = fmt::format("the LME basis cannot be evaluated on the moved nodes: {} (the node distribution degraded: a smaller "
                          "time_step or max_motion, a lower flow.redistribute_anisotropy, or more nodes)",
                          e.what());
    return false;
  } catch (const std::invalid_argument& e) {  // background cells of a degenerate node set
    failure = fmt::format("the moved nodes cannot be discretized: {}", e.what());
    return false;
  }
  rebuild_s_ += rebuild.seconds();
  u_ = space_.primary->create_vector();
  set_from_original(*space_.disc, space_.state, bound_.layout.dofs_per_node, u_);
  result = ProblemResult{};
  Stopwatch solve;
  bound_.solver->solve(ctx_.comm, bound_, space_, input_, u_, result);
  if (!result.converged && !settings_.continuation.empty()) {
    // From the easy problem to the scene's, each stage from the last solution.
    set_from_original(*space_.disc, space_.state, bound_.layout.dofs_per_node, u_);
    int iterations = 0;
    for (int stage = 0; stage <= settings_.continuation_stages; ++stage) {
      const double f = double(stage) / settings_.continuation_stages;
      for (const auto& [name, start] : settings_.continuation) space_.set_constant(name, start + f * (bound_.constants.at(name) - start));
      result = ProblemResult{};
      bound_.solver->solve(ctx_.comm, bound_, space_, input_, u_, result);
      iterations += result.iterations;
      if (!result.converged) {
        result.message = fmt::format("continuation stage {} of {}: {}", stage, settings_.continuation_stages, result.message);
        break;
      }
    }
    result.iterations = iterations;
    ++continuations_;
  }
  double assembled = 0;
  for (const auto& [label, a] : space_.assemblers) assembled += a->totals().vector + a->totals().matrix + a->totals().create_matrix;
  assembly_s_ += assembled;
  solve_s_ += std::max(0.0, solve.seconds() - assembled);
  if (!result.converged) {
    failure = "the flow solve did not converge: " + result.message;
    return false;
  }
  state_ = to_original(*space_.disc, u_, bound_.layout.dofs_per_node);
  return true;
}

/// The velocity field at each node (original order): the field's value v_h(x_a), not the
/// coefficient v_a. LME does not interpolate, and the coefficients carry modes that the basis
/// averages away inside: where a node moves with its coefficient, a free surface turns wavy within
/// tens of steps and Newton fails (measured in the upsetting runs). On the hull of the nodes the
/// basis tends to the Kronecker delta at a vertex (every node of a curved surface) and to the
/// face's lower-dimensional basis on a face, whose solve does not converge to round-off: there the
/// value is that coefficient again, or noisy. So a node on (or within 1e-3 of) the hull takes the
/// field's first-order Taylor expansion from a quarter of its spacing inside, toward the centroid
/// of its neighbours: v_h(x̃) + ∇v_h(x̃)·(x_a − x̃), exact for linear fields like the value. A
/// prescribed component (a plate, an axis, a symmetry plane) is its prescribed value, so that those
/// nodes stay on their line exactly.
std::vector<double> FlowStepper::nodal_velocities() const {
  const Discretization& disc = *space_.disc;
  const LmeBasis& basis = disc.basis();
  const auto bs = std::size_t(bound_.layout.dofs_per_node);
  const auto d = std::size_t(bound_.dim);
  const NodeSet& nodes = input_.nodes;
  std::vector<double> v(nodes.size() * d, 0.0);
  const auto original = disc.original_index();
  const auto renumbered = disc.renumbered_index();
  std::vector<char> near_hull(nodes.size(), 0);
  for (const int a : hull_boundary_nodes(nodes, kSurfaceTolerance)) near_hull[std::size_t(a)] = 1;
  std::vector<double> xe(d);
  for (std::size_t a = 0; a < nodes.size(); ++a) {
    const auto x = nodes.point(a);
    for (std::size_t c = 0; c < d; ++c) v[a * d + c] = state_[a * bs + std::size_t(velocity_offset_) + c];
    std::copy(x.begin(), x.end(), xe.begin());
    if (near_hull[a] != 0) {
      std::vector<double> centroid(d, 0.0);
      const std::vector<int> around = basis.neighbours(x);
      for (const int b : around)
        for (std::size_t c = 0; c < d; ++c) centroid[c] += basis.nodes().point(std::size_t(b))[c] / double(around.size());
      double length = 0;
      for (std::size_t c = 0; c < d; ++c) length += (centroid[c] - x[c]) * (centroid[c] - x[c]);
      length = std::sqrt(length);
      const double step = 0.25 * basis.spacing()[std::size_t(renumbered[a])];
      if (length > 0)
        for (std::size_t c = 0; c < d; ++c) xe[c] = x[c] + step * (centroid[c] - x[c]) / length;
    }
    try {
      const std::vector<int> list = basis.neighbours(xe);
      const std::vector<double> jet = basis.evaluate(xe, list, 1);
      const std::size_t n = list.size();
      for (std::size_t c = 0; c < d; ++c) {
        double value = 0;
        for (std::size_t m = 0; m < n; ++m) {
          const double coefficient = state_[std::size_t(original[std::size_t(list[m])]) * bs + std::size_t(velocity_offset_) + c];
          double slope = 0;
          for (std::size_t i = 0; i < d; ++i) slope += jet[(1 + i) * n + m] * (x[i] - xe[i]);
          value += (jet[m] + slope) * coefficient;
        }
        v[a * d + c] = value;
      }
    } catch (const LmeEvaluationError&) {
      // a point the basis cannot evaluate (a degraded neighbourhood): the coefficient
    }
  }
  for (const auto& [node, dof] : space_.fixed_pairs)
    if (dof >= velocity_offset_ && dof < velocity_offset_ + bound_.dim)
      v[std::size_t(node) * d + std::size_t(dof - velocity_offset_)] = state_[std::size_t(node) * bs + std::size_t(dof)];
  return v;
}

/// The longest time over which no node moves more than max_motion of its spacing.
double FlowStepper::allowed_time(const std::vector<double>& velocity) const {
  const auto spacing = space_.disc->basis().spacing();  // renumbered
  const auto renumbered = space_.disc->renumbered_index();
  const auto d = std::size_t(bound_.dim);
  double t = std::numeric_limits<double>::infinity();
  for (std::size_t a = 0; a < input_.nodes.size(); ++a) {
    double s = 0;
    for (std::size_t c = 0; c < d; ++c) s += velocity[a * d + c] * velocity[a * d + c];
    if (s > 0) t = std::min(t, settings_.max_motion * spacing[std::size_t(renumbered[a])] / std::sqrt(s));
  }
  return t;
}

/// x_a += dt v_a; plates advance, capture the nodes that reach them and put back those that cross.
void FlowStepper::move(const std::vector<double>& velocity, double dt) {
  const auto d = std::size_t(bound_.dim);
  const auto spacing = space_.disc->basis().spacing();
  const auto renumbered = space_.disc->renumbered_index();
  std::vector<double> h(input_.nodes.size());
  for (std::size_t a = 0; a < h.size(); ++a) h[a] = spacing[std::size_t(renumbered[a])];
  std::vector<double>& x = input_.nodes.coords;
  for (std::size_t i = 0; i < x.size(); ++i) x[i] += dt * velocity[i];
  for (std::size_t i = 0; i < settings_.plates.size(); ++i) {
    const FlowPlate& p = settings_.plates[i];
    plate_position_[i] += dt * plate_velocity(p);
    std::vector<int>& on = input_.part_nodes.at(p.part);
    std::set<int> held(on.begin(), on.end());
    for (std::size_t a = 0; a < input_.nodes.size(); ++a) {
      double& xa = x[a * d + std::size_t(p.axis)];
      const double beyond = p.side * (xa - plate_position_[i]);  // > 0: through the plate
      if (held.contains(int(a))) {
        xa = plate_position_[i];
      } else if (beyond > -settings_.contact_tolerance * h[a]) {
        if (beyond > settings_.contact_tolerance * h[a]) ++clamped_;
        xa = plate_position_[i];
        held.insert(int(a));
      }
    }
    on.assign(held.begin(), held.end());
  }
  // The Dirichlet entries on a plate's part hold the nodes it captured.
  time_ += dt;
}

/// New interior nodes: the surface (hull) nodes stay with their parts; inside, a regular grid of
/// the initial spacing, at least half a spacing from the hull; the state is the old field there.
void FlowStepper::redistribute() {
  const NodeSet& old = input_.nodes;
  const auto d = std::size_t(old.dim);
  const double h = initial_spacing_;
  const ConvexHull hull = convex_hull(old);
  const std::vector<int> surface = hull_boundary_nodes(old, hull, kSurfaceTolerance);
  std::vector<double> coords;
  std::vector<int> new_index(old.size(), -1);
  for (const int a : surface) {
    new_index[std::size_t(a)] = int(coords.size() / d);
    const auto x = old.point(std::size_t(a));
    coords.insert(coords.end(), x.begin(), x.end());
  }
  const std::size_t kept = coords.size() / d;
  std::vector<double> lo(d, std::numeric_limits<double>::infinity()), hi(d, -std::numeric_limits<double>::infinity());
  for (std::size_t a = 0; a < old.size(); ++a)
    for (std::size_t c = 0; c < d; ++c) lo[c] = std::min(lo[c], old.point(a)[c]), hi[c] = std::max(hi[c], old.point(a)[c]);
  std::vector<int> counts(d);
  std::size_t total = 1;
  for (std::size_t c = 0; c < d; ++c) counts[c] = std::max(1, int(std::floor((hi[c] - lo[c]) / h)) + 1), total *= std::size_t(counts[c]);
  std::vector<double> x(d);
  for (std::size_t i = 0; i < total; ++i) {
    std::size_t rest = i;
    for (std::size_t c = 0; c < d; ++c) {
      const double width = (counts[c] - 1) * h;
      x[c] = 0.5 * (lo[c] + hi[c] - width) + double(rest % std::size_t(counts[c])) * h;  // centred in the box
      rest /= std::size_t(counts[c]);
    }
    bool inside = true;
    for (std::size_t f = 0; f < hull.offsets.size() && inside; ++f) {
      double s = hull.offsets[f];
      for (std::size_t c = 0; c < d; ++c) s += hull.normals[f * d + c] * x[c];
      inside = s < -0.5 * h;
    }
    if (inside) coords.insert(coords.end(), x.begin(), x.end());
  }
  NodeSet nodes(old.dim, std::move(coords));
  // The old field at the new interior nodes (a start for the next solve); surface nodes keep theirs.
  const auto bs = std::size_t(bound_.layout.dofs_per_node);
  std::vector<double> state(nodes.size() * bs, 0.0);
  for (std::size_t a = 0; a < old.size(); ++a)
    if (new_index[a] >= 0) std::copy_n(state_.begin() + std::ptrdiff_t(a * bs), bs, state.begin() + std::ptrdiff_t(std::size_t(new_index[a]) * bs));
  const Discretization& disc = *space_.disc;
  const auto original = disc.original_index();
  for (std::size_t a = kept; a < nodes.size(); ++a) {
    const auto xa = nodes.point(a);
    const std::vector<int> list = disc.basis().neighbours(xa);
    const std::vector<double> p = disc.basis().evaluate(xa, list, 0);
    for (std::size_t m = 0; m < list.size(); ++m)
      for (std::size_t k = 0; k < bs; ++k) state[a * bs + k] += p[m] * state_[std::size_t(original[std::size_t(list[m])]) * bs + k];
  }
  for (auto& [part, on] : input_.part_nodes) {
    std::vector<int> renumbered;
    for (const int n : on)
      if (new_index[std::size_t(n)] >= 0) renumbered.push_back(new_index[std::size_t(n)]);
    on = std::move(renumbered);
  }
  if (ctx_.log != nullptr)
    *ctx_.log << fmt::format("  redistributed the nodes (anisotropy {:.3g} > {:.3g}): {} surface nodes kept, {} interior nodes on a grid of "
                             "spacing {:.4g} (were {})\n",
                             anisotropy_, settings_.redistribute_anisotropy, kept, nodes.size() - kept, h, old.size() - kept);
  input_.nodes = std::move(nodes);
  state_ = std::move(state);
  ++redistributions_;
}

bool FlowStepper::advance(int step) {
  rebuild_s_ = assembly_s_ = solve_s_ = 0;
  ProblemResult result;
  std::string failure;
  int substeps = 0;
  if (step == 0) {
    if (!solve_here(result, failure)) {
      run_.failure = "the start (step 0): " + failure;
      return false;
    }
    check_stroke();
    const auto h = space_.disc->basis().spacing();
    std::vector<double> sorted(h.begin(), h.end());
    std::nth_element(sorted.begin(), sorted.begin() + std::ptrdiff_t(sorted.size() / 2), sorted.end());
    initial_spacing_ = sorted[sorted.size() / 2];
  } else {
    if (settings_.redistribute_anisotropy > 0 && anisotropy_ > settings_.redistribute_anisotropy) {
      redistribute();
      if (!solve_here(result, failure)) {
        run_.failure = fmt::format("step {}: the solve on the redistributed nodes: {}", step, failure);
        return false;
      }
    }
    // The step is applied only whole: on failure the nodes, parts and state go back.
    const NodeSet nodes = input_.nodes;
    const auto parts = input_.part_nodes;
    const std::vector<double> state = state_, plates = plate_position_;
    const double time = time_;
    const long clamped = clamped_;
    const double target = step * settings_.time_step;
    std::vector<double> velocity = nodal_velocities();
    while (time_ < target - 1e-12 * settings_.time_step) {
      if (++substeps > settings_.max_substeps) {
        failure = fmt::format("more than {} sub-steps (max_substeps): the nodes move more than max_motion = {} of their spacing in "
                              "{:.3g} of a step",
                              settings_.max_substeps, settings_.max_motion, 1.0 / settings_.max_substeps);
        break;
      }
      const double dt = std::min(target - time_, allowed_time(velocity));
      if (settings_.midpoint) {
        const NodeSet from = input_.nodes;
        const auto from_parts = input_.part_nodes;
        const std::vector<double> from_plates = plate_position_;
        const double from_time = time_;
        const long from_clamped = clamped_;
        move(velocity, dt / 2);
        if (!solve_here(result, failure)) break;
        const std::vector<double> midpoint_velocity = nodal_velocities();
        input_.nodes = from;
        input_.part_nodes = from_parts;
        plate_position_ = from_plates;
        time_ = from_time;
        clamped_ = from_clamped;
        move(midpoint_velocity, dt);
      } else {
        move(velocity, dt);
      }
      if (!solve_here(result, failure)) break;
      velocity = nodal_velocities();
      failure.clear();
    }
    if (!failure.empty()) {
      run_.failure = fmt::format("step {} (time {:.6g}): {}; the step is not applied, step {} is the last on disk", step, target, failure, step - 1);
      input_.nodes = nodes;
      input_.part_nodes = parts;
      state_ = state;
      plate_position_ = plates;
      time_ = time;
      clamped_ = clamped;
      return false;
    }
  }
  record(step, result, substeps);
  return true;
}

void FlowStepper::record(int step, const ProblemResult& result, int substeps) {
  StepRow s;
  s.step = step;
  s.position = time_;
  s.quantities = evaluate_quantities(bound_, space_, u_, result);
  const NodeSet& nodes = input_.nodes;
  for (int i = 0; i < nodes.dim; ++i) {
    double lo = std::numeric_limits<double>::infinity(), hi = -lo;
    for (std::size_t a = 0; a < nodes.size(); ++a) lo = std::min(lo, nodes.point(a)[std::size_t(i)]), hi = std::max(hi, nodes.point(a)[std::size_t(i)]);
    s.quantities.emplace_back(fmt::format("extent_min[{}]", i), lo);
    s.quantities.emplace_back(fmt::format("extent_max[{}]", i), hi);
  }
  for (std::size_t i = 0; i < settings_.plates.size(); ++i) {
    s.quantities.emplace_back(fmt::format("plate_{}", settings_.plates[i].part), plate_position_[i]);
    s.quantities.emplace_back(fmt::format("contact_nodes_{}", settings_.plates[i].part), double(input_.part_nodes.at(settings_.plates[i].part).size()));
  }
  const NodeQuality q = node_quality(space_.disc->basis());
  anisotropy_ = q.anisotropy;
  s.quantities.emplace_back("spacing_ratio", q.spacing_ratio);
  s.quantities.emplace_back("anisotropy", q.anisotropy);
  s.quantities.emplace_back("lme_condition", q.lme_condition);
  s.quantities.emplace_back("clamped_nodes", double(clamped_));
  if (!settings_.continuation.empty()) s.quantities.emplace_back("continuations", double(continuations_));
  s.quantities.emplace_back("redistributions", double(redistributions_));
  s.quantities.emplace_back("nodes", double(input_.nodes.size()));
  s.quantities.emplace_back("rebuild_s", rebuild_s_);
  s.quantities.emplace_back("assembly_s", assembly_s_);
  s.quantities.emplace_back("solve_s", solve_s_);
  s.counts = {{"iterations", result.iterations}, {"substeps", substeps}};
  s.wall_s = clock_.seconds();
  run_.history.push_back(s);
  if (ctx_.log == nullptr) return;
  std::string values;
  for (const auto& [name, v] : s.quantities)
    if (name.find("extent_min") == std::string::npos) values += fmt::format("  {} {:.6g}", name, v);
  *ctx_.log << fmt::format("step {:4d}/{}  time {:.6g}{}  newton {}  substeps {}  {:.1f} s", step, settings_.count, s.position, values,
                           result.iterations, substeps, s.wall_s)
            << std::endl;
}

void FlowStepper::write_history() const {
  write_step_history(ctx_.output_directory, ctx_.scene->name, kHistoryFormat, run_.history);
}

void FlowStepper::write_outputs(int step) {
  if (ctx_.output_directory.empty()) return;
  // Every rank holds the gathered state and writes its block of rows (collective HDF5).
  const BackgroundCells cells = delaunay(input_.nodes);
  std::vector<std::vector<double>> values;
  values.reserve(bound_.layout.fields.size() + input_.part_nodes.size());  // the views below point into it
  FieldViews fields;
  for (const auto& f : bound_.layout.fields) {
    values.push_back(bound_.layout.values(state_, f));
    fields.emplace(f.name, FieldView{values.back(), f.components});
  }
  const OutputAttributes attributes{{"step", static_cast<std::int64_t>(step)}, {"time", time_}};
  const ReplicatedShare share(ctx_.comm, input_.nodes.size(), fields);
  series_->write(ctx_.comm, time_, step, input_.nodes, cells, share.part(), attributes);
  if (rank_ == 0) write_history();
  if (settings_.checkpoint_every == 0 || (step % settings_.checkpoint_every != 0 && step != settings_.until)) return;
  // The checkpoint: the moved nodes, the state, each followed part as a 0/1 field, the plates.
  FieldViews checkpoint{{"state", FieldView{state_, bound_.layout.dofs_per_node}}};
  for (const auto& [part, on] : input_.part_nodes) {
    std::vector<double>& flag = values.emplace_back(input_.nodes.size(), 0.0);
    for (const int n : on) flag[std::size_t(n)] = 1;
    checkpoint.emplace("part_" + part, FieldView{flag, 1});
  }
  OutputAttributes cp = attributes;
  for (std::size_t i = 0; i < settings_.plates.size(); ++i) cp.emplace("plate_" + settings_.plates[i].part, plate_position_[i]);
  cp.emplace("clamped", static_cast<std::int64_t>(clamped_));
  cp.emplace("redistributions", static_cast<std::int64_t>(redistributions_));
  cp.emplace("initial_spacing", initial_spacing_);
  cp.emplace("anisotropy", anisotropy_);
  const ReplicatedShare checkpoint_share(ctx_.comm, input_.nodes.size(), checkpoint);
  write_field_hdf5(ctx_.comm, path("_checkpoint.h5"), input_.nodes, cells, checkpoint_share.part(), cp);
}

void FlowStepper::resume() {
  const fs::path checkpoint = path("_checkpoint.h5"), history = ctx_.output_directory / "history.json";
  if (!fs::exists(checkpoint) || !fs::exists(history))
    throw std::runtime_error(fmt::format("--restart: no checkpoint in {} (expected {} and history.json)", ctx_.output_directory.string(),
                                         checkpoint.filename().string()));
  const FieldFile cp = read_field_hdf5(checkpoint, ctx_.comm);
  if (cp.nodes.dim != input_.nodes.dim)
    throw std::runtime_error(fmt::format("--restart: {} holds {}D nodes, the scene is {}D", checkpoint.string(), cp.nodes.dim, input_.nodes.dim));
  const int step = static_cast<int>(std::get<std::int64_t>(cp.attributes.at("step")));
  input_.nodes = cp.nodes;
  state_ = cp.fields.at("state").values;
  for (auto& [part, on] : input_.part_nodes) {
    const auto it = cp.fields.find("part_" + part);
    if (it == cp.fields.end()) throw std::runtime_error(fmt::format("--restart: {} has no nodes of part '{}'", checkpoint.string(), part));
    on.clear();
    for (std::size_t a = 0; a < it->second.values.size(); ++a)
      if (it->second.values[a] > 0.5) on.push_back(int(a));
  }
  for (std::size_t i = 0; i < settings_.plates.size(); ++i) plate_position_[i] = std::get<double>(cp.attributes.at("plate_" + settings_.plates[i].part));
  clamped_ = std::get<std::int64_t>(cp.attributes.at("clamped"));
  redistributions_ = std::get<std::int64_t>(cp.attributes.at("redistributions"));
  initial_spacing_ = std::get<double>(cp.attributes.at("initial_spacing"));
  anisotropy_ = std::get<double>(cp.attributes.at("anisotropy"));
  time_ = std::get<double>(cp.attributes.at("time"));
  run_.history = read_step_history(ctx_.output_directory, kHistoryFormat, step);
  series_->restore(restored_series(ctx_.comm, *series_, ctx_.output_directory, run_.history, bound_.layout, bound_.dim));
  first_step_ = step + 1;
  if (ctx_.log != nullptr) *ctx_.log << fmt::format("resumed from {} at step {} (time {:.6g})\n", checkpoint.string(), step, time_);
}

FlowStepper::Run FlowStepper::run() {
  setup();
  const ScopedPetscOptions petsc_options(ctx_.scene->solver.petsc_options);
  if (ctx_.restart) {
    resume();
    rebuild_s_ = assembly_s_ = solve_s_ = 0;
    ProblemResult result;
    std::string failure;
    // The checkpoint's state solved the flow on its nodes: the re-solve converges at once, and
    // rebuilds the space the next step moves from.
    if (!solve_here(result, failure)) {
      run_.failure = fmt::format("--restart at step {}: {}", first_step_ - 1, failure);
      run_.wall_s = clock_.seconds();
      return std::move(run_);
    }
    check_stroke();
  }
  for (int step = first_step_; step <= settings_.until; ++step) {
    if (!advance(step)) break;
    write_outputs(step);
  }
  run_.wall_s = clock_.seconds();
  return std::move(run_);
}

ReportFields FlowStepper::final_fields() const {
  ProblemResult r;
  r.nodes = input_.nodes;
  r.cells = delaunay(input_.nodes);
  r.state = state_;
  ReportFields f = state_fields(bound_.layout, bound_.axisymmetric, r);
  f.attributes.emplace("time", time_);
  return f;
}

class FlowStepsDriver final : public ProblemDriver {
 public:
  [[nodiscard]] std::string_view name() const override { return "flow steps"; }
  [[nodiscard]] std::string_view table() const override { return kFlowTable; }
  [[nodiscard]] bool claims(const Scene& scene) const override { return scene.has_extension(kFlowTable); }
  [[nodiscard]] bool restartable() const override { return true; }
  void check(const DriverContext& ctx) const override {
    const FlowSettings settings = read_flow(*ctx.scene);
    const FlowStepper stepper(ctx, settings);
  }
  [[nodiscard]] RunReport run(const DriverContext& ctx) const override {
    const FlowSettings settings = read_flow(*ctx.scene);
    FlowStepper stepper(ctx, settings);
    const FlowStepper::Run run = stepper.run();
    RunReport report;
    report.problem = fmt::format("{} ({} on moving nodes)", name(), stepper.bound().solver->name());
    report.success = run.failure.empty();
    report.status = !run.failure.empty()              ? "STOPPED: " + run.failure
                    : settings.until < settings.count ? fmt::format("stopped after step {} as asked (flow.until): --restart continues", settings.until)
                                                      : std::string("every step converged");
    if (run.history.empty()) throw std::runtime_error(report.status);
    const StepRow& last = run.history.back();
    int substeps = 0, newton = 0;
    double rebuild = 0, assembly = 0, solve = 0;
    for (const StepRow& s : run.history) {
      substeps += int(s.count("substeps")), newton += int(s.count("iterations"));
      for (const auto& [name, v] : s.quantities) {
        if (name == "rebuild_s") rebuild += v;
        if (name == "assembly_s") assembly += v;
        if (name == "solve_s") solve += v;
      }
    }
    report.row("steps", fmt::format("{} of {} (time {:.6g}), {} solves, {} Newton iterations", last.step, settings.count, last.position,
                                    substeps + 1, newton));
    report.row("time per step", fmt::format("rebuild {:.3f} s, assembly {:.3f} s, solve {:.3f} s (means)", rebuild / double(run.history.size()),
                                            assembly / double(run.history.size()), solve / double(run.history.size())));
    describe_quantities(last.quantities, report);
    report.fields = stepper.final_fields();
    report_step_history(kHistoryFormat, run.history, ctx.output_directory, ctx.scene->name, report);
    return report;
  }
};

}  // namespace

const ProblemDriver& flow_steps_driver() {
  static const FlowStepsDriver driver;
  return driver;
}

}  // namespace lmeform::problems
