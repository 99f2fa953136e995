// Scene files: strict TOML reading (every key known, typed and range-checked) and the geometric helpers
// a run needs from the scene (initial profile, feasibility of the constraint targets, resolution check).
#include "lmeform/scene.hpp"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <fstream>
#include <initializer_list>
#include <limits>
#include <numbers>
#include <sstream>

#include <toml++/toml.h>

#include "lmeform/cvt.hpp"
#include "lmeform/quadrature.hpp"

namespace lmeform {
namespace {

std::string fmt(double v) {
  std::ostringstream s;
  s.precision(10);
  s << v;
  return s.str();
}

std::size_t edit_distance(std::string_view a, std::string_view b) {
  std::vector<std::size_t> row(b.size() + 1);
  for (std::size_t j = 0; j <= b.size(); ++j) row[j] = j;
  for (std::size_t i = 1; i <= a.size(); ++i) {
    std::size_t diag = row[0];
    row[0] = i;
    for (std::size_t j = 1; j <= b.size(); ++j) {
      const std::size_t up = row[j];
      row[j] = std::min({row[j] + 1, row[j - 1] + 1, diag + (a[i - 1] == b[j - 1] ? 0 : 1)});
      diag = up;
    }
  }
  return row[b.size()];
}

/// The closest candidate when it is close enough to be a likely typo; empty otherwise.
std::string closest(std::string_view word, std::initializer_list<std::string_view> candidates) {
  std::string best;
  std::size_t best_d = std::numeric_limits<std::size_t>::max();
  for (auto c : candidates) {
    const std::size_t d = edit_distance(word, c);
    if (d < best_d) {
      best_d = d;
      best = std::string(c);
    }
  }
  const std::size_t limit = std::max<std::size_t>(2, std::min(word.size(), best.size()) / 3);
  return best_d <= limit ? best : std::string{};
}

/// Candidates one of whose '_'-separated words is close to `word` ("tolerence": every *_tolerance).
std::vector<std::string_view> partial_matches(std::string_view word,
                                              std::initializer_list<std::string_view> candidates) {
  std::vector<std::string_view> out;
  for (auto c : candidates) {
    std::size_t start = 0;
    while (start <= c.size()) {
      const std::size_t end = std::min(c.find('_', start), c.size());
      const std::string_view part = c.substr(start, end - start);
      const std::size_t limit = std::max<std::size_t>(1, std::min(word.size(), part.size()) / 4);
      if (part.size() >= 3 && edit_distance(word, part) <= limit) {
        out.push_back(c);
        break;
      }
      start = end + 1;
    }
  }
  return out;
}

std::string join(std::initializer_list<std::string_view> items) {
  std::string s;
  for (auto it : items) {
    if (!s.empty()) s += ", ";
    s += "'";
    s += it;
    s += "'";
  }
  return s;
}

const char* type_name(toml::node_type t) {
  switch (t) {
    case toml::node_type::table: return "a table";
    case toml::node_type::array: return "an array";
    case toml::node_type::string: return "a string";
    case toml::node_type::integer: return "an integer";
    case toml::node_type::floating_point: return "a floating-point number";
    case toml::node_type::boolean: return "a boolean";
    case toml::node_type::date: return "a date";
    case toml::node_type::time: return "a time";
    case toml::node_type::date_time: return "a date-time";
    case toml::node_type::none: break;
  }
  return "nothing";
}

struct Context {
  std::string file;
};

[[noreturn]] void fail(const Context& ctx, const toml::node* at, const std::string& message) {
  std::string where = ctx.file;
  if (at != nullptr && at->source().begin.line > 0) where += ":" + std::to_string(at->source().begin.line);
  throw SceneError(where + ": " + message);
}

/// A table of the scene with its key path; construction refuses unknown keys.
class Section {
 public:
  Section(const Context& ctx, const toml::table& table, std::string path,
          std::initializer_list<std::string_view> allowed)
      : ctx_(ctx), table_(table), path_(std::move(path)) {
    for (const auto& [key, node] : table_) {
      const std::string_view k = key.str();
      if (std::find(allowed.begin(), allowed.end(), k) != allowed.end()) continue;
      std::string msg = "unknown key '" + key_path(k) + "'";
      if (path_.empty()) msg = "unknown table [" + std::string(k) + "]";
      const std::string guess = closest(k, allowed);
      const std::vector<std::string_view> partial = partial_matches(k, allowed);
      if (!guess.empty()) {
        msg += "; did you mean '" + guess + "'?";
      } else if (!partial.empty()) {
        msg += partial.size() == 1 ? "; did you mean " : "; did you mean one of ";
        for (std::size_t i = 0; i < partial.size(); ++i)
          msg += (i == 0 ? "'" : ", '") + std::string(partial[i]) + "'";
        msg += "?";
      } else
        msg += "; the keys of " + (path_.empty() ? std::string("a scene") : "[" + path_ + "]") + " are " +
               join(allowed);
      fail(ctx_, &node, msg);
    }
  }

  [[nodiscard]] const Context& context() const { return ctx_; }
  [[nodiscard]] const std::string& path() const { return path_; }
  [[nodiscard]] std::string key_path(std::string_view key) const {
    return path_.empty() ? std::string(key) : path_ + "." + std::string(key);
  }
  [[nodiscard]] bool has(std::string_view key) const { return table_.get(key) != nullptr; }
  [[nodiscard]] const toml::node* node(std::string_view key) const { return table_.get(key); }
  /// The node to point at for a message about `key`: the key's value, else this table.
  [[nodiscard]] const toml::node* at(std::string_view key) const {
    const toml::node* n = table_.get(key);
    return n != nullptr ? n : &table_;
  }

  [[noreturn]] void fail_key(std::string_view key, const std::string& reason) const {
    fail(ctx_, at(key), "key '" + key_path(key) + "' " + reason);
  }

  const toml::node& require(std::string_view key) const {
    const toml::node* n = table_.get(key);
    if (n == nullptr) {
      if (path_.empty()) fail(ctx_, &table_, "missing table [" + std::string(key) + "]");
      fail(ctx_, &table_, "missing key '" + key_path(key) + "' in [" + path_ + "]");
    }
    return *n;
  }

  void wrong_type(std::string_view key, const toml::node& n, const char* expected) const {
    fail(ctx_, &n, "key '" + key_path(key) + "' must be " + expected + ", found " + type_name(n.type()));
  }

  double number_of(std::string_view key, const toml::node& n) const {
    double v = 0;
    if (const auto* f = n.as_floating_point()) {
      v = f->get();
    } else if (const auto* i = n.as_integer()) {
      v = static_cast<double>(i->get());
    } else {
      wrong_type(key, n, "a number");
    }
    if (!std::isfinite(v)) fail(ctx_, &n, "key '" + key_path(key) + "' must be finite, got " + fmt(v));
    return v;
  }

  [[nodiscard]] double number(std::string_view key) const { return number_of(key, require(key)); }
  [[nodiscard]] double number(std::string_view key, double fallback) const {
    const toml::node* n = node(key);
    return n != nullptr ? number_of(key, *n) : fallback;
  }
  [[nodiscard]] std::optional<double> optional_number(std::string_view key) const {
    const toml::node* n = node(key);
    if (n == nullptr) return std::nullopt;
    return number_of(key, *n);
  }

  [[nodiscard]] int integer_of(std::string_view key, const toml::node& n) const {
    const auto* i = n.as_integer();
    if (i == nullptr) wrong_type(key, n, "an integer");
    const std::int64_t v = i->get();
    if (v < std::numeric_limits<int>::min() || v > std::numeric_limits<int>::max())
      fail(ctx_, &n, "key '" + key_path(key) + "' is out of range: " + std::to_string(v));
    return static_cast<int>(v);
  }
  [[nodiscard]] int integer(std::string_view key, int fallback) const {
    const toml::node* n = node(key);
    return n != nullptr ? integer_of(key, *n) : fallback;
  }

  [[nodiscard]] bool boolean(std::string_view key, bool fallback) const {
    const toml::node* n = node(key);
    if (n == nullptr) return fallback;
    const auto* b = n->as_boolean();
    if (b == nullptr) wrong_type(key, *n, "a boolean (true or false)");
    return b->get();
  }

  [[nodiscard]] std::string string_of(std::string_view key, const toml::node& n) const {
    const auto* s = n.as_string();
    if (s == nullptr) wrong_type(key, n, "a string");
    if (s->get().empty()) fail(ctx_, &n, "key '" + key_path(key) + "' must not be empty");
    return s->get();
  }
  [[nodiscard]] std::string string(std::string_view key) const { return string_of(key, require(key)); }
  [[nodiscard]] std::optional<std::string> optional_string(std::string_view key) const {
    const toml::node* n = node(key);
    if (n == nullptr) return std::nullopt;
    return string_of(key, *n);
  }

  /// A string that must be one of `choices`.
  [[nodiscard]] std::string choice_of(std::string_view key, const std::string& value,
                                      std::initializer_list<std::string_view> choices) const {
    if (std::find(choices.begin(), choices.end(), value) != choices.end()) return value;
    std::string msg = "must be one of " + join(choices) + ", got '" + value + "'";
    const std::string guess = closest(value, choices);
    if (!guess.empty()) msg += "; did you mean '" + guess + "'?";
    fail_key(key, msg);
  }

  /// An array of `count` numbers (count = 0: 2 or 3 numbers).
  [[nodiscard]] std::vector<double> numbers(std::string_view key, int count) const {
    const toml::node& n = require(key);
    const auto* a = n.as_array();
    const std::string expected = count > 0 ? "an array of " + std::to_string(count) + " numbers"
                                           : std::string("an array of 2 or 3 numbers");
    if (a == nullptr) wrong_type(key, n, expected.c_str());
    const auto size = static_cast<int>(a->size());
    if ((count > 0 && size != count) || (count == 0 && (size < 2 || size > 3)))
      fail(ctx_, &n, "key '" + key_path(key) + "' must be " + expected + ", found " + std::to_string(size) +
                         (size == 1 ? " entry" : " entries"));
    std::vector<double> v;
    for (std::size_t i = 0; i < a->size(); ++i)
      v.push_back(number_of(std::string(key) + "[" + std::to_string(i) + "]", (*a)[i]));
    return v;
  }

  [[nodiscard]] std::vector<int> integers(std::string_view key, int count) const {
    const toml::node& n = require(key);
    const auto* a = n.as_array();
    const std::string expected = "an array of " + std::to_string(count) + " integers";
    if (a == nullptr) wrong_type(key, n, expected.c_str());
    if (static_cast<int>(a->size()) != count)
      fail(ctx_, &n, "key '" + key_path(key) + "' must be " + expected + ", found " + std::to_string(a->size()) +
                         (a->size() == 1 ? " entry" : " entries"));
    std::vector<int> v;
    for (std::size_t i = 0; i < a->size(); ++i)
      v.push_back(integer_of(std::string(key) + "[" + std::to_string(i) + "]", (*a)[i]));
    return v;
  }

  [[nodiscard]] Section table_of(std::string_view key, const toml::node& n,
                                 std::initializer_list<std::string_view> allowed) const {
    const auto* t = n.as_table();
    if (t == nullptr) {
      if (path_.empty())
        fail(ctx_, &n, "'" + std::string(key) + "' must be a table ([" + std::string(key) + "]), found " +
                           type_name(n.type()));
      wrong_type(key, n, "a table");
    }
    return Section(ctx_, *t, key_path(key), allowed);
  }
  [[nodiscard]] Section table(std::string_view key, std::initializer_list<std::string_view> allowed) const {
    return table_of(key, require(key), allowed);
  }
  [[nodiscard]] std::optional<Section> optional_table(std::string_view key,
                                                      std::initializer_list<std::string_view> allowed) const {
    const toml::node* n = node(key);
    if (n == nullptr) return std::nullopt;
    return table_of(key, *n, allowed);
  }

  // Range checks: the value is returned for chaining.
  double positive(std::string_view key, double v) const {
    if (!(v > 0)) fail_key(key, "must be positive, got " + fmt(v));
    return v;
  }
  double non_negative(std::string_view key, double v) const {
    if (!(v >= 0)) fail_key(key, "must be non-negative, got " + fmt(v));
    return v;
  }
  int at_least(std::string_view key, int v, int lo) const {
    if (v < lo) fail_key(key, "must be at least " + std::to_string(lo) + ", got " + std::to_string(v));
    return v;
  }

 private:
  const Context& ctx_;
  const toml::table& table_;
  std::string path_;
};

const char* axis_name(bool axisymmetric, int dim, int i) {
  static const char* cart[3] = {"x", "y", "z"};
  if (axisymmetric) return i == 0 ? "r" : "z";
  return i < dim ? cart[i] : "?";
}

void read_scene_section(const Section& root, Scene& s) {
  const Section t = root.table("scene", {"name", "coordinates", "description"});
  s.name = t.string("name");
  (void)t.optional_string("description");
  const std::string c =
      t.choice_of("coordinates", t.string("coordinates"), {"axisymmetric", "cartesian"});
  s.coordinates = c == "axisymmetric" ? Coordinates::axisymmetric : Coordinates::cartesian;
}

void read_domain(const Section& root, Scene& s) {
  const Section t = root.table("domain", {"lower", "upper"});
  const int count = s.axisymmetric() ? 2 : 0;
  const std::vector<double> lo = t.numbers("lower", count);
  const std::vector<double> hi = t.numbers("upper", static_cast<int>(lo.size()));
  s.domain.dim = static_cast<int>(lo.size());
  for (int i = 0; i < s.domain.dim; ++i) {
    const auto k = static_cast<std::size_t>(i);
    if (!(lo[k] < hi[k]))
      t.fail_key("upper", "must exceed 'domain.lower' on every axis: axis " +
                              std::string(axis_name(s.axisymmetric(), s.domain.dim, i)) + " has lower " +
                              fmt(lo[k]) + ", upper " + fmt(hi[k]));
    s.domain.lo[k] = lo[k];
    s.domain.hi[k] = hi[k];
  }
  if (s.axisymmetric() && lo[0] < 0)
    t.fail_key("lower", "must have r >= 0 in an axisymmetric scene (r is the distance to the axis), got r = " +
                            fmt(lo[0]));
}

void read_nodes(const Section& root, const std::filesystem::path& folder, Scene& s) {
  const Section t = root.table(
      "nodes", {"spacing", "counts", "count", "lloyd_iterations", "file", "gamma", "spacing_smoothing", "quadrature_points",
                "resolution_factor"});
  SceneNodes& n = s.nodes;
  const char* const kinds[] = {"spacing", "counts", "count", "file"};
  std::vector<std::string> present;
  for (const char* k : kinds) {
    if (t.has(k)) present.emplace_back(k);
  }
  if (present.empty())
    fail(t.context(), t.at("spacing"),
         "missing key in [nodes]: one of 'nodes.spacing', 'nodes.counts', 'nodes.count' or 'nodes.file' is needed");
  if (present.size() > 1) {
    t.fail_key(present[1], "cannot be combined with 'nodes." + present[0] + "': give one of spacing, counts, count, file");
  }
  if (t.has("lloyd_iterations") && !t.has("count"))
    t.fail_key("lloyd_iterations", "belongs to 'nodes.count' (the Lloyd iterations of its uniform CVT)");
  double extent = std::numeric_limits<double>::infinity();
  for (int i = 0; i < s.dim(); ++i)
    extent = std::min(extent, s.domain.hi[std::size_t(i)] - s.domain.lo[std::size_t(i)]);
  if (t.has("spacing")) {
    n.kind = SceneNodes::Kind::spacing;
    n.spacing = t.positive("spacing", t.number("spacing"));
    if (n.spacing > extent)
      t.fail_key("spacing", "= " + fmt(n.spacing) + " exceeds the smallest extent of the domain (" + fmt(extent) +
                                ")");
  } else if (t.has("counts")) {
    n.kind = SceneNodes::Kind::counts;
    const std::vector<int> c = t.integers("counts", s.dim());
    for (std::size_t i = 0; i < c.size(); ++i) {
      if (c[i] < 2)
        t.fail_key("counts", "must have at least 2 nodes per axis, got " + std::to_string(c[i]) + " on axis " +
                                 axis_name(s.axisymmetric(), s.dim(), int(i)));
      n.counts[i] = c[i];
    }
  } else if (t.has("count")) {
    n.kind = SceneNodes::Kind::count;
    if (s.dim() != 2) t.fail_key("count", "is a 2D node set (uniform CVT); this domain is " + std::to_string(s.dim()) + "D");
    n.count = t.at_least("count", t.integer_of("count", t.require("count")), 16);
    n.lloyd_iterations = t.at_least("lloyd_iterations", t.integer("lloyd_iterations", n.lloyd_iterations), 0);
  } else {
    n.kind = SceneNodes::Kind::file;
    std::filesystem::path p = t.string("file");
    if (p.is_relative()) p = folder / p;
    if (!std::filesystem::is_regular_file(p))
      t.fail_key("file", "names a file that does not exist: " + p.string());
    n.file = p;
  }
  n.gamma = t.positive("gamma", t.number("gamma", n.gamma));
  n.spacing_smoothing = t.at_least("spacing_smoothing", t.integer("spacing_smoothing", n.spacing_smoothing), 0);
  n.quadrature_points = t.integer("quadrature_points", n.quadrature_points);
  const std::vector<int> sizes = s.dim() == 2 ? triangle_rule_sizes() : tetrahedron_rule_sizes();
  if (std::find(sizes.begin(), sizes.end(), n.quadrature_points) == sizes.end()) {
    std::string list;
    for (int k : sizes) list += (list.empty() ? "" : ", ") + std::to_string(k);
    t.fail_key("quadrature_points", "= " + std::to_string(n.quadrature_points) + " is not a " +
                                        (s.dim() == 2 ? "triangle" : "tetrahedron") + " rule; available: " + list);
  }
  n.resolution_factor = t.positive("resolution_factor", t.number("resolution_factor", n.resolution_factor));
}

void read_initial(const Section& root, Scene& s) {
  const Section t = root.table("initial", {"shape", "center", "semi_axes", "radius", "eps"});
  SceneInitial& in = s.initial;
  const std::string shape = t.choice_of("shape", t.string("shape"), {"ellipsoid", "sphere"});
  const std::vector<double> c = t.numbers("center", s.dim());
  for (std::size_t i = 0; i < c.size(); ++i) in.center[i] = c[i];
  if (shape == "ellipsoid") {
    in.shape = SceneInitial::Shape::ellipsoid;
    if (t.has("radius")) t.fail_key("radius", "belongs to shape 'sphere'; an ellipsoid takes 'semi_axes'");
    const std::vector<double> a = t.numbers("semi_axes", s.dim());
    for (std::size_t i = 0; i < a.size(); ++i) {
      if (!(a[i] > 0))
        t.fail_key("semi_axes", "must be positive, got " + fmt(a[i]) + " on axis " +
                                    axis_name(s.axisymmetric(), s.dim(), int(i)));
      in.semi_axes[i] = a[i];
    }
  } else {
    in.shape = SceneInitial::Shape::sphere;
    if (t.has("semi_axes")) t.fail_key("semi_axes", "belongs to shape 'ellipsoid'; a sphere takes 'radius'");
    const double r = t.positive("radius", t.number("radius"));
    for (int i = 0; i < s.dim(); ++i) in.semi_axes[std::size_t(i)] = r;
  }
  if (t.has("eps")) in.eps = t.positive("eps", t.number("eps"));
  if (s.axisymmetric() && in.center[0] != 0.0)
    t.fail_key("center", "must lie on the axis (r = 0) in an axisymmetric scene, got r = " + fmt(in.center[0]));
  for (int i = 0; i < s.dim(); ++i) {
    const auto k = std::size_t(i);
    const char* ax = axis_name(s.axisymmetric(), s.dim(), i);
    const double lo = in.center[k] - in.semi_axes[k], hi = in.center[k] + in.semi_axes[k];
    const std::string key = in.shape == SceneInitial::Shape::sphere ? "radius" : "semi_axes";
    if (hi > s.domain.hi[k])
      t.fail_key(key, "puts the initial shape outside the domain: it reaches " + std::string(ax) + " = " + fmt(hi) +
                          " > upper bound " + fmt(s.domain.hi[k]));
    if (!(s.axisymmetric() && i == 0) && lo < s.domain.lo[k])
      t.fail_key(key, "puts the initial shape outside the domain: it reaches " + std::string(ax) + " = " + fmt(lo) +
                          " < lower bound " + fmt(s.domain.lo[k]));
  }
}

void read_model(const Section& root, Scene& s) {
  const Section t = root.table("model", {"form", "k", "eps", "C0", "boundary_phi"});
  SceneModel& m = s.model;
  const std::string expected = s.axisymmetric() ? "helfrich_axisymmetric" : "helfrich";
  m.form = expected;
  if (t.has("form")) {
    m.form = t.choice_of("form", t.string("form"), {"helfrich", "helfrich_axisymmetric"});
    if (m.form != expected)
      t.fail_key("form", "= '" + m.form + "' does not match scene.coordinates = '" + to_string(s.coordinates) +
                             "'; use '" + expected + "'");
  }
  m.k = t.positive("k", t.number("k", m.k));
  m.eps = t.positive("eps", t.number("eps"));
  m.C0 = t.number("C0", m.C0);
  m.boundary_phi = t.number("boundary_phi", m.boundary_phi);
  if (m.boundary_phi < -1 || m.boundary_phi > 1)
    t.fail_key("boundary_phi", "must lie in [-1, 1], got " + fmt(m.boundary_phi));
  // The first solve must be resolved by the grid when the scene describes it completely.
  if (const auto h = s.uniform_min_spacing()) {
    try {
      check_resolution(m.eps, *h, s.nodes.resolution_factor, "key 'model.eps'");
    } catch (const std::invalid_argument& e) {
      fail(t.context(), t.at("eps"), std::string(e.what()) + " (the uniform grid of [nodes]; lower " +
                                         "nodes.spacing or raise model.eps)");
    }
  }
}

void read_constraints(const Section& root, Scene& s) {
  const auto t = root.optional_table("constraints", {"area", "volume", "moment"});
  if (!t) return;
  SceneConstraints& c = s.constraints;
  const int measure_dim = s.axisymmetric() ? 3 : s.dim();
  const double pi = std::numbers::pi;
  // Sphere (disc in 2D) of radius R: area 4 pi R^2 (2 pi R), volume 4/3 pi R^3 (pi R^2).
  auto sphere_area = [&](double r) { return measure_dim == 3 ? 4 * pi * r * r : 2 * pi * r; };
  auto sphere_volume = [&](double r) { return measure_dim == 3 ? 4.0 / 3.0 * pi * r * r * r : pi * r * r; };
  auto radius_of_area = [&](double a) { return measure_dim == 3 ? std::sqrt(a / (4 * pi)) : a / (2 * pi); };

  if (auto a = t->optional_table("area", {"target", "radius"})) {
    if (a->has("target") == a->has("radius"))
      fail(a->context(), t->at("area"),
           a->has("target") ? "keys 'constraints.area.target' and 'constraints.area.radius' exclude each other"
                            : "missing key in 'constraints.area': give 'target' (A0) or 'radius' (A0 = area of "
                              "the sphere of that radius)");
    c.area = a->has("target") ? a->positive("target", a->number("target"))
                              : sphere_area(a->positive("radius", a->number("radius")));
  }
  if (auto v = t->optional_table("volume", {"target", "reduced_volume", "radius"})) {
    if (v->has("target")) {
      if (v->has("reduced_volume") || v->has("radius"))
        v->fail_key(v->has("radius") ? "radius" : "reduced_volume",
                    "cannot be combined with 'constraints.volume.target'");
      c.volume = v->positive("target", v->number("target"));
    } else {
      if (!v->has("reduced_volume"))
        fail(v->context(), t->at("volume"),
             "missing key in 'constraints.volume': give 'target' (V0) or 'reduced_volume' (V0 = v times the "
             "volume of the sphere)");
      const double rv = v->positive("reduced_volume", v->number("reduced_volume"));
      if (rv > 1)
        v->fail_key("reduced_volume", "= " + fmt(rv) +
                                          " must not exceed 1: no closed surface encloses more volume than the "
                                          "sphere of the same area");
      double r = 0;
      if (v->has("radius")) {
        r = v->positive("radius", v->number("radius"));
      } else if (c.area) {
        r = radius_of_area(*c.area);
      } else {
        v->fail_key("reduced_volume",
                    "needs the sphere it refers to: add 'radius' to 'constraints.volume' or an area constraint");
      }
      c.volume = rv * sphere_volume(r);
    }
  }
  if (auto m = t->optional_table("moment", {"target", "z_center"})) {
    if (s.dim() != 2)
      fail(m->context(), t->at("moment"),
           "key 'constraints.moment': the static moment constraint is available in 2D and axisymmetric scenes only");
    SceneMoment mo;
    mo.target = m->number("target", 0.0);
    mo.z_center = m->number("z_center", s.initial.center[std::size_t(s.dim() - 1)]);
    c.moment = mo;
  }
  if (c.area && c.volume) {
    try {
      check_feasible(*c.area, *c.volume, measure_dim);
    } catch (const SceneError& e) {
      fail(t->context(), t->at("volume"), std::string("constraints: ") + e.what());
    }
    c.reduced_volume = *c.volume / max_volume_for_area(*c.area, measure_dim);
  }
}

void read_solver(const Section& root, Scene& s) {
  const auto t = root.optional_table(
      "solver", {"penalty", "augmented_tolerance", "inner_tolerance", "max_outer_iterations", "max_inner_iterations",
                 "newton_tolerance", "constraint_tolerance", "max_newton_iterations"});
  if (!t) return;
  SceneSolver& o = s.solver;
  o.penalty = t->positive("penalty", t->number("penalty", o.penalty));
  o.augmented_tolerance = t->positive("augmented_tolerance", t->number("augmented_tolerance", o.augmented_tolerance));
  o.inner_tolerance = t->positive("inner_tolerance", t->number("inner_tolerance", o.inner_tolerance));
  o.max_outer_iterations = t->at_least("max_outer_iterations", t->integer("max_outer_iterations", o.max_outer_iterations), 1);
  o.max_inner_iterations = t->at_least("max_inner_iterations", t->integer("max_inner_iterations", o.max_inner_iterations), 1);
  o.newton_tolerance = t->positive("newton_tolerance", t->number("newton_tolerance", o.newton_tolerance));
  o.constraint_tolerance =
      t->positive("constraint_tolerance", t->number("constraint_tolerance", o.constraint_tolerance));
  o.max_newton_iterations =
      t->at_least("max_newton_iterations", t->integer("max_newton_iterations", o.max_newton_iterations), 0);
}

void read_adaptivity(const Section& root, Scene& s) {
  const auto t = root.optional_table("adaptivity", {"stages", "lloyd_iterations", "start", "samples_per_node"});
  if (!t) return;
  const int lloyd = t->at_least("lloyd_iterations", t->integer("lloyd_iterations", 20), 1);
  SceneAdaptivity a;
  a.start_from_density = t->choice_of("start", t->optional_string("start").value_or("nodes"), {"nodes", "density"}) == "density";
  a.samples_per_node = t->positive("samples_per_node", t->number("samples_per_node", a.samples_per_node));
  if (a.samples_per_node < 1) t->fail_key("samples_per_node", "must be at least 1, got " + fmt(a.samples_per_node));
  const toml::node& n = t->require("stages");
  const auto* arr = n.as_array();
  if (arr == nullptr) t->wrong_type("stages", n, "an array of tables");
  if (arr->empty()) t->fail_key("stages", "must list at least one stage (or leave out [adaptivity])");
  double previous = s.model.eps, main_eps = s.model.eps;
  for (std::size_t i = 0; i < arr->size(); ++i) {
    const std::string key = "stages[" + std::to_string(i) + "]";
    const Section st = t->table_of(key, (*arr)[i], {"eps", "f", "lloyd_iterations", "branch"});
    AdaptivityStage stage;
    stage.eps = st.positive("eps", st.number("eps"));
    // lloyd_iterations = 0: no relocation, the stage only lowers eps (f may then be left out).
    stage.lloyd_iterations = st.at_least("lloyd_iterations", st.integer("lloyd_iterations", lloyd), 0);
    stage.f = stage.lloyd_iterations == 0 && !st.has("f") ? 0.0 : st.non_negative("f", st.number("f"));
    stage.branch = st.boolean("branch", false);
    // Each stage lowers eps from the stage it continues from: the previous one, or for a stage
    // after a branch that is not one itself, the last stage that is not a branch.
    const bool after_branch = !a.stages.empty() && a.stages.back().branch;
    const double from = after_branch && !stage.branch ? main_eps : previous;
    if (stage.eps > from)
      st.fail_key("eps", "= " + fmt(stage.eps) + " exceeds the previous eps (" + fmt(from) +
                             (i == 0 ? ", model.eps" : "") + "): the schedule lowers eps");
    previous = stage.eps;
    if (!stage.branch) main_eps = stage.eps;
    a.stages.push_back(stage);
  }
  s.adaptivity = std::move(a);
}

void read_reference(const Section& root, Scene& s) {
  const auto t = root.optional_table("reference", {"energy"});
  if (!t) return;
  s.reference_energy = t->number("energy");
}

void read_output(const Section& root, Scene& s) {
  const auto t = root.optional_table("output", {"directory", "hdf5", "png"});
  if (!t) return;
  SceneOutput o;
  o.directory = t->string("directory");
  o.hdf5 = t->boolean("hdf5", o.hdf5);
  o.png = t->boolean("png", o.png);
  s.output = std::move(o);
}

}  // namespace

const char* to_string(Coordinates c) noexcept {
  return c == Coordinates::axisymmetric ? "axisymmetric" : "cartesian";
}

double Scene::final_eps() const noexcept {
  if (adaptivity && !adaptivity->stages.empty()) return adaptivity->stages.back().eps;
  return model.eps;
}

std::optional<double> Scene::uniform_min_spacing() const {
  if (nodes.kind == SceneNodes::Kind::file || nodes.kind == SceneNodes::Kind::count) return std::nullopt;
  double h = std::numeric_limits<double>::infinity();
  for (int i = 0; i < dim(); ++i) {
    const auto k = std::size_t(i);
    const double len = domain.hi[k] - domain.lo[k];
    // Same count as uniform_grid(box, spacing): round(L / spacing) + 1 nodes, at least 2.
    const double intervals = nodes.kind == SceneNodes::Kind::counts
                                 ? double(nodes.counts[k] - 1)
                                 : std::max(1.0, std::round(len / nodes.spacing));
    h = std::min(h, len / intervals);
  }
  return h;
}

double Scene::initial_distance(std::span<const double> x) const {
  const auto d = std::size_t(dim());
  return ellipsoid_signed_distance(x.first(d), std::span<const double>(initial.center).first(d),
                                   std::span<const double>(initial.semi_axes).first(d));
}

double Scene::initial_phi(std::span<const double> x) const {
  const double eps = initial.eps.value_or(model.eps);
  return std::tanh(initial_distance(x) / (std::numbers::sqrt2 * eps));
}

Scene parse_scene(std::string_view text, std::string source_name) {
  const Context ctx{source_name};
  toml::table root_table;
  try {
    root_table = toml::parse(text, source_name);
  } catch (const toml::parse_error& e) {
    const auto& b = e.source().begin;
    throw SceneError(source_name + ":" + std::to_string(b.line) + ":" + std::to_string(b.column) +
                     ": TOML syntax error: " + std::string(e.description()));
  }
  const Section root(ctx, root_table, "",
                     {"scene", "domain", "nodes", "initial", "model", "constraints", "solver", "adaptivity",
                      "reference", "output"});
  Scene s;
  s.source = source_name;
  const std::filesystem::path folder = std::filesystem::path(source_name).parent_path();
  read_scene_section(root, s);
  read_domain(root, s);
  read_nodes(root, folder, s);
  read_initial(root, s);
  read_model(root, s);
  read_constraints(root, s);
  read_solver(root, s);
  read_adaptivity(root, s);
  read_reference(root, s);
  read_output(root, s);

  return s;
}

Scene load_scene(const std::filesystem::path& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) throw SceneError(path.string() + ": cannot open the scene file");
  std::ostringstream text;
  text << in.rdbuf();
  return parse_scene(text.str(), path.string());
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
  if (!(A0 > 0)) throw SceneError(std::string(area) + " A0 = " + fmt(A0) + " must be positive");
  if (!(V0 > 0)) throw SceneError(std::string(volume) + " V0 = " + fmt(V0) + " must be positive");
  const double vmax = max_volume_for_area(A0, dim);
  if (V0 > vmax * (1 + 1e-12))
    throw SceneError("infeasible targets: " + std::string(volume) + " V0 = " + fmt(V0) + " exceeds V_max = " +
                     fmt(vmax) + ", the " + volume + " of the " + sphere + " with " + area + " A0 = " + fmt(A0) +
                     " (reduced volume " + fmt(V0 / vmax) + " > 1)");
}

double ellipsoid_signed_distance(std::span<const double> x, std::span<const double> center,
                                 std::span<const double> semi_axes) {
  const std::size_t n = x.size();
  if (n == 0 || n > 3 || center.size() != n || semi_axes.size() != n)
    throw std::invalid_argument("ellipsoid_signed_distance: dimension mismatch");
  std::array<double, 3> y{}, e{};
  double inside = 0, emin = std::numeric_limits<double>::infinity(), emax = 0, ynorm2 = 0;
  for (std::size_t i = 0; i < n; ++i) {
    y[i] = std::abs(x[i] - center[i]);
    e[i] = semi_axes[i];
    inside += (y[i] / e[i]) * (y[i] / e[i]);
    emin = std::min(emin, e[i]);
    emax = std::max(emax, e[i]);
    ynorm2 += y[i] * y[i];
  }
  // Closest point p_i = e_i^2 y_i / (t + e_i^2) with F(t) = sum (e_i y_i / (t + e_i^2))^2 - 1 = 0 on
  // t > -emin^2, where F decreases; F(emax |y|) <= 0.
  auto F = [&](double t) {
    double s = -1;
    for (std::size_t i = 0; i < n; ++i) {
      if (y[i] == 0) continue;  // also at the pole t = -e_i^2 of a shortest axis
      const double q = e[i] * y[i] / (t + e[i] * e[i]);
      s += q * q;
    }
    return s;
  };
  const double t_lo = -emin * emin;
  std::array<double, 3> p{};
  double lo_value = 0;
  bool lo_finite = true;
  for (std::size_t i = 0; i < n; ++i)
    if (e[i] == emin && y[i] > 0) lo_finite = false;
  if (lo_finite) lo_value = F(t_lo);
  if (lo_finite && lo_value <= 0) {
    // Degenerate: the point lies on the plane of a shortest axis, deep inside; t = -emin^2.
    double rest = 1;
    std::size_t kmin = n;
    for (std::size_t i = 0; i < n; ++i) {
      if (e[i] > emin) {
        p[i] = e[i] * e[i] * y[i] / (e[i] * e[i] - emin * emin);
        rest -= (p[i] / e[i]) * (p[i] / e[i]);
      } else if (kmin == n) {
        kmin = i;
      } else {
        p[i] = 0;
      }
    }
    p[kmin] = emin * std::sqrt(std::max(0.0, rest));
  } else {
    double a = t_lo, b = std::max(emax * std::sqrt(ynorm2), 0.0);
    for (int it = 0; it < 200 && b - a > 0; ++it) {
      const double m = 0.5 * (a + b);
      if (m <= a || m >= b) break;
      (F(m) > 0 ? a : b) = m;
    }
    const double t = 0.5 * (a + b);
    for (std::size_t i = 0; i < n; ++i) p[i] = e[i] * e[i] * y[i] / (t + e[i] * e[i]);
  }
  double d2 = 0;
  for (std::size_t i = 0; i < n; ++i) d2 += (p[i] - y[i]) * (p[i] - y[i]);
  const double d = std::sqrt(d2);
  return inside < 1 ? d : -d;
}

}  // namespace lmeform
