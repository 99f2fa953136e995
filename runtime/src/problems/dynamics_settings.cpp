// The [dynamics] table: the method, the time interval and step control, resets and re-meshes,
// outputs, and the schedules of constants.
#include <algorithm>
#include <limits>

#include <fmt/format.h>

#include "dynamics.hpp"
#include "lmeform/scene_table.hpp"

namespace lmeform::problems {


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

/// The deformation maps the reference nodes to their current positions. A map that sends a
/// region to one point folds (det F = 0 there), and no step from it can be taken: the start must
/// be given, and not as a number; a Dirichlet number on every component sends a side to a point.
void check_motion(const Scene& s, const DynamicsSettings& d) {
  // Without model.energy the problem is every energy output of the forms, the dissipation's too
  // (a run without it stopped on "forms with coefficients can only be summed as the first term").
  if (s.model.energy.empty())
    throw SceneError(fmt::format("{}: missing key 'model.energy': [dynamics] moves the minimizer of the energies model.energy names; "
                                 "without it every energy output of the forms would be minimized, the dissipation '{}' among them",
                                 s.source, d.dissipation.name));
  for (const auto& e : s.model.energy)
    if (e.name == d.dissipation.name)
      throw SceneError(fmt::format("{} = '{}' is the dissipation ('dynamics.dissipation'): it weighs the motion of a step, it is not "
                                   "an energy the motion lowers; name the energies only",
                                   e.where, e.name));
  const auto start =
      std::find_if(s.initial.begin(), s.initial.end(), [&](const SceneInitialField& f) { return f.unknown == d.deformation; });
  if (start == s.initial.end())
    throw SceneError(fmt::format("{}: missing key 'initial.{}': [dynamics] moves the deformation '{}' from the positions [initial] gives "
                                 "(unset, every node would start at 0, a folded map); give {} = \"x\", the identity, or a previous "
                                 "run's {{file, field}}",
                                 s.source, d.deformation, d.deformation, d.deformation));
  if (start->kind == SceneInitialField::Kind::value && start->value.is_number())
    throw SceneError(fmt::format("{} = {} maps every node to one point (a folded map, det F = 0): the deformation '{}' starts from "
                                 "positions; give \"x\", the identity, or an expression of x",
                                 start->where, scene_detail::format_number(start->value.number()), d.deformation));
  for (const auto& b : s.dirichlet) {
    if (b.unknown != d.deformation || !b.value.is_number()) continue;
    // An axisymmetric motion keeps the axis on the axis: y_r = 0 at r = 0 (y_r is odd in r). On
    // r = -1 the first step failed 13 times and the run stopped.
    const bool radial = b.components.empty() || std::find(b.components.begin(), b.components.end(), 0) != b.components.end();
    if (s.axisymmetric() && s.domain.lo[0] == 0 && radial && b.value.number() != 0 &&
        std::find(b.boundary.begin(), b.boundary.end(), "axis") != b.boundary.end())
      throw SceneError(fmt::format("{} = {} moves the axis off itself: in an axisymmetric motion the radial component of the "
                                   "deformation '{}' is 0 on the axis r = 0; give value = 0 with components = [0]",
                                   b.value.where, scene_detail::format_number(b.value.number()), d.deformation));
    bool every = true;  // no components listed: every one
    for (int c = 0; c < s.dim() && !b.components.empty(); ++c)
      if (std::find(b.components.begin(), b.components.end(), c) == b.components.end()) every = false;
    if (!every) continue;
    std::string parts;
    for (const auto& p : b.boundary) parts += (parts.empty() ? "'" : ", '") + p + "'";
    throw SceneError(fmt::format("{} = {} gives every component of the deformation '{}' one number: the nodes of {} all go to one point "
                                 "(a folded map, det F = 0); give a number to some components only (components = [0]) or an "
                                 "expression of x (\"x\" holds the side in place)",
                                 b.value.where, scene_detail::format_number(b.value.number()), d.deformation, parts));
  }
}

std::optional<DynamicsSettings> read_dynamics(const Scene& s) {
  const auto t = extension_table(
      s, kDynamicsExtension,
      {"method", "deformation", "dissipation", "time_unit", "t_start", "t_end", "dt", "adaptive", "dt_max",
       "dt_min", "growth", "energy_decrement", "target_newton", "max_steps", "max_retries", "hessian", "min_jacobian",
       "output_every", "checkpoint_every", "report_times", "schedule", "reset_every", "reset_distortion", "require_decrease", "remesh_every", "remesh_factor",
       "remesh_iterations", "remesh_field", "remesh_fit_iterations", "remesh_projection", "remesh_gradient_length", "remesh_nodes",
       "topology_field", "topology_guard"});
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
  d.topology_field_given = t->has("topology_field");
  d.topology_field = d.topology_field_given ? t->string("topology_field") : d.remesh_field;
  d.topology_guard = t->boolean("topology_guard", d.topology_guard);
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
  check_motion(s, d);
  return d;
}

}  // namespace lmeform::problems
