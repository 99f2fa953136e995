// RAII wrappers around the PETSc objects lmeform uses, and PETSc errors as exceptions.
//
// PETSc reports errors by return code; every call goes through LMEFORM_PETSC_CHECK, which turns
// a non-zero code into lmeform::PetscError carrying the call's text, file and line and PETSc's
// own message. Handles own their object (move-only) and destroy it once.
#pragma once

#include <petscksp.h>
#include <petscsnes.h>
#include <petscmat.h>
#include <petscvec.h>

#include <stdexcept>
#include <string>
#include <utility>

namespace lmeform {

class PetscError : public std::runtime_error {
 public:
  PetscError(PetscErrorCode code, const char* call, const char* file, int line);
  [[nodiscard]] PetscErrorCode code() const noexcept { return code_; }

 private:
  PetscErrorCode code_;
};

inline void petsc_check(PetscErrorCode code, const char* call, const char* file, int line) {
  if (code != 0) throw PetscError(code, call, file, line);
}

#define LMEFORM_PETSC_CHECK(call) ::lmeform::petsc_check((call), #call, __FILE__, __LINE__)

/// Initializes PETSc (and MPI, if needed) for the lifetime of the object. One per program.
class PetscSession {
 public:
  PetscSession(int* argc, char*** argv, const char* help = nullptr);
  ~PetscSession();
  PetscSession(const PetscSession&) = delete;
  PetscSession& operator=(const PetscSession&) = delete;

  [[nodiscard]] static int rank(MPI_Comm comm = PETSC_COMM_WORLD);
  [[nodiscard]] static int size(MPI_Comm comm = PETSC_COMM_WORLD);
};

/// Owning handle for a PETSc object type T destroyed by Destroy(T*).
template <class T, PetscErrorCode (*Destroy)(T*)>
class PetscHandle {
 public:
  PetscHandle() = default;
  explicit PetscHandle(T object) noexcept : object_(object) {}
  PetscHandle(const PetscHandle&) = delete;
  PetscHandle& operator=(const PetscHandle&) = delete;
  PetscHandle(PetscHandle&& other) noexcept : object_(std::exchange(other.object_, nullptr)) {}
  PetscHandle& operator=(PetscHandle&& other) noexcept {
    if (this != &other) {
      reset();
      object_ = std::exchange(other.object_, nullptr);
    }
    return *this;
  }
  ~PetscHandle() { reset(); }

  void reset() noexcept {
    if (object_ != nullptr) {
      // Destroy errors cannot be reported from a destructor; PETSc prints its own trace.
      (void)Destroy(&object_);
      object_ = nullptr;
    }
  }
  [[nodiscard]] T get() const noexcept { return object_; }
  [[nodiscard]] T* out() noexcept {  // for PETSc's XxxCreate(&obj)
    reset();
    return &object_;
  }
  operator T() const noexcept { return object_; }  // NOLINT: PETSc calls take the raw handle
  explicit operator bool() const noexcept { return object_ != nullptr; }

 private:
  T object_ = nullptr;
};

using PetscMatrix = PetscHandle<Mat, MatDestroy>;
using PetscVector = PetscHandle<Vec, VecDestroy>;
using PetscLinearSolver = PetscHandle<KSP, KSPDestroy>;
using PetscNonlinearSolver = PetscHandle<SNES, SNESDestroy>;
using PetscIndexSet = PetscHandle<IS, ISDestroy>;
using PetscScatter = PetscHandle<VecScatter, VecScatterDestroy>;

/// Read access to a Vec's local array for the scope of the object.
class VecReadView {
 public:
  explicit VecReadView(Vec v);
  ~VecReadView();
  VecReadView(const VecReadView&) = delete;
  VecReadView& operator=(const VecReadView&) = delete;
  [[nodiscard]] const PetscScalar* data() const noexcept { return data_; }
  [[nodiscard]] PetscInt size() const noexcept { return size_; }
  const PetscScalar& operator[](PetscInt i) const noexcept { return data_[i]; }

 private:
  Vec vec_;
  const PetscScalar* data_ = nullptr;
  PetscInt size_ = 0;
};

/// Write access to a Vec's local array for the scope of the object.
class VecWriteView {
 public:
  explicit VecWriteView(Vec v);
  ~VecWriteView();
  VecWriteView(const VecWriteView&) = delete;
  VecWriteView& operator=(const VecWriteView&) = delete;
  [[nodiscard]] PetscScalar* data() const noexcept { return data_; }
  [[nodiscard]] PetscInt size() const noexcept { return size_; }
  PetscScalar& operator[](PetscInt i) const noexcept { return data_[i]; }

 private:
  Vec vec_;
  PetscScalar* data_ = nullptr;
  PetscInt size_ = 0;
};

}  // namespace lmeform
