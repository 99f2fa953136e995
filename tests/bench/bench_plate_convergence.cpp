// The manufactured simply supported Kirchhoff plate (demos/convergence/plate_mms.toml) with the
// first- and the second-order max-ent basis, on uniform and jittered node ladders, solved through
// the same driver as `lmeform run`. Writes DIR/basis_order.json: one record per run with basis,
// gamma, node_set, spacing, nodes, quadrature_points, error_l2, error_h1, error_h2, wall_s and
// the observed rates against the previous spacing; prints the table (docs/convergence.md).
//   bench_plate_convergence [--quick] [--out DIR]
#include <cmath>
#include <cstdio>
#include <iostream>
#include <string>
#include <vector>

#include <fmt/format.h>

#include "lmeform/node_sets.hpp"
#include "scene_runs.hpp"

namespace {

using namespace lmeform;
namespace fs = std::filesystem;

struct Case {
  std::string node_set;  ///< "uniform" or "jittered" (interior nodes moved by up to 0.3 h)
  LmeConsistency basis;
  double gamma;
  int quadrature_points;
  bool quick;                 ///< part of the quick sweep
  bool consistent = false;    ///< integration = "consistent" (gradients and Hessians corrected cell by cell)
};

std::vector<Case> cases() {
  constexpr auto first = LmeConsistency::first, second = LmeConsistency::second;
  return {{"uniform", first, 0.5, 6, false},   {"uniform", first, 0.8, 6, true},    {"uniform", first, 1.8, 6, false},
          {"uniform", second, 0.5, 6, false},  {"uniform", second, 0.8, 6, true},   {"jittered", first, 0.8, 6, false},
          {"jittered", first, 0.8, 12, false}, {"jittered", second, 0.8, 6, false}, {"jittered", second, 0.8, 12, true},
          {"jittered", second, 0.8, 19, false}, {"jittered", second, 0.5, 12, false},
          {"uniform", second, 0.8, 6, false, true}, {"jittered", first, 0.8, 6, false, true},
          {"jittered", second, 0.8, 6, true, true}, {"jittered", second, 0.5, 6, false, true}};
}

/// The error of unknown w in the report: l2, h1 or h2.
double error_of(const nlohmann::json& report, const char* norm) {
  for (const auto& e : report.at("errors"))
    if (e.at("unknown") == "w" && e.contains(norm)) return e.at(norm).get<double>();
  return NAN;
}

/// A jittered grid of spacing h in a point file (the same nodes for every basis and rule).
fs::path jittered_nodes(double h, const fs::path& folder) {
  const Box box = Box::unit(2);
  const NodeSet nodes = jitter_interior(uniform_grid(box, h), box, 0.3 * h, 11);
  std::string text;
  for (std::size_t a = 0; a < nodes.size(); ++a) text += fmt::format("{:.17g} {:.17g}\n", nodes.coords[2 * a], nodes.coords[2 * a + 1]);
  const fs::path path = folder / fmt::format("jittered_{:g}.txt", h);
  fs::create_directories(folder);
  write_text_atomically(path, text);
  return path;
}

}  // namespace

int main(int argc, char** argv) {
  const bench::BenchOptions options = bench::parse_bench_options(argc, argv);
  if (!options.unknown.empty()) {
    std::cerr << "bench_plate_convergence: unknown option " << options.unknown.front() << " (use --quick, --out DIR)\n";
    return 2;
  }
  PetscSession session(&argc, &argv);
  try {
    const fs::path demo = fs::path(LMEFORM_DEMOS) / "convergence";
    const fs::path work = fs::absolute(options.out / "plate_convergence");
    std::string scene = bench::read_text(demo / "plate_mms.toml");
    scene = bench::with_key(scene, "model", "forms", "[\"" + (demo / "plate_mms.form").string() + "\"]");
    scene = bench::with_key(scene, "output", "directory", "\"" + (work / "output").string() + "\"");
    const std::vector<double> spacings = options.quick ? std::vector<double>{0.1, 0.05, 0.025}
                                                       : std::vector<double>{0.1, 0.05, 0.025, 0.0125, 0.00625};
    nlohmann::ordered_json records = nlohmann::ordered_json::array();
    std::printf("%-8s %-6s %5s %3s %-10s %8s %6s %10s %10s %10s %6s %6s %6s %7s\n", "nodes", "basis", "gamma", "qp", "integration", "h", "N", "L2", "H1 semi",
                "H2 semi", "r L2", "r H1", "r H2", "wall s");
    for (const Case& c : cases()) {
      if (options.quick && !c.quick) continue;
      double previous[3] = {NAN, NAN, NAN}, previous_h = NAN;
      for (const double h : spacings) {
        std::string text = bench::with_key(scene, "nodes", "basis", fmt::format("\"{}\"", to_string(c.basis)));
        text = bench::with_key(text, "nodes", "gamma", fmt::format("{:g}", c.gamma));
        text = bench::with_key(text, "nodes", "quadrature_points", std::to_string(c.quadrature_points));
        text = bench::with_key(text, "nodes", "integration", c.consistent ? "\"consistent\"" : "\"gauss\"");
        if (c.node_set == "uniform") {
          text = bench::with_key(text, "nodes", "spacing", fmt::format("{:g}", h));
        } else {
          text = bench::without_key(text, "nodes", "spacing");
          text = bench::with_key(text, "nodes", "file", "\"" + jittered_nodes(h, work).string() + "\"");
        }
        double wall = 0;
        const fs::path path = work / fmt::format("plate_{}_{}_{:g}_{}{}_{:g}.toml", c.node_set, to_string(c.basis), c.gamma, c.quadrature_points,
                                                 c.consistent ? "_consistent" : "", h);
        const nlohmann::json report = bench::run_scene_text(text, path, wall);
        const double e[3] = {error_of(report, "l2"), error_of(report, "h1"), error_of(report, "h2")};
        double rate[3];
        for (int k = 0; k < 3; ++k) rate[k] = std::log(previous[k] / e[k]) / std::log(previous_h / h);
        const auto nodes = report.at("nodes").get<long>();
        std::printf("%-8s %-6s %5.2g %3d %-10s %8.5g %6ld %10.3e %10.3e %10.3e %6.2f %6.2f %6.2f %7.2f\n", c.node_set.c_str(), to_string(c.basis),
                    c.gamma, c.quadrature_points, c.consistent ? "consistent" : "gauss", h, nodes, e[0], e[1], e[2], rate[0], rate[1], rate[2], wall);
        std::fflush(stdout);
        auto number = [](double v) { return std::isfinite(v) ? nlohmann::ordered_json(v) : nlohmann::ordered_json(); };
        records.push_back({{"basis", to_string(c.basis)},
                           {"gamma", c.gamma},
                           {"node_set", c.node_set},
                           {"spacing", h},
                           {"nodes", nodes},
                           {"quadrature_points", c.quadrature_points},
                           {"integration", c.consistent ? "consistent" : "gauss"},
                           {"error_l2", number(e[0])},
                           {"error_h1", number(e[1])},
                           {"error_h2", number(e[2])},
                           {"rate_l2", number(rate[0])},
                           {"rate_h1", number(rate[1])},
                           {"rate_h2", number(rate[2])},
                           {"wall_s", wall},
                           {"setup_s", number(report.at("setup_s").get<double>())},
                           {"solve_s", number(report.at("solve_s").get<double>())}});
        for (int k = 0; k < 3; ++k) previous[k] = e[k];
        previous_h = h;
      }
    }
    if (PetscSession::rank() == 0) {
      fs::create_directories(options.out);
      nlohmann::ordered_json doc = {{"benchmark", "basis_order"},
                                    {"quick", options.quick},
                                    {"scene", "demos/convergence/plate_mms.toml"},
                                    {"reference", "w = sin(pi x) sin(pi y)"},
                                    {"records", records}};
      write_text_atomically(options.out / "basis_order.json", doc.dump(2) + "\n");
      std::printf("wrote %s (%zu records)\n", (options.out / "basis_order.json").string().c_str(), records.size());
    }
  } catch (const std::exception& e) {
    std::cerr << "bench_plate_convergence: " << e.what() << "\n";
    return 1;
  }
  return 0;
}
