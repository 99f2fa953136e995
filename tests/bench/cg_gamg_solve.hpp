// CG preconditioned by GAMG (overridable with -ksp_type / -pc_type) for the symmetric positive
// definite systems of the heat benchmarks (bench_assembly, bench_scaling).
#pragma once

#include <petscksp.h>

#include <string>

#include "bench_common.hpp"
#include "bench_mpi.hpp"
#include "lmeform/petsc.hpp"

namespace lmeform::bench {

struct KrylovSolve {
  double seconds = 0;  ///< the slowest rank's wall time of KSPSolve (setup of the preconditioner included)
  int iterations = 0;
  KSPConvergedReason reason{};
  std::string solver;  ///< "cg+gamg" or what the options chose
};

inline KrylovSolve solve_cg_gamg(MPI_Comm comm, Mat A, Vec b, Vec x, double rtol, int max_iterations) {
  KrylovSolve out;
  Stopwatch clock;
  PetscLinearSolver ksp;
  LMEFORM_PETSC_CHECK(KSPCreate(comm, ksp.out()));
  LMEFORM_PETSC_CHECK(KSPSetOperators(ksp, A, A));
  LMEFORM_PETSC_CHECK(KSPSetType(ksp, KSPCG));
  PC pc = nullptr;
  LMEFORM_PETSC_CHECK(KSPGetPC(ksp, &pc));
  LMEFORM_PETSC_CHECK(PCSetType(pc, PCGAMG));
  LMEFORM_PETSC_CHECK(KSPSetTolerances(ksp, rtol, PETSC_DEFAULT, PETSC_DEFAULT, max_iterations));
  LMEFORM_PETSC_CHECK(KSPSetFromOptions(ksp));
  LMEFORM_PETSC_CHECK(KSPSolve(ksp, b, x));
  out.seconds = max_over_ranks(clock.seconds());
  LMEFORM_PETSC_CHECK(KSPGetConvergedReason(ksp, &out.reason));
  PetscInt its = 0;
  LMEFORM_PETSC_CHECK(KSPGetIterationNumber(ksp, &its));
  out.iterations = static_cast<int>(its);
  KSPType kt = nullptr;
  PCType pt = nullptr;
  LMEFORM_PETSC_CHECK(KSPGetType(ksp, &kt));
  LMEFORM_PETSC_CHECK(PCGetType(pc, &pt));
  out.solver = std::string(kt) + "+" + pt;
  return out;
}

}  // namespace lmeform::bench
