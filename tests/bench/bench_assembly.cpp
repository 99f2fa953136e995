// Assembly benchmarks of issue 4 (seed 4.1, Fig. 6-9): `bench_assembly [--quick] [--out DIR]`.
//
// 1. DIR/assembly.json: the heat problem -Lap T = 2y on a uniform grid of the unit square with the
//    generated poisson form (energy 1/2 |grad T|^2 - f T; its Hessian is the stiffness matrix),
//    for gamma in {0.8, 1.6, 4.0} x {3, 6, 12} Gauss points per Delaunay cell x grids 50^2, 100^2
//    (and 200^2 unless --quick). Each configuration is built twice, per-point (seed Algorithm 1)
//    and cell-based (Algorithm 2) neighbourhoods, with the same nodes, cells, quadrature, basis
//    values (full storage) and generated kernel, so their ratio measures the algorithm:
//      structure = Discretization::times().structure (elements, ghosts, dual lists, pattern)
//                  + Assembler::times().create_matrix (MatXAIJSetPreallocation)
//      fill      = Assembler::matrix (MatZeroEntries, element loop, one MatSetValuesBlocked per
//                  element, MatAssemblyBegin/End); best of `reps` calls.
//    The cell-based run also solves the heat problem (Dirichlet T = 0 on the convex-hull
//    boundary, MatZeroRowsColumns, CG + GAMG to rtol 1e-10; override with -ksp_type/-pc_type).
// 2. DIR/assembly_roofline.json: the Hessian of the fourth-order Helfrich bending energy
//    (helfrich.form, 2D, basis order 2) on a 100^2 grid, gamma = 1.6, 6 points per cell,
//    against an Eigen GEMM of the shape of the kernel's main contraction in the same run.
#include <mpi.h>

#include <Eigen/Core>
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <exception>
#include <limits>
#include <string>
#include <vector>

#include "bench_common.hpp"
#include "bench_mpi.hpp"
#include "cg_gamg_solve.hpp"
#include "helfrich_kernels.hpp"
#include "lmeform/assembler.hpp"
#include "lmeform/convex_hull.hpp"
#include "lmeform/discretization.hpp"
#include "lmeform/neighbourhoods.hpp"
#include "lmeform/node_sets.hpp"
#include "lmeform/petsc.hpp"
#include "lmeform/sparsity_pattern.hpp"
#include "poisson_kernels.hpp"

namespace lmeform::bench {
namespace {

const kernel::FormKernels& heat_form() { return poisson_heat_2d; }
const kernel::FormKernels& helfrich_form() { return helfrich_bending_2d; }


DiscretizationOptions heat_options(double gamma, int points, NeighbourhoodStrategy strategy) {
  DiscretizationOptions o;
  o.gamma = {gamma};
  o.quadrature_points = points;
  o.strategy = strategy;
  o.storage = BasisStorage::Full;
  o.basis_order = 1;
  return o;
}

/// Rough peak memory (GB) of one Discretization + matrix: basis values, point lists, storage lists,
/// per-point element lists and their dual lists, for a uniform grid (support radius from tol0).
double estimate_gb(int per_axis, double gamma, int points) {
  const double cells = 2.0 * (per_axis - 1) * (per_axis - 1);
  const double neighbours = M_PI * -std::log(LmeOptions{}.tol0) / gamma;  // pi r^2 / h^2
  const double entries = cells * points * neighbours;
  return entries * (3 * 8 + 4 * 4) / 1e9;
}

struct StrategyRun {
  double neighbour_search = 0, cells = 0, basis = 0, structure = 0, create_matrix = 0;
  double fill = 0, fill_kernel = 0, fill_first = 0;
  double fill_setvalues = 0;  // the same fill through MatSetValues (Assembler::MatrixInsertion::SetValues)
  double setup_cpu = 0, fill_cpu = 0;  // thread CPU time: the whole Discretization, best fill
  double mean_neighbours = 0, mean_element_nodes = 0;
  long long pattern_nonzeros = 0;
  long long elements = 0;
  // Node pairs of all elements, sum |e|^2: the visits of the pattern's construction and the
  // entries the fill adds, so the per-point / cell ratio of this sum bounds the structure ratio.
  long long element_pairs = 0;
  // cell-based only
  double union_lists = 0;  // seed Algorithm 2's union of the points' lists (inside neighbour_search)
  double rhs = 0, dirichlet = 0, solve = 0, t_max = 0;
  int iterations = 0;
  std::string solver;
};

/// -Lap T = 2y, T = 0 on the hull boundary: b = -grad E(0), K = Hess E, solve K T = b.
void solve_heat(const Discretization& disc, Assembler& heat, Mat K, StrategyRun& run) {
  PetscVector zero = heat.create_vector(), b = heat.create_vector(), T = heat.create_vector();
  Stopwatch clock;
  heat.vector(zero, b);
  LMEFORM_PETSC_CHECK(VecScale(b, -1.0));
  run.rhs = max_over_ranks(clock.seconds());

  clock.restart();
  const std::vector<int> boundary = hull_boundary_nodes(disc.nodes());  // renumbered = any order
  std::vector<int> original(boundary.size());
  for (std::size_t i = 0; i < boundary.size(); ++i) {
    original[i] = disc.original_index()[static_cast<std::size_t>(boundary[i])];
  }
  const auto dofs = owned_dofs_of_nodes(disc, original, 1);
  apply_dirichlet(K, b, zero, dofs);
  run.dirichlet = max_over_ranks(clock.seconds());

  const KrylovSolve solve = solve_cg_gamg(disc.comm(), K, b, T, 1e-10, 1000);
  run.solve = solve.seconds;
  if (solve.reason < 0) throw std::runtime_error("heat solve diverged: KSPConvergedReason " + std::to_string(solve.reason));
  run.iterations = solve.iterations;
  run.solver = solve.solver;
  PetscReal t_max = 0;
  LMEFORM_PETSC_CHECK(VecMax(T, nullptr, &t_max));
  run.t_max = t_max;
}

StrategyRun run_strategy(const NodeSet& nodes, double gamma, int points, NeighbourhoodStrategy strategy, int reps,
                         bool solve) {
  StrategyRun run;
  CpuStopwatch setup_clock;
  const Discretization disc(PETSC_COMM_WORLD, nodes, heat_options(gamma, points, strategy));
  run.setup_cpu = max_over_ranks(setup_clock.seconds());
  run.neighbour_search = max_over_ranks(disc.times().neighbour_search);
  run.cells = max_over_ranks(disc.times().cells);
  run.basis = max_over_ranks(disc.times().basis);
  run.structure = max_over_ranks(disc.times().structure);
  run.mean_neighbours = disc.mean_point_neighbours();
  run.mean_element_nodes = disc.element_lists().mean_size();
  run.elements = disc.n_elements();
  for (std::size_t e = 0; e < disc.element_lists().size(); ++e) {
    const auto size = static_cast<long long>(disc.element_lists()[e].size());
    run.element_pairs += size * size;
  }
  MPI_Allreduce(MPI_IN_PLACE, &run.element_pairs, 1, MPI_LONG_LONG, MPI_MAX, PETSC_COMM_WORLD);
  long long nnz = disc.pattern().nonzeros();
  MPI_Allreduce(MPI_IN_PLACE, &nnz, 1, MPI_LONG_LONG, MPI_SUM, PETSC_COMM_WORLD);
  run.pattern_nonzeros = nnz;
  if (strategy == NeighbourhoodStrategy::CellBased) {
    // The Discretization counts the union in neighbour_search; timed again here on its own.
    Stopwatch clock;
    const CsrLists unions = union_of_groups(disc.point_lists(), points, disc.n_nodes());
    run.union_lists = max_over_ranks(clock.seconds());
    if (unions.size() * static_cast<std::size_t>(points) != disc.point_lists().size()) {
      throw std::logic_error("union_of_groups: unexpected number of cells");
    }
  }

  Assembler heat(disc, heat_form());
  PetscMatrix K = heat.create_matrix();
  run.create_matrix = max_over_ranks(heat.times().create_matrix);
  // The structure is built once per Discretization; rebuilt here `reps` times (dual lists, the
  // pattern of this rank's rows, the matrix) so that its ratio is a best of several like the fill's.
  for (int r = 1; r < reps; ++r) {
    Stopwatch clock;
    const CsrLists dual = dual_lists(disc.element_lists(), disc.n_nodes());
    const CsrLists& elements = disc.element_lists();
    const SparsityPattern pattern = build_sparsity_pattern(elements.offsets, elements.indices, dual.offsets, dual.indices,
                                                           disc.n_nodes(), disc.owned_begin(), disc.owned_end());
    run.structure = std::min(run.structure, max_over_ranks(clock.seconds()));
    if (pattern.nonzeros() != disc.pattern().nonzeros()) throw std::logic_error("the rebuilt pattern differs from the discretization's");
    PetscMatrix again = heat.create_matrix();
    run.create_matrix = std::min(run.create_matrix, max_over_ranks(heat.times().create_matrix));
  }
  PetscVector u = heat.create_vector();
  run.fill = std::numeric_limits<double>::infinity();
  run.fill_cpu = std::numeric_limits<double>::infinity();
  for (int r = 0; r < reps; ++r) {
    CpuStopwatch cpu;
    heat.matrix(u, K);
    run.fill_cpu = std::min(run.fill_cpu, max_over_ranks(cpu.seconds()));
    const double fill = max_over_ranks(heat.times().matrix);
    if (r == 0) run.fill_first = fill;
    if (fill < run.fill) {
      run.fill = fill;
      run.fill_kernel = max_over_ranks(heat.times().matrix_kernel);
    }
  }
  {
    // The same fill with PETSc's MatSetValues insertion instead of the direct AIJ addition.
    PetscMatrix K_set = heat.create_matrix(Assembler::MatrixInsertion::SetValues);
    run.fill_setvalues = std::numeric_limits<double>::infinity();
    for (int r = 0; r < reps; ++r) {
      heat.matrix(u, K_set);
      run.fill_setvalues = std::min(run.fill_setvalues, max_over_ranks(heat.times().matrix));
    }
  }
  if (solve) solve_heat(disc, heat, K, run);
  return run;
}

/// Restricts the heat sweep to one grid / gamma / rule (0: all): --grid N --gamma G --points Q.
struct SweepFilter {
  int grid = 0;
  double gamma = 0;
  int points = 0;
  bool skip_roofline = false;
};

SweepFilter parse_filter(int& argc, char** argv) {
  SweepFilter f;
  int kept = 1;
  for (int i = 1; i < argc; ++i) {
    const std::string arg = argv[i];
    if (arg == "--grid" && i + 1 < argc) {
      f.grid = std::stoi(argv[++i]);
    } else if (arg == "--gamma" && i + 1 < argc) {
      f.gamma = std::stod(argv[++i]);
    } else if (arg == "--points" && i + 1 < argc) {
      f.points = std::stoi(argv[++i]);
    } else if (arg == "--no-roofline") {
      f.skip_roofline = true;
    } else {
      argv[kept++] = argv[i];
    }
  }
  argc = kept;
  argv[argc] = nullptr;
  return f;
}

template <class T>
std::vector<T> select(std::vector<T> all, T only) {
  if (only != T{}) all.assign(1, only);
  return all;
}

std::vector<JsonRecord> heat_benchmark(bool quick, const SweepFilter& filter, JsonRecord& meta) {
  const std::vector<int> grids = select(quick ? std::vector<int>{50, 100} : std::vector<int>{50, 100, 200}, filter.grid);
  const std::vector<double> gammas = select(std::vector<double>{0.8, 1.6, 4.0}, filter.gamma);
  const std::vector<int> rules = select(std::vector<int>{3, 6, 12}, filter.points);
  const int reps = quick ? 1 : 3;  // the first fill (into the empty preallocated rows) costs the same as later ones
  const double max_gb = 12.0;
  meta.set("fill_repetitions", reps).set("basis_storage", "full").set("form", "poisson.form heat (2D)");
  meta.set("ranks", PetscSession::size());

  std::vector<JsonRecord> records;
  say("\nheat problem -Lap T = 2y: per-point (pt) vs cell-based (cell) neighbourhoods; times in s\n");
  say("%6s %4s %3s %6s %6s | %8s %8s %6s | %8s %8s %6s | %6s | %7s %7s %7s %7s %7s | %8s %6s %6s %7s\n", "nodes", "gam", "nq",
      "nbrs", "cellN", "str_pt", "str_cell", "x", "fill_pt", "fill_cl", "x", "nnz_x", "search", "basis", "struct", "fill",
      "solve", "fill_set", "x", "set_x", "pairs_x");
  for (const int n : grids) {
    const NodeSet nodes = uniform_grid(Box::unit(2), {n, n, 1});
    for (const double gamma : gammas) {
      for (const int points : rules) {
        const double gb = estimate_gb(n, gamma, points);
        if (gb > max_gb) {
          say("%6d %4.1f %3d skipped: estimated %.1f GB > %.1f GB\n", n * n, gamma, points, gb, max_gb);
          continue;
        }
        const StrategyRun pt = run_strategy(nodes, gamma, points, NeighbourhoodStrategy::PerPoint, reps, false);
        const StrategyRun cell = run_strategy(nodes, gamma, points, NeighbourhoodStrategy::CellBased, reps, true);
        const double s_pt = pt.structure + pt.create_matrix;
        const double s_cell = cell.structure + cell.create_matrix;
        JsonRecord r;
        r.set("gamma", gamma)
            .set("gauss_points_per_cell", points)
            .set("nodes", n * n)
            .set("mean_neighbours", cell.mean_neighbours)
            .set("structure_s_point", s_pt)
            .set("structure_s_cell", s_cell)
            .set("fill_s_point", pt.fill)
            .set("fill_s_cell", cell.fill)
            .set("structure_speedup", s_pt / s_cell)
            .set("fill_speedup", pt.fill / cell.fill)
            // the seed's heat-equation stages, cell-based run
            .set("neighbour_search_s", cell.neighbour_search)
            .set("cells_s", cell.cells)
            .set("basis_s", cell.basis)
            .set("structure_s", s_cell)
            .set("fill_s", cell.fill)
            .set("rhs_s", cell.rhs)
            .set("dirichlet_s", cell.dirichlet)
            .set("solve_s", cell.solve)
            .set("solver", cell.solver)
            .set("solver_iterations", cell.iterations)
            .set("t_max", cell.t_max)
            // what the ratios are made of
            .set("neighbour_search_s_point", pt.neighbour_search)
            .set("basis_s_point", pt.basis)
            .set("union_s_cell", cell.union_lists)
            .set("create_matrix_s_point", pt.create_matrix)
            .set("create_matrix_s_cell", cell.create_matrix)
            .set("fill_first_s_point", pt.fill_first)
            .set("fill_first_s_cell", cell.fill_first)
            .set("fill_cpu_s_point", pt.fill_cpu)
            .set("fill_cpu_s_cell", cell.fill_cpu)
            .set("fill_speedup_cpu", pt.fill_cpu / cell.fill_cpu)
            .set("setup_cpu_s_point", pt.setup_cpu)
            .set("setup_cpu_s_cell", cell.setup_cpu)
            .set("fill_setvalues_s_point", pt.fill_setvalues)
            .set("fill_setvalues_s_cell", cell.fill_setvalues)
            .set("direct_insertion_speedup_cell", cell.fill_setvalues / cell.fill)
            .set("fill_speedup_setvalues", pt.fill_setvalues / cell.fill_setvalues)
            .set("fill_kernel_s_point", pt.fill_kernel)
            .set("fill_kernel_s_cell", cell.fill_kernel)
            .set("mean_cell_nodes", cell.mean_element_nodes)
            .set("elements_point", pt.elements)
            .set("elements_cell", cell.elements)
            .set("pattern_nonzeros_point", pt.pattern_nonzeros)
            .set("pattern_nonzeros_cell", cell.pattern_nonzeros)
            .set("element_pairs_point", pt.element_pairs)
            .set("element_pairs_cell", cell.element_pairs)
            .set("element_pairs_ratio", static_cast<double>(pt.element_pairs) / static_cast<double>(cell.element_pairs));
        records.push_back(std::move(r));
        say("%6d %4.1f %3d %6.1f %6.1f | %8.4f %8.4f %6.1f | %8.4f %8.4f %6.1f | %6.2f | %7.3f %7.3f %7.3f %7.3f %7.3f | "
            "%8.4f %6.1f %6.1f %7.1f\n",
            n * n, gamma, points, cell.mean_neighbours, cell.mean_element_nodes, s_pt, s_cell, s_pt / s_cell, pt.fill,
            cell.fill, pt.fill / cell.fill,
            static_cast<double>(cell.pattern_nonzeros) / static_cast<double>(pt.pattern_nonzeros),
            cell.neighbour_search, cell.basis, s_cell, cell.fill, cell.solve, cell.fill_setvalues,
            cell.fill_setvalues / cell.fill, pt.fill_setvalues / cell.fill_setvalues,
            static_cast<double>(pt.element_pairs) / static_cast<double>(cell.element_pairs));
      }
    }
  }
  return records;
}

/// Best GFLOP/s of an (n x k) * (k x n) row-major Eigen product, the shape of the kernel's
/// H = Bs^T (D Bs) contraction, repeated for at least `seconds`.
double eigen_gemm_gflops(int n, int k, double seconds) {
  using RowMatrix = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;
  const RowMatrix Bt = RowMatrix::Random(k, n);
  const RowMatrix S = RowMatrix::Random(k, n);
  RowMatrix H = RowMatrix::Zero(n, n);
  const double flops = 2.0 * n * n * static_cast<double>(k);
  double best = 0;
  Stopwatch total;
  do {
    const int inner = std::max(1, static_cast<int>(2e7 / flops));
    Stopwatch clock;
    for (int i = 0; i < inner; ++i) H.noalias() += Bt.transpose() * S;
    best = std::max(best, flops * inner / clock.seconds() / 1e9);
  } while (total.seconds() < seconds);
  if (!std::isfinite(H.sum())) throw std::runtime_error("gemm produced non-finite values");
  return best;
}

JsonRecord roofline_benchmark(bool quick) {
  const int per_axis = 100;
  const double gamma = 1.6;
  const int points = 6;
  const int reps = quick ? 2 : 5;
  const NodeSet nodes = uniform_grid(Box::unit(2), {per_axis, per_axis, 1});
  DiscretizationOptions o;
  o.gamma = {gamma};
  o.quadrature_points = points;
  o.strategy = NeighbourhoodStrategy::CellBased;
  o.storage = BasisStorage::Full;
  o.basis_order = 2;
  const Discretization disc(PETSC_COMM_WORLD, nodes, o);
  const kernel::FormKernels& form = helfrich_form();
  Assembler helfrich(disc, form);
  const double eps = 0.04;
  helfrich.set_constant("k", 1.0);
  helfrich.set_constant("eps", eps);
  helfrich.set_constant("C0", 0.0);

  // A vesicle: phi = tanh((0.3 - r) / (sqrt2 eps)), +1 inside.
  std::vector<double> phi(nodes.size());
  for (std::size_t a = 0; a < nodes.size(); ++a) {
    const double x = nodes.coords[2 * a] - 0.5, y = nodes.coords[2 * a + 1] - 0.5;
    phi[a] = std::tanh((0.3 - std::hypot(x, y)) / (std::sqrt(2.0) * eps));
  }
  PetscVector u = helfrich.create_vector();
  set_from_original(disc, phi, 1, u);
  PetscMatrix H = helfrich.create_matrix();

  double fill = std::numeric_limits<double>::infinity(), kernel_s = 0;
  for (int r = 0; r < reps; ++r) {
    helfrich.matrix(u, H);
    const double t = max_over_ranks(helfrich.times().matrix);
    if (t < fill) {
      fill = t;
      kernel_s = max_over_ranks(helfrich.times().matrix_kernel);
    }
  }

  // Flops of this rank's elements from the generated flop model, and the part of it that is the
  // dense n x n contraction (the model's n^2 term: 2 S flops per node pair and point per block).
  double model_flops = 0, pair_flops = 0, mean_n = 0;
  const auto& fm = form.flop_model_matrix;
  for (int e = 0; e < disc.n_elements(); ++e) {
    const int n = static_cast<int>(disc.element_nodes(e).size());
    const int nq = disc.element_point_count(e);
    model_flops += fm(n, nq);
    pair_flops += static_cast<double>(nq) * n * n * fm.per_node_pair_point;
    mean_n += n;
  }
  mean_n /= std::max(1, disc.n_elements());
  MPI_Allreduce(MPI_IN_PLACE, &model_flops, 1, MPI_DOUBLE, MPI_SUM, PETSC_COMM_WORLD);
  MPI_Allreduce(MPI_IN_PLACE, &pair_flops, 1, MPI_DOUBLE, MPI_SUM, PETSC_COMM_WORLD);
  const double gflops = model_flops / fill / 1e9;
  const double kernel_gflops = model_flops / kernel_s / 1e9;

  // The kernel's contraction is n x (nq S) times (nq S) x n, S = jet slots it reads
  // (per_node_pair_point = 2 S for the one scalar block).
  const int slots = std::max(1, static_cast<int>(std::lround(fm.per_node_pair_point / 2.0)));
  const int n_typical = static_cast<int>(std::lround(mean_n));
  const int inner = points * slots;
  const double dgemm = eigen_gemm_gflops(n_typical, inner, quick ? 0.5 : 2.0);
  const int jet = kernel::jet_size(2, 2);
  const double dgemm_jet = eigen_gemm_gflops(n_typical, points * jet, quick ? 0.5 : 2.0);

  JsonRecord r;
  r.set("form", std::string(form.module) + "/" + form.name + " (2D, basis order 2)")
      .set("nodes", per_axis * per_axis)
      .set("gamma", gamma)
      .set("gauss_points_per_cell", points)
      .set("eps", eps)
      .set("elements", static_cast<long long>(disc.n_elements()))
      .set("mean_cell_nodes", mean_n)
      .set("mean_neighbours", disc.mean_point_neighbours())
      .set("hessian_assembly_s", fill)
      .set("hessian_kernel_s", kernel_s)
      .set("flops", model_flops)
      .set("flops_source", "generated FormKernels::flop_model_matrix summed over the cells")
      .set("flops_dense_contraction_fraction", pair_flops / model_flops)
      .set("hessian_assembly_gflops", gflops)
      .set("hessian_kernel_gflops", kernel_gflops)
      .set("dgemm_shape", std::to_string(n_typical) + "x" + std::to_string(inner) + " * " + std::to_string(inner) +
                              "x" + std::to_string(n_typical) + " (Eigen, row-major, same compiler flags)")
      .set("dgemm_gflops", dgemm)
      .set("fraction_of_dgemm", gflops / dgemm)
      .set("kernel_fraction_of_dgemm", kernel_gflops / dgemm)
      .set("dgemm_gflops_full_jet", dgemm_jet)
      .set("dgemm_full_jet_inner", points * jet);
  say("\nHelfrich Hessian, 100^2 nodes, gamma %.1f, %d points/cell, %d cells of %.0f nodes (mean)\n", gamma, points,
      disc.n_elements(), mean_n);
  say("  assembly %.3f s (kernel+tabulation %.3f s), %.3g flops (model; %.0f %% in the n^2 contraction)\n", fill,
      kernel_s, model_flops, 100 * pair_flops / model_flops);
  say("  assembly %.2f GFLOP/s, kernel %.2f GFLOP/s; Eigen GEMM %dx%d*%dx%d %.2f GFLOP/s (inner %d: %.2f)\n", gflops,
      kernel_gflops, n_typical, inner, inner, n_typical, dgemm, points * jet, dgemm_jet);
  say("  fraction of GEMM: assembly %.2f, kernel %.2f\n", gflops / dgemm, kernel_gflops / dgemm);
  return r;
}

}  // namespace
}  // namespace lmeform::bench

int main(int argc, char** argv) {
  using namespace lmeform::bench;
  const SweepFilter filter = parse_filter(argc, argv);
  const BenchOptions options = parse_bench_options(argc, argv);
  lmeform::PetscSession session(&argc, &argv);
  try {
    for (const auto& u : options.unknown) say("bench_assembly: ignoring unknown option %s\n", u.c_str());
    Stopwatch total;
    JsonRecord meta;
    auto records = heat_benchmark(options.quick, filter, meta);
    meta.set("total_s", total.seconds());
    if (rank0()) write_json(options.out / "assembly.json", "assembly", options.quick, meta, records);
    say("\nwrote %s (%.1f s)\n", (options.out / "assembly.json").c_str(), total.seconds());
    if (!filter.skip_roofline) {
      const JsonRecord roofline = roofline_benchmark(options.quick);
      if (rank0()) write_json_object(options.out / "assembly_roofline.json", roofline);
      say("wrote %s (%.1f s)\n", (options.out / "assembly_roofline.json").c_str(), total.seconds());
    }
  } catch (const std::exception& e) {
    std::fprintf(stderr, "bench_assembly: %s\n", e.what());
    return 1;
  }
  return 0;
}
