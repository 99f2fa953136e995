// A direct factorization of a symmetric, possibly indefinite, sparse matrix with its inertia:
// MUMPS's LDLᵀ by default (a KSPPREONLY + PCCHOLESKY solver whose options prefix lets the
// options database choose another), refactored in place as the matrix's values change.
//
// PETSc's MUMPS interface skips every later numerical factorization of a factor whose last one
// failed, so after a failure the factor is rebuilt from its analysis; a failure for lack of MUMPS
// workspace (numerical pivoting delayed more pivots than the analysis foresaw) is retried with a
// larger ICNTL(14).
#pragma once

#include <iosfwd>
#include <span>
#include <string>

#include "lmeform/petsc.hpp"

namespace lmeform {

class SymmetricFactorization {
 public:
  /// `prefix`: the KSP's options prefix ("constrained_" reads -constrained_pc_type ...).
  SymmetricFactorization(MPI_Comm comm, const std::string& prefix);

  /// Factors A (its values as they are now; the analysis is reused while A is the same matrix).
  /// Returns whether the factorization succeeded; when it did not, failure() says why and the next
  /// call factors afresh.
  bool factor(Mat A);
  /// Solves A x = b with the last successful factorization; throws if the solve fails.
  void solve(Vec b, Vec x);
  /// Solves A x_i = b_i for every pair in one pass over the factors (MUMPS reads its factors once
  /// for all the right-hand sides, where separate solves read them once each).
  void solve(std::span<const Vec> b, std::span<const Vec> x);

  [[nodiscard]] bool failed() const noexcept { return failed_; }
  /// PETSc's reason, MUMPS's INFOG(1) and whether the matrix has non-finite entries.
  [[nodiscard]] const std::string& failure() const noexcept { return failure_; }
  /// Negative eigenvalues of the last factored matrix; -1 when unknown (not MUMPS's LDLᵀ, or failed).
  [[nodiscard]] PetscInt negative_eigenvalues() const noexcept { return negative_eigenvalues_; }
  /// MUMPS's ICNTL(14) after the workspace retries so far; 0 while MUMPS's default is in use.
  [[nodiscard]] PetscInt workspace_percent() const noexcept { return workspace_percent_; }
  /// Sets ICNTL(14) for the next analysis (the options database, -mat_mumps_icntl_14, overrides it).
  void set_workspace_percent(PetscInt percent);
  /// Where the workspace retries are reported (rank 0 of the communicator only); nullptr: silent.
  void set_log(std::ostream* log) noexcept { log_ = log; }
  /// Forgets the last matrix: the next factor() analyses afresh (a new matrix may reuse the
  /// address of a destroyed one).
  void forget_matrix();
  /// MUMPS's ICNTL(i) of the current factor (as the options database and this class set it);
  /// -1 without a MUMPS factor.
  [[nodiscard]] PetscInt mumps_control(PetscInt i) const;

 private:
  MPI_Comm comm_;
  PetscLinearSolver ksp_;
  std::ostream* log_ = nullptr;
  Mat matrix_ = nullptr;  // the matrix last factored (compared, never dereferenced)
  bool configured_ = false;
  bool failed_ = false;
  std::string failure_;
  PetscInt negative_eigenvalues_ = -1;
  PetscInt workspace_percent_ = 0;
  bool workspace_set_ = false;  // ICNTL(14) given (set_workspace_percent or a retry), even if 0
};

}  // namespace lmeform
