// The driver of scenes with a [dynamics] table: the time integration (run_dynamics) with its time
// series and checkpoints in the output directory, reported as the energy's path, the constraints'
// drift, the steps and their times.
#include <algorithm>
#include <cmath>
#include <limits>

#include <fmt/format.h>

#include "dynamics.hpp"
#include "dynamics_integrator.hpp"
#include "membrane_topology.hpp"

namespace lmeform::problems {

namespace {

/// The smallest and largest Δt* taken, and each constraint's largest relative drift from the start.
struct StepSummary {
  double dt_lo = std::numeric_limits<double>::infinity(), dt_hi = 0;
  std::vector<double> max_drift;
};

StepSummary summarize(const DynamicsRun& run) {
  StepSummary s;
  s.max_drift.assign(run.constraint_names.size(), 0.0);
  const auto& first = run.history.front();
  for (std::size_t k = 1; k < run.history.size(); ++k) {
    s.dt_lo = std::min(s.dt_lo, run.history[k].dt_star);
    s.dt_hi = std::max(s.dt_hi, run.history[k].dt_star);
    for (std::size_t i = 0; i < s.max_drift.size(); ++i)
      s.max_drift[i] = std::max(s.max_drift[i], std::abs(run.history[k].constraints[i] - first.constraints[i]) /
                                                    std::max(std::abs(first.constraints[i]), 1e-300));
  }
  return s;
}

void describe_run(const Scene& scene, const DynamicsSettings& settings, const DynamicsRun& run, RunReport& report) {
  const auto& first = run.history.front();
  const auto& last = run.history.back();
  const StepSummary s = summarize(run);
  const bool vti = settings.method == DynamicsSettings::Method::vti;
  report.row("method", vti ? "variational (VTI)" : "forward Euler");
  report.row("t*", fmt::format("{:.6e} -> {:.6e}", first.t_star, last.t_star));
  report.row("energy", fmt::format("{:.8f} -> {:.8f}", first.energy, last.energy));
  if (const auto& ref = scene.reference.energy)
    report.row("reference energy", fmt::format("{:.6f} (final relative difference {:+.3f} %)", *ref, 100 * (last.energy - *ref) / *ref));
  for (std::size_t i = 0; i < s.max_drift.size(); ++i)
    report.row("max drift of " + run.constraint_names[i],
               fmt::format("{:.3e} (final multiplier {:.6g})", s.max_drift[i], last.multipliers.empty() ? 0.0 : last.multipliers[i]));
  report.row("steps", fmt::format("{} accepted, {} rejected", run.accepted, run.rejected));
  if (run.resets > 0) {
    double worst = 0;
    for (const auto& c : run.reset_changes) {
      worst = std::max(worst, std::abs(c.energy));
      for (const double v : c.constraints) worst = std::max(worst, std::abs(v));
    }
    report.row("resets", fmt::format("{} (largest relative change of E, area, volume by a reset {:.1e})", run.resets, worst));
  }
  if (run.history.size() > 1) report.row("dt*", fmt::format("{:.3e} .. {:.3e} (ratio {:.0f})", s.dt_lo, s.dt_hi, s.dt_hi / s.dt_lo));
  report.row("evaluations", fmt::format("{} gradient, {} Hessian", run.gradient_evaluations, run.hessian_evaluations));
  report.row("times (s)", fmt::format("setup {:.2f}, dissipation K {:.2f}, Hessian of E {:.2f}, factor+solve {:.2f}, resets {:.2f}",
                                      run.seconds_setup, run.seconds_dissipation, run.seconds_hessian, run.seconds_solve, run.seconds_reset));
  report.json["method"] = vti ? "vti" : "forward_euler";
  report.json["energy_start"] = json_number(first.energy);
  report.json["energy"] = json_number(last.energy);
  report.json["t_star"] = last.t_star;
  report.json["steps"] = run.accepted;
  report.json["rejected"] = run.rejected;
  report.json["resets"] = run.resets;
  report.json["gradient_evaluations"] = run.gradient_evaluations;
  report.json["hessian_evaluations"] = run.hessian_evaluations;
  report.json["dt_min"] = json_number(s.dt_lo);
  report.json["dt_max"] = json_number(s.dt_hi);
  if (run.initial_topology || last.topology) {
    std::string text = last.topology ? last.topology->describe() : std::string("not evaluated");
    if (last.topology && run.initial_topology)
      text += last.topology->same_as(*run.initial_topology) ? ", as at the start" : ", CHANGED from the start's " + run.initial_topology->describe();
    report.row("membrane (" + settings.topology_field + " = 0)", text);
    report.json["topology_start"] = run.initial_topology ? topology_json(*run.initial_topology) : nlohmann::json();
    report.json["topology"] = last.topology ? topology_json(*last.topology) : nlohmann::json();
  }
  report.warnings = run.warnings;
  report.json["max_relative_drift"] = nlohmann::json::object();
  for (std::size_t i = 0; i < s.max_drift.size(); ++i) report.json["max_relative_drift"][run.constraint_names[i]] = s.max_drift[i];
}

class DynamicsDriver final : public ProblemDriver {
 public:
  [[nodiscard]] std::string_view name() const override { return "dynamics"; }
  [[nodiscard]] std::string_view table() const override { return kDynamicsExtension; }
  [[nodiscard]] bool claims(const Scene& scene) const override { return scene.has_extension(kDynamicsExtension); }
  [[nodiscard]] bool restartable() const override { return true; }

  void check(const DriverContext& ctx) const override {
    const DynamicsSettings settings = *read_dynamics(*ctx.scene);
    OutputRoles extra;
    extra.auxiliary = {settings.dissipation};
    DynamicsIntegrator::check_scene(*ctx.scene, settings, bind_scene(*ctx.scene, ctx.comm, ctx.log, extra));
  }

  [[nodiscard]] RunReport run(const DriverContext& ctx) const override {
    const Scene& scene = *ctx.scene;
    const DynamicsSettings settings = *read_dynamics(scene);
    const DynamicsOutput output{ctx.output_directory, scene.name, ctx.restart};
    const DynamicsRun run = run_dynamics(ctx.comm, scene, settings, ctx.output_directory.empty() ? nullptr : &output, ctx.log);
    RunReport report;
    report.problem = "dynamics";
    report.success = run.failure.empty();
    report.status = run.failure.empty() ? "reached t_end" : "STOPPED: " + run.failure;
    describe_run(scene, settings, run, report);
    if (!ctx.output_directory.empty()) {
      report.files.emplace_back("time series", (ctx.output_directory / (scene.name + ".xmf")).string() + " (ParaView)");
      report.files.emplace_back("history", (ctx.output_directory / (scene.name + "_history.json")).string());
    }
    return report;
  }
};

}  // namespace

const ProblemDriver& dynamics_driver() {
  static const DynamicsDriver driver;
  return driver;
}

}  // namespace lmeform::problems
