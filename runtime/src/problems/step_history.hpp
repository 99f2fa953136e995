// The history of a stepped run (load steps, flow steps): one row per converged step, written as
// <output>/history.csv and history.json after every step (atomically), read back by --restart,
// and the time-series entries of the steps a restart keeps.
#pragma once

#include <mpi.h>

#include <filesystem>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include "lmeform/output.hpp"
#include "report.hpp"
#include "toolkit.hpp"

namespace lmeform::problems {

/// One converged step: its position (a load, a time), the stepped constants, the quantities, the
/// solver's counts (iterations, cut increments, sub-steps) and the wall clock since the run began.
struct StepRow {
  int step = 0;
  double position = 0;
  std::vector<std::pair<std::string, double>> constants;
  std::vector<std::pair<std::string, double>> quantities;
  std::vector<std::pair<std::string, long>> counts;
  double wall_s = 0;

  /// The count of that name (0 when the row has none).
  [[nodiscard]] long count(std::string_view name) const;
};

/// The columns of a history: the position's name ("load", "time") and the counts, in order.
struct StepHistoryFormat {
  std::string position;
  std::vector<std::string> counts;
};

/// Writes <directory>/history.csv (step, position, constants, quantities, counts, wall_s) and
/// history.json ({"scene", "steps": [{step, position, counts..., wall_s, constants, quantities}]}).
void write_step_history(const std::filesystem::path& directory, const std::string& scene, const StepHistoryFormat& format,
                        const std::vector<StepRow>& rows);

/// The rows of <directory>/history.json up to `last_step`. Throws std::runtime_error naming the file.
[[nodiscard]] std::vector<StepRow> read_step_history(const std::filesystem::path& directory, const StepHistoryFormat& format, int last_step);

/// The time-series entries of restored rows: each step's file as `series` names it, its node and cell
/// counts read from it (a node set may change between steps; collective over comm), the fields of `layout`.
[[nodiscard]] std::vector<TimeSeriesStep> restored_series(MPI_Comm comm, const TimeSeriesWriter& series, const std::filesystem::path& directory,
                                                          const std::vector<StepRow>& rows, const StateLayout& layout, int dim);

/// The run report's JSON "steps" (step, position, counts, quantities per row) and, with an output
/// folder, its history and series files in the closing table.
void report_step_history(const StepHistoryFormat& format, const std::vector<StepRow>& rows, const std::filesystem::path& output_directory,
                         const std::string& scene, RunReport& report);

}  // namespace lmeform::problems
