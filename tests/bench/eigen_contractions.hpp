// The cell contractions with Eigen's products alone, as the runtime computed them before its
// n x n product went to BLAS: bench_kernels times the generated Hessians with both in one run.
#pragma once

#include <lmeform/kernel.hpp>

#include <Eigen/Core>

namespace lmeform::bench {

namespace eigen_detail {
using RowMatrix = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;
using ConstRowMap = Eigen::Map<const RowMatrix>;
using RowMap = Eigen::Map<RowMatrix>;
using StridedRowMap = Eigen::Map<RowMatrix, 0, Eigen::Stride<Eigen::Dynamic, Eigen::Dynamic>>;

inline void contract_vector(int n, int nq, int n_slots, int R, const double* Bs, const double* G, double* local_vector) {
  RowMap out(local_vector, n, R);
  out.noalias() += ConstRowMap(Bs, Eigen::Index(nq) * n_slots, n).transpose() * ConstRowMap(G, Eigen::Index(nq) * n_slots, R);
}

inline void contract_matrix(int n, int nq, int n_slots, int R, int C, const double* Bs, const double* D,
                            const kernel::MatrixBlock* blocks, int n_blocks, double* work, double* local_matrix) {
  const Eigen::Index S = n_slots;
  const Eigen::Index ld = Eigen::Index(C) * S;
  double* stacked = work;
  double* block = work + std::size_t(nq) * n_slots * n;
  const ConstRowMap all(Bs, Eigen::Index(nq) * S, n);
  for (int b = 0; b < n_blocks; ++b) {
    const int r = blocks[b].row, c = blocks[b].col;
    for (int q = 0; q < nq; ++q) {
      const double* Dq = D + std::size_t(q) * std::size_t(R) * S * ld + std::size_t(r) * S * ld + std::size_t(c) * S;
      Eigen::Map<const RowMatrix, 0, Eigen::OuterStride<>> Dblock(Dq, S, S, Eigen::OuterStride<>(ld));
      RowMap(stacked + std::size_t(q) * S * n, S, n).noalias() = Dblock * ConstRowMap(Bs + std::size_t(q) * S * n, S, n);
    }
    RowMap H(block, n, n);
    if (blocks[b].symmetric) {
      H.triangularView<Eigen::Upper>() = all.transpose() * ConstRowMap(stacked, Eigen::Index(nq) * S, n);
      for (int a = 1; a < n; ++a)
        for (int e = 0; e < a; ++e) H(a, e) = H(e, a);
    } else {
      H.noalias() = all.transpose() * ConstRowMap(stacked, Eigen::Index(nq) * S, n);
    }
    const Eigen::Index row_stride = Eigen::Index(R) * n * C;
    StridedRowMap(local_matrix + std::size_t(r) * n * C + c, n, n, Eigen::Stride<Eigen::Dynamic, Eigen::Dynamic>(row_stride, C)) += H;
    if (blocks[b].mirror)
      StridedRowMap(local_matrix + std::size_t(c) * n * C + r, n, n, Eigen::Stride<Eigen::Dynamic, Eigen::Dynamic>(row_stride, C)) +=
          H.transpose();
  }
}
}  // namespace eigen_detail

/// Eigen-only contraction routines for CellInputs::contractions.
inline const kernel::ContractionRoutines& eigen_contractions() noexcept {
  static const kernel::ContractionRoutines routines{&eigen_detail::contract_vector, &eigen_detail::contract_matrix};
  return routines;
}

}  // namespace lmeform::bench
