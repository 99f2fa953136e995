// "Naive" Hessian kernels written the way the thesis code assembles them: per quadrature point,
// a loop over node pairs (and dof components) evaluating the closed-form second derivatives of
// seed Paper A App. A (axisymmetric Helfrich, 1472-1570) and Paper B App. B (Lagrangian Helfrich,
// 2057-2200) entry by entry. They follow lmeform/kernel.hpp, so they can be checked with the same
// tools as generated kernels, and they are the baseline of bench_kernels.
#pragma once

#include <lmeform/kernel.hpp>

#include <cmath>
#include <cstddef>
#include <numbers>

namespace lmeform::naive {

using kernel::CellInputs;
using kernel::hessian_slot;
using kernel::jet_size;

inline constexpr double kFE = 3.0 / (8.0 * std::numbers::sqrt2);

/// Axisymmetric phase-field Helfrich Hessian; constants {k, eps, C0}; x = (r, z).
///   H_ab = f_E k/(2 eps) int 2 (dW_a dW_b + W d2W_ab) 2 pi r dr dz
///   dW_a = eps (p_a,rr + p_a,zz + p_a,r / r) + p_a (1/eps - 3 phi^2/eps - 2 sqrt2 C0 phi),
///   d2W_ab = -2 p_a p_b (3 phi/eps + C0 sqrt2)
inline void helfrich_axisymmetric_hessian(const CellInputs& in, double* H) {
  const int n = in.n_nodes, J = jet_size(2, in.basis_order);
  const double k = in.constants[0], eps = in.constants[1], C0 = in.constants[2];
  const int srr = hessian_slot(0, 0, 2), szz = hessian_slot(1, 1, 2);
  for (int q = 0; q < in.n_points; ++q) {
    const double* B = in.basis + static_cast<std::size_t>(q) * J * n;
    const double r = in.points[2 * q];
    double phi = 0, phi_r = 0, phi_rr = 0, phi_zz = 0;
    for (int a = 0; a < n; ++a) {
      phi += B[a] * in.unknowns[a];
      phi_r += B[n + a] * in.unknowns[a];
      phi_rr += B[srr * n + a] * in.unknowns[a];
      phi_zz += B[szz * n + a] * in.unknowns[a];
    }
    const double lap = phi_rr + phi_zz + phi_r / r;
    const double W = eps * lap + (phi / eps + C0 * std::numbers::sqrt2) * (1.0 - phi * phi);
    const double c = in.weights[q] * 2.0 * std::numbers::pi * r * kFE * k / (2.0 * eps) * 2.0;
    for (int a = 0; a < n; ++a) {
      const double pa = B[a];
      const double dWa = eps * (B[srr * n + a] + B[szz * n + a] + B[n + a] / r) +
                         pa * (1.0 / eps - 3.0 * phi * phi / eps - 2.0 * std::numbers::sqrt2 * C0 * phi);
      for (int b = 0; b < n; ++b) {
        const double pb = B[b];
        const double dWb = eps * (B[srr * n + b] + B[szz * n + b] + B[n + b] / r) +
                           pb * (1.0 / eps - 3.0 * phi * phi / eps - 2.0 * std::numbers::sqrt2 * C0 * phi);
        const double d2W = -2.0 * pa * pb * (3.0 * phi / eps + C0 * std::numbers::sqrt2);
        H[static_cast<std::size_t>(a) * n + b] += c * (dWa * dWb + W * d2W);
      }
    }
  }
}

/// Lagrangian Helfrich Hessian (Cartesian 2D), seed (3.21) and App. B: unknown y (2 per node,
/// interleaved), qdata per point [phi0, grad phi0 (2), hess phi0 (2x2)], constants {k, eps, C0}.
/// Entry (a i, b j): f_E k/(2 eps) int [2 dW_A dW_B det + 2 W d2W_AB det + 2 W dW_A ddet_B
///                                    + 2 W dW_B ddet_A + W^2 d2det_AB] dX
/// with the nodal derivatives of F, F^-1, grad F^-1 and det F of App. B.2 evaluated per pair.
inline void helfrich_lagrangian_hessian(const CellInputs& in, double* H) {
  const int n = in.n_nodes, J = jet_size(2, in.basis_order), N = 2 * n;
  const double k = in.constants[0], eps = in.constants[1], C0 = in.constants[2];
  const int hs[2][2] = {{hessian_slot(0, 0, 2), hessian_slot(0, 1, 2)}, {hessian_slot(1, 0, 2), hessian_slot(1, 1, 2)}};
  for (int q = 0; q < in.n_points; ++q) {
    const double* B = in.basis + static_cast<std::size_t>(q) * J * n;
    const double* qd = in.qdata + static_cast<std::size_t>(q) * 7;
    const double phi0 = qd[0];
    const double g0[2] = {qd[1], qd[2]};
    const double H0[2][2] = {{qd[3], qd[4]}, {qd[5], qd[6]}};
    // Spatial derivatives of the motion (App. B.1).
    double F[2][2] = {}, hy[2][2][2] = {};  // F[i][I], hy[n][K][L] = d_KL y_n
    for (int a = 0; a < n; ++a)
      for (int i = 0; i < 2; ++i) {
        const double ya = in.unknowns[2 * a + i];
        for (int I = 0; I < 2; ++I) {
          F[i][I] += B[(1 + I) * n + a] * ya;
          for (int K = 0; K < 2; ++K) hy[i][I][K] += B[hs[I][K] * n + a] * ya;
        }
      }
    const double det = F[0][0] * F[1][1] - F[0][1] * F[1][0];
    const double Fi[2][2] = {{F[1][1] / det, -F[0][1] / det}, {-F[1][0] / det, F[0][0] / det}};  // Fi[I][i]
    double dFi[2][2][2] = {};  // dFi[I][i][L] = d_L Fi_Ii = -Fi_In d_L F_nK Fi_Ki
    for (int I = 0; I < 2; ++I)
      for (int i = 0; i < 2; ++i)
        for (int L = 0; L < 2; ++L)
          for (int m = 0; m < 2; ++m)
            for (int K = 0; K < 2; ++K) dFi[I][i][L] -= Fi[I][m] * hy[m][K][L] * Fi[K][i];
    double lap = 0.0;
    for (int I = 0; I < 2; ++I)
      for (int i = 0; i < 2; ++i)
        for (int L = 0; L < 2; ++L) lap += H0[I][L] * Fi[I][i] * Fi[L][i] + g0[I] * dFi[I][i][L] * Fi[L][i];
    const double C1 = (phi0 / eps + C0 * std::numbers::sqrt2) * (1.0 - phi0 * phi0);
    const double W = eps * lap + C1;
    const double c = in.weights[q] * kFE * k / (2.0 * eps);

    // First nodal derivatives for dof A = (a, i_): dF, dFi, dhy, ddFi, dW, ddet.
    auto first = [&](int a, int comp, double dF[2][2], double dFiA[2][2], double dhy[2][2][2], double ddFi[2][2][2],
                     double& dW, double& ddet) {
      for (int i = 0; i < 2; ++i)
        for (int I = 0; I < 2; ++I) {
          dF[i][I] = i == comp ? B[(1 + I) * n + a] : 0.0;
          for (int K = 0; K < 2; ++K) dhy[i][I][K] = i == comp ? B[hs[I][K] * n + a] : 0.0;
        }
      for (int I = 0; I < 2; ++I)
        for (int i = 0; i < 2; ++i) {
          dFiA[I][i] = 0.0;
          for (int m = 0; m < 2; ++m)
            for (int K = 0; K < 2; ++K) dFiA[I][i] -= Fi[I][m] * dF[m][K] * Fi[K][i];
        }
      for (int I = 0; I < 2; ++I)
        for (int i = 0; i < 2; ++i)
          for (int L = 0; L < 2; ++L) {
            double s = 0.0;
            for (int m = 0; m < 2; ++m)
              for (int K = 0; K < 2; ++K)
                s += dFiA[I][m] * hy[m][K][L] * Fi[K][i] + Fi[I][m] * dhy[m][K][L] * Fi[K][i] +
                     Fi[I][m] * hy[m][K][L] * dFiA[K][i];
            ddFi[I][i][L] = -s;
          }
      double dlap = 0.0;
      for (int I = 0; I < 2; ++I)
        for (int i = 0; i < 2; ++i)
          for (int L = 0; L < 2; ++L)
            dlap += H0[I][L] * (dFiA[I][i] * Fi[L][i] + Fi[I][i] * dFiA[L][i]) +
                    g0[I] * (ddFi[I][i][L] * Fi[L][i] + dFi[I][i][L] * dFiA[L][i]);
      dW = eps * dlap;
      ddet = 0.0;
      for (int I = 0; I < 2; ++I)
        for (int i = 0; i < 2; ++i) ddet += det * Fi[I][i] * dF[i][I];
    };

    for (int a = 0; a < n; ++a)
      for (int ia = 0; ia < 2; ++ia) {
        double dFA[2][2], dFiA[2][2], dhyA[2][2][2], ddFiA[2][2][2], dWA, ddetA;
        first(a, ia, dFA, dFiA, dhyA, ddFiA, dWA, ddetA);
        for (int b = 0; b < n; ++b)
          for (int jb = 0; jb < 2; ++jb) {
            double dFB[2][2], dFiB[2][2], dhyB[2][2][2], ddFiB[2][2][2], dWB, ddetB;
            first(b, jb, dFB, dFiB, dhyB, ddFiB, dWB, ddetB);
            // Second nodal derivative of F^-1 (App. B.2): d2Fi = Fi dF_A Fi dF_B Fi + Fi dF_B Fi dF_A Fi
            double d2Fi[2][2] = {};
            for (int I = 0; I < 2; ++I)
              for (int i = 0; i < 2; ++i)
                for (int m = 0; m < 2; ++m)
                  for (int K = 0; K < 2; ++K) d2Fi[I][i] -= dFiB[I][m] * dFA[m][K] * Fi[K][i] + Fi[I][m] * dFA[m][K] * dFiB[K][i];
            // Second nodal derivative of grad F^-1 (App. B.2), product rule on Fi hy Fi (d2 hy = 0).
            double d2dFi[2][2][2] = {};
            for (int I = 0; I < 2; ++I)
              for (int i = 0; i < 2; ++i)
                for (int L = 0; L < 2; ++L) {
                  double s = 0.0;
                  for (int m = 0; m < 2; ++m)
                    for (int K = 0; K < 2; ++K)
                      s += d2Fi[I][m] * hy[m][K][L] * Fi[K][i] + dFiA[I][m] * dhyB[m][K][L] * Fi[K][i] +
                           dFiA[I][m] * hy[m][K][L] * dFiB[K][i] + dFiB[I][m] * dhyA[m][K][L] * Fi[K][i] +
                           Fi[I][m] * dhyA[m][K][L] * dFiB[K][i] + dFiB[I][m] * hy[m][K][L] * dFiA[K][i] +
                           Fi[I][m] * dhyB[m][K][L] * dFiA[K][i] + Fi[I][m] * hy[m][K][L] * d2Fi[K][i];
                  d2dFi[I][i][L] = -s;
                }
            double d2lap = 0.0;
            for (int I = 0; I < 2; ++I)
              for (int i = 0; i < 2; ++i)
                for (int L = 0; L < 2; ++L)
                  d2lap += H0[I][L] * (d2Fi[I][i] * Fi[L][i] + dFiA[I][i] * dFiB[L][i] + dFiB[I][i] * dFiA[L][i] +
                                       Fi[I][i] * d2Fi[L][i]) +
                           g0[I] * (d2dFi[I][i][L] * Fi[L][i] + ddFiA[I][i][L] * dFiB[L][i] +
                                    ddFiB[I][i][L] * dFiA[L][i] + dFi[I][i][L] * d2Fi[L][i]);
            const double d2W = eps * d2lap;
            // Second nodal derivative of det F (App. B.2).
            double trA = 0, trB = 0, trAB = 0;
            for (int I = 0; I < 2; ++I)
              for (int i = 0; i < 2; ++i) {
                trA += Fi[I][i] * dFA[i][I];
                trB += Fi[I][i] * dFB[i][I];
                for (int m = 0; m < 2; ++m)
                  for (int K = 0; K < 2; ++K) trAB += Fi[I][m] * dFA[m][K] * Fi[K][i] * dFB[i][I];
              }
            const double d2det = det * (trA * trB - trAB);
            H[static_cast<std::size_t>(2 * a + ia) * N + 2 * b + jb] +=
                c * (2.0 * dWA * dWB * det + 2.0 * W * d2W * det + 2.0 * W * dWA * ddetB + 2.0 * W * dWB * ddetA +
                     W * W * d2det);
          }
      }
  }
}

}  // namespace lmeform::naive
