// Boundary and point kernels (generated at build time from data/boundary.form and
// data/kinematics.form) called on hand-built cells with known basis jets, normals and weights,
// against values written out by hand or computed here from the same jets.
#include <gtest/gtest.h>

#include <Eigen/Dense>
#include <cmath>
#include <functional>
#include <limits>
#include <random>
#include <string>
#include <vector>

#include "boundary_kernels.hpp"
#include "kinematics_kernels.hpp"

using lmeform::kernel::CellInputs;
using lmeform::kernel::FormKernels;
using lmeform::kernel::FunctionalKind;
using lmeform::kernel::hessian_slot;
using lmeform::kernel::IntegralDomain;
using lmeform::kernel::jet_size;

namespace {

/// A cell given entry by entry: basis jets up to second order, weights, points, normals.
struct HandCell {
  int dim = 2, n = 0, nq = 0;
  std::vector<double> weights, points, basis, normals, qdata, constants, workspace;

  HandCell(int d, int nodes, int points_) : dim(d), n(nodes), nq(points_) {
    basis.assign(std::size_t(nq) * jet_size(dim, 2) * n, 0.0);
    weights.assign(std::size_t(nq), 0.0);
    points.assign(std::size_t(nq) * dim, 0.0);
    normals.assign(std::size_t(nq) * dim, 0.0);
  }
  double& B(int q, int slot, int a) { return basis[(std::size_t(q) * jet_size(dim, 2) + slot) * n + a]; }
  /// Slot `slot` at point q of component c of a nodal field with `stride` values per node.
  double jet(int q, int slot, const std::vector<double>& nodal, int stride, int c) {
    double s = 0;
    for (int a = 0; a < n; ++a) s += B(q, slot, a) * nodal[std::size_t(a) * stride + c];
    return s;
  }
  /// Random jets, weights, points and unit normals.
  void randomize(unsigned seed) {
    std::mt19937 rng(seed);
    std::uniform_real_distribution<double> U(-1.0, 1.0);
    for (double& b : basis) b = U(rng);
    for (double& w : weights) w = 0.5 + 0.4 * U(rng);
    for (double& x : points) x = U(rng);
    for (int q = 0; q < nq; ++q) {
      double norm = 0;
      for (int i = 0; i < dim; ++i) norm += std::pow(normals[std::size_t(q) * dim + i] = U(rng), 2);
      for (int i = 0; i < dim; ++i) normals[std::size_t(q) * dim + i] /= std::sqrt(norm);
    }
  }
  CellInputs inputs(const FormKernels& k, const std::vector<double>& u, bool with_normals) {
    workspace.assign(k.workspace_doubles(n, nq) + 1, 0.0);
    CellInputs in;
    in.n_nodes = n;
    in.n_points = nq;
    in.basis_order = 2;
    in.weights = weights.data();
    in.points = points.data();
    in.basis = basis.data();
    in.unknowns = u.data();
    in.qdata = qdata.empty() ? nullptr : qdata.data();
    in.constants = constants.empty() ? nullptr : constants.data();
    in.workspace = workspace.data();
    in.normals = with_normals ? normals.data() : nullptr;
    return in;
  }
  std::vector<double> vector(const FormKernels& k, const std::vector<double>& u, bool with_normals) {
    std::vector<double> out(std::size_t(n) * k.dofs_per_node, 0.0);
    k.vector(inputs(k, u, with_normals), out.data());
    return out;
  }
  std::vector<double> matrix(const FormKernels& k, const std::vector<double>& u, bool with_normals) {
    const std::size_t N = std::size_t(n) * k.dofs_per_node;
    std::vector<double> out(N * N, 0.0);
    k.matrix(inputs(k, u, with_normals), out.data());
    return out;
  }
};

/// The kernels of `name` in dimension dim, in the module's order.
template <std::size_t K>
std::vector<const FormKernels*> kernels_named(const FormKernels* const (&all)[K], const std::string& name, int dim) {
  std::vector<const FormKernels*> out;
  for (const FormKernels* k : all)
    if (k->name == name && k->dim == dim) out.push_back(k);
  return out;
}

}  // namespace

TEST(DomainKernels, OneOutputHasOneKernelPerDomain) {
  for (const int dim : {2, 3}) {
    SCOPED_TRACE(dim);
    const auto E = kernels_named(boundary_all_kernels, "E", dim);
    ASSERT_EQ(E.size(), 2u);
    EXPECT_EQ(E[0]->domain, IntegralDomain::Cells);
    EXPECT_STREQ(E[0]->boundary_part, "");
    EXPECT_EQ(E[1]->domain, IntegralDomain::Boundary);
    EXPECT_STREQ(E[1]->boundary_part, "top");
    for (const FormKernels* k : E) {
      EXPECT_EQ(k->kind, FunctionalKind::Energy);
      EXPECT_EQ(k->contract_version, lmeform::kernel::kContractVersion);
      EXPECT_EQ(k->basis_order, 1) << "one layout for the output: the cells' gradient";
      EXPECT_EQ(k->dofs_per_node, 1);
      EXPECT_EQ(k->n_constants, 1);
      EXPECT_NE(k->value, nullptr);
      EXPECT_NE(k->vector, nullptr);
      EXPECT_NE(k->matrix, nullptr);
    }
    EXPECT_FALSE(E[0]->matrix_structurally_zero);
    EXPECT_TRUE(E[1]->matrix_structurally_zero) << "linear in u over ds(top)";
    const auto R = kernels_named(boundary_all_kernels, "R", dim);
    ASSERT_EQ(R.size(), 2u);
    EXPECT_EQ(R[1]->domain, IntegralDomain::Boundary);
    EXPECT_STREQ(R[1]->boundary_part, "");
    EXPECT_EQ(R[1]->kind, FunctionalKind::Residual);
    EXPECT_FALSE(R[1]->matrix_structurally_zero);
    const auto W = kernels_named(boundary_all_kernels, "W", dim);
    ASSERT_EQ(W.size(), 1u);
    EXPECT_STREQ(W[0]->boundary_part, "left");
    EXPECT_EQ(W[0]->basis_order, 2);
  }
}

// 2D, three nodes, one point: jets u = 2.3, grad u = (-1.5, -1) at x = (0.5, 0.7), w = 0.25, k = 2.
TEST(DomainKernels, MixedEnergyByHand) {
  HandCell c(2, 3, 1);
  const double B0[] = {0.2, 0.3, 0.5}, B1[] = {1.0, -0.5, -0.5}, B2[] = {0.0, 1.0, -1.0};
  for (int a = 0; a < 3; ++a) {
    c.B(0, 0, a) = B0[a];
    c.B(0, 1, a) = B1[a];
    c.B(0, 2, a) = B2[a];
  }
  c.weights = {0.25};
  c.points = {0.5, 0.7};
  c.normals = {0.0, 1.0};
  c.constants = {2.0};
  const std::vector<double> u = {1.0, 2.0, 3.0};
  // Over ds(top): -u x0.
  EXPECT_NEAR(boundary_E_ds_top_2d.value(c.inputs(boundary_E_ds_top_2d, u, true)), -0.25 * 2.3 * 0.5, 1e-15);
  const auto g_top = c.vector(boundary_E_ds_top_2d, u, true);
  EXPECT_NEAR(g_top[0], -0.025, 1e-15);
  EXPECT_NEAR(g_top[1], -0.0375, 1e-15);
  EXPECT_NEAR(g_top[2], -0.0625, 1e-15);
  for (const double h : c.matrix(boundary_E_ds_top_2d, u, true)) EXPECT_EQ(h, 0.0);
  // Over the cells (no normals): k/2 |grad u|^2 = 3.25; gradient k w grad(u).grad(p_a).
  EXPECT_NEAR(boundary_E_2d.value(c.inputs(boundary_E_2d, u, false)), 0.25 * 3.25, 1e-15);
  const auto g = c.vector(boundary_E_2d, u, false);
  const double expected_g[] = {2 * 0.25 * (-1.5 * 1.0), 2 * 0.25 * (-1.5 * -0.5 - 1.0 * 1.0), 2 * 0.25 * (-1.5 * -0.5 + 1.0)};
  for (int a = 0; a < 3; ++a) EXPECT_NEAR(g[std::size_t(a)], expected_g[a], 1e-15) << a;
  const auto H = c.matrix(boundary_E_2d, u, false);
  for (int a = 0; a < 3; ++a)
    for (int b = 0; b < 3; ++b) EXPECT_NEAR(H[std::size_t(a * 3 + b)], 0.5 * (B1[a] * B1[b] + B2[a] * B2[b]), 1e-15);
}

// R over ds: -(grad u . n) v. Two points, random jets and unit normals, in 2D and 3D.
TEST(DomainKernels, NitscheFluxReadsTheNormals) {
  for (const int dim : {2, 3}) {
    SCOPED_TRACE(dim);
    const FormKernels& R = dim == 2 ? boundary_R_ds_2d : boundary_R_ds_3d;
    HandCell c(dim, 5, 2);
    c.randomize(17 + static_cast<unsigned>(dim));
    const std::vector<double> u = {0.3, -0.2, 0.9, 0.4, -0.7};
    std::vector<double> expected_r(5, 0.0), expected_J(25, 0.0);
    for (int q = 0; q < 2; ++q) {
      const double* nq = c.normals.data() + std::size_t(q) * dim;
      double flux = 0;
      for (int i = 0; i < dim; ++i) flux += c.jet(q, 1 + i, u, 1, 0) * nq[i];
      for (int a = 0; a < 5; ++a) {
        expected_r[std::size_t(a)] -= c.weights[std::size_t(q)] * flux * c.B(q, 0, a);
        for (int b = 0; b < 5; ++b) {
          double dn = 0;
          for (int i = 0; i < dim; ++i) dn += c.B(q, 1 + i, b) * nq[i];
          expected_J[std::size_t(a * 5 + b)] -= c.weights[std::size_t(q)] * c.B(q, 0, a) * dn;
        }
      }
    }
    const auto r = c.vector(R, u, true);
    const auto J = c.matrix(R, u, true);
    for (int a = 0; a < 5; ++a) EXPECT_NEAR(r[std::size_t(a)], expected_r[std::size_t(a)], 1e-14);
    for (int i = 0; i < 25; ++i) EXPECT_NEAR(J[std::size_t(i)], expected_J[std::size_t(i)], 1e-14);
    // The opposite normals flip the flux.
    for (double& x : c.normals) x = -x;
    const auto flipped = c.vector(R, u, true);
    for (int a = 0; a < 5; ++a) EXPECT_NEAR(flipped[std::size_t(a)], -expected_r[std::size_t(a)], 1e-14);
  }
}

// W over ds(left): (n . hess(u) n)^2, value, gradient and Hessian from the second-order jets.
TEST(DomainKernels, NormalSecondDerivativeOnTheBoundary) {
  for (const int dim : {2, 3}) {
    SCOPED_TRACE(dim);
    const FormKernels& W = dim == 2 ? boundary_W_ds_left_2d : boundary_W_ds_left_3d;
    HandCell c(dim, 4, 2);
    c.randomize(5 + static_cast<unsigned>(dim));
    c.constants = {2.0};
    const std::vector<double> u = {0.5, -1.0, 0.25, 2.0};
    // nHn of the field u, and of each basis function a.
    auto nHn = [&](int q, const std::function<double(int slot)>& jet) {
      const double* nq = c.normals.data() + std::size_t(q) * dim;
      double s = 0;
      for (int i = 0; i < dim; ++i)
        for (int j = 0; j < dim; ++j) s += nq[i] * nq[j] * jet(hessian_slot(i, j, dim));
      return s;
    };
    double value = 0;
    std::vector<double> g(4, 0.0), H(16, 0.0);
    for (int q = 0; q < 2; ++q) {
      const double w = c.weights[std::size_t(q)];
      const double s = nHn(q, [&](int slot) { return c.jet(q, slot, u, 1, 0); });
      value += w * s * s;
      for (int a = 0; a < 4; ++a) {
        const double sa = nHn(q, [&](int slot) { return c.B(q, slot, a); });
        g[std::size_t(a)] += 2 * w * s * sa;
        for (int b = 0; b < 4; ++b) H[std::size_t(a * 4 + b)] += 2 * w * sa * nHn(q, [&](int slot) { return c.B(q, slot, b); });
      }
    }
    EXPECT_NEAR(W.value(c.inputs(W, u, true)), value, 1e-13 * (1 + std::abs(value)));
    const auto gk = c.vector(W, u, true);
    const auto Hk = c.matrix(W, u, true);
    for (int a = 0; a < 4; ++a) EXPECT_NEAR(gk[std::size_t(a)], g[std::size_t(a)], 1e-13);
    for (int i = 0; i < 16; ++i) EXPECT_NEAR(Hk[std::size_t(i)], H[std::size_t(i)], 1e-13);
  }
}

namespace {

/// Calls a point kernel on a buffer filled with garbage (point kernels overwrite) with a sentinel
/// tail (they write n_values per point, no more).
std::vector<double> point_values(const FormKernels& k, HandCell& c, const std::vector<double>& y) {
  EXPECT_EQ(k.kind, FunctionalKind::Point);
  EXPECT_NE(k.point, nullptr);
  EXPECT_EQ(k.value, nullptr);
  EXPECT_EQ(k.vector, nullptr);
  EXPECT_EQ(k.matrix, nullptr);
  const std::size_t size = std::size_t(c.nq) * k.n_values;
  std::vector<double> values(size + 4, 1e300);
  CellInputs in = c.inputs(k, y, false);
  in.weights = nullptr;  // point kernels read none
  k.point(in, values.data());
  for (std::size_t i = size; i < values.size(); ++i) EXPECT_EQ(values[i], 1e300) << "wrote past n_values";
  values.resize(size);
  return values;
}

}  // namespace

// 2D, three nodes, one point: grad p = (1, 0, 0) and (0, 1, 0), so F's columns are y_0 and y_1:
// F = [[2, 1], [0, 3]], det F = 6, F^-T (1, 1) = (1/2, 1/6); p_,xx = (0, 0, 1), p_,yy = (1, 0, 0),
// so hess(y)[i, 0, 0] = y_2 = (1, 1), hess(y)[i, 1, 1] = y_0 = (2, 0), and g0 . hess(y) = diag(2, 2).
TEST(PointKernels, KinematicsByHandIn2D) {
  HandCell c(2, 3, 1);
  const double B0[] = {0.2, 0.3, 0.5};
  for (int a = 0; a < 3; ++a) c.B(0, 0, a) = B0[a];
  c.B(0, 1, 0) = 1.0;
  c.B(0, 2, 1) = 1.0;
  c.B(0, hessian_slot(0, 0, 2), 2) = 1.0;
  c.B(0, hessian_slot(1, 1, 2), 0) = 1.0;
  c.qdata = {1.0, 1.0};
  const std::vector<double> y = {2.0, 0.0, 1.0, 3.0, 1.0, 1.0};
  const auto Y = point_values(kinematics_Y_2d, c, y);
  ASSERT_EQ(Y.size(), 2u);
  EXPECT_NEAR(Y[0], 1.2, 1e-15);
  EXPECT_NEAR(Y[1], 1.4, 1e-15);
  EXPECT_EQ(point_values(kinematics_FF_2d, c, y), (std::vector<double>{2.0, 1.0, 0.0, 3.0}));
  EXPECT_EQ(point_values(kinematics_J_2d, c, y), (std::vector<double>{6.0}));
  EXPECT_EQ(point_values(kinematics_H_2d, c, y), (std::vector<double>{1.0, 0.0, 0.0, 2.0, 1.0, 0.0, 0.0, 0.0}));
  EXPECT_EQ(point_values(kinematics_K_2d, c, y), (std::vector<double>{2.0, 0.0, 0.0, 2.0}));
  const auto G = point_values(kinematics_G_2d, c, y);
  ASSERT_EQ(G.size(), 2u);
  EXPECT_NEAR(G[0], 0.5, 1e-15);
  EXPECT_NEAR(G[1], 1.0 / 6.0, 1e-15);
  // Shapes.
  EXPECT_EQ(kinematics_J_2d.point_rank, 0);
  EXPECT_EQ(kinematics_J_2d.n_values, 1);
  EXPECT_EQ(kinematics_FF_2d.point_rank, 2);
  EXPECT_EQ(kinematics_H_2d.point_rank, 3);
  EXPECT_EQ(kinematics_H_2d.n_values, 8);
  EXPECT_EQ(kinematics_H_2d.point_extents[2], 2);
  EXPECT_EQ(kinematics_H_2d.basis_order, 2);
  EXPECT_EQ(kinematics_FF_2d.basis_order, 1);
  EXPECT_EQ(kinematics_H_2d.workspace_doubles(3, 1), 0u);
}

// 2D and 3D, several points, random jets: every point output against Eigen on the same jets.
TEST(PointKernels, KinematicsAgainstEigen) {
  for (const int dim : {2, 3}) {
    SCOPED_TRACE(dim);
    const int n = 6, nq = 3;
    HandCell c(dim, n, nq);
    c.randomize(41 + static_cast<unsigned>(dim));
    // y = X + a perturbation: nodal values whose gradient is near the identity.
    std::mt19937 rng(3);
    std::uniform_real_distribution<double> U(-1.0, 1.0);
    std::vector<double> y(std::size_t(n) * dim);
    for (double& v : y) v = U(rng);
    for (int i = 0; i < nq * dim; ++i) c.qdata.push_back(U(rng));
    const auto find = [&](const char* name) -> const FormKernels& { return *kernels_named(kinematics_all_kernels, name, dim).at(0); };
    const auto Y = point_values(find("Y"), c, y), FF = point_values(find("FF"), c, y), J = point_values(find("J"), c, y),
               H = point_values(find("H"), c, y), K = point_values(find("K"), c, y), G = point_values(find("G"), c, y);
    const std::size_t d = std::size_t(dim);
    for (int q = 0; q < nq; ++q) {
      Eigen::MatrixXd F(dim, dim);
      Eigen::VectorXd g0(dim);
      for (int i = 0; i < dim; ++i) {
        g0(i) = c.qdata[std::size_t(q) * d + std::size_t(i)];
        EXPECT_NEAR(Y[std::size_t(q) * d + std::size_t(i)], c.jet(q, 0, y, dim, i), 1e-14);
        for (int j = 0; j < dim; ++j) {
          F(i, j) = c.jet(q, 1 + j, y, dim, i);
          EXPECT_NEAR(FF[std::size_t(q) * d * d + std::size_t(i * dim + j)], F(i, j), 1e-14);
        }
      }
      EXPECT_NEAR(J[std::size_t(q)], F.determinant(), 1e-13);
      const Eigen::VectorXd pushed = F.inverse().transpose() * g0;
      for (int i = 0; i < dim; ++i) EXPECT_NEAR(G[std::size_t(q) * d + std::size_t(i)], pushed(i), 1e-11 * (1 + pushed.norm()));
      for (int j = 0; j < dim; ++j)
        for (int k = 0; k < dim; ++k) {
          double contracted = 0;
          for (int i = 0; i < dim; ++i) {
            const double hijk = c.jet(q, hessian_slot(j, k, dim), y, dim, i);
            EXPECT_NEAR(H[std::size_t(q) * d * d * d + std::size_t((i * dim + j) * dim + k)], hijk, 1e-14);
            contracted += g0(i) * hijk;
          }
          EXPECT_NEAR(K[std::size_t(q) * d * d + std::size_t(j * dim + k)], contracted, 1e-13);
        }
    }
  }
}
