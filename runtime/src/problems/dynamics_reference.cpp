#include "dynamics_reference.hpp"

#include <Eigen/Dense>

#include <algorithm>

#include <fmt/format.h>

#include "expressions.hpp"
#include "lmeform/kernel.hpp"
#include "point_values.hpp"

namespace lmeform::problems {

ReferenceConfiguration::ReferenceConfiguration(MPI_Comm comm, const BoundScene& b, const ProblemInput& input,
                                               const ConstrainedMinimizerOptions& options, bool forward_euler, const std::string& deformation)
    : space(build_problem_space(comm, b, input)),
      nodes(input.nodes),
      deformation_offset(b.unknown(deformation).offset),
      kinematics(&compile_kinematics_form(b.dim, deformation, comm, nullptr)) {
  minimizer = std::make_unique<ConstrainedMinimizer>(space.energy_terms, space.constraints, options);
  minimizer->set_fixed_dofs(space.fixed);
  Assembler& primary = *space.primary;
  u = primary.create_vector();
  yn = primary.create_vector();
  trial = primary.create_vector();
  gradient = primary.create_vector();
  w = primary.create_vector();
  for (std::size_t i = 0; i < space.constraints.size(); ++i) {
    G.push_back(primary.create_vector());
    Z.push_back(primary.create_vector());
  }
  set_from_original(*space.disc, space.state, b.layout.dofs_per_node, u);
  Assembler& dissipation = *space.auxiliary.front();
  K = dissipation.create_matrix();
  dissipation_coefficients = space.coefficient_vectors.at(b.auxiliary.front().label);
  const kernel::FormKernels& k = dissipation.form();
  for (int i = 0; i < k.n_coefficients; ++i) {
    if (k.coefficients[i].name == deformation) coefficient_offset = coefficients_per_node;
    coefficients_per_node += k.coefficients[i].components;
  }
  if (forward_euler) {
    LMEFORM_PETSC_CHECK(KSPCreate(comm, euler_ksp.out()));
    configure_direct_solver(euler_ksp);
  }
}

std::vector<PointKinematics> point_kinematics(const ReferenceConfiguration& ref, const std::vector<double>& y_original, int order) {
  const Discretization& disc = *ref.space.disc;
  const int dim = disc.dim();
  const int bs = ref.space.primary->block_size();
  auto values_of = [&](const char* output) {
    return point_values_on_cells(disc, ref.kinematics->at(output, dim), y_original, bs, ref.deformation_offset);
  };
  const CellPointValues position = values_of("position"), F = values_of("F");
  const CellPointValues H = order >= 2 ? values_of("H") : CellPointValues{};
  const auto d = std::size_t(dim);
  std::vector<PointKinematics> out(position.points.size());
  for (std::size_t r = 0; r < out.size(); ++r) {
    PointKinematics& p = out[r];
    p.point = position.points[r];
    std::copy_n(position.values.begin() + std::ptrdiff_t(r * d), d, p.position.begin());
    std::copy_n(F.values.begin() + std::ptrdiff_t(r * d * d), d * d, p.F.begin());
    if (order >= 2) std::copy_n(H.values.begin() + std::ptrdiff_t(r * d * d * d), d * d * d, p.H.begin());
  }
  return out;
}

namespace {

Eigen::MatrixXd matrix_of(const std::array<double, 9>& F, int dim) {
  Eigen::MatrixXd M(dim, dim);
  for (int i = 0; i < dim; ++i)
    for (int j = 0; j < dim; ++j) M(i, j) = F[std::size_t(i * dim + j)];
  return M;
}

void sum_over_ranks(std::vector<double>& v, MPI_Comm comm) {
  MPI_Allreduce(MPI_IN_PLACE, v.data(), static_cast<int>(v.size()), MPI_DOUBLE, MPI_SUM, comm);
}

}  // namespace

DeformationMeasures deformation_measures(const ReferenceConfiguration& ref, const std::vector<double>& y, bool axisymmetric) {
  const Discretization& disc = *ref.space.disc;
  const int dim = disc.dim();
  DeformationMeasures local;
  for (const PointKinematics& p : point_kinematics(ref, y, 1)) {
    const Eigen::MatrixXd M = matrix_of(p.F, dim);
    double det = M.determinant();
    const Eigen::VectorXd sv = Eigen::JacobiSVD<Eigen::MatrixXd>(M).singularValues();
    double largest = sv.maxCoeff(), smallest = sv.minCoeff();
    const auto X = disc.quadrature().point(std::size_t(p.point));
    if (axisymmetric && X[0] > 0) {
      const double hoop = p.position[0] / X[0];
      det *= hoop;
      largest = std::max(largest, std::abs(hoop));
      smallest = std::min(smallest, std::abs(hoop));
    }
    if (det < local.min_jacobian) {
      local.min_jacobian = det;
      local.point = long(disc.global_point(std::size_t(p.point)));
      std::copy(X.begin(), X.end(), local.position.begin());
    }
    if (smallest > 0) local.max_distortion = std::max(local.max_distortion, largest / smallest);
  }
  // The rank holding the smallest det F tells where it is.
  int rank = 0;
  MPI_Comm_rank(disc.comm(), &rank);
  struct {
    double value;
    int rank;
  } in{local.min_jacobian, rank}, out{};
  MPI_Allreduce(&in, &out, 1, MPI_DOUBLE_INT, MPI_MINLOC, disc.comm());
  DeformationMeasures all = local;
  all.min_jacobian = out.value;
  MPI_Bcast(&all.point, 1, MPI_LONG, out.rank, disc.comm());
  MPI_Bcast(all.position.data(), 3, MPI_DOUBLE, out.rank, disc.comm());
  MPI_Allreduce(MPI_IN_PLACE, &all.max_distortion, 1, MPI_DOUBLE, MPI_MAX, disc.comm());
  return all;
}

std::vector<double> every_point_values(const Discretization& disc, std::span<const double> local, std::size_t size) {
  const ElementSet& cells = disc.cells_domain();
  std::vector<double> out(disc.cells().size() * std::size_t(disc.quadrature().points_per_cell) * size, 0.0);
  for (int e = 0; e < cells.n_elements(); ++e) {
    if (!cells.element_owned(e)) continue;
    for (int k = 0; k < cells.element_point_count(e); ++k) {
      const auto q = std::size_t(cells.element_first_point(e) + k);
      std::copy_n(local.begin() + std::ptrdiff_t(q * size), size, out.begin() + std::ptrdiff_t(disc.global_point(q) * size));
    }
  }
  sum_over_ranks(out, disc.comm());
  return out;
}

CarriedQuadrature every_point_quadrature(const Discretization& disc, const BackgroundCells& cells) {
  const CellQuadrature& quad = disc.quadrature();
  CarriedQuadrature out;
  out.cells = cells;
  out.quadrature.dim = quad.dim;
  out.quadrature.points_per_cell = quad.points_per_cell;
  out.quadrature.points = every_point_values(disc, quad.points, std::size_t(quad.dim));
  out.quadrature.weights = every_point_values(disc, quad.weights, 1);
  return out;
}

CarriedReference carry_reference(const ReferenceConfiguration& ref, const BackgroundCells& cells, const std::vector<double>& y,
                                 const std::map<std::string, FieldJets>& jets) {
  const Discretization& disc = *ref.space.disc;
  const int dim = disc.dim();
  const auto d = std::size_t(dim);
  const CellQuadrature& quad = disc.quadrature();
  const std::size_t Q = disc.cells().size() * std::size_t(quad.points_per_cell);  // every point, numbered as the cells
  const auto& qdata = ref.space.qdata;
  CarriedReference out;
  out.quadrature.cells = cells;
  out.quadrature.quadrature.dim = dim;
  out.quadrature.quadrature.points_per_cell = quad.points_per_cell;
  out.quadrature.quadrature.points.assign(Q * d, 0.0);
  out.quadrature.quadrature.weights.assign(Q, 0.0);
  // Jets no assembler reads are not carried (a field's Hessian needs its gradient: checked at the start).
  std::map<std::string, FieldJets> carried;
  for (const auto& [field, j] : jets) {
    FieldJets c;
    if (qdata.contains(j.value)) c.value = j.value;
    if (qdata.contains(j.gradient)) c.gradient = j.gradient;
    if (qdata.contains(j.hessian) && !c.gradient.empty()) c.hessian = j.hessian;
    if (!c.value.empty()) out.jets[c.value].assign(Q, 0.0);  // material: unchanged
    if (!c.gradient.empty()) out.jets[c.gradient].assign(Q * d, 0.0);
    if (!c.hessian.empty()) out.jets[c.hessian].assign(Q * d * d, 0.0);
    carried[field] = c;
  }
  // D²y only where a Hessian is pushed forward (positions and F need the gradients alone).
  const bool hessians = std::any_of(carried.begin(), carried.end(), [](const auto& c) { return !c.second.hessian.empty(); });
  // Each rank computes the points of its owned elements (each point on one rank), in their
  // numbering on every rank; the sums over the ranks put them together.
  for (const PointKinematics& k : point_kinematics(ref, y, hessians ? 2 : 1)) {
    const auto p = std::size_t(k.point), g = disc.global_point(p);
    for (std::size_t i = 0; i < d; ++i) out.quadrature.quadrature.points[g * d + i] = k.position[i];
    const Eigen::MatrixXd F = matrix_of(k.F, dim);
    out.quadrature.quadrature.weights[g] = quad.weights[p] * F.determinant();
    const Eigen::MatrixXd Fi = F.inverse();  // Fi(I, i) = ∂X_I / ∂y_i
    for (const auto& [field, j] : carried) {
      if (!j.value.empty()) out.jets[j.value][g] = qdata.at(j.value)[p];
      if (j.gradient.empty()) continue;
      const Eigen::VectorXd grad = Fi.transpose() * Eigen::Map<const Eigen::VectorXd>(qdata.at(j.gradient).data() + p * d, dim);
      for (std::size_t i = 0; i < d; ++i) out.jets[j.gradient][g * d + i] = grad[Eigen::Index(i)];
      if (j.hessian.empty()) continue;
      // ∂²φ/∂y_i∂y_j = Fi_Ii Fi_Jj (∂²φ0/∂X_I∂X_J − Σ_k ∂φ/∂y_k ∂²y_k/∂X_I∂X_J)
      const auto& h0 = qdata.at(j.hessian);
      Eigen::MatrixXd M(dim, dim);
      for (std::size_t I = 0; I < d; ++I)
        for (std::size_t K = 0; K < d; ++K) {
          double m = h0[p * d * d + I * d + K];
          for (std::size_t kk = 0; kk < d; ++kk) m -= grad[Eigen::Index(kk)] * k.H[(kk * d + I) * d + K];
          M(Eigen::Index(I), Eigen::Index(K)) = m;
        }
      const Eigen::MatrixXd h = Fi.transpose() * M * Fi;
      for (std::size_t i = 0; i < d; ++i)
        for (std::size_t jj = 0; jj < d; ++jj) out.jets[j.hessian][g * d * d + i * d + jj] = h(Eigen::Index(i), Eigen::Index(jj));
    }
  }
  sum_over_ranks(out.quadrature.quadrature.points, disc.comm());
  sum_over_ranks(out.quadrature.quadrature.weights, disc.comm());
  for (auto& [name, values] : out.jets) sum_over_ranks(values, disc.comm());
  return out;
}

}  // namespace lmeform::problems
