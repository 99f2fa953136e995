// End to end: kernels generated at build time (lmeform_add_forms) from the test forms, called on
// one cell with a synthetic tabulation, checked against finite differences: gradient vs FD of the
// value, Hessian/Jacobian vs FD of the vector kernel, symmetry, and consistency between the
// residual, bilinear, linear and energy versions of the same Poisson problem.
#include <gtest/gtest.h>

#include <Eigen/Dense>
#include <cmath>
#include <random>
#include <span>
#include <vector>

#include "axisymmetric_kernels.hpp"
#include "lagrangian_kernels.hpp"
#include "phasefield_kernels.hpp"
#include "poisson_kernels.hpp"
#include "stokes_kernels.hpp"
#include "unit_vectors_kernels.hpp"
#include "lmeform/compiler/ir.hpp"

using lmeform::kernel::CellInputs;
using lmeform::kernel::FormKernels;
using lmeform::kernel::FunctionalKind;

namespace {

/// A cell with a synthetic tabulation: random values and Hessians, and gradients that reproduce
/// linear functions exactly (Σ_a ∇p_a X_aᵀ = I), so that y = X + noise gives F ≈ I.
struct Cell {
  int dim = 2, n = 0, nq = 0, order = 2;
  std::vector<double> weights, points, basis, X, unknowns, coefficients, qdata, constants, workspace;

  Cell(const FormKernels& k, unsigned seed) : dim(k.dim) {
    std::mt19937 rng(seed);
    std::uniform_real_distribution<double> U(-1.0, 1.0);
    n = dim == 2 ? 6 : 9;
    nq = 3;
    const int J = lmeform::kernel::jet_size(dim, order);
    X.resize(std::size_t(n) * dim);
    for (auto& v : X) v = 1.0 + 0.5 * U(rng);
    Eigen::Map<Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>> Xm(X.data(), n, dim);
    const Eigen::MatrixXd M = (Xm.transpose() * Xm).inverse();
    basis.resize(std::size_t(nq) * J * n);
    for (int q = 0; q < nq; ++q) {
      weights.push_back(0.2 + 0.1 * q);
      for (int i = 0; i < dim; ++i) points.push_back(1.0 + 0.3 * U(rng));
      double* Bq = basis.data() + std::size_t(q) * J * n;
      for (int a = 0; a < n; ++a) Bq[a] = 1.0 / n + 0.05 * U(rng);
      Eigen::MatrixXd G0(dim, n);
      for (int i = 0; i < dim; ++i)
        for (int a = 0; a < n; ++a) G0(i, a) = 0.5 * U(rng);
      const Eigen::MatrixXd G = G0 + (Eigen::MatrixXd::Identity(dim, dim) - G0 * Xm) * M * Xm.transpose();
      for (int i = 0; i < dim; ++i)
        for (int a = 0; a < n; ++a) Bq[(1 + i) * n + a] = G(i, a);
      for (int s = 1 + dim; s < J; ++s)
        for (int a = 0; a < n; ++a) Bq[s * n + a] = 0.3 * U(rng);
    }
    // Unknowns: vector fields near the identity map, scalars small.
    for (int a = 0; a < n; ++a)
      for (int f = 0; f < k.n_unknowns; ++f)
        for (int c = 0; c < k.unknowns[f].components; ++c)
          unknowns.push_back(k.unknowns[f].components == dim && dim > 1 ? X[a * dim + c] + 0.05 * U(rng) : 0.4 * U(rng));
    for (int i = 0; i < n * k.coefficient_components_per_node; ++i) coefficients.push_back(0.4 * U(rng));
    for (int i = 0; i < nq * k.qdata_per_point; ++i) qdata.push_back(0.5 * U(rng));
    for (int i = 0; i < k.n_constants; ++i) constants.push_back(0.9 + 0.1 * i);
    workspace.resize(k.workspace_doubles(n, nq));
  }

  CellInputs inputs(std::span<const double> u) {
    CellInputs in;
    in.n_nodes = n;
    in.n_points = nq;
    in.basis_order = order;
    in.weights = weights.data();
    in.points = points.data();
    in.basis = basis.data();
    in.unknowns = u.data();
    in.coefficients = coefficients.data();
    in.qdata = qdata.data();
    in.constants = constants.data();
    in.workspace = workspace.data();
    return in;
  }
  std::size_t ndofs(const FormKernels& k) const { return std::size_t(n) * k.dofs_per_node; }
  double value(const FormKernels& k, const std::vector<double>& u) { return k.value(inputs(u)); }
  std::vector<double> vector(const FormKernels& k, const std::vector<double>& u, std::size_t rows) {
    std::vector<double> out(rows, 0.0);
    k.vector(inputs(u), out.data());
    return out;
  }
  std::vector<double> matrix(const FormKernels& k, const std::vector<double>& u, std::size_t rows, std::size_t cols) {
    std::vector<double> out(rows * cols, 0.0);
    k.matrix(inputs(u), out.data());
    return out;
  }
};

double max_abs(const std::vector<double>& v) {
  double m = 0;
  for (double x : v) m = std::max(m, std::abs(x));
  return m;
}

void check_kernels(const FormKernels& k) {
  SCOPED_TRACE(std::string(k.module) + "." + k.name + " " + std::to_string(k.dim) + "d");
  Cell cell(k, 1234 + static_cast<unsigned>(k.dim));
  const std::size_t N = cell.ndofs(k);
  const std::vector<double> u = cell.unknowns;
  const double h = 1e-6;
  if (k.value) {
    ASSERT_NE(k.vector, nullptr);
    const auto g = cell.vector(k, u, N);
    const double scale = 1.0 + max_abs(g);
    for (std::size_t i = 0; i < N; ++i) {
      auto up = u, um = u;
      up[i] += h;
      um[i] -= h;
      const double fd = (cell.value(k, up) - cell.value(k, um)) / (2 * h);
      EXPECT_NEAR(g[i], fd, 1e-6 * scale) << "gradient dof " << i;
    }
  }
  if (k.matrix && k.vector) {
    const auto H = cell.matrix(k, u, N, N);
    const double scale = 1.0 + max_abs(H);
    for (std::size_t j = 0; j < N; ++j) {
      auto up = u, um = u;
      up[j] += h;
      um[j] -= h;
      const auto gp = cell.vector(k, up, N), gm = cell.vector(k, um, N);
      for (std::size_t i = 0; i < N; ++i)
        EXPECT_NEAR(H[i * N + j], (gp[i] - gm[i]) / (2 * h), 1e-6 * scale) << "matrix entry " << i << "," << j;
    }
    if (k.kind == FunctionalKind::Energy || k.kind == FunctionalKind::Constraint) {
      for (std::size_t i = 0; i < N; ++i)
        for (std::size_t j = 0; j < i; ++j) EXPECT_NEAR(H[i * N + j], H[j * N + i], 1e-12 * scale);
    }
  }
}

template <std::size_t K>
void check_all(const FormKernels* const (&all)[K]) {
  for (const FormKernels* k : all)
    if (k->kind != FunctionalKind::Bilinear && k->kind != FunctionalKind::Linear) check_kernels(*k);
}

}  // namespace

TEST(GeneratedKernels, JetLayoutMatchesTheContract) {
  for (int d = 1; d <= 3; ++d) {
    for (int o = 0; o <= 2; ++o) EXPECT_EQ(lmeform::kernel::jet_size(d, o), lmeform::compiler::ir::jet_size(d, o));
    for (int i = 0; i < d; ++i)
      for (int j = 0; j < d; ++j) EXPECT_EQ(lmeform::kernel::hessian_slot(i, j, d), lmeform::compiler::ir::hessian_slot(i, j, d));
  }
}

TEST(GeneratedKernels, PhaseFieldScalarEnergy) { check_all(phasefield_all_kernels); }
TEST(GeneratedKernels, AxisymmetricEnergyAndConstraint) {
  check_all(axisymmetric_all_kernels);
  EXPECT_EQ(axisymmetric_area_2d.target_constant, 1);
  EXPECT_EQ(axisymmetric_area_2d.kind, FunctionalKind::Constraint);
}
TEST(GeneratedKernels, LagrangianVectorUnknown) { check_all(lagrangian_all_kernels); }
TEST(GeneratedKernels, StokesMixedResidual) { check_all(stokes_all_kernels); }
TEST(GeneratedKernels, PoissonResidualAndEnergy) { check_all(poisson_all_kernels); }

TEST(GeneratedKernels, PoissonFormsAgree) {
  for (const auto* set : {&poisson_R_2d, &poisson_R_3d}) {
    const int dim = set->dim;
    const FormKernels& R = *set;
    const FormKernels& A = dim == 2 ? poisson_a_2d : poisson_a_3d;
    const FormKernels& L = dim == 2 ? poisson_l_2d : poisson_l_3d;
    const FormKernels& E = dim == 2 ? poisson_E_2d : poisson_E_3d;
    Cell cell(R, 99);
    const std::size_t N = cell.ndofs(R);
    const std::vector<double> zero(N, 0.0);
    // a(w, v) = dR/du at u = 0 (the T^3 term vanishes there); l(v) = -R(0; v).
    const auto Jac0 = cell.matrix(R, zero, N, N);
    const auto Amat = cell.matrix(A, zero, N, N);
    for (std::size_t i = 0; i < N * N; ++i) EXPECT_NEAR(Jac0[i], Amat[i], 1e-12);
    const auto R0 = cell.vector(R, zero, N);
    const auto l = cell.vector(L, zero, N);
    for (std::size_t i = 0; i < N; ++i) EXPECT_NEAR(R0[i], -l[i], 1e-12);
    // The energy's gradient is the residual.
    const auto gE = cell.vector(E, cell.unknowns, N);
    const auto Ru = cell.vector(R, cell.unknowns, N);
    for (std::size_t i = 0; i < N; ++i) EXPECT_NEAR(gE[i], Ru[i], 1e-12);
    EXPECT_EQ(R.basis_order, 1);
    EXPECT_EQ(A.matrix != nullptr, true);
    EXPECT_EQ(A.vector, nullptr);
  }
}

TEST(GeneratedKernels, UnitVectorsInTwoAndThreeDimensions) {
  check_all(unit_vectors_all_kernels);
  for (const FormKernels* k : {&unit_vectors_E_2d, &unit_vectors_E_3d}) {
    const int dim = k->dim;
    SCOPED_TRACE(dim);
    Cell cell(*k, 7);
    // The value against the integrand evaluated here: b = (sin x0, cos x1[, x2]).
    double expected = 0;
    for (int q = 0; q < cell.nq; ++q) {
      const double* x = cell.points.data() + std::size_t(q) * dim;
      const double* Bq = cell.basis.data() + std::size_t(q) * lmeform::kernel::jet_size(dim, cell.order) * cell.n;
      std::vector<double> y(std::size_t(dim), 0.0), b = {std::sin(x[0]), std::cos(x[1])};
      if (dim == 3) b.push_back(x[2]);
      for (int a = 0; a < cell.n; ++a)
        for (int c = 0; c < dim; ++c) y[std::size_t(c)] += Bq[a] * cell.unknowns[std::size_t(a) * dim + c];
      double yy = 0, bb = 0, yb = 0;
      for (std::size_t c = 0; c < std::size_t(dim); ++c) {
        yy += y[c] * y[c];
        bb += b[c] * b[c];
        yb += y[c] * b[c];
      }
      expected += cell.weights[std::size_t(q)] * (cell.constants[0] / 2 * yy * bb + yb / dim);
    }
    EXPECT_NEAR(cell.value(*k, cell.unknowns), expected, 1e-12 * (1 + std::abs(expected)));
  }
}
