// Speed against error for the discocyte (issue 5): uniform grids (uniform CVTs of a node count,
// eps = 2 h) against one adapted grid that follows the progressive schedule of seed Table B.6
// down in eps, each point with its error against the sharp-interface energy and the wall time it
// took (adapted: cumulative over the stages, relocations included). Runs scenes through the same
// stage loop as `lmeform run` (problems::run_vesicle). Writes DIR/statics.json and DIR/statics.png.
//   bench_statics [--quick] [--out DIR]
#include <cmath>
#include <cstdio>
#include <cstring>
#include <iostream>
#include <filesystem>
#include <sstream>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "lmeform/output.hpp"
#include "lmeform/petsc.hpp"
#include "lmeform/scene.hpp"
#include "problem_registry.hpp"
#include "vesicle.hpp"

namespace {

using namespace lmeform;
constexpr double kSharp = 9.12657;  // discocyte, seed Paper A Sec. 4

struct Record {
  double eps;
  std::string grid;
  int nodes;
  double h_min, energy, relative_error_sharp, wall_s;
};

// The discocyte of demos/discocyte.toml on a uniform CVT of `count` nodes, gamma 0.5 on both
// ladders (the adapted grids need it, docs/results_adapted.md), plus `adaptivity` (TOML) if any.
std::string discocyte_scene(int count, double eps, const std::string& adaptivity) {
  std::ostringstream s;
  s << "[scene]\nname = \"discocyte\"\ncoordinates = \"axisymmetric\"\n"
    << "[domain]\nlower = [0.0, 0.0]\nupper = [1.5, 2.0]\n"
    << "[nodes]\ncount = " << count << "\ngamma = 0.5\nquadrature_points = 6\n"
    << "[model]\nforms = [\"helfrich_axisymmetric\", \"area_axisymmetric\", \"volume_axisymmetric\", \"moment_axisymmetric\"]\n"
    << "[constants]\neps = " << eps << "\nzc = 1.0\n"
    << "[constraints]\narea = {}\nvolume = {}\nmoment = 0.0\n"
    << "[[dirichlet]]\nboundary = [\"r_max\", \"z_min\", \"z_max\"]\nunknown = \"phi\"\nvalue = -1.0\n"
    << "[solver]\naugmented_tolerance = 1e-3\n"
    << "[reference]\nenergy = " << kSharp << "\n"
    << "[vesicle]\nradius = 0.4\nreduced_volume = 0.8\nresolution_factor = 1.6\n"
    << "[vesicle.initial]\nshape = \"ellipsoid\"\ncenter = [0.0, 1.0]\nsemi_axes = [0.4987, 0.2059]\n"
    << adaptivity;
  return s.str();
}

Record record_of(const problems::StageRecord& st, const std::string& grid, double wall) {
  const double e = st.result.energy;
  Record r{st.eps, grid, st.nodes, st.h_min, e, (e - kSharp) / kSharp, wall};
  std::printf("%-8s %6d nodes  h_min %.4f  eps %.4f  E %.5f  rel. error %+7.3f %%  %7.1f s\n", grid.c_str(), r.nodes,
              r.h_min, r.eps, r.energy, 100 * r.relative_error_sharp, r.wall_s);
  return r;
}

// A uniform CVT of n nodes has the hexagonal spacing h = sqrt(2 |Omega| / (sqrt 3 n)).
double hex_spacing(int n) { return std::sqrt(2.0 * 1.5 * 2.0 / (std::sqrt(3.0) * n)); }

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

  // Uniform ladder: eps = 2 h, rounded up to 1e-3.
  const std::vector<int> counts = quick ? std::vector<int>{3000, 6124, 12271} : std::vector<int>{3000, 6124, 12271, 24597};
  for (const int n : counts) {
    const double eps = std::ceil(2000.0 * hex_spacing(n)) / 1000.0;
    const Scene scene = parse_scene(discocyte_scene(n, eps, ""), "bench_statics uniform", problems::driver_tables());
    const problems::VesicleRun run = problems::run_vesicle(PETSC_COMM_WORLD, scene, *problems::read_vesicle(scene), nullptr);
    records.push_back(record_of(run.stages.back(), "uniform", run.wall_s));
  }

  // Adapted ladder: the Table 3 schedule (f = 10, 100, 1000, eps lowered in between) scaled to the
  // node count, eps_k = c_k h with the seed's c_k for O1 (h = 0.024): 0.04 ... 0.01 (quick, 3000 nodes: the last
  // at 0.012, which its grid still resolves).
  const int n = quick ? 3000 : 6124;
  const double scale = hex_spacing(n) / 0.024;
  auto e = [&](double seed_eps) { return std::round(1000.0 * seed_eps * scale) / 1000.0; };
  std::ostringstream adaptivity;
  adaptivity << "[vesicle.adaptivity]\nlloyd_iterations = 40\nstart = \"density\"\nstages = [\n"
             << "  { eps = " << e(0.04) << ", f = 10.0 },\n  { eps = " << e(0.03) << ", lloyd_iterations = 0 },\n"
             << "  { eps = " << e(0.03) << ", f = 100.0 },\n  { eps = " << e(0.025) << ", lloyd_iterations = 0 },\n"
             << "  { eps = " << e(0.025) << ", f = 1000.0 },\n  { eps = " << e(0.02) << ", lloyd_iterations = 0 },\n"
             << "  { eps = " << e(0.015) << ", lloyd_iterations = 0 },\n  { eps = " << e(quick ? 0.012 : 0.01)
             << ", lloyd_iterations = 0 },\n]\n";
  const Scene scene = parse_scene(discocyte_scene(n, e(0.04), adaptivity.str()), "bench_statics adapted", problems::driver_tables());
  const problems::VesicleRun run = problems::run_vesicle(PETSC_COMM_WORLD, scene, *problems::read_vesicle(scene), quick ? nullptr : &std::cout);
  double cumulative = run.wall_s;
  for (const auto& st : run.stages) cumulative -= st.wall_s;  // the uniform CVT of the start
  for (const auto& st : run.stages) {
    cumulative += st.wall_s;
    if (st.stage > 0) records.push_back(record_of(st, "adapted", cumulative));
  }
  if (!run.failure.empty()) std::printf("adapted ladder stopped: %s\n", run.failure.c_str());
  if (!run.stages.back().result.converged) {
    std::printf("adapted ladder stopped: stage %d did not converge: %s\n", run.stages.back().stage,
                run.stages.back().result.message.c_str());
  }

  if (PetscSession::rank() == 0) {
    nlohmann::json js = nlohmann::json::array();
    for (const auto& r : records)
      js.push_back({{"eps", r.eps},
                    {"grid", r.grid},
                    {"nodes", r.nodes},
                    {"h_min", r.h_min},
                    {"energy", r.energy},
                    {"relative_error_sharp", r.relative_error_sharp},
                    {"wall_s", r.wall_s}});
    write_text_atomically(out / "statics.json", js.dump(1) + "\n");
    const std::string command = "/usr/bin/python3 " LMEFORM_SOURCE_DIR "/scripts/plot_statics.py '" +
                                (out / "statics.json").string() + "' '" + (out / "statics.png").string() + "'";
    if (std::system(command.c_str()) != 0) std::fprintf(stderr, "bench_statics: the plot script failed\n");
    std::printf("wrote %s and statics.png\n", (out / "statics.json").c_str());
  }
  return 0;
}
