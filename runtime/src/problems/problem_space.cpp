#include "problem_space.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <map>

#include <Eigen/Eigenvalues>
#include <fmt/format.h>
#include <fmt/ranges.h>

#include "requirements.hpp"
#include "expressions.hpp"
#include "quadrature_data.hpp"

namespace lmeform::problems {

namespace {

std::shared_ptr<Discretization> discretization_of(MPI_Comm comm, const BoundScene& b, const ProblemInput& input) {
  if (input.discretization) {
    if (input.carried || input.discretization->n_nodes() != static_cast<int>(input.nodes.size()))
      throw std::invalid_argument(fmt::format("build_problem_space: a reused discretization of {} nodes for {} nodes{}",
                                              input.discretization->n_nodes(), input.nodes.size(),
                                              input.carried ? " with carried quadrature" : ""));
    return input.discretization;
  }
  DiscretizationOptions options;
  options.gamma = {b.discretization.gamma};
  options.lme = input.lme;
  options.quadrature_points = b.discretization.quadrature_points;
  options.partition = b.discretization.partition;
  options.basis_order = std::max(b.basis_order, 1);  // |∇u| at the nodes and H1 errors need gradients
  options.carried = input.carried;
  options.flat_cell_tolerance = input.flat_cell_tolerance;
  // The facet rule is the boundary rule: hull facets then carry the points of ds, and a traction
  // balances the corrected gradients exactly.
  if (b.discretization.consistent_integration) options.consistent_integration = b.boundary_points;
  // The boundary parts the forms integrate over: a rule per segment between boundary nodes.
  for (const std::string& part : b.boundary_parts) {
    if (input.carried)
      throw SceneError(fmt::format("{}: a boundary integral ds({}) on a moving reference configuration is not supported", b.source, part));
    try {
      options.boundary.push_back(boundary_quadrature(b.geometry, input.nodes, part, b.boundary_points));
    } catch (const std::invalid_argument& e) {
      throw SceneError(fmt::format("{}: the boundary quadrature of ds({}): {}", b.source, part, e.what()));
    }
  }
  try {
    return std::make_shared<Discretization>(comm, input.nodes, options);
  } catch (const LmeEvaluationError& e) {
    // A compact support leaves a point few neighbours: say which key made it so.
    if (e.reason() != LmeFailure::infeasible_second_moment && b.discretization.support_tolerance > 1e-6)
      throw SceneError(fmt::format("{}: the LME basis cannot be evaluated on these nodes with key 'nodes.support_tolerance' = {:g}: {}\n"
                                   "  in the scene: a smaller 'nodes.support_tolerance' (the default 1e-6 keeps more neighbours) or "
                                   "a smaller 'nodes.gamma' (now {:g})",
                                   b.source, b.discretization.support_tolerance, e.what(), b.discretization.gamma));
    if (e.reason() != LmeFailure::infeasible_second_moment) throw;
    throw SceneError(fmt::format("{}: key 'nodes.basis' = \"second\" cannot be evaluated on these nodes: {}\n  in the scene: a smaller "
                                 "'nodes.gamma' (now {:g}), more nodes there (or less steep 'nodes.refine' grading), or "
                                 "'nodes.basis' = \"first\"",
                                 b.source, e.what(), b.discretization.gamma));
  }
}

/// The bound constants, the input's overrides and the constraint targets; the constraints' targets
/// and scales (ScalarConstraint order).
void resolve_constants(const BoundScene& b, const ProblemInput& input, ProblemSpace& space, std::vector<double>& targets,
                       std::vector<double>& scales) {
  space.constants = b.constants;
  for (const auto& [name, value] : input.constants) space.constants[name] = value;
  for (const auto& c : b.constraints) {
    double target = c.target;
    if (!c.target_constant.empty() && input.constants.contains(c.target_constant)) target = input.constants.at(c.target_constant);
    if (const auto it = input.targets.find(c.name); it != input.targets.end()) target = it->second;
    if (!c.target_constant.empty()) space.constants[c.target_constant] = target;
    const auto s = input.scales.find(c.name);
    targets.push_back(target);
    scales.push_back(s != input.scales.end() ? s->second : c.scale);
  }
}

/// The quadrature data kernel `k` reads at every point of a domain, interleaved per point.
std::vector<double> qdata_of(const BoundScene& b, const kernel::FormKernels& k, const ElementSet& domain, QuadratureData& qdata) {
  const auto per_point = std::size_t(k.qdata_per_point);
  std::vector<double> data(domain.n_points() * per_point, 0.0);
  std::size_t offset = 0;
  for (int i = 0; i < k.n_qdata; ++i) {
    const auto size = std::size_t(k.qdata[i].size);
    const auto source = std::find_if(b.qdata.begin(), b.qdata.end(), [&](const BoundQdata& q) { return q.name == k.qdata[i].name; });
    const std::vector<double>& values = qdata.values(*source, domain);
    for (std::size_t q = 0; q < domain.n_points(); ++q)
      std::copy_n(values.begin() + std::ptrdiff_t(q * size), size, data.begin() + std::ptrdiff_t(q * per_point + offset));
    offset += size;
  }
  return data;
}

/// Turns `value` (expression `handle` at x, every component) into the coefficient of node `node`
/// (renumbered) for the second-order basis: g(x_a) - G_a : Hg(x_a) / 2 (LmeBasis::gap_corrected).
/// With nodal values as coefficients the data's error is O(h^2), and a Poisson problem with curved
/// boundary data converges at O(h^2) in L2 with either basis. The curvature of g along each
/// principal direction e of G_a (on the hull: tangent to it) is a central difference of step
/// sqrt(lambda), O(h^2) accurate, so the coefficient is O(h^4). The first-order basis keeps `value`.
void gap_correct(const PointExpressions& expressions, int handle, const LmeBasis& basis, int node, std::span<const double> x,
                 std::vector<double>& value) {
  if (basis.consistency() != LmeConsistency::second) return;
  const int dim = static_cast<int>(x.size());
  const std::size_t packed = std::size_t(dim * (dim + 1) / 2);
  const auto g = basis.gaps().subspan(std::size_t(node) * packed, packed);
  Eigen::Matrix3d gap = Eigen::Matrix3d::Zero();
  for (int i = 0; i < dim; ++i)
    for (int j = i; j < dim; ++j) gap(i, j) = gap(j, i) = g[std::size_t(kernel::hessian_slot(i, j, dim) - 1 - dim)];
  const Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> eigen(gap.topLeftCorner(dim, dim));
  const std::vector<double> centre = value;
  std::vector<double> plus(value.size()), minus(value.size()), y(x.begin(), x.end()), z(x.begin(), x.end());
  for (int k = 0; k < dim; ++k) {
    const double lambda = eigen.eigenvalues()[k];
    if (lambda <= 1e-14 * gap.norm()) continue;
    const double step = std::sqrt(lambda);
    for (int i = 0; i < dim; ++i) {
      y[std::size_t(i)] = x[std::size_t(i)] + step * eigen.eigenvectors()(i, k);
      z[std::size_t(i)] = x[std::size_t(i)] - step * eigen.eigenvectors()(i, k);
    }
    expressions.evaluate(handle, y, plus);
    expressions.evaluate(handle, z, minus);
    // lambda * curvature / 2 = (g(x + s e) + g(x - s e) - 2 g(x)) / 2 with s^2 = lambda.
    for (std::size_t c = 0; c < value.size(); ++c) value[c] -= 0.5 * (plus[c] + minus[c] - 2 * centre[c]);
  }
}

/// Nodal fields of `entries` given as expressions (the scene's [initial] or [coefficients]) as
/// coefficients of the second-order basis (gap_correct): a curved field (a tanh profile, a load) is
/// then represented to O(h^3) instead of O(h^2). Fields in `given` (a transfer's values) are left.
/// The correction is G_a : Hg / 2, small only where g varies on scales longer than the gaps; a
/// profile narrower than the nodes there (a crack's band of width l on the coarse nodes away from
/// it) would be pushed out of the values it takes (a damage field above 1). So the coefficients
/// stay within the range of the field's values at the nodes, component by component.
void gap_correct_fields(const BoundScene& b, const std::vector<BoundNodalField>& entries, const StateLayout& layout, const NodeSet& nodes,
                        const Discretization& disc, std::vector<double>& values,
                        const std::map<std::string, std::vector<double>, std::less<>>& given = {}) {
  if (disc.basis().consistency() != LmeConsistency::second) return;
  const auto bs = static_cast<std::size_t>(layout.dofs_per_node);
  const auto renumbered = disc.renumbered_index();
  std::vector<double> value(3);
  for (const BoundNodalField& f : entries) {
    if (!layout.has(f.name) || !f.file.empty() || !f.value.is_expression() || given.contains(f.name)) continue;
    const UnknownField& u = layout.field(f.name);
    const auto components = std::size_t(u.components);
    std::vector<double> at_nodes(nodes.size() * components);
    std::vector<double> low(components, std::numeric_limits<double>::infinity()), high(components, -std::numeric_limits<double>::infinity());
    for (std::size_t a = 0; a < nodes.size(); ++a) {
      b.expressions->evaluate(f.value.expression, nodes.point(a), value);
      for (std::size_t c = 0; c < components; ++c) {
        at_nodes[a * components + c] = value[c];
        low[c] = std::min(low[c], value[c]), high[c] = std::max(high[c], value[c]);
      }
    }
    for (std::size_t a = 0; a < nodes.size(); ++a) {
      std::copy_n(at_nodes.begin() + std::ptrdiff_t(a * components), components, value.begin());
      gap_correct(*b.expressions, f.value.expression, disc.basis(), renumbered[a], nodes.point(a), value);
      for (std::size_t c = 0; c < components; ++c) values[a * bs + std::size_t(u.offset) + c] = std::clamp(value[c], low[c], high[c]);
    }
  }
}

/// An assembler of one output with its coefficients, constants and quadrature data set.
std::unique_ptr<Assembler> make_assembler(const BoundScene& b, const BoundOutput& output, const ProblemInput& input,
                                          QuadratureData& qdata, ProblemSpace& space) {
  const Discretization& disc = *space.disc;
  const kernel::FormKernels& k = output.first();
  auto a = std::make_unique<Assembler>(disc, output.kernels);
  if (k.n_coefficients > 0) {
    std::vector<double> values = kernel_coefficient_values(b, k, input.nodes, input.coefficient_values);
    gap_correct_fields(b, b.coefficients, kernel_coefficient_layout(k), input.nodes, disc, values, input.coefficient_values);
    PetscVector& c = space.coefficient_vectors[output.label] = a->create_coefficient_vector();
    set_from_original(disc, values, k.coefficient_components_per_node, c);
    a->set_coefficients(c);
  }
  for (int i = 0; i < k.n_constants; ++i) {
    const bool initial_target = std::any_of(b.constraints.begin(), b.constraints.end(), [&](const BoundConstraint& c) {
      return c.initial && c.target_constant == k.constants[i];
    });
    const double v = initial_target ? 0.0 : space.constants.at(k.constants[i]);  // an initial target: set from the start
    if (std::isnan(v)) throw SceneError(fmt::format("{}: the constant '{}' of {} has no value", b.source, k.constants[i], output.label));
    a->set_constant(k.constants[i], v);
  }
  if (k.qdata_per_point > 0)
    for (const Assembler::Integral& integral : a->integrals()) a->set_qdata(*integral.domain, qdata_of(b, k, *integral.domain, qdata));
  return a;
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

/// The prescribed coefficients of Dirichlet entry d at node `node` (renumbered) at x, every component.
void dirichlet_value(const BoundScene& b, const BoundDirichlet& d, const LmeBasis& basis, int node, std::span<const double> x,
                     std::vector<double>& value) {
  if (!d.value.is_expression()) {
    std::fill(value.begin(), value.end(), d.value.number);
    return;
  }
  b.expressions->evaluate(d.value.expression, x, value);
  gap_correct(*b.expressions, d.value.expression, basis, node, x, value);
}

/// The start (the input's, else the scene's [initial]) with the Dirichlet values imposed.
void impose_dirichlet(const BoundScene& b, const ProblemInput& input, ProblemSpace& space) {
  const NodeSet& nodes = input.nodes;
  const int bs = b.layout.dofs_per_node;
  std::vector<double>& state = space.state;
  if (input.initial.empty()) {
    state = initial_state(b, nodes);
    gap_correct_fields(b, b.initial, b.layout, nodes, *space.disc, state);
  } else {
    state = input.initial;
  }
  if (state.size() != nodes.size() * std::size_t(bs))
    throw std::invalid_argument(fmt::format("build_problem_space: the initial state has {} values for {} nodes x {} dofs", state.size(),
                                            nodes.size(), bs));
  space.part_nodes = input.part_nodes;
  space.dirichlet_nodes = input.dirichlet_nodes.empty() ? dirichlet_nodes(b, nodes, input.part_nodes) : input.dirichlet_nodes;
  if (space.dirichlet_nodes.size() != b.dirichlet.size())
    throw std::invalid_argument(fmt::format("build_problem_space: node sets for {} Dirichlet entries, the scene has {}",
                                            space.dirichlet_nodes.size(), b.dirichlet.size()));
  std::vector<double> value(3);
  const auto renumbered = space.disc->renumbered_index();
  // Two entries that fix one dof (a corner shared by two parts) must agree: which of two values a
  // corner takes is the user's decision, not the order of the entries.
  std::map<std::pair<int, int>, std::size_t> fixed_by;
  for (std::size_t i = 0; i < b.dirichlet.size(); ++i) {
    const BoundDirichlet& d = b.dirichlet[i];
    for (const int n : space.dirichlet_nodes[i]) {
      dirichlet_value(b, d, space.disc->basis(), renumbered[std::size_t(n)], nodes.point(std::size_t(n)), value);
      for (const int c : d.components) {
        double& slot = state[std::size_t(n) * std::size_t(bs) + std::size_t(d.field.offset + c)];
        const double v = value[d.field.components == 1 ? 0 : std::size_t(c)];
        const auto [it, first] = fixed_by.emplace(std::pair{n, d.field.offset + c}, i);
        if (!first && std::abs(slot - v) > 1e-12 * std::max({1.0, std::abs(slot), std::abs(v)}))
          throw SceneError(fmt::format("{} and {} prescribe {}{} at the node ({}) as {} and {}: a node on both parts needs one value "
                                       "(give the entries equal values there, or leave the corner to one of them)",
                                       b.dirichlet[it->second].where, d.where, d.field.name,
                                       d.field.components == 1 ? std::string() : fmt::format("[{}]", c),
                                       fmt::join(nodes.point(std::size_t(n)), ", "), slot, v));
        slot = v;
        if (first) space.fixed_pairs.emplace_back(n, d.field.offset + c);
      }
    }
  }
  space.fixed = owned_dofs(*space.disc, space.fixed_pairs, bs);
}

void make_assemblers(const BoundScene& b, const ProblemInput& input, const std::vector<double>& targets, const std::vector<double>& scales,
                     ProblemSpace& space) {
  QuadratureData qdata(b, *space.disc, input);
  auto add = [&](const BoundOutput& o) {
    auto& slot = space.assemblers[o.label];
    if (!slot) slot = make_assembler(b, o, input, qdata, space);
    return slot.get();
  };
  for (const auto& e : b.energy) space.energy_terms.push_back(add(e));
  for (std::size_t i = 0; i < b.constraints.size(); ++i)
    space.constraints.push_back({b.constraints[i].name, add(b.constraints[i].output), targets[i], scales[i]});
  if (b.residual) space.residual = add(*b.residual);
  if (b.bilinear) space.bilinear = add(*b.bilinear);
  if (b.linear) space.linear = add(*b.linear);
  for (const auto& a : b.auxiliary) space.auxiliary.push_back(add(a));
  for (const auto& q : b.quantities)
    if (q.integral) (void)add(*q.integral);
  space.primary = space.assemblers.at(b.primary->label).get();
  space.qdata = qdata.field_data();
}

/// The bound vectors from [bounds]: values at the nodes, or the start for "previous"; the start must
/// lie within them.
void make_bounds(const BoundScene& b, const ProblemInput& input, ProblemSpace& space) {
  if (b.bounds.empty()) return;
  const Discretization& disc = *space.disc;
  const int bs = b.layout.dofs_per_node;
  const std::size_t n = space.nodes.size();
  std::vector<double> lower(n * std::size_t(bs), PETSC_NINFINITY), upper(n * std::size_t(bs), PETSC_INFINITY);
  std::vector<double> value(3);
  auto fill = [&](const BoundValue& v, std::span<const double> x) {
    if (v.is_expression()) b.expressions->evaluate(v.expression, x, value);
    else std::fill(value.begin(), value.end(), v.number);
  };
  for (const BoundBound& bb : b.bounds)
    for (std::size_t a = 0; a < n; ++a)
      for (int c = 0; c < bb.field.components; ++c) {
        const std::size_t dof = a * std::size_t(bs) + std::size_t(bb.field.offset + c);
        if (bb.lower) fill(*bb.lower, space.nodes.point(a)), lower[dof] = value[std::size_t(c)];
        if (bb.upper) fill(*bb.upper, space.nodes.point(a)), upper[dof] = value[std::size_t(c)];
        if (input.clamp_start_to_bounds && lower[dof] <= upper[dof]) space.state[dof] = std::clamp(space.state[dof], lower[dof], upper[dof]);
        if (bb.lower_previous) lower[dof] = space.state[dof];
        if (bb.upper_previous) upper[dof] = space.state[dof];
        if (lower[dof] > upper[dof])
          throw SceneError(fmt::format("{}: the lower bound {} lies above the upper bound {} at ({})", bb.where, lower[dof], upper[dof],
                                       fmt::join(space.nodes.point(a), ", ")));
        if (space.state[dof] < lower[dof] - 1e-12 * std::max(1.0, std::abs(lower[dof])) ||
            space.state[dof] > upper[dof] + 1e-12 * std::max(1.0, std::abs(upper[dof])))
          throw SceneError(fmt::format("{}: the start violates the bounds: {} = {} outside [{}, {}] at ({})", bb.where, bb.field.name,
                                       space.state[dof], lower[dof], upper[dof], fmt::join(space.nodes.point(a), ", ")));
      }
  // Prescribed dofs keep their Dirichlet values: no bound there.
  for (const auto& [node, dof] : space.fixed_pairs) {
    lower[std::size_t(node) * std::size_t(bs) + std::size_t(dof)] = PETSC_NINFINITY;
    upper[std::size_t(node) * std::size_t(bs) + std::size_t(dof)] = PETSC_INFINITY;
  }
  space.lower_bound = space.primary->create_vector();
  space.upper_bound = space.primary->create_vector();
  set_from_original(disc, lower, bs, space.lower_bound);
  set_from_original(disc, upper, bs, space.upper_bound);
}

/// Targets given as "initial": the constraint's value at the start (the scale follows unless given).
void set_initial_targets(const BoundScene& b, const ProblemInput& input, ProblemSpace& space) {
  if (std::none_of(b.constraints.begin(), b.constraints.end(), [](const BoundConstraint& c) { return c.initial; })) return;
  PetscVector u = space.primary->create_vector();
  set_from_original(*space.disc, space.state, b.layout.dofs_per_node, u);
  for (std::size_t i = 0; i < b.constraints.size(); ++i) {
    if (!b.constraints[i].initial || input.targets.contains(b.constraints[i].name)) continue;
    ScalarConstraint& c = space.constraints[i];
    c.target = c.functional->value(u);
    if (!input.scales.contains(c.name) && !b.constraints[i].scale_given) c.scale = std::abs(c.target) > 0 ? std::abs(c.target) : 1.0;
    if (!b.constraints[i].target_constant.empty()) space.set_constant(b.constraints[i].target_constant, c.target);
  }
}

}  // namespace

void ProblemSpace::set_constant(const std::string& name, double value) {
  constants[name] = value;
  for (auto& [label, a] : assemblers)
    for (int j = 0; j < a->form().n_constants; ++j)
      if (a->form().constants[j] == name) a->set_constant(name, value);
}

void ProblemSpace::impose_dirichlet_values(const BoundScene& b, Vec u) const {
  const Discretization& d = *disc;
  const int bs = b.layout.dofs_per_node;
  const auto renumbered = d.renumbered_index();
  std::vector<double> value(3);
  {
    VecWriteView v(u);
    for (std::size_t i = 0; i < b.dirichlet.size(); ++i) {
      const BoundDirichlet& entry = b.dirichlet[i];
      for (const int n : dirichlet_nodes[i]) {
        const int node = renumbered[std::size_t(n)];
        if (!d.owns(node)) continue;
        dirichlet_value(b, entry, d.basis(), node, nodes.point(std::size_t(n)), value);
        for (const int c : entry.components)
          v[(node - d.owned_begin()) * bs + entry.field.offset + c] = value[entry.field.components == 1 ? 0 : std::size_t(c)];
      }
    }
  }
}

void ProblemSpace::update_previous_bounds(const BoundScene& b, Vec u) {
  if (!bounded()) return;
  const int bs = b.layout.dofs_per_node;
  std::vector<char> prescribed(std::size_t(disc->n_owned()) * std::size_t(bs), 0);
  const auto renumbered = disc->renumbered_index();
  for (const auto& [node, dof] : fixed_pairs) {
    const int r = renumbered[std::size_t(node)];
    if (disc->owns(r)) prescribed[std::size_t(r - disc->owned_begin()) * std::size_t(bs) + std::size_t(dof)] = 1;
  }
  const VecReadView previous(u);
  VecWriteView lower(lower_bound), upper(upper_bound);
  for (const BoundBound& bb : b.bounds)
    for (PetscInt a = 0; a < disc->n_owned(); ++a)
      for (int c = 0; c < bb.field.components; ++c) {
        const PetscInt dof = a * bs + bb.field.offset + c;
        if (prescribed[std::size_t(dof)] != 0) continue;
        if (bb.lower_previous) lower[dof] = previous[dof];
        if (bb.upper_previous) upper[dof] = previous[dof];
      }
}

double ProblemSpace::energy(Vec u) const {
  double e = 0;
  for (Assembler* term : energy_terms) e += term->value(u);
  return e;
}

std::vector<double> ProblemSpace::constraint_values(Vec u) const {
  std::vector<double> v;
  for (const auto& c : constraints) v.push_back(c.functional->value(u));
  return v;
}

ProblemSpace build_problem_space(MPI_Comm comm, const BoundScene& b, const ProblemInput& input) {
  ProblemSpace space;
  space.disc = discretization_of(comm, b, input);
  space.nodes = input.nodes;
  std::vector<double> targets, scales;
  resolve_constants(b, input, space, targets, scales);
  impose_dirichlet(b, input, space);
  make_assemblers(b, input, targets, scales, space);
  set_initial_targets(b, input, space);
  make_bounds(b, input, space);
  check_requirements(b, space, input.log);
  return space;
}

}  // namespace lmeform::problems
