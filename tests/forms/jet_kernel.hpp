// Hand-written kernels following runtime/include/lmeform/kernel.hpp, for validating the
// derivative checker (and as a cross-check of generated kernels).
//
// A pointwise integrand I is written once in terms of the jet of the unknowns at a quadrature
// point, J[c * Js + s] (component c, jet slot s), and returns its value together with dI/dJ and
// d2I/dJ2 coded by hand. JetKernel<I> contracts those with the basis exactly as the contract
// prescribes:
//   value    = sum_q w_q I(J_q)
//   gradient = sum_q w_q B_q^T dI/dJ         (interleaved dofs a*nc + c)
//   Hessian  = sum_q w_q B_q^T d2I/dJ2 B_q
//
// Integrand requirements (static members):
//   static constexpr int dim, components, order, n_constants, qdata_per_point;
//   static double eval(const double* J, const double* x, const double* qd, const double* k,
//                      double* dJ, double* d2J);   // dJ, d2J may be null; d2J row-major (nJ x nJ)
#pragma once

#include <lmeform/kernel.hpp>

#include <array>
#include <cstddef>

namespace lmeform::formcheck {

template <class I>
struct JetKernel {
  static constexpr int Js = kernel::jet_size(I::dim, I::order);
  static constexpr int nJ = I::components * Js;

  /// Jet of the unknowns at point q; reads the basis in the layout of in.basis_order.
  static void jet(const kernel::CellInputs& in, int q, double* J) {
    const int Jin = kernel::jet_size(I::dim, in.basis_order);
    const int n = in.n_nodes;
    for (int c = 0; c < I::components; ++c)
      for (int s = 0; s < Js; ++s) {
        const double* B = in.basis + (static_cast<std::size_t>(q) * Jin + s) * n;
        double v = 0.0;
        for (int a = 0; a < n; ++a) v += B[a] * in.unknowns[a * I::components + c];
        J[c * Js + s] = v;
      }
  }

  static const double* qd(const kernel::CellInputs& in, int q) {
    return I::qdata_per_point ? in.qdata + static_cast<std::size_t>(q) * I::qdata_per_point : nullptr;
  }

  static double value(const kernel::CellInputs& in) {
    double E = 0.0;
    std::array<double, nJ> J{};
    for (int q = 0; q < in.n_points; ++q) {
      jet(in, q, J.data());
      E += in.weights[q] * I::eval(J.data(), in.points + q * I::dim, qd(in, q), in.constants, nullptr, nullptr);
    }
    return E;
  }

  static void vector(const kernel::CellInputs& in, double* g) {
    const int Jin = kernel::jet_size(I::dim, in.basis_order);
    const int n = in.n_nodes;
    std::array<double, nJ> J{}, dJ{};
    for (int q = 0; q < in.n_points; ++q) {
      jet(in, q, J.data());
      dJ.fill(0.0);
      I::eval(J.data(), in.points + q * I::dim, qd(in, q), in.constants, dJ.data(), nullptr);
      for (int c = 0; c < I::components; ++c)
        for (int s = 0; s < Js; ++s) {
          const double f = in.weights[q] * dJ[c * Js + s];
          const double* B = in.basis + (static_cast<std::size_t>(q) * Jin + s) * n;
          for (int a = 0; a < n; ++a) g[a * I::components + c] += f * B[a];
        }
    }
  }

  static void matrix(const kernel::CellInputs& in, double* H) {
    const int Jin = kernel::jet_size(I::dim, in.basis_order);
    const int n = in.n_nodes;
    const int N = n * I::components;
    std::array<double, nJ> J{}, dJ{};
    std::array<double, nJ * nJ> D{};
    for (int q = 0; q < in.n_points; ++q) {
      jet(in, q, J.data());
      D.fill(0.0);
      I::eval(J.data(), in.points + q * I::dim, qd(in, q), in.constants, dJ.data(), D.data());
      const double* Bq = in.basis + static_cast<std::size_t>(q) * Jin * n;
      for (int a = 0; a < n; ++a)
        for (int c = 0; c < I::components; ++c) {
          // t[d*Js+t] = sum_s B[s,a] D[(c,s),(d,t)]
          std::array<double, nJ> t{};
          for (int s = 0; s < Js; ++s) {
            const double bsa = Bq[s * n + a];
            if (bsa == 0.0) continue;
            for (int k = 0; k < nJ; ++k) t[k] += bsa * D[(c * Js + s) * nJ + k];
          }
          double* row = H + static_cast<std::size_t>(a * I::components + c) * N;
          for (int b = 0; b < n; ++b)
            for (int d = 0; d < I::components; ++d) {
              double v = 0.0;
              for (int s = 0; s < Js; ++s) v += t[d * Js + s] * Bq[s * n + b];
              row[b * I::components + d] += in.weights[q] * v;
            }
        }
    }
  }

  static std::size_t workspace(int, int) { return 0; }
};

/// A FormKernels descriptor for a hand-written integrand.
template <class I>
kernel::FormKernels make_form(const char* name, bool with_hessian = true) {
  static const kernel::FieldInfo field{"u", I::components};
  kernel::FormKernels f;
  f.module = "handwritten";
  f.name = name;
  f.kind = kernel::FunctionalKind::Energy;
  f.dim = I::dim;
  f.basis_order = I::order;
  f.unknowns = &field;
  f.n_unknowns = 1;
  f.dofs_per_node = I::components;
  f.n_constants = I::n_constants;
  f.qdata_per_point = I::qdata_per_point;
  f.n_qdata = I::qdata_per_point ? 1 : 0;
  f.workspace_doubles = &JetKernel<I>::workspace;
  f.value = &JetKernel<I>::value;
  f.vector = &JetKernel<I>::vector;
  f.matrix = with_hessian ? &JetKernel<I>::matrix : nullptr;
  return f;
}

}  // namespace lmeform::formcheck
