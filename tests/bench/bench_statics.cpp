// Speed against error for the discocyte (issue 5): a ladder of (ε, grid) — uniform grids and CVT-
// adapted grids of the same node count — with the energy's error against the sharp-interface
// value and the wall time of each run. Writes DIR/statics.json and DIR/statics.png.
//   bench_statics [--quick] [--out DIR]
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <numbers>
#include <sstream>
#include <string>
#include <vector>

#include "lmeform/cvt.hpp"
#include "lmeform/output.hpp"
#include "lmeform/petsc.hpp"
#include "vesicle.hpp"

namespace {

using namespace lmeform;
constexpr double kSharp = 9.12657;  // discocyte, seed Paper A Sec. 4
constexpr double pi = std::numbers::pi;

struct Record {
  double eps;
  std::string grid;
  int nodes;
  double energy, relative_error_sharp, wall_s;
};

app::VesicleSetup discocyte(double spacing, double eps) {
  app::VesicleSetup s;
  s.lower = {0.0, 0.0};
  s.upper = {1.5, 2.0};
  s.spacing = spacing;
  s.gamma = 0.8;
  s.eps = eps;
  s.z_center = 1.0;
  s.semi_axes = {0.4987, 0.2059};  // oblate spheroid with the sharp A0 and V0 (demos/discocyte.toml)
  const double R = 0.4;
  s.area_target = 4 * pi * R * R;
  s.volume_target = 0.8 * 4.0 / 3.0 * pi * R * R * R;
  s.moment_target = 0.0;
  return s;
}

Record run(const app::VesicleSetup& s, const std::string& grid, app::VesicleResult* keep = nullptr) {
  const auto t0 = std::chrono::steady_clock::now();
  auto r = app::solve_vesicle(PETSC_COMM_WORLD, s);
  const double wall = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  Record rec{s.eps, grid, r.nodes_count, r.solve.energy, (r.solve.energy - kSharp) / kSharp, wall};
  std::printf("%-9s %7d nodes  eps %.3f  E %.5f  rel. error %+7.3f %%  %7.1f s  %s\n", grid.c_str(), rec.nodes, rec.eps,
              rec.energy, 100 * rec.relative_error_sharp, rec.wall_s, r.solve.converged ? "" : r.solve.message.c_str());
  if (keep != nullptr) *keep = std::move(r);
  return rec;
}

}  // namespace

int main(int argc, char** argv) {
  bool quick = false;
  std::filesystem::path out = "build/bench";
  for (int i = 1; i < argc; ++i) {
    if (std::strcmp(argv[i], "--quick") == 0) quick = true;
    else if (std::strcmp(argv[i], "--out") == 0 && i + 1 < argc) out = argv[++i];
  }
  PetscSession session(&argc, &argv);
  std::setvbuf(stdout, nullptr, _IOLBF, 0);  // progress lines as they come, also into a log file
  std::filesystem::create_directories(out);
  std::vector<Record> records;
  // Uniform ladder: ε = 2h.
  const std::vector<std::pair<double, double>> uniform =
      quick ? std::vector<std::pair<double, double>>{{0.05, 0.10}, {0.04, 0.08}}
            : std::vector<std::pair<double, double>>{{0.05, 0.10}, {0.04, 0.08}, {0.03, 0.06}, {0.024, 0.05}};
  app::VesicleResult coarse;
  for (std::size_t k = 0; k < uniform.size(); ++k) {
    records.push_back(run(discocyte(uniform[k].first, uniform[k].second), "uniform", k == 0 ? &coarse : nullptr));
  }
  // Adapted ladder: the coarsest grid's node count, relocated by CVT on the previous solution,
  // then solved at the smallest ε the adapted grid resolves (ε ≥ 2 h_min).
  const int stages = quick ? 1 : 3;
  app::VesicleResult previous = std::move(coarse);
  double f = 10.0;
  for (int stage = 0; stage < stages; ++stage, f *= 2) {
    const auto t0 = std::chrono::steady_clock::now();
    CvtOptions cvt;
    cvt.iterations = 40;
    const NodeSet adapted = app::adapt_nodes(previous, {0.0, 0.0}, {1.5, 2.0}, f, cvt);
    const double eps = std::ceil(min_admissible_eps(adapted) * 1000.0) / 1000.0;
    app::VesicleSetup s = discocyte(0.0, eps);
    s.nodes = adapted;
    s.initial_phi = app::transfer_phi(previous.nodes, previous.phi, 0.8, s.spacing_smoothing, adapted);
    app::VesicleResult result;
    Record rec = run(s, "adapted", &result);
    rec.wall_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();  // adaptation included
    records.push_back(rec);
    previous = std::move(result);
  }
  if (PetscSession::rank() == 0) {
    std::ostringstream js;
    js << "[\n";
    for (std::size_t i = 0; i < records.size(); ++i) {
      const auto& r = records[i];
      js << "  {\"eps\": " << r.eps << ", \"grid\": \"" << r.grid << "\", \"nodes\": " << r.nodes
         << ", \"energy\": " << r.energy << ", \"relative_error_sharp\": " << r.relative_error_sharp
         << ", \"wall_s\": " << r.wall_s << "}" << (i + 1 < records.size() ? "," : "") << "\n";
    }
    js << "]\n";
    write_text_atomically(out / "statics.json", js.str());
    const std::string command = "/usr/bin/python3 " LMEFORM_SOURCE_DIR "/scripts/plot_statics.py '" +
                                (out / "statics.json").string() + "' '" + (out / "statics.png").string() + "'";
    if (std::system(command.c_str()) != 0) std::fprintf(stderr, "bench_statics: the plot script failed\n");
    std::printf("wrote %s and statics.png\n", (out / "statics.json").c_str());
  }
  return 0;
}
