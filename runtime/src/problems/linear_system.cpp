#include "linear_system.hpp"

#include <mpi.h>

#include <string_view>

#include <fmt/format.h>

#include "lmeform/petsc.hpp"
#include "lmeform/stopwatch.hpp"
#include "toolkit.hpp"

namespace lmeform::problems {
namespace {

bool direct_preconditioner(PC pc) {
  PCType type = nullptr;
  LMEFORM_PETSC_CHECK(PCGetType(pc, &type));
  return type != nullptr && (std::string_view(type) == PCLU || std::string_view(type) == PCCHOLESKY);
}

bool fieldsplit_preconditioner(PC pc) {
  PCType type = nullptr;
  LMEFORM_PETSC_CHECK(PCGetType(pc, &type));
  return type != nullptr && std::string_view(type) == PCFIELDSPLIT;
}

/// Names the fields as splits of a PCFIELDSPLIT (their options prefixes are -fieldsplit_<name>_).
void name_field_splits(MPI_Comm comm, PC pc, Mat A, const LinearSystemLayout& layout) {
  PetscInt begin = 0, end = 0;
  LMEFORM_PETSC_CHECK(MatGetOwnershipRange(A, &begin, &end));
  for (const auto& f : layout.fields) {
    std::vector<PetscInt> dofs;
    for (PetscInt node_first = begin; node_first < end; node_first += layout.dofs_per_node)
      for (int c = 0; c < f.components; ++c) dofs.push_back(node_first + f.offset + c);
    PetscIndexSet is;
    LMEFORM_PETSC_CHECK(ISCreateGeneral(comm, static_cast<PetscInt>(dofs.size()), dofs.data(), PETSC_COPY_VALUES, is.out()));
    LMEFORM_PETSC_CHECK(PCFieldSplitSetIS(pc, f.name.c_str(), is));
  }
}

}  // namespace

PetscMatrix bordered_matrix(MPI_Comm comm, Mat A, std::span<const Vec> columns) {
  int rank = 0, size = 1;
  MPI_Comm_rank(comm, &rank);
  MPI_Comm_size(comm, &size);
  const bool last = rank == size - 1;
  const auto k = static_cast<PetscInt>(columns.size());
  PetscInt n = 0, begin = 0, end = 0;
  LMEFORM_PETSC_CHECK(MatGetSize(A, &n, nullptr));
  LMEFORM_PETSC_CHECK(MatGetOwnershipRange(A, &begin, &end));
  const PetscInt local_rows = end - begin + (last ? k : 0);
  const PetscInt diagonal_end = end + (last ? k : 0);  // the columns of this rank's diagonal block

  std::vector<std::vector<PetscScalar>> c(columns.size());
  for (std::size_t j = 0; j < columns.size(); ++j) {
    const VecReadView view(columns[j]);
    c[j].assign(view.data(), view.data() + view.size());
  }
  std::vector<PetscInt> d_nnz(static_cast<std::size_t>(local_rows), 0), o_nnz(static_cast<std::size_t>(local_rows), 0);
  for (PetscInt row = begin; row < end; ++row) {
    PetscInt ncols = 0;
    const PetscInt* cols = nullptr;
    LMEFORM_PETSC_CHECK(MatGetRow(A, row, &ncols, &cols, nullptr));
    auto& d = d_nnz[static_cast<std::size_t>(row - begin)];
    auto& o = o_nnz[static_cast<std::size_t>(row - begin)];
    for (PetscInt i = 0; i < ncols; ++i) (cols[i] >= begin && cols[i] < diagonal_end ? d : o) += 1;
    LMEFORM_PETSC_CHECK(MatRestoreRow(A, row, &ncols, &cols, nullptr));
    for (const auto& cj : c)
      if (cj[static_cast<std::size_t>(row - begin)] != 0.0) (last ? d : o) += 1;
  }
  for (std::size_t j = 0; j < c.size(); ++j) {
    PetscInt local = 0, global = 0;
    for (const double v : c[j]) local += v != 0.0 ? 1 : 0;
    MPI_Allreduce(&local, &global, 1, MPIU_INT, MPI_SUM, comm);
    if (last) {
      d_nnz[static_cast<std::size_t>(end - begin) + j] = local;
      o_nnz[static_cast<std::size_t>(end - begin) + j] = global - local;
    }
  }
  PetscMatrix K;
  LMEFORM_PETSC_CHECK(MatCreateAIJ(comm, local_rows, local_rows, n + k, n + k, 0, d_nnz.data(), 0, o_nnz.data(), K.out()));
  for (PetscInt row = begin; row < end; ++row) {
    PetscInt ncols = 0;
    const PetscInt* cols = nullptr;
    const PetscScalar* values = nullptr;
    LMEFORM_PETSC_CHECK(MatGetRow(A, row, &ncols, &cols, &values));
    LMEFORM_PETSC_CHECK(MatSetValues(K, 1, &row, ncols, cols, values, INSERT_VALUES));
    LMEFORM_PETSC_CHECK(MatRestoreRow(A, row, &ncols, &cols, &values));
    for (std::size_t j = 0; j < c.size(); ++j) {
      const PetscScalar v = c[j][static_cast<std::size_t>(row - begin)];
      if (v == 0.0) continue;
      const PetscInt border = n + static_cast<PetscInt>(j);
      LMEFORM_PETSC_CHECK(MatSetValue(K, row, border, v, INSERT_VALUES));
      LMEFORM_PETSC_CHECK(MatSetValue(K, border, row, v, INSERT_VALUES));  // off-process: stashed
    }
  }
  LMEFORM_PETSC_CHECK(MatAssemblyBegin(K, MAT_FINAL_ASSEMBLY));
  LMEFORM_PETSC_CHECK(MatAssemblyEnd(K, MAT_FINAL_ASSEMBLY));
  return K;
}

/// A vector of the bordered layout holding v in its first part and zeros in the border.
PetscVector bordered_vector(MPI_Comm comm, Vec v, PetscInt k) {
  int rank = 0, size = 1;
  MPI_Comm_rank(comm, &rank);
  MPI_Comm_size(comm, &size);
  PetscInt local = 0, global = 0;
  LMEFORM_PETSC_CHECK(VecGetLocalSize(v, &local));
  LMEFORM_PETSC_CHECK(VecGetSize(v, &global));
  PetscVector out;
  LMEFORM_PETSC_CHECK(VecCreateMPI(comm, local + (rank == size - 1 ? k : 0), global + k, out.out()));
  LMEFORM_PETSC_CHECK(VecSet(out, 0.0));
  {
    const VecReadView in(v);
    VecWriteView o(out);
    for (PetscInt i = 0; i < local; ++i) o[i] = in[i];
  }
  return out;
}

namespace {

double relative_residual(Mat A, Vec x, Vec b) {
  PetscVector r;
  LMEFORM_PETSC_CHECK(VecDuplicate(b, r.out()));
  LMEFORM_PETSC_CHECK(MatMult(A, x, r));
  LMEFORM_PETSC_CHECK(VecAXPY(r, -1.0, b));
  PetscReal rn = 0, bn = 0;
  LMEFORM_PETSC_CHECK(VecNorm(r, NORM_2, &rn));
  LMEFORM_PETSC_CHECK(VecNorm(b, NORM_2, &bn));
  return bn > 0 ? rn / bn : rn;
}

}  // namespace

LinearSolveReport solve_linear_system(MPI_Comm comm, Mat A, Vec b, Vec x, const LinearSystemLayout& layout) {
  const Stopwatch clock;
  LinearSolveReport report;
  PetscLinearSolver ksp;
  LMEFORM_PETSC_CHECK(KSPCreate(comm, ksp.out()));
  configure_direct_solver(ksp);
  LMEFORM_PETSC_CHECK(KSPSetFromOptions(ksp));
  PC pc = nullptr;
  LMEFORM_PETSC_CHECK(KSPGetPC(ksp, &pc));

  const auto k = static_cast<PetscInt>(layout.mean_functionals.size());
  const bool bordered = k > 0 && direct_preconditioner(pc);
  PetscMatrix K;
  PetscVector rhs, y;
  MatNullSpace null_space = nullptr;
  if (bordered) {
    report.zero_mean_method = "constraint";
    K = bordered_matrix(comm, A, layout.mean_functionals);
    rhs = bordered_vector(comm, b, k);
    y = bordered_vector(comm, x, k);
    LMEFORM_PETSC_CHECK(KSPSetOperators(ksp, K, K));
  } else {
    if (k > 0) {
      report.zero_mean_method = "null space";
      std::vector<Vec> modes;
      for (const Vec mode : layout.constant_modes) {
        Vec m = nullptr;
        LMEFORM_PETSC_CHECK(VecDuplicate(mode, &m));
        LMEFORM_PETSC_CHECK(VecCopy(mode, m));
        LMEFORM_PETSC_CHECK(VecNormalize(m, nullptr));
        modes.push_back(m);
      }
      LMEFORM_PETSC_CHECK(MatNullSpaceCreate(comm, PETSC_FALSE, k, modes.data(), &null_space));
      for (Vec& m : modes) VecDestroy(&m);
      LMEFORM_PETSC_CHECK(MatSetNullSpace(A, null_space));
    }
    LMEFORM_PETSC_CHECK(KSPSetOperators(ksp, A, A));
    if (fieldsplit_preconditioner(pc)) name_field_splits(comm, pc, A, layout);
  }
  const PetscErrorCode solved = KSPSolve(ksp, bordered ? Vec(rhs) : b, bordered ? Vec(y) : x);
  KSPConvergedReason reason = KSP_CONVERGED_ITERATING;
  PetscInt its = 0;
  KSPGetConvergedReason(ksp, &reason);
  KSPGetIterationNumber(ksp, &its);
  if (null_space != nullptr) {
    MatSetNullSpace(A, nullptr);
    MatNullSpaceDestroy(&null_space);
  }
  LMEFORM_PETSC_CHECK(solved);

  if (bordered) {
    report.relative_residual = relative_residual(K, y, rhs);
    const VecReadView from(y);
    VecWriteView to(x);
    for (PetscInt i = 0; i < to.size(); ++i) to[i] = from[i];
  } else {
    // The Krylov method returns some member of x + span(modes): take the one of zero mean.
    for (PetscInt j = 0; j < k; ++j) {
      const Vec c = layout.mean_functionals[static_cast<std::size_t>(j)];
      const Vec mode = layout.constant_modes[static_cast<std::size_t>(j)];
      PetscScalar mean = 0, measure = 0;
      LMEFORM_PETSC_CHECK(VecDot(c, x, &mean));
      LMEFORM_PETSC_CHECK(VecDot(c, mode, &measure));
      LMEFORM_PETSC_CHECK(VecAXPY(x, -mean / measure, mode));
    }
    report.relative_residual = relative_residual(A, x, b);
  }
  report.iterations = static_cast<int>(its);
  // A Krylov method judges its own convergence (-ksp_rtol); a direct solve must reproduce b.
  report.converged = reason > 0 && (!direct_preconditioner(pc) || report.relative_residual < 1e-6);
  report.message = fmt::format("KSP {} in {} iterations, |Au - b| / |b| = {:.2e}{}", KSPConvergedReasons[reason], its,
                               report.relative_residual,
                               report.zero_mean_method.empty() ? "" : " (zero mean by " + report.zero_mean_method + ")");
  report.seconds = clock.seconds();
  return report;
}

}  // namespace lmeform::problems
