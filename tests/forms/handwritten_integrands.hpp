// Pointwise integrands with hand-coded jet derivatives (see jet_kernel.hpp).
// Used to validate the derivative checker, and as independent references for generated kernels.
#pragma once

#include <lmeform/kernel.hpp>

#include <cmath>
#include <numbers>

namespace lmeform::formcheck::hand {

using kernel::hessian_slot;
using kernel::jet_size;

inline constexpr double kFE = 3.0 / (8.0 * std::numbers::sqrt2);  // f_E of seed (3.4)
inline constexpr double kFA = 3.0 / (2.0 * std::numbers::sqrt2);  // f_A of seed (3.4)

/// 1/2 |grad u|^2 - f u with f = 2 x_1 (poisson.form). Quadratic.
template <int D>
struct Poisson {
  static constexpr int dim = D, components = 1, order = 1, n_constants = 0, qdata_per_point = 0;
  static double eval(const double* J, const double* x, const double*, const double*, double* dJ, double* d2J) {
    constexpr int nJ = jet_size(D, 1);
    const double f = 2.0 * x[1];
    double g2 = 0.0;
    for (int i = 0; i < D; ++i) g2 += J[1 + i] * J[1 + i];
    if (dJ) {
      dJ[0] = -f;
      for (int i = 0; i < D; ++i) dJ[1 + i] = J[1 + i];
    }
    if (d2J)
      for (int i = 0; i < D; ++i) d2J[(1 + i) * nJ + 1 + i] = 1.0;
    return 0.5 * g2 - f * J[0];
  }
};

/// V = 1/2 (phi) integrand without the constant Vol(Omega)/2 part. Linear.
template <int D>
struct HalfValue {
  static constexpr int dim = D, components = 1, order = 0, n_constants = 0, qdata_per_point = 0;
  static double eval(const double* J, const double*, const double*, const double*, double* dJ, double*) {
    if (dJ) dJ[0] = 0.5;
    return 0.5 * J[0];
  }
};

/// Phase-field Helfrich bending density, seed (3.4)/(3.10), Cartesian or axisymmetric (r = x_0, z = x_1).
/// constants: k, eps, C0.   f = f_E k/(2 eps) W^2 [* 2 pi r],  W = eps Lap(phi) + (phi/eps + C0 sqrt2)(1 - phi^2)
/// `Bug` = 1 drops the W d2W term of the Hessian, `Bug` = 2 scales the gradient by 1.001 (checker validation).
template <int D, bool Axi = false, int Bug = 0>
struct Helfrich {
  static constexpr int dim = D, components = 1, order = 2, n_constants = 3, qdata_per_point = 0;
  static double eval(const double* J, const double* x, const double*, const double* k, double* dJ, double* d2J) {
    constexpr int nJ = jet_size(D, 2);
    const double kb = k[0], eps = k[1], C0 = k[2];
    const double u = J[0];
    double lap = 0.0;
    for (int i = 0; i < D; ++i) lap += J[hessian_slot(i, i, D)];
    const double r = x[0];
    if (Axi) lap += J[1] / r;
    const double a = u / eps + C0 * std::numbers::sqrt2;
    const double W = eps * lap + a * (1.0 - u * u);
    const double m = Axi ? 2.0 * std::numbers::pi * r : 1.0;
    const double c = m * kFE * kb / (2.0 * eps);
    // dW/dJ
    double dW[nJ] = {};
    dW[0] = (1.0 - u * u) / eps - 2.0 * u * a;
    for (int i = 0; i < D; ++i) dW[hessian_slot(i, i, D)] = eps;
    if (Axi) dW[1] = eps / r;
    const double d2Wuu = -6.0 * u / eps - 2.0 * C0 * std::numbers::sqrt2;
    if (dJ)
      for (int s = 0; s < nJ; ++s) dJ[s] = (Bug == 2 ? 1.001 : 1.0) * 2.0 * c * W * dW[s];
    if (d2J) {
      for (int s = 0; s < nJ; ++s)
        for (int t = 0; t < nJ; ++t) d2J[s * nJ + t] = 2.0 * c * dW[s] * dW[t];
      if (Bug != 1) d2J[0] += 2.0 * c * W * d2Wuu;
    }
    return c * W * W;
  }
};

/// Phase-field area density f_A [eps/2 |grad phi|^2 + (phi^2-1)^2/(4 eps)]; constants: eps, A0 (target, unused).
template <int D>
struct Area {
  static constexpr int dim = D, components = 1, order = 1, n_constants = 2, qdata_per_point = 0;
  static double eval(const double* J, const double*, const double*, const double* k, double* dJ, double* d2J) {
    constexpr int nJ = jet_size(D, 1);
    const double eps = k[0], u = J[0];
    double g2 = 0.0;
    for (int i = 0; i < D; ++i) g2 += J[1 + i] * J[1 + i];
    if (dJ) {
      dJ[0] = kFA * u * (u * u - 1.0) / eps;
      for (int i = 0; i < D; ++i) dJ[1 + i] = kFA * eps * J[1 + i];
    }
    if (d2J) {
      d2J[0] = kFA * (3.0 * u * u - 1.0) / eps;
      for (int i = 0; i < D; ++i) d2J[(1 + i) * nJ + 1 + i] = kFA * eps;
    }
    return kFA * (0.5 * eps * g2 + (u * u - 1.0) * (u * u - 1.0) / (4.0 * eps));
  }
};

/// Compressible neo-Hookean density of a vector unknown y (checks dof interleaving):
/// mu/2 (|F|^2 - D) - mu ln J + lambda/2 (ln J)^2, F = grad y (2D only). constants: mu, lambda.
struct NeoHooke2 {
  static constexpr int dim = 2, components = 2, order = 1, n_constants = 2, qdata_per_point = 0;
  static constexpr int Js = jet_size(2, 1), nJ = 2 * Js;
  static int slot(int i, int I) { return i * Js + 1 + I; }
  static double eval(const double* J, const double*, const double*, const double* k, double* dJ, double* d2J) {
    const double mu = k[0], lam = k[1];
    double F[2][2];
    for (int i = 0; i < 2; ++i)
      for (int I = 0; I < 2; ++I) F[i][I] = J[slot(i, I)];
    const double det = F[0][0] * F[1][1] - F[0][1] * F[1][0];
    const double Fi[2][2] = {{F[1][1] / det, -F[0][1] / det}, {-F[1][0] / det, F[0][0] / det}};  // Fi[I][i]
    const double lnJ = std::log(det);
    double F2 = 0.0;
    for (int i = 0; i < 2; ++i)
      for (int I = 0; I < 2; ++I) F2 += F[i][I] * F[i][I];
    if (dJ)
      for (int i = 0; i < 2; ++i)
        for (int I = 0; I < 2; ++I) dJ[slot(i, I)] = mu * (F[i][I] - Fi[I][i]) + lam * lnJ * Fi[I][i];
    if (d2J)
      for (int i = 0; i < 2; ++i)
        for (int I = 0; I < 2; ++I)
          for (int kk = 0; kk < 2; ++kk)
            for (int K = 0; K < 2; ++K)
              d2J[slot(i, I) * nJ + slot(kk, K)] = mu * (i == kk && I == K ? 1.0 : 0.0) +
                                                   (mu - lam * lnJ) * Fi[I][kk] * Fi[K][i] +
                                                   lam * Fi[I][i] * Fi[K][kk];
    return 0.5 * mu * (F2 - 2.0) - mu * lnJ + 0.5 * lam * lnJ * lnJ;
  }
};

}  // namespace lmeform::formcheck::hand
