// Shared helpers of the assembly tests: a PETSc-initialising main, dense copies of PETSc objects
// in the original node numbering, and a linear solve.
#pragma once

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <vector>

#include "lmeform/assembler.hpp"
#include "lmeform/discretization.hpp"
#include "lmeform/petsc.hpp"

namespace lmeform::testing {

/// Dense (N*bs)^2 copy of A in the ORIGINAL node numbering, summed over ranks (every rank gets it).
inline std::vector<double> dense_original(const Discretization& disc, Mat A, int bs) {
  const int n = disc.n_nodes() * bs;
  std::vector<double> dense(static_cast<std::size_t>(n) * static_cast<std::size_t>(n), 0.0);
  PetscInt begin = 0, end = 0;
  LMEFORM_PETSC_CHECK(MatGetOwnershipRange(A, &begin, &end));
  for (PetscInt row = begin; row < end; ++row) {
    PetscInt ncols = 0;
    const PetscInt* cols = nullptr;
    const PetscScalar* vals = nullptr;
    LMEFORM_PETSC_CHECK(MatGetRow(A, row, &ncols, &cols, &vals));
    const int orow = disc.original_index()[static_cast<std::size_t>(row / bs)] * bs + static_cast<int>(row % bs);
    for (PetscInt k = 0; k < ncols; ++k) {
      const int ocol = disc.original_index()[static_cast<std::size_t>(cols[k] / bs)] * bs + static_cast<int>(cols[k] % bs);
      dense[static_cast<std::size_t>(orow) * static_cast<std::size_t>(n) + static_cast<std::size_t>(ocol)] = vals[k];
    }
    LMEFORM_PETSC_CHECK(MatRestoreRow(A, row, &ncols, &cols, &vals));
  }
  MPI_Allreduce(MPI_IN_PLACE, dense.data(), static_cast<int>(dense.size()), MPI_DOUBLE, MPI_SUM, disc.comm());
  return dense;
}

inline double max_abs(const std::vector<double>& v) {
  double m = 0;
  for (const double x : v) m = std::max(m, std::abs(x));
  return m;
}

inline double max_abs_difference(const std::vector<double>& a, const std::vector<double>& b) {
  double m = 0;
  for (std::size_t i = 0; i < a.size(); ++i) m = std::max(m, std::abs(a[i] - b[i]));
  return m;
}

/// Energy, gradient and Hessian of a form at u (original node order), gathered in the original
/// numbering on every rank.
struct Assembled {
  double energy = 0;
  std::vector<double> gradient;
  std::vector<double> hessian;
};

inline Assembled assemble_all(const Discretization& disc, const kernel::FormKernels& form,
                              const std::vector<double>& u_original, std::span<const double> constants = {},
                              Assembler::MatrixInsertion insertion = Assembler::MatrixInsertion::Direct) {
  Assembler assembler(disc, form);
  if (!constants.empty()) assembler.set_constants(constants);
  const int bs = form.dofs_per_node;
  PetscVector u = assembler.create_vector();
  PetscVector g = assembler.create_vector();
  set_from_original(disc, u_original, bs, u);
  PetscMatrix H = assembler.create_matrix(insertion);
  Assembled out;
  out.energy = assembler.value(u);
  assembler.vector(u, g);
  assembler.matrix(u, H);
  out.gradient = to_original(disc, g, bs);
  out.hessian = dense_original(disc, H, bs);
  return out;
}

/// The components outside `coupled` held fixed: the Hessian from create_matrix(…, coupled) equals
/// the full one once both have those rows and columns turned into the identity
/// (MatZeroRowsColumns, as the Newton solvers do), holds fewer entries, and coupled_components()
/// finds the same components from the fixed dofs.
inline void expect_coupled_hessian_equals_full(Assembler& assembler, Vec u, const std::vector<int>& coupled,
                                               Assembler::MatrixInsertion insertion = Assembler::MatrixInsertion::Direct) {
  const Discretization& disc = assembler.discretization();
  const int bs = assembler.block_size();
  std::vector<PetscInt> fixed;
  for (int b = disc.owned_begin(); b < disc.owned_end(); ++b)
    for (int c = 0; c < bs; ++c)
      if (std::find(coupled.begin(), coupled.end(), c) == coupled.end()) fixed.push_back(static_cast<PetscInt>(b) * bs + c);
  EXPECT_EQ(coupled_components(disc, bs, fixed), coupled);
  PetscMatrix full = assembler.create_matrix();
  PetscMatrix restricted = assembler.create_matrix(insertion, coupled);
  assembler.matrix(u, full);
  assembler.matrix(u, restricted);
  for (Mat A : {full.get(), restricted.get()})
    LMEFORM_PETSC_CHECK(MatZeroRowsColumns(A, static_cast<PetscInt>(fixed.size()), fixed.data(), 1.0, nullptr, nullptr));
  const auto f = dense_original(disc, full, bs), r = dense_original(disc, restricted, bs);
  const auto n = static_cast<std::size_t>(disc.n_nodes() * bs);
  double coupling = 0;  // the largest entry off the diagonal: what the identity rows do not hold
  for (std::size_t i = 0; i < n; ++i)
    for (std::size_t j = 0; j < n; ++j)
      if (i != j) coupling = std::max(coupling, std::abs(f[i * n + j]));
  ASSERT_GT(coupling, 0.0);
  EXPECT_LE(max_abs_difference(f, r), 1e-13 * coupling);
  MatInfo full_info, restricted_info;
  LMEFORM_PETSC_CHECK(MatGetInfo(full, MAT_GLOBAL_SUM, &full_info));
  LMEFORM_PETSC_CHECK(MatGetInfo(restricted, MAT_GLOBAL_SUM, &restricted_info));
  const double share = double(coupled.size()) / bs;
  EXPECT_LT(restricted_info.nz_used, (share * share + 0.1) * full_info.nz_used);
}

/// The linear system K x = b of a quadratic energy: K its Hessian, b = −∇E(0). `x` is a zero
/// vector of the same layout, ready for Dirichlet values and the solution.
struct LinearSystem {
  PetscMatrix K;
  PetscVector b, x;
};

inline LinearSystem assemble_linear_system(Assembler& assembler) {
  LinearSystem system{assembler.create_matrix(), assembler.create_vector(), assembler.create_vector()};
  assembler.matrix(system.x, system.K);
  assembler.vector(system.x, system.b);
  LMEFORM_PETSC_CHECK(VecScale(system.b, -1.0));
  return system;
}

/// Solves A x = b with a direct solver (MUMPS in parallel, PETSc LU serially).
inline void solve_direct(Mat A, Vec b, Vec x) {
  PetscLinearSolver ksp;
  MPI_Comm comm = MPI_COMM_NULL;
  LMEFORM_PETSC_CHECK(PetscObjectGetComm(reinterpret_cast<PetscObject>(A), &comm));
  LMEFORM_PETSC_CHECK(KSPCreate(comm, ksp.out()));
  LMEFORM_PETSC_CHECK(KSPSetOperators(ksp, A, A));
  LMEFORM_PETSC_CHECK(KSPSetType(ksp, KSPPREONLY));
  PC pc = nullptr;
  LMEFORM_PETSC_CHECK(KSPGetPC(ksp, &pc));
  LMEFORM_PETSC_CHECK(PCSetType(pc, PCLU));
  int size = 1;
  MPI_Comm_size(comm, &size);
  if (size > 1) LMEFORM_PETSC_CHECK(PCFactorSetMatSolverType(pc, MATSOLVERMUMPS));
  LMEFORM_PETSC_CHECK(KSPSolve(ksp, b, x));
}

/// Values written straight into the AIJ arrays must reach a solver that factored the matrix
/// before: the fill must leave the matrix marked changed, so that KSPSetUp refactors. Solves
/// H x1 = b, then assembles 2H into the same matrix and checks the new solve gives x1 / 2.
inline void expect_solver_refactors_after_direct_fill(const Discretization& disc, const kernel::FormKernels& form) {
  Assembler assembler(disc, form);
  PetscVector u = assembler.create_vector(), b = assembler.create_vector(), x1 = assembler.create_vector(),
              x2 = assembler.create_vector();
  std::vector<double> state(static_cast<std::size_t>(disc.n_nodes()));
  for (std::size_t a = 0; a < state.size(); ++a) state[a] = 0.3 * std::sin(1.7 * static_cast<double>(a));
  set_from_original(disc, state, 1, u);
  LMEFORM_PETSC_CHECK(VecSet(b, 1.0));
  PetscMatrix H = assembler.create_matrix();
  assembler.matrix(u, H);
  PetscLinearSolver ksp;
  LMEFORM_PETSC_CHECK(KSPCreate(disc.comm(), ksp.out()));
  LMEFORM_PETSC_CHECK(KSPSetType(ksp, KSPPREONLY));
  PC pc = nullptr;
  LMEFORM_PETSC_CHECK(KSPGetPC(ksp, &pc));
  LMEFORM_PETSC_CHECK(PCSetType(pc, PCLU));
  if (disc.ranks() > 1) LMEFORM_PETSC_CHECK(PCFactorSetMatSolverType(pc, MATSOLVERMUMPS));
  LMEFORM_PETSC_CHECK(KSPSetOperators(ksp, H, H));
  LMEFORM_PETSC_CHECK(KSPSetUp(ksp));
  LMEFORM_PETSC_CHECK(KSPSolve(ksp, b, x1));
  const Assembler::MatrixTerm twice{&assembler, 2.0};
  assembler.matrix_sum(u, {&twice, 1}, H);
  LMEFORM_PETSC_CHECK(KSPSetOperators(ksp, H, H));
  LMEFORM_PETSC_CHECK(KSPSetUp(ksp));
  LMEFORM_PETSC_CHECK(KSPSolve(ksp, b, x2));
  LMEFORM_PETSC_CHECK(VecScale(x2, 2.0));
  LMEFORM_PETSC_CHECK(VecAXPY(x2, -1.0, x1));
  PetscReal diff = 0, size = 0;
  LMEFORM_PETSC_CHECK(VecNorm(x2, NORM_INFINITY, &diff));
  LMEFORM_PETSC_CHECK(VecNorm(x1, NORM_INFINITY, &size));
  ASSERT_GT(size, 0.0);
  EXPECT_LE(diff, 1e-10 * size);
}

}  // namespace lmeform::testing
