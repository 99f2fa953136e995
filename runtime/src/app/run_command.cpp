#include "run_command.hpp"

#include <unistd.h>

#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <iostream>

#include <fmt/format.h>

#include "figures.hpp"
#include "lmeform/output.hpp"
#include "lmeform/petsc.hpp"
#include "lmeform/resource_usage.hpp"
#include "lmeform/scene.hpp"
#include "lmeform/stopwatch.hpp"
#include "problem_registry.hpp"

namespace lmeform::app {

namespace {

namespace fs = std::filesystem;
using problems::RunReport;

/// Refuses, before any work, an output that could not be written at the end.
void check_writable(const fs::path& json_path, const fs::path& out_dir, bool writes_files) {
  if (!json_path.empty()) {
    const fs::path dir = json_path.parent_path().empty() ? fs::path(".") : json_path.parent_path();
    if (fs::is_directory(json_path)) throw std::runtime_error(fmt::format("--json {}: is a directory", json_path.string()));
    if (!fs::is_directory(dir)) throw std::runtime_error(fmt::format("--json {}: the folder {} does not exist", json_path.string(), dir.string()));
    if (::access(dir.c_str(), W_OK) != 0)
      throw std::runtime_error(fmt::format("--json {}: the folder {} is not writable", json_path.string(), dir.string()));
  }
  if (writes_files) {
    std::error_code ec;
    fs::create_directories(out_dir, ec);
    if (ec || !fs::is_directory(out_dir) || ::access(out_dir.c_str(), W_OK) != 0)
      throw std::runtime_error(fmt::format("the output directory {} cannot be created or written{}", out_dir.string(),
                                           ec ? " (" + ec.message() + ")" : ""));
  }
}

/// The same check on every rank: rank 0 looks, all learn the verdict.
void check_writable_everywhere(const fs::path& json_path, const fs::path& out_dir, bool writes_files) {
  int ok = 1;
  std::string why;
  if (PetscSession::rank() == 0) {
    try {
      check_writable(json_path, out_dir, writes_files);
    } catch (const std::exception& e) {
      ok = 0;
      why = e.what();
    }
  }
  MPI_Bcast(&ok, 1, MPI_INT, 0, PETSC_COMM_WORLD);
  if (ok == 0) throw std::runtime_error(PetscSession::rank() == 0 ? why : "an output cannot be written");
}

/// NAME=VALUE of a --set option.
std::pair<std::string, double> parse_constant_setting(const std::string& text) {
  const auto eq = text.find('=');
  if (eq == std::string::npos || eq == 0) throw SceneError(fmt::format("--set {}: expected NAME=VALUE (e.g. --set C=0.5)", text));
  const std::string value = text.substr(eq + 1);
  char* end = nullptr;
  const double v = std::strtod(value.c_str(), &end);
  if (value.empty() || end == nullptr || *end != '\0') throw SceneError(fmt::format("--set {}: '{}' is not a number", text, value));
  return {text.substr(0, eq), v};
}

Scene load_with_settings(const RunOptions& options) {
  Scene scene = load_scene(options.scene, problems::driver_tables());
  for (const auto& setting : options.settings) {
    const auto [name, value] = parse_constant_setting(setting);
    scene.constants[name] = value;
    scene.constant_where[name] = "command line: --set " + setting;
  }
  return scene;
}

/// The final state as <out>/<scene>.h5 (+ .xmf) and, where the scene asks, a figure of it.
/// Collective: every rank holds the whole fields and writes its block of rows into the file.
void write_fields(const Scene& scene, const fs::path& out_dir, RunReport& report) {
  const problems::ReportFields& f = *report.fields;
  FieldViews views;
  for (const auto& field : f.fields) views.emplace(field.name, FieldView{field.values, field.components});
  OutputAttributes attributes = f.attributes;
  attributes.emplace("converged", static_cast<std::int64_t>(report.success ? 1 : 0));
  attributes.emplace("status", report.status);
  attributes.emplace("scene", scene.source);
  const fs::path h5 = out_dir / (scene.name + ".h5");
  const ReplicatedShare share(PETSC_COMM_WORLD, f.nodes.size(), views);
  write_field_hdf5(PETSC_COMM_WORLD, h5, f.nodes, f.cells, share.part(), attributes);
  report.files.emplace_back("fields", h5.string() + " (+ .xmf for ParaView)");
  const bool figure = scene.output && scene.output->png;
  if (!figure || PetscSession::rank() != 0) return;
  if (f.figure_field.empty() || scene.dim() != 2) {
    std::cerr << "lmeform: warning: no figure: [output] png draws the first unknown of a 2D scene when it is scalar\n";
    return;
  }
  const fs::path png = out_dir / (scene.name + ".png");
  const FigureResult drawn = plot_field(h5, png, f.figure_field, f.mirror);
  if (drawn.written) report.files.emplace_back("figure", png.string());
  else std::cerr << "lmeform: warning: " << drawn.warning << "\n";
}

void print_report(const Scene& scene, const RunReport& report, double total_s) {
  std::printf("\n%-26s %s\n", "scene", scene.source.c_str());
  std::printf("%-26s %s\n", "status", report.status.c_str());
  for (const auto& [label, value] : report.rows) std::printf("%-26s %s\n", label.c_str(), value.c_str());
  std::printf("%-26s %.1f s\n", "total wall time", total_s);
  for (const auto& [label, value] : report.files) std::printf("%-26s %s\n", label.c_str(), value.c_str());
  if (!report.table) return;
  std::vector<std::size_t> width;
  for (const auto& h : report.table->header) width.push_back(std::max<std::size_t>(h.size(), 8));
  for (const auto& row : report.table->rows)
    for (std::size_t i = 0; i < row.size() && i < width.size(); ++i) width[i] = std::max(width[i], row[i].size());
  std::printf("\n");
  for (std::size_t i = 0; i < width.size(); ++i) std::printf(i == 0 ? "%-*s" : " %*s", int(width[i]), report.table->header[i].c_str());
  std::printf("\n");
  for (const auto& row : report.table->rows) {
    for (std::size_t i = 0; i < row.size() && i < width.size(); ++i) std::printf(i == 0 ? "%-*s" : " %*s", int(width[i]), row[i].c_str());
    std::printf("\n");
  }
}

void write_json(const Scene& scene, const RunReport& report, double total_s, const fs::path& path) {
  nlohmann::json js = report.json;
  js["scene"] = scene.name;
  js["problem"] = report.problem;
  js["converged"] = report.success;
  js["status"] = report.status;
  js["wall_s"] = problems::json_number(total_s);
  if (!report.warnings.empty()) js["warnings"] = report.warnings;
  write_text_atomically(path, js.dump(2) + "\n");
}

}  // namespace

int run_command(const RunOptions& options) {
  const Stopwatch clock;
  const int rank = PetscSession::rank();
  const Scene scene = load_with_settings(options);
  const problems::ProblemDriver& driver = problems::driver_for(scene);
  problems::DriverContext ctx;
  ctx.comm = PETSC_COMM_WORLD;
  ctx.scene = &scene;
  ctx.log = rank == 0 ? &std::cout : nullptr;
  ctx.restart = options.restart;
  if (options.restart && !driver.restartable())
    throw SceneError(fmt::format("{}: --restart resumes a run that writes checkpoints; the {} problem of this scene has none", scene.source,
                                 driver.name()));
  if (options.check) {
    driver.check(ctx);
    if (rank == 0) std::printf("%s: the scene binds to its forms (problem: %s); nothing was solved\n", scene.source.c_str(), driver.name().data());
    return 0;
  }
  const fs::path out_dir = !options.output.empty() ? fs::path(options.output)
                           : scene.output          ? scene.output->directory
                                                   : fs::path("out") / scene.name;
  const bool writes_files = !scene.output || scene.output->hdf5;
  check_writable_everywhere(options.json, out_dir, writes_files);
  if (writes_files) ctx.output_directory = out_dir;

  RunReport report = driver.run(ctx);
  if (report.fields && writes_files) write_fields(scene, out_dir, report);
  int ranks = 1;
  MPI_Comm_size(PETSC_COMM_WORLD, &ranks);
  const double peak_mb = peak_resident_mb_per_rank(PETSC_COMM_WORLD);
  report.row("ranks, peak memory", fmt::format("{} rank{}, {:.0f} MiB resident at most per rank", ranks, ranks == 1 ? "" : "s", peak_mb));
  report.json["ranks"] = ranks;
  report.json["peak_rss_mb_per_rank"] = problems::json_number(peak_mb);
  if (rank == 0) {
    const double total_s = clock.seconds();
    print_report(scene, report, total_s);
    for (const auto& warning : report.warnings) std::cerr << "lmeform: warning: " << warning << "\n";
    if (!options.json.empty()) write_json(scene, report, total_s, options.json);
  }
  return report.success ? 0 : 2;
}

}  // namespace lmeform::app
