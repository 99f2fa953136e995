// One round of alternate minimization, group by group: what a group's Newton matrix costs with the
// whole (u, v) structure against the group's own (Assembler::create_matrix with coupled
// components, which the staggered driver's group solves use).
//
//   bench_staggered [--quick] [--out DIR] [--reps R]        writes DIR/staggered.json
//
// The fracture form (forms/fracture_at2.form: elastic with the volumetric-deviatoric split, and
// the AT2 surface energy, l = 0.015) on a strongly graded node set (spacing 0.0075 = l/2 within
// 0.15 of the centre, 0.05 outside), γ = 1.4, 3 points per cell, a state with damage across the
// square. For each group (u: components 0, 1; v: component 2) and each structure, best of R:
//   create   create_matrix (the structure, once per group solve in the driver)
//   assemble the Hessian of elastic + surface (matrix_sum)
//   factor   MatZeroRowsColumns on the other group's dofs, then MUMPS LU with its analysis (a
//            group solve makes its own solver, so the analysis is part of each)
//   solve    one solve with a fixed right-hand side
// The two structures must give the same solution (relative 1e-10), else the benchmark fails.
#include <mpi.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <exception>
#include <filesystem>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "bench_common.hpp"
#include "bench_mpi.hpp"
#include "fracture_at2_kernels.hpp"
#include "lmeform/assembler.hpp"
#include "lmeform/discretization.hpp"
#include "lmeform/node_sets.hpp"
#include "lmeform/output.hpp"
#include "lmeform/petsc.hpp"

namespace lmeform::bench {
namespace {

constexpr double kMaxRelativeDifference = 1e-10;

struct Timing {
  double create = 1e300, assemble = 1e300, factor = 1e300, solve = 1e300;
  PetscInt nonzeros = 0;
  std::vector<double> solution;
};

void set_fracture_constants(Assembler& a) {
  const std::vector<std::pair<const char*, double>> constants{{"lambda", 121.15}, {"mu", 80.77}, {"Gc", 2.7e-3},
                                                              {"l", 0.015},       {"k", 1e-6},   {"split", 1.0}, {"split_width", 0.0}};
  for (int i = 0; i < a.form().n_constants; ++i)
    for (const auto& [name, value] : constants)
      if (std::string(name) == a.form().constants[i]) a.set_constant(name, value);
}

Timing time_group(Assembler& elastic, Assembler& surface, Vec u, const std::vector<PetscInt>& fixed, const std::vector<int>& coupled,
                  int reps) {
  Timing t;
  PetscVector rhs = elastic.create_vector(), x = elastic.create_vector();
  LMEFORM_PETSC_CHECK(VecSet(rhs, 1.0));
  for (int r = 0; r < reps; ++r) {
    Stopwatch clock;
    PetscMatrix H = elastic.create_matrix(Assembler::MatrixInsertion::Direct, coupled);
    t.create = std::min(t.create, max_over_ranks(clock.seconds()));
    clock.restart();
    const std::vector<Assembler::MatrixTerm> terms{{&elastic, 1.0}, {&surface, 1.0}};
    elastic.matrix_sum(u, terms, H);
    t.assemble = std::min(t.assemble, max_over_ranks(clock.seconds()));
    clock.restart();
    LMEFORM_PETSC_CHECK(MatZeroRowsColumns(H, static_cast<PetscInt>(fixed.size()), fixed.data(), 1.0, nullptr, nullptr));
    PetscLinearSolver ksp;
    LMEFORM_PETSC_CHECK(KSPCreate(PETSC_COMM_WORLD, ksp.out()));
    LMEFORM_PETSC_CHECK(KSPSetType(ksp, KSPPREONLY));
    PC pc = nullptr;
    LMEFORM_PETSC_CHECK(KSPGetPC(ksp, &pc));
    LMEFORM_PETSC_CHECK(PCSetType(pc, PCLU));
    LMEFORM_PETSC_CHECK(PCFactorSetMatSolverType(pc, MATSOLVERMUMPS));
    LMEFORM_PETSC_CHECK(KSPSetOperators(ksp, H, H));
    LMEFORM_PETSC_CHECK(KSPSetUp(ksp));
    t.factor = std::min(t.factor, max_over_ranks(clock.seconds()));
    clock.restart();
    LMEFORM_PETSC_CHECK(KSPSolve(ksp, rhs, x));
    t.solve = std::min(t.solve, max_over_ranks(clock.seconds()));
    MatInfo info;
    LMEFORM_PETSC_CHECK(MatGetInfo(H, MAT_GLOBAL_SUM, &info));
    t.nonzeros = static_cast<PetscInt>(info.nz_used);
  }
  t.solution = to_original(elastic.discretization(), x, 3);
  return t;
}

}  // namespace
}  // namespace lmeform::bench

int main(int argc, char** argv) {
  using namespace lmeform;
  using namespace lmeform::bench;
  int reps = 0;
  int kept = 1;
  for (int i = 1; i < argc; ++i) {
    if (std::string(argv[i]) == "--reps" && i + 1 < argc) reps = std::atoi(argv[++i]);
    else argv[kept++] = argv[i];
  }
  argc = kept;
  const BenchOptions options = parse_bench_options(argc, argv);
  PetscSession session(&argc, &argv);
  try {
    for (const auto& u : options.unknown) say("bench_staggered: ignoring unknown option %s\n", u.c_str());
    if (reps <= 0) reps = options.quick ? 2 : 5;
    GradedGridOptions graded;
    graded.h_min = 0.0075;
    graded.h_max = 0.05;
    graded.radius = 0.15;
    graded.transition = 0.15;
    const NodeSet nodes = graded_grid_2d(graded);
    DiscretizationOptions o;
    o.gamma = {1.4};
    o.quadrature_points = 3;
    const Discretization disc(PETSC_COMM_WORLD, nodes, o);
    Assembler elastic(disc, fracture_at2_elastic_2d), surface(disc, fracture_at2_surface_2d);
    set_fracture_constants(elastic);
    set_fracture_constants(surface);
    std::vector<double> state(nodes.size() * 3);
    for (std::size_t a = 0; a < nodes.size(); ++a) {
      const double x = nodes.coords[2 * a], y = nodes.coords[2 * a + 1];
      state[3 * a] = 1e-3 * x * y;
      state[3 * a + 1] = 2e-3 * y - 1e-3 * x * x;
      state[3 * a + 2] = 1.0 - std::exp(-std::abs(y - 0.5) / 0.015);  // a crack along y = 1/2
    }
    PetscVector u = elastic.create_vector();
    set_from_original(disc, state, 3, u);

    say("staggered groups' Newton matrices: fracture_at2 (elastic with split + AT2 surface), %zu nodes, gamma 1.4, "
        "3 points per cell, %d rank(s), best of %d; seconds\n",
        nodes.size(), disc.ranks(), reps);
    say("%6s %9s %10s %8s %8s %8s %8s %8s %9s\n", "group", "structure", "nonzeros", "create", "assemble", "factor", "solve", "total",
        "rel diff");
    nlohmann::json records = nlohmann::json::array();
    bool agree = true;
    const std::vector<std::pair<std::string, std::vector<int>>> groups{{"u", {0, 1}}, {"v", {2}}};
    for (const auto& [name, coupled] : groups) {
      std::vector<PetscInt> fixed;
      for (int b = disc.owned_begin(); b < disc.owned_end(); ++b)
        for (int c = 0; c < 3; ++c)
          if (std::find(coupled.begin(), coupled.end(), c) == coupled.end()) fixed.push_back(static_cast<PetscInt>(b) * 3 + c);
      const Timing full = time_group(elastic, surface, u, fixed, {}, reps);
      const Timing own = time_group(elastic, surface, u, fixed, coupled, reps);
      double diff = 0, scale = 0;
      for (std::size_t i = 0; i < full.solution.size(); ++i) {
        diff = std::max(diff, std::abs(full.solution[i] - own.solution[i]));
        scale = std::max(scale, std::abs(full.solution[i]));
      }
      const double relative = diff / scale;
      agree = agree && relative <= kMaxRelativeDifference;
      const auto total = [](const Timing& t) { return t.create + t.assemble + t.factor + t.solve; };
      for (const auto* t : {&full, &own})
        say("%6s %9s %10lld %8.4f %8.4f %8.4f %8.4f %8.4f %9.1e\n", name.c_str(), t == &full ? "whole" : "group",
            static_cast<long long>(t->nonzeros), t->create, t->assemble, t->factor, t->solve, total(*t), relative);
      say("%6s %9s %10.2f %8.2f %8.2f %8.2f %8.2f %8.2f\n", name.c_str(), "ratio", double(full.nonzeros) / double(own.nonzeros),
          full.create / own.create, full.assemble / own.assemble, full.factor / own.factor, full.solve / own.solve,
          total(full) / total(own));
      records.push_back({{"group", name},
                         {"nodes", nodes.size()},
                         {"ranks", disc.ranks()},
                         {"reps", reps},
                         {"nonzeros_whole", full.nonzeros},
                         {"nonzeros_group", own.nonzeros},
                         {"create_s_whole", full.create},
                         {"create_s_group", own.create},
                         {"assemble_s_whole", full.assemble},
                         {"assemble_s_group", own.assemble},
                         {"factor_s_whole", full.factor},
                         {"factor_s_group", own.factor},
                         {"solve_s_whole", full.solve},
                         {"solve_s_group", own.solve},
                         {"total_ratio", total(full) / total(own)},
                         {"solution_relative_difference", relative}});
    }
    if (rank0()) {
      std::filesystem::create_directories(options.out);
      write_text_atomically(options.out / "staggered.json", records.dump(2) + "\n");
    }
    say("wrote %s\n", (options.out / "staggered.json").c_str());
    if (!agree) {
      std::fprintf(stderr, "bench_staggered: the group's own structure gave another solution (relative difference above %.0e)\n",
                   kMaxRelativeDifference);
      return 1;
    }
  } catch (const std::exception& e) {
    std::fprintf(stderr, "bench_staggered: %s\n", e.what());
    return 1;
  }
  return 0;
}
