// The shape family: oblate and prolate starts at several reduced volumes, each through the
// interface-resolving schedule (grids graded from the interface, eps lowered in between) with
// default solver settings. Per stage: the energy, the grid, the Newton and augmented-Lagrangian
// iterations, how far the constraint residual rose above its best value during the stage, and the
// wall time. Runs the scenes through the stage loop of `lmeform run` (problems::run_vesicle); under mpirun
// every scene runs on all ranks. Writes DIR/shapes.json and DIR/shapes.png (energy against eps).
// --fine goes on from eps = 0.01 to a fourth grid resolving eps = 0.005 (stages 0.0075, 0.005) and
// writes DIR/shapes_fine.json, with one `extrapolation` record per shape: E(eps) = E0 + a eps +
// b eps^2 fitted to the stages eps <= 0.02, E0 against the sharp-interface reference.
// --basis second runs every grid with the second-order max-ent basis ([nodes] basis = "second")
// and names the outputs shapes[_fine]_second.{json,png}. --factor F (2, 3 or 4) makes every grid
// F times finer than the eps it resolves ([vesicle] resolution_factor; default 2) and the uniform
// start (F/2)^2 times denser (6124, 13800, 24600 nodes); F != 2 appends _fF to the output names.
//   bench_shapes [--quick | --fine] [--basis first|second] [--factor F] [--log | --quiet] [--out DIR] [--nodes N] [--shape oblate:0.8 ...]
// --log prints the progress of every stage (the Newton iterates) as `lmeform run` does; --fine
// runs (an hour and more per shape) print it unless --quiet.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <iostream>
#include <optional>
#include <sstream>
#include <string>
#include <vector>

#include <Eigen/Dense>
#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include "lmeform/output.hpp"
#include "lmeform/petsc.hpp"
#include "lmeform/scene.hpp"
#include "problem_registry.hpp"
#include "vesicle.hpp"

namespace {

using namespace lmeform;

struct Shape {
  std::string branch;  // "oblate" or "prolate"
  double v = 0;
};

// The sharp-interface references of the seed (Paper A Sec. 4) where it gives them.
double sharp_reference(const Shape& s) {
  if (s.v == 0.8) return s.branch == "oblate" ? 9.12657 : 8.71756;
  return std::nan("");
}

// A uniform CVT of n nodes on [0, 1.5] x [0, 2] has the hexagonal spacing sqrt(2 |Omega| / (sqrt 3 n)).
double hex_spacing(int n) { return std::sqrt(2.0 * 1.5 * 2.0 / (std::sqrt(3.0) * n)); }

// The vesicle of demos/discocyte.toml with the start of `shape` and the interface-resolving
// schedule of demos/shapes/: a uniform CVT of `nodes` at eps_0 = factor h (the resolution rule), then a
// grid that resolves eps >= 0.025 around the eps_0 solution (stages 0.04, 0.03, 0.025) and one that
// resolves eps >= last_eps around the eps = 0.025 solution (stages 0.02, 0.015, ..., last_eps).
std::string shape_scene(const Shape& shape, int nodes, double last_eps, const std::string& basis, int factor) {
  const bool fine = last_eps < 0.01 - 1e-12;
  const double eps0 = std::max(0.05, std::ceil(1000.0 * (factor + 0.05) * hex_spacing(nodes)) / 1000.0);
  std::ostringstream s;
  s << "[scene]\nname = \"" << shape.branch << "_" << shape.v << "\"\ncoordinates = \"axisymmetric\"\n"
    << "[domain]\nlower = [0.0, 0.0]\nupper = [1.5, 2.0]\n"
    << "[nodes]\ncount = " << nodes << "\ngamma = 0.5\nquadrature_points = 6\nbasis = \"" << basis << "\"\n"
    << "[model]\nforms = [\"helfrich_axisymmetric\", \"area_axisymmetric\", \"volume_axisymmetric\", \"moment_axisymmetric\"]\n"
    << "energy = \"bending\"\n"
    << "[constants]\nk = 1.0\neps = " << eps0 << "\nC0 = 0.0\nzc = 1.0\n"
    << "[constraints]\narea = {}\nvolume = {}\nmoment = 0.0\n"
    << "[[dirichlet]]\nboundary = [\"r_max\", \"z_min\", \"z_max\"]\nunknown = \"phi\"\nvalue = -1.0\n"
    << "[vesicle]\nradius = 0.4\nreduced_volume = " << shape.v << "\nresolution_factor = " << factor << ".0\n"
    << "[vesicle.initial]\nshape = \"" << shape.branch << "\"\ncenter = [0.0, 1.0]\n"
    // The grid resolving 0.005 at factor 4 has about 68000 nodes, above the default budget.
    << "[vesicle.adaptivity]\nlloyd_iterations = 20\n" << (fine ? "max_nodes = 100000\n" : "") << "stages = [\n"
    << "  { eps = 0.04, resolve = 0.025 },\n  { eps = 0.03, lloyd_iterations = 0 },\n"
    << "  { eps = 0.025, lloyd_iterations = 0 },\n  { eps = 0.02, resolve = " << std::max(last_eps, 0.01) << " },\n";
  for (const double eps : {0.015, 0.01})
    if (eps >= last_eps - 1e-12) s << "  { eps = " << eps << ", lloyd_iterations = 0 },\n";
  // Finer than 0.01: a fourth grid resolving last_eps around the eps = 0.01 solution (the grids
  // before are the full run's, so its records up to 0.01 compare with shapes.json).
  if (fine) s << "  { eps = 0.0075, resolve = " << last_eps << " },\n  { eps = " << last_eps << ", lloyd_iterations = 0 },\n";
  s << "]\n";
  return s.str();
}

// The largest rise of the constraint residual over its best value so far (1: it never rose).
// Values below the solver's constraint tolerance (1e-10, relative) count as that tolerance: a
// residual of 1e-12 after 1e-14 is rounding, not a rise.
double constraint_rise(const ConstrainedResult& r) {
  constexpr double floor = 1e-10;
  double best = std::numeric_limits<double>::infinity(), rise = 1;
  for (const auto& it : r.history) {
    const double c = std::max(it.constraint_norm, floor);
    if (std::isfinite(best)) rise = std::max(rise, c / best);
    best = std::min(best, c);
  }
  return rise;
}

}  // namespace

int main(int argc, char** argv) {
  bool quick = false, fine = false;
  std::optional<bool> log;
  std::string basis = "first";
  std::filesystem::path out = "build/bench";
  int nodes = 0, factor = 2;
  std::vector<Shape> shapes;
  for (int i = 1; i < argc; ++i) {
    if (std::strcmp(argv[i], "--quick") == 0) {
      quick = true;
    } else if (std::strcmp(argv[i], "--fine") == 0) {
      fine = true;
    } else if (std::strcmp(argv[i], "--basis") == 0 && i + 1 < argc) {
      basis = argv[++i];
      if (basis != "first" && basis != "second") {
        std::fprintf(stderr, "bench_shapes: --basis takes first or second, got '%s'\n", basis.c_str());
        return 2;
      }
    } else if (std::strcmp(argv[i], "--factor") == 0 && i + 1 < argc) {
      factor = std::atoi(argv[++i]);
      if (factor < 2 || factor > 4) {
        std::fprintf(stderr, "bench_shapes: --factor takes 2, 3 or 4, got '%s'\n", argv[i]);
        return 2;
      }
    } else if (std::strcmp(argv[i], "--log") == 0) {
      log = true;
    } else if (std::strcmp(argv[i], "--quiet") == 0) {
      log = false;
    } else if (std::strcmp(argv[i], "--out") == 0 && i + 1 < argc) {
      out = argv[++i];
    } else if (std::strcmp(argv[i], "--nodes") == 0 && i + 1 < argc) {
      nodes = std::atoi(argv[++i]);
    } else if (std::strcmp(argv[i], "--shape") == 0 && i + 1 < argc) {
      const std::string s = argv[++i];
      const auto colon = s.find(':');
      const std::string branch = s.substr(0, colon);
      if (colon == std::string::npos || (branch != "oblate" && branch != "prolate")) {
        std::fprintf(stderr, "bench_shapes: --shape takes oblate:V or prolate:V, got '%s'\n", s.c_str());
        return 2;
      }
      shapes.push_back({branch, std::atof(s.c_str() + colon + 1)});
    } else {
      std::fprintf(stderr, "usage: bench_shapes [--quick | --fine] [--basis first|second] [--factor F] [--log | --quiet] [--out DIR] [--nodes N] [--shape oblate:0.8 ...]\n");
      return 2;
    }
  }
  PetscSession session(&argc, &argv);
  std::setvbuf(stdout, nullptr, _IOLBF, 0);
  std::filesystem::create_directories(out);
  if (shapes.empty())
    for (const char* branch : {"oblate", "prolate"})
      for (const double v : {0.7, 0.8, 0.9}) shapes.push_back({branch, v});
  // Quick: a coarser last grid and no eps = 0.01 stage. The start keeps O1's 6124 nodes: a
  // coarser start needs a larger eps by the resolution rule, and at eps = 0.07 (3000 nodes) the
  // oblate v = 0.9 energy lies below its eps = 0.04 value (8.0115 against 8.0286).
  if (nodes == 0) nodes = factor == 2 ? 6124 : factor == 3 ? 13800 : 24600;
  if (quick && fine) {
    std::fprintf(stderr, "bench_shapes: --quick and --fine exclude each other\n");
    return 2;
  }
  const double last_eps = quick ? 0.015 : fine ? 0.005 : 0.01;
  const std::string name = std::string(fine ? "shapes_fine" : "shapes") + (basis == "second" ? "_second" : "") +
                           (factor != 2 ? "_f" + std::to_string(factor) : "");

  nlohmann::json records = nlohmann::json::array();
  for (const Shape& shape : shapes) {
    std::printf("== %s start, v = %.2f, %d nodes\n", shape.branch.c_str(), shape.v, nodes);
    const Scene scene = parse_scene(shape_scene(shape, nodes, last_eps, basis, factor), "bench_shapes " + shape.branch, problems::driver_tables());
    const problems::VesicleRun run = problems::run_vesicle(PETSC_COMM_WORLD, scene, *problems::read_vesicle(scene), log.value_or(fine) ? &std::cout : nullptr);
    double cumulative = run.wall_s;
    for (const auto& st : run.stages) cumulative -= st.wall_s;  // the uniform CVT of the start
    const double reference = sharp_reference(shape);
    for (const auto& st : run.stages) {
      cumulative += st.wall_s;
      const ConstrainedResult& m = st.result.minimization;
      nlohmann::json r{{"branch", shape.branch},
                       {"v", shape.v},
                       {"basis", basis},
                       {"resolution_factor", factor},
                       {"stage", st.stage},
                       {"grid", st.grid},
                       {"eps", st.eps},
                       {"nodes", st.nodes},
                       {"h_min", st.h_min},
                       {"energy", st.result.energy},
                       {"converged", st.result.converged},
                       {"newton_iterations", m.newton_iterations},
                       {"augmented_iterations", m.augmented_iterations},
                       {"multiplier_updates", m.outer_iterations},
                       {"constraint_rise", constraint_rise(m)},
                       {"shifted_steps", m.corrected_steps},
                       {"constraint_corrections", m.constraint_corrections},
                       {"negative_curvature_directions", m.negative_curvature_directions},
                       {"wall_s", st.wall_s},
                       {"cumulative_wall_s", cumulative}};
      if (std::isfinite(reference)) r["relative_error_sharp"] = (st.result.energy - reference) / reference;
      std::printf("%-7s v %.2f  stage %2d %-6s %5d nodes  h_min %.4f  eps %.4f  E %.5f  AL %3d  KKT %2d  rise %.2f  %6.1f s%s%s\n",
                  shape.branch.c_str(), shape.v, st.stage, st.grid.c_str(), st.nodes, st.h_min, st.eps, st.result.energy,
                  m.augmented_iterations, m.newton_iterations, constraint_rise(m), st.wall_s,
                  st.result.converged ? "" : "  NOT CONVERGED", m.negative_curvature_directions > 0 ? "  SADDLE" : "");
      records.push_back(std::move(r));
    }
    if (!run.failure.empty()) std::printf("%s v %.2f stopped: %s\n", shape.branch.c_str(), shape.v, run.failure.c_str());
    if (fine) {
      // The phase-field energy approaches the sharp one as E0 + a eps + b eps^2 (a from the
      // interface's profile, b its next order): least squares over the converged stages eps <= 0.02.
      std::vector<double> eps, energy;
      for (const auto& st : run.stages)
        if (st.eps <= 0.02 + 1e-12 && st.result.converged) eps.push_back(st.eps), energy.push_back(st.result.energy);
      if (eps.size() >= 4) {
        Eigen::MatrixXd A(eps.size(), 3);
        Eigen::VectorXd b(eps.size());
        for (std::size_t i = 0; i < eps.size(); ++i) {
          A(Eigen::Index(i), 0) = 1, A(Eigen::Index(i), 1) = eps[i], A(Eigen::Index(i), 2) = eps[i] * eps[i];
          b(Eigen::Index(i)) = energy[i];
        }
        const Eigen::VectorXd c = A.colPivHouseholderQr().solve(b);
        const double residual = (A * c - b).cwiseAbs().maxCoeff();
        nlohmann::json r{{"branch", shape.branch}, {"v", shape.v}, {"basis", basis}, {"record", "extrapolation"}, {"fit", "E0 + a eps + b eps^2"},
                         {"eps_fitted", eps}, {"E0", c(0)}, {"a", c(1)}, {"b", c(2)}, {"max_fit_residual", residual}};
        if (std::isfinite(reference)) r["relative_error_sharp"] = (c(0) - reference) / reference;
        std::printf("%-7s v %.2f  extrapolated E0 = %.5f (fit over %zu stages, residual %.1e)%s\n", shape.branch.c_str(), shape.v, c(0), eps.size(),
                    residual, std::isfinite(reference) ? fmt::format(", {:+.3f} % from the sharp {:.5f}", 100 * (c(0) - reference) / reference, reference).c_str() : "");
        records.push_back(std::move(r));
      }
    }
  }

  if (PetscSession::rank() == 0) {
    write_text_atomically(out / (name + ".json"), records.dump(1) + "\n");
    const std::string command = "/usr/bin/python3 " LMEFORM_SOURCE_DIR "/scripts/plot_shapes.py '" + (out / (name + ".json")).string() +
                                "' '" + (out / (name + ".png")).string() + "'";
    if (std::system(command.c_str()) != 0) std::fprintf(stderr, "bench_shapes: the plot script failed\n");
    std::printf("wrote %s and %s.png\n", (out / (name + ".json")).c_str(), name.c_str());
  }
  return 0;
}
