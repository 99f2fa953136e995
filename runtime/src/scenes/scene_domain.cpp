// [domain] and the node refinements of [nodes]: the box, convex polygon or convex polyhedron of a
// scene with its named boundary parts (domain.hpp), and where generated nodes are graded finer.
#include "scene_domain.hpp"

#include <algorithm>
#include <cctype>
#include <stdexcept>

#include "lmeform/scene_table.hpp"

namespace lmeform::scene_detail {

namespace {

/// Part names are what forms write in ds(NAME): identifiers, or "" for an unnamed face.
void check_part_names(const SceneTable& t, const std::string& key, const std::vector<std::string>& parts) {
  for (std::size_t i = 0; i < parts.size(); ++i) {
    const std::string& p = parts[i];
    const bool identifier = !p.empty() && (std::isalpha(static_cast<unsigned char>(p[0])) != 0 || p[0] == '_') &&
                            std::all_of(p.begin(), p.end(), [](char c) { return std::isalnum(static_cast<unsigned char>(c)) != 0 || c == '_'; });
    if (!p.empty() && !identifier)
      t.fail_key(key, "has '" + p + "' at " + std::to_string(i) + ": a part name is an identifier (what a form writes in ds(" + p +
                          ")), or \"\" for an unnamed face");
    if (p == "hull" || p == "axis")
      t.fail_key(key, "has '" + p + "' at " + std::to_string(i) + ": '" + p + "' is a reserved part name (" +
                          (p == "hull" ? "the whole boundary" : "the axis of an axisymmetric scene") + ")");
  }
}

std::vector<std::string> strings_of(const SceneTable& t, const std::string& key) {
  const toml::node& n = t.require(key);
  const auto* a = n.as_array();
  if (a == nullptr) t.wrong_type(key, n, "an array of part names");
  std::vector<std::string> out;
  for (std::size_t i = 0; i < a->size(); ++i) out.push_back(t.string_of(key + "[" + std::to_string(i) + "]", (*a)[i]));
  return out;
}

/// An array of points of `dim` coordinates.
std::vector<std::array<double, 3>> points_of(const SceneTable& t, const std::string& key, const toml::node& n, int dim) {
  const auto* a = n.as_array();
  if (a == nullptr) t.wrong_type(key, n, "an array of points");
  std::vector<std::array<double, 3>> out;
  for (std::size_t i = 0; i < a->size(); ++i) {
    const std::string item = key + "[" + std::to_string(i) + "]";
    const auto* p = (*a)[i].as_array();
    if (p == nullptr || static_cast<int>(p->size()) != dim)
      t.fail_key(key, "must hold points of " + std::to_string(dim) + " coordinates; entry " + std::to_string(i) + " is not one");
    std::array<double, 3> x{};
    for (std::size_t k = 0; k < p->size(); ++k) x[k] = t.number_of(item + "[" + std::to_string(k) + "]", (*p)[k]);
    out.push_back(x);
  }
  return out;
}

void read_polygon(const SceneTable& t, Scene& s) {
  const auto vertices3 = points_of(t, "polygon", t.require("polygon"), 2);
  std::vector<std::array<double, 2>> vertices;
  for (const auto& v : vertices3) vertices.push_back({v[0], v[1]});
  std::vector<std::string> parts;
  if (t.has("parts")) {
    parts = strings_of(t, "parts");
    check_part_names(t, "parts", parts);
  }
  try {
    s.geometry = Domain::polygon(vertices, parts);
  } catch (const std::invalid_argument& e) {
    t.fail_key(parts.size() != vertices.size() && !parts.empty() ? "parts" : "polygon", std::string("does not give a domain: ") + e.what());
  }
  if (s.axisymmetric())
    for (const auto& v : vertices)
      if (v[0] < 0) t.fail_key("polygon", "has a vertex at r = " + format_number(v[0]) + " < 0 in an axisymmetric scene");
}

void read_polyhedron(const SceneTable& root, Scene& s) {
  const SceneTable t = root.table("polyhedron", {"vertices", "faces", "parts"});
  const auto vertices = points_of(t, "vertices", t.require("vertices"), 3);
  const toml::node& fn = t.require("faces");
  const auto* fa = fn.as_array();
  if (fa == nullptr) t.wrong_type("faces", fn, "an array of faces (arrays of vertex indices)");
  std::vector<std::vector<int>> faces;
  for (std::size_t i = 0; i < fa->size(); ++i) {
    const auto* f = (*fa)[i].as_array();
    if (f == nullptr) t.fail_key("faces", "entry " + std::to_string(i) + " is not an array of vertex indices");
    std::vector<int> loop;
    for (std::size_t k = 0; k < f->size(); ++k) loop.push_back(t.integer_of("faces[" + std::to_string(i) + "][" + std::to_string(k) + "]", (*f)[k]));
    faces.push_back(std::move(loop));
  }
  std::vector<std::string> parts;
  if (t.has("parts")) {
    parts = strings_of(t, "parts");
    check_part_names(t, "parts", parts);
  }
  try {
    s.geometry = Domain::polyhedron(vertices, faces, parts);
  } catch (const std::invalid_argument& e) {
    t.fail_key("faces", std::string("do not give a domain: ") + e.what());
  }
}

// Not inlined: GCC 12 reports a false -Wrestrict in SceneTable::where's concatenations when it is.
[[gnu::noinline]] std::string where_of(const SceneTable& t, std::string_view key) { return t.where(key); }

void read_box(const SceneTable& t, Scene& s) {
  static const char* cartesian[3] = {"x", "y", "z"};
  const int count = s.axisymmetric() ? 2 : 0;
  const std::vector<double> lo = t.numbers("lower", count);
  const std::vector<double> hi = t.numbers("upper", static_cast<int>(lo.size()));
  s.domain.dim = static_cast<int>(lo.size());
  for (int i = 0; i < s.domain.dim; ++i) {
    const auto k = static_cast<std::size_t>(i);
    if (!(lo[k] < hi[k]))
      t.fail_key("upper", "must exceed 'domain.lower' on every axis: axis " + std::string(s.axisymmetric() ? (i == 0 ? "r" : "z") : cartesian[i]) +
                              " has lower " + format_number(lo[k]) + ", upper " + format_number(hi[k]));
    s.domain.lo[k] = lo[k];
    s.domain.hi[k] = hi[k];
  }
  if (s.axisymmetric() && lo[0] < 0)
    t.fail_key("lower", "must have r >= 0 in an axisymmetric scene (r is the distance to the axis), got r = " + format_number(lo[0]));
}

/// The sides of the box that are planes of symmetry (box face names and their axisymmetric aliases,
/// as the box's Domain names them).
void read_mirrors(const SceneTable& t, Scene& s) {
  s.mirror_where = t.where("mirror");
  for (const std::string& name : strings_of(t, "mirror")) {
    const std::vector<int> faces = name.empty() || name == "hull" ? std::vector<int>{} : s.geometry.faces_of(name);
    if (faces.size() != 1) t.fail_key("mirror", "names '" + name + "', no side of the box (x_min, x_max, y_min, ...)");
    const DomainFace& face = s.geometry.faces()[std::size_t(faces[0])];
    const auto along = std::find_if(face.normal.begin(), face.normal.end(), [](double n) { return n != 0.0; });
    const int axis = int(along - face.normal.begin());
    if (s.axisymmetric() && axis == 0)
      t.fail_key("mirror", "names '" + name + "': in an axisymmetric scene only z_min or z_max can be a plane of symmetry (the axis is one already)");
    for (const MirrorPlane& m : s.mirrors)
      if (m.axis == axis) t.fail_key("mirror", "names two sides on axis " + std::to_string(axis) + ": a box has one plane of symmetry per axis here");
    s.mirrors.push_back({axis, *along * face.offset});  // the face is normal · x = offset, normal = ±e_axis
  }
}

}  // namespace

void read_domain(const SceneTable& root, Scene& s) {
  const SceneTable t = root.table("domain", {"lower", "upper", "polygon", "polyhedron", "parts", "mirror"});
  if (t.has("mirror") && !(t.has("lower") || t.has("upper"))) t.fail_key("mirror", "names sides of a box: give [domain] lower and upper");
  const int shapes = int(t.has("lower") || t.has("upper")) + int(t.has("polygon")) + int(t.has("polyhedron"));
  if (shapes == 0) t.fail_key("lower", "is missing: [domain] is a box (lower, upper), a 'polygon' or a 'polyhedron'");
  if (shapes > 1) t.fail_key(t.has("polygon") ? "polygon" : "polyhedron", "cannot be combined with another shape: [domain] is a box, a polygon or a polyhedron");
  if (t.has("polygon")) {
    read_polygon(t, s);
  } else if (t.has("polyhedron")) {
    if (s.axisymmetric()) t.fail_key("polyhedron", "is 3D; an axisymmetric scene is 2D (r, z)");
    read_polyhedron(t, s);
  } else {
    if (t.has("parts")) t.fail_key("parts", "names the faces of a polygon or polyhedron; a box's sides are x_min, x_max, ...");
    read_box(t, s);
    s.geometry = Domain::box(s.domain, s.axisymmetric());
    if (t.has("mirror")) read_mirrors(t, s);
    return;
  }
  s.domain = s.geometry.bounds();
}

std::vector<SceneRefinement> read_refinements(const SceneTable& nodes, const Scene& s) {
  std::vector<SceneRefinement> out;
  const toml::node* n = nodes.node("refine");
  if (n == nullptr) return out;
  const auto* a = n->as_array();
  if (a == nullptr) nodes.wrong_type("refine", *n, "an array of tables {part or path, spacing, width, grading}");
  for (std::size_t i = 0; i < a->size(); ++i) {
    const std::string key = "refine[" + std::to_string(i) + "]";
    const SceneTable t = nodes.table_of(key, (*a)[i], {"part", "path", "spacing", "width", "grading"});
    SceneRefinement r;
    r.where = where_of(t, "spacing");
    if (t.has("part") == t.has("path")) t.fail_key("part", "or 'path' (one of them): the boundary part or the polyline to refine near");
    if (t.has("part")) {
      r.part = t.string("part");
      if (!s.geometry.has_part(r.part)) {
        const auto names = s.geometry.part_names();
        t.fail_key("part", "names '" + r.part + "', no boundary part of the domain" +
                               (closest_name(r.part, names).empty() ? "" : "; did you mean '" + closest_name(r.part, names) + "'?"));
      }
    } else {
      r.path = points_of(t, "path", t.require("path"), s.dim());
      if (r.path.empty()) t.fail_key("path", "is empty: give at least one point");
    }
    r.spacing = t.positive("spacing", t.number("spacing"));
    r.width = t.non_negative("width", t.number("width", 0.0));
    r.grading = t.positive("grading", t.number("grading", r.grading));
    out.push_back(std::move(r));
  }
  return out;
}

SceneAdaptation read_adaptation(const SceneTable& nodes) {
  const SceneTable t = nodes.table_of("adapt", *nodes.node("adapt"), {"field", "below", "spacing", "width", "grading", "fit_iterations"});
  SceneAdaptation a;
  a.where = where_of(nodes, "adapt");
  a.field = t.string("field");
  a.below = t.number("below", a.below);
  a.spacing = t.positive("spacing", t.number("spacing"));
  a.width = t.non_negative("width", t.number("width", 0.0));
  a.grading = t.positive("grading", t.number("grading", a.grading));
  a.fit_iterations = t.at_least("fit_iterations", t.integer("fit_iterations", a.fit_iterations), 0);
  return a;
}

void read_quantities(const SceneTable& root, Scene& s) {
  const auto table = root.optional_any_table("quantities");
  if (!table) return;
  for (const auto& [name, node] : in_file_order(table->entries())) {
    const SceneTable t = table->table_of(name, *node, {"reaction", "unknown", "probe", "field", "component", "integral", "part", "constant", "energy"});
    SceneQuantity q;
    q.name = name;
    q.where = where_of(*table, name);
    const int kinds = int(t.has("reaction")) + int(t.has("probe")) + int(t.has("integral")) + int(t.has("constant")) + int(t.has("energy"));
    if (kinds != 1)
      table->fail_key(name, "must be one of { reaction = PART, unknown }, { probe = POINT, field }, { integral = EXPRESSION }, "
                            "{ constant = NAME }, { energy = OUTPUT }");
    if (t.has("reaction")) {
      q.kind = SceneQuantity::Kind::reaction;
      q.part = t.string("reaction");
      q.field = t.string("unknown");
      const bool dirichlet = std::any_of(s.dirichlet.begin(), s.dirichlet.end(), [&](const SceneDirichlet& d) {
        return d.unknown == q.field && std::find(d.boundary.begin(), d.boundary.end(), q.part) != d.boundary.end();
      });
      if (!dirichlet)
        t.fail_key("reaction", "names '" + q.part + "', on which no [[dirichlet]] entry fixes '" + q.field +
                                   "': a reaction is the force where the unknown is prescribed");
    } else if (t.has("probe")) {
      q.kind = SceneQuantity::Kind::probe;
      const std::vector<double> x = t.numbers("probe", s.dim());
      for (std::size_t i = 0; i < x.size(); ++i) q.point[i] = x[i];
      if (!s.geometry.contains(std::span<const double>(q.point.data(), std::size_t(s.dim())), 1e-9 * s.geometry.diameter()))
        t.fail_key("probe", "lies outside the domain");
      q.field = t.string("field");
    } else if (t.has("integral")) {
      q.kind = SceneQuantity::Kind::integral;
      q.expression = t.string("integral");
      if (t.has("part")) {
        q.part = t.string("part");
        if (!s.geometry.has_part(q.part)) t.fail_key("part", "names '" + q.part + "', no boundary part of the domain");
      }
    } else if (t.has("energy")) {
      q.kind = SceneQuantity::Kind::energy;
      q.output = t.string("energy");
    } else {
      q.kind = SceneQuantity::Kind::constant;
      q.constant = t.string("constant");
    }
    if (t.has("component")) {
      if (q.kind != SceneQuantity::Kind::probe && q.kind != SceneQuantity::Kind::reaction)
        t.fail_key("component", "selects a component of a probe or a reaction");
      q.component = t.integer_of("component", t.require("component"));
      if (q.component < 0 || q.component >= s.dim()) t.fail_key("component", "must lie in 0.." + std::to_string(s.dim() - 1));
    }
    for (const char* k : {"unknown", "field", "part"})
      if (t.has(k) && ((std::string(k) == "unknown" && q.kind != SceneQuantity::Kind::reaction) ||
                       (std::string(k) == "field" && q.kind != SceneQuantity::Kind::probe) ||
                       (std::string(k) == "part" && q.kind != SceneQuantity::Kind::integral)))
        t.fail_key(k, "does not belong to this kind of quantity");
    s.quantities.push_back(std::move(q));
  }
}

void read_bounds(const SceneTable& root, Scene& s) {
  const auto table = root.optional_any_table("bounds");
  if (!table) return;
  for (const auto& [name, node] : in_file_order(table->entries())) {
    const SceneTable t = table->table_of(name, *node, {"lower", "upper"});
    SceneBound b;
    b.unknown = name;
    b.where = where_of(*table, name);
    if (!t.has("lower") && !t.has("upper")) table->fail_key(name, "gives neither 'lower' nor 'upper'");
    for (const char* side : {"lower", "upper"}) {
      if (!t.has(side)) continue;
      SceneValue v = value_of(t, side, t.require(side));
      const bool previous = !v.is_number() && v.expression() == "previous";
      (std::string(side) == "lower" ? b.lower_previous : b.upper_previous) = previous;
      if (!previous) (std::string(side) == "lower" ? b.lower : b.upper) = std::move(v);
    }
    if (b.lower && b.upper && b.lower->is_number() && b.upper->is_number() && b.lower->number() > b.upper->number())
      t.fail_key("lower", "= " + format_number(b.lower->number()) + " lies above upper = " + format_number(b.upper->number()));
    if (b.lower_previous && b.upper_previous) t.fail_key("upper", "and 'lower' cannot both be \"previous\": the unknown would not move");
    s.bounds.push_back(std::move(b));
  }
}

}  // namespace lmeform::scene_detail
