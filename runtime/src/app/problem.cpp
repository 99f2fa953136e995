#include "problem.hpp"
#include "linear_solve.hpp"

#include <petscsnes.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>
#include <memory>
#include <numeric>
#include <optional>
#include <ostream>
#include <set>
#include <sstream>
#include <cstdlib>

#include <Eigen/Sparse>
#include <fmt/format.h>
#include <fmt/ranges.h>

#include "lmeform/assembler.hpp"
#include "lmeform/convex_hull.hpp"
#include "lmeform/cvt.hpp"
#include "lmeform/delaunay.hpp"
#include "lmeform/discretization.hpp"
#include "lmeform/node_sets.hpp"
#include "lmeform/output.hpp"

// PETSc callbacks of the residual problem, at global scope: inside namespace lmeform the name
// PetscError would find lmeform::PetscError, not the PETSc function PETSc's macros call.
namespace {

struct SnesContext {
  lmeform::Assembler* residual;
  const std::vector<PetscInt>* fixed;
};

PetscErrorCode snes_residual(SNES, Vec u, Vec r, void* ctx) {
  auto* c = static_cast<SnesContext*>(ctx);
  try {
    c->residual->vector(u, r);
    // Fixed dofs hold their prescribed values: their equations are u_i − g_i = 0, satisfied from the start.
    std::vector<PetscScalar> zeros(c->fixed->size(), 0.0);
    PetscCall(VecSetValues(r, static_cast<PetscInt>(c->fixed->size()), c->fixed->data(), zeros.data(), INSERT_VALUES));
    PetscCall(VecAssemblyBegin(r));
    PetscCall(VecAssemblyEnd(r));
  } catch (const std::exception& e) {
    SETERRQ(PETSC_COMM_SELF, PETSC_ERR_LIB, "%s", e.what());
  }
  return 0;
}

PetscErrorCode snes_jacobian(SNES, Vec u, Mat J, Mat, void* ctx) {
  auto* c = static_cast<SnesContext*>(ctx);
  try {
    c->residual->matrix(u, J);
    PetscCall(MatZeroRowsColumns(J, static_cast<PetscInt>(c->fixed->size()), c->fixed->data(), 1.0, nullptr, nullptr));
  } catch (const std::exception& e) {
    SETERRQ(PETSC_COMM_SELF, PETSC_ERR_LIB, "%s", e.what());
  }
  return 0;
}

}  // namespace

namespace lmeform::app {

std::string did_you_mean(std::string_view name, const std::vector<std::string>& candidates) {
  const std::string guess = closest_name(name, candidates);
  return guess.empty() ? std::string() : "; did you mean '" + guess + "'?";
}

namespace {

const char* kind_name(kernel::FunctionalKind k) {
  switch (k) {
    case kernel::FunctionalKind::Energy: return "energy";
    case kernel::FunctionalKind::Constraint: return "constraint";
    case kernel::FunctionalKind::Residual: return "residual";
    case kernel::FunctionalKind::Bilinear: return "bilinear";
    case kernel::FunctionalKind::Linear: return "linear";
  }
  return "?";
}

/// "module.output" or "output" of `kind` among the modules, in the scene's dimension.
const kernel::FormKernels* find_output(const BoundScene& b, const SceneName& name, kernel::FunctionalKind kind) {
  const int dim = b.scene->dim();
  std::string module_name, output = name.name;
  if (const auto dot = name.name.find('.'); dot != std::string::npos && !name.name.ends_with(".form")) {
    module_name = name.name.substr(0, dot);
    output = name.name.substr(dot + 1);
  }
  std::vector<const kernel::FormKernels*> found;
  std::vector<std::string> candidates;
  for (const FormModule* m : b.modules) {
    if (!module_name.empty() && m->name != module_name) continue;
    for (const auto* k : m->kernels) {
      if (k->kind != kind) continue;
      if (std::find(candidates.begin(), candidates.end(), k->name) == candidates.end()) candidates.emplace_back(k->name);
      if (k->name == output && k->dim == dim) found.push_back(k);
    }
  }
  if (found.size() == 1) return found.front();
  if (found.size() > 1)
    throw SceneError(fmt::format("{} = '{}' is ambiguous: several forms define a {} '{}'; write 'module.{}'", name.where,
                                 name.name, kind_name(kind), output, output));
  // Not found: in another dimension, of another kind, or not at all.
  for (const FormModule* m : b.modules)
    for (const auto* k : m->kernels)
      if (k->name == output && (module_name.empty() || m->name == module_name)) {
        if (k->kind != kind)
          throw SceneError(fmt::format("{}: '{}' of form {} is a {} output, not a {} output", name.where, output, m->name,
                                       kind_name(k->kind), kind_name(kind)));
        std::string dims;
        for (const int d : m->dimensions()) dims += (dims.empty() ? "" : ", ") + std::to_string(d);
        throw SceneError(fmt::format("{}: form {} declares '{}' in dimension {} only; this scene is {}D", name.where,
                                     m->name, output, dims, dim));
      }
  throw SceneError(fmt::format("{}: no {} output '{}' in the scene's forms{}{}", name.where, kind_name(kind), output,
                               did_you_mean(output, candidates),
                               candidates.empty() ? fmt::format(" (they define no {} output)", kind_name(kind))
                                                  : fmt::format(" ({} outputs: '{}')", kind_name(kind),
                                                                fmt::join(candidates, "', '"))));
}

std::vector<UnknownField> unknowns_of(const kernel::FormKernels& k) {
  std::vector<UnknownField> out;
  int offset = 0;
  for (int i = 0; i < k.n_unknowns; ++i) {
    out.push_back({k.unknowns[i].name, k.unknowns[i].components, offset});
    offset += k.unknowns[i].components;
  }
  return out;
}

double seconds_since(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

}  // namespace

const UnknownField& BoundScene::unknown(std::string_view name) const {
  for (const auto& u : unknowns)
    if (u.name == name) return u;
  throw std::out_of_range("no unknown " + std::string(name));
}

std::vector<const kernel::FormKernels*> BoundScene::kernels() const {
  std::vector<const kernel::FormKernels*> out = energy;
  for (const auto& c : constraints) out.push_back(c.kernel);
  for (const auto* k : {residual, bilinear, linear})
    if (k != nullptr) out.push_back(k);
  out.insert(out.end(), auxiliary.begin(), auxiliary.end());
  return out;
}

BoundScene bind_scene(const Scene& scene, MPI_Comm comm, std::ostream* log, const std::vector<std::string>& provided_constants,
                      const std::vector<std::string>& provided_qdata, const std::vector<SceneName>& auxiliary_energies) {
  BoundScene b;
  b.scene = &scene;
  b.kind = scene.model.kind;
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
  const int dim = scene.dim();

  // The outputs that make the problem.
  switch (b.kind) {
    case ProblemKind::minimization:
      if (scene.model.energy.empty()) {
        for (const FormModule* m : b.modules)
          for (const auto* k : m->kernels)
            if (k->kind == kernel::FunctionalKind::Energy && k->dim == dim) b.energy.push_back(k);
        if (b.energy.empty())
          throw SceneError(fmt::format("{}: key 'model': the forms define no energy output in dimension {}; name the "
                                       "problem's outputs with model.energy, model.residual or model.bilinear + model.linear",
                                       scene.source, dim));
      } else {
        for (const auto& e : scene.model.energy) b.energy.push_back(find_output(b, e, kernel::FunctionalKind::Energy));
      }
      break;
    case ProblemKind::residual: b.residual = find_output(b, *scene.model.residual, kernel::FunctionalKind::Residual); break;
    case ProblemKind::linear:
      b.bilinear = find_output(b, *scene.model.bilinear, kernel::FunctionalKind::Bilinear);
      b.linear = find_output(b, *scene.model.linear, kernel::FunctionalKind::Linear);
      break;
  }
  if (b.kind != ProblemKind::minimization && !scene.constraints.empty())
    throw SceneError(fmt::format("{}: [constraints] apply to energy minimization; this scene solves a {} problem",
                                 scene.constraints.front().where, b.kind == ProblemKind::residual ? "residual" : "linear"));

  for (const auto& a : auxiliary_energies) b.auxiliary.push_back(find_output(b, a, kernel::FunctionalKind::Energy));

  // Constraints, by the form's constraint output names.
  for (const auto& c : scene.constraints) {
    BoundConstraint bc;
    bc.name = c.name;
    bc.kernel = find_output(b, {c.name, c.where}, kernel::FunctionalKind::Constraint);
    if (bc.kernel->target_constant >= 0) bc.target_constant = bc.kernel->constants[bc.kernel->target_constant];
    b.constraints.push_back(bc);
  }

  // One layout of unknowns for every kernel.
  const kernel::FormKernels* primary = b.kind == ProblemKind::minimization ? b.energy.front()
                                       : b.kind == ProblemKind::residual   ? b.residual
                                                                           : b.bilinear;
  b.unknowns = unknowns_of(*primary);
  b.dofs_per_node = primary->dofs_per_node;
  for (const auto* k : b.kernels()) {
    const bool auxiliary = std::find(b.auxiliary.begin(), b.auxiliary.end(), k) != b.auxiliary.end();
    if (auxiliary && k->dofs_per_node != b.dofs_per_node)
      throw SceneError(fmt::format("{}: {}.{} has {} dofs per node, the problem {}", scene.source, k->module, k->name,
                                   k->dofs_per_node, b.dofs_per_node));
    const auto u = unknowns_of(*k);
    bool same = auxiliary || u.size() == b.unknowns.size();
    for (std::size_t i = 0; same && !auxiliary && i < u.size(); ++i)
      same = u[i].components == b.unknowns[i].components &&
             (k->kind == kernel::FunctionalKind::Linear || primary->kind == kernel::FunctionalKind::Bilinear ||
              u[i].name == b.unknowns[i].name);
    if (!same)
      throw SceneError(fmt::format("{}: the outputs {}.{} and {}.{} have different unknowns: a scene's outputs share "
                                   "one set of unknown fields (names, shapes and order)",
                                   scene.source, primary->module, primary->name, k->module, k->name));
    for (int i = 0; i < k->n_coefficients; ++i) {
      const kernel::FieldInfo& c = k->coefficients[i];
      if (auxiliary && std::any_of(b.unknowns.begin(), b.unknowns.end(), [&](const UnknownField& f) { return f.name == c.name; }))
        continue;  // the unknown's current value, set by the model
      const auto known = std::find_if(b.coefficients.begin(), b.coefficients.end(),
                                      [&](const UnknownField& f) { return f.name == c.name; });
      if (known == b.coefficients.end()) b.coefficients.push_back({c.name, c.components, 0});
      else if (known->components != c.components)
        throw SceneError(fmt::format("{}: {}.{} reads the coefficient '{}' with {} components, another output with {}",
                                     scene.source, k->module, k->name, c.name, c.components, known->components));
    }
    b.basis_order = std::max({b.basis_order, k->basis_order, k->coefficient_basis_order});
  }

  // Constants: the scene's value, else the form's default; every scene constant must be a form's.
  std::vector<std::string> form_constants;
  for (const auto* k : b.kernels())
    for (int i = 0; i < k->n_constants; ++i)
      if (std::find(form_constants.begin(), form_constants.end(), k->constants[i]) == form_constants.end())
        form_constants.emplace_back(k->constants[i]);
  const std::string constant_list =
      form_constants.empty() ? std::string("they have none") : fmt::format("{}", fmt::join(form_constants, ", "));
  for (const auto& [name, value] : scene.constants) {
    if (std::find(form_constants.begin(), form_constants.end(), name) != form_constants.end()) continue;
    throw SceneError(fmt::format("{}: no form of the problem has a constant '{}'{} (the forms' constants: {})",
                                 scene.where_constant(name), name, did_you_mean(name, form_constants), constant_list));
  }
  for (const auto* k : b.kernels()) {
    for (int i = 0; i < k->n_constants; ++i) {
      const std::string name = k->constants[i];
      if (b.constants.contains(name)) continue;
      if (const auto it = scene.constants.find(name); it != scene.constants.end()) {
        b.constants[name] = it->second;
        continue;
      }
      const bool is_target = std::any_of(b.constraints.begin(), b.constraints.end(),
                                         [&](const BoundConstraint& c) { return c.target_constant == name; });
      // (a target of a constraint given "initial" is set from the start state in build_problem_space)
      const bool provided = std::find(provided_constants.begin(), provided_constants.end(), name) != provided_constants.end();
      if (k->constant_defaults != nullptr && !std::isnan(k->constant_defaults[i])) {
        b.constants[name] = k->constant_defaults[i];
      } else if (is_target || provided) {
        b.constants[name] = std::numeric_limits<double>::quiet_NaN();  // set from the target / by the model
      } else {
        throw SceneError(fmt::format("{}: missing key 'constants.{}': form {} ({}) needs the constant '{}' and gives it "
                                     "no default (the forms' constants: {})",
                                     scene.source, name, k->module, k->source, name, constant_list));
      }
    }
  }
  // Constraint targets: [constraints] NAME = target, else the form's target constant or number.
  for (std::size_t i = 0; i < b.constraints.size(); ++i) {
    BoundConstraint& bc = b.constraints[i];
    const SceneConstraint& sc = scene.constraints[i];
    if (sc.target) {
      bc.target = *sc.target;
      if (!bc.target_constant.empty()) {
        if (scene.constants.contains(bc.target_constant) && scene.constants.at(bc.target_constant) != *sc.target)
          throw SceneError(fmt::format("{}: the target {} differs from {} = {} in [constants] (the constant is the "
                                       "constraint's target: give it once)",
                                       sc.where, *sc.target, bc.target_constant, scene.constants.at(bc.target_constant)));
        b.constants[bc.target_constant] = *sc.target;
      }
    } else if (sc.initial) {
      bc.initial = true;
      bc.target = std::numeric_limits<double>::quiet_NaN();
    } else if (bc.target_constant.empty()) {
      bc.target = bc.kernel->target_value;
    } else {
      bc.target = b.constants.at(bc.target_constant);
      const bool provided = std::find(provided_constants.begin(), provided_constants.end(), bc.target_constant) !=
                            provided_constants.end();
      if (std::isnan(bc.target) && !provided)
        throw SceneError(fmt::format("{}: constraint '{}' compares with the constant '{}', which has no value: give "
                                     "constraints.{} = TARGET or constants.{}",
                                     sc.where, bc.name, bc.target_constant, bc.name, bc.target_constant));
    }
    bc.scale = sc.scale.value_or(std::abs(bc.target) > 0 ? std::abs(bc.target) : 1.0);  // "initial": set with the target
  }

  // Quadrature data: every datum the kernels read is supplied by the scene or by the model.
  std::vector<std::string> needed;
  for (const auto* k : b.kernels())
    for (int i = 0; i < k->n_qdata; ++i)
      if (std::find(needed.begin(), needed.end(), k->qdata[i].name) == needed.end()) needed.emplace_back(k->qdata[i].name);
  for (const auto& q : scene.qdata) {
    if (std::find(needed.begin(), needed.end(), q.name) != needed.end()) continue;
    throw SceneError(fmt::format("{}: no form of the problem reads quadrature data '{}'{} ({})", q.where, q.name,
                                 did_you_mean(q.name, needed),
                                 needed.empty() ? std::string("they read none")
                                                : fmt::format("they read: {}", fmt::join(needed, ", "))));
  }
  for (const auto& n : needed) {
    const bool given = std::any_of(scene.qdata.begin(), scene.qdata.end(), [&](const SceneQdata& q) { return q.name == n; });
    const bool provided = std::find(provided_qdata.begin(), provided_qdata.end(), n) != provided_qdata.end();
    if (!given && !provided)
      throw SceneError(fmt::format("{}: missing key 'qdata.{}': the forms read the quadrature datum '{}' (give a "
                                   "provider: \"support_size\", \"zero\", a number or an expression of x)",
                                   scene.source, n, n));
  }

  // Unknown names in [initial], [[dirichlet]] and [reference.solution]; their expressions.
  std::vector<std::string> unknown_names;
  for (const auto& u : b.unknowns) unknown_names.push_back(u.name);
  auto check_unknown = [&](const std::string& name, const std::string& where) -> const UnknownField& {
    for (const auto& u : b.unknowns)
      if (u.name == name) return u;
    throw SceneError(fmt::format("{}: '{}' is no unknown of the problem{} (unknowns: {})", where, name,
                                 did_you_mean(name, unknown_names), fmt::join(unknown_names, ", ")));
  };
  std::map<std::string, double, std::less<>> expression_constants = b.constants;
  for (auto& [name, value] : expression_constants)
    if (std::isnan(value)) value = 0;  // a model's constant: set at solve time, not usable in expressions
  b.expressions = std::make_shared<PointExpressions>(dim, expression_constants);
  for (const auto& f : scene.initial) {
    const UnknownField& u = check_unknown(f.unknown, f.where);
    int handle = -1;
    if (f.kind == SceneInitialField::Kind::value && !f.value.is_number())
      handle = b.expressions->add(f.value.expression(), u.components, f.where);
    b.initial_expression.push_back(handle);
  }
  // Scalar nodal fields that quadrature data interpolate are coefficients too.
  for (const auto& q : scene.qdata) {
    if (q.provider != "field") continue;
    int size = 0;
    for (const auto* k : b.kernels())
      for (int i = 0; i < k->n_qdata; ++i)
        if (k->qdata[i].name == q.name) size = k->qdata[i].size;
    const int expected = q.derivative == 0 ? 1 : q.derivative == 1 ? dim : dim * dim;
    if (size != expected)
      throw SceneError(fmt::format("{}: '{}' has {} values per point; the {} of a scalar field has {}", q.where, q.name, size,
                                   q.derivative == 0 ? "value" : q.derivative == 1 ? "gradient" : "Hessian", expected));
    const auto known = std::find_if(b.coefficients.begin(), b.coefficients.end(), [&](const UnknownField& f) { return f.name == q.field; });
    if (known == b.coefficients.end()) b.coefficients.push_back({q.field, 1, 0});
    else if (known->components != 1)
      throw SceneError(fmt::format("{}: key 'field': '{}' has {} components; quadrature data interpolate scalar fields", q.where,
                                   q.field, known->components));
    b.basis_order = std::max(b.basis_order, q.derivative);
  }
  std::vector<std::string> coefficient_names;
  for (const auto& c : b.coefficients) coefficient_names.push_back(c.name);
  for (const auto& f : scene.coefficients) {
    const auto c = std::find_if(b.coefficients.begin(), b.coefficients.end(),
                                [&](const UnknownField& x) { return x.name == f.unknown; });
    if (c == b.coefficients.end()) {
      throw SceneError(fmt::format("{}: '{}' is no coefficient field of the forms{} ({})", f.where, f.unknown,
                                   did_you_mean(f.unknown, coefficient_names),
                                   coefficient_names.empty() ? std::string("they read none")
                                                             : fmt::format("they read: {}", fmt::join(coefficient_names, ", "))));
    }
    int handle = -1;
    if (f.kind == SceneInitialField::Kind::value && !f.value.is_number())
      handle = b.expressions->add(f.value.expression(), c->components, f.where);
    b.coefficient_expression.push_back(handle);
  }
  for (const auto& c : b.coefficients)
    if (std::none_of(scene.coefficients.begin(), scene.coefficients.end(),
                     [&](const SceneInitialField& f) { return f.unknown == c.name; }))
      throw SceneError(fmt::format("{}: missing key 'coefficients.{}': the forms read the known nodal field '{}' ({} "
                                   "component{}; give a number, an expression of x or {{file, field}})",
                                   scene.source, c.name, c.name, c.components, c.components == 1 ? "" : "s"));
  for (const auto& d : scene.dirichlet) {
    const UnknownField& u = check_unknown(d.unknown, d.where + ": key 'unknown'");
    for (const int c : d.components)
      if (c >= u.components)
        throw SceneError(fmt::format("{}: key 'components' lists component {} of '{}', which has {}", d.where, c, u.name,
                                     u.components));
    int handle = -1;
    if (!d.value.is_number()) handle = b.expressions->add(d.value.expression(), u.components, d.value.where);
    b.dirichlet_expression.push_back(handle);
  }
  for (const auto& q : scene.qdata) {
    if (q.provider != "value") continue;
    int size = 0;
    for (const auto* k : b.kernels())
      for (int i = 0; i < k->n_qdata; ++i)
        if (k->qdata[i].name == q.name) size = k->qdata[i].size;
    if (size != 1 && size != dim)
      throw SceneError(fmt::format("{}: '{}' has {} values per point; a value or an expression gives a scalar or a "
                                   "vector",
                                   q.where, q.name, size));
    b.qdata_expression[q.name] =
        q.value.is_number() ? -1 : b.expressions->add(q.value.expression(), size, q.value.where);
  }
  for (const auto& z : scene.model.zero_mean) {
    const UnknownField& u = check_unknown(z.name, z.where);
    if (u.components != 1)
      throw SceneError(fmt::format("{}: '{}' is a vector; model.zero_mean takes scalar unknowns", z.where, u.name));
    b.zero_mean.push_back(u.name);
  }
  if (!b.zero_mean.empty()) (void)compile_integral_form(dim, comm, log);  // compiled now, not during the solve
  b.expressions->compile(comm, log);
  for (const auto& [name, value] : scene.reference.solution) {
    const UnknownField& u = check_unknown(name, value.where);
    if (value.is_number()) throw SceneError(fmt::format("{}: an exact solution is an expression string", value.where));
    // Compiled now, so that a typo is reported before the solve, not after it.
    (void)compile_error_form(dim, name, u.components, value.expression(), expression_constants, value.where, comm, log);
  }
  return b;
}

NodeSet initial_nodes(const Scene& scene, std::ostream* log) {
  switch (scene.nodes.kind) {
    case SceneNodes::Kind::spacing: return uniform_grid(scene.domain, scene.nodes.spacing);
    case SceneNodes::Kind::counts: return uniform_grid(scene.domain, scene.nodes.counts);
    case SceneNodes::Kind::count: {
      const auto t0 = std::chrono::steady_clock::now();
      CvtOptions cvt;
      cvt.iterations = scene.nodes.lloyd_iterations;
      CvtReport report;
      NodeSet nodes = uniform_cvt(scene.domain, static_cast<std::size_t>(scene.nodes.count), cvt, &report);
      if (log != nullptr) {
        *log << "uniform CVT of " << nodes.size() << " nodes: " << report.iterations.size() << " Lloyd iterations"
             << (report.iterations.empty() ? std::string()
                                           : ", last mean move " + std::to_string(report.iterations.back().mean_displacement / report.h_bar) + " h")
             << ", " << seconds_since(t0) << " s\n";
      }
      return nodes;
    }
    case SceneNodes::Kind::file: {
      try {
        // A previous run's output (HDF5): its nodes, so that its fields can be read back on them.
        if (scene.nodes.file.extension() == ".h5") {
          NodeSet nodes = read_field_hdf5(scene.nodes.file).nodes;
          if (nodes.dim != scene.dim())
            throw std::runtime_error(fmt::format("{} holds {}D nodes, the scene is {}D", scene.nodes.file.string(), nodes.dim, scene.dim()));
          return nodes;
        }
        return read_points(scene.nodes.file, scene.dim(), &scene.domain);
      } catch (const std::runtime_error& e) {
        throw SceneError(fmt::format("{}: key 'nodes.file': {}", scene.source, e.what()));
      }
    }
  }
  throw std::logic_error("unknown node kind");
}

std::vector<int> boundary_nodes(const Scene& scene, const NodeSet& nodes, const std::string& part) {
  if (part == "hull") return hull_boundary_nodes(nodes);
  const Box& box = scene.domain;
  double extent = 0;
  for (int i = 0; i < box.dim; ++i) extent = std::max(extent, box.hi[std::size_t(i)] - box.lo[std::size_t(i)]);
  const double tol = 1e-9 * extent;
  int axis = 0;
  bool upper = false;
  if (part == "axis") {
    axis = 0;
  } else {
    static const std::string names[] = {"x", "y", "z"};
    const std::string a = part.substr(0, part.find('_'));
    axis = a == "r" ? 0 : (scene.axisymmetric() && a == "z") ? 1 : static_cast<int>(std::find(names, names + 3, a) - names);
    upper = part.ends_with("_max");
  }
  const auto k = static_cast<std::size_t>(axis);
  std::vector<int> out;
  for (std::size_t n = 0; n < nodes.size(); ++n) {
    const double x = nodes.point(n)[k];
    if (upper ? x >= box.hi[k] - tol : x <= box.lo[k] + tol) out.push_back(static_cast<int>(n));
  }
  return out;
}

std::vector<std::vector<int>> dirichlet_nodes(const Scene& scene, const NodeSet& nodes) {
  std::vector<std::vector<int>> out;
  for (const SceneDirichlet& d : scene.dirichlet) {
    std::set<int> on;
    for (const auto& part : d.boundary)
      for (const int n : boundary_nodes(scene, nodes, part)) on.insert(n);
    if (on.empty()) throw SceneError(fmt::format("{}: no node lies on the boundary parts given in key 'boundary'", d.where));
    out.emplace_back(on.begin(), on.end());
  }
  return out;
}

namespace {

/// Values at the nodes (original order, dofs interleaved as in `layout`, `per_node` per node) of
/// the nodal fields of a scene table ([initial], [coefficients]): numbers, expressions (handles into
/// the scene's expressions, -1 for a number) or fields of a previous run's output on the same nodes.
std::vector<double> nodal_values(const BoundScene& b, const std::vector<SceneInitialField>& entries,
                                 const std::vector<int>& handles, const std::vector<UnknownField>& layout, int per_node,
                                 const NodeSet& nodes) {
  const auto bs = static_cast<std::size_t>(per_node);
  std::vector<double> state(nodes.size() * bs, 0.0);
  std::vector<double> value(3);
  for (std::size_t i = 0; i < entries.size(); ++i) {
    const SceneInitialField& f = entries[i];
    const auto field = std::find_if(layout.begin(), layout.end(), [&](const UnknownField& u) { return u.name == f.unknown; });
    if (field == layout.end()) continue;
    const UnknownField& u = *field;
    const auto off = static_cast<std::size_t>(u.offset);
    if (f.kind == SceneInitialField::Kind::file) {
      const FieldFile file = read_field_hdf5(f.file);
      const auto it = file.fields.find(f.field);
      if (it == file.fields.end()) throw SceneError(fmt::format("{}: {} has no field '{}'", f.where, f.file.string(), f.field));
      if (it->second.components != u.components)
        throw SceneError(fmt::format("{}: field '{}' of {} has {} components, '{}' has {}", f.where, f.field,
                                     f.file.string(), it->second.components, u.name, u.components));
      if (file.nodes.size() != nodes.size() || file.nodes.coords != nodes.coords)
        throw SceneError(fmt::format("{}: {} was computed on other nodes ({} nodes); a field is read back on the node set "
                                     "it was written with (same [nodes])",
                                     f.where, f.file.string(), file.nodes.size()));
      for (std::size_t a = 0; a < nodes.size(); ++a)
        for (int c = 0; c < u.components; ++c)
          state[a * bs + off + std::size_t(c)] = it->second.values[a * std::size_t(u.components) + std::size_t(c)];
      continue;
    }
    const int handle = handles[i];
    for (std::size_t a = 0; a < nodes.size(); ++a) {
      if (handle >= 0) b.expressions->evaluate(handle, nodes.point(a), value);
      else std::fill(value.begin(), value.end(), f.value.number());
      for (int c = 0; c < u.components; ++c) state[a * bs + off + std::size_t(c)] = value[std::size_t(c)];
    }
  }
  return state;
}

// On a strongly graded node set a point of a long cell can lie outside the hull of the nodes whose
// supports reach it, or see only collinear ones (measured: carried and new quadrature points beside
// the waist of the eps = 0.01 prolate at a re-mesh, 41 neighbours all on the fine side). The
// vertices of a cell holding the point restore the hull, as the discretization's own point lists
// do. `cell_vertices` is asked only then; it returns the vertices in the basis' numbering, or none.
template <class CellVertices>
std::vector<double> evaluate_with_cell_fallback(const LmeBasis& basis, std::span<const double> x, std::vector<int>& list, int order,
                                                CellVertices&& cell_vertices) {
  try {
    return basis.evaluate(x, list, order);
  } catch (const LmeEvaluationError& e) {
    const auto r = e.reason();
    if (r != LmeFailure::outside_hull && r != LmeFailure::degenerate && r != LmeFailure::too_few_neighbours &&
        r != LmeFailure::singular_jacobian)  // at a vertex of its neighbours' hull
      throw;
    const std::vector<int> vertices = cell_vertices();
    if (vertices.empty()) throw;
    for (const int v : vertices)
      if (std::find(list.begin(), list.end(), v) == list.end()) list.push_back(v);
    std::sort(list.begin(), list.end());
    return basis.evaluate(x, list, order);
  }
}

}  // namespace

std::vector<double> interpolate_nodal_field(const NodeSet& old_nodes, std::span<const double> phi, double gamma, const LmeOptions& lme,
                                            const NodeSet& new_nodes, std::size_t* nearest_fallbacks) {
  const std::vector<double> gammas(old_nodes.size(), gamma);
  const LmeBasis basis(old_nodes, gammas, lme);
  std::vector<double> out(new_nodes.size());
  for (std::size_t a = 0; a < new_nodes.size(); ++a) {
    const auto x = new_nodes.point(a);
    const auto list = basis.neighbours(x);
    try {
      const auto p = basis.evaluate(x, list, 0);
      double v = 0;
      for (std::size_t m = 0; m < list.size(); ++m) v += p[m] * phi[static_cast<std::size_t>(list[m])];
      out[a] = v;
    } catch (const LmeEvaluationError&) {
      if (nearest_fallbacks == nullptr) throw;
      double best = std::numeric_limits<double>::infinity();
      for (std::size_t b = 0; b < old_nodes.size(); ++b) {
        double d2 = 0;
        for (int i = 0; i < old_nodes.dim; ++i) d2 += std::pow(old_nodes.point(b)[std::size_t(i)] - x[std::size_t(i)], 2);
        if (d2 < best) best = d2, out[a] = phi[b];
      }
      ++*nearest_fallbacks;
    }
  }
  return out;
}

std::vector<double> fit_nodal_values(const NodeSet& nodes, std::span<const double> values, double gamma, const LmeOptions& lme,
                                     int iterations) {
  if (values.size() != nodes.size())
    throw std::invalid_argument(fmt::format("fit_nodal_values: {} values for {} nodes", values.size(), nodes.size()));
  std::vector<double> phi(values.begin(), values.end());
  if (iterations <= 0) return phi;
  const LmeBasis basis(nodes, std::vector<double>(nodes.size(), gamma), lme);
  std::vector<std::vector<int>> rows(nodes.size());
  std::vector<std::vector<double>> weights(nodes.size());
  for (std::size_t node = 0; node < nodes.size(); ++node) {
    rows[node] = basis.neighbours(nodes.point(node));
    weights[node] = basis.evaluate(nodes.point(node), rows[node], 0);
  }
  std::vector<double> next(phi.size());
  for (int it = 0; it < iterations; ++it) {
    for (std::size_t node = 0; node < nodes.size(); ++node) {
      double v = 0;
      for (std::size_t m = 0; m < rows[node].size(); ++m) v += weights[node][m] * phi[std::size_t(rows[node][m])];
      next[node] = phi[node] + values[node] - v;
    }
    phi.swap(next);
  }
  return phi;
}

PointProjection project_point_values(const NodeSet& nodes, double gamma, const LmeOptions& lme, std::span<const double> points,
                                     std::span<const double> weights, std::span<const double> values, std::span<const double> start,
                                     double tolerance, int max_iterations, PointGradients gradients) {
  const int dim = nodes.dim;
  const std::size_t n = nodes.size();
  if (points.size() != weights.size() * std::size_t(dim) || values.size() != weights.size() || start.size() != n)
    throw std::invalid_argument(fmt::format("project_point_values: {} coordinates, {} weights, {} values and {} start values "
                                            "do not match {} nodes in dimension {}",
                                            points.size(), weights.size(), values.size(), start.size(), n, dim));
  const bool h1 = gradients.length > 0 && !gradients.values.empty();
  if (h1 && gradients.values.size() != weights.size() * std::size_t(dim))
    throw std::invalid_argument(fmt::format("project_point_values: {} gradient values for {} points in dimension {}",
                                            gradients.values.size(), weights.size(), dim));
  if (gradients.length < 0) throw std::invalid_argument("project_point_values: the gradient length must not be negative");
  const double l2 = gradients.length * gradients.length;
  const std::size_t jets = h1 ? std::size_t(1 + dim) : 1;  // value, then each derivative, per neighbour
  const LmeBasis basis(nodes, std::vector<double>(n, gamma), lme);
  struct Row {
    double weight;
    std::vector<int> nodes;
    std::vector<double> p;
  };
  std::vector<Row> rows;
  std::optional<BackgroundCells> cells;  // for points the plain neighbour lists cannot evaluate
  std::optional<CellLocator> locator;
  auto enclosing_cell = [&](std::span<const double> x) {
    if (!locator) {
      cells.emplace(delaunay(nodes));
      locator.emplace(*cells, nodes);
    }
    const long c = locator->locate(x, 1e-10);
    if (c < 0) return std::vector<int>{};
    const auto v = cells->cell(std::size_t(c));
    return std::vector<int>(v.begin(), v.end());
  };
  Eigen::VectorXd rhs = Eigen::VectorXd::Zero(Eigen::Index(n)), diagonal = Eigen::VectorXd::Zero(Eigen::Index(n));
  for (std::size_t q = 0; q < weights.size(); ++q) {
    if (weights[q] <= 0) continue;
    const std::span<const double> x = points.subspan(q * std::size_t(dim), std::size_t(dim));
    Row r{weights[q], basis.neighbours(x), {}};
    r.p = evaluate_with_cell_fallback(basis, x, r.nodes, h1 ? 1 : 0, [&] { return enclosing_cell(x); });
    r.p.resize(jets * r.nodes.size());
    const std::size_t m = r.nodes.size();
    for (std::size_t a = 0; a < m; ++a) {
      rhs[r.nodes[a]] += r.weight * r.p[a] * values[q];
      diagonal[r.nodes[a]] += r.weight * r.p[a] * r.p[a];
      for (std::size_t i = 1; i < jets; ++i) {
        const double d = r.p[i * m + a];
        rhs[r.nodes[a]] += r.weight * l2 * d * gradients.values[q * std::size_t(dim) + i - 1];
        diagonal[r.nodes[a]] += r.weight * l2 * d * d;
      }
    }
    rows.push_back(std::move(r));
  }
  for (std::size_t a = 0; a < n; ++a)
    if (!(diagonal[Eigen::Index(a)] > 0))
      throw std::runtime_error(fmt::format("project_point_values: node {} at ({}) has no point in its support", a, fmt::join(nodes.point(a), ", ")));
  auto apply_mass = [&](const Eigen::VectorXd& c) {
    Eigen::VectorXd m = Eigen::VectorXd::Zero(c.size());
    for (const Row& r : rows) {
      const std::size_t count = r.nodes.size();
      for (std::size_t i = 0; i < jets; ++i) {
        const double* p = r.p.data() + i * count;
        double v = 0;
        for (std::size_t a = 0; a < count; ++a) v += p[a] * c[r.nodes[a]];
        v *= i == 0 ? r.weight : r.weight * l2;
        for (std::size_t a = 0; a < count; ++a) m[r.nodes[a]] += v * p[a];
      }
    }
    return m;
  };
  PointProjection result;
  Eigen::VectorXd c = Eigen::Map<const Eigen::VectorXd>(start.data(), Eigen::Index(n));
  Eigen::VectorXd residual = rhs - apply_mass(c);
  const double norm_rhs = std::max(rhs.norm(), 1e-300);
  Eigen::VectorXd z = residual.cwiseQuotient(diagonal), direction = z;
  double rz = residual.dot(z);
  result.relative_residual = residual.norm() / norm_rhs;
  while (result.relative_residual > tolerance && result.iterations < max_iterations) {
    const Eigen::VectorXd md = apply_mass(direction);
    const double alpha = rz / direction.dot(md);
    c += alpha * direction;
    residual -= alpha * md;
    z = residual.cwiseQuotient(diagonal);
    const double rz_next = residual.dot(z);
    direction = z + (rz_next / rz) * direction;
    rz = rz_next;
    ++result.iterations;
    result.relative_residual = residual.norm() / norm_rhs;
  }
  result.values.assign(c.data(), c.data() + c.size());
  return result;
}

std::vector<double> coefficient_values(const BoundScene& b, const std::string& name, int components, const NodeSet& nodes) {
  if (std::none_of(b.scene->coefficients.begin(), b.scene->coefficients.end(),
                   [&](const SceneInitialField& f) { return f.unknown == name; }))
    throw SceneError(fmt::format("{}: [coefficients] gives no field '{}'", b.scene->source, name));
  return nodal_values(b, b.scene->coefficients, b.coefficient_expression, {{name, components, 0}}, components, nodes);
}

std::vector<double> initial_state(const BoundScene& b, const NodeSet& nodes) {
  return nodal_values(b, b.scene->initial, b.initial_expression, b.unknowns, b.dofs_per_node, nodes);
}

namespace {

/// ρ̄ at every quadrature point: Σ_a p_a(x_q) h_a over the point's LME neighbours, the partition of
/// unity weighting each nodal spacing by the node's share of the point. It is the local length
/// scale of the basis the point actually sees (a plain mean over the support would count far, barely
/// contributing nodes as much as the nearest ones, and jump as nodes enter the support).
std::vector<double> support_size_qdata(const Discretization& disc) {
  const auto& quad = disc.quadrature();
  const auto& lists = disc.point_lists();
  const auto h = disc.basis().spacing();
  std::vector<double> out(quad.size());
  for (std::size_t q = 0; q < quad.size(); ++q) {
    const auto list = lists[q];
    const auto p = disc.basis().evaluate(quad.point(q), list, 0);
    double s = 0;
    for (std::size_t m = 0; m < list.size(); ++m) s += p[m] * h[static_cast<std::size_t>(list[m])];
    out[q] = s;
  }
  return out;
}

/// Owned global (renumbered) dofs of (original node, component) pairs.
std::vector<PetscInt> owned_dofs(const Discretization& disc, const std::vector<std::pair<int, int>>& node_components, int bs) {
  std::vector<PetscInt> dofs;
  const auto renumbered = disc.renumbered_index();
  for (const auto& [node, comp] : node_components) {
    const int r = renumbered[static_cast<std::size_t>(node)];
    if (disc.owns(r)) dofs.push_back(static_cast<PetscInt>(r) * bs + comp);
  }
  std::sort(dofs.begin(), dofs.end());
  dofs.erase(std::unique(dofs.begin(), dofs.end()), dofs.end());
  return dofs;
}

/// PETSc options of the scene, set for the solve and cleared after it. The command line wins: an
/// option it already sets is left as it is.
class ScopedPetscOptions {
 public:
  explicit ScopedPetscOptions(const std::string& options) {
    std::vector<std::string> tokens;
    std::istringstream in(options);
    for (std::string t; in >> t;) tokens.push_back(t);
    auto is_value = [](const std::string& t) {
      if (t.empty() || t[0] != '-') return true;
      char* end = nullptr;
      (void)std::strtod(t.c_str(), &end);  // a negative number is a value, not an option
      return end != nullptr && *end == '\0';
    };
    for (std::size_t i = 0; i < tokens.size(); ++i) {
      if (is_value(tokens[i])) throw SceneError("key 'solver.petsc_options': '" + tokens[i] + "' is not an option (options start with '-')");
      const std::string key = tokens[i];
      std::string value;
      if (i + 1 < tokens.size() && is_value(tokens[i + 1])) value = tokens[++i];
      PetscBool set = PETSC_FALSE;
      LMEFORM_PETSC_CHECK(PetscOptionsHasName(nullptr, nullptr, key.c_str(), &set));
      if (set) continue;
      LMEFORM_PETSC_CHECK(PetscOptionsSetValue(nullptr, key.c_str(), value.empty() ? nullptr : value.c_str()));
      set_.push_back(key);
    }
  }
  ~ScopedPetscOptions() {
    for (const auto& key : set_) PetscOptionsClearValue(nullptr, key.c_str());
  }
  ScopedPetscOptions(const ScopedPetscOptions&) = delete;
  ScopedPetscOptions& operator=(const ScopedPetscOptions&) = delete;

 private:
  std::vector<std::string> set_;
};

void configure_direct_solver(KSP ksp) {
  // MUMPS LU by default (direct, robust for the indefinite saddle points of mixed problems); the
  // options database overrides it (-ksp_type gmres -pc_type fieldsplit ...).
  LMEFORM_PETSC_CHECK(KSPSetType(ksp, KSPPREONLY));
  PC pc = nullptr;
  LMEFORM_PETSC_CHECK(KSPGetPC(ksp, &pc));
  LMEFORM_PETSC_CHECK(PCSetType(pc, PCLU));
  LMEFORM_PETSC_CHECK(PCFactorSetMatSolverType(pc, MATSOLVERMUMPS));
}


/// φ, ∇φ or ∇∇φ of a scalar nodal field (original node order) at every quadrature point (each rank
/// computes the points of the elements it owns), jet-size values each: the reference field of a
/// Lagrangian form.
/// `field_basis` interpolates (its node b is original node `original_of[b]`); with a null basis the
/// discretization's own.
std::vector<double> interpolated_field_qdata(const Discretization& disc, std::span<const double> original_values, int derivative,
                                             const LmeBasis* field_basis) {
  const auto& quad = disc.quadrature();
  const auto& lists = disc.point_lists();
  const int dim = disc.dim();
  const std::size_t size = derivative == 0 ? 1 : derivative == 1 ? std::size_t(dim) : std::size_t(dim * dim);
  const std::size_t first = derivative == 0 ? 0 : derivative == 1 ? 1 : 1 + std::size_t(dim);
  const auto original = disc.original_index();
  std::vector<double> out(quad.size() * size, 0.0);
  std::vector<int> own_list;
  for (int e = 0; e < disc.n_elements(); ++e) {
    if (!disc.element_owned(e)) continue;  // each point once over the ranks: summed below
    for (int q = disc.element_first_point(e); q < disc.element_first_point(e) + disc.element_point_count(e); ++q) {
      const auto x = quad.point(std::size_t(q));
      std::span<const int> list = lists[std::size_t(q)];
      std::vector<double> jet;
      if (field_basis != nullptr) {
        own_list = field_basis->neighbours(x);
        jet = evaluate_with_cell_fallback(*field_basis, x, own_list, derivative, [&] {
          std::vector<int> vertices;
          for (const int v : disc.cells().cell(std::size_t(q) / std::size_t(quad.points_per_cell)))
            vertices.push_back(original[std::size_t(v)]);
          return vertices;
        });
        list = own_list;
      } else {
        jet = disc.basis().evaluate(x, list, derivative);
      }
      for (std::size_t m = 0; m < list.size(); ++m) {
        const auto node = field_basis != nullptr ? std::size_t(list[m]) : std::size_t(original[std::size_t(list[m])]);
        const double phi = original_values[node];
        if (derivative < 2) {
          for (std::size_t c = 0; c < size; ++c) out[std::size_t(q) * size + c] += jet[(first + c) * list.size() + m] * phi;
        } else {
          for (int i = 0; i < dim; ++i)
            for (int j = i; j < dim; ++j) {
              const auto row = static_cast<std::size_t>(kernel::hessian_slot(i, j, dim));
              const double v = jet[row * list.size() + m] * phi;
              out[std::size_t(q) * size + std::size_t(i * dim + j)] += v;
              if (i != j) out[std::size_t(q) * size + std::size_t(j * dim + i)] += v;
            }
        }
      }
    }
  }
  MPI_Allreduce(MPI_IN_PLACE, out.data(), static_cast<int>(out.size()), MPI_DOUBLE, MPI_SUM, disc.comm());
  return out;
}

}  // namespace

ProblemSpace build_problem_space(MPI_Comm comm, const BoundScene& b, const ProblemInput& input) {
  const Scene& scene = *b.scene;
  ProblemSpace space;
  const NodeSet& nodes = input.nodes;
  const int bs = b.dofs_per_node;

  DiscretizationOptions options;
  options.gamma = {scene.nodes.gamma};
  options.lme = input.lme;
  options.quadrature_points = scene.nodes.quadrature_points;
  options.basis_order = std::max(b.basis_order, 1);  // |∇u| at the nodes and H1 errors need gradients
  options.carried = input.carried;
  if (input.discretization) {
    if (input.carried || input.discretization->n_nodes() != static_cast<int>(nodes.size()))
      throw std::invalid_argument(fmt::format("build_problem_space: a reused discretization of {} nodes for {} nodes{}",
                                              input.discretization->n_nodes(), nodes.size(),
                                              input.carried ? " with carried quadrature" : ""));
    space.disc = input.discretization;
  } else {
    space.disc = std::make_shared<Discretization>(comm, nodes, options);
  }
  const Discretization& disc = *space.disc;

  // Constants: the bound values, the input's overrides, the constraint targets.
  std::map<std::string, double, std::less<>>& constants = space.constants;
  constants = b.constants;
  for (const auto& [name, value] : input.constants) constants[name] = value;
  std::vector<double> targets, scales;
  for (const auto& c : b.constraints) {
    double target = c.target;
    if (!c.target_constant.empty() && input.constants.contains(c.target_constant)) target = input.constants.at(c.target_constant);
    if (const auto it = input.targets.find(c.name); it != input.targets.end()) target = it->second;
    if (!c.target_constant.empty()) constants[c.target_constant] = target;
    const auto s = input.scales.find(c.name);
    targets.push_back(target);
    scales.push_back(s != input.scales.end() ? s->second : c.scale);
  }
  std::vector<double> rho_bar;
  std::map<std::pair<std::string, int>, std::vector<double>> interpolated;  // (field, derivative) -> qdata
  // Scalar fields of an axisymmetric scene are even in r: interpolated with the mirrored basis even
  // when the unknowns' basis is not (a deformation's y_r is odd, so its basis has the axis as hull).
  std::optional<LmeBasis> field_basis;
  const bool mirror_fields = scene.axisymmetric() && input.lme.mirror_axis < 0;
  auto make = [&](const kernel::FormKernels* k) {
    auto a = std::make_unique<Assembler>(disc, *k);
    if (k->n_coefficients > 0) {
      // The kernel's own layout of its coefficient fields, filled from [coefficients].
      std::vector<UnknownField> layout;
      int per_node = 0;
      for (int i = 0; i < k->n_coefficients; ++i) {
        layout.push_back({k->coefficients[i].name, k->coefficients[i].components, per_node});
        per_node += k->coefficients[i].components;
      }
      std::vector<double> values = nodal_values(b, scene.coefficients, b.coefficient_expression, layout, per_node, nodes);
      for (const auto& field : layout) {
        const auto given = input.coefficient_values.find(field.name);
        if (given == input.coefficient_values.end() || field.components != 1) continue;
        for (std::size_t n = 0; n < nodes.size(); ++n) values[n * std::size_t(per_node) + std::size_t(field.offset)] = given->second.at(n);
      }
      space.coefficient_vectors.push_back(a->create_coefficient_vector());
      set_from_original(disc, values, per_node, space.coefficient_vectors.back());
      a->set_coefficients(space.coefficient_vectors.back());
    }
    for (int i = 0; i < k->n_constants; ++i) {
      const bool initial_target = std::any_of(b.constraints.begin(), b.constraints.end(), [&](const BoundConstraint& c) {
        return c.initial && c.target_constant == k->constants[i];
      });
      const double v = initial_target ? 0.0 : constants.at(k->constants[i]);  // an initial target: set below
      if (std::isnan(v))
        throw SceneError(fmt::format("{}: the constant '{}' of {}.{} has no value", scene.source, k->constants[i], k->module, k->name));
      a->set_constant(k->constants[i], v);
    }
    if (k->qdata_per_point > 0) {
      std::vector<double> data(disc.quadrature().size() * static_cast<std::size_t>(k->qdata_per_point), 0.0);
      int offset = 0;
      for (int i = 0; i < k->n_qdata; ++i) {
        const auto provider = std::find_if(scene.qdata.begin(), scene.qdata.end(),
                                           [&](const SceneQdata& q) { return q.name == k->qdata[i].name; });
        const auto per_point = std::size_t(k->qdata_per_point);
        const int size = k->qdata[i].size;
        if (const auto given = input.qdata_values.find(k->qdata[i].name); given != input.qdata_values.end()) {
          if (given->second.size() != disc.quadrature().size() * std::size_t(size))
            throw std::invalid_argument(fmt::format("build_problem_space: {} values of '{}' for {} points x {}",
                                                    given->second.size(), given->first, disc.quadrature().size(), size));
          for (std::size_t q = 0; q < disc.quadrature().size(); ++q)
            for (int c = 0; c < size; ++c) data[q * per_point + std::size_t(offset + c)] = given->second[q * std::size_t(size) + std::size_t(c)];
          space.qdata[given->first] = given->second;
          offset += size;
          continue;
        }
        if (provider != scene.qdata.end() && provider->provider == "value") {
          const int handle = b.qdata_expression.at(provider->name);
          std::vector<double> v(static_cast<std::size_t>(size), handle < 0 ? provider->value.number() : 0.0);
          for (std::size_t q = 0; q < disc.quadrature().size(); ++q) {
            if (handle >= 0) b.expressions->evaluate(handle, disc.quadrature().point(q), v);
            for (int c = 0; c < size; ++c) data[q * per_point + std::size_t(offset + c)] = v[std::size_t(c)];
          }
        }
        if (provider != scene.qdata.end() && provider->provider == "support_size") {
          if (size != 1)
            throw SceneError(fmt::format("{}: \"support_size\" is a scalar; '{}' has {} values per point", provider->where,
                                         provider->name, size));
          if (rho_bar.empty()) rho_bar = support_size_qdata(disc);
          for (std::size_t q = 0; q < rho_bar.size(); ++q) data[q * per_point + std::size_t(offset)] = rho_bar[q];
        }
        if (provider != scene.qdata.end() && provider->provider == "field") {
          auto& values = interpolated[{provider->field, provider->derivative}];
          if (values.empty()) {
            const auto given = input.coefficient_values.find(provider->field);
            const std::vector<double> field =
                given != input.coefficient_values.end()
                    ? given->second
                    : nodal_values(b, scene.coefficients, b.coefficient_expression, {{provider->field, 1, 0}}, 1, nodes);
            if (mirror_fields && !field_basis) {
              LmeOptions lme = input.lme;
              lme.mirror_axis = 0;
              lme.mirror_position = 0.0;
              const std::vector<double> gamma{scene.nodes.gamma};
              field_basis.emplace(nodes, gamma, lme);
            }
            values = interpolated_field_qdata(disc, field, provider->derivative, field_basis ? &*field_basis : nullptr);
          }
          space.qdata[provider->name] = values;
          for (std::size_t q = 0; q < disc.quadrature().size(); ++q)
            for (int c = 0; c < size; ++c) data[q * per_point + std::size_t(offset + c)] = values[q * std::size_t(size) + std::size_t(c)];
        }
        offset += size;
      }
      a->set_qdata(data);
    }
    return a;
  };

  // The state: the given start, or the scene's [initial]; Dirichlet values imposed on it.
  std::vector<double>& state = space.state;
  state = input.initial.empty() ? initial_state(b, nodes) : input.initial;
  if (state.size() != nodes.size() * std::size_t(bs))
    throw std::invalid_argument(fmt::format("solve_problem: the initial state has {} values for {} nodes x {} dofs",
                                            state.size(), nodes.size(), bs));
  space.first_scalar_fixed.assign(nodes.size(), 0);
  std::vector<double> value(3);
  const std::vector<std::vector<int>> on_boundary = input.dirichlet_nodes.empty() ? dirichlet_nodes(scene, nodes) : input.dirichlet_nodes;
  if (on_boundary.size() != scene.dirichlet.size())
    throw std::invalid_argument(fmt::format("build_problem_space: node sets for {} Dirichlet entries, the scene has {}",
                                            on_boundary.size(), scene.dirichlet.size()));
  for (std::size_t i = 0; i < scene.dirichlet.size(); ++i) {
    const SceneDirichlet& d = scene.dirichlet[i];
    const UnknownField& u = b.unknown(d.unknown);
    std::vector<int> comps = d.components;
    if (comps.empty())
      for (int c = 0; c < u.components; ++c) comps.push_back(c);
    for (const int n : on_boundary.at(i)) {
      const int handle = b.dirichlet_expression[i];
      if (handle >= 0) b.expressions->evaluate(handle, nodes.point(std::size_t(n)), value);
      else std::fill(value.begin(), value.end(), d.value.number());
      for (const int c : comps) {
        state[std::size_t(n) * std::size_t(bs) + std::size_t(u.offset + c)] = value[u.components == 1 ? 0 : std::size_t(c)];
        space.fixed_pairs.emplace_back(n, u.offset + c);
      }
      if (u.offset == 0 && u.components == 1) space.first_scalar_fixed[std::size_t(n)] = 1;
    }
  }
  space.fixed = owned_dofs(disc, space.fixed_pairs, bs);

  for (const auto* k : b.energy) {
    space.assemblers.push_back(make(k));
    space.energy_terms.push_back(space.assemblers.back().get());
  }
  for (std::size_t i = 0; i < b.constraints.size(); ++i) {
    space.assemblers.push_back(make(b.constraints[i].kernel));
    space.constraints.push_back({b.constraints[i].name, space.assemblers.back().get(), targets[i], scales[i]});
  }
  if (b.kind == ProblemKind::minimization) space.primary = space.energy_terms.front();
  if (b.residual != nullptr) {
    space.assemblers.push_back(make(b.residual));
    space.primary = space.assemblers.back().get();
  }
  if (b.bilinear != nullptr) {
    space.assemblers.push_back(make(b.bilinear));
    space.primary = space.assemblers.back().get();
    space.assemblers.push_back(make(b.linear));
    space.linear = space.assemblers.back().get();
  }
  for (const auto* k : b.auxiliary) {
    space.assemblers.push_back(make(k));
    space.auxiliary.push_back(space.assemblers.back().get());
  }
  // Targets given as "initial": the constraint's value at the start (the scale follows unless given).
  if (std::any_of(b.constraints.begin(), b.constraints.end(), [](const BoundConstraint& c) { return c.initial; })) {
    PetscVector u = space.primary->create_vector();
    set_from_original(disc, state, bs, u);
    for (std::size_t i = 0; i < b.constraints.size(); ++i) {
      if (!b.constraints[i].initial || input.targets.contains(b.constraints[i].name)) continue;
      ScalarConstraint& c = space.constraints[i];
      c.target = c.functional->value(u);
      if (!input.scales.contains(c.name) && !scene.constraints[i].scale) c.scale = std::abs(c.target) > 0 ? std::abs(c.target) : 1.0;
      const std::string& name = b.constraints[i].target_constant;
      if (name.empty()) continue;
      constants[name] = c.target;
      for (auto& a : space.assemblers)
        for (int j = 0; j < a->form().n_constants; ++j)
          if (a->form().constants[j] == name) a->set_constant(name, c.target);
    }
  }
  return space;
}

ProblemResult solve_problem(MPI_Comm comm, const BoundScene& b, const ProblemInput& input) {
  const Scene& scene = *b.scene;
  const auto t0 = std::chrono::steady_clock::now();
  const ScopedPetscOptions petsc_options(scene.solver.petsc_options);
  ProblemResult result;
  result.nodes = input.nodes;
  const NodeSet& nodes = result.nodes;
  const int bs = b.dofs_per_node;
  ProblemSpace space = build_problem_space(comm, b, input);
  const Discretization& disc = *space.disc;
  result.discretization = space.disc;
  {
    const auto h = disc.basis().spacing();
    result.h_min = *std::min_element(h.begin(), h.end());
    result.h_mean = std::accumulate(h.begin(), h.end(), 0.0) / static_cast<double>(h.size());
  }
  const auto& constants = space.constants;
  const auto& fixed_pairs = space.fixed_pairs;
  const auto& fixed = space.fixed;
  const auto& first_scalar_fixed = space.first_scalar_fixed;
  const auto& energy_terms = space.energy_terms;
  const auto& constraints = space.constraints;
  Assembler* primary = space.primary;
  Assembler* linear = space.linear;
  for (const auto& c : b.constraints) result.constraint_names.push_back(c.name);
  const std::vector<double>& state = space.state;
  PetscVector u = primary->create_vector();
  set_from_original(disc, state, bs, u);
  result.seconds_setup = seconds_since(t0);
  const auto t1 = std::chrono::steady_clock::now();
  // The value of every energy term and constraint at the state in u.
  auto record_values = [&]() {
    for (std::size_t i = 0; i < energy_terms.size(); ++i)
      result.values[std::string(b.energy[i]->module) + "." + b.energy[i]->name] = energy_terms[i]->value(u);
    for (const auto& c : constraints) result.values[c.name] = c.functional->value(u);
  };
  if (input.evaluate_only) {
    record_values();
    result.state = to_original(disc, u, bs);
    result.energy = std::numeric_limits<double>::quiet_NaN();
    result.message = "evaluated, not solved";
    return result;
  }

  switch (b.kind) {
    case ProblemKind::minimization: {
      ConstrainedMinimizerOptions o;
      o.kkt_first = scene.solver.kkt_first;
      o.penalty = scene.solver.penalty;
      o.augmented_tolerance = scene.solver.augmented_tolerance;
      o.inner_tolerance = scene.solver.inner_tolerance;
      o.max_outer_iterations = scene.solver.max_outer_iterations;
      o.max_inner_iterations = scene.solver.max_inner_iterations;
      o.newton_tolerance = scene.solver.newton_tolerance;
      o.constraint_tolerance = scene.solver.constraint_tolerance;
      o.max_newton_iterations = scene.solver.max_newton_iterations;
      o.inertia_correction = scene.solver.inertia_correction;
      o.log = input.log;
      ConstrainedMinimizer minimizer(energy_terms, constraints, o);
      minimizer.set_fixed_dofs(fixed);
      std::vector<double> nu;  // the minimizer works with multipliers of the scaled constraints
      if (!input.initial_multipliers.empty()) {
        if (input.initial_multipliers.size() != constraints.size())
          throw std::invalid_argument(fmt::format("solve_problem: {} starting multipliers for {} constraints",
                                                  input.initial_multipliers.size(), constraints.size()));
        for (std::size_t i = 0; i < constraints.size(); ++i) nu.push_back(input.initial_multipliers[i] * constraints[i].scale);
      }
      result.minimization = minimizer.minimize(u, nu);
      result.converged = result.minimization.converged;
      result.message = result.minimization.message;
      result.energy = result.minimization.energy;
      result.iterations = result.minimization.augmented_iterations + result.minimization.newton_iterations;
      break;
    }
    case ProblemKind::residual: {
      SnesContext ctx{primary, &fixed};
      SNES snes = nullptr;
      LMEFORM_PETSC_CHECK(SNESCreate(comm, &snes));
      PetscMatrix J = primary->create_matrix();
      PetscVector r = primary->create_vector();
      LMEFORM_PETSC_CHECK(SNESSetFunction(snes, r, snes_residual, &ctx));
      LMEFORM_PETSC_CHECK(SNESSetJacobian(snes, J, J, snes_jacobian, &ctx));
      KSP ksp = nullptr;
      LMEFORM_PETSC_CHECK(SNESGetKSP(snes, &ksp));
      configure_direct_solver(ksp);
      LMEFORM_PETSC_CHECK(SNESSetTolerances(snes, 1e-12, scene.solver.newton_tolerance, 1e-14,
                                            scene.solver.max_newton_iterations, 10000));
      LMEFORM_PETSC_CHECK(SNESSetFromOptions(snes));
      const PetscErrorCode solved = SNESSolve(snes, nullptr, u);
      SNESConvergedReason reason = SNES_CONVERGED_ITERATING;
      PetscInt its = 0;
      PetscReal norm = 0;
      SNESGetConvergedReason(snes, &reason);
      SNESGetIterationNumber(snes, &its);
      SNESGetFunctionNorm(snes, &norm);
      SNESDestroy(&snes);
      LMEFORM_PETSC_CHECK(solved);
      result.converged = reason > 0;
      result.message = fmt::format("SNES {} after {} Newton steps, |R| = {:.3e}", SNESConvergedReasons[reason], its, norm);
      result.iterations = static_cast<int>(its);
      result.residual_norm = norm;
      result.energy = std::numeric_limits<double>::quiet_NaN();
      break;
    }
    case ProblemKind::linear: {
      const auto ta = std::chrono::steady_clock::now();
      PetscMatrix A = primary->create_matrix();
      PetscVector rhs = linear->create_vector(), x = primary->create_vector();
      primary->matrix(u, A);
      linear->vector(u, rhs);
      result.seconds_assembly = seconds_since(ta);
      LMEFORM_PETSC_CHECK(VecCopy(u, x));
      apply_dirichlet(A, rhs, x, fixed);
      LinearSystemLayout layout;
      layout.dofs_per_node = bs;
      for (const auto& f : b.unknowns) layout.fields.push_back({f.name, f.offset, f.components});
      std::vector<PetscVector> means, modes;
      for (const auto& name : b.zero_mean) {
        const UnknownField& f = b.unknown(name);
        const bool prescribed =
            std::any_of(fixed_pairs.begin(), fixed_pairs.end(), [&](const auto& p) { return p.second == f.offset; });
        if (prescribed)
          throw SceneError(fmt::format("{}: '{}' has Dirichlet values and model.zero_mean: give one or the other",
                                       scene.source, name));
        // c_a = ∫ N_a dx: the gradient of ∫ u dx, assembled like any form.
        const FormModule& integral = compile_integral_form(scene.dim(), comm, input.log);
        Assembler integral_form(disc, integral.at("integral", scene.dim()));
        PetscVector one = integral_form.create_vector(), weights = integral_form.create_vector();
        LMEFORM_PETSC_CHECK(VecSet(one, 1.0));
        integral_form.vector(one, weights);
        PetscVector c = primary->create_vector(), mode = primary->create_vector();
        LMEFORM_PETSC_CHECK(VecSet(c, 0.0));
        LMEFORM_PETSC_CHECK(VecSet(mode, 0.0));
        {
          const VecReadView w(weights);
          VecWriteView cv(c), mv(mode);
          for (PetscInt i = 0; i < w.size(); ++i) {
            cv[i * bs + f.offset] = w[i];
            mv[i * bs + f.offset] = 1.0;
          }
        }
        layout.mean_functionals.push_back(c);
        layout.constant_modes.push_back(mode);
        means.push_back(std::move(c));
        modes.push_back(std::move(mode));
      }
      const LinearSolveReport solve = solve_linear_system(comm, A, rhs, x, layout);
      result.residual_norm = solve.relative_residual;
      result.converged = solve.converged;
      result.message = solve.message;
      result.iterations = solve.iterations;
      result.zero_mean_method = solve.zero_mean_method;
      result.energy = std::numeric_limits<double>::quiet_NaN();
      LMEFORM_PETSC_CHECK(VecCopy(x, u));
      break;
    }
  }
  result.seconds_solve = seconds_since(t1);
  if (energy_terms.size() > 1) record_values();
  result.state = to_original(disc, u, bs);

  // Errors against the scene's exact solutions.
  for (const auto& [name, exact] : scene.reference.solution) {
    const UnknownField& field = b.unknown(name);
    const FormModule& errors = compile_error_form(scene.dim(), name, field.components, exact.expression(), b.constants,
                                                  exact.where, comm, input.log);
    // The error form has this unknown alone: its state is the unknown's components.
    const auto& l2 = errors.at("l2", scene.dim());
    const auto& h1 = errors.at("h1", scene.dim());
    Assembler l2_form(disc, l2), h1_form(disc, h1);
    for (int i = 0; i < l2.n_constants; ++i) {
      l2_form.set_constant(l2.constants[i], std::isnan(constants.at(l2.constants[i])) ? 0.0 : constants.at(l2.constants[i]));
      h1_form.set_constant(h1.constants[i], std::isnan(constants.at(h1.constants[i])) ? 0.0 : constants.at(h1.constants[i]));
    }
    std::vector<double> field_state(nodes.size() * std::size_t(field.components));
    for (std::size_t a = 0; a < nodes.size(); ++a)
      for (int c = 0; c < field.components; ++c)
        field_state[a * std::size_t(field.components) + std::size_t(c)] = result.state[a * std::size_t(bs) + std::size_t(field.offset + c)];
    PetscVector v = l2_form.create_vector();
    set_from_original(disc, field_state, field.components, v);
    result.errors.push_back({name, std::sqrt(std::max(0.0, l2_form.value(v))), std::sqrt(std::max(0.0, h1_form.value(v)))});
  }

  // |∇u| of the first scalar unknown at the nodes (0 where it is prescribed): adaptivity indicators.
  if (!b.unknowns.empty() && b.unknowns.front().components == 1) {
    result.gradient_norm.assign(nodes.size(), 0.0);
    const int dim = nodes.dim;
    for (std::size_t r = 0; r < nodes.size(); ++r) {
      const auto o = static_cast<std::size_t>(disc.original_index()[r]);
      if (first_scalar_fixed[o] != 0) continue;
      const auto x = disc.nodes().point(r);
      const auto list = disc.basis().neighbours(x);
      const auto jet = disc.basis().evaluate(x, list, 1);
      double g2 = 0;
      for (int i = 0; i < dim; ++i) {
        double g = 0;
        for (std::size_t m = 0; m < list.size(); ++m)
          g += jet[std::size_t(1 + i) * list.size() + m] *
               result.state[std::size_t(disc.original_index()[static_cast<std::size_t>(list[m])]) * std::size_t(bs)];
        g2 += g * g;
      }
      result.gradient_norm[o] = std::sqrt(g2);
    }
  }
  result.cells = delaunay(nodes);
  return result;
}

}  // namespace lmeform::app
