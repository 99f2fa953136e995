// Equal-order stabilized Stokes with LME (forms/stokes.form): errors, rates and times of the three
// problems of demos/ (colliding flow, Poiseuille, manufactured) on uniform and graded node ladders,
// for each stabilization (none, GLS, SUPG-like, Douglas–Wang), and the sensitivity of GLS to C over
// two decades and to gamma. Solves go through the same path as `lmeform run` (bind_scene,
// solve_problem). Writes DIR/stokes.json (a list of records, one per solve) and prints tables.
//   bench_stokes [--quick] [--out DIR]
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <iostream>
#include <string>
#include <vector>

#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include "bench_common.hpp"
#include "lmeform/output.hpp"
#include "lmeform/petsc.hpp"
#include "lmeform/scene.hpp"
#include "stationary.hpp"
#include "stokes_problems.hpp"

namespace {

using namespace lmeform;
using namespace lmeform::stokes_problems;

/// The basis of a run: the LME basis, or the second-order max-ent basis with consistent integration.
struct Basis {
  std::string name = "first";
  bool consistent = false;
  double support_tolerance = 1e-6;  ///< [nodes] support_tolerance: the weight at which a node leaves a list
  std::string solver_options;       ///< [solver] petsc_options; empty: MUMPS LU
};

/// GMRES with an ILU(0) preconditioner (block Jacobi of ILU(0) on several ranks), to 1e-10.
constexpr const char* kIterative = "-ksp_type gmres -ksp_rtol 1e-10 -ksp_gmres_restart 200 -ksp_max_it 2000 -pc_type bjacobi";

struct Record {
  std::string problem, node_set, stabilization, basis = "first", integration = "gauss", solver = "mumps";
  int nodes = 0, unknowns = 0;
  double gamma = 0, C = 0, support_tolerance = 1e-6;
  long long matrix_nonzeros = 0;
  double error_u_l2 = 0, error_u_h1 = 0, error_p_l2 = 0;
  double setup_s = 0, assembly_s = 0, solve_s = 0, wall_s = 0;
};

Record solve(const Problem& pb, const std::string& node_set, int n, const Stabilization& st, double gamma, double C,
             const Basis& basis = {}) {
  const std::string nodes_extra = fmt::format("basis = \"{}\"\nintegration = \"{}\"\nsupport_tolerance = {:g}\n", basis.name,
                                              basis.consistent ? "consistent" : "gauss", basis.support_tolerance);
  const std::string solver_extra = basis.solver_options.empty() ? "" : "[solver]\npetsc_options = \"" + basis.solver_options + "\"\n";
  const Scene scene = parse_scene(scene_text(pb, gamma, solver_extra, nodes_extra), pb.name + ".toml");
  const problems::BoundScene bound = problems::bind_scene(scene, PETSC_COMM_WORLD, nullptr);
  problems::ProblemInput input;
  input.nodes = node_set == "uniform" ? uniform_nodes(pb, n) : graded_nodes(pb, n);
  input.lme.consistency = bound.discretization.basis;  // the ladders predate spacing smoothing: kept without it
  input.lme.tol0 = bound.discretization.support_tolerance;
  input.constants = {{"C", st.name == "none" ? 0.0 : C}, {"alpha", st.alpha}, {"beta", st.beta}};
  const problems::ProblemResult r = problems::solve_problem(PETSC_COMM_WORLD, bound, input);
  Record rec{pb.name, node_set, st.name, basis.name, basis.consistent ? "consistent" : "gauss", "mumps", static_cast<int>(input.nodes.size()),
             static_cast<int>(input.nodes.size()) * 3, gamma, st.name == "none" ? 0.0 : C, basis.support_tolerance, r.matrix_nonzeros};
  if (!basis.solver_options.empty()) rec.solver = "gmres+ilu0";
  for (const auto& e : r.errors) {
    if (e.unknown == "u") {
      rec.error_u_l2 = e.l2;
      rec.error_u_h1 = e.h1;
    } else if (e.unknown == "p") {
      rec.error_p_l2 = e.l2;
    }
  }
  rec.setup_s = r.seconds_setup;
  rec.assembly_s = r.seconds_assembly;
  rec.solve_s = r.seconds_solve - r.seconds_assembly;
  rec.wall_s = r.seconds_setup + r.seconds_solve;
  if (!r.converged) std::fprintf(stderr, "warning: %s %s n=%d %s: %s\n", pb.name.c_str(), node_set.c_str(), n, st.name.c_str(), r.message.c_str());
  std::printf("%-15s %-8s %-6s %6d %-13s %5.2f %6.3f tol %.0e %-10s u L2 %.3e  u H1 %.3e  p L2 %.3e  %6.2f s (setup %.2f, assembly %.2f, "
              "solve %.2f; %.0f non-zeros per row)\n",
              rec.problem.c_str(), rec.node_set.c_str(), rec.basis.c_str(), rec.nodes, rec.stabilization.c_str(), rec.gamma, rec.C,
              rec.support_tolerance, rec.solver.c_str(), rec.error_u_l2, rec.error_u_h1, rec.error_p_l2, rec.wall_s, rec.setup_s, rec.assembly_s, rec.solve_s,
              double(rec.matrix_nonzeros) / std::max(rec.unknowns, 1));
  std::fflush(stdout);
  return rec;
}

nlohmann::json to_json(const Record& r) {
  return {{"problem", r.problem},       {"node_set", r.node_set},     {"nodes", r.nodes},
          {"unknowns", r.unknowns},     {"stabilization", r.stabilization}, {"gamma", r.gamma},
          {"basis", r.basis},           {"integration", r.integration},
          {"support_tolerance", r.support_tolerance}, {"matrix_nonzeros", r.matrix_nonzeros}, {"solver", r.solver},
          {"C", r.C},                   {"error_u_l2", r.error_u_l2}, {"error_u_h1", r.error_u_h1},
          {"error_p_l2", r.error_p_l2}, {"setup_s", r.setup_s},       {"assembly_s", r.assembly_s},
          {"solve_s", r.solve_s},       {"wall_s", r.wall_s}};
}

/// Rates between consecutive records of one ladder, against h ~ nodes^(-1/2).
void print_rates(const std::vector<Record>& ladder) {
  for (std::size_t i = 1; i < ladder.size(); ++i) {
    const double dh = std::log(std::sqrt(double(ladder[i - 1].nodes) / ladder[i].nodes));
    std::printf("    rates %5d -> %5d nodes: u L2 %.2f  u H1 %.2f  p L2 %.2f\n", ladder[i - 1].nodes, ladder[i].nodes,
                std::log(ladder[i].error_u_l2 / ladder[i - 1].error_u_l2) / dh,
                std::log(ladder[i].error_u_h1 / ladder[i - 1].error_u_h1) / dh,
                std::log(ladder[i].error_p_l2 / ladder[i - 1].error_p_l2) / dh);
  }
}

}  // namespace

int main(int argc, char** argv) {
  const bench::BenchOptions options = bench::parse_bench_options(argc, argv);
  if (!options.unknown.empty()) {
    std::cerr << "bench_stokes: unknown option " << options.unknown.front() << " (use --quick, --out DIR)\n";
    return 2;
  }
  const bool quick = options.quick;
  const std::filesystem::path out = options.out;
  PetscSession session(&argc, &argv);
  try {
    const std::vector<int> ladder = quick ? std::vector<int>{9, 17, 33} : std::vector<int>{9, 17, 33, 65};
    const int fixed_n = quick ? 17 : 33;
    std::vector<Record> records;
    std::printf("%-15s %-8s %-6s %6s %-13s %5s %6s\n", "problem", "nodes", "basis", "n", "stabilization", "gamma", "C");
    // Convergence: every problem, both node ladders, every stabilization at C = 0.1, gamma = 1.
    for (const auto& pb : demo_problems())
      for (const std::string node_set : {"uniform", "graded"})
        for (const auto& st : stabilizations()) {
          std::vector<Record> l;
          for (const int n : ladder) l.push_back(solve(pb, node_set, n, st, 1.0, 0.1));
          print_rates(l);
          records.insert(records.end(), l.begin(), l.end());
        }
    // The second-order basis with consistent integration (gradients and the GLS term's Hessians),
    // GLS at C = 0.1, gamma = 1 (docs/convergence.md).
    // Again with the compact support (support_tolerance 1e-3: about half the non-zeros per row),
    // and with it GMRES + ILU(0) in place of MUMPS.
    const std::vector<Basis> second_order{{"second", true, 1e-6, ""}, {"second", true, 1e-3, ""}, {"second", true, 1e-3, kIterative}};
    for (const Basis& basis : second_order)
      for (const auto& pb : demo_problems()) {
        std::vector<Record> l;
        for (const int n : ladder) l.push_back(solve(pb, "uniform", n, stabilizations()[1], 1.0, 0.1, basis));
        print_rates(l);
        records.insert(records.end(), l.begin(), l.end());
      }
    // Sensitivity of GLS to C (two decades and beyond) and to gamma, on one uniform grid.
    for (const auto& pb : demo_problems()) {
      for (const double C : {0.003, 0.01, 0.03, 0.1, 0.3, 1.0, 3.0})
        records.push_back(solve(pb, "uniform", fixed_n, stabilizations()[1], 1.0, C));
      for (const double gamma : {0.8, 1.6})
        for (const int n : ladder) records.push_back(solve(pb, "uniform", n, stabilizations()[1], gamma, 0.1));
    }
    if (PetscSession::rank() == 0) {
      nlohmann::json js = nlohmann::json::array();
      for (const auto& r : records) js.push_back(to_json(r));
      std::filesystem::create_directories(out);
      write_text_atomically(out / "stokes.json", js.dump(2) + "\n");
      std::printf("wrote %s (%zu records)\n", (out / "stokes.json").string().c_str(), records.size());
    }
  } catch (const std::exception& e) {
    std::cerr << "bench_stokes: " << e.what() << "\n";
    return 1;
  }
  return 0;
}
