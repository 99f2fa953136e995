// The phase-field vesicle's driver: a scene with a [vesicle] table runs the model's schedule of
// stages (run_vesicle) and reports the last stage with a table of all of them.
#include <fmt/format.h>

#include "membrane_topology.hpp"
#include "minimization.hpp"
#include "quantities.hpp"
#include "vesicle.hpp"
#include "vesicle_checkpoint.hpp"

namespace lmeform::problems {

namespace {

/// The stage table printed under the closing rows, and its JSON records.
void describe_stages(const VesicleRun& run, const VesicleModel& model, const std::optional<double>& reference, RunReport& report) {
  auto rel_error = [&](double e) { return reference ? (e - *reference) / *reference : std::nan(""); };
  ReportTable table;
  table.header = {"stage", "nodes", model.width, "h_min", "energy", "rel. error", "AL+KKT", "adapt s", "setup s", "AL s", "KKT s", "MiB", "membrane"};
  report.json["stages"] = nlohmann::json::array();
  std::vector<const StageRecord*> stages;
  for (const auto& s : run.stages) stages.push_back(&s);
  if (run.rejected) stages.push_back(&*run.rejected);
  const StageRecord* written = run.stages.empty() ? &*run.rejected : &run.stages.back();
  for (const StageRecord* stage : stages) {
    const StageRecord& s = *stage;
    const bool rejected = run.rejected && stage == &*run.rejected;
    const ConstrainedResult& m = s.result.minimization;
    // The written stage's saddle is warned of by describe_minimization; an earlier one here.
    if (m.negative_curvature_directions > 0 && stage != written && !rejected)
      report.warnings.push_back(fmt::format("stage {} ended on a saddle ({} direction{} of negative curvature along the constraints); "
                                            "the next stage started from it",
                                            s.stage, m.negative_curvature_directions, m.negative_curvature_directions == 1 ? "" : "s"));
    table.rows.push_back({std::to_string(s.stage) + " " + s.grid + s.label + (rejected ? " (rejected)" : ""), std::to_string(s.nodes), fmt::format("{:g}", s.eps),
                          fmt::format("{:.4g}", s.h_min), fmt::format("{:.5f}", s.result.energy),
                          reference ? fmt::format("{:+.3f}%", 100 * rel_error(s.result.energy)) : "-",
                          fmt::format("{}+{}", m.augmented_iterations, m.newton_iterations), fmt::format("{:.2f}", s.adapt_s),
                          fmt::format("{:.2f}", s.result.seconds_setup), fmt::format("{:.2f}", m.seconds_augmented),
                          fmt::format("{:.2f}", m.seconds_newton), fmt::format("{:.0f}", s.peak_rss_mb), s.topology ? s.topology->shapes() : "-"});
    report.json["stages"].push_back({{"stage", s.stage},
                                     {"grid", s.grid},
                                     {"branch", !s.label.empty()},
                                     {"rejected", rejected},
                                     {"topology", s.topology ? topology_json(*s.topology) : nlohmann::json()},
                                     {model.width, json_number(s.eps)},
                                     {"nodes", s.nodes},
                                     {"h_min", json_number(s.h_min)},
                                     {"energy", json_number(s.result.energy)},
                                     {"relative_error_sharp", json_number(rel_error(s.result.energy))},
                                     {"augmented_iterations", m.augmented_iterations},
                                     {"newton_iterations", m.newton_iterations},
                                     {"gradient_evaluations", m.gradient_evaluations},
                                     {"hessian_evaluations", m.hessian_evaluations},
                                     {"shifted_steps", m.corrected_steps},
                                     {"inertia_corrections", m.inertia_corrections},
                                     {"constraint_corrections", m.constraint_corrections},
                                     {"negative_curvature_directions", m.negative_curvature_directions},
                                     {"adapt_s", json_number(s.adapt_s)},
                                     {"setup_s", json_number(s.result.seconds_setup)},
                                     {"hessian_s", json_number(m.seconds_hessian)},
                                     {"factor_solve_s", json_number(m.seconds_factor)},
                                     {"wall_s", json_number(s.wall_s)},
                                     {"peak_rss_mb_per_rank", json_number(s.peak_rss_mb)}});
  }
  report.table = std::move(table);
}

/// The closing row and JSON keys of the membrane's topology: the written stage's against the start's.
void describe_topology(const VesicleRun& run, const StageRecord& written, RunReport& report) {
  report.warnings.insert(report.warnings.end(), run.warnings.begin(), run.warnings.end());
  report.json["topology_start"] = run.initial_topology ? topology_json(*run.initial_topology) : nlohmann::json();
  report.json["topology"] = written.topology ? topology_json(*written.topology) : nlohmann::json();
  if (!written.topology) {
    report.row("membrane (phi = 0)", "topology not evaluated");
    return;
  }
  std::string text = written.topology->describe();
  if (run.initial_topology)
    text += written.topology->same_as(*run.initial_topology) ? ", as at the start" : ", CHANGED from the start's " + run.initial_topology->describe();
  report.row("membrane (phi = 0)", text);
}

class VesicleDriver final : public ProblemDriver {
 public:
  [[nodiscard]] std::string_view name() const override { return "vesicle"; }
  [[nodiscard]] std::string_view table() const override { return kVesicleExtension; }
  [[nodiscard]] bool claims(const Scene& scene) const override { return scene.has_extension(kVesicleExtension); }
  [[nodiscard]] bool restartable() const override { return true; }

  void check(const DriverContext& ctx) const override {
    const VesicleModel model = *read_vesicle(*ctx.scene);
    const Scene completed = with_vesicle_targets(*ctx.scene, model);
    (void)bind_vesicle(completed, ctx.comm, ctx.log, model);
  }

  [[nodiscard]] RunReport run(const DriverContext& ctx) const override {
    const Scene& scene = *ctx.scene;
    const VesicleModel model = *read_vesicle(scene);
    const VesicleCheckpoint checkpoint{ctx.output_directory, scene.name, ctx.restart};
    const VesicleRun run = run_vesicle(ctx.comm, scene, model, ctx.log, ctx.output_directory.empty() ? nullptr : &checkpoint);
    // The guard may have rejected the first stage: then that one is written (the status says why).
    const StageRecord& last = run.stages.empty() ? *run.rejected : run.stages.back();
    const ProblemResult& r = last.result;
    RunReport report;
    report.problem = "minimization";
    report.success = run.failure.empty() && r.converged;
    report.status = !run.failure.empty() ? "FAILED: " + run.failure : r.converged ? std::string("converged") : "FAILED: " + r.message;
    report.fields = state_fields(run.layout, scene.axisymmetric(), r);
    report.fields->attributes.emplace(model.width, last.eps);
    // The area multiplier is the membrane tension, the volume multiplier the pressure difference.
    describe_minimization(scene.reference.energy, r, report, {{"area", "tension"}, {"volume", "pressure"}},
                          "[vesicle.initial]: an ellipsoid with slightly unequal semi-axes instead of a sphere");
    describe_errors(r, report);
    describe_quantities(r.quantities, report);
    report.row("nodes", fmt::format("{} (h_min {:.4g}, h_mean {:.4g})", last.nodes, r.h_min, r.h_mean));
    describe_basis(scene.nodes, report);
    report.row(model.width, fmt::format("{:g}", last.eps));
    const auto& reference = scene.reference.energy;
    report.json["nodes"] = last.nodes;
    report.json["h_min"] = json_number(r.h_min);
    report.json["setup_s"] = json_number(r.seconds_setup);
    report.json["solve_s"] = json_number(r.seconds_solve);
    report.json[model.width] = json_number(last.eps);
    report.json["grid"] = run.stages.size() > 1 ? "adapted" : "uniform";
    report.json["relative_error_sharp"] = json_number(reference ? (r.energy - *reference) / *reference : std::nan(""));
    describe_topology(run, last, report);
    describe_stages(run, model, reference, report);
    return report;
  }
};

}  // namespace

const ProblemDriver& vesicle_driver() {
  static const VesicleDriver driver;
  return driver;
}

}  // namespace lmeform::problems
