// The symmetric indefinite factorization behind the constrained Newton: inertia, and recovery
// after a failed factorization (PETSc's MUMPS interface would otherwise skip every later one).
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <sstream>
#include <string>
#include <vector>

#include "lmeform/petsc.hpp"
#include "lmeform/symmetric_factorization.hpp"

namespace lmeform {
namespace {

/// The five-point Laplacian of an m×m grid with zero boundary values (m² unknowns, positive
/// definite), distributed over PETSC_COMM_WORLD, plus `diagonal` times the identity: indefinite
/// for a negative `diagonal` below −(smallest eigenvalue).
PetscMatrix grid_laplacian(PetscInt m, double diagonal) {
  PetscMatrix A;
  const PetscInt n = m * m;
  LMEFORM_PETSC_CHECK(MatCreateAIJ(PETSC_COMM_WORLD, PETSC_DECIDE, PETSC_DECIDE, n, n, 5, nullptr, 5, nullptr, A.out()));
  PetscInt begin = 0, end = 0;
  LMEFORM_PETSC_CHECK(MatGetOwnershipRange(A, &begin, &end));
  for (PetscInt row = begin; row < end; ++row) {
    const PetscInt i = row / m, j = row % m;
    LMEFORM_PETSC_CHECK(MatSetValue(A, row, row, 4.0 + diagonal, INSERT_VALUES));
    if (i > 0) LMEFORM_PETSC_CHECK(MatSetValue(A, row, row - m, -1.0, INSERT_VALUES));
    if (i + 1 < m) LMEFORM_PETSC_CHECK(MatSetValue(A, row, row + m, -1.0, INSERT_VALUES));
    if (j > 0) LMEFORM_PETSC_CHECK(MatSetValue(A, row, row - 1, -1.0, INSERT_VALUES));
    if (j + 1 < m) LMEFORM_PETSC_CHECK(MatSetValue(A, row, row + 1, -1.0, INSERT_VALUES));
  }
  LMEFORM_PETSC_CHECK(MatAssemblyBegin(A, MAT_FINAL_ASSEMBLY));
  LMEFORM_PETSC_CHECK(MatAssemblyEnd(A, MAT_FINAL_ASSEMBLY));
  return A;
}

/// Eigenvalues of the grid Laplacian: 4 − 2cos(πp/(m+1)) − 2cos(πq/(m+1)), p, q = 1..m.
PetscInt negative_eigenvalues_of_shifted_laplacian(PetscInt m, double diagonal) {
  PetscInt count = 0;
  const double pi = std::acos(-1.0);
  for (PetscInt p = 1; p <= m; ++p)
    for (PetscInt q = 1; q <= m; ++q)
      if (4 - 2 * std::cos(pi * p / (m + 1)) - 2 * std::cos(pi * q / (m + 1)) + diagonal < 0) ++count;
  return count;
}

/// The diagonal matrix diag(first + i) of order n with a zero in row n/2: an exact zero pivot
/// for the LDLᵀ (INFOG(1) = -10).
PetscMatrix diagonal_with_a_zero(PetscInt n, double first) {
  PetscMatrix A;
  LMEFORM_PETSC_CHECK(MatCreateAIJ(PETSC_COMM_WORLD, PETSC_DECIDE, PETSC_DECIDE, n, n, 1, nullptr, 0, nullptr, A.out()));
  PetscInt begin = 0, end = 0;
  LMEFORM_PETSC_CHECK(MatGetOwnershipRange(A, &begin, &end));
  for (PetscInt row = begin; row < end; ++row)
    LMEFORM_PETSC_CHECK(MatSetValue(A, row, row, row == n / 2 ? 0.0 : first + static_cast<double>(row), INSERT_VALUES));
  LMEFORM_PETSC_CHECK(MatAssemblyBegin(A, MAT_FINAL_ASSEMBLY));
  LMEFORM_PETSC_CHECK(MatAssemblyEnd(A, MAT_FINAL_ASSEMBLY));
  return A;
}

/// max |A x − b| / max |b| after solving with the factorization.
double relative_solve_error(SymmetricFactorization& factorization, Mat A) {
  PetscVector b, x, r;
  LMEFORM_PETSC_CHECK(MatCreateVecs(A, x.out(), b.out()));
  LMEFORM_PETSC_CHECK(VecDuplicate(b, r.out()));
  LMEFORM_PETSC_CHECK(VecSet(b, 1.0));
  factorization.solve(b, x);
  LMEFORM_PETSC_CHECK(MatMult(A, x, r));
  LMEFORM_PETSC_CHECK(VecAXPY(r, -1.0, b));
  PetscReal error = 0;
  LMEFORM_PETSC_CHECK(VecNorm(r, NORM_INFINITY, &error));
  return static_cast<double>(error);
}

TEST(SymmetricFactorization, CountsTheNegativeEigenvaluesOfAnIndefiniteMatrix) {
  const PetscInt m = 20;
  SymmetricFactorization factorization(PETSC_COMM_WORLD, "test_inertia_");
  for (const double diagonal : {0.0, -1.3, -4.1, -6.05}) {  // every |eigenvalue| > 8e-3
    const PetscMatrix A = grid_laplacian(m, diagonal);
    ASSERT_TRUE(factorization.factor(A)) << factorization.failure();
    EXPECT_EQ(factorization.negative_eigenvalues(), negative_eigenvalues_of_shifted_laplacian(m, diagonal)) << diagonal;
    EXPECT_LT(relative_solve_error(factorization, A), 1e-9) << diagonal;
  }
}

TEST(SymmetricFactorization, AFailedFactorizationDoesNotSkipTheNextOne) {
  // A diagonal matrix with one zero entry: the LDLᵀ meets an exact zero pivot (INFOG(1) = -10).
  PetscMatrix A = diagonal_with_a_zero(50, 1.0);
  SymmetricFactorization factorization(PETSC_COMM_WORLD, "test_failure_");
  ASSERT_FALSE(factorization.factor(A));
  EXPECT_TRUE(factorization.failed());
  EXPECT_NE(factorization.failure().find("INFOG(1)"), std::string::npos) << factorization.failure();
  std::printf("singular: %s\n", factorization.failure().c_str());
  // The same matrix object shifted in place, as the inertia correction does: it must be factored.
  LMEFORM_PETSC_CHECK(MatShift(A, -0.5));
  ASSERT_TRUE(factorization.factor(A)) << factorization.failure();
  EXPECT_EQ(factorization.negative_eigenvalues(), 1);  // 0 − 0.5; the others are ≥ 0.5
  EXPECT_LT(relative_solve_error(factorization, A), 1e-12);
}

TEST(SymmetricFactorization, AForgottenMatrixIsAnalysedAfresh) {
  // A constrained minimizer whose fixed components change builds another Hessian, which may take
  // the address of the destroyed one: after forget_matrix the next factor starts from nothing.
  SymmetricFactorization factorization(PETSC_COMM_WORLD, "test_forget_");
  {
    PetscMatrix A = grid_laplacian(6, 0.0);
    ASSERT_TRUE(factorization.factor(A));
    EXPECT_EQ(factorization.negative_eigenvalues(), 0);
  }
  factorization.forget_matrix();
  PetscMatrix B = grid_laplacian(7, -2.5);  // another size and inertia
  ASSERT_TRUE(factorization.factor(B)) << factorization.failure();
  EXPECT_EQ(factorization.negative_eigenvalues(), negative_eigenvalues_of_shifted_laplacian(7, -2.5));
  EXPECT_GT(factorization.negative_eigenvalues(), 0);
  EXPECT_LT(relative_solve_error(factorization, B), 1e-10);
}

TEST(SymmetricFactorization, SolvesSeveralRightHandSidesAtOnceAsOneByOne) {
  const PetscInt m = 24;
  PetscMatrix A = grid_laplacian(m, -1.3);  // indefinite
  SymmetricFactorization factorization(PETSC_COMM_WORLD, "test_many_");
  ASSERT_TRUE(factorization.factor(A)) << factorization.failure();
  std::vector<PetscVector> b(3), together(3), apart(3);
  for (std::size_t i = 0; i < b.size(); ++i) {
    LMEFORM_PETSC_CHECK(MatCreateVecs(A, together[i].out(), b[i].out()));
    LMEFORM_PETSC_CHECK(VecDuplicate(together[i], apart[i].out()));
    PetscInt begin = 0, end = 0;
    LMEFORM_PETSC_CHECK(VecGetOwnershipRange(b[i], &begin, &end));
    for (PetscInt row = begin; row < end; ++row)
      LMEFORM_PETSC_CHECK(VecSetValue(b[i], row, std::sin(0.1 * double(row) * double(i + 1)) + double(i), INSERT_VALUES));
    LMEFORM_PETSC_CHECK(VecAssemblyBegin(b[i]));
    LMEFORM_PETSC_CHECK(VecAssemblyEnd(b[i]));
    factorization.solve(b[i], apart[i]);
  }
  const std::vector<Vec> bs{b[0], b[1], b[2]}, xs{together[0], together[1], together[2]};
  factorization.solve(bs, xs);
  for (std::size_t i = 0; i < b.size(); ++i) {
    PetscReal scale = 0, difference = 0;
    LMEFORM_PETSC_CHECK(VecNorm(apart[i], NORM_INFINITY, &scale));
    LMEFORM_PETSC_CHECK(VecAXPY(apart[i], -1.0, together[i]));
    LMEFORM_PETSC_CHECK(VecNorm(apart[i], NORM_INFINITY, &difference));
    EXPECT_LT(difference, 1e-12 * scale) << "right-hand side " << i;
    EXPECT_GT(scale, 0.0);
  }
  const std::vector<Vec> one_short{together[0], together[1]};
  EXPECT_THROW(factorization.solve(bs, one_short), std::invalid_argument);

  // A Krylov solver from the options database: the columns are solved and checked one by one.
  LMEFORM_PETSC_CHECK(PetscOptionsSetValue(nullptr, "-test_krylov_ksp_type", "gmres"));
  LMEFORM_PETSC_CHECK(PetscOptionsSetValue(nullptr, "-test_krylov_ksp_rtol", "1e-13"));
  SymmetricFactorization krylov(PETSC_COMM_WORLD, "test_krylov_");
  ASSERT_TRUE(krylov.factor(A)) << krylov.failure();
  krylov.solve(bs, xs);
  for (std::size_t i = 0; i < b.size(); ++i) {
    PetscVector r;
    LMEFORM_PETSC_CHECK(VecDuplicate(b[i], r.out()));
    LMEFORM_PETSC_CHECK(MatMult(A, together[i], r));
    LMEFORM_PETSC_CHECK(VecAXPY(r, -1.0, b[i]));
    PetscReal residual = 0, scale = 0;
    LMEFORM_PETSC_CHECK(VecNorm(r, NORM_2, &residual));
    LMEFORM_PETSC_CHECK(VecNorm(b[i], NORM_2, &scale));
    EXPECT_LT(residual, 1e-10 * scale) << "right-hand side " << i;
  }
  LMEFORM_PETSC_CHECK(PetscOptionsClearValue(nullptr, "-test_krylov_ksp_type"));
  LMEFORM_PETSC_CHECK(PetscOptionsClearValue(nullptr, "-test_krylov_ksp_rtol"));
}

TEST(SymmetricFactorization, TheOptionsDatabaseStillAppliesAfterAFailedFactorization) {
  // The factor rebuilt after a failure reads -PREFIX_mat_mumps_icntl_* again (here the ordering):
  // a user's MUMPS settings are not silently dropped once a factorization failed.
  LMEFORM_PETSC_CHECK(PetscOptionsSetValue(nullptr, "-test_reread_mat_mumps_icntl_7", "0"));
  PetscMatrix A = diagonal_with_a_zero(40, 2.0);
  SymmetricFactorization factorization(PETSC_COMM_WORLD, "test_reread_");
  ASSERT_FALSE(factorization.factor(A));  // a zero pivot
  LMEFORM_PETSC_CHECK(MatShift(A, -1.0));
  ASSERT_TRUE(factorization.factor(A)) << factorization.failure();
  EXPECT_EQ(factorization.mumps_control(7), 0);  // AMD, as asked; MUMPS's default is 7
  EXPECT_EQ(factorization.mumps_control(13), 1);  // and this class's own setting stays
  LMEFORM_PETSC_CHECK(PetscOptionsClearValue(nullptr, "-test_reread_mat_mumps_icntl_7"));
}

TEST(SymmetricFactorization, AWorkspaceFailureIsRetriedWithMoreWorkspace) {
  // A grid Laplacian with tiny diagonal entries of both signs: the analysis sees a regular pattern,
  // the numerical factorization rejects most 1×1 pivots and delays them, needing more workspace
  // than the analysis estimated. With no margin (ICNTL(14) = 0) MUMPS stops with INFOG(1) = -9;
  // the factorization retries with a larger margin.
  const PetscInt m = 60;
  PetscMatrix A = grid_laplacian(m, -4.0);
  PetscInt begin = 0, end = 0;
  LMEFORM_PETSC_CHECK(MatGetOwnershipRange(A, &begin, &end));
  for (PetscInt row = begin; row < end; ++row)
    LMEFORM_PETSC_CHECK(MatSetValue(A, row, row, (row % 3 == 0 ? -1e-6 : 1e-6) * static_cast<double>(1 + row % 7), INSERT_VALUES));
  LMEFORM_PETSC_CHECK(MatAssemblyBegin(A, MAT_FINAL_ASSEMBLY));
  LMEFORM_PETSC_CHECK(MatAssemblyEnd(A, MAT_FINAL_ASSEMBLY));
  SymmetricFactorization factorization(PETSC_COMM_WORLD, "test_workspace_");
  std::ostringstream log;
  factorization.set_log(&log);
  factorization.set_workspace_percent(0);
  const bool factored = factorization.factor(A);
  std::printf("%s -> %s, ICNTL(14) %d\n", log.str().c_str(), factored ? "factored" : factorization.failure().c_str(),
              static_cast<int>(factorization.workspace_percent()));
  ASSERT_TRUE(factored) << factorization.failure();
  EXPECT_GE(factorization.workspace_percent(), 50);  // at least one retry
  if (PetscSession::rank() == 0) {
    EXPECT_NE(log.str().find("INFOG(1) = -9"), std::string::npos) << log.str();
  }
  EXPECT_LT(relative_solve_error(factorization, A), 1e-6);
}

}  // namespace
}  // namespace lmeform
