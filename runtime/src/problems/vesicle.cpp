#include "vesicle.hpp"

#include <algorithm>
#include <cmath>
#include <memory>
#include <numbers>
#include <set>
#include <stdexcept>

#include <fmt/format.h>

#include "lmeform/cvt.hpp"
#include "lmeform/delaunay.hpp"
#include "lmeform/neighbour_search.hpp"
#include "lmeform/node_sets.hpp"
#include "lmeform/resource_usage.hpp"
#include "lmeform/scene_table.hpp"
#include "lmeform/stopwatch.hpp"
#include "field_transfer.hpp"
#include "membrane_topology.hpp"
#include "vesicle_checkpoint.hpp"

namespace lmeform::problems {

namespace {

using scene_detail::format_number;

void read_initial_shape(const Scene& s, const SceneTable& t, VesicleModel& m) {
  const std::string shape = t.choice_of("shape", t.string("shape"), {"ellipsoid", "sphere", "oblate", "prolate", "stomatocyte"});
  const std::vector<double> c = t.numbers("center", s.dim());
  for (std::size_t i = 0; i < c.size(); ++i) m.center[i] = c[i];
  if (shape == "oblate" || shape == "prolate") {
    // The spheroid of the model's own area and volume: a start on the branch with no residual in
    // the constraints of the sharp shape.
    m.shape = VesicleModel::Shape::ellipsoid;
    for (const char* key : {"semi_axes", "radius"})
      if (t.has(key))
        t.fail_key(key, fmt::format("does not apply to shape '{}': its semi-axes follow from vesicle.radius and "
                                    "vesicle.reduced_volume",
                                    shape));
    if (!m.area || !m.reduced_volume)
      t.fail_key("shape", fmt::format("= '{}' needs the area and volume it encloses: give vesicle.radius and vesicle.reduced_volume",
                                      shape));
    const int measure_dim = s.axisymmetric() ? 3 : s.dim();
    const auto [equatorial, polar] = spheroid_semi_axes(*m.area, *m.reduced_volume, measure_dim, shape == "oblate");
    for (int i = 0; i < s.dim(); ++i) m.semi_axes[std::size_t(i)] = i == s.dim() - 1 ? polar : equatorial;
  } else if (shape == "ellipsoid") {
    m.shape = VesicleModel::Shape::ellipsoid;
    if (t.has("radius")) t.fail_key("radius", "belongs to shape 'sphere'; an ellipsoid takes 'semi_axes'");
    const std::vector<double> a = t.numbers("semi_axes", s.dim());
    for (std::size_t i = 0; i < a.size(); ++i) m.semi_axes[i] = t.positive("semi_axes", a[i]);
  } else if (shape == "stomatocyte") {
    m.shape = VesicleModel::Shape::stomatocyte;
    if (t.has("semi_axes")) t.fail_key("semi_axes", "belongs to shape 'ellipsoid'; a stomatocyte takes 'radius', 'thickness' and 'aperture'");
    m.cup_radius = t.positive("radius", t.number("radius"));
    m.cup_thickness = t.positive("thickness", t.number("thickness"));
    if (m.cup_thickness >= m.cup_radius)
      t.fail_key("thickness", fmt::format("= {} must be below the radius {}: the cup would have no cavity", m.cup_thickness, m.cup_radius));
    const double aperture_degrees = t.number("aperture");
    if (!(aperture_degrees > 0 && aperture_degrees < 180))
      t.fail_key("aperture", "must lie in (0, 180) degrees, got " + format_number(aperture_degrees));
    m.cup_aperture = aperture_degrees * std::numbers::pi / 180;
    for (int i = 0; i < s.dim(); ++i) m.semi_axes[std::size_t(i)] = m.cup_radius + m.cup_thickness / 2;
  } else {
    m.shape = VesicleModel::Shape::sphere;
    if (t.has("semi_axes")) t.fail_key("semi_axes", "belongs to shape 'ellipsoid'; a sphere takes 'radius'");
    const double r = t.positive("radius", t.number("radius"));
    for (int i = 0; i < s.dim(); ++i) m.semi_axes[std::size_t(i)] = r;
  }
  if (m.shape != VesicleModel::Shape::stomatocyte)
    for (const char* key : {"thickness", "aperture"})
      if (t.has(key)) t.fail_key(key, "belongs to shape 'stomatocyte'");
  if (t.has("eps")) m.profile_eps = t.positive("eps", t.number("eps"));
  if (s.axisymmetric() && m.center[0] != 0.0)
    t.fail_key("center", "must lie on the axis (r = 0) in an axisymmetric scene, got r = " + format_number(m.center[0]));
  for (int i = 0; i < s.dim(); ++i) {
    const auto k = std::size_t(i);
    // The shape must be symmetric about a plane of symmetry: centred on it, and it crosses it.
    const auto plane = std::find_if(s.mirrors.begin(), s.mirrors.end(), [&](const MirrorPlane& q) { return q.axis == i; });
    if (plane != s.mirrors.end() && m.center[k] != plane->position)
      t.fail_key("center", fmt::format("must lie on the plane of symmetry x[{}] = {} ([domain] mirror), got {}", i, plane->position, m.center[k]));
    const bool open_below = (s.axisymmetric() && i == 0) || (plane != s.mirrors.end() && plane->position == s.domain.lo[k]);
    const bool open_above = plane != s.mirrors.end() && plane->position == s.domain.hi[k];
    const std::string key = m.shape == VesicleModel::Shape::ellipsoid ? "semi_axes" : "radius";
    const double lo = m.center[k] - m.semi_axes[k], hi = m.center[k] + m.semi_axes[k];
    if (!open_above && hi > s.domain.hi[k])
      t.fail_key(key, fmt::format("puts the initial shape outside the domain: it reaches {} on axis {} > upper bound {}", hi, i,
                                  s.domain.hi[k]));
    if (!open_below && lo < s.domain.lo[k])
      t.fail_key(key, fmt::format("puts the initial shape outside the domain: it reaches {} on axis {} < lower bound {}", lo, i,
                                  s.domain.lo[k]));
  }
}

void read_adaptivity(const SceneTable& t, VesicleModel& m) {
  const int lloyd = t.at_least("lloyd_iterations", t.integer("lloyd_iterations", 20), 1);
  VesicleAdaptivity a;
  a.start_from_density = t.choice_of("start", t.optional_string("start").value_or("nodes"), {"nodes", "density"}) == "density";
  a.samples_per_node = t.positive("samples_per_node", t.number("samples_per_node", a.samples_per_node));
  if (a.samples_per_node < 1) t.fail_key("samples_per_node", "must be at least 1, got " + format_number(a.samples_per_node));
  a.fit_iterations = t.at_least("fit_iterations", t.integer("fit_iterations", a.fit_iterations), 0);
  InterfaceResolution& r = a.interface;
  r.band = t.non_negative("band", t.number("band", r.band));
  r.grading = t.positive("grading", t.number("grading", r.grading));
  r.coarsening = t.positive("coarsening", t.number("coarsening", r.coarsening));
  if (r.coarsening < 1) t.fail_key("coarsening", "must be at least 1 (the far spacing over the interface spacing), got " + format_number(r.coarsening));
  r.max_nodes = static_cast<std::size_t>(t.at_least("max_nodes", t.integer("max_nodes", static_cast<int>(r.max_nodes)), 4));
  // Without stages the table only shapes the first grid of initial.resolve.
  if (!t.has("stages") && m.initial_resolve) {
    m.adaptivity = std::move(a);
    return;
  }
  const toml::node& n = t.require("stages");
  const auto* arr = n.as_array();
  if (arr == nullptr) t.wrong_type("stages", n, "an array of tables");
  if (arr->empty()) t.fail_key("stages", "must list at least one stage (or leave out [vesicle.adaptivity])");
  double previous = m.eps, main_eps = m.eps;
  for (std::size_t i = 0; i < arr->size(); ++i) {
    const std::string key = "stages[" + std::to_string(i) + "]";
    const SceneTable st = t.table_of(key, (*arr)[i], {"eps", "f", "lloyd_iterations", "branch", "resolve"});
    AdaptivityStage stage;
    stage.eps = st.positive("eps", st.number("eps"));
    stage.lloyd_iterations = st.at_least("lloyd_iterations", st.integer("lloyd_iterations", lloyd), 0);
    if (st.has("resolve")) {
      if (st.has("f")) st.fail_key("f", "does not apply to a stage with 'resolve': its grid follows the interface, not 1 + f |grad phi|");
      stage.resolve = st.positive("resolve", st.number("resolve"));
      // Without Lloyd iterations the grid is the raw density placement: its irregular spacing
      // spoils the LME basis (measured: a stomatocyte stage at eps = 0.00625 converged to E = 43
      // with phi reaching 2.2 on it; after 20 iterations it runs at E = 12.5-12.6).
      if (stage.lloyd_iterations == 0)
        st.fail_key("lloyd_iterations", "must be at least 1 with 'resolve': the grid without Lloyd iterations is the raw density "
                                        "placement, too irregular for the LME basis");
      if (*stage.resolve > stage.eps)
        st.fail_key("resolve", fmt::format("= {} exceeds the stage's eps ({}): the grid must resolve the stage itself", *stage.resolve,
                                           stage.eps));
    } else {
      stage.f = stage.lloyd_iterations == 0 && !st.has("f") ? 0.0 : st.non_negative("f", st.number("f"));
    }
    stage.branch = st.boolean("branch", false);
    // Each stage lowers eps from the stage it continues from.
    const bool after_branch = !a.stages.empty() && a.stages.back().branch;
    const double from = after_branch && !stage.branch ? main_eps : previous;
    if (stage.eps > from)
      st.fail_key("eps", fmt::format("= {} exceeds the previous eps ({}{}): the schedule lowers eps", stage.eps, from,
                                     i == 0 ? ", constants.eps" : ""));
    // Same eps on the same grid is the solve it continues from, repeated.
    if (stage.eps == from && !stage.new_grid())
      st.fail_key("eps", fmt::format("= {} is the eps of the stage it continues from and the stage keeps its grid (lloyd_iterations = 0, "
                                     "no 'resolve'): it would repeat that solve; lower eps or build a new grid",
                                     stage.eps));
    previous = stage.eps;
    if (!stage.branch) main_eps = stage.eps;
    a.stages.push_back(stage);
  }
  m.adaptivity = std::move(a);
}

/// The number of copies of the domain that make the symmetric body: 2 per plane of symmetry.
double symmetric_copies(const Scene& s) { return double(1 << s.mirrors.size()); }

/// The measure of the domain (axisymmetric: the volume of revolution), with its mirror images.
double domain_measure(const Scene& s) {
  const Box& b = s.domain;
  if (s.axisymmetric()) return symmetric_copies(s) * std::numbers::pi * b.hi[0] * b.hi[0] * (b.hi[1] - b.lo[1]);
  double m = symmetric_copies(s);
  for (int i = 0; i < s.dim(); ++i) m *= b.hi[std::size_t(i)] - b.lo[std::size_t(i)];
  return m;
}

/// The targets must fit the domain: the volume inside it, and the membrane, a diffuse layer of
/// width ε over the area A0, too (a radius of 1e8 in a unit box ran 40 multiplier updates and
/// then stopped on its tolerance).
void check_fits_domain(const Scene& s, const SceneTable& t, const VesicleModel& m) {
  const double measure = domain_measure(s);
  if (m.volume && *m.volume > measure)
    t.fail_key("radius", fmt::format("gives a target volume {} larger than the domain's {}", *m.volume, measure));
  if (*m.area * m.eps > measure)
    t.fail_key("radius", fmt::format("gives a target area {} whose interface layer (area x {} = {}) cannot fit in the domain's "
                                     "measure {}",
                                     *m.area, m.width, *m.area * m.eps, measure));
}

/// The vesicle (phi = 1) lies inside the domain (its initial shape and its targets fit it), so the
/// phase field is -1, the outside phase, on the boundary. Another prescribed value puts an
/// interface along the boundary that the constraints cannot absorb: phi = 0 there ran 772
/// augmented-Lagrangian iterations in 94 s before stopping on its tolerance.
void check_boundary_values(const Scene& s, const VesicleModel& m) {
  for (const auto& d : s.dirichlet) {
    if (d.unknown != m.field || !d.value.is_number() || d.value.number() == -1.0) continue;
    throw SceneError(fmt::format("{} = {} prescribes the phase field '{}' off its outside phase: [vesicle] keeps the vesicle (phi = 1) "
                                 "inside the domain, so phi is -1 on the boundary; give value = -1",
                                 d.value.where, format_number(d.value.number()), m.field));
  }
}

}  // namespace

std::optional<VesicleModel> read_vesicle(const Scene& s) {
  const auto t = extension_table(s, kVesicleExtension,
                                 {"field", "width", "radius", "reduced_volume", "resolution_factor", "initial", "adaptivity", "topology_guard"});
  if (!t) return std::nullopt;
  VesicleModel m;
  m.field = t->optional_string("field").value_or(m.field);
  m.width = t->optional_string("width").value_or(m.width);
  const auto eps = s.constants.find(m.width);
  if (eps == s.constants.end())
    t->fail_key("width", fmt::format("names the constant '{}', which [constants] does not give: the vesicle model needs "
                                     "the interface width",
                                     m.width));
  m.eps = eps->second;
  if (!(m.eps > 0)) throw SceneError(fmt::format("{}: must be positive, got {}", s.where_constant(m.width), m.eps));
  m.resolution_factor = t->positive("resolution_factor", t->number("resolution_factor", m.resolution_factor));
  m.topology_guard = t->boolean("topology_guard", m.topology_guard);

  // Targets from a sphere: area 4πR² (2πR in 2D), volume v · 4/3 πR³ (v · πR² in 2D).
  const int measure_dim = s.axisymmetric() ? 3 : s.dim();
  const double pi = std::numbers::pi;
  if (t->has("radius")) {
    const double r = t->positive("radius", t->number("radius"));
    m.area = measure_dim == 3 ? 4 * pi * r * r : 2 * pi * r;
    if (t->has("reduced_volume")) {
      const double v = t->positive("reduced_volume", t->number("reduced_volume"));
      if (v > 1)
        t->fail_key("reduced_volume", fmt::format("= {} must not exceed 1: no closed surface encloses more volume than the "
                                                  "sphere of the same area",
                                                  v));
      m.reduced_volume = v;
      m.volume = v * (measure_dim == 3 ? 4.0 / 3.0 * pi * r * r * r : pi * r * r);
      try {
        check_feasible(*m.area, *m.volume, measure_dim);
      } catch (const SceneError& e) {
        t->fail_key("reduced_volume", e.what());
      }
    }
  } else if (t->has("reduced_volume")) {
    t->fail_key("reduced_volume", "needs the sphere it refers to: add 'vesicle.radius'");
  }
  if (m.area) check_fits_domain(s, *t, m);
  check_boundary_values(s, m);
  for (const auto& c : s.constraints) {
    if ((c.name == "area" && m.area && c.target) || (c.name == "volume" && m.volume && c.target))
      throw SceneError(fmt::format("{}: the target is already set by [vesicle] (radius / reduced_volume); give it once",
                                   c.where));
  }
  if (const auto init = t->optional_table("initial", {"shape", "center", "semi_axes", "radius", "eps", "thickness", "aperture", "resolve"})) {
    read_initial_shape(s, *init, m);
    if (init->has("resolve")) {
      m.initial_resolve = init->positive("resolve", init->number("resolve"));
      if (m.eps < *m.initial_resolve)
        init->fail_key("resolve", fmt::format("= {} is coarser than the first solve's {} = {}: the first grid must resolve it",
                                              *m.initial_resolve, m.width, m.eps));
    }
  } else if (std::none_of(s.initial.begin(), s.initial.end(), [&](const SceneInitialField& f) { return f.unknown == m.field; })) {
    t->fail_key("initial", fmt::format("is missing: the vesicle model starts from [vesicle.initial] (shape, center, semi_axes or "
                                       "radius), or from '{}' given in [initial]",
                                       m.field));
  }
  if (const auto adapt = t->optional_table("adaptivity", {"stages", "lloyd_iterations", "start", "samples_per_node", "band", "grading", "coarsening", "max_nodes", "fit_iterations"})) {
    read_adaptivity(*adapt, m);
    // A 3D grid is built only to resolve an interface (nested grids); the CVT relocation is 2D.
    if (s.dim() == 3)
      for (std::size_t i = 0; i < m.adaptivity->stages.size(); ++i)
        if (const AdaptivityStage& st = m.adaptivity->stages[i]; !st.resolve && st.new_grid())
          adapt->fail_key("stages", fmt::format("[{}] relocates the nodes by a CVT (f, lloyd_iterations = {}), which is 2D and axisymmetric "
                                                "only: in 3D a stage resolves the interface ('resolve = ...', nested grids) or keeps "
                                                "its grid ('lloyd_iterations = 0')",
                                                i, st.lloyd_iterations));
  }
  // The sphere of the targets must be wider than the interface at least at the schedule's finest
  // eps: a diffuse interface wider than the vesicle leaves it no inside phase (radius 1e-14 in the
  // tiny scene ran 40 multiplier updates and stopped; 1e-4 stalled in KKT Newton).
  if (t->has("radius")) {
    double finest = m.eps;
    if (m.adaptivity)
      for (const auto& st : m.adaptivity->stages) finest = std::min(finest, st.eps);
    const double r = t->number("radius");
    if (r < finest)
      t->fail_key("radius", fmt::format("= {} is below the interface width {} = {}{}: a diffuse interface wider than the vesicle leaves "
                                        "it no inside phase; give a radius of at least {} or a narrower interface",
                                        format_number(r), m.width, format_number(finest),
                                        m.adaptivity ? " (the finest of the schedule)" : "", format_number(finest)));
  }
  // The first solve must be resolved by the grid when the scene describes it completely (with
  // initial.resolve, [nodes] only samples the initial profile).
  if (!m.initial_resolve && (s.nodes.kind == SceneNodes::Kind::spacing || s.nodes.kind == SceneNodes::Kind::counts)) {
    double h = std::numeric_limits<double>::infinity();
    for (int i = 0; i < s.dim(); ++i) {
      const auto k = std::size_t(i);
      const double len = s.domain.hi[k] - s.domain.lo[k];
      const double intervals = s.nodes.kind == SceneNodes::Kind::counts ? double(s.nodes.counts[k] - 1)
                                                                        : std::max(1.0, std::round(len / s.nodes.spacing));
      h = std::min(h, len / intervals);
    }
    try {
      check_resolution(m.eps, h, m.resolution_factor, "constant '" + m.width + "'");
    } catch (const std::invalid_argument& e) {
      throw SceneError(fmt::format("{}: {} (the uniform grid of [nodes]; lower nodes.spacing or raise {})",
                                   s.where_constant(m.width), e.what(), m.width));
    }
  }
  return m;
}

std::array<double, 2> spheroid_semi_axes(double A0, double v, int dim, bool oblate) {
  if (!(A0 > 0) || !(v > 0) || v > 1) throw std::invalid_argument(fmt::format("spheroid_semi_axes: A0 = {}, v = {}", A0, v));
  const double pi = std::numbers::pi;
  // Area (perimeter in 2D) and volume (area in 2D) of the spheroid with equatorial semi-axis 1 and
  // polar semi-axis rho; the reduced volume does not depend on the scale.
  auto measures = [&](double rho) -> std::array<double, 2> {
    if (dim == 2) {
      const double major = std::max(1.0, rho), minor = std::min(1.0, rho);
      const double e = std::sqrt(1 - (minor / major) * (minor / major));
      return {4 * major * std::comp_ellint_2(e), pi * rho};
    }
    double area = 4 * pi;
    if (rho < 1) {
      const double e = std::sqrt(1 - rho * rho);
      area = e > 1e-8 ? 2 * pi * (1 + (1 - e * e) / e * std::atanh(e)) : area;
    } else if (rho > 1) {
      const double e = std::sqrt(1 - 1 / (rho * rho));
      area = e > 1e-8 ? 2 * pi * (1 + rho / e * std::asin(e)) : area;
    }
    return {area, 4.0 / 3.0 * pi * rho};
  };
  auto reduced = [&](double rho) {
    const auto [area, volume] = measures(rho);
    return volume / max_volume_for_area(area, dim);
  };
  // v(rho) rises to 1 at rho = 1 on the oblate side and falls from 1 on the prolate side.
  double lo = oblate ? 1e-6 : 1.0, hi = oblate ? 1.0 : 1e6;
  for (int it = 0; it < 200; ++it) {
    const double mid = oblate ? 0.5 * (lo + hi) : std::sqrt(lo * hi);
    if ((reduced(mid) < v) == oblate) lo = mid; else hi = mid;
  }
  const double rho = 0.5 * (lo + hi);
  const double scale = dim == 2 ? A0 / measures(rho)[0] : std::sqrt(A0 / measures(rho)[0]);
  return {scale, scale * rho};
}

double max_volume_for_area(double A0, int dim) {
  const double pi = std::numbers::pi;
  if (dim == 2) return A0 * A0 / (4 * pi);
  return std::pow(A0, 1.5) / (6 * std::sqrt(pi));
}

void check_feasible(double A0, double V0, int dim) {
  const char* area = dim == 2 ? "perimeter" : "area";
  const char* volume = dim == 2 ? "area" : "volume";
  const char* sphere = dim == 2 ? "circle" : "sphere";
  if (!(A0 > 0)) throw SceneError(fmt::format("{} A0 = {} must be positive", area, A0));
  if (!(V0 > 0)) throw SceneError(fmt::format("{} V0 = {} must be positive", volume, V0));
  const double vmax = max_volume_for_area(A0, dim);
  if (V0 > vmax * (1 + 1e-12))
    throw SceneError(fmt::format("infeasible targets: {} V0 = {} exceeds V_max = {}, the {} of the {} with {} A0 = {} "
                                 "(reduced volume {} > 1)",
                                 volume, V0, vmax, volume, sphere, area, A0, V0 / vmax));
}

double membrane_area_capacity(const Box& domain, bool axisymmetric, double eps) {
  double measure = 1;
  if (axisymmetric) {
    measure = std::numbers::pi * (domain.hi[0] * domain.hi[0] - domain.lo[0] * domain.lo[0]) * (domain.hi[1] - domain.lo[1]);
  } else {
    for (int i = 0; i < domain.dim; ++i) measure *= domain.hi[std::size_t(i)] - domain.lo[std::size_t(i)];
  }
  return measure / (2 * eps);
}

void check_vesicle_targets(const BoundScene& b, const std::map<std::string, double, std::less<>>& constants,
                           std::span<const ScheduledTarget> targets) {
  const auto eps = constants.find("eps");
  if (eps == constants.end() || !(eps->second > 0)) return;
  for (const ScheduledTarget& t : targets) {
    if (t.constraint != "area") continue;
    const double capacity = membrane_area_capacity(b.domain, b.axisymmetric, eps->second);
    if (t.peak > capacity)
      throw SceneError(fmt::format("{}: the schedule takes the area target to A0 = {:.6g}, more membrane than the domain can hold at "
                                   "eps = {:g}: at most about |domain| / (2 eps) = {:.6g} (interfaces stacked 2 eps apart); a smaller "
                                   "increase, a larger domain or a thinner interface",
                                   t.where, t.peak, eps->second, capacity));
  }
}

double initial_profile(const VesicleModel& m, std::span<const double> x, int dim) {
  const auto d = std::size_t(dim);
  double inside = 0;
  if (m.shape == VesicleModel::Shape::stomatocyte) {
    // The meridian plane: rho across the axis (the last coordinate), z along it.
    double rho2 = 0;
    for (std::size_t i = 0; i + 1 < d; ++i) rho2 += (x[i] - m.center[i]) * (x[i] - m.center[i]);
    const double rho = std::sqrt(rho2), z = x[d - 1] - m.center[d - 1], radius = m.cup_radius;
    const double polar = std::atan2(rho, z);  // from the top pole
    const double to_mid_surface = polar >= m.cup_aperture
                                      ? std::abs(std::hypot(rho, z) - radius)
                                      : std::hypot(rho - radius * std::sin(m.cup_aperture), z - radius * std::cos(m.cup_aperture));
    inside = m.cup_thickness / 2 - to_mid_surface;
  } else {
    inside = ellipsoid_signed_distance(x.first(d), std::span<const double>(m.center).first(d),
                                       std::span<const double>(m.semi_axes).first(d));
  }
  return std::tanh(inside / (std::numbers::sqrt2 * m.profile_eps.value_or(m.eps)));
}

std::vector<double> rescale_interface(std::span<const double> phi, double eps_from, double eps_to) {
  if (!(eps_from > 0) || !(eps_to > 0)) throw std::invalid_argument("rescale_interface: eps must be positive");
  const double ratio = eps_from / eps_to, bound = 1.0 - 1e-15;
  std::vector<double> out(phi.size());
  for (std::size_t a = 0; a < phi.size(); ++a) out[a] = std::tanh(ratio * std::atanh(std::clamp(phi[a], -bound, bound)));
  return out;
}

namespace {

/// The grid of a stage that builds one: an interface-resolving grid, or a CVT relocation with the
/// density 1 + f |∇φ| of the solution it continues from.
NodeSet relocated_nodes(const Scene& scene, const VesicleModel& model, const AdaptivityStage& st, const StageRecord& from,
                        std::ostream* log) {
  CvtOptions cvt;
  cvt.iterations = st.lloyd_iterations;
  cvt.samples_per_node = model.adaptivity->samples_per_node;
  if (st.resolve)
    return resolve_interface(from.result.nodes, from.result.state, scene.domain, *st.resolve, model.resolution_factor,
                             model.adaptivity->interface, cvt, log);
  cvt.start = model.adaptivity->start_from_density ? CvtStart::density : CvtStart::given;
  CvtReport report;
  NodeSet nodes = adapt_nodes(from.result, scene.domain, st.f, cvt, &report);
  if (log != nullptr)
    *log << "CVT with rho = 1 + " << st.f << " |grad phi|: " << report.iterations.size() << " Lloyd iterations"
         << (cvt.start == CvtStart::density ? " from the density's node placement" : " from the current nodes") << ", " << report.samples
         << (cvt.centroids == CvtCentroids::voronoi ? " density evaluations per iteration\n" : " samples\n");
  return nodes;
}

/// The first grid resolving the initial profile's interface (initial_resolve).
NodeSet initially_resolved_nodes(const Scene& scene, const VesicleModel& model, const NodeSet& nodes, std::ostream* log) {
  std::vector<double> profile(nodes.size());
  for (std::size_t a = 0; a < nodes.size(); ++a) profile[a] = initial_profile(model, nodes.point(a), scene.dim());
  CvtOptions cvt;
  cvt.iterations = AdaptivityStage{}.lloyd_iterations;
  cvt.samples_per_node = model.adaptivity ? model.adaptivity->samples_per_node : VesicleAdaptivity{}.samples_per_node;
  return resolve_interface(nodes, profile, scene.domain, *model.initial_resolve, model.resolution_factor,
                           model.adaptivity ? model.adaptivity->interface : InterfaceResolution{}, cvt, log);
}

/// The start of a later stage: the previous field (on the same grid its coefficients, else its
/// values at the new nodes), re-profiled to a narrower interface, and the previous multipliers.
void continue_from(const BoundScene& bound, const VesicleModel& model, const AdaptivityStage& st, const StageRecord& from, double eps,
                   ProblemInput& input) {
  const auto& previous = from.result;
  const double gamma = bound.discretization.gamma;
  // With fit_iterations > 0 the start is the previous field's values at the nodes, re-profiled,
  // with coefficients fitted so that the LME field takes them (LME is not interpolating). Measured,
  // fitted against not: the discocyte's eps 0.015 -> 0.01 stage starts at E = 9.42 against 20.07
  // and needs 11 KKT steps against 13, but the dumbbell's stages at eps = 0.02 and 0.015 crawl for
  // 25 damped steps against 9 and 12, so fitting is not the default.
  const int fit = model.adaptivity->fit_iterations;
  if (fit > 0 && (st.new_grid() || eps != from.eps)) {
    std::vector<double> values = interpolate_nodal_field(previous.nodes, previous.state, gamma, input.lme, input.nodes);
    if (eps < from.eps) values = rescale_interface(values, from.eps, eps);
    input.initial = fit_nodal_values(input.nodes, values, gamma, input.lme, fit);
  } else {
    input.initial = !st.new_grid() ? previous.state : interpolate_nodal_field(previous.nodes, previous.state, gamma, input.lme, input.nodes);
    if (eps < from.eps) input.initial = rescale_interface(input.initial, from.eps, eps);
  }
  // The multipliers (tension, pressure) change little between stages: start from the last ones.
  if (previous.converged) input.initial_multipliers = previous.minimization.multipliers;
  // Only eps changes: the nodes, cells, quadrature and basis are those of the stage before.
  if (!st.new_grid()) input.discretization = previous.discretization;
}

/// The start of the first stage: the scene's [initial], else the model's profile.
std::vector<double> first_start(const BoundScene& bound, const VesicleModel& model, const NodeSet& nodes) {
  std::vector<double> start = initial_state(bound, nodes);
  if (std::none_of(bound.initial.begin(), bound.initial.end(), [&](const BoundNodalField& f) { return f.name == model.field; }))
    for (std::size_t a = 0; a < nodes.size(); ++a) start[a] = initial_profile(model, nodes.point(a), bound.dim);
  return start;
}

/// The topology of φ = 0 for coefficients on a solve's discretization; none (and a note in the
/// log) when the field cannot be evaluated, which ends no run.
std::optional<LevelSetTopology> topology_or_none(const ProblemResult& solved, std::span<const double> coefficients, const BoundScene& bound,
                                                 std::ostream* log) {
  if (!solved.discretization) return std::nullopt;
  try {
    // With planes of symmetry, the topology of the whole body (the part's level set has boundary on the planes).
    return field_topology(*solved.discretization, coefficients, level_set_geometry(bound.dim, bound.axisymmetric), bound.discretization.mirrors);
  } catch (const std::exception& e) {
    if (log != nullptr) *log << "the membrane's topology could not be evaluated: " << e.what() << "\n";
    return std::nullopt;
  }
}

/// One stage of the schedule: the relocation (if any), the resolution check and the solve,
/// continuing from stage `from` of `stages` (none for stage 0). Throws when the stage cannot run.
/// Stage 0 also gives the topology of its start.
StageRecord run_vesicle_stage(MPI_Comm comm, const BoundScene& bound, const VesicleModel& model, std::ostream* log, int stage,
                              const std::vector<StageRecord>& stages, std::size_t main_stage, NodeSet& nodes,
                              std::optional<LevelSetTopology>& start_topology) {
  const Scene& scene = *bound.scene;
  const Stopwatch clock;
  StageRecord rec;
  rec.stage = stage;
  rec.eps = stage == 0 ? model.eps : model.adaptivity->stages[static_cast<std::size_t>(stage - 1)].eps;
  rec.grid = scene.nodes.kind == SceneNodes::Kind::file ? "file" : "uniform";
  const AdaptivityStage* st = stage > 0 ? &model.adaptivity->stages[static_cast<std::size_t>(stage - 1)] : nullptr;
  const std::size_t from = st == nullptr ? 0 : st->branch ? stages.size() - 1 : main_stage;
  if (st != nullptr) {
    nodes = stages[from].result.nodes;
    rec.generation = stages[from].generation + (st->new_grid() ? 1 : 0);
    // A 3D stage's new grid is a nested grid around the interface; in 2D it is a CVT.
    rec.grid = rec.generation == 0 ? stages[from].grid : (scene.dim() == 3 ? "nested-" : "cvt-") + std::to_string(rec.generation);
    if (st->branch) rec.label = " (branch)";
    if (st->new_grid()) nodes = relocated_nodes(scene, model, *st, stages[from], log);
    rec.adapt_s = clock.seconds();
  } else if (model.initial_resolve) {
    nodes = initially_resolved_nodes(scene, model, nodes, log);
    rec.grid = "interface";
    rec.adapt_s = clock.seconds();
  }
  const SpacingSummary spacing = spacing_summary(nodes);
  rec.h_min = spacing.h_min;
  // An under-resolved interface is refused before any work (seed App. B: ε ≥ 2 h_min).
  check_resolution(rec.eps, spacing, model.resolution_factor, rec.grid + " grid");

  ProblemInput input;
  input.nodes = nodes;
  input.lme = bound.lme(AxisParity::even);
  input.log = log;
  input.constants[model.width] = rec.eps;
  if (st == nullptr) input.initial = first_start(bound, model, nodes);
  else continue_from(bound, model, *st, stages[from], rec.eps, input);
  if (log != nullptr)
    *log << "== stage " << stage << " (" << rec.grid << rec.label << "): " << nodes.size() << " nodes, eps " << rec.eps << ", h_min "
         << rec.h_min << "\n";
  rec.result = solve_problem(comm, bound, input);
  rec.nodes = static_cast<int>(nodes.size());
  const Stopwatch topology_clock;
  if (stage == 0) start_topology = topology_or_none(rec.result, input.initial, bound, log);
  rec.topology = topology_or_none(rec.result, rec.result.state, bound, log);
  rec.topology_s = topology_clock.seconds();
  rec.wall_s = clock.seconds();
  rec.peak_rss_mb = peak_resident_mb_per_rank(comm);
  return rec;
}

}  // namespace

Scene with_vesicle_targets(const Scene& scene, const VesicleModel& model) {
  Scene completed = scene;
  for (auto& c : completed.constraints) {
    // With planes of symmetry the forms integrate over one part of the body.
    if (c.name == "area" && model.area) c.target = *model.area / symmetric_copies(scene);
    if (c.name == "volume" && model.volume) c.target = *model.volume / symmetric_copies(scene);
    if (c.name == "moment" && model.volume && !c.scale) c.scale = std::abs(*model.volume) / symmetric_copies(scene);
  }
  return completed;
}

BoundScene bind_vesicle(const Scene& completed, MPI_Comm comm, std::ostream* log, const VesicleModel& model) {
  OutputRoles extra;
  extra.provided_constants = {model.width};
  BoundScene bound = bind_scene(completed, comm, log, extra);
  if (bound.energy.empty() || bound.layout.fields.size() != 1 || bound.layout.fields.front().components != 1 ||
      bound.layout.fields.front().name != model.field)
    throw SceneError(fmt::format("{}: [vesicle] minimizes an energy of one scalar phase field '{}'; the scene's problem has other "
                                 "unknowns or outputs",
                                 completed.source, model.field));
  return bound;
}

namespace {

/// The last stage's membrane topology against the one before it (for the first stage: its start):
/// logged, and a change either warned of or, with the guard, the end of the run (the stage moves
/// to run.rejected). False when the run ends here.
bool watch_topology(const VesicleModel& model, int stage, std::ostream* log, VesicleRun& run) {
  const StageRecord& rec = run.stages.back();
  if (!rec.topology) return true;
  const auto before = run.stages.size() > 1 ? run.stages[run.stages.size() - 2].topology : run.initial_topology;
  if (log != nullptr) {
    if (stage == 0 && run.initial_topology) *log << "the membrane (phi = 0) at the start: " << run.initial_topology->describe() << "\n";
    *log << "the membrane (phi = 0) after stage " << stage << ": " << rec.topology->describe()
         << fmt::format(" ({:.2f} s)\n", rec.topology_s);
  }
  if (!before) return true;
  const std::string change = topology_change_warning(*before, *rec.topology, "stage " + std::to_string(stage));
  if (change.empty()) return true;
  if (model.topology_guard) {
    run.failure = fmt::format("stage {}: the membrane's topology changed: {} -> {}; vesicle.topology_guard rejects the stage", stage,
                              before->describe(), rec.topology->describe());
    run.rejected = std::move(run.stages.back());
    run.stages.pop_back();
    if (log != nullptr)
      *log << "lmeform: " << run.failure << "\nlmeform: "
           << (run.stages.empty() ? "no stage kept the start's topology: writing the rejected stage\n" : "writing the last stage that kept it\n");
    return false;
  }
  const std::string warning = change + " (the phase field joins or splits the membrane where its parts come within about the "
                                       "interface width, a change the sharp model cannot make: another branch than the start's; "
                                       "vesicle.topology_guard = true stops the run at such a stage)";
  run.warnings.push_back(warning);
  if (log != nullptr) *log << "lmeform: warning: " << warning << "\n";
  return true;
}

}  // namespace

VesicleRun run_vesicle(MPI_Comm comm, const Scene& scene, const VesicleModel& model, std::ostream* log, const VesicleCheckpoint* checkpoint) {
  const Stopwatch clock;
  const Scene completed = with_vesicle_targets(scene, model);
  const BoundScene bound = bind_vesicle(completed, comm, log, model);
  VesicleRun run;
  std::size_t main_stage = 0;
  int first_stage = 0;
  NodeSet nodes;
  if (checkpoint != nullptr && checkpoint->restart) {
    ResumedSchedule resumed = read_vesicle_checkpoint(comm, *checkpoint, model, level_set_geometry(bound.dim, bound.axisymmetric));
    run = std::move(resumed.run);
    main_stage = resumed.main_stage;
    first_stage = static_cast<int>(run.stages.size());
    if (log != nullptr)
      *log << fmt::format("resumed from {} after stage {} (E = {:.8g}, {} nodes)\n", checkpoint->directory.string(), first_stage - 1,
                          run.stages.back().result.energy, run.stages.back().nodes);
  } else {
    nodes = initial_nodes(scene, comm, log);
  }
  run.layout = bound.layout;
  const int n_stages = 1 + (model.adaptivity ? static_cast<int>(model.adaptivity->stages.size()) : 0);
  for (int stage = first_stage; stage < n_stages; ++stage) {
    try {
      run.stages.push_back(run_vesicle_stage(comm, bound, model, log, stage, run.stages, main_stage, nodes, run.initial_topology));
    } catch (const std::exception& e) {
      if (run.stages.empty()) throw;  // nothing to write
      run.failure = "stage " + std::to_string(stage) + ": " + e.what();
      if (log != nullptr) *log << "lmeform: " << run.failure << "\nlmeform: writing the last finished stage\n";
      break;
    }
    if (!watch_topology(model, stage, log, run)) break;
    const bool branch = stage > 0 && model.adaptivity->stages[static_cast<std::size_t>(stage - 1)].branch;
    if (!branch) main_stage = run.stages.size() - 1;
    // Later stages continue from the last stage or the main one: only their discretizations are kept.
    for (std::size_t i = 0; i + 1 < run.stages.size(); ++i)
      if (i != main_stage) run.stages[i].result.discretization.reset();
    if (!run.stages.back().result.converged) break;
    if (checkpoint != nullptr) {
      // A checkpoint that cannot be written costs the restart, not the run.
      try {
        write_vesicle_checkpoint(comm, *checkpoint, run, main_stage);
      } catch (const std::exception& e) {
        run.warnings.push_back(fmt::format("no checkpoint after stage {}: {}", stage, e.what()));
        if (log != nullptr) *log << "lmeform: warning: " << run.warnings.back() << "\n";
      }
    }
  }
  run.wall_s = clock.seconds();
  return run;
}

SpacingFunction interface_spacing(const NodeSet& nodes, std::span<const double> phi, double eps_resolve, double h_interface,
                               const InterfaceResolution& resolution) {
  if (phi.size() != nodes.size())
    throw std::invalid_argument(fmt::format("interface_spacing: {} values for {} nodes", phi.size(), nodes.size()));
  if (!(h_interface > 0) || !(eps_resolve > 0))
    throw std::invalid_argument(fmt::format("interface_spacing: h_interface = {} and eps = {} must be positive", h_interface, eps_resolve));
  // The zero level set, sampled where it crosses the edges of the Delaunay cells (linear between
  // the two nodal values): points about one old spacing apart, far closer than the band.
  const BackgroundCells cells = delaunay(nodes);
  const auto du = static_cast<std::size_t>(nodes.dim);
  std::vector<double> crossings;
  std::set<std::pair<int, int>> seen;
  for (std::size_t c = 0; c < cells.size(); ++c) {
    const auto v = cells.cell(c);
    for (std::size_t i = 0; i < v.size(); ++i) {
      for (std::size_t j = i + 1; j < v.size(); ++j) {
        const auto a = static_cast<std::size_t>(std::min(v[i], v[j])), b = static_cast<std::size_t>(std::max(v[i], v[j]));
        if (!((phi[a] < 0) != (phi[b] < 0)) || !seen.emplace(int(a), int(b)).second) continue;
        const double t = phi[a] / (phi[a] - phi[b]);
        for (std::size_t k = 0; k < du; ++k) crossings.push_back(nodes.coords[a * du + k] + t * (nodes.coords[b * du + k] - nodes.coords[a * du + k]));
      }
    }
  }
  if (crossings.empty()) throw std::invalid_argument("interface_spacing: the phase field has no interface (no sign change)");
  struct Interface {
    NodeSet points;
    KdTree tree;
    explicit Interface(NodeSet p) : points(std::move(p)), tree(points) {}
  };
  auto interface = std::make_shared<const Interface>(NodeSet(nodes.dim, std::move(crossings)));
  const double band = resolution.band * eps_resolve, grading = resolution.grading, h_far = resolution.coarsening * h_interface;
  SpacingFunction field;
  field.h_min = h_interface;
  field.h = [interface, band, grading, h_interface, h_far](std::span<const double> x) {
    thread_local std::vector<int> nearest;
    thread_local std::vector<double> distance;
    interface->tree.knn(x, 1, nearest, &distance);
    return std::min(h_far, h_interface + grading * std::max(0.0, distance[0] - band));
  };
  return field;
}

NodeSet resolve_interface(const NodeSet& sampled, std::span<const double> phi, const Box& box, double eps_resolve, double resolution_factor,
                          const InterfaceResolution& resolution, const CvtOptions& cvt, std::ostream* log) {
  const Stopwatch clock;
  double h_interface = eps_resolve / resolution_factor;
  // In 3D (no CVT there) the grid is an octree's vertices: uniform grids nested toward the interface,
  // whose finest level is already at or below the interface spacing.
  if (box.dim == 3) {
    const NodeSet nodes = nested_grids(box, interface_spacing(sampled, phi, eps_resolve, h_interface, resolution), resolution.max_nodes);
    const SpacingSummary spacing = spacing_summary(nodes);
    if (log != nullptr)
      *log << fmt::format("interface grid for eps >= {}: h {:.4g} within {:.4g} of the interface, grading {}, {} nodes of nested "
                          "grids, h_min {:.4g} ({:.1f} s)\n",
                          eps_resolve, h_interface, resolution.band * eps_resolve, resolution.grading, nodes.size(), spacing.h_min,
                          clock.seconds())
           << std::flush;
    return nodes;
  }
  for (int attempt = 0;; ++attempt) {
    const SpacingFunction field = interface_spacing(sampled, phi, eps_resolve, h_interface, resolution);
    if (const std::size_t needed_nodes = count_nodes_for_spacing(box, field).total; needed_nodes > resolution.max_nodes)
      throw std::invalid_argument(fmt::format("the grid resolving eps >= {} (h {:.4g} at the interface) needs {} nodes, more than "
                                              "[vesicle.adaptivity] max_nodes = {}: raise 'max_nodes' or resolve a larger eps",
                                              eps_resolve, h_interface, needed_nodes, resolution.max_nodes));
    CvtReport report;
    NodeSet nodes = cvt_for_spacing(box, field, resolution.max_nodes, cvt, &report);
    const SpacingSummary spacing = spacing_summary(nodes);
    const double needed = resolution_factor * spacing.h_min;
    if (log != nullptr) {
      *log << fmt::format("interface grid for eps >= {}: h {:.4g} within {:.4g} of the interface, grading {}, {} nodes, "
                          "{} Lloyd iterations, h_min {:.4g} ({:.1f} s)\n",
                          eps_resolve, h_interface, resolution.band * eps_resolve, resolution.grading, nodes.size(),
                          report.iterations.size(), spacing.h_min, clock.seconds())
           << std::flush;
    }
    // The measured h_min (a low quantile of the Voronoi-ring spacing) lies a little below the
    // target spacing of a CVT: refine by the ratio until the resolution rule holds.
    if (eps_resolve >= needed * (1 - 1e-12)) return nodes;
    if (attempt == 3)
      throw std::invalid_argument(fmt::format("resolve_interface: after 4 grids h_min = {} still exceeds eps / {} = {}", spacing.h_min,
                                              resolution_factor, eps_resolve / resolution_factor));
    h_interface *= 0.99 * eps_resolve / needed;
  }
}

NodeSet adapt_nodes(const ProblemResult& solved, const Box& box, double f, const CvtOptions& cvt, CvtReport* report) {
  const auto density = phase_field_density(f, solved.nodes, solved.gradient_norm);
  return cvt_relocate(solved.nodes, box, density, cvt, report);
}

}  // namespace lmeform::problems
