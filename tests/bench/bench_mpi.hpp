// Rank-0 printing and reductions shared by the MPI benchmarks (bench_assembly, bench_storage).
#pragma once

#include <mpi.h>

#include <cstdio>

#include "lmeform/petsc.hpp"

namespace lmeform::bench {

inline bool rank0() { return PetscSession::rank() == 0; }

/// printf on rank 0, flushed (progress lines of long runs).
template <class... Args>
void say(const char* format, Args... args) {
  if (rank0()) {
    std::printf(format, args...);
    std::fflush(stdout);
  }
}

inline double max_over_ranks(double v) {
  double m = 0;
  MPI_Allreduce(&v, &m, 1, MPI_DOUBLE, MPI_MAX, PETSC_COMM_WORLD);
  return m;
}

inline long long sum_over_ranks(long long v) {
  long long s = 0;
  MPI_Allreduce(&v, &s, 1, MPI_LONG_LONG, MPI_SUM, PETSC_COMM_WORLD);
  return s;
}

}  // namespace lmeform::bench
