// Child processes of the runtime: lmeformc and the C++ compiler of a run-time compiled form, the
// plotting scripts of `lmeform plot`. No shell: arguments are passed as they are.
#pragma once

#include <filesystem>
#include <string>
#include <vector>

namespace lmeform {

struct ProcessResult {
  int exit_code = -1;  ///< 128 + the signal for a process killed by one
  std::string out, err;
};

/// Runs argv[0] (looked up on PATH) with its arguments and waits for it, capturing stdout and
/// stderr. Throws std::runtime_error only when the program cannot be started.
[[nodiscard]] ProcessResult run_process(const std::vector<std::string>& argv);

/// The folder of the running executable (empty when /proc/self/exe cannot be read).
[[nodiscard]] std::filesystem::path executable_directory();

}  // namespace lmeform
