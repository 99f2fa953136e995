#include "aij_direct_add.hpp"

#include <algorithm>
#include <stdexcept>
#include <string>
#include <utility>

#include "lmeform/petsc.hpp"

namespace lmeform::detail {

namespace {

constexpr const char* kKey = "lmeform_aij_direct_add";

PetscErrorCode destroy_map(void* pointer) {
  delete static_cast<AijDirectAdd*>(pointer);
  return 0;
}

// Row offsets and columns of a SeqAIJ matrix (PETSc's own arrays, no copy).
struct RowStructure {
  PetscInt rows = 0;
  const PetscInt* offsets = nullptr;
  const PetscInt* columns = nullptr;
};

RowStructure row_structure(Mat A) {
  RowStructure s;
  PetscBool done = PETSC_FALSE;
  LMEFORM_PETSC_CHECK(MatGetRowIJ(A, 0, PETSC_FALSE, PETSC_FALSE, &s.rows, &s.offsets, &s.columns, &done));
  if (!done) throw std::runtime_error("AijDirectAdd: MatGetRowIJ gave no row structure");
  return s;
}

void release(Mat A, RowStructure& s) {
  PetscBool done = PETSC_FALSE;
  LMEFORM_PETSC_CHECK(MatRestoreRowIJ(A, 0, PETSC_FALSE, PETSC_FALSE, &s.rows, &s.offsets, &s.columns, &done));
}

}  // namespace

AijDirectAdd* AijDirectAdd::attach(Mat A) {
  PetscBool seq = PETSC_FALSE, mpi = PETSC_FALSE;
  LMEFORM_PETSC_CHECK(PetscObjectTypeCompare(reinterpret_cast<PetscObject>(A), MATSEQAIJ, &seq));
  LMEFORM_PETSC_CHECK(PetscObjectTypeCompare(reinterpret_cast<PetscObject>(A), MATMPIAIJ, &mpi));
  if (!seq && !mpi) return nullptr;

  std::unique_ptr<AijDirectAdd> map(new AijDirectAdd());
  PetscInt row_end = 0;
  LMEFORM_PETSC_CHECK(MatGetOwnershipRange(A, &map->row_begin_, &row_end));
  const PetscInt n_rows = row_end - map->row_begin_;
  map->mpi_ = mpi == PETSC_TRUE;
  map->offsets_.assign(static_cast<std::size_t>(n_rows) + 1, 0);

  if (!map->mpi_) {
    RowStructure s = row_structure(A);
    map->columns_.assign(s.columns, s.columns + s.offsets[s.rows]);
    map->positions_.resize(map->columns_.size());
    for (std::size_t k = 0; k < map->positions_.size(); ++k) map->positions_[k] = static_cast<PetscInt>(k);
    std::copy(s.offsets, s.offsets + s.rows + 1, map->offsets_.begin());
    map->diagonal_nonzeros_ = s.offsets[s.rows];
    release(A, s);
  } else {
    Mat Ad = nullptr, Ao = nullptr;
    const PetscInt* garray = nullptr;
    LMEFORM_PETSC_CHECK(MatMPIAIJGetSeqAIJ(A, &Ad, &Ao, &garray));
    PetscInt column_begin = 0, column_end = 0;
    LMEFORM_PETSC_CHECK(MatGetOwnershipRangeColumn(A, &column_begin, &column_end));
    RowStructure d = row_structure(Ad), o = row_structure(Ao);
    map->diagonal_nonzeros_ = d.offsets[d.rows];
    map->off_diagonal_nonzeros_ = o.offsets[o.rows];
    map->columns_.reserve(static_cast<std::size_t>(map->diagonal_nonzeros_ + map->off_diagonal_nonzeros_));
    map->positions_.reserve(map->columns_.capacity());
    std::vector<std::pair<PetscInt, PetscInt>> row;  // (global column, position)
    for (PetscInt i = 0; i < n_rows; ++i) {
      row.clear();
      for (PetscInt p = d.offsets[i]; p < d.offsets[i + 1]; ++p) row.emplace_back(column_begin + d.columns[p], p);
      for (PetscInt p = o.offsets[i]; p < o.offsets[i + 1]; ++p) row.emplace_back(garray[o.columns[p]], ~p);
      std::sort(row.begin(), row.end());
      for (const auto& [column, position] : row) {
        map->columns_.push_back(column);
        map->positions_.push_back(position);
      }
      map->offsets_[static_cast<std::size_t>(i) + 1] = static_cast<PetscInt>(map->columns_.size());
    }
    release(Ad, d);
    release(Ao, o);
  }

  PetscContainer container = nullptr;
  LMEFORM_PETSC_CHECK(PetscContainerCreate(PetscObjectComm(reinterpret_cast<PetscObject>(A)), &container));
  AijDirectAdd* raw = map.release();
  LMEFORM_PETSC_CHECK(PetscContainerSetPointer(container, raw));
  LMEFORM_PETSC_CHECK(PetscContainerSetUserDestroy(container, destroy_map));
  LMEFORM_PETSC_CHECK(PetscObjectCompose(reinterpret_cast<PetscObject>(A), kKey, reinterpret_cast<PetscObject>(container)));
  LMEFORM_PETSC_CHECK(PetscContainerDestroy(&container));  // A holds the reference now
  return raw;
}

AijDirectAdd* AijDirectAdd::find(Mat A) {
  PetscObject object = nullptr;
  LMEFORM_PETSC_CHECK(PetscObjectQuery(reinterpret_cast<PetscObject>(A), kKey, &object));
  if (object == nullptr) return nullptr;
  void* pointer = nullptr;
  LMEFORM_PETSC_CHECK(PetscContainerGetPointer(reinterpret_cast<PetscContainer>(object), &pointer));
  return static_cast<AijDirectAdd*>(pointer);
}

void AijDirectAdd::check_structure(Mat A) const {
  // The map is valid while PETSc's arrays keep the structure it was read from; anything that
  // changes the structure (new nonzeros are refused by create_matrix's options) also changes
  // the nonzero counts.
  auto count = [](Mat M) {
    RowStructure s = row_structure(M);
    const PetscInt nnz = s.offsets[s.rows];
    release(M, s);
    return nnz;
  };
  PetscInt diagonal = 0, off_diagonal = 0;
  if (mpi_) {
    Mat Ad = nullptr, Ao = nullptr;
    LMEFORM_PETSC_CHECK(MatMPIAIJGetSeqAIJ(A, &Ad, &Ao, nullptr));
    diagonal = count(Ad);
    off_diagonal = count(Ao);
  } else {
    diagonal = count(A);
  }
  if (diagonal != diagonal_nonzeros_ || off_diagonal != off_diagonal_nonzeros_) {
    throw std::logic_error("AijDirectAdd: the matrix structure changed since create_matrix (" +
                           std::to_string(diagonal) + " + " + std::to_string(off_diagonal) + " nonzeros, the map has " +
                           std::to_string(diagonal_nonzeros_) + " + " + std::to_string(off_diagonal_nonzeros_) + ")");
  }
}

AijDirectAdd::Fill::Fill(AijDirectAdd& map, Mat A) : map_(&map), A_(A) {
  map.check_structure(A);
  if (map.mpi_) {
    LMEFORM_PETSC_CHECK(MatMPIAIJGetSeqAIJ(A, &diagonal_, &off_diagonal_, nullptr));
    LMEFORM_PETSC_CHECK(MatSeqAIJGetArray(diagonal_, &diagonal_values_));
    LMEFORM_PETSC_CHECK(MatSeqAIJGetArray(off_diagonal_, &off_diagonal_values_));
  } else {
    diagonal_ = A;
    LMEFORM_PETSC_CHECK(MatSeqAIJGetArray(diagonal_, &diagonal_values_));
  }
}

AijDirectAdd::Fill::~Fill() {
  if (finished_) return;
  // Unwinding after an error: give the arrays back; the values are incomplete either way.
  if (diagonal_values_ != nullptr) (void)MatSeqAIJRestoreArray(diagonal_, &diagonal_values_);
  if (off_diagonal_values_ != nullptr) (void)MatSeqAIJRestoreArray(off_diagonal_, &off_diagonal_values_);
}

void AijDirectAdd::Fill::add(std::span<const PetscInt> rows, std::span<const PetscInt> columns, const double* values,
                             double scale) {
  const AijDirectAdd& m = *map_;
  const std::size_t n_columns = columns.size();
  if (n_columns == 0) return;
  const PetscInt n_owned = static_cast<PetscInt>(m.offsets_.size()) - 1;
  for (std::size_t i = 0; i < rows.size(); ++i) {
    if (rows[i] < 0) continue;
    const PetscInt local = rows[i] - m.row_begin_;
    if (local < 0 || local >= n_owned) {
      throw std::logic_error("AijDirectAdd: row " + std::to_string(rows[i]) + " is not owned by this rank");
    }
    const PetscInt begin = m.offsets_[static_cast<std::size_t>(local)];
    const PetscInt end = m.offsets_[static_cast<std::size_t>(local) + 1];
    const PetscInt* row_columns = m.columns_.data();
    PetscInt p = static_cast<PetscInt>(std::lower_bound(row_columns + begin, row_columns + end, columns[0]) - row_columns);
    const double* v = values + i * n_columns;
    for (std::size_t j = 0; j < n_columns; ++j) {
      while (p < end && row_columns[p] < columns[j]) ++p;
      if (p == end || row_columns[p] != columns[j]) {
        throw std::logic_error("AijDirectAdd: entry (" + std::to_string(rows[i]) + ", " + std::to_string(columns[j]) +
                               ") is outside the matrix's nonzero structure");
      }
      const PetscInt position = m.positions_[static_cast<std::size_t>(p)];
      if (position >= 0) diagonal_values_[position] += scale * v[j];
      else off_diagonal_values_[~position] += scale * v[j];
      ++p;
    }
  }
}

void AijDirectAdd::Fill::finish() {
  if (finished_) return;
  finished_ = true;
  LMEFORM_PETSC_CHECK(MatSeqAIJRestoreArray(diagonal_, &diagonal_values_));
  if (off_diagonal_ != nullptr) LMEFORM_PETSC_CHECK(MatSeqAIJRestoreArray(off_diagonal_, &off_diagonal_values_));
  // Marks the matrix changed (its object state increases) so that solvers refactor it.
  LMEFORM_PETSC_CHECK(MatAssemblyBegin(A_, MAT_FINAL_ASSEMBLY));
  LMEFORM_PETSC_CHECK(MatAssemblyEnd(A_, MAT_FINAL_ASSEMBLY));
}

}  // namespace lmeform::detail
