// The solids cases of docs/solids.md against their closed-form references, on node ladders: the
// patch test, the Timoshenko–Goodier cantilever, the thick cylinder (Lamé), the simply supported
// and clamped Kirchhoff plates (series solutions) and the neo-Hookean block in load steps (its
// homogeneous solution). Each run is the demo scene of demos/solids/ with its spacing replaced,
// solved through the same driver as `lmeform run`. Writes DIR/solids.json: one record per case and
// node set with case, nodes, quantity, value, reference, rel_error, wall_s (and the case's other
// errors), and prints the table with the observed rates.
//   bench_solids [--quick] [--out DIR]
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <functional>
#include <iostream>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "bench_common.hpp"
#include "scene_runs.hpp"

namespace {

using namespace lmeform;
namespace fs = std::filesystem;

/// The homogeneous plane-strain neo-Hookean block, stretched l1 across and l2 = 1 - delta along
/// the press: the first Piola stress P22 at the free (P11 = 0) or contact (l1 = contact) state.
double block_press_stress(double E, double nu, double delta, double contact) {
  const double mu = E / (2 * (1 + nu)), lambda = E * nu / ((1 + nu) * (1 - 2 * nu));
  const double l2 = 1 - delta;
  auto p11 = [&](double l1) { return mu * (l1 - 1 / l1) + lambda * std::log(l1 * l2) / l1; };
  double lo = 1.0, hi = 2.0;  // P11(1) < 0 under compression, P11(2) > 0
  for (int i = 0; i < 200; ++i) (p11(0.5 * (lo + hi)) > 0 ? hi : lo) = 0.5 * (lo + hi);
  const double l1 = std::min(0.5 * (lo + hi), contact);
  return mu * (l2 - 1 / l2) + lambda * std::log(l1 * l2) / l2;
}

struct Case {
  std::string name;         ///< the record's case
  std::string scene;        ///< demos/solids/<scene>.toml
  std::string quantity;     ///< what `value` is
  double reference;         ///< its closed-form value
  std::vector<double> spacings, quick_spacings;
  /// The value from the run's report (quantities, errors).
  std::function<double(const nlohmann::json&)> value;
  std::vector<double> gammas = {0.8};  ///< LME locality: the plates show its effect on the limit
};

double quantity(const nlohmann::json& report, const std::string& name) { return report.at("quantities").at(name).get<double>(); }

double error_l2(const nlohmann::json& report) {
  for (const auto& e : report.at("errors"))
    if (e.at("unknown") == "u") return e.at("l2").get<double>();
  return NAN;
}


std::vector<Case> cases() {
  std::vector<Case> c;
  c.push_back({"patch", "patch", "L2 error of the linear field", 0.0, {0.4, 0.2, 0.1}, {0.4, 0.2}, error_l2});
  c.push_back({"cantilever", "cantilever", "tip deflection u_y(L, 0)", 4.0275, {0.5, 0.25, 0.125, 0.0625, 0.03125}, {0.5, 0.25, 0.125},
               [](const nlohmann::json& r) { return quantity(r, "tip_deflection"); }});
  c.push_back({"cylinder", "cylinder", "radial displacement u_r(1)", 1.3 * (0.4 / 3 + 4.0 / 3), {0.125, 0.0625, 0.03125, 0.015625},
               {0.125, 0.0625, 0.03125}, [](const nlohmann::json& r) { return quantity(r, "u_inner"); }});
  c.push_back({"plate_simply_supported", "plate_simply_supported", "centre deflection w D / (q a^4)", 0.00406235,
               {0.1, 0.05, 0.025, 0.0125}, {0.1, 0.05, 0.025}, [](const nlohmann::json& r) { return quantity(r, "centre_deflection"); },
               {0.8, 1.6}});
  c.push_back({"plate_clamped", "plate_clamped", "centre deflection w D / (q a^4)", 0.00126532, {0.1, 0.05, 0.025, 0.0125},
               {0.1, 0.05, 0.025}, [](const nlohmann::json& r) { return quantity(r, "centre_deflection"); }, {0.8, 1.6}});
  c.push_back({"load_steps", "block_compression", "press force at delta = 0.3", block_press_stress(1.0, 0.3, 0.3, 1.05), {0.1, 0.05},
               {0.1}, [](const nlohmann::json& r) { return quantity(r, "press_force[1]"); }});
  return c;
}

nlohmann::json run(const Case& c, double spacing, double gamma, const fs::path& work, double& wall) {
  std::string text = bench::read_text(fs::path(LMEFORM_DEMOS) / "solids" / (c.scene + ".toml"));
  text = bench::with_key(text, "nodes", "spacing", std::to_string(spacing));
  text = bench::with_key(text, "nodes", "gamma", std::to_string(gamma));
  try {
    return bench::run_scene_text(text, work / (c.scene + ".toml"), wall);
  } catch (const std::runtime_error& e) {
    throw std::runtime_error(c.name + " at spacing " + std::to_string(spacing) + ": " + e.what());
  }
}

}  // namespace

int main(int argc, char** argv) {
  const bench::BenchOptions options = bench::parse_bench_options(argc, argv);
  if (!options.unknown.empty()) {
    std::cerr << "bench_solids: unknown option " << options.unknown.front() << " (use --quick, --out DIR)\n";
    return 2;
  }
  PetscSession session(&argc, &argv);
  try {
    nlohmann::ordered_json records = nlohmann::ordered_json::array();
    const fs::path work = options.out / "solids_scenes";
    std::printf("%-24s %5s %8s %8s %16s %16s %10s %8s %8s\n", "case", "gamma", "spacing", "nodes", "value", "reference", "rel_error", "rate",
                "wall_s");
    for (const Case& c : cases())
      for (const double gamma : options.quick ? std::vector<double>{c.gammas.front()} : c.gammas) {
        double previous_error = NAN, previous_nodes = NAN;
        for (const double spacing : options.quick ? c.quick_spacings : c.spacings) {
          double wall = 0;
          const nlohmann::json report = run(c, spacing, gamma, work, wall);
          const double value = c.value(report);
          const auto nodes = report.contains("nodes") ? report.at("nodes").get<double>() : NAN;
          const double error = c.reference == 0 ? std::abs(value) : std::abs(value - c.reference) / std::abs(c.reference);
          // Against h ~ nodes^(-1/2) in 2D.
          const double rate = std::log(previous_error / error) / std::log(std::sqrt(nodes / previous_nodes));
          nlohmann::ordered_json r = {{"case", c.name}, {"scene", "demos/solids/" + c.scene + ".toml"}, {"spacing", spacing}, {"gamma", gamma},
                                      {"nodes", std::isnan(nodes) ? nlohmann::ordered_json() : nlohmann::ordered_json(nodes)},
                                      {"quantity", c.quantity}, {"value", value}, {"reference", c.reference}, {"rel_error", error},
                                      {"wall_s", wall}};
          if (report.contains("errors"))
            for (const auto& e : report.at("errors")) r["error_" + e.at("unknown").get<std::string>()] = {{"l2", e.at("l2")}, {"h1", e.at("h1")}};
          if (report.contains("quantities")) r["quantities"] = report.at("quantities");
          records.push_back(r);
          std::printf("%-24s %5.2g %8.4g %8.0f %16.9g %16.9g %10.3e %8.2f %8.2f\n", c.name.c_str(), gamma, spacing, nodes, value, c.reference,
                      error, rate, wall);
          std::fflush(stdout);
          previous_error = error;
          previous_nodes = nodes;
        }
      }
    if (PetscSession::rank() == 0) {
      fs::create_directories(options.out);
      write_text_atomically(options.out / "solids.json", records.dump(2) + "\n");
      std::printf("wrote %s (%zu records)\n", (options.out / "solids.json").string().c_str(), records.size());
    }
  } catch (const std::exception& e) {
    std::cerr << "bench_solids: " << e.what() << "\n";
    return 1;
  }
  return 0;
}
