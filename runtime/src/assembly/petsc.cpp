#include "lmeform/petsc.hpp"

#include <sstream>

namespace lmeform {

namespace {
std::string describe(PetscErrorCode code, const char* call, const char* file, int line) {
  const char* text = nullptr;
  PetscErrorMessage(code, &text, nullptr);
  std::ostringstream os;
  os << "PETSc error " << code << " (" << (text != nullptr ? text : "unknown") << ") in " << call << " at "
     << file << ":" << line;
  return os.str();
}
}  // namespace

PetscError::PetscError(PetscErrorCode code, const char* call, const char* file, int line)
    : std::runtime_error(describe(code, call, file, line)), code_(code) {}

PetscSession::PetscSession(int* argc, char*** argv, const char* help) {
  LMEFORM_PETSC_CHECK(PetscInitialize(argc, argv, nullptr, help));
  // Errors come back as codes that LMEFORM_PETSC_CHECK turns into exceptions; PETSc's default
  // handler would also print a traceback for every error a test provokes on purpose.
  LMEFORM_PETSC_CHECK(PetscPushErrorHandler(PetscReturnErrorHandler, nullptr));
}

PetscSession::~PetscSession() {
  PetscPopErrorHandler();
  PetscFinalize();
}

int PetscSession::rank(MPI_Comm comm) {
  int r = 0;
  MPI_Comm_rank(comm, &r);
  return r;
}

int PetscSession::size(MPI_Comm comm) {
  int s = 1;
  MPI_Comm_size(comm, &s);
  return s;
}

VecReadView::VecReadView(Vec v) : vec_(v) {
  LMEFORM_PETSC_CHECK(VecGetArrayRead(vec_, &data_));
  LMEFORM_PETSC_CHECK(VecGetLocalSize(vec_, &size_));
}
VecReadView::~VecReadView() { VecRestoreArrayRead(vec_, &data_); }

VecWriteView::VecWriteView(Vec v) : vec_(v) {
  LMEFORM_PETSC_CHECK(VecGetArray(vec_, &data_));
  LMEFORM_PETSC_CHECK(VecGetLocalSize(vec_, &size_));
}
VecWriteView::~VecWriteView() { VecRestoreArray(vec_, &data_); }

}  // namespace lmeform
