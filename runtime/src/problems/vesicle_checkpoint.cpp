#include "vesicle_checkpoint.hpp"

#include <cmath>
#include <fstream>
#include <limits>
#include <stdexcept>

#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include "lmeform/output.hpp"
#include "membrane_topology.hpp"
#include "report.hpp"

namespace lmeform::problems {

namespace fs = std::filesystem;

namespace {

constexpr int kFormat = 1;

fs::path schedule_path(const VesicleCheckpoint& c) { return c.directory / (c.scene_name + "_stages.json"); }
fs::path stage_path(const VesicleCheckpoint& c, int stage) { return c.directory / fmt::format("{}_stage_{}.h5", c.scene_name, stage); }

double number(const nlohmann::json& js, const char* key) {
  const auto& v = js.at(key);
  return v.is_null() ? std::numeric_limits<double>::quiet_NaN() : v.get<double>();
}

std::vector<double> numbers(const nlohmann::json& js, const char* key) {
  std::vector<double> out;
  for (const auto& v : js.at(key)) out.push_back(v.is_null() ? std::numeric_limits<double>::quiet_NaN() : v.get<double>());
  return out;
}

nlohmann::json json_numbers(const std::vector<double>& values) {
  nlohmann::json out = nlohmann::json::array();
  for (double v : values) out.push_back(json_number(v));
  return out;
}

/// Everything of a stage but its fields: what the closing table and a continuation need.
nlohmann::json stage_json(const StageRecord& s) {
  const ProblemResult& r = s.result;
  const ConstrainedResult& m = r.minimization;
  return {{"stage", s.stage},
          {"eps", json_number(s.eps)},
          {"grid", s.grid},
          {"generation", s.generation},
          {"label", s.label},
          {"nodes", s.nodes},
          {"h_min", json_number(s.h_min)},
          {"topology", s.topology ? topology_json(*s.topology) : nlohmann::json()},
          {"topology_s", json_number(s.topology_s)},
          {"wall_s", json_number(s.wall_s)},
          {"adapt_s", json_number(s.adapt_s)},
          {"peak_rss_mb", json_number(s.peak_rss_mb)},
          {"converged", r.converged},
          {"message", r.message},
          {"energy", json_number(r.energy)},
          {"result_h_min", json_number(r.h_min)},
          {"result_h_mean", json_number(r.h_mean)},
          {"seconds_setup", json_number(r.seconds_setup)},
          {"seconds_solve", json_number(r.seconds_solve)},
          {"constraint_names", r.constraint_names},
          {"minimization",
           {{"energy", json_number(m.energy)},
            {"objective", json_number(m.objective)},
            {"multipliers", json_numbers(m.multipliers)},
            {"constraint_values", json_numbers(m.constraint_values)},
            {"relative_residuals", json_numbers(m.relative_residuals)},
            {"augmented_iterations", m.augmented_iterations},
            {"outer_iterations", m.outer_iterations},
            {"newton_iterations", m.newton_iterations},
            {"gradient_evaluations", m.gradient_evaluations},
            {"hessian_evaluations", m.hessian_evaluations},
            {"inertia_corrections", m.inertia_corrections},
            {"corrected_steps", m.corrected_steps},
            {"constraint_corrections", m.constraint_corrections},
            {"negative_curvature_directions", m.negative_curvature_directions},
            {"seconds_hessian", json_number(m.seconds_hessian)},
            {"seconds_factor", json_number(m.seconds_factor)},
            {"seconds_augmented", json_number(m.seconds_augmented)},
            {"seconds_newton", json_number(m.seconds_newton)}}}};
}

StageRecord stage_from_json(const nlohmann::json& js, LevelSetGeometry geometry) {
  StageRecord s;
  s.stage = js.at("stage").get<int>();
  s.eps = number(js, "eps");
  s.grid = js.at("grid").get<std::string>();
  s.generation = js.at("generation").get<int>();
  s.label = js.at("label").get<std::string>();
  s.nodes = js.at("nodes").get<int>();
  s.h_min = number(js, "h_min");
  if (!js.at("topology").is_null()) s.topology = topology_from_json(js["topology"], geometry);
  s.topology_s = number(js, "topology_s");
  s.wall_s = number(js, "wall_s");
  s.adapt_s = number(js, "adapt_s");
  s.peak_rss_mb = number(js, "peak_rss_mb");
  ProblemResult& r = s.result;
  r.converged = js.at("converged").get<bool>();
  r.message = js.at("message").get<std::string>();
  r.energy = number(js, "energy");
  r.h_min = number(js, "result_h_min");
  r.h_mean = number(js, "result_h_mean");
  r.seconds_setup = number(js, "seconds_setup");
  r.seconds_solve = number(js, "seconds_solve");
  r.constraint_names = js.at("constraint_names").get<std::vector<std::string>>();
  const auto& mj = js.at("minimization");
  ConstrainedResult& m = r.minimization;
  m.energy = number(mj, "energy");
  m.objective = number(mj, "objective");
  m.multipliers = numbers(mj, "multipliers");
  m.constraint_values = numbers(mj, "constraint_values");
  m.relative_residuals = numbers(mj, "relative_residuals");
  m.augmented_iterations = mj.at("augmented_iterations").get<int>();
  m.outer_iterations = mj.at("outer_iterations").get<int>();
  m.newton_iterations = mj.at("newton_iterations").get<int>();
  m.gradient_evaluations = mj.at("gradient_evaluations").get<int>();
  m.hessian_evaluations = mj.at("hessian_evaluations").get<int>();
  m.inertia_corrections = mj.at("inertia_corrections").get<int>();
  m.corrected_steps = mj.at("corrected_steps").get<int>();
  m.constraint_corrections = mj.at("constraint_corrections").get<int>();
  m.negative_curvature_directions = mj.at("negative_curvature_directions").get<int>();
  m.seconds_hessian = number(mj, "seconds_hessian");
  m.seconds_factor = number(mj, "seconds_factor");
  m.seconds_augmented = number(mj, "seconds_augmented");
  m.seconds_newton = number(mj, "seconds_newton");
  return s;
}

/// The fields a later stage continues from: nodes, cells, the state and |∇φ| (a CVT's density).
void read_stage_fields(MPI_Comm comm, const VesicleCheckpoint& checkpoint, StageRecord& s) {
  const fs::path path = stage_path(checkpoint, s.stage);
  if (!fs::exists(path)) throw std::runtime_error(fmt::format("--restart: {} names stage {}, whose file {} is missing",
                                                              schedule_path(checkpoint).string(), s.stage, path.string()));
  FieldFile file = read_field_hdf5(path, comm);
  if (file.nodes.size() != static_cast<std::size_t>(s.nodes) || !file.fields.contains("state"))
    throw std::runtime_error(fmt::format("--restart: {} does not hold the {} nodes and the state of stage {}", path.string(), s.nodes, s.stage));
  s.result.nodes = std::move(file.nodes);
  s.result.cells = std::move(file.cells);
  s.result.state = std::move(file.fields.at("state").values);
  if (const auto g = file.fields.find("gradient_norm"); g != file.fields.end()) s.result.gradient_norm = std::move(g->second.values);
}

}  // namespace

void write_vesicle_checkpoint(MPI_Comm comm, const VesicleCheckpoint& checkpoint, const VesicleRun& run, std::size_t main_stage) {
  if (checkpoint.directory.empty() || run.stages.empty()) return;
  const StageRecord& last = run.stages.back();
  const ProblemResult& r = last.result;
  FieldViews fields{{"state", FieldView{r.state, 1}}};
  if (r.gradient_norm.size() == r.nodes.size()) fields.emplace("gradient_norm", FieldView{r.gradient_norm, 1});
  const ReplicatedShare share(comm, r.nodes.size(), fields);
  write_field_hdf5(comm, stage_path(checkpoint, last.stage), r.nodes, r.cells, share.part(),
                   {{"stage", static_cast<std::int64_t>(last.stage)}, {"eps", last.eps}, {"energy", r.energy}});
  int rank = 0;
  MPI_Comm_rank(comm, &rank);
  std::string failure;
  if (rank == 0) {
    nlohmann::json js{{"format", kFormat},
                      {"scene", checkpoint.scene_name},
                      {"main_stage", main_stage},
                      {"topology_start", run.initial_topology ? topology_json(*run.initial_topology) : nlohmann::json()},
                      {"warnings", run.warnings},
                      {"stages", nlohmann::json::array()}};
    for (const StageRecord& s : run.stages) js["stages"].push_back(stage_json(s));
    try {
      write_text_atomically(schedule_path(checkpoint), js.dump(1) + "\n");
    } catch (const std::exception& e) {
      failure = e.what();
    }
  }
  // Every rank learns whether rank 0 wrote the schedule file, so that all throw or none.
  int failed = failure.empty() ? 0 : 1;
  MPI_Bcast(&failed, 1, MPI_INT, 0, comm);
  if (failed != 0) throw std::runtime_error(failure.empty() ? fmt::format("{} could not be written", schedule_path(checkpoint).string()) : failure);
}

ResumedSchedule read_vesicle_checkpoint(MPI_Comm comm, const VesicleCheckpoint& checkpoint, const VesicleModel& model, LevelSetGeometry geometry) {
  const fs::path path = schedule_path(checkpoint);
  if (!fs::exists(path))
    throw std::runtime_error(fmt::format("--restart: no checkpoint in {} (expected {}, written after each converged stage)",
                                         checkpoint.directory.string(), path.filename().string()));
  nlohmann::json js;
  try {
    std::ifstream in(path);
    js = nlohmann::json::parse(in);
  } catch (const std::exception& e) {
    throw std::runtime_error(fmt::format("--restart: {} cannot be read: {}", path.string(), e.what()));
  }
  if (js.value("format", 0) != kFormat || js.value("scene", std::string()) != checkpoint.scene_name)
    throw std::runtime_error(fmt::format("--restart: {} is no schedule checkpoint of scene '{}'", path.string(), checkpoint.scene_name));
  ResumedSchedule resumed;
  try {
    for (const auto& s : js.at("stages")) resumed.run.stages.push_back(stage_from_json(s, geometry));
    resumed.main_stage = js.at("main_stage").get<std::size_t>();
    if (!js.at("topology_start").is_null()) resumed.run.initial_topology = topology_from_json(js["topology_start"], geometry);
    // What was warned of before the stop belongs to the run's report too.
    resumed.run.warnings = js.value("warnings", std::vector<std::string>{});
  } catch (const nlohmann::json::exception& e) {
    throw std::runtime_error(fmt::format("--restart: {} is malformed: {}", path.string(), e.what()));
  }
  auto& stages = resumed.run.stages;
  const std::size_t scheduled = 1 + (model.adaptivity ? model.adaptivity->stages.size() : 0);
  if (stages.empty() || resumed.main_stage >= stages.size())
    throw std::runtime_error(fmt::format("--restart: {} holds no finished stage", path.string()));
  if (stages.size() >= scheduled)
    throw std::runtime_error(fmt::format("--restart: all {} stages of the schedule are in {}: nothing to resume", scheduled, path.string()));
  // The stages must be the scene's: a schedule edited since would continue from another state.
  for (std::size_t k = 0; k < stages.size(); ++k) {
    const double eps = k == 0 ? model.eps : model.adaptivity->stages[k - 1].eps;
    if (stages[k].stage != static_cast<int>(k) || stages[k].eps != eps)
      throw std::runtime_error(fmt::format("--restart: stage {} of {} has eps = {}, the scene's schedule {}: the checkpoint belongs to "
                                           "another schedule",
                                           k, path.string(), stages[k].eps, eps));
  }
  read_stage_fields(comm, checkpoint, stages[resumed.main_stage]);
  if (resumed.main_stage + 1 != stages.size()) read_stage_fields(comm, checkpoint, stages.back());
  return resumed;
}

}  // namespace lmeform::problems
