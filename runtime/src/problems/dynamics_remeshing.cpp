// The two ways a Lagrangian run renews its reference configuration: a reset (the current
// positions become the nodes, nothing is projected) and a re-mesh (new nodes by CVT, the fields
// projected onto them, the motion restarted from the identity).
#include <algorithm>
#include <cmath>

#include <fmt/format.h>

#include "dynamics_integrator.hpp"
#include "dynamics_reference.hpp"
#include "field_transfer.hpp"
#include "lmeform/cvt.hpp"
#include "lmeform/delaunay.hpp"
#include "membrane_topology.hpp"

namespace lmeform::problems {

namespace {

double relative(double after, double before) { return (after - before) / std::max(std::abs(before), 1e-300); }

}  // namespace

std::map<std::string, std::vector<double>, std::less<>> DynamicsIntegrator::material_fields() const {
  std::map<std::string, std::vector<double>, std::less<>> values;
  for (const auto& [name, v] : scalar_fields_) values[name] = v;
  return values;
}

// Where the material points of the nodes went, y(X_a), not the coefficients y_a: LME is not
// interpolating, and a free node's coefficient can leave the domain (measured: r = -0.11 beside the
// axis of a compressed graded grid). Nodes held in every component of y keep their prescribed place
// (on hull vertices the map's value is the coefficient anyway). Returns the positions and the state
// y with those positions as its coefficients (the identity on them).
std::pair<std::vector<double>, std::vector<double>> DynamicsIntegrator::material_node_positions(const std::vector<double>& y) const {
  std::vector<int> held(n_nodes_, 0);
  for (const auto& [node, dof] : ref_->space.fixed_pairs)
    if (dof >= offset_ && dof < offset_ + dim_) ++held[std::size_t(node)];
  std::vector<double> positions(n_nodes_ * std::size_t(dim_));
  std::vector<double> state = y;
  const LmeBasis basis(ref_->nodes, std::vector<double>(n_nodes_, bound_.discretization.gamma), bound_.lme(AxisParity::odd));
  const auto bs = std::size_t(bs_), d = std::size_t(dim_), offset = std::size_t(offset_);
  // y(X_a) by blocks of nodes over the ranks (a solve of the dual problem per node), put together
  // by a sum: each value comes from one rank, so the sum is exact.
  int rank = 0, size = 1;
  MPI_Comm_rank(comm_, &rank);
  MPI_Comm_size(comm_, &size);
  const std::size_t begin = n_nodes_ * std::size_t(rank) / std::size_t(size), end = n_nodes_ * std::size_t(rank + 1) / std::size_t(size);
  for (std::size_t a = begin; a < end; ++a) {
    if (held[a] == dim_) continue;
    const auto X = ref_->nodes.point(a);
    const auto list = basis.neighbours(X);
    const auto p = basis.evaluate(X, list, 0);
    for (std::size_t i = 0; i < d; ++i)
      for (std::size_t m = 0; m < list.size(); ++m) positions[a * d + i] += p[m] * y[std::size_t(list[m]) * bs + offset + i];
  }
  MPI_Allreduce(MPI_IN_PLACE, positions.data(), static_cast<int>(positions.size()), MPI_DOUBLE, MPI_SUM, comm_);
  for (std::size_t a = 0; a < n_nodes_; ++a)
    for (std::size_t i = 0; i < d; ++i) {
      if (held[a] == dim_) positions[a * d + i] = y[a * bs + offset + i];
      state[a * bs + offset + i] = positions[a * d + i];
    }
  return {positions, state};
}

// Reset of the reference configuration (seed Fig. 3.8): the current positions become the nodes,
// the quadrature points are carried (x̂ → y(x̂), w → w det F), the field values at the points are
// kept, their gradients and Hessians pushed forward, the basis rebuilt; nothing is projected.
void DynamicsIntegrator::reset_reference() {
  const double t0 = MPI_Wtime();
  apply_schedule(t_);  // before and after at the same constants (a folding attempt set those of t + dt)
  const double energy_before = energy_of(ref_->u);
  const std::vector<double> constraints_before = constraint_values(ref_->u);
  const std::vector<double> y = to_original(*ref_->space.disc, ref_->u, bs_);
  CarriedReference carried = carry_reference(*ref_, run_.cells, y, jets_);
  auto [positions, state] = material_node_positions(y);
  ref_ = build_reference(NodeSet(dim_, std::move(positions)), state, std::move(carried.quadrature), std::move(carried.jets), true,
                         material_fields());
  apply_schedule(t_);
  // The same physical state: energy and constraints unchanged up to the basis' consistency error.
  ResetChange change;
  change.energy = relative(energy_of(ref_->u), energy_before);
  for (const PointKinematics& k : point_kinematics(*ref_, state, 2)) {
    for (int i = 0; i < dim_; ++i)
      for (int I = 0; I < dim_; ++I)
        change.gradient_consistency = std::max(change.gradient_consistency, std::abs(k.F[std::size_t(i * dim_ + I)] - (i == I ? 1.0 : 0.0)));
    for (int s = 0; s < dim_ * dim_ * dim_; ++s) change.hessian_consistency = std::max(change.hessian_consistency, std::abs(k.H[std::size_t(s)]));
  }
  MPI_Allreduce(MPI_IN_PLACE, &change.gradient_consistency, 1, MPI_DOUBLE, MPI_MAX, comm_);
  MPI_Allreduce(MPI_IN_PLACE, &change.hessian_consistency, 1, MPI_DOUBLE, MPI_MAX, comm_);
  const std::vector<double> constraints_after = constraint_values(ref_->u);
  for (std::size_t i = 0; i < k_; ++i) change.constraints.push_back(relative(constraints_after[i], constraints_before[i]));
  run_.reset_changes.push_back(change);
  if (out_ != nullptr) {
    std::string c;
    for (std::size_t i = 0; i < k_; ++i) c += fmt::format(", {} {:+.1e}", run_.constraint_names[i], change.constraints[i]);
    const std::size_t outside = ref_->space.disc->points_outside_carried_cells();
    *out_ << fmt::format("  reset {} of the reference configuration at step {}: relative change of E {:+.1e}{}; identity reproduced to "
                         "|F - I| {:.1e}, |D2 y| {:.1e}{}\n",
                         run_.resets + 1, step_, change.energy, c, change.gradient_consistency, change.hessian_consistency,
                         outside == 0 ? std::string()
                                      : fmt::format("; {} points carried out of their cells took an enclosing cell's vertices", outside))
          << std::flush;
  }
  ++run_.resets;
  steps_since_reset_ = 0;
  run_.seconds_reset += MPI_Wtime() - t0;
}

namespace {

/// |∇φ| at the nodes of a scalar field, 0 on the box's walls, where the field is at its far value
/// (a motion can leave a node at a vertex of its neighbours' hull: measured beside the waist of the
/// eps = 0.01 prolate at step 150).
std::vector<double> field_gradient_norm(const NodeSet& nodes, std::span<const double> field, const Box& box, const LmeBasis& basis,
                                        std::size_t& undefined) {
  std::vector<char> on_wall(nodes.size(), 0);
  for (std::size_t a = 0; a < nodes.size(); ++a) {
    const auto x = nodes.point(a);
    for (std::size_t i = 0; i < std::size_t(nodes.dim); ++i) {
      const double tol = 1e-9 * (box.hi[i] - box.lo[i]);
      if (x[i] <= box.lo[i] + tol || x[i] >= box.hi[i] - tol) on_wall[a] = 1;
    }
  }
  return nodal_gradient_norm(basis, field, on_wall, &undefined);
}

/// More nodes than `current`: the current ones keep their places (a good start for Lloyd), and one
/// is added at the centroid of each of the cells that hold most of a CVT's nodes for their size,
/// the measure times ρ^(dim/(dim+2)) (the node density of a CVT with density ρ).
NodeSet with_added_nodes(const NodeSet& current, const Density& density, std::size_t total, const std::string& source) {
  const std::size_t n = current.size();
  const int dim = current.dim;
  if (total < n)
    throw std::runtime_error(fmt::format("{}: [dynamics] remesh_nodes = {} is below the {} nodes of the run: a re-mesh adds nodes, it does "
                                         "not remove them",
                                         source, total, n));
  const BackgroundCells cells = delaunay(current);
  std::vector<std::pair<double, std::size_t>> share(cells.size());
  std::vector<double> centroids(cells.size() * std::size_t(dim), 0.0);
  for (std::size_t c = 0; c < cells.size(); ++c) {
    const std::span<double> x(centroids.data() + c * std::size_t(dim), std::size_t(dim));
    for (const int v : cells.cell(c))
      for (int i = 0; i < dim; ++i) x[std::size_t(i)] += current.point(std::size_t(v))[std::size_t(i)] / double(dim + 1);
    share[c] = {cells.measures[c] * std::pow(density(x), double(dim) / double(dim + 2)), c};
  }
  const std::size_t added = total - n;
  if (added > cells.size())
    throw std::runtime_error(fmt::format("{}: [dynamics] remesh_nodes = {}: a re-mesh adds at most one node per cell, {} to the {} nodes "
                                         "of the run",
                                         source, total, cells.size(), n));
  std::partial_sort(share.begin(), share.begin() + std::ptrdiff_t(added), share.end(), std::greater<>());
  std::vector<double> coords = current.coords;
  for (std::size_t pick = 0; pick < added; ++pick) {
    const std::size_t c = share[pick].second;
    coords.insert(coords.end(), centroids.begin() + std::ptrdiff_t(c * std::size_t(dim)),
                  centroids.begin() + std::ptrdiff_t((c + 1) * std::size_t(dim)));
  }
  return NodeSet(dim, std::move(coords));
}

}  // namespace

/// The new nodes: CVT for the density 1 + f |∇φ| of the current field, from the current nodes
/// (with nodes added when remesh_nodes asks for more).
NodeSet DynamicsIntegrator::remeshed_nodes(const NodeSet& current, std::string& notes) const {
  const auto field = std::find_if(scalar_fields_.begin(), scalar_fields_.end(), [&](const auto& f) { return f.first == settings_.remesh_field; });
  std::size_t undefined = 0;
  const LmeBasis basis(current, std::vector<double>(n_nodes_, bound_.discretization.gamma), bound_.lme(AxisParity::even));
  const std::vector<double> grad_norm = field_gradient_norm(current, field->second, scene_.domain, basis, undefined);
  if (undefined > 0)
    notes += fmt::format("; the density took a neighbour's |grad {}| at {} nodes where the gradient is undefined", settings_.remesh_field,
                         undefined);
  CvtOptions cvt;
  cvt.iterations = settings_.remesh_iterations;
  const Density density = phase_field_density(settings_.remesh_factor, current, grad_norm);
  const bool more = settings_.remesh_nodes > 0 && settings_.remesh_nodes != n_nodes_;
  const NodeSet start = more ? with_added_nodes(current, density, settings_.remesh_nodes, scene_.source) : current;
  return cvt_relocate(start, scene_.domain, density, cvt);
}

/// Every scalar nodal field carried to the new nodes. A field with a value jet is known exactly at
/// the current quadrature points (a material field, carried): its L2 (or H1) projection onto the
/// new space depends on no node positions. Otherwise the new nodal values make the new LME field
/// take the old field's values at the new nodes.
std::map<std::string, std::vector<double>, std::less<>> DynamicsIntegrator::projected_fields(const NodeSet& current, const NodeSet& nodes,
                                                                                             const std::vector<double>& y,
                                                                                             std::string& notes) const {
  auto from_points = [&](const std::string& name) {
    const auto j = jets_.find(name);
    return settings_.remesh_projection == DynamicsSettings::Projection::points && j != jets_.end() && ref_->space.qdata.contains(j->second.value);
  };
  std::optional<CarriedReference> carried;  // the current quadrature points, weights and gradients
  if (std::any_of(scalar_fields_.begin(), scalar_fields_.end(), [&](const auto& f) { return from_points(f.first); }))
    carried = carry_reference(*ref_, run_.cells, y, jets_);
  const double gamma = bound_.discretization.gamma;
  const LmeOptions lme = bound_.lme(AxisParity::even);  // scalar fields are even in r
  std::map<std::string, std::vector<double>, std::less<>> projected;
  for (const auto& [name, values] : scalar_fields_) {
    // From the points, the old field at the new nodes only starts the CG iteration: where the
    // motion tore the old nodes apart and their basis cannot be evaluated, the nearest old value
    // does. Fitted to the old field, it must be evaluated everywhere.
    std::size_t fallbacks = 0;
    const std::vector<double> interpolated = interpolate_nodal_field(current, values, gamma, lme, nodes, from_points(name) ? &fallbacks : nullptr);
    if (fallbacks > 0) notes += fmt::format("; the CG start took the nearest old value at {} new nodes", fallbacks);
    if (!from_points(name)) {
      projected[name] = fit_nodal_values(nodes, interpolated, gamma, lme, settings_.remesh_fit_iterations);
      continue;
    }
    const FieldJets& j = jets_.at(name);
    const bool h1 = settings_.remesh_gradient_length > 0 && carried->jets.contains(j.gradient);
    PointProjection fit;
    try {
      fit = project_point_values(nodes, gamma, lme, carried->quadrature.quadrature.points, carried->quadrature.quadrature.weights,
                                 carried->jets.at(j.value), interpolated, 1e-8, 5000,
                                 h1 ? PointGradients{carried->jets.at(j.gradient), settings_.remesh_gradient_length} : PointGradients{});
    } catch (const LmeEvaluationError& e) {
      // Measured on the eps = 0.01 prolate at step 120 (f = 1000 and 300): a carried quadrature
      // point beside the waist lay outside the hull of its new neighbours, whether the CVT started
      // from the coefficients y_a or from y(X_a). The run stops here, before anything is replaced.
      throw std::runtime_error(fmt::format("re-mesh {} at step {} (t* = {:.6e}, remesh_factor = {}, remesh_iterations = {}): a carried "
                                           "quadrature point cannot be evaluated on the new nodes: {}",
                                           run_.remeshes + 1, step_, t_, settings_.remesh_factor, settings_.remesh_iterations, e.what()));
    }
    projected[name] = std::move(fit.values);
    notes += fmt::format("; '{}' {}-projected from the points ({} CG iterations, relative residual {:.1e})", name, h1 ? "H1" : "L2",
                         fit.iterations, fit.relative_residual);
  }
  return projected;
}

// A full re-mesh (the cases resets cannot help: nodes accumulated or spread too thin): new nodes by
// CVT for the density 1 + f |∇φ| of the current field, every scalar nodal field projected onto
// them (a projection changes E, and the change is reported), the motion restarted from the
// identity on a new triangulation and quadrature.
bool DynamicsIntegrator::remesh() {
  const double t0 = MPI_Wtime();
  apply_schedule(t_);
  const double energy_before = energy_of(ref_->u);
  // The current node positions start the CVT, carry the density |∇φ| and, for fields without point
  // values, the interpolated field: the coefficients y_a, where the new basis reproduces the first
  // moments the old one does through the map (on the test box, with nodes at y(X_a) the step after
  // a `nodes` re-mesh raised E). A coefficient that left the box takes y(X_a) instead, which stays
  // inside.
  const std::vector<double> y = to_original(*ref_->space.disc, ref_->u, bs_);
  const std::vector<double> inside = material_node_positions(y).first;
  std::vector<double> positions(n_nodes_ * std::size_t(dim_));
  const auto d = std::size_t(dim_);
  for (std::size_t a = 0; a < n_nodes_; ++a) {
    bool out_of_box = false;
    for (std::size_t i = 0; i < d; ++i) {
      const double x = y[a * std::size_t(bs_) + std::size_t(offset_) + i];
      out_of_box = out_of_box || x < scene_.domain.lo[i] || x > scene_.domain.hi[i];
    }
    for (std::size_t i = 0; i < d; ++i) positions[a * d + i] = out_of_box ? inside[a * d + i] : y[a * std::size_t(bs_) + std::size_t(offset_) + i];
  }
  const NodeSet current(dim_, positions);
  std::string notes;
  const NodeSet nodes = remeshed_nodes(current, notes);
  // The new values are gathered first and replace the old ones only when every field is carried.
  std::map<std::string, std::vector<double>, std::less<>> projected = projected_fields(current, nodes, y, notes);
  BackgroundCells cells = delaunay(nodes);
  // The projection is the one operation that can change the membrane's topology: checked before
  // anything is replaced, so that the guard leaves the last accepted step as it was.
  std::optional<LevelSetTopology> topology;
  if (topology_values() != nullptr) topology = membrane_topology(nodes, cells, projected.at(settings_.topology_field));
  if (topology && topology_) {
    const std::string where = fmt::format("re-mesh {} (step {})", run_.remeshes + 1, step_);
    const std::string change = topology_change_warning(*topology_, *topology, where);
    if (!change.empty() && settings_.topology_guard) {
      run_.failure = change + "; dynamics.topology_guard rejects the re-mesh and stops at the step before it";
      run_.seconds_reset += MPI_Wtime() - t0;
      return false;
    }
    if (!change.empty()) {
      const std::string warning = change + " (the projection onto the new nodes joined or split the interface; "
                                           "dynamics.topology_guard = true stops the run before such a re-mesh)";
      run_.warnings.push_back(warning);
      if (out_ != nullptr) *out_ << "lmeform: warning: " << warning << "\n";
    }
  }
  if (topology) topology_ = topology;
  for (auto& [name, values] : scalar_fields_) values = projected.at(name);
  material_nodes_ = nodes;
  dirichlet_sets_ = dirichlet_nodes(bound_, material_nodes_);
  n_nodes_ = nodes.size();
  run_.cells = std::move(cells);
  velocity_.assign(n_nodes_ * std::size_t(bs_), 0.0);
  std::vector<double> identity(n_nodes_ * std::size_t(bs_), 0.0);
  for (std::size_t a = 0; a < n_nodes_; ++a)
    for (std::size_t i = 0; i < d; ++i) identity[a * std::size_t(bs_) + std::size_t(offset_) + i] = nodes.point(a)[i];
  ref_ = build_reference(nodes, identity, std::nullopt, {}, true, std::move(projected));
  apply_schedule(t_);
  run_.reference_nodes = material_nodes_;
  ++run_.remeshes;
  steps_since_remesh_ = steps_since_reset_ = 0;
  run_.remesh_changes.push_back(relative(energy_of(ref_->u), energy_before));
  if (out_ != nullptr)
    *out_ << fmt::format("  re-mesh {} at step {}: {} nodes, the projection changed E by {:+.2e} (relative){}\n", run_.remeshes, step_,
                         n_nodes_, run_.remesh_changes.back(), notes)
          << std::flush;
  run_.seconds_reset += MPI_Wtime() - t0;
  return true;
}

}  // namespace lmeform::problems
