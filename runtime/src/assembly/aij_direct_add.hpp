// Direct addition of dense element blocks into the value arrays of an AIJ matrix whose nonzero
// structure is fixed (internal to lmeform_assembly).
//
// MatSetValues searches every entry in its row and goes through PETSc's generic insertion path
// (about 30 ns per entry measured here); a cell-based Helfrich Hessian inserts tens of millions of
// entries per assembly, so insertion dominated the whole Newton step. When the matrix structure is
// known and fixed (Assembler::create_matrix inserts the exact pattern once), each element row can
// be located by one binary search and a merge walk over the row's sorted columns, and the values
// added straight into the SeqAIJ arrays (MPIAIJ: its diagonal and off-diagonal SeqAIJ blocks).
//
// The map is read from the matrix itself (MatGetRowIJ, MatMPIAIJGetSeqAIJ), not predicted, so it
// follows PETSc's actual layout; it is attached to the Mat (PetscObjectCompose), so any Assembler
// of the same discretization adding into that matrix finds it.
#pragma once

#include <petscmat.h>

#include <memory>
#include <span>
#include <vector>

namespace lmeform::detail {

class AijDirectAdd {
 public:
  /// Builds the map of A's owned rows and attaches it to A. A must be assembled, of type
  /// MATSEQAIJ or MATMPIAIJ; returns null (and attaches nothing) for any other type.
  static AijDirectAdd* attach(Mat A);
  /// The map attached to A, or null.
  static AijDirectAdd* find(Mat A);

  /// Values access for one assembly: get the arrays, add element blocks, restore.
  class Fill {
   public:
    Fill(AijDirectAdd& map, Mat A);
    ~Fill();
    Fill(const Fill&) = delete;
    Fill& operator=(const Fill&) = delete;
    /// values[(i * m) + j] (m = columns.size(), row-major) times `scale` is added at
    /// (rows[i], columns[j]); rows < 0 are skipped, the others must be owned. Rows and columns are
    /// global scalar indices, the columns sorted ascending.
    void add(std::span<const PetscInt> rows, std::span<const PetscInt> columns, const double* values, double scale);
    /// Restores the arrays and marks the matrix changed (MatAssemblyBegin/End).
    void finish();

   private:
    AijDirectAdd* map_;
    Mat A_;
    Mat diagonal_ = nullptr;
    Mat off_diagonal_ = nullptr;
    PetscScalar* diagonal_values_ = nullptr;
    PetscScalar* off_diagonal_values_ = nullptr;
    bool finished_ = false;
  };

  [[nodiscard]] PetscInt nonzeros() const noexcept { return static_cast<PetscInt>(columns_.size()); }

 private:
  AijDirectAdd() = default;
  void check_structure(Mat A) const;

  PetscInt row_begin_ = 0;
  PetscInt diagonal_nonzeros_ = 0;
  PetscInt off_diagonal_nonzeros_ = 0;
  bool mpi_ = false;
  std::vector<PetscInt> offsets_;   // per owned row into columns_/positions_
  std::vector<PetscInt> columns_;   // sorted global columns of each owned row
  std::vector<PetscInt> positions_; // >= 0: index into the diagonal block's values; < 0: ~index off-diagonal
};

}  // namespace lmeform::detail
