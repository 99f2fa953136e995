// The flexoelectric size effects of docs/flexoelectricity.md (seed Sec. 5.3): the cantilever's
// normalized Young's modulus Y' (seed Eq. 5.17) against the normalized thickness h' in three
// electrical settings, against the Euler–Bernoulli estimate; the truncated pyramid's effective
// piezoelectric coefficient e' against h' on a rigid and a flexible support, against the
// one-dimensional model; both on a ladder of four node sets at one size (convergence), with the
// saddle-point solve's time against the unknowns. Each run is a demo scene of demos/flexoelectric/
// with its spacing and flexoelectric constants replaced, solved through the same driver as
// `lmeform run`. Units: h = 1, E = 1, kappa = 1, so h' = h / l = 1 / mu with l = mu / sqrt(kappa E).
// Writes DIR/flexo.json (one record per run: case, circuit or support, h_prime, spacing, nodes,
// unknowns, quantity "Y_prime" or "e_prime", value, reference, wall_s, solve_s) and
// DIR/flexo_midlines.json (the cantilevers' deflected midlines).
//   bench_flexo [--quick] [--out DIR]
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <iostream>
#include <string>
#include <vector>

#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include "bench_common.hpp"
#include "scene_runs.hpp"

namespace {

using namespace lmeform;
namespace fs = std::filesystem;

constexpr double kNu = 0.37;                 // the demos' Poisson ratio
constexpr double kLength = 20.0;             // the cantilever's length (h = 1)
constexpr double kTipLoad = 1e-4;            // the demos' tip load P
constexpr double kTopWidth = 1.0, kBottomWidth = 2.0, kHeight = 1.0;  // the pyramid's a1, a2, h

/// The strain-gradient coefficient of the thickness polarization of a bent plane-strain beam or a
/// compressed column: P_y = mu_T eps_xx,y + mu_L eps_yy,y with eps_xx = -nu/(1 - nu) eps_yy under
/// uniaxial stress (column) or eps_yy = -nu/(1 - nu) eps_xx (beam); mu_L = mu_T = mu here.
double effective_mu(double mu) { return mu * (1 - kNu / (1 - kNu)); }

/// Euler–Bernoulli, open circuit (D_y = 0 across the thickness): the bending stiffness Y I grows
/// by mu_eff^2 h / kappa, so Y_EB = 1 + 12 mu_eff^2 / (kappa Y h^2) with Y = E / (1 - nu^2); at
/// a given load the elastic energy falls as 1 / Y_EB^2, and Eq. 5.17's ratio is Y_EB^2.
double euler_bernoulli_y_prime(double h_prime) {
  const double y = 1.0 / (1 - kNu * kNu), mu = effective_mu(1.0 / h_prime);
  const double stiffening = 1 + 12 * mu * mu / y;
  return stiffening * stiffening;
}

/// The one-dimensional pyramid: a column of width a(y) under F, eps_yy = -F / (C a(y)), D_y = 0 (a
/// floating electrode with no charge): V = -int E_y = mu_eff / kappa (eps(h) - eps(0)), and e' =
/// -kappa V / (Delta u sqrt(kappa E)) = mu_eff (a2 - a1)^2 / (a1 a2 h ln(a2 / a1)) / sqrt(kappa E).
double one_dimensional_e_prime(double h_prime) {
  return effective_mu(1.0 / h_prime) * std::pow(kBottomWidth - kTopWidth, 2) /
         (kTopWidth * kBottomWidth * kHeight * std::log(kBottomWidth / kTopWidth));
}

struct Outcome {
  nlohmann::json report;
  double wall = 0;
};

double quantity(const nlohmann::json& report, const std::string& name) { return report.at("quantities").at(name).get<double>(); }

/// The demo scene with its spacing and flexoelectric constants set, midline probes added.
Outcome run(const std::string& scene, double spacing, double mu, const fs::path& work, bool midline = false) {
  std::string text = bench::read_text(fs::path(LMEFORM_DEMOS) / "flexoelectric" / (scene + ".toml"));
  text = bench::with_key(text, "nodes", "spacing", fmt::format("{}", spacing));
  text = bench::with_key(text, "constants", "mu_L", fmt::format("{}", mu));
  text = bench::with_key(text, "constants", "mu_T", fmt::format("{}", mu));
  text = bench::with_key(text, "output", "hdf5", "false");
  if (midline) {
    std::string probes;
    for (int i = 0; i <= 40; ++i)
      probes += fmt::format("midline_{} = {{ probe = [{}, 0.0], field = \"u\", component = 1 }}\n", i, kLength * i / 40.0);
    const auto at = text.find("\n[output]");
    text.insert(at + 1, probes);
  }
  Outcome o;
  const std::string name = fmt::format("{}_{}_{}.toml", scene, spacing, mu);
  o.report = bench::run_scene_text(text, work / name, o.wall);
  return o;
}

std::vector<double> midline(const nlohmann::json& report) {
  std::vector<double> w;
  for (int i = 0; i <= 40; ++i) w.push_back(quantity(report, fmt::format("midline_{}", i)));
  return w;
}

nlohmann::ordered_json record(const std::string& case_name, const std::string& setting_key, const std::string& setting, double h_prime,
                              double spacing, const Outcome& o, const std::string& q, double value, double reference) {
  const double nodes = o.report.at("nodes").get<double>();
  nlohmann::ordered_json r = {{"case", case_name},
                              {setting_key, setting},
                              {"h_prime", h_prime},
                              {"spacing", spacing},
                              {"nodes", nodes},
                              {"unknowns", 3 * nodes},
                              {"quantity", q},
                              {"value", value},
                              {"reference", std::isnan(reference) ? nlohmann::ordered_json() : nlohmann::ordered_json(reference)},
                              {"wall_s", o.wall},
                              {"setup_s", o.report.at("setup_s")},
                              {"solve_s", o.report.at("solve_s")},
                              {"assembly_s", o.report.at("assembly_s")},
                              {"factorization_s", o.report.at("factorization_s")},
                              {"negative_eigenvalues", o.report.at("negative_eigenvalues")},
                              {"expected_negative_eigenvalues", o.report.at("expected_negative_eigenvalues")}};
  r["quantities"] = o.report.at("quantities");
  return r;
}

/// Y' of the cantilever in one electrical setting, against the elastic run on the same nodes.
nlohmann::ordered_json cantilever_record(const std::string& case_name, const std::string& circuit, double h_prime, double spacing,
                                         const Outcome& elastic, const fs::path& work, bool midline_probes, nlohmann::ordered_json& midlines) {
  const std::string scene = circuit == "closed" ? "cantilever" : "cantilever_" + circuit;
  const Outcome o = run(scene, spacing, 1.0 / h_prime, work, midline_probes);
  const double y_prime = quantity(elastic.report, "elastic_energy") / quantity(o.report, "elastic_energy");
  const double reference = circuit == "open" ? euler_bernoulli_y_prime(h_prime) : circuit == "closed" ? 1.0 : NAN;
  nlohmann::ordered_json r = record(case_name, "circuit", circuit, h_prime, spacing, o, "Y_prime", y_prime, reference);
  r["tip_deflection"] = quantity(o.report, "tip_deflection");
  r["tip_deflection_elastic"] = quantity(elastic.report, "tip_deflection");
  std::printf("%-12s %-9s %6.3g %7.4g %7.0f %14.8f %14.8f %10.3e %8.2f %8.2f\n", case_name.c_str(), circuit.c_str(), h_prime, spacing,
              r["nodes"].get<double>(), y_prime, reference, y_prime - 1, o.report.at("solve_s").get<double>(), o.wall);
  std::fflush(stdout);
  if (midline_probes)
    midlines.push_back({{"circuit", circuit}, {"h_prime", h_prime}, {"spacing", spacing}, {"x", [] {
                          std::vector<double> x;
                          for (int i = 0; i <= 40; ++i) x.push_back(kLength * i / 40.0);
                          return x;
                        }()},
                        {"deflection", midline(o.report)}, {"deflection_elastic", midline(elastic.report)}});
  return r;
}

nlohmann::ordered_json pyramid_record(const std::string& case_name, const std::string& support, double h_prime, double spacing,
                                      const fs::path& work) {
  const Outcome o = run("pyramid_" + support, spacing, 1.0 / h_prime, work);
  // e' = -kappa V / (Delta u sqrt(kappa E)), Delta u the top's mean vertical displacement (the bottom's is 0).
  const double v = quantity(o.report, "bottom_potential"), du = quantity(o.report, "top_displacement") / kTopWidth;
  const double e_prime = -v / du, reference = one_dimensional_e_prime(h_prime);
  nlohmann::ordered_json r = record(case_name, "support", support, h_prime, spacing, o, "e_prime", e_prime, reference);
  std::printf("%-12s %-9s %6.3g %7.4g %7.0f %14.8f %14.8f %10.3e %8.2f %8.2f\n", case_name.c_str(), support.c_str(), h_prime, spacing,
              r["nodes"].get<double>(), e_prime, reference, e_prime / reference, o.report.at("solve_s").get<double>(), o.wall);
  std::fflush(stdout);
  return r;
}

}  // namespace

int main(int argc, char** argv) {
  const bench::BenchOptions options = bench::parse_bench_options(argc, argv);
  if (!options.unknown.empty()) {
    std::cerr << "bench_flexo: unknown option " << options.unknown.front() << " (use --quick, --out DIR)\n";
    return 2;
  }
  PetscSession session(&argc, &argv);
  try {
    const bool quick = options.quick;
    nlohmann::ordered_json records = nlohmann::ordered_json::array(), midlines = nlohmann::ordered_json::array();
    const fs::path work = options.out / "flexo_scenes";
    std::printf("%-12s %-9s %6s %7s %7s %14s %14s %10s %8s %8s\n", "case", "setting", "h'", "spacing", "nodes", "value", "reference",
                "Y'-1|ratio", "solve_s", "wall_s");

    // The cantilever's size effect: Y'(h') in each electrical setting.
    const double beam_spacing = quick ? 0.125 : 0.0625;
    const std::vector<double> beam_sizes = quick ? std::vector<double>{0.5, 2, 8, 32} : std::vector<double>{0.25, 0.5, 1, 2, 4, 8, 16, 32, 64};
    const std::vector<std::string> circuits = quick ? std::vector<std::string>{"closed", "open"} : std::vector<std::string>{"closed", "floating", "open"};
    const Outcome elastic = run("cantilever", beam_spacing, 0.0, work, true);
    for (const auto& circuit : circuits)
      for (const double h_prime : beam_sizes) {
        const bool drawn = h_prime == 1 || h_prime == 8 || (quick && h_prime == 2);
        records.push_back(cantilever_record("cantilever", circuit, h_prime, beam_spacing, elastic, work, drawn, midlines));
      }

    // The pyramid's e'(h') on both supports.
    const double pyramid_spacing = quick ? 0.05 : 0.025;
    const std::vector<double> pyramid_sizes = quick ? std::vector<double>{0.5, 2, 8} : std::vector<double>{0.25, 0.5, 1, 2, 4, 8, 16, 32};
    for (const std::string support : {"rigid", "flexible"})
      for (const double h_prime : pyramid_sizes) records.push_back(pyramid_record("pyramid", support, h_prime, pyramid_spacing, work));

    // Convergence at one size each: Y' of the open-circuit beam at h' = 4, e' of the rigidly
    // supported pyramid at h' = 2, on four node sets (three in quick mode).
    const std::vector<double> beam_ladder = quick ? std::vector<double>{0.25, 0.125, 0.0625} : std::vector<double>{0.25, 0.125, 0.0625, 0.03125};
    for (const double spacing : beam_ladder) {
      const Outcome e = run("cantilever", spacing, 0.0, work);
      records.push_back(cantilever_record("convergence", "open", 4.0, spacing, e, work, false, midlines));
    }
    const std::vector<double> pyramid_ladder = quick ? std::vector<double>{0.1, 0.05, 0.025} : std::vector<double>{0.1, 0.05, 0.025, 0.0125};
    for (const double spacing : pyramid_ladder) records.push_back(pyramid_record("convergence", "rigid", 2.0, spacing, work));

    if (PetscSession::rank() == 0) {
      fs::create_directories(options.out);
      write_text_atomically(options.out / "flexo.json", records.dump(2) + "\n");
      write_text_atomically(options.out / "flexo_midlines.json", midlines.dump(2) + "\n");
      std::printf("wrote %s (%zu records) and %s\n", (options.out / "flexo.json").string().c_str(), records.size(),
                  (options.out / "flexo_midlines.json").string().c_str());
    }
  } catch (const std::exception& e) {
    std::cerr << "bench_flexo: " << e.what() << "\n";
    return 1;
  }
  return 0;
}
