#include "step_history.hpp"

#include <algorithm>
#include <cmath>
#include <fstream>
#include <sstream>
#include <stdexcept>

#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include "report.hpp"

namespace lmeform::problems {

namespace fs = std::filesystem;

long StepRow::count(std::string_view name) const {
  for (const auto& [n, v] : counts)
    if (n == name) return v;
  return 0;
}

void write_step_history(const fs::path& directory, const std::string& scene, const StepHistoryFormat& format, const std::vector<StepRow>& rows) {
  if (rows.empty()) return;
  std::ostringstream csv;
  nlohmann::ordered_json js;
  js["scene"] = scene;
  js["steps"] = nlohmann::ordered_json::array();
  // The columns are every name any row has, in order of appearance: rows may differ (a step 0
  // without a solve has no solver figures; a restarted run may record a column its first part did not).
  std::vector<std::string> constant_columns, quantity_columns;
  const auto add_columns = [](std::vector<std::string>& columns, const std::vector<std::pair<std::string, double>>& values) {
    for (const auto& [name, v] : values)
      if (std::find(columns.begin(), columns.end(), name) == columns.end()) columns.push_back(name);
  };
  for (const StepRow& s : rows) add_columns(constant_columns, s.constants), add_columns(quantity_columns, s.quantities);
  const auto csv_cells = [&csv](const std::vector<std::string>& columns, const std::vector<std::pair<std::string, double>>& values) {
    for (const std::string& column : columns) {
      csv << ",";
      const auto it = std::find_if(values.begin(), values.end(), [&](const auto& nv) { return nv.first == column; });
      if (it != values.end()) csv << fmt::format("{:.17g}", it->second);
    }
  };
  csv << "step," << format.position;
  for (const std::string& name : constant_columns) csv << "," << name;
  for (const std::string& name : quantity_columns) csv << "," << name;
  for (const std::string& name : format.counts) csv << "," << name;
  csv << ",wall_s\n";
  for (const StepRow& s : rows) {
    csv << s.step << "," << fmt::format("{:.17g}", s.position);
    nlohmann::ordered_json row{{"step", s.step}, {format.position, s.position}};
    for (const std::string& name : format.counts) row[name] = s.count(name);
    row["wall_s"] = s.wall_s;
    for (const auto& [name, v] : s.constants) row["constants"][name] = json_number(v);
    for (const auto& [name, v] : s.quantities) row["quantities"][name] = json_number(v);
    csv_cells(constant_columns, s.constants);
    csv_cells(quantity_columns, s.quantities);
    for (const std::string& name : format.counts) csv << "," << s.count(name);
    csv << "," << fmt::format("{:.3f}", s.wall_s) << "\n";
    js["steps"].push_back(row);
  }
  write_text_atomically(directory / "history.csv", csv.str());
  write_text_atomically(directory / "history.json", js.dump(1) + "\n");
}

std::vector<StepRow> read_step_history(const fs::path& directory, const StepHistoryFormat& format, int last_step) {
  const fs::path path = directory / "history.json";
  std::ifstream in(path);
  if (!in) throw std::runtime_error(fmt::format("cannot read {}", path.string()));
  std::vector<StepRow> rows;
  try {
    const nlohmann::ordered_json js = nlohmann::ordered_json::parse(in);
    for (const auto& row : js.at("steps")) {
      if (row.at("step").get<int>() > last_step) break;
      StepRow s;
      s.step = row.at("step");
      s.position = row.at(format.position);
      for (const std::string& name : format.counts) s.counts.emplace_back(name, row.at(name).get<long>());
      s.wall_s = row.at("wall_s");
      // Named copies: items() views its object.
      const nlohmann::ordered_json constants = row.value("constants", nlohmann::ordered_json::object());
      const nlohmann::ordered_json quantities = row.value("quantities", nlohmann::ordered_json::object());
      for (const auto& [name, v] : constants.items()) s.constants.emplace_back(name, v.is_null() ? NAN : v.get<double>());
      for (const auto& [name, v] : quantities.items()) s.quantities.emplace_back(name, v.is_null() ? NAN : v.get<double>());
      rows.push_back(std::move(s));
    }
  } catch (const nlohmann::json::exception& e) {
    throw std::runtime_error(fmt::format("{}: not a step history: {}", path.string(), e.what()));
  }
  return rows;
}

std::vector<TimeSeriesStep> restored_series(MPI_Comm comm, const TimeSeriesWriter& series, const fs::path& directory,
                                            const std::vector<StepRow>& rows, const StateLayout& layout, int dim) {
  std::vector<TimeSeriesStep> out;
  for (const StepRow& s : rows) {
    // Only its sizes are needed: the nodes and cells are read, not the fields.
    const FieldFile written =
        read_field_hdf5(directory / series.file_of(s.step), comm, {.cells = true, .fields = std::vector<std::string>{}, .attributes = false});
    TimeSeriesStep entry{s.position, series.file_of(s.step), dim, written.nodes.size(), written.cells.size(), {}};
    for (const auto& f : layout.fields) entry.fields.emplace_back(f.name, f.components);
    std::sort(entry.fields.begin(), entry.fields.end());
    out.push_back(std::move(entry));
  }
  return out;
}

void report_step_history(const StepHistoryFormat& format, const std::vector<StepRow>& rows, const fs::path& output_directory,
                         const std::string& scene, RunReport& report) {
  report.json["steps"] = nlohmann::json::array();
  for (const StepRow& s : rows) {
    nlohmann::json row{{"step", s.step}, {format.position, s.position}};
    for (const std::string& name : format.counts) row[name] = s.count(name);
    for (const auto& [name, v] : s.quantities) row["quantities"][name] = json_number(v);
    report.json["steps"].push_back(row);
  }
  if (output_directory.empty()) return;
  report.files.emplace_back("history", (output_directory / "history.csv").string() + " (+ history.json)");
  report.files.emplace_back("series", (output_directory / (scene + ".xmf")).string() + " (ParaView)");
}

}  // namespace lmeform::problems
