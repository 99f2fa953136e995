// GoogleTest main that brackets the tests with PETSc (and MPI) initialisation.
#include <gtest/gtest.h>

#include "lmeform/petsc.hpp"

int main(int argc, char** argv) {
  ::testing::InitGoogleTest(&argc, argv);
  lmeform::PetscSession session(&argc, &argv);
  if (lmeform::PetscSession::rank() != 0) {
    // Only rank 0 reports; every rank still runs and asserts.
    auto& listeners = ::testing::UnitTest::GetInstance()->listeners();
    delete listeners.Release(listeners.default_result_printer());
  }
  return RUN_ALL_TESTS();
}
