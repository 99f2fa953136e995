// One run of the scaling study: `mpirun -n P bench_scaling --dim D --nodes N [--storage full|compressed]
// [--partition metis|hilbert|block] [--off-process zero|exchange] [--record FILE]`.
//
// The heat problem -Lap T = 1 (the generated poisson form, T = 0 on the hull) on a jittered grid of
// about N nodes in the unit square or cube: the Discretization (setup, per stage), one matrix and
// one vector assembly, a CG + GAMG solve to rtol 1e-8. Every figure is the largest over the ranks
// (what a run waits for) except the memory, given per rank; `*_cpu_s` are the CPU seconds of the
// busiest rank (oversubscribed ranks share a core: their wall time stretches, their CPU time not):
//   peak_rss_mb_per_rank   the largest peak resident set of any rank (getrusage, whole process)
//   base_rss_mb            the same right after PetscInitialize (MPI and PETSc themselves)
//   work_rss_mb_per_rank   peak minus base: what this run's data cost the rank
//   replicated_mb, local_mb  the Discretization's own accounting of its arrays (memory_report())
// Rank 0 appends one JSON record per run to FILE (one line each); scripts/scaling_study.py runs
// the rank counts and writes build/bench/scaling.json.
#include <mpi.h>

#include <cmath>
#include <cstdio>
#include <exception>
#include <fstream>
#include <string>
#include <vector>

#include "bench_common.hpp"
#include "bench_mpi.hpp"
#include "cg_gamg_solve.hpp"
#include "lmeform/assembler.hpp"
#include "lmeform/convex_hull.hpp"
#include "lmeform/discretization.hpp"
#include "lmeform/node_sets.hpp"
#include "lmeform/petsc.hpp"
#include "lmeform/resource_usage.hpp"
#include "poisson_kernels.hpp"

namespace lmeform::bench {
namespace {

struct ScalingArgs {
  int dim = 2;
  long long nodes = 100000;
  std::string storage = "compressed";
  std::string partition = "metis";
  std::string off_process = "zero";
  double gamma = 1.6;
  int points = 0;  // 0: 6 per triangle, 4 per tetrahedron
  std::string record;
  std::string case_name;
};

ScalingArgs parse_args(int argc, char** argv) {
  ScalingArgs a;
  for (int i = 1; i < argc; ++i) {
    const std::string arg = argv[i];
    const auto next = [&]() -> std::string {
      if (i + 1 >= argc) throw std::invalid_argument("bench_scaling: " + arg + " needs a value");
      return argv[++i];
    };
    if (arg == "--dim") a.dim = std::stoi(next());
    else if (arg == "--nodes") a.nodes = std::stoll(next());
    else if (arg == "--storage") a.storage = next();
    else if (arg == "--partition") a.partition = next();
    else if (arg == "--off-process") a.off_process = next();
    else if (arg == "--gamma") a.gamma = std::stod(next());
    else if (arg == "--points") a.points = std::stoi(next());
    else if (arg == "--record") a.record = next();
    else if (arg == "--case") a.case_name = next();
    else if (arg.starts_with("--")) throw std::invalid_argument("bench_scaling: unknown option " + arg);
  }
  if (a.dim != 2 && a.dim != 3) throw std::invalid_argument("bench_scaling: --dim 2 or 3");
  if (a.points == 0) a.points = a.dim == 2 ? 6 : 4;
  if (a.case_name.empty()) a.case_name = "heat_" + std::to_string(a.dim) + "d";
  return a;
}

NodeSet jittered_grid(int dim, long long nodes) {
  const int per_axis = static_cast<int>(std::lround(std::pow(static_cast<double>(nodes), 1.0 / dim)));
  const Box box = Box::unit(dim);
  const NodeSet grid = uniform_grid(box, {per_axis, per_axis, dim == 3 ? per_axis : 1});
  // Jitter breaks the cocircular ties of a uniform grid, whose Delaunay cells are then unique.
  return jitter_interior(grid, box, 0.2 / (per_axis - 1), 7);
}

int run(int argc, char** argv) {
  const double base_rss = max_over_ranks(peak_resident_mb());
  const ScalingArgs args = parse_args(argc, argv);
  int ranks = 1;
  MPI_Comm_size(PETSC_COMM_WORLD, &ranks);

  Stopwatch total;
  const NodeSet nodes = jittered_grid(args.dim, args.nodes);
  const double nodes_s = max_over_ranks(total.seconds());
  say("bench_scaling: %s, %zu nodes, %d ranks, storage %s, partition %s\n", args.case_name.c_str(), nodes.size(), ranks,
      args.storage.c_str(), args.partition.c_str());

  DiscretizationOptions o;
  o.gamma = {args.gamma};
  o.quadrature_points = args.points;
  o.basis_order = 1;
  o.storage = args.storage == "full" ? BasisStorage::Full : BasisStorage::Compressed;
  o.off_process = args.off_process == "exchange" ? OffProcessMode::PetscExchange : OffProcessMode::ZeroCommunication;
  o.partition = parse_partition_method(args.partition);

  Stopwatch clock;
  CpuStopwatch cpu;
  const Discretization disc(PETSC_COMM_WORLD, nodes, o);
  const double setup_s = max_over_ranks(clock.seconds());
  const double setup_cpu_s = max_over_ranks(cpu.seconds());
  const StageTimes& t = disc.times();
  const double setup_rss = max_over_ranks(peak_resident_mb());
  const Discretization::MemoryReport memory = disc.memory_report();

  const kernel::FormKernels& form = args.dim == 2 ? poisson_heat_2d : poisson_heat_3d;
  Assembler heat(disc, form);
  PetscMatrix K = heat.create_matrix();
  PetscVector zero = heat.create_vector(), b = heat.create_vector(), T = heat.create_vector();
  clock.restart();
  cpu.restart();
  heat.matrix(zero, K);
  const double matrix_s = max_over_ranks(clock.seconds());
  const double matrix_cpu_s = max_over_ranks(cpu.seconds());
  clock.restart();
  heat.vector(zero, b);
  const double vector_s = max_over_ranks(clock.seconds());
  LMEFORM_PETSC_CHECK(VecScale(b, -1.0));
  const std::vector<int> boundary = hull_boundary_nodes(disc.nodes());
  std::vector<int> original(boundary.size());
  for (std::size_t i = 0; i < boundary.size(); ++i) original[i] = disc.original_index()[static_cast<std::size_t>(boundary[i])];
  apply_dirichlet(K, b, zero, owned_dofs_of_nodes(disc, original, 1));

  const KrylovSolve solve = solve_cg_gamg(disc.comm(), K, b, T, 1e-8, 2000);
  const double solve_s = solve.seconds;
  const KSPConvergedReason reason = solve.reason;
  const PetscInt iterations = solve.iterations;
  PetscReal t_max = 0;
  LMEFORM_PETSC_CHECK(VecMax(T, nullptr, &t_max));

  const double peak = max_over_ranks(peak_resident_mb());
  long long elements = disc.n_elements(), owned_elements = 0;
  for (int e = 0; e < disc.n_elements(); ++e) owned_elements += disc.cells_domain().element_owned(e) ? 1 : 0;
  const long long max_elements = static_cast<long long>(max_over_ranks(static_cast<double>(elements)));
  const long long total_elements = sum_over_ranks(elements), distinct_elements = sum_over_ranks(owned_elements);

  JsonRecord r;
  r.set("case", args.case_name)
      .set("dim", args.dim)
      .set("nodes", static_cast<long long>(nodes.size()))
      .set("ranks", ranks)
      .set("storage", args.storage)
      .set("partition", args.partition)
      .set("off_process", args.off_process)
      .set("gamma", args.gamma)
      .set("points_per_cell", args.points)
      .set("node_set_s", nodes_s)
      .set("setup_s", setup_s)
      .set("setup_cpu_s", setup_cpu_s)
      .set("neighbour_search_s", max_over_ranks(t.neighbour_search))
      .set("cells_s", max_over_ranks(t.cells))
      .set("basis_s", max_over_ranks(t.basis))
      .set("structure_s", max_over_ranks(t.structure))
      .set("assembly_s", matrix_s + vector_s)
      .set("matrix_s", matrix_s)
      .set("matrix_cpu_s", matrix_cpu_s)
      .set("vector_s", vector_s)
      .set("solve_s", solve_s)
      .set("solve_iterations", static_cast<long long>(iterations))
      .set("solve_converged", reason > 0)
      .set("t_max", static_cast<double>(t_max))
      .set("elements_max_per_rank", max_elements)
      .set("elements_computed", total_elements)
      .set("elements_distinct", distinct_elements)
      .set("base_rss_mb", base_rss)
      .set("setup_rss_mb_per_rank", setup_rss)
      .set("peak_rss_mb_per_rank", peak)
      .set("work_rss_mb_per_rank", max_over_ranks(peak_resident_mb() - base_rss))
      .set("replicated_mb", max_over_ranks(memory.replicated_bytes / 1e6))
      .set("local_mb_per_rank", max_over_ranks(memory.local_bytes / 1e6));
  say("%s\n", r.str(0).c_str());
  if (rank0() && !args.record.empty()) {
    std::ofstream out(args.record, std::ios::app);
    std::string line = r.str(0);
    for (char& c : line)
      if (c == '\n') c = ' ';
    out << line << "\n";
  }
  return reason > 0 ? 0 : 3;
}

}  // namespace
}  // namespace lmeform::bench

int main(int argc, char** argv) {
  lmeform::PetscSession petsc(&argc, &argv);
  try {
    return lmeform::bench::run(argc, argv);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "bench_scaling: %s\n", e.what());
    return 1;
  }
}
