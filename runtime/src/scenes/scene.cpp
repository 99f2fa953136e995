// Scene files: strict TOML reading (every key known, typed and range-checked). Names that refer to
// the forms are checked by app::bind_scene once the forms are loaded.
#include "lmeform/scene.hpp"

#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstdint>
#include <fstream>
#include <limits>
#include <sstream>

#include "lmeform/lme_basis.hpp"
#include "lmeform/quadrature.hpp"
#include "lmeform/scene_table.hpp"
#include "scene_domain.hpp"

namespace lmeform {
namespace {

using Section = SceneTable;
using scene_detail::Context;
using scene_detail::fail;
using scene_detail::format_number;
using scene_detail::read_domain;
using scene_detail::in_file_order;
using scene_detail::value_of;

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


void read_nodes(const Section& root, const std::filesystem::path& folder, Scene& s) {
  const Section t = root.table("nodes", {"spacing", "counts", "count", "lloyd_iterations", "file", "gamma", "spacing_smoothing",
                                         "quadrature_points", "refine", "adapt", "boundary_points", "integration", "basis", "partition", "support_tolerance", "sampling"});
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
  // A uniform grid's node count: node indices are 32-bit integers.
  auto check_grid_size = [&](const char* key, const std::array<double, 3>& per_axis) {
    double total = 1;
    for (int i = 0; i < s.dim(); ++i) total *= per_axis[std::size_t(i)];
    if (total > kLargestNodeCount)
      t.fail_key(key, "gives a grid of " + format_number(total) + " nodes, more than node indices (32-bit integers) can number (" +
                          format_number(kLargestNodeCount) + "): give fewer nodes");
  };
  if (t.has("spacing")) {
    n.kind = SceneNodes::Kind::spacing;
    n.spacing = t.positive("spacing", t.number("spacing"));
    if (n.spacing > extent)
      t.fail_key("spacing", "= " + format_number(n.spacing) + " exceeds the smallest extent of the domain (" + format_number(extent) +
                                ")");
    std::array<double, 3> per_axis{1, 1, 1};
    for (int i = 0; i < s.dim(); ++i) {
      const auto k = std::size_t(i);
      // uniform_grid's own limit: round(L / spacing) intervals per axis, at most kLargestGridIntervals.
      const double intervals = std::round((s.domain.hi[k] - s.domain.lo[k]) / n.spacing);
      if (intervals > kLargestGridIntervals)
        t.fail_key("spacing", "= " + format_number(n.spacing) + " gives " + format_number(intervals) + " intervals on axis " +
                                  axis_name(s.axisymmetric(), s.dim(), i) + ", more than the " + format_number(kLargestGridIntervals) +
                                  " a uniform grid takes per axis: give a larger spacing");
      per_axis[k] = std::max(1.0, intervals) + 1;
    }
    check_grid_size("spacing", per_axis);
  } else if (t.has("counts")) {
    if (!s.geometry.is_box()) t.fail_key("counts", "makes a grid of a box; a polygon or polyhedron takes 'nodes.spacing' or 'nodes.file'");
    n.kind = SceneNodes::Kind::counts;
    const std::vector<int> c = t.integers("counts", s.dim());
    std::array<double, 3> per_axis{1, 1, 1};
    for (std::size_t i = 0; i < c.size(); ++i) {
      if (c[i] < 2)
        t.fail_key("counts", "must have at least 2 nodes per axis, got " + std::to_string(c[i]) + " on axis " +
                                 axis_name(s.axisymmetric(), s.dim(), int(i)));
      n.counts[i] = c[i];
      per_axis[i] = c[i];
    }
    check_grid_size("counts", per_axis);
  } else if (t.has("count")) {
    n.kind = SceneNodes::Kind::count;
    if (!s.geometry.is_box()) t.fail_key("count", "places a CVT in a box; a polygon or polyhedron takes 'nodes.spacing' or 'nodes.file'");
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
  if (t.has("refine")) {
    if (n.kind != SceneNodes::Kind::spacing) t.fail_key("refine", "grades the nodes generated for 'nodes.spacing'");
    n.refine = scene_detail::read_refinements(t, s);
    for (const auto& r : n.refine)
      if (r.spacing > n.spacing) t.fail_key("refine", "asks for a spacing " + format_number(r.spacing) + " coarser than nodes.spacing = " + format_number(n.spacing));
  }
  if (t.has("sampling")) {
    if (n.kind != SceneNodes::Kind::spacing) t.fail_key("sampling", "chooses how the nodes for 'nodes.spacing' are generated");
    if (t.choice_of("sampling", t.string("sampling"), {"poisson", "grids"}) == "grids") {
      if (!s.geometry.is_box())
        t.fail_key("sampling", "= \"grids\" nests uniform grids in a box; a polygon or polyhedron is sampled by \"poisson\"");
      if (s.dim() == 1) t.fail_key("sampling", "= \"grids\" is for 2D and 3D boxes; a 1D bar's nodes are a uniform grid or a file");
      n.sampling = SceneNodes::Sampling::nested_grids;
    }
  }
  if (t.has("adapt")) {
    if (n.kind != SceneNodes::Kind::spacing) t.fail_key("adapt", "refines the nodes generated for 'nodes.spacing'");
    n.adapt = scene_detail::read_adaptation(t);
    if (n.adapt->spacing > n.spacing)
      t.fail_key("adapt", "asks for a spacing " + format_number(n.adapt->spacing) + " coarser than nodes.spacing = " + format_number(n.spacing));
  }
  n.gamma = t.positive("gamma", t.number("gamma", n.gamma));
  // The LME support radius is h sqrt(-ln(tol0) / gamma): above -ln(tol0) it is shorter than the
  // nodal spacing h, and a node sees no other node (gamma = 20 on the Poisson demo's grid failed
  // its first LME evaluation with 1 neighbour; 50 and 1e100 did not converge).
  n.support_tolerance = t.number("support_tolerance", n.support_tolerance);
  if (!(n.support_tolerance >= 1e-12 && n.support_tolerance <= 1e-2))
    t.fail_key("support_tolerance", "= " + format_number(n.support_tolerance) +
                                        " must lie in [1e-12, 1e-2]: above, the support cuts weights the basis needs (the list holds only the "
                                        "nearest ring); below, the lists grow without changing the basis");
  const double largest_gamma = -std::log(n.support_tolerance);
  if (n.gamma > largest_gamma)
    t.fail_key("gamma", "= " + format_number(n.gamma) + " makes the LME support (radius h sqrt(" + format_number(largest_gamma) +
                            " / gamma)) shorter than the nodal spacing h: give at most " + format_number(largest_gamma) +
                            " (0.5 to 4 are usual)");
  n.basis = t.choice_of("basis", t.optional_string("basis").value_or("first"), {"first", "second"}) == "second"
                ? LmeConsistency::second
                : LmeConsistency::first;
  if (n.basis == LmeConsistency::second && n.gamma > lme_second_order_max_gamma)
    t.fail_key("gamma", "= " + format_number(n.gamma) + " is too large for nodes.basis = \"second\": its nodal gap h^2 / (2 gamma) must be " +
                            "wider than the holes between nodes; give at most " + format_number(lme_second_order_max_gamma) +
                            " (0.5 to 0.8 are usual), or the first-order basis");
  const std::string partition = t.choice_of("partition", t.optional_string("partition").value_or("metis"), {"metis", "hilbert", "block"});
  n.partition = partition == "hilbert" ? PartitionMethod::Hilbert : partition == "block" ? PartitionMethod::Block : PartitionMethod::Metis;
  n.spacing_smoothing = t.at_least("spacing_smoothing", t.integer("spacing_smoothing", n.spacing_smoothing), 0);
  // Default: a positive rule of degree 4 in 2D (6 points), degree 5 in 3D (14 points).
  // 1D: Gauss-Legendre points per segment between nodes (4: exact to degree 7).
  n.quadrature_points = t.integer("quadrature_points", s.dim() == 3 ? 14 : s.dim() == 1 ? 4 : n.quadrature_points);
  n.boundary_points = t.integer("boundary_points", s.dim() == 3 ? 6 : n.boundary_points);
  if (s.dim() == 1) {
    if (n.quadrature_points < 1 || n.quadrature_points > 10)
      t.fail_key("quadrature_points", "= " + std::to_string(n.quadrature_points) + " must lie in 1..10 (Gauss-Legendre points per segment in 1D)");
    const std::string integration = t.choice_of("integration", t.optional_string("integration").value_or("gauss"), {"gauss", "consistent"});
    if (integration == "consistent")
      t.fail_key("integration", "= \"consistent\" corrects gradients against the facets of 2D or 3D cells; a 1D scene integrates with "
                                "Gauss-Legendre points per segment (nodes.quadrature_points)");
    return;
  }
  if (s.dim() == 2 ? (n.boundary_points < 1 || n.boundary_points > 10)
                   : std::find(triangle_rule_sizes().begin(), triangle_rule_sizes().end(), n.boundary_points) == triangle_rule_sizes().end())
    t.fail_key("boundary_points", "= " + std::to_string(n.boundary_points) + (s.dim() == 2 ? " must lie in 1..10 (Gauss-Legendre points per boundary segment)"
                                                                                    : " is not a triangle rule (per boundary triangle)"));
  const std::string integration = t.choice_of("integration", t.optional_string("integration").value_or("gauss"), {"gauss", "consistent"});
  n.consistent_integration = integration == "consistent";
  const std::vector<int> sizes = s.dim() == 2 ? triangle_rule_sizes() : tetrahedron_rule_sizes();
  if (std::find(sizes.begin(), sizes.end(), n.quadrature_points) == sizes.end()) {
    std::string list;
    for (int k : sizes) list += (list.empty() ? "" : ", ") + std::to_string(k);
    t.fail_key("quadrature_points", "= " + std::to_string(n.quadrature_points) + " is not a " +
                                        (s.dim() == 2 ? "triangle" : "tetrahedron") + " rule; available: " + list);
  }
}

/// A number, or a string holding an expression of the coordinates.

SceneName name_of(const Section& t, std::string_view key, const toml::node& n) {
  return {t.string_of(key, n), t.where(key)};
}

/// A string or an array of strings.
std::vector<SceneName> names_of(const Section& t, std::string_view key) {
  const toml::node& n = t.require(key);
  if (n.is_string()) return {name_of(t, key, n)};
  const auto* a = n.as_array();
  if (a == nullptr) t.wrong_type(key, n, "a string or an array of strings");
  if (a->empty()) t.fail_key(key, "must name at least one entry");
  std::vector<SceneName> out;
  for (std::size_t i = 0; i < a->size(); ++i) {
    const std::string k = std::string(key) + "[" + std::to_string(i) + "]";
    SceneName name{t.string_of(k, (*a)[i]), t.where(key)};
    name.where = name.where.substr(0, name.where.rfind("key '")) + "key '" + t.key_path(k) + "'";
    out.push_back(std::move(name));
  }
  return out;
}

void read_model(const Section& root, Scene& s) {
  const Section t = root.table("model", {"forms", "energy", "residual", "bilinear", "linear", "zero_mean", "maximize"});
  SceneModel& m = s.model;
  m.forms = names_of(t, "forms");
  for (auto& f : m.forms) {
    // A path (with a '/' or ending in .form) is relative to the scene's folder; a bare name is a built-in module.
    const bool is_path = f.name.find('/') != std::string::npos || f.name.ends_with(".form");
    if (is_path && std::filesystem::path(f.name).is_relative()) f.name = (s.folder / f.name).lexically_normal().string();
  }
  const bool energy = t.has("energy"), residual = t.has("residual"), bilinear = t.has("bilinear"), linear = t.has("linear");
  if (residual && (energy || bilinear || linear))
    t.fail_key("residual", "cannot be combined with 'model.energy', 'model.bilinear' or 'model.linear': a scene solves one problem");
  if ((bilinear || linear) && energy)
    t.fail_key(bilinear ? "bilinear" : "linear", "cannot be combined with 'model.energy': a scene solves one problem");
  if (bilinear != linear)
    t.fail_key(bilinear ? "bilinear" : "linear", std::string("needs 'model.") + (bilinear ? "linear" : "bilinear") +
                                                     "' too: a linear problem is a(u, v) = l(v)");
  if (residual) {
    m.residual = name_of(t, "residual", t.require("residual"));
  } else if (bilinear) {
    m.bilinear = name_of(t, "bilinear", t.require("bilinear"));
    m.linear = name_of(t, "linear", t.require("linear"));
  } else if (energy) {
    m.energy = names_of(t, "energy");
  }
  if (t.has("maximize")) {
    if (residual || bilinear)
      t.fail_key("maximize", "belongs to an energy problem (a saddle point of model.energy); a residual or linear problem has no energy to "
                             "maximize");
    m.maximize = names_of(t, "maximize");
  }
  if (t.has("zero_mean")) {
    if (!bilinear && m.maximize.empty())
      t.fail_key("zero_mean", "is supported for linear problems (model.bilinear + model.linear) and saddle points (model.maximize) only");
    m.zero_mean = names_of(t, "zero_mean");
  }
}

void read_constants(const Section& root, Scene& s) {
  const auto t = root.optional_any_table("constants");
  if (!t) return;
  for (const auto& [key, node] : t->entries()) {
    const std::string name(key.str());
    s.constants[name] = t->number_of(name, node);
    s.constant_where[name] = t->where(name);
  }
}

void read_parameters(const Section& root, Scene& s) {
  const auto t = root.optional_any_table("parameters");
  if (!t) return;
  for (const auto& [key, node] : t->entries()) {
    const std::string name(key.str());
    const bool identifier = !name.empty() && (std::isalpha(static_cast<unsigned char>(name[0])) != 0 || name[0] == '_') &&
                            std::all_of(name.begin(), name.end(), [](char c) { return std::isalnum(static_cast<unsigned char>(c)) != 0 || c == '_'; });
    if (!identifier) t->fail_key(name, "is not a name an expression can use (letters, digits and _, not starting with a digit)");
    s.parameters[name] = t->number_of(name, node);
    s.parameter_where[name] = t->where(name);
  }
}

void read_constraints(const Section& root, Scene& s) {
  const auto t = root.optional_any_table("constraints");
  if (!t) return;
  for (const auto& [key, node_ptr] : in_file_order(t->entries())) {
    const toml::node& node = *node_ptr;
    const std::string& name = key;
    SceneConstraint c;
    c.name = name;
    c.where = t->where(name);
    if (node.is_number()) {
      c.target = t->number_of(name, node);
    } else if (node.is_string()) {
      if (*node.value<std::string>() != "initial")
        t->fail_key(name, "must be a number (the target), \"initial\" (the value at the start) or a table { target = ..., "
                          "scale = ... }, got '" + *node.value<std::string>() + "'");
      c.initial = true;
    } else if (node.is_table()) {
      const Section ct = t->table_of(name, node, {"target", "scale"});
      if (const toml::node* target = ct.node("target"); target != nullptr && target->is_string()) {
        if (*target->value<std::string>() != "initial")
          ct.fail_key("target", "must be a number or \"initial\" (the value at the start), got '" + *target->value<std::string>() + "'");
        c.initial = true;
      } else

        c.target = ct.optional_number("target");
      if (ct.has("scale")) c.scale = ct.positive("scale", ct.number("scale"));
    } else {
      t->wrong_type(name, node, "a number (the target), \"initial\" or a table { target = ..., scale = ... }");
    }
    s.constraints.push_back(std::move(c));
  }
}

/// The boundary parts a [[dirichlet]] or [[equipotential]] entry may name: a box's sides by axis, a
/// polygon's or polyhedron's named parts, "hull" (and "axis" of an axisymmetric box).
std::vector<std::string> boundary_part_names(const Scene& s) {
  std::vector<std::string> sides = s.geometry.is_box() ? std::vector<std::string>{} : s.geometry.part_names();
  static const char* const cartesian[] = {"x", "y", "z"};
  for (int i = 0; i < s.dim() && s.geometry.is_box(); ++i) {
    const std::string axis = s.axisymmetric() ? (i == 0 ? "r" : "z") : cartesian[i];
    if (!(s.axisymmetric() && i == 0)) sides.push_back(axis + "_min");
    sides.push_back(axis + "_max");
  }
  sides.emplace_back("hull");
  if (s.axisymmetric() && s.geometry.is_box()) sides.emplace_back("axis");
  return sides;
}

/// The key 'boundary' of an entry: parts of the scene's geometry, with a did-you-mean.
std::vector<std::string> boundary_parts_of(const Section& t, const Scene& s, const std::vector<std::string>& sides) {
  std::vector<std::string> out;
  for (const auto& b : names_of(t, "boundary")) {
    if (std::find(sides.begin(), sides.end(), b.name) == sides.end()) {
      std::string list;
      for (const auto& side : sides) list += (list.empty() ? "'" : ", '") + side + "'";
      const std::string guess = closest_name(b.name, sides);
      t.fail_key("boundary", "names '" + b.name + "', which is no boundary part of this " +
                                 (s.axisymmetric() ? std::string("axisymmetric") : std::to_string(s.dim()) + "D") + " scene" +
                                 (guess.empty() ? "" : "; did you mean '" + guess + "'?") + " (parts: " + list + ")");
    }
    out.push_back(b.name);
  }
  return out;
}

void read_dirichlet(const Section& root, Scene& s) {
  const toml::node* n = root.node("dirichlet");
  if (n == nullptr) return;
  const auto* a = n->as_array();
  if (a == nullptr) root.wrong_type("dirichlet", *n, "an array of tables ([[dirichlet]])");
  const std::vector<std::string> sides = boundary_part_names(s);
  for (std::size_t i = 0; i < a->size(); ++i) {
    const std::string key = "dirichlet[" + std::to_string(i) + "]";
    const Section t = root.table_of(key, (*a)[i], {"boundary", "unknown", "components", "value"});
    SceneDirichlet d;
    d.where = s.source;
    if (const auto line = (*a)[i].source().begin.line; line > 0) d.where += ":" + std::to_string(line);
    d.where += ": key '" + key + "'";
    d.boundary = boundary_parts_of(t, s, sides);
    d.unknown = t.string("unknown");
    if (t.has("components")) {
      const toml::node& c = t.require("components");
      const auto* ca = c.as_array();
      if (ca == nullptr) t.wrong_type("components", c, "an array of component indices");
      for (std::size_t j = 0; j < ca->size(); ++j) {
        const int comp = t.integer_of("components[" + std::to_string(j) + "]", (*ca)[j]);
        if (comp < 0 || comp >= s.dim()) t.fail_key("components", "has component " + std::to_string(comp) + ", outside 0.." + std::to_string(s.dim() - 1));
        d.components.push_back(comp);
      }
    }
    d.value = value_of(t, "value", t.require("value"));
    s.dirichlet.push_back(std::move(d));
  }
}

/// [[equipotential]]: a scalar unknown constant on parts of the boundary, its value unknown.
void read_equipotentials(const Section& root, Scene& s) {
  const toml::node* n = root.node("equipotential");
  if (n == nullptr) return;
  const auto* a = n->as_array();
  if (a == nullptr) root.wrong_type("equipotential", *n, "an array of tables ([[equipotential]])");
  const std::vector<std::string> sides = boundary_part_names(s);
  for (std::size_t i = 0; i < a->size(); ++i) {
    const std::string key = "equipotential[" + std::to_string(i) + "]";
    const Section t = root.table_of(key, (*a)[i], {"boundary", "unknown", "charge", "name"});
    SceneEquipotential e;
    e.where = s.source;
    if (const auto line = (*a)[i].source().begin.line; line > 0) e.where += ":" + std::to_string(line);
    e.where += ": key '" + key + "'";
    e.boundary = boundary_parts_of(t, s, sides);
    e.unknown = t.string("unknown");
    e.charge = t.number("charge", 0.0);
    e.name = t.optional_string("name").value_or(e.boundary.front());
    for (const auto& other : s.equipotentials)
      if (other.name == e.name)
        t.fail_key("name", "'" + e.name + "' is already the name of another [[equipotential]] entry (" + other.where +
                               "): give each a 'name' of its own");
    s.equipotentials.push_back(std::move(e));
  }
}

/// A table of nodal fields by name ([initial], [coefficients]): a number, an expression, or
/// {file, field} naming a previous run's HDF5 output.
std::vector<SceneInitialField> read_nodal_fields(const Section& root, const char* table, const Scene& s) {
  std::vector<SceneInitialField> out;
  const auto t = root.optional_any_table(table);
  if (!t) return out;
  for (const auto& [name, node_ptr] : in_file_order(t->entries())) {
    const toml::node& node = *node_ptr;
    SceneInitialField f;
    f.unknown = name;
    f.where = t->where(name);
    if (node.is_table()) {
      const Section ft = t->table_of(name, node, {"file", "field"});
      f.kind = SceneInitialField::Kind::file;
      std::filesystem::path p = ft.string("file");
      if (p.is_relative()) p = s.folder / p;
      if (!std::filesystem::is_regular_file(p)) ft.fail_key("file", "names a file that does not exist: " + p.string());
      f.file = p;
      f.field = ft.optional_string("field").value_or(name);
    } else {
      f.value = value_of(*t, name, node);
    }
    out.push_back(std::move(f));
  }
  return out;
}

void read_initial(const Section& root, Scene& s) { s.initial = read_nodal_fields(root, "initial", s); }

void read_coefficients(const Section& root, Scene& s) { s.coefficients = read_nodal_fields(root, "coefficients", s); }

void read_qdata(const Section& root, Scene& s) {
  const auto t = root.optional_any_table("qdata");
  if (!t) return;
  for (const auto& [key, node] : t->entries()) {
    const std::string name(key.str());
    SceneQdata q;
    q.name = name;
    q.where = t->where(name);
    // A string other than the two provider names is an expression ("sin(pi*x[0])*e(0)"); a bare
    // word close to a provider name is taken for a misspelt provider.
    if (node.is_table()) {
      // { field = "phi", jet = "value" | "gradient" | "hessian" }
      const Section ft = t->table_of(name, node, {"field", "jet"});
      q.source = SceneQdata::Source::field;
      q.field = ft.string("field");
      static const std::vector<std::string> jets{"value", "gradient", "hessian"};
      const std::string jet = ft.optional_string("jet").value_or("value");
      const auto it = std::find(jets.begin(), jets.end(), jet);
      if (it == jets.end()) {
        const std::string guess = closest_name(jet, jets);
        ft.fail_key("jet", "must be 'value', 'gradient' or 'hessian', got '" + jet + "'" +
                               (guess.empty() ? std::string() : "; did you mean '" + guess + "'?"));
      }
      q.derivative = static_cast<int>(it - jets.begin());
      s.qdata.push_back(std::move(q));
      continue;
    }
    static const std::vector<std::string> providers{"support_size", "zero"};
    const std::string text = node.is_string() ? *node.value<std::string>() : std::string();
    const bool word = !text.empty() && std::all_of(text.begin(), text.end(), [](unsigned char c) {
      return std::isalnum(c) != 0 || c == '_';
    });
    if (text == "support_size" || text == "zero") {
      q.source = text == "zero" ? SceneQdata::Source::zero : SceneQdata::Source::support_size;
    } else if (word && !closest_name(text, providers).empty()) {
      t->fail_key(name, "must be one of 'support_size', 'zero', a number or an expression, got '" + text +
                            "'; did you mean '" + closest_name(text, providers) + "'?");
    } else {
      q.source = SceneQdata::Source::value;
      q.value = value_of(*t, name, node);
    }
    s.qdata.push_back(std::move(q));
  }
}

void read_reference(const Section& root, Scene& s) {
  const auto t = root.optional_table("reference", {"energy", "solution"});
  if (!t) return;
  s.reference.energy = t->optional_number("energy");
  if (const auto sol = t->optional_any_table("solution")) {
    for (const auto& [key, node] : sol->entries()) {
      const std::string name(key.str());
      SceneValue v = value_of(*sol, name, node);
      s.reference.solution.emplace_back(name, std::move(v));
    }
  }
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

void read_solver(const Section& root, Scene& s) {
  const auto t = root.optional_table(
      "solver", {"start", "penalty", "augmented_tolerance", "inner_tolerance", "max_outer_iterations", "max_inner_iterations",
                 "newton_tolerance", "constraint_tolerance", "max_newton_iterations", "inertia_correction", "monitor", "petsc_options"});
  if (!t) return;
  SceneSolver& o = s.solver;
  o.kkt_first = t->choice_of("start", t->optional_string("start").value_or("kkt"), {"kkt", "augmented"}) == "kkt";
  o.penalty = t->positive("penalty", t->number("penalty", o.penalty));
  o.augmented_tolerance = t->relative_tolerance("augmented_tolerance", t->number("augmented_tolerance", o.augmented_tolerance));
  // When KKT Newton stalls, the minimizer resumes the augmented Lagrangian with its tolerance
  // 100 times tighter, twice at most: that must stay reachable (from 1e-14 the tiny vesicle ran
  // 40 multiplier updates, 74 s, towards 1e-16 and stopped).
  if (o.augmented_tolerance < kSmallestRelativeTolerance * 1e4)
    t->fail_key("augmented_tolerance", "= " + format_number(o.augmented_tolerance) +
                                           " leaves no room for the minimizer's fallback, which tightens it 100-fold twice when KKT "
                                           "Newton stalls (below double precision): give at least " +
                                           format_number(kSmallestRelativeTolerance * 1e4));
  o.inner_tolerance = t->relative_tolerance("inner_tolerance", t->number("inner_tolerance", o.inner_tolerance));
  o.max_outer_iterations = t->at_least("max_outer_iterations", t->integer("max_outer_iterations", o.max_outer_iterations), 1);
  o.max_inner_iterations = t->at_least("max_inner_iterations", t->integer("max_inner_iterations", o.max_inner_iterations), 1);
  o.newton_tolerance = t->relative_tolerance("newton_tolerance", t->number("newton_tolerance", o.newton_tolerance));
  o.constraint_tolerance =
      t->relative_tolerance("constraint_tolerance", t->number("constraint_tolerance", o.constraint_tolerance));
  o.max_newton_iterations =
      t->at_least("max_newton_iterations", t->integer("max_newton_iterations", o.max_newton_iterations), 0);
  o.inertia_correction = t->boolean("inertia_correction", o.inertia_correction);
  o.monitor = t->boolean("monitor", o.monitor);
  if (t->has("petsc_options")) o.petsc_options = t->string("petsc_options");
}

}  // namespace

const char* to_string(Coordinates c) noexcept {
  return c == Coordinates::axisymmetric ? "axisymmetric" : "cartesian";
}

bool Scene::has_extension(std::string_view table) const {
  return std::find(extensions.begin(), extensions.end(), table) != extensions.end();
}

std::string Scene::where_constant(std::string_view constant) const {
  if (const auto it = constant_where.find(constant); it != constant_where.end()) return it->second;
  return source + ": [constants]";
}

std::string closest_name(std::string_view word, std::span<const std::string> candidates) {
  std::string best;
  std::size_t best_d = std::numeric_limits<std::size_t>::max();
  for (const auto& c : candidates) {
    const std::size_t d = scene_detail::edit_distance(word, c);
    if (d < best_d) {
      best_d = d;
      best = c;
    }
  }
  const std::size_t limit = std::max<std::size_t>(2, std::min(word.size(), best.size()) / 3);
  return best_d <= limit ? best : std::string{};
}

Scene parse_scene(std::string_view text, std::string source_name, std::span<const std::string_view> extensions) {
  auto document = std::make_shared<SceneDocument>();
  document->context.file = source_name;
  try {
    document->root = toml::parse(text, source_name);
  } catch (const toml::parse_error& e) {
    const auto& b = e.source().begin;
    throw SceneError(source_name + ":" + std::to_string(b.line) + ":" + std::to_string(b.column) +
                     ": TOML syntax error: " + std::string(e.description()));
  }
  std::vector<std::string_view> tables{"scene", "domain", "nodes", "model", "constants", "parameters", "constraints", "dirichlet",
                                       "equipotential", "initial", "coefficients", "qdata", "solver", "reference", "quantities", "bounds", "output"};
  tables.insert(tables.end(), extensions.begin(), extensions.end());
  // The initializer_list interface of SceneTable wants a list: check the top-level keys here.
  for (const auto& [key, node] : document->root) {
    if (std::find(tables.begin(), tables.end(), key.str()) != tables.end()) continue;
    std::vector<std::string> names(tables.begin(), tables.end());
    const std::string guess = closest_name(key.str(), names);
    std::string list;
    for (const auto& t : tables) list += (list.empty() ? "[" : ", [") + std::string(t) + "]";
    fail(document->context, &node, "unknown table [" + std::string(key.str()) + "]" +
                                       (guess.empty() ? "; the tables of a scene are " + list : "; did you mean [" + guess + "]?"));
  }
  const Section root(document->context, document->root, "", Section::AnyKeys{});
  Scene s;
  s.source = source_name;
  s.folder = std::filesystem::path(source_name).parent_path();
  for (const auto e : extensions)
    if (root.has(e)) s.extensions.emplace_back(e);
  read_scene_section(root, s);
  read_domain(root, s);
  read_nodes(root, s.folder, s);
  read_model(root, s);
  read_constants(root, s);
  read_parameters(root, s);
  read_constraints(root, s);
  read_dirichlet(root, s);
  read_equipotentials(root, s);
  read_initial(root, s);
  read_coefficients(root, s);
  read_qdata(root, s);
  read_solver(root, s);
  read_reference(root, s);
  scene_detail::read_quantities(root, s);
  scene_detail::read_bounds(root, s);
  read_output(root, s);
  s.document = std::move(document);
  return s;
}

Scene load_scene(const std::filesystem::path& path, std::span<const std::string_view> extensions) {
  std::ifstream in(path, std::ios::binary);
  if (!in) throw SceneError(path.string() + ": cannot open the scene file");
  std::ostringstream text;
  text << in.rdbuf();
  return parse_scene(text.str(), path.string(), extensions);
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
