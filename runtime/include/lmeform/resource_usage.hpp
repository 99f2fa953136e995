// The memory a run has taken: the peak resident set of this process and the largest over ranks,
// the figure per rank that the run tables and scaling records report; and the memory still free.
#pragma once

#include <mpi.h>
#include <sys/resource.h>

#include <cstdint>
#include <fstream>
#include <string>

namespace lmeform {

/// The peak resident set of this process so far, in MiB (getrusage; Linux gives kilobytes).
[[nodiscard]] inline double peak_resident_mb() noexcept {
  rusage usage{};
  getrusage(RUSAGE_SELF, &usage);
  return static_cast<double>(usage.ru_maxrss) / 1024.0;
}

/// The largest peak resident set of any rank of comm, in MiB. Collective.
[[nodiscard]] inline double peak_resident_mb_per_rank(MPI_Comm comm) {
  double mb = peak_resident_mb();
  MPI_Allreduce(MPI_IN_PLACE, &mb, 1, MPI_DOUBLE, MPI_MAX, comm);
  return mb;
}

/// The memory this machine can still give to processes, in bytes (MemAvailable of /proc/meminfo:
/// free memory plus the caches it could drop); 0 when it cannot be read.
[[nodiscard]] inline std::uint64_t available_memory_bytes() {
  std::ifstream meminfo("/proc/meminfo");
  std::string key;
  std::uint64_t kilobytes = 0;
  std::string unit;
  while (meminfo >> key >> kilobytes >> unit)
    if (key == "MemAvailable:") return kilobytes * 1024;
  return 0;
}

}  // namespace lmeform
