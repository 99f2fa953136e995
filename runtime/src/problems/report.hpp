// What a run reports, whatever drove it: a status, the rows of the closing table, an optional
// table of stages or steps, the keys of the --json document, and the fields of the final state.
// `lmeform run` prints and writes a report without knowing the driver that made it.
#pragma once

#include <optional>
#include <string>
#include <utility>
#include <vector>

#include <nlohmann/json.hpp>

#include "lmeform/delaunay.hpp"
#include "lmeform/node_set.hpp"
#include "lmeform/output.hpp"

namespace lmeform::problems {

/// A JSON number, or null for NaN and infinities (JSON has neither).
[[nodiscard]] nlohmann::json json_number(double v);

/// A table printed under the closing rows (a schedule's stages).
struct ReportTable {
  std::vector<std::string> header;
  std::vector<std::vector<std::string>> rows;
};

/// A nodal field of the final state.
struct ReportField {
  std::string name;
  int components = 1;
  std::vector<double> values;  ///< node-major, components interleaved
};

/// The final state, written as <output>/<scene>.h5 with its .xmf sidecar.
struct ReportFields {
  NodeSet nodes;
  BackgroundCells cells;
  std::vector<ReportField> fields;
  OutputAttributes attributes;
  /// The scalar field a figure of the state shows ("": no figure); `mirror` reflects an
  /// axisymmetric field across the axis.
  std::string figure_field;
  bool mirror = false;
};

struct RunReport {
  std::string problem;                 ///< the problem solved ("minimization", "dynamics", ...)
  bool success = false;                ///< the exit status: converged / reached its end
  std::string status;                  ///< "converged", "FAILED: ...", "reached t_end", ...
  std::vector<std::pair<std::string, std::string>> rows;  ///< the closing table, label and value
  std::optional<ReportTable> table;
  nlohmann::json json = nlohmann::json::object();  ///< the --json document's keys
  std::optional<ReportFields> fields;  ///< written by the command, not by the driver
  std::vector<std::pair<std::string, std::string>> files;  ///< written by the driver: label, path
  std::vector<std::string> warnings;   ///< what the user must know although the run went on (stderr, JSON "warnings")

  void row(std::string label, std::string value) { rows.emplace_back(std::move(label), std::move(value)); }
};

}  // namespace lmeform::problems
