#include "lmeform/contractions.hpp"

#include <Eigen/Core>

// The reference BLAS interface (libblas.so.3: OpenBLAS on the machines install-deps sets up).
extern "C" void dgemm_(const char* transa, const char* transb, const int* m, const int* n, const int* k,
                       const double* alpha, const double* a, const int* lda, const double* b, const int* ldb,
                       const double* beta, double* c, const int* ldc);

namespace lmeform {
namespace {

using RowMatrix = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;
using ConstRowMap = Eigen::Map<const RowMatrix>;
using RowMap = Eigen::Map<RowMatrix>;
using StridedRowMap = Eigen::Map<RowMatrix, 0, Eigen::Stride<Eigen::Dynamic, Eigen::Dynamic>>;

void contract_vector(int n, int nq, int n_slots, int R, const double* Bs, const double* G, double* local_vector) {
  RowMap out(local_vector, n, R);
  out.noalias() += ConstRowMap(Bs, Eigen::Index(nq) * n_slots, n).transpose() * ConstRowMap(G, Eigen::Index(nq) * n_slots, R);
}

void contract_matrix(int n, int nq, int n_slots, int R, int C, const double* Bs, const double* D,
                     const kernel::MatrixBlock* blocks, int n_blocks, double* work, double* local_matrix) {
  if (n == 0) return;  // BLAS refuses a leading dimension of 0
  const Eigen::Index S = n_slots;
  const Eigen::Index ld = Eigen::Index(C) * S;
  double* stacked = work;                               // (nq*S x n): D_q^{rc} Bs_q stacked
  double* block = work + std::size_t(nq) * n_slots * n;  // (n x n)
  for (int b = 0; b < n_blocks; ++b) {
    const int r = blocks[b].row, c = blocks[b].col;
    for (int q = 0; q < nq; ++q) {
      const double* Dq = D + std::size_t(q) * std::size_t(R) * S * ld + std::size_t(r) * S * ld + std::size_t(c) * S;
      Eigen::Map<const RowMatrix, 0, Eigen::OuterStride<>> Dblock(Dq, S, S, Eigen::OuterStride<>(ld));
      RowMap(stacked + std::size_t(q) * S * n, S, n).noalias() = Dblock * ConstRowMap(Bs + std::size_t(q) * S * n, S, n);
    }
    // H = Bsᵀ stacked, the cell's n x n block and the bulk of its flops, by BLAS: OpenBLAS picks
    // its kernels for the CPU it runs on, where Eigen's are fixed at compile time (SSE2 in the
    // portable build; docs/assembly.md measures both). Row-major H is, in
    // BLAS's column-major terms, (stacked viewed as n x rows) times (Bs viewed as n x rows)ᵀ.
    RowMap H(block, n, n);
    {
      const int rows = nq * n_slots;
      const double one = 1.0, zero = 0.0;
      dgemm_("N", "T", &n, &n, &rows, &one, stacked, &n, Bs, &n, &zero, block, &n);
    }
    if (blocks[b].symmetric) {
      // A diagonal block of a symmetric Hessian: the upper triangle mirrored, so that the block is
      // symmetric to the bit (the two triangles of a product round differently).
      for (int a = 1; a < n; ++a)
        for (int e = 0; e < a; ++e) H(a, e) = H(e, a);
    }
    const Eigen::Index row_stride = Eigen::Index(R) * n * C;
    StridedRowMap(local_matrix + std::size_t(r) * n * C + c, n, n, Eigen::Stride<Eigen::Dynamic, Eigen::Dynamic>(row_stride, C)) += H;
    if (blocks[b].mirror)
      StridedRowMap(local_matrix + std::size_t(c) * n * C + r, n, n, Eigen::Stride<Eigen::Dynamic, Eigen::Dynamic>(row_stride, C)) +=
          H.transpose();
  }
}

}  // namespace

const kernel::ContractionRoutines& dense_contractions() noexcept {
  static const kernel::ContractionRoutines routines{&contract_vector, &contract_matrix};
  return routines;
}

}  // namespace lmeform
