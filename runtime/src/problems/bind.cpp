#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <limits>
#include <optional>
#include <span>
#include <string>

#include <fmt/format.h>
#include <fmt/ranges.h>

#include "bound_scene.hpp"
#include "lmeform/node_sets.hpp"
#include "lmeform/scene_table.hpp"
#include "problem_registry.hpp"
#include "point_values.hpp"
#include "problem_space.hpp"
#include "saddle_point.hpp"

namespace lmeform::problems {

namespace {

using kernel::FormKernels;
using kernel::FunctionalKind;

std::vector<std::string> unique_names(std::vector<std::string> names) {
  std::vector<std::string> out;
  for (auto& n : names)
    if (std::find(out.begin(), out.end(), n) == out.end()) out.push_back(std::move(n));
  return out;
}

template <class T, class Name>
bool contains_name(const std::vector<T>& items, std::string_view name, Name&& name_of) {
  return std::any_of(items.begin(), items.end(), [&](const T& x) { return name_of(x) == name; });
}

bool contains(const std::vector<std::string>& names, std::string_view name) {
  return std::find(names.begin(), names.end(), name) != names.end();
}

/// Why no output `output` of `kind` is found: it is in another dimension, of another kind, or absent.
[[noreturn]] void explain_missing_output(const BoundScene& b, const SceneName& name, const std::string& module_name,
                                         const std::string& output, FunctionalKind kind, const std::vector<std::string>& candidates) {
  for (const FormModule* m : b.modules)
    for (const auto* k : m->kernels)
      if (k->name == output && (module_name.empty() || m->name == module_name)) {
        if (k->kind != kind)
          throw SceneError(fmt::format("{}: '{}' of form {} is a {} output, not a {} output", name.where, output, m->name,
                                       to_string(k->kind), to_string(kind)));
        throw SceneError(fmt::format("{}: form {} declares '{}' in dimension {} only; this scene is {}D", name.where, m->name,
                                     output, fmt::join(m->dimensions(), ", "), b.dim));
      }
  throw SceneError(fmt::format("{}: no {} output '{}' in the scene's forms{}{}", name.where, to_string(kind), output,
                               did_you_mean(output, candidates),
                               candidates.empty() ? fmt::format(" (they define no {} output)", to_string(kind))
                                                  : fmt::format(" ({} outputs: '{}')", to_string(kind), fmt::join(candidates, "', '"))));
}

/// "module.output" or "output" of `kind` among the modules, in the scene's dimension: every kernel
/// of that output (one per integration domain) of the one module defining it.
BoundOutput find_output(const BoundScene& b, const SceneName& name, FunctionalKind kind) {
  std::string module_name, output = name.name;
  if (const auto dot = name.name.find('.'); dot != std::string::npos && !name.name.ends_with(".form")) {
    module_name = name.name.substr(0, dot);
    output = name.name.substr(dot + 1);
  }
  std::vector<const FormModule*> defining;
  std::vector<std::string> candidates;
  BoundOutput found;
  for (const FormModule* m : b.modules) {
    if (!module_name.empty() && m->name != module_name) continue;
    for (const auto* k : m->kernels) {
      if (k->kind != kind) continue;
      candidates.emplace_back(k->name);
      if (k->name != output || k->dim != b.dim) continue;
      if (std::find(defining.begin(), defining.end(), m) == defining.end()) defining.push_back(m);
      found.kernels.push_back(k);
    }
  }
  if (defining.size() > 1)
    throw SceneError(fmt::format("{} = '{}' is ambiguous: several forms define a {} '{}'; write 'module.{}'", name.where, name.name,
                                 to_string(kind), output, output));
  if (defining.empty()) explain_missing_output(b, name, module_name, output, kind, unique_names(candidates));
  found.label = defining.front()->name + "." + output;
  return found;
}

void load_modules(const Scene& scene, MPI_Comm comm, std::ostream* log, BoundScene& b) {
  FormLoadOptions load;
  load.comm = comm;
  load.log = log;
  if (!scene.folder.empty()) load.include_dirs.push_back(scene.folder);
  for (const auto& f : scene.model.forms) {
    try {
      b.modules.push_back(&load_form(f.name, load));
    } catch (const FormLoadError& e) {
      throw FormLoadError(fmt::format("{} = '{}':\n{}", f.where, f.name, e.what()));
    }
  }
}

void bind_outputs(const Scene& scene, const OutputRoles& roles, BoundScene& b) {
  if (roles.all_energies) {
    for (const FormModule* m : b.modules)
      for (const auto* k : m->kernels)
        if (k->kind == FunctionalKind::Energy && k->dim == b.dim &&
            !contains_name(b.energy, std::string(m->name) + "." + k->name, [](const BoundOutput& o) { return o.label; }))
          b.energy.push_back(find_output(b, {std::string(m->name) + "." + k->name, scene.source}, FunctionalKind::Energy));
    if (b.energy.empty())
      throw SceneError(fmt::format("{}: key 'model': the forms define no energy output in dimension {}; name the problem's outputs "
                                   "with model.energy, model.residual or model.bilinear + model.linear",
                                   scene.source, b.dim));
  }
  for (const auto& e : roles.energies) b.energy.push_back(find_output(b, e, FunctionalKind::Energy));
  if (roles.residual) b.residual = find_output(b, *roles.residual, FunctionalKind::Residual);
  if (roles.bilinear) b.bilinear = find_output(b, *roles.bilinear, FunctionalKind::Bilinear);
  if (roles.linear) b.linear = find_output(b, *roles.linear, FunctionalKind::Linear);
  for (const auto& a : roles.auxiliary) b.auxiliary.push_back(find_output(b, a, FunctionalKind::Energy));
  if (!roles.constraints && !scene.constraints.empty())
    throw SceneError(fmt::format("{}: [constraints] constrain the minimization of energies; this scene's problem is {}",
                                 scene.constraints.front().where, b.residual ? "a residual" : "a linear problem"));
  for (const auto& c : scene.constraints) {
    BoundConstraint bc;
    bc.name = c.name;
    bc.output = find_output(b, {c.name, c.where}, FunctionalKind::Constraint);
    const FormKernels& k = bc.output.first();
    if (k.target_constant >= 0) bc.target_constant = k.constants[k.target_constant];
    b.constraints.push_back(std::move(bc));
  }
  b.primary = !b.energy.empty() ? &b.energy.front() : b.residual ? &*b.residual : b.bilinear ? &*b.bilinear : nullptr;
  if (b.primary == nullptr) throw SceneError(fmt::format("{}: key 'model': the scene names no output to solve", scene.source));
}

std::vector<UnknownField> unknowns_of(const FormKernels& k) {
  std::vector<UnknownField> out;
  int offset = 0;
  for (int i = 0; i < k.n_unknowns; ++i) {
    out.push_back({k.unknowns[i].name, k.unknowns[i].components, offset});
    offset += k.unknowns[i].components;
  }
  return out;
}

/// One layout of unknowns for every kernel; the coefficient fields they read; the basis order.
void bind_layout(const Scene& scene, BoundScene& b) {
  const FormKernels& primary = b.primary->first();
  b.layout.fields = unknowns_of(primary);
  b.layout.dofs_per_node = primary.dofs_per_node;
  for (const BoundOutput* o : b.outputs()) {
    const bool auxiliary = contains_name(b.auxiliary, o->label, [](const BoundOutput& x) { return x.label; });
    for (const FormKernels* k : o->kernels) {
      if (auxiliary && k->dofs_per_node != b.layout.dofs_per_node)
        throw SceneError(fmt::format("{}: {}.{} has {} dofs per node, the problem {}", scene.source, k->module, k->name,
                                     k->dofs_per_node, b.layout.dofs_per_node));
      const auto u = unknowns_of(*k);
      bool same = auxiliary || u.size() == b.layout.fields.size();
      for (std::size_t i = 0; same && !auxiliary && i < u.size(); ++i)
        same = u[i].components == b.layout.fields[i].components &&
               (k->kind == FunctionalKind::Linear || primary.kind == FunctionalKind::Bilinear || u[i].name == b.layout.fields[i].name);
      if (!same)
        throw SceneError(fmt::format("{}: the outputs {}.{} and {}.{} have different unknowns: a scene's outputs share one set of "
                                     "unknown fields (names, shapes and order)",
                                     scene.source, primary.module, primary.name, k->module, k->name));
      for (int i = 0; i < k->n_coefficients; ++i) {
        const kernel::FieldInfo& c = k->coefficients[i];
        if (auxiliary && b.layout.has(c.name)) continue;  // the unknown's current value, set by the driver
        const auto known = std::find_if(b.coefficient_fields.begin(), b.coefficient_fields.end(),
                                        [&](const UnknownField& f) { return f.name == c.name; });
        if (known == b.coefficient_fields.end()) b.coefficient_fields.push_back({c.name, c.components, 0});
        else if (known->components != c.components)
          throw SceneError(fmt::format("{}: {}.{} reads the coefficient '{}' with {} components, another output with {}", scene.source,
                                       k->module, k->name, c.name, c.components, known->components));
      }
      b.basis_order = std::max({b.basis_order, k->basis_order, k->coefficient_basis_order});
    }
  }
}

/// Every ds(part) of the outputs must name a part of the scene's domain.
/// "FILE:LINE:COL" and the line with a caret under the first `ds(part)` of a form's file, or "".
std::string locate_measure(const std::filesystem::path& source, const std::string& part) {
  std::ifstream in(source);
  std::string line;
  for (int number = 1; std::getline(in, line); ++number) {
    const std::size_t column = line.find("ds(" + part + ")");
    if (column == std::string::npos) continue;
    return fmt::format("{}:{}:{}:\n{}\n{}^", source.string(), number, column + 1, line, std::string(column, ' '));
  }
  return {};
}

/// Every ds(part) of the outputs names a part of the scene's domain.
void bind_boundary_parts(const Scene& scene, BoundScene& b) {
  for (const BoundOutput* o : b.outputs())
    for (const FormKernels* k : o->kernels) {
      if (k->domain != kernel::IntegralDomain::Boundary) continue;
      const std::string part = k->boundary_part;
      if (!b.geometry.has_part(part)) {
        std::vector<std::string> parts = b.geometry.part_names();
        std::string where = scene.source;
        std::filesystem::path form = k->source;
        for (std::size_t i = 0; i < b.modules.size() && i < scene.model.forms.size(); ++i)
          if (b.modules[i]->name == k->module) {
            where = scene.model.forms[i].where + " = '" + scene.model.forms[i].name + "'";
            form = b.modules[i]->source;
          }
        const std::string location = locate_measure(form, part);
        throw SceneError(fmt::format("{}: {} integrates over ds({}), but the scene's [domain] has no part '{}'{} (its parts: {}){}", where,
                                     o->label, part, part, did_you_mean(part, parts),
                                     parts.empty() ? std::string("none named") : fmt::format("{}", fmt::join(parts, ", ")),
                                     location.empty() ? std::string() : "\n" + location));
      }
      if (std::find(b.boundary_parts.begin(), b.boundary_parts.end(), part) == b.boundary_parts.end()) b.boundary_parts.push_back(part);
    }
}

/// The scene's value of each constant, else the form's default; every scene constant must be a form's.
void bind_constants(const Scene& scene, const OutputRoles& roles, BoundScene& b) {
  std::vector<std::string> form_constants;
  for (const BoundOutput* o : b.outputs())
    for (const FormKernels* k : o->kernels)
      for (int i = 0; i < k->n_constants; ++i) form_constants.emplace_back(k->constants[i]);
  form_constants = unique_names(std::move(form_constants));
  const std::string constant_list =
      form_constants.empty() ? std::string("they have none") : fmt::format("{}", fmt::join(form_constants, ", "));
  for (const auto& [name, value] : scene.constants)
    if (!contains(form_constants, name))
      throw SceneError(fmt::format("{}: no form of the problem has a constant '{}'{} (the forms' constants: {})",
                                   scene.where_constant(name), name, did_you_mean(name, form_constants), constant_list));
  for (const BoundOutput* o : b.outputs())
    for (const FormKernels* k : o->kernels)
      for (int i = 0; i < k->n_constants; ++i) {
        const std::string name = k->constants[i];
        if (b.constants.contains(name)) continue;
        if (const auto it = scene.constants.find(name); it != scene.constants.end()) {
          b.constants[name] = it->second;
          continue;
        }
        // A target of a constraint given "initial" is set from the start state by the problem space.
        const bool is_target = contains_name(b.constraints, name, [](const BoundConstraint& c) { return c.target_constant; });
        if (k->constant_defaults != nullptr && !std::isnan(k->constant_defaults[i])) {
          b.constants[name] = k->constant_defaults[i];
        } else if (is_target || contains(roles.provided_constants, name)) {
          b.constants[name] = std::numeric_limits<double>::quiet_NaN();  // set from the target / by the driver
        } else {
          throw SceneError(fmt::format("{}: missing key 'constants.{}': form {} ({}) needs the constant '{}' and gives it no default "
                                       "(the forms' constants: {})",
                                       scene.source, name, k->module, k->source, name, constant_list));
        }
      }
}

/// [parameters]: the scene's own named numbers, constants of its expressions (not of the forms).
void bind_parameters(const Scene& scene, BoundScene& b) {
  for (const auto& [name, value] : scene.parameters) {
    if (b.constants.contains(name))
      throw SceneError(fmt::format("{} is a constant of the forms: give its value in [constants]", scene.parameter_where.at(name)));
    b.constants[name] = value;
  }
}

/// Targets: [constraints] NAME = target, else the form's target constant or number.
void bind_constraint_targets(const Scene& scene, const OutputRoles& roles, BoundScene& b) {
  for (std::size_t i = 0; i < b.constraints.size(); ++i) {
    BoundConstraint& bc = b.constraints[i];
    const SceneConstraint& sc = scene.constraints[i];
    if (sc.target) {
      bc.target = *sc.target;
      if (!bc.target_constant.empty()) {
        if (scene.constants.contains(bc.target_constant) && scene.constants.at(bc.target_constant) != *sc.target)
          throw SceneError(fmt::format("{}: the target {} differs from {} = {} in [constants] (the constant is the constraint's "
                                       "target: give it once)",
                                       sc.where, *sc.target, bc.target_constant, scene.constants.at(bc.target_constant)));
        b.constants[bc.target_constant] = *sc.target;
      }
    } else if (sc.initial) {
      bc.initial = true;
      bc.target = std::numeric_limits<double>::quiet_NaN();
    } else if (bc.target_constant.empty()) {
      bc.target = bc.output.first().target_value;
    } else {
      bc.target = b.constants.at(bc.target_constant);
      if (std::isnan(bc.target) && !contains(roles.provided_constants, bc.target_constant))
        throw SceneError(fmt::format("{}: constraint '{}' compares with the constant '{}', which has no value: give constraints.{} = "
                                     "TARGET or constants.{}",
                                     sc.where, bc.name, bc.target_constant, bc.name, bc.target_constant));
    }
    bc.scale_given = sc.scale.has_value();
    bc.scale = sc.scale.value_or(std::abs(bc.target) > 0 ? std::abs(bc.target) : 1.0);  // "initial": set with the target
  }
}

/// The size of quadrature datum `name` in the kernels (0 if none reads it).
int qdata_size(const BoundScene& b, std::string_view name) {
  for (const BoundOutput* o : b.outputs())
    for (const FormKernels* k : o->kernels)
      for (int i = 0; i < k->n_qdata; ++i)
        if (k->qdata[i].name == name) return k->qdata[i].size;
  return 0;
}

/// A value of the scene as a number or a registered expression.
BoundValue bind_value(BoundScene& b, const SceneValue& v, int components, const std::string& where, bool scalar_allowed = false) {
  if (v.is_number()) return {v.number(), -1};
  return {0.0, b.expressions->add(v.expression(), components, where, scalar_allowed)};
}

/// Every datum the kernels read is supplied by the scene; sources that need a field register it.
void bind_qdata(const Scene& scene, BoundScene& b) {
  std::vector<std::string> needed;
  for (const BoundOutput* o : b.outputs())
    for (const FormKernels* k : o->kernels)
      for (int i = 0; i < k->n_qdata; ++i) needed.emplace_back(k->qdata[i].name);
  needed = unique_names(std::move(needed));
  for (const auto& q : scene.qdata)
    if (!contains(needed, q.name))
      throw SceneError(fmt::format("{}: no form of the problem reads quadrature data '{}'{} ({})", q.where, q.name,
                                   did_you_mean(q.name, needed),
                                   needed.empty() ? std::string("they read none") : fmt::format("they read: {}", fmt::join(needed, ", "))));
  for (const auto& n : needed)
    if (!contains_name(scene.qdata, n, [](const SceneQdata& q) { return q.name; }))
      throw SceneError(fmt::format("{}: missing key 'qdata.{}': the forms read the quadrature datum '{}' (give a source: "
                                   "\"support_size\", \"zero\", a number, an expression of x or {{ field, jet }})",
                                   scene.source, n, n));
  for (const auto& q : scene.qdata) {
    BoundQdata d{q.name, q.source, qdata_size(b, q.name), {}, q.field, q.derivative, q.where};
    using Source = SceneQdata::Source;
    if (q.source == Source::support_size && d.size != 1)
      throw SceneError(fmt::format("{}: \"support_size\" is a scalar; '{}' has {} values per point", q.where, q.name, d.size));
    if (q.source == Source::value) {
      if (d.size != 1 && d.size != b.dim)
        throw SceneError(fmt::format("{}: '{}' has {} values per point; a value or an expression gives a scalar or a vector", q.where,
                                     q.name, d.size));
      d.value = bind_value(b, q.value, d.size, q.value.where);
    }
    if (q.source == Source::field) {
      const int expected = q.derivative == 0 ? 1 : q.derivative == 1 ? b.dim : b.dim * b.dim;
      if (d.size != expected)
        throw SceneError(fmt::format("{}: '{}' has {} values per point; the {} of a scalar field has {}", q.where, q.name, d.size,
                                     q.derivative == 0 ? "value" : q.derivative == 1 ? "gradient" : "Hessian", expected));
      // The interpolated scalar field is a coefficient field too.
      const auto known = std::find_if(b.coefficient_fields.begin(), b.coefficient_fields.end(),
                                      [&](const UnknownField& f) { return f.name == q.field; });
      if (known == b.coefficient_fields.end()) b.coefficient_fields.push_back({q.field, 1, 0});
      else if (known->components != 1)
        throw SceneError(fmt::format("{}: key 'field': '{}' has {} components; quadrature data interpolate scalar fields", q.where,
                                     q.field, known->components));
      b.basis_order = std::max(b.basis_order, q.derivative);
    }
    b.qdata.push_back(std::move(d));
  }
}

const UnknownField& check_unknown(const BoundScene& b, const std::string& name, const std::string& where) {
  if (b.layout.has(name)) return b.layout.field(name);
  std::vector<std::string> names;
  for (const auto& u : b.layout.fields) names.push_back(u.name);
  throw SceneError(fmt::format("{}: '{}' is no unknown of the problem{} (unknowns: {})", where, name, did_you_mean(name, names),
                               fmt::join(names, ", ")));
}

BoundNodalField bind_nodal_field(BoundScene& b, const SceneInitialField& f, int components) {
  BoundNodalField out{f.unknown, {}, {}, f.field, f.where};
  if (f.kind == SceneInitialField::Kind::file) out.file = f.file;
  else out.value = bind_value(b, f.value, components, f.where);
  return out;
}

/// [initial], [coefficients] and [[dirichlet]]: names checked, expressions registered.
void bind_nodal_data(const Scene& scene, BoundScene& b) {
  for (const auto& f : scene.initial) {
    const UnknownField& u = check_unknown(b, f.unknown, f.where);
    b.initial.push_back(bind_nodal_field(b, f, u.components));
  }
  std::vector<std::string> coefficient_names;
  for (const auto& c : b.coefficient_fields) coefficient_names.push_back(c.name);
  for (const auto& f : scene.coefficients) {
    const auto c = std::find_if(b.coefficient_fields.begin(), b.coefficient_fields.end(),
                                [&](const UnknownField& x) { return x.name == f.unknown; });
    if (c == b.coefficient_fields.end())
      throw SceneError(fmt::format("{}: '{}' is no coefficient field of the forms{} ({})", f.where, f.unknown,
                                   did_you_mean(f.unknown, coefficient_names),
                                   coefficient_names.empty() ? std::string("they read none")
                                                             : fmt::format("they read: {}", fmt::join(coefficient_names, ", "))));
    b.coefficients.push_back(bind_nodal_field(b, f, c->components));
  }
  for (const auto& c : b.coefficient_fields)
    if (!contains_name(scene.coefficients, c.name, [](const SceneInitialField& f) { return f.unknown; }))
      throw SceneError(fmt::format("{}: missing key 'coefficients.{}': the forms read the known nodal field '{}' ({} component{}; give "
                                   "a number, an expression of x or {{file, field}})",
                                   scene.source, c.name, c.name, c.components, c.components == 1 ? "" : "s"));
  for (const auto& d : scene.dirichlet) {
    const UnknownField& u = check_unknown(b, d.unknown, d.where + ": key 'unknown'");
    BoundDirichlet bd{d.boundary, u, d.components, {}, d.where};
    for (const int c : d.components)
      if (c >= u.components)
        throw SceneError(fmt::format("{}: key 'components' lists component {} of '{}', which has {}", d.where, c, u.name, u.components));
    if (bd.components.empty())
      for (int c = 0; c < u.components; ++c) bd.components.push_back(c);
    // One listed component of a vector: a scalar expression is its value ("-delta").
    bd.value = bind_value(b, d.value, u.components, d.value.where, bd.components.size() == 1);
    b.dirichlet.push_back(std::move(bd));
  }
}

/// Zero-mean unknowns and exact solutions; the generated forms they need are compiled now, so
/// that a typo is reported before any solve.
void bind_reference(const Scene& scene, MPI_Comm comm, std::ostream* log, const std::map<std::string, double, std::less<>>& constants,
                    BoundScene& b) {
  for (const auto& z : scene.model.zero_mean) {
    const UnknownField& u = check_unknown(b, z.name, z.where);
    if (u.components != 1) throw SceneError(fmt::format("{}: '{}' is a vector; model.zero_mean takes scalar unknowns", z.where, u.name));
    if (contains_name(b.dirichlet, u.name, [](const BoundDirichlet& d) { return d.field.name; }))
      throw SceneError(fmt::format("{}: '{}' has Dirichlet values and model.zero_mean: give one or the other", z.where, u.name));
    b.zero_mean.push_back(u.name);
  }
  if (!b.zero_mean.empty()) (void)compile_integral_form(b.dim, comm, log);
  for (const auto& [name, value] : scene.reference.solution) {
    const UnknownField& u = check_unknown(b, name, value.where);
    if (value.is_number()) throw SceneError(fmt::format("{}: an exact solution is an expression string", value.where));
    (void)compile_error_form(b.dim, name, u.components, value.expression(), constants, value.where, comm, log);
    b.exact.push_back({u, value.expression(), value.where});
  }
}

/// [quantities]: fields and constants checked, the integrals compiled into one generated form.
void bind_quantities(const Scene& scene, MPI_Comm comm, std::ostream* log, const std::map<std::string, double, std::less<>>& constants,
                     BoundScene& b) {
  std::vector<QuantityIntegral> integrals;
  std::vector<std::string> where;
  for (const SceneQuantity& q : scene.quantities) {
    BoundQuantity bq{q, {}, nullptr, std::nullopt};
    using Kind = SceneQuantity::Kind;
    if (q.kind == Kind::probe && !b.layout.has(q.field)) {
      const auto point = std::find_if(b.point_outputs.begin(), b.point_outputs.end(), [&](const auto& p) { return p.first == q.field; });
      if (point == b.point_outputs.end()) {
        std::vector<std::string> names;
        for (const auto& u : b.layout.fields) names.push_back(u.name);
        for (const auto& p : b.point_outputs) names.push_back(p.first);
        throw SceneError(fmt::format("{}: '{}' is no unknown or point output of the problem{} (fields: {})", q.where, q.field,
                                     did_you_mean(q.field, names), fmt::join(names, ", ")));
      }
      bq.point = point->second;
      if (q.component >= bq.point->n_values)
        throw SceneError(fmt::format("{}: key 'component' = {}: '{}' has {} value(s)", q.where, q.component, q.field, bq.point->n_values));
    } else if (q.kind == Kind::reaction || q.kind == Kind::probe) {
      bq.field = check_unknown(b, q.field, q.where);
      if (q.component >= bq.field.components)
        throw SceneError(fmt::format("{}: key 'component' = {}: '{}' has {} component(s)", q.where, q.component, q.field, bq.field.components));
    }
    if (q.kind == Kind::constant && !b.constants.contains(q.constant)) {
      std::vector<std::string> names;
      for (const auto& [n, v] : b.constants) names.push_back(n);
      throw SceneError(fmt::format("{}: '{}' is no constant of the forms{}", q.where, q.constant, did_you_mean(q.constant, names)));
    }
    if (q.kind == Kind::energy) {
      std::vector<std::string> names;
      for (const BoundOutput& e : b.energy) {
        const std::string short_name = e.label.substr(e.label.find('.') + 1);
        names.push_back(short_name);
        if (q.output == e.label || q.output == short_name) {
          if (bq.integral)
            throw SceneError(fmt::format("{}: '{}' names several energy outputs: write MODULE.OUTPUT ({} or {})", q.where, q.output,
                                         bq.integral->label, e.label));
          bq.integral = e;
        }
      }
      if (!bq.integral)
        throw SceneError(fmt::format("{}: '{}' is no energy output of the problem{} (energies: {})", q.where, q.output,
                                     did_you_mean(q.output, names), fmt::join(names, ", ")));
    }
    if (q.kind == Kind::integral) {
      integrals.push_back({q.expression, q.part, !q.part.empty()});
      where.push_back(q.where);
      if (!q.part.empty() && std::find(b.boundary_parts.begin(), b.boundary_parts.end(), q.part) == b.boundary_parts.end())
        b.boundary_parts.push_back(q.part);
    }
    b.quantities.push_back(std::move(bq));
  }
  if (integrals.empty()) return;
  std::vector<std::pair<std::string, int>> unknowns;
  for (const auto& u : b.layout.fields) unknowns.emplace_back(u.name, u.components);
  const FormModule& module = compile_quantity_form(b.dim, unknowns, constants, integrals, where, comm, log);
  std::size_t i = 0;
  for (BoundQuantity& q : b.quantities) {
    if (q.scene.kind != SceneQuantity::Kind::integral) continue;
    BoundOutput out;
    out.label = module.name + ".q" + std::to_string(i++);
    for (const auto* k : module.kernels)
      if (k->dim == b.dim && out.label == module.name + "." + k->name) out.kernels.push_back(k);
    q.integral = std::move(out);
  }
}

/// The point outputs the unknowns and the bound constants determine, by field name.
void bind_point_outputs(const Scene& scene, BoundScene& b) {
  b.write_point_fields = scene.output && scene.output->hdf5;
  for (const FormModule* m : b.modules)
    for (const auto* k : m->kernels) {
      if (k->kind != FunctionalKind::Point || k->requirement != nullptr || k->dim != b.dim || !PointEvaluator::can_evaluate(*k, b.layout)) continue;
      bool known = true;
      for (int i = 0; i < k->n_constants; ++i) known = known && b.constants.contains(k->constants[i]);
      if (!known) continue;
      const bool taken = std::any_of(b.point_outputs.begin(), b.point_outputs.end(), [&](const auto& p) { return p.first == k->name; }) ||
                         b.layout.has(k->name);
      b.point_outputs.emplace_back(taken ? m->name + "." + k->name : std::string(k->name), k);
    }
}

/// [bounds]: the unknowns checked, the expressions registered; bounds constrain a minimization
/// without global constraints, a residual or a linear problem.
void bind_bounds(const Scene& scene, BoundScene& b) {
  for (const SceneBound& sb : scene.bounds) {
    BoundBound bb;
    bb.field = check_unknown(b, sb.unknown, sb.where);
    bb.where = sb.where;
    bb.lower_previous = sb.lower_previous;
    bb.upper_previous = sb.upper_previous;
    if (sb.lower) bb.lower = bind_value(b, *sb.lower, bb.field.components, sb.lower->where);
    if (sb.upper) bb.upper = bind_value(b, *sb.upper, bb.field.components, sb.upper->where);
    b.bounds.push_back(std::move(bb));
  }
  if (!b.bounds.empty() && !b.constraints.empty())
    throw SceneError(fmt::format("{}: [bounds] and [constraints] together are not supported: a bounded problem is solved as a variational "
                                 "inequality, without multipliers of global constraints",
                                 b.bounds.front().where));
}

/// The most nodes at which binding evaluates the scene's expressions (a grid of 4 million nodes
/// takes about a second; larger grids are left to the run).
constexpr double kEvaluatedNodes = 4e6;

/// The scene's node set when it is known before a run without work: a uniform grid (nodes.spacing
/// or nodes.counts) of at most kEvaluatedNodes nodes, or a node file, read now so that a file that
/// cannot be read, or holds too few points to triangulate, is refused before the solve. A CVT
/// (nodes.count) is built by the run.
std::optional<NodeSet> known_nodes(const Scene& scene, MPI_Comm comm) {
  const SceneNodes& n = scene.nodes;
  const bool grid = n.kind == SceneNodes::Kind::counts || (n.kind == SceneNodes::Kind::spacing && scene.geometry.is_box() && n.refine.empty());
  if (grid) {
    double total = 1;
    for (int i = 0; i < scene.dim(); ++i) {
      const auto k = std::size_t(i);
      total *= n.kind == SceneNodes::Kind::counts ? n.counts[k]
                                                  : std::max(2.0, std::round((scene.domain.hi[k] - scene.domain.lo[k]) / n.spacing) + 1);
    }
    if (total > kEvaluatedNodes) return std::nullopt;
    return n.kind == SceneNodes::Kind::counts ? uniform_grid(scene.domain, n.counts) : uniform_grid(scene.domain, n.spacing);
  }
  if (n.kind == SceneNodes::Kind::file) {
    NodeSet nodes = initial_nodes(scene, comm);  // SceneError naming 'nodes.file' when it cannot be read
    if (nodes.size() < static_cast<std::size_t>(scene.dim() + 1))
      throw SceneError(fmt::format("{}: key 'nodes.file': {} holds {} point{}; a triangulation of a {}D domain needs at least {}",
                                   scene.source, n.file.string(), nodes.size(), nodes.size() == 1 ? "" : "s", scene.dim(),
                                   scene.dim() + 1));
    return nodes;
  }
  return std::nullopt;
}

std::string point_text(std::span<const double> x) {
  std::string s = "(";
  for (std::size_t i = 0; i < x.size(); ++i) s += (i == 0 ? "" : ", ") + scene_detail::format_number(x[i]);
  return s + ")";
}

/// The values an expression of [initial], [coefficients] or [[dirichlet]] takes at the nodes where
/// the run evaluates it must be finite and at most kLargestSceneNumber in magnitude, like the
/// scene's numbers: a Dirichlet value of log(x[0]) on a side through x[0] = 0 put -inf into the
/// right-hand side and the solve returned NaN. `components`: the components the run uses.
void check_expression_at(const BoundScene& b, const BoundValue& value, const std::string& expression, int size,
                         const std::vector<int>& components, const NodeSet& nodes, std::span<const int> at, const std::string& where,
                         const std::string& on) {
  if (!value.is_expression()) return;
  std::vector<double> out(static_cast<std::size_t>(size));
  auto check = [&](std::size_t n) {
    const auto x = nodes.point(n);
    b.expressions->evaluate(value.expression, x, out);
    for (const int c : components) {
      const double v = out[static_cast<std::size_t>(c)];
      if (std::isfinite(v) && std::abs(v) <= kLargestSceneNumber) continue;
      const std::string component = size > 1 ? fmt::format(" (component {})", c) : std::string();
      throw SceneError(fmt::format("{}: the expression \"{}\" is {}{} at the node {}{}: {}", where, expression,
                                   scene_detail::format_number(v), component, point_text(x), on,
                                   std::isfinite(v) ? fmt::format("scene values are at most {} in magnitude (products and squares of "
                                                                  "larger ones overflow a solve)",
                                                                  scene_detail::format_number(kLargestSceneNumber))
                                                    : std::string("a solve needs finite values; change the expression where it is not")));
    }
  };
  if (at.empty())
    for (std::size_t n = 0; n < nodes.size(); ++n) check(n);
  else
    for (const int n : at) check(static_cast<std::size_t>(n));
}

/// The expressions of the nodal fields and Dirichlet values, at the nodes when they are known.
void check_expression_values(const Scene& scene, const BoundScene& b) {
  const std::optional<NodeSet> nodes = known_nodes(scene, b.comm);
  if (!nodes) return;
  auto all = [](int n) {
    std::vector<int> c(static_cast<std::size_t>(n));
    for (int i = 0; i < n; ++i) c[static_cast<std::size_t>(i)] = i;
    return c;
  };
  for (std::size_t i = 0; i < b.initial.size(); ++i) {
    const BoundNodalField& f = b.initial[i];
    if (!f.file.empty() || !f.value.is_expression()) continue;
    const int size = b.unknown(f.name).components;
    check_expression_at(b, f.value, scene.initial[i].value.expression(), size, all(size), *nodes, {}, f.where, "");
  }
  for (std::size_t i = 0; i < b.coefficients.size(); ++i) {
    const BoundNodalField& f = b.coefficients[i];
    if (!f.file.empty() || !f.value.is_expression()) continue;
    const auto c = std::find_if(b.coefficient_fields.begin(), b.coefficient_fields.end(),
                                [&](const UnknownField& x) { return x.name == f.name; });
    check_expression_at(b, f.value, scene.coefficients[i].value.expression(), c->components, all(c->components), *nodes, {}, f.where, "");
  }
  for (std::size_t i = 0; i < b.dirichlet.size(); ++i) {
    const BoundDirichlet& d = b.dirichlet[i];
    if (!d.value.is_expression()) continue;
    for (const auto& part : d.parts) {
      const std::vector<int> on = boundary_nodes(b.geometry, *nodes, part);
      check_expression_at(b, d.value, scene.dirichlet[i].value.expression(), d.field.components, d.components, *nodes, on,
                          scene.dirichlet[i].value.where, " on '" + part + "'");
    }
  }
}

}  // namespace

std::vector<const BoundOutput*> BoundScene::outputs() const {
  std::vector<const BoundOutput*> out;
  for (const auto& e : energy) out.push_back(&e);
  for (const auto& c : constraints) out.push_back(&c.output);
  for (const auto* o : {&residual, &bilinear, &linear})
    if (o->has_value()) out.push_back(&**o);
  for (const auto& a : auxiliary) out.push_back(&a);
  return out;
}

LmeOptions BoundScene::lme(AxisParity parity) const {
  LmeOptions o = lme_options(discretization.spacing_smoothing, axisymmetric, parity, discretization.basis, discretization.support_tolerance);
  if (!discretization.mirrors.empty()) {
    if (parity == AxisParity::odd)
      throw SceneError(fmt::format("{}: this problem moves the nodes or solves for a velocity, whose normal component is odd across a plane "
                                   "of symmetry; leave out [domain] mirror",
                                   source));
    o.mirrors.insert(o.mirrors.end(), discretization.mirrors.begin(), discretization.mirrors.end());
  }
  return o;
}

BoundScene bind_scene(const Scene& scene, MPI_Comm comm, std::ostream* log, const StationaryDriver& solver, const OutputRoles& extra) {
  BoundScene b;
  b.scene = &scene;
  b.source = scene.source;
  b.comm = comm;
  b.dim = scene.dim();
  b.axisymmetric = scene.axisymmetric();
  b.domain = scene.domain;
  b.geometry = scene.geometry;
  b.boundary_points = scene.nodes.boundary_points;
  b.discretization = {scene.nodes.gamma, scene.nodes.quadrature_points, scene.nodes.spacing_smoothing, scene.nodes.consistent_integration,
                      scene.nodes.basis, scene.nodes.partition, scene.nodes.support_tolerance, scene.mirrors};
  b.solver = &solver;
  OutputRoles roles = solver.roles(scene);
  roles.auxiliary.insert(roles.auxiliary.end(), extra.auxiliary.begin(), extra.auxiliary.end());
  roles.provided_constants.insert(roles.provided_constants.end(), extra.provided_constants.begin(), extra.provided_constants.end());

  load_modules(scene, comm, log, b);
  bind_outputs(scene, roles, b);
  bind_layout(scene, b);
  // Only a scalar is even across a plane of symmetry; a vector's normal component is odd.
  if (!scene.mirrors.empty())
    for (const auto& f : b.layout.fields)
      if (f.components != 1)
        throw SceneError(fmt::format("{}: planes of symmetry need scalar unknowns (the basis is even across them); '{}' has {} components, "
                                     "whose normal one is odd across the plane",
                                     scene.mirror_where, f.name, f.components));
  bind_boundary_parts(scene, b);
  bind_constants(scene, roles, b);
  bind_constraint_targets(scene, roles, b);
  bind_parameters(scene, b);
  // A driver's constants are set at solve time: expressions see them as 0.
  std::map<std::string, double, std::less<>> expression_constants = b.constants;
  for (auto& [name, value] : expression_constants)
    if (std::isnan(value)) value = 0;
  b.expressions = std::make_shared<PointExpressions>(b.dim, expression_constants);
  bind_qdata(scene, b);
  bind_nodal_data(scene, b);
  bind_bounds(scene, b);
  bind_point_outputs(scene, b);
  bind_reference(scene, comm, log, expression_constants, b);
  bind_saddle_point(scene, b);
  bind_quantities(scene, comm, log, expression_constants, b);
  b.expressions->compile(comm, log);
  check_expression_values(scene, b);
  return b;
}

BoundScene bind_scene(const Scene& scene, MPI_Comm comm, std::ostream* log, const OutputRoles& extra) {
  return bind_scene(scene, comm, log, stationary_driver_for(scene), extra);
}

}  // namespace lmeform::problems
