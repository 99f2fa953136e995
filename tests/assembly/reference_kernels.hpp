// Hand-written kernels that follow lmeform/kernel.hpp, for testing the assembly independently of
// the form compiler. Each integrand gives f, df/dJ and d2f/dJ2 with respect to the jet
// J = (u_c, ∇u_c, ∇∇u_c) of every component c; the contraction with the basis is a plain loop.
#pragma once

#include <cmath>
#include <numbers>
#include <vector>

#include "lmeform/kernel.hpp"

namespace lmeform::testing {

template <class Integrand>
struct JetKernel {
  static constexpr int bs = Integrand::components;
  static constexpr int dim = 2;
  static constexpr int order = Integrand::order;
  static constexpr int J = kernel::jet_size(dim, order);
  static constexpr int K = bs * J;

  static std::size_t workspace(int, int) { return 0; }

  static void jets(const kernel::CellInputs& in, int q, double* jet) {
    const int stride = kernel::jet_size(dim, in.basis_order);
    const double* B = in.basis + static_cast<std::size_t>(q) * static_cast<std::size_t>(stride * in.n_nodes);
    for (int c = 0; c < bs; ++c) {
      for (int s = 0; s < J; ++s) {
        double v = 0;
        for (int a = 0; a < in.n_nodes; ++a) v += B[s * in.n_nodes + a] * in.unknowns[a * bs + c];
        jet[c * J + s] = v;
      }
    }
  }

  static double value(const kernel::CellInputs& in) {
    double sum = 0;
    double jet[K];
    for (int q = 0; q < in.n_points; ++q) {
      jets(in, q, jet);
      sum += in.weights[q] * Integrand::f(jet, in.points + q * dim, in.constants);
    }
    return sum;
  }

  static void vector(const kernel::CellInputs& in, double* g) {
    const int stride = kernel::jet_size(dim, in.basis_order);
    double jet[K];
    double d[K];
    for (int q = 0; q < in.n_points; ++q) {
      jets(in, q, jet);
      Integrand::df(jet, in.points + q * dim, in.constants, d);
      const double* B = in.basis + static_cast<std::size_t>(q) * static_cast<std::size_t>(stride * in.n_nodes);
      for (int a = 0; a < in.n_nodes; ++a) {
        for (int c = 0; c < bs; ++c) {
          double v = 0;
          for (int s = 0; s < J; ++s) v += B[s * in.n_nodes + a] * d[c * J + s];
          g[a * bs + c] += in.weights[q] * v;
        }
      }
    }
  }

  static void matrix(const kernel::CellInputs& in, double* H) {
    const int stride = kernel::jet_size(dim, in.basis_order);
    const int m = in.n_nodes * bs;
    double jet[K];
    double d2[K * K];
    for (int q = 0; q < in.n_points; ++q) {
      jets(in, q, jet);
      Integrand::d2f(jet, in.points + q * dim, in.constants, d2);
      const double* B = in.basis + static_cast<std::size_t>(q) * static_cast<std::size_t>(stride * in.n_nodes);
      for (int a = 0; a < in.n_nodes; ++a) {
        for (int c = 0; c < bs; ++c) {
          for (int b = 0; b < in.n_nodes; ++b) {
            for (int e = 0; e < bs; ++e) {
              double v = 0;
              for (int s = 0; s < J; ++s) {
                for (int t = 0; t < J; ++t) v += B[s * in.n_nodes + a] * d2[(c * J + s) * K + e * J + t] * B[t * in.n_nodes + b];
              }
              H[(a * bs + c) * m + b * bs + e] += in.weights[q] * v;
            }
          }
        }
      }
    }
  }

  static kernel::FormKernels descriptor(const char* name, const char* const* constants, int n_constants) {
    static const kernel::FieldInfo unknown{"u", bs};
    kernel::FormKernels k;
    k.module = "reference";
    k.name = name;
    k.kind = kernel::FunctionalKind::Energy;
    k.dim = dim;
    k.basis_order = order;
    k.unknowns = &unknown;
    k.n_unknowns = 1;
    k.dofs_per_node = bs;
    k.constants = constants;
    k.n_constants = n_constants;
    k.workspace_doubles = &workspace;
    k.value = &value;
    k.vector = &vector;
    k.matrix = &matrix;
    return k;
  }
};

/// Heat/Poisson energy ½|∇T|² − f T with f = source * s(x): s = 2y (seed 4.1) or the
/// manufactured source 2π² sin(πx) sin(πy) of T = sin(πx) sin(πy).
template <bool Manufactured>
struct Poisson {
  static constexpr int components = 1;
  static constexpr int order = 1;
  static double source(const double* x, const double* c) {
    if constexpr (Manufactured) {
      const double pi = std::numbers::pi;
      return c[0] * 2 * pi * pi * std::sin(pi * x[0]) * std::sin(pi * x[1]);
    } else {
      return c[0] * 2 * x[1];
    }
  }
  static double f(const double* j, const double* x, const double* c) {
    return 0.5 * (j[1] * j[1] + j[2] * j[2]) - source(x, c) * j[0];
  }
  static void df(const double* j, const double* x, const double* c, double* d) {
    d[0] = -source(x, c);
    d[1] = j[1];
    d[2] = j[2];
  }
  static void d2f(const double*, const double*, const double*, double* d) {
    for (int i = 0; i < 9; ++i) d[i] = 0;
    d[4] = d[8] = 1;
  }
};

/// ½|∇u|² + ¼u⁴ − x u: nonlinear, for global finite-difference checks.
struct Nonlinear {
  static constexpr int components = 1;
  static constexpr int order = 1;
  static double f(const double* j, const double* x, const double*) {
    return 0.5 * (j[1] * j[1] + j[2] * j[2]) + 0.25 * std::pow(j[0], 4) - x[0] * j[0];
  }
  static void df(const double* j, const double* x, const double*, double* d) {
    d[0] = std::pow(j[0], 3) - x[0];
    d[1] = j[1];
    d[2] = j[2];
  }
  static void d2f(const double* j, const double*, const double*, double* d) {
    for (int i = 0; i < 9; ++i) d[i] = 0;
    d[0] = 3 * j[0] * j[0];
    d[4] = d[8] = 1;
  }
};

/// ½(Δu)²: needs basis Hessians (order 2).
struct Bilaplacian {
  static constexpr int components = 1;
  static constexpr int order = 2;
  // slots: 0 u, 1-2 grad, 3 u_xx, 4 u_xy, 5 u_yy
  static double f(const double* j, const double*, const double*) { return 0.5 * (j[3] + j[5]) * (j[3] + j[5]); }
  static void df(const double* j, const double*, const double*, double* d) {
    for (int i = 0; i < 6; ++i) d[i] = 0;
    d[3] = d[5] = j[3] + j[5];
  }
  static void d2f(const double*, const double*, const double*, double* d) {
    for (int i = 0; i < 36; ++i) d[i] = 0;
    d[3 * 6 + 3] = d[3 * 6 + 5] = d[5 * 6 + 3] = d[5 * 6 + 5] = 1;
  }
};

/// Vector field (2 components): ½∇u:∇u + ¼(|u|² − 1)² + u_0 u_1 x_0 — a coupled block system.
struct VectorField {
  static constexpr int components = 2;
  static constexpr int order = 1;
  static double f(const double* j, const double* x, const double*) {
    const double u0 = j[0], u1 = j[3];
    const double r = u0 * u0 + u1 * u1 - 1;
    return 0.5 * (j[1] * j[1] + j[2] * j[2] + j[4] * j[4] + j[5] * j[5]) + 0.25 * r * r + u0 * u1 * x[0];
  }
  static void df(const double* j, const double* x, const double*, double* d) {
    const double u0 = j[0], u1 = j[3];
    const double r = u0 * u0 + u1 * u1 - 1;
    d[0] = r * u0 + u1 * x[0];
    d[1] = j[1];
    d[2] = j[2];
    d[3] = r * u1 + u0 * x[0];
    d[4] = j[4];
    d[5] = j[5];
  }
  static void d2f(const double* j, const double* x, const double*, double* d) {
    const double u0 = j[0], u1 = j[3];
    const double r = u0 * u0 + u1 * u1 - 1;
    for (int i = 0; i < 36; ++i) d[i] = 0;
    d[0 * 6 + 0] = r + 2 * u0 * u0;
    d[0 * 6 + 3] = d[3 * 6 + 0] = 2 * u0 * u1 + x[0];
    d[3 * 6 + 3] = r + 2 * u1 * u1;
    d[1 * 6 + 1] = d[2 * 6 + 2] = d[4 * 6 + 4] = d[5 * 6 + 5] = 1;
  }
};

/// (u − u_exact)² and |∇u − ∇u_exact|² for T = sin(πx) sin(πy): error norms as "energies".
template <bool Gradient>
struct ManufacturedError {
  static constexpr int components = 1;
  static constexpr int order = 1;
  static double f(const double* j, const double* x, const double*) {
    const double pi = std::numbers::pi;
    const double sx = std::sin(pi * x[0]), sy = std::sin(pi * x[1]);
    if constexpr (Gradient) {
      const double gx = pi * std::cos(pi * x[0]) * sy, gy = pi * sx * std::cos(pi * x[1]);
      return (j[1] - gx) * (j[1] - gx) + (j[2] - gy) * (j[2] - gy);
    } else {
      return (j[0] - sx * sy) * (j[0] - sx * sy);
    }
  }
  static void df(const double*, const double*, const double*, double* d) {
    for (int i = 0; i < 3; ++i) d[i] = 0;
  }
  static void d2f(const double*, const double*, const double*, double* d) {
    for (int i = 0; i < 9; ++i) d[i] = 0;
  }
};

}  // namespace lmeform::testing
