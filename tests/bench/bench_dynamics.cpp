// Seed Table 3.3 in form: the variational time integrator (VTI) at constant steps against forward
// Euler at its largest stable constant step, over the same interval [t1*, t2*] of the oblate
// relaxation (demos/dynamics/oblate_relaxation.toml), from the same state at t1* (reached by an
// adaptive VTI run from the start). Per run: the energies at t1* and t2*, steps, gradient and
// Hessian evaluations, wall time split into the assembly of K, of E's Hessian, the solves and the
// resets. Forward Euler's largest stable step is searched over a descending ladder (the interval
// down to interval / 10⁴): stable means at least 50 steps (past t2* if need be; E(t2*) is recorded
// on the way) with the energy never increasing (beyond 1e-10 relative) and no folded map.
//
//   bench_dynamics [--quick] [--out DIR]      writes DIR/dynamics.json
//   bench_dynamics --out DIR -window 0.3 0.4  another interval: DIR/dynamics_0.3_0.4.json
//   bench_dynamics --out DIR -scene S.toml -window T1 T2 [-vti_divisors 1,10]
//                                             any dynamics scene (its own grid, eps, resets):
//                                             DIR/dynamics_S_T1_T2.json; VTI at (T2 - T1) / each divisor
//   ... -euler_dts 1e-5,5e-6 -euler_steps 50   forward Euler trials at these steps only, each run
//                                             for that many steps (E(t2*) only if they reach t2*):
//                                             on a stiff grid Euler needs 10^4 steps to reach t2*
//
// Quick: h = 1/16, eps = 0.125 and the window [1e-3, 3e-3]; full: the demo's grid (h = 0.025,
// eps = 0.05) and the seed's window [1e-3, 1.1e-2].
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <string>
#include <string_view>
#include <vector>

#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include "bench_common.hpp"
#include "dynamics.hpp"
#include "lmeform/output.hpp"
#include "lmeform/petsc.hpp"
#include "lmeform/scene.hpp"

namespace {

using namespace lmeform;

struct Record {
  std::string method;
  double dt_star = 0;
  bool stable = true;
  double energy_t2 = 0;
  int steps_to_t2 = 0;  ///< forward Euler trials run on past t2* to show stability
  problems::DynamicsRun run;
};

}  // namespace

int main(int argc, char** argv) {
  const bench::BenchOptions options = bench::parse_bench_options(argc, argv);
  PetscSession session(&argc, &argv);
  const int rank = PetscSession::rank();
  const std::string_view extensions[] = {problems::kDynamicsExtension};
  // PETSc-style options after --quick/--out: -window T1 T2 (another interval), -scene PATH (another
  // dynamics scene), -vti_divisors D1,D2,... (VTI steps (T2 - T1) / D).
  double t1 = 1e-3, t2 = options.quick ? 3e-3 : 1.1e-2;
  std::string label = "seed", scene_path = std::string(LMEFORM_SOURCE_DIR) + "/demos/dynamics/oblate_relaxation.toml";
  std::vector<double> vti_divisors{1, 10, 100}, euler_dts;
  int euler_steps = 0;  // 0: to t2* and at least 50 steps
  for (int i = 1; i < argc; ++i) {
    const std::string_view arg = argv[i];
    if (arg == "-window" && i + 2 < argc) {
      t1 = std::stod(argv[i + 1]);
      t2 = std::stod(argv[i + 2]);
      label = fmt::format("{:g}_{:g}", t1, t2);
    } else if (arg == "-scene" && i + 1 < argc) {
      scene_path = argv[i + 1];
    } else if ((arg == "-vti_divisors" || arg == "-euler_dts") && i + 1 < argc) {
      std::vector<double>& values = arg == "-vti_divisors" ? vti_divisors : euler_dts;
      values.clear();
      const std::string list = argv[i + 1];
      for (std::size_t begin = 0; begin <= list.size();) {
        const std::size_t end = std::min(list.find(',', begin), list.size());
        values.push_back(std::stod(list.substr(begin, end - begin)));
        begin = end + 1;
      }
    } else if (arg == "-euler_steps" && i + 1 < argc) {
      euler_steps = std::stoi(argv[i + 1]);
    }
  }
  if (!(t2 > t1 && t1 > 0)) {
    std::fprintf(stderr, "bench_dynamics: -window T1 T2 needs 0 < T1 < T2\n");
    return 1;
  }
  if (vti_divisors.empty() || std::any_of(vti_divisors.begin(), vti_divisors.end(), [](double d) { return !(d >= 1); })) {
    std::fprintf(stderr, "bench_dynamics: -vti_divisors needs numbers >= 1\n");
    return 1;
  }
  const bool own_scene = scene_path.find("/demos/dynamics/oblate_relaxation.toml") == std::string::npos;
  Scene scene = load_scene(scene_path, extensions);
  if (own_scene) label = std::filesystem::path(scene_path).stem().string() + "_" + fmt::format("{:g}_{:g}", t1, t2);
  if (options.quick && !own_scene) {
    scene.nodes.spacing = 0.0625;
    scene.constants["eps"] = 0.125;
  }
  problems::DynamicsSettings base = *problems::read_dynamics(scene);
  base.output_every = 0;
  base.checkpoint_every = 0;
  // A re-mesh projects the field and changes E: the methods are compared on the motion alone.
  base.remesh_every = 0;
  base.report_times.clear();

  // The common state at t1*: adaptive VTI from the start with small first steps.
  problems::DynamicsSettings lead = base;
  lead.t_end = t1;
  lead.dt = std::min(t1 / 10, 1e-4);
  const problems::DynamicsRun start = problems::run_dynamics(PETSC_COMM_WORLD, scene, lead, nullptr, nullptr);
  if (!start.failure.empty()) {
    std::fprintf(stderr, "bench_dynamics: the run to t1* failed: %s\n", start.failure.c_str());
    return 1;
  }
  if (rank == 0)
    std::printf("state at t1* = %.1e: E = %.8f after %d adaptive VTI steps (%zu nodes, h_min %.4g)\n", t1,
                start.history.back().energy, start.accepted, start.reference_nodes.size(), start.h_min);

  auto window = [&](problems::DynamicsSettings::Method method, double dt_star) {
    problems::DynamicsSettings s = base;
    s.method = method;
    s.adaptive = false;
    s.dt = dt_star;
    s.t_start = t1;
    s.t_end = t2;
    if (method == problems::DynamicsSettings::Method::forward_euler) {
      // Stability shows over many steps: at least 50 of them (beyond t2* if need be), E(t2*) recorded.
      s.t_end = euler_steps > 0 ? t1 + euler_steps * dt_star : std::max(t2, t1 + 50 * dt_star);
      if (s.t_end >= t2 * (1 - 1e-12)) s.report_times = {t2};
    }
    s.start_state = start.final_state;
    s.start_multipliers = start.final_multipliers;
    s.max_retries = 0;  // a constant step: a failure is a failure
    s.require_decrease = method == problems::DynamicsSettings::Method::forward_euler;  // instability ends the trial
    s.max_steps = static_cast<int>(std::ceil((s.t_end - t1) / dt_star * 1.001)) + 2;
    Record r;
    r.method = method == problems::DynamicsSettings::Method::vti ? "vti" : "forward_euler";
    r.dt_star = dt_star;
    r.run = problems::run_dynamics(PETSC_COMM_WORLD, scene, s, nullptr, nullptr);
    r.stable = r.run.failure.empty();
    for (std::size_t i = 1; r.stable && i < r.run.history.size(); ++i)
      if (!(r.run.history[i].energy <= r.run.history[i - 1].energy + 1e-10 * std::abs(r.run.history[i - 1].energy))) r.stable = false;
    const bool reaches_t2 = s.t_end >= t2 * (1 - 1e-12);
    r.energy_t2 = !reaches_t2 ? std::nan("") : r.run.energy_at.contains(t2) ? r.run.energy_at.at(t2) : r.run.history.back().energy;
    r.steps_to_t2 = 0;
    for (const auto& h : r.run.history)
      if (h.step > 0 && h.t_star <= t2 * (1 + 1e-12)) ++r.steps_to_t2;
    if (rank == 0)
      std::printf("%-14s dt* %.1e: E(t2*) %.8f  steps %5d  grad %5d  hess %4d  %8.2f s%s\n", r.method.c_str(), dt_star,
                  r.energy_t2, r.run.accepted, r.run.gradient_evaluations, r.run.hessian_evaluations, r.run.wall_s,
                  r.stable ? "" : ("  UNSTABLE: " + (r.run.failure.empty() ? std::string("the energy increased") : r.run.failure)).c_str());
    return r;
  };

  std::vector<Record> records;
  const double interval = t2 - t1;  // full: 1e-2, the seed's largest VTI step (one step)
  for (const double divisor : vti_divisors) records.push_back(window(problems::DynamicsSettings::Method::vti, interval / divisor));
  // Forward Euler: the largest stable step of a descending ladder.
  std::vector<Record> euler_trials;
  std::vector<double> ladder = euler_dts;
  if (ladder.empty())
    for (const double divisor : {1.0, 2.0, 5.0, 10.0, 20.0, 50.0, 100.0, 200.0, 500.0, 1e3, 2e3, 5e3, 1e4}) ladder.push_back(interval / divisor);
  for (const double dt : ladder) {
    euler_trials.push_back(window(problems::DynamicsSettings::Method::forward_euler, dt));
    if (euler_trials.back().stable) break;
  }
  const Record* euler = euler_trials.back().stable ? &euler_trials.back() : nullptr;

  // Both methods are first order: the VTI energies at the two smallest steps extrapolate
  // (Richardson) to the limit dt -> 0, the reference both are measured against.
  double reference = std::nan("");
  if (records.size() >= 2 && records[records.size() - 2].stable && records.back().stable) {
    const Record &coarse = records[records.size() - 2], &fine = records.back();
    const double ratio = coarse.dt_star / fine.dt_star;
    if (ratio > 1) reference = fine.energy_t2 + (fine.energy_t2 - coarse.energy_t2) / (ratio - 1);
  }
  nlohmann::json out = nlohmann::json::array();
  auto add = [&](const Record& r, bool largest_stable) {
    const problems::DynamicsRun& run = r.run;
    // A forward Euler trial runs on past t2* to show stability: its cost up to t2* is its share of
    // the steps (one gradient per step, the same work every step).
    const double share = run.accepted > 0 ? double(r.steps_to_t2) / run.accepted : 1.0;
    nlohmann::json j{{"method", r.method},
                     {"dt_star", r.dt_star},
                     {"t1_star", t1},
                     {"t2_star", t2},
                     {"energy_t1", run.history.front().energy},
                     {"energy_t2", r.stable && std::isfinite(r.energy_t2) ? nlohmann::json(r.energy_t2) : nlohmann::json(nullptr)},
                     {"steps", r.steps_to_t2},
                     {"steps_run", run.accepted},
                     {"gradient_evaluations", static_cast<int>(std::lround(run.gradient_evaluations * share))},
                     {"hessian_evaluations", static_cast<int>(std::lround(run.hessian_evaluations * share))},
                     {"wall_s", (run.wall_s - run.seconds_setup) * share + run.seconds_setup},
                     {"setup_s", run.seconds_setup},
                     {"assembly_K_s", run.seconds_dissipation * share},
                     {"assembly_hessian_s", run.seconds_hessian * share},
                     {"solve_s", run.seconds_solve * share},
                     {"reset_s", run.seconds_reset * share},
                     {"stable", r.stable},
                     {"largest_stable", largest_stable},
                     {"nodes", run.reference_nodes.size()},
                     {"quick", options.quick},
                     {"energy_t2_extrapolated", std::isfinite(reference) ? nlohmann::json(reference) : nlohmann::json(nullptr)}};
    if (r.stable && std::isfinite(reference) && std::isfinite(r.energy_t2)) j["relative_error_extrapolated"] = (r.energy_t2 - reference) / std::abs(reference);
    if (euler != nullptr && r.stable) {
      if (std::isfinite(r.energy_t2) && std::isfinite(euler->energy_t2))
        j["relative_difference_to_forward_euler"] = (r.energy_t2 - euler->energy_t2) / std::abs(euler->energy_t2);
      j["step_ratio_to_forward_euler"] = r.dt_star / euler->dt_star;
    }
    out.push_back(j);
  };
  for (const auto& r : records) add(r, false);
  for (const auto& r : euler_trials) add(r, &r == euler);

  if (rank == 0) {
    std::printf("\nTable 3.3 in form: [t1*, t2*] = [%.1e, %.1e], E(t1*) = %.6f\n", t1, t2, start.history.back().energy);
    std::printf("E(t2*) extrapolated from the VTI energies at the two smallest steps: %.6f\n", reference);
    std::printf("%-14s %9s %12s %7s %6s %6s %9s %12s %12s %10s\n", "method", "dt*", "E(t2*)", "steps", "grad", "hess", "wall s",
                "vs FE", "vs extrap.", "dt / FE dt");
    for (const auto& j : out) {
      if (j["method"] == "forward_euler" && !j["largest_stable"].get<bool>()) continue;
      std::printf("%-14s %9.1e %12.6f %7d %6d %6d %9.2f %12s %12s %10s\n", j["method"].get<std::string>().c_str(), j["dt_star"].get<double>(),
                  j["energy_t2"].is_null() ? std::nan("") : j["energy_t2"].get<double>(), j["steps"].get<int>(),
                  j["gradient_evaluations"].get<int>(), j["hessian_evaluations"].get<int>(), j["wall_s"].get<double>(),
                  j.contains("relative_difference_to_forward_euler")
                      ? fmt::format("{:+.2e}", j["relative_difference_to_forward_euler"].get<double>()).c_str()
                      : "-",
                  j.contains("relative_error_extrapolated") ? fmt::format("{:+.2e}", j["relative_error_extrapolated"].get<double>()).c_str() : "-",
                  j.contains("step_ratio_to_forward_euler") ? fmt::format("{:.0f}", j["step_ratio_to_forward_euler"].get<double>()).c_str()
                                                             : "-");
    }
    if (euler == nullptr) std::printf("forward Euler: no stable step down to %.1e\n", interval / 1e4);
    std::filesystem::create_directories(options.out);
    const std::string name = label == "seed" ? "dynamics.json" : "dynamics_" + label + ".json";
    write_text_atomically(options.out / name, out.dump(2) + "\n");
    std::printf("wrote %s\n", (options.out / name).string().c_str());
  }
  return 0;
}
