#include "lmeform/symmetric_factorization.hpp"

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <ostream>
#include <stdexcept>
#include <string_view>

namespace lmeform {

SymmetricFactorization::SymmetricFactorization(MPI_Comm comm, const std::string& prefix) : comm_(comm) {
  LMEFORM_PETSC_CHECK(KSPCreate(comm, ksp_.out()));
  LMEFORM_PETSC_CHECK(KSPSetType(ksp_, KSPPREONLY));
  PC pc = nullptr;
  LMEFORM_PETSC_CHECK(KSPGetPC(ksp_, &pc));
  // MUMPS's symmetric indefinite LDLᵀ: it pivots, so indefinite matrices factor too, it costs
  // half an LU, and it counts the negative pivots.
  LMEFORM_PETSC_CHECK(PCSetType(pc, PCCHOLESKY));
  LMEFORM_PETSC_CHECK(PCFactorSetMatSolverType(pc, MATSOLVERMUMPS));
  LMEFORM_PETSC_CHECK(KSPSetOptionsPrefix(ksp_, prefix.c_str()));
  LMEFORM_PETSC_CHECK(KSPSetFromOptions(ksp_));
}

bool SymmetricFactorization::factor(Mat A) {
  if (A != matrix_) {
    // Another matrix: the factor and its MUMPS settings start afresh.
    LMEFORM_PETSC_CHECK(KSPReset(ksp_));
    configured_ = false;
    matrix_ = A;
  }
  PC pc = nullptr;
  LMEFORM_PETSC_CHECK(KSPGetPC(ksp_, &pc));
  for (int attempt = 0;; ++attempt) {
    LMEFORM_PETSC_CHECK(KSPSetOperators(ksp_, A, A));
    PCType pc_type = nullptr;
    MatSolverType solver_type = nullptr;
    LMEFORM_PETSC_CHECK(PCGetType(pc, &pc_type));
    LMEFORM_PETSC_CHECK(PCFactorGetMatSolverType(pc, &solver_type));
    const bool mumps_ldlt = pc_type != nullptr && solver_type != nullptr && std::string_view(pc_type) == PCCHOLESKY &&
                            std::string_view(solver_type) == MATSOLVERMUMPS;
    if (!configured_ && mumps_ldlt) {
      LMEFORM_PETSC_CHECK(PCFactorSetUpMatSolverType(pc));
      Mat F = nullptr;
      LMEFORM_PETSC_CHECK(PCFactorGetMatrix(pc, &F));
      // Without ScaLAPACK on the root front MUMPS counts the negative pivots of every rank.
      LMEFORM_PETSC_CHECK(MatMumpsSetIcntl(F, 13, 1));
      if (workspace_set_) LMEFORM_PETSC_CHECK(MatMumpsSetIcntl(F, 14, workspace_percent_));
    }
    configured_ = true;
    LMEFORM_PETSC_CHECK(KSPSetUp(ksp_));
    negative_eigenvalues_ = -1;
    PCFailedReason reason = PC_NOERROR;
    LMEFORM_PETSC_CHECK(PCGetFailedReason(pc, &reason));
    failed_ = reason != PC_NOERROR;
    failure_.clear();
    if (!failed_) {
      if (mumps_ldlt) {
        Mat F = nullptr;
        LMEFORM_PETSC_CHECK(PCFactorGetMatrix(pc, &F));
        PetscInt negative = 0;
        LMEFORM_PETSC_CHECK(MatGetInertia(F, &negative, nullptr, nullptr));
        negative_eigenvalues_ = negative;
      }
      return true;
    }
    failure_ = PCFailedReasons[reason];
    PetscReal frobenius = 0;
    LMEFORM_PETSC_CHECK(MatNorm(A, NORM_FROBENIUS, &frobenius));
    if (!std::isfinite(static_cast<double>(frobenius))) failure_ += ", the matrix has non-finite entries";
    PetscInt info = 0, workspace = 0;
    if (mumps_ldlt) {
      Mat F = nullptr;
      LMEFORM_PETSC_CHECK(PCFactorGetMatrix(pc, &F));
      LMEFORM_PETSC_CHECK(MatMumpsGetInfog(F, 1, &info));
      LMEFORM_PETSC_CHECK(MatMumpsGetIcntl(F, 14, &workspace));
      failure_ += ", MUMPS INFOG(1) = " + std::to_string(info);
    }
    // Rebuilt, so that the next factorization (a shifted matrix, a shorter time step) is done at all.
    LMEFORM_PETSC_CHECK(KSPReset(ksp_));
    configured_ = false;
    // INFOG(1) = -8, -9, -11, -12, -14, -15: a work array sized at the analysis was too small.
    const bool workspace_short = info == -8 || info == -9 || (-16 < info && info < -10 && info != -13);
    if (!workspace_short || attempt == 4) return false;
    workspace_percent_ = std::max<PetscInt>(2 * workspace, 50);
    workspace_set_ = true;
    int rank = 0;
    MPI_Comm_rank(comm_, &rank);
    if (log_ != nullptr && rank == 0)
      *log_ << "           MUMPS workspace too small (INFOG(1) = " << info << "): ICNTL(14) raised to " << workspace_percent_
            << " %, factoring again" << std::endl;
  }
}

void SymmetricFactorization::set_workspace_percent(PetscInt percent) {
  if (percent < 0) throw std::invalid_argument("symmetric factorization: a negative MUMPS workspace increase");
  workspace_percent_ = percent;
  workspace_set_ = true;
  // Read at the next analysis.
  LMEFORM_PETSC_CHECK(KSPReset(ksp_));
  configured_ = false;
}

void SymmetricFactorization::forget_matrix() {
  LMEFORM_PETSC_CHECK(KSPReset(ksp_));
  configured_ = false;
  matrix_ = nullptr;
}

namespace {

void throw_if_failed(KSP ksp) {
  KSPConvergedReason reason;
  LMEFORM_PETSC_CHECK(KSPGetConvergedReason(ksp, &reason));
  if (reason < 0) {
    throw std::runtime_error(std::string("symmetric factorization: the solve failed (") + KSPConvergedReasons[reason] +
                             "): the matrix is singular");
  }
}

/// Copies between a vector and a column of a dense matrix with the same row layout.
void copy_column(Mat dense, PetscInt column, Vec v, bool into_matrix) {
  Vec col = nullptr;
  if (into_matrix) {
    LMEFORM_PETSC_CHECK(MatDenseGetColumnVecWrite(dense, column, &col));
    LMEFORM_PETSC_CHECK(VecCopy(v, col));
    LMEFORM_PETSC_CHECK(MatDenseRestoreColumnVecWrite(dense, column, &col));
  } else {
    LMEFORM_PETSC_CHECK(MatDenseGetColumnVecRead(dense, column, &col));
    LMEFORM_PETSC_CHECK(VecCopy(col, v));
    LMEFORM_PETSC_CHECK(MatDenseRestoreColumnVecRead(dense, column, &col));
  }
}

}  // namespace

void SymmetricFactorization::solve(Vec b, Vec x) {
  if (failed_) throw std::runtime_error("symmetric factorization: the factorization failed (" + failure_ + ")");
  LMEFORM_PETSC_CHECK(KSPSolve(ksp_, b, x));
  throw_if_failed(ksp_);
}

void SymmetricFactorization::solve(std::span<const Vec> b, std::span<const Vec> x) {
  if (b.size() != x.size())
    throw std::invalid_argument("symmetric factorization: " + std::to_string(b.size()) + " right-hand sides for " +
                                std::to_string(x.size()) + " solutions");
  KSPType type = nullptr;
  LMEFORM_PETSC_CHECK(KSPGetType(ksp_, &type));
  // A Krylov solver chosen in the options database solves the block column by column, and only
  // the last column's convergence would be seen: those are solved one by one and each checked.
  if (b.size() <= 1 || type == nullptr || std::string_view(type) != KSPPREONLY) {
    for (std::size_t i = 0; i < b.size(); ++i) solve(b[i], x[i]);
    return;
  }
  if (failed_) throw std::runtime_error("symmetric factorization: the factorization failed (" + failure_ + ")");
  PetscInt local = 0, global = 0;
  LMEFORM_PETSC_CHECK(VecGetLocalSize(b[0], &local));
  LMEFORM_PETSC_CHECK(VecGetSize(b[0], &global));
  const auto columns = static_cast<PetscInt>(b.size());
  PetscMatrix B, X;
  LMEFORM_PETSC_CHECK(MatCreateDense(comm_, local, PETSC_DECIDE, global, columns, nullptr, B.out()));
  LMEFORM_PETSC_CHECK(MatCreateDense(comm_, local, PETSC_DECIDE, global, columns, nullptr, X.out()));
  for (PetscInt j = 0; j < columns; ++j) copy_column(B, j, b[std::size_t(j)], true);
  LMEFORM_PETSC_CHECK(KSPMatSolve(ksp_, B, X));
  throw_if_failed(ksp_);
  for (PetscInt j = 0; j < columns; ++j) copy_column(X, j, x[std::size_t(j)], false);
}

PetscInt SymmetricFactorization::mumps_control(PetscInt i) const {
  if (!configured_) return -1;
  PC pc = nullptr;
  LMEFORM_PETSC_CHECK(KSPGetPC(ksp_, &pc));
  MatSolverType solver_type = nullptr;
  LMEFORM_PETSC_CHECK(PCFactorGetMatSolverType(pc, &solver_type));
  if (solver_type == nullptr || std::string_view(solver_type) != MATSOLVERMUMPS) return -1;
  Mat F = nullptr;
  LMEFORM_PETSC_CHECK(PCFactorGetMatrix(pc, &F));
  PetscInt value = 0;
  LMEFORM_PETSC_CHECK(MatMumpsGetIcntl(F, i, &value));
  return value;
}

}  // namespace lmeform
