// Run with 2 ranks: everything assembled on PETSC_COMM_WORLD must equal, to 1e-12 relative,
// the same problem assembled on one rank (PETSC_COMM_SELF) — energies, gradients, Hessians and
// solutions, in both off-process modes and both neighbourhood strategies.
#include <gtest/gtest.h>

#include <random>

#include "assembly_fixtures.hpp"
#include "lmeform/collective_error.hpp"
#include "lmeform/convex_hull.hpp"
#include "lmeform/node_sets.hpp"
#include "reference_kernels.hpp"

namespace lmeform {
namespace {

using testing::JetKernel;

const char* const kSourceConstant[] = {"source"};

NodeSet test_nodes() {
  const Box box = Box::unit(2);
  return jitter_interior(uniform_grid(box, {13, 13, 1}), box, 0.3 / 12, 17);
}

std::vector<double> deterministic_values(std::size_t n, std::uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> u(-0.8, 0.8);
  std::vector<double> v(n);
  for (double& x : v) x = u(rng);
  return v;
}

using Result = testing::Assembled;

Result assemble(MPI_Comm comm, const NodeSet& nodes, const DiscretizationOptions& opts, const kernel::FormKernels& form,
                const std::vector<double>& u_original,
                Assembler::MatrixInsertion insertion = Assembler::MatrixInsertion::Direct) {
  const Discretization disc(comm, nodes, opts);
  return testing::assemble_all(disc, form, u_original, {}, insertion);
}

void expect_same(const Result& parallel, const Result& serial, const std::string& what) {
  EXPECT_NEAR(parallel.energy, serial.energy, 1e-12 * std::abs(serial.energy)) << what;
  EXPECT_LE(testing::max_abs_difference(parallel.gradient, serial.gradient), 1e-12 * testing::max_abs(serial.gradient)) << what;
  EXPECT_LE(testing::max_abs_difference(parallel.hessian, serial.hessian), 1e-12 * testing::max_abs(serial.hessian)) << what;
}

TEST(AssemblyMpi, RunsOnTwoRanks) { EXPECT_EQ(PetscSession::size(), 2); }

TEST(AssemblyMpi, AnErrorOnOneRankIsThrownOnEveryRank) {
  int rank = 0;
  MPI_Comm_rank(PETSC_COMM_WORLD, &rank);
  EXPECT_NO_THROW(throw_on_every_rank(PETSC_COMM_WORLD, nullptr));
  // Only rank 1 fails: rank 0 throws the same LME error, with its reason, point and neighbours.
  const std::vector<double> x{0.98970, 0.39605};
  const LmeEvaluationError original(LmeFailure::not_converged, x, 9, 0.0994, "100 iterations, tolerance 1.0e-12");
  try {
    throw_on_every_rank(PETSC_COMM_WORLD, rank == 1 ? std::make_exception_ptr(original) : nullptr);
    ADD_FAILURE() << "rank " << rank << " returned";
  } catch (const LmeEvaluationError& e) {
    EXPECT_EQ(e.reason(), LmeFailure::not_converged);
    EXPECT_EQ(e.point(), x);
    EXPECT_EQ(e.neighbour_count(), 9u);
    EXPECT_STREQ(e.what(), original.what());
  }
  // Both fail: the lowest rank's error is everyone's.
  try {
    throw_on_every_rank(PETSC_COMM_WORLD, std::make_exception_ptr(std::invalid_argument("failed on rank " + std::to_string(rank))));
    ADD_FAILURE() << "rank " << rank << " returned";
  } catch (const std::invalid_argument& e) {
    EXPECT_STREQ(e.what(), "failed on rank 0");
  }
}

TEST(AssemblyMpi, OneRankEqualsTwoRanks) {
  const NodeSet nodes = test_nodes();
  const auto scalar = JetKernel<testing::Nonlinear>::descriptor("nonlinear", nullptr, 0);
  const auto vector = JetKernel<testing::VectorField>::descriptor("vector", nullptr, 0);
  for (const auto* form : {&scalar, &vector}) {
    const auto u = deterministic_values(nodes.size() * static_cast<std::size_t>(form->dofs_per_node), 5);
    for (const auto strategy : {NeighbourhoodStrategy::CellBased, NeighbourhoodStrategy::PerPoint}) {
      for (const auto mode : {OffProcessMode::ZeroCommunication, OffProcessMode::PetscExchange}) {
        DiscretizationOptions opts;
        opts.gamma = {1.6};
        opts.quadrature_points = 3;
        opts.strategy = strategy;
        opts.off_process = mode;
        const Result serial = assemble(PETSC_COMM_SELF, nodes, opts, *form, u);
        const std::string what = std::string(form->name) + " " + to_string(strategy) + " " + to_string(mode);
        // Direct addition into the MPIAIJ diagonal and off-diagonal blocks, and MatSetValues.
        for (const auto insertion : {Assembler::MatrixInsertion::Direct, Assembler::MatrixInsertion::SetValues}) {
          const Result parallel = assemble(PETSC_COMM_WORLD, nodes, opts, *form, u, insertion);
          expect_same(parallel, serial, what + (insertion == Assembler::MatrixInsertion::Direct ? " direct" : " MatSetValues"));
        }
      }
    }
  }
}

TEST(AssemblyMpi, MetisGivesContiguousBalancedOwnership) {
  const NodeSet nodes = test_nodes();
  DiscretizationOptions opts;
  const Discretization disc(PETSC_COMM_WORLD, nodes, opts);
  EXPECT_EQ(disc.partition().offsets.front(), 0);
  EXPECT_EQ(disc.partition().offsets.back(), disc.n_nodes());
  const int owned = disc.n_owned();
  EXPECT_GT(owned, disc.n_nodes() * 4 / 10);
  EXPECT_LT(owned, disc.n_nodes() * 6 / 10);
  // Every ghost is a node of the other rank, used by an element of this rank.
  for (const int g : disc.ghost_nodes()) EXPECT_FALSE(disc.owns(g));
}

std::vector<double> solve_poisson(MPI_Comm comm, const NodeSet& nodes, OffProcessMode mode) {
  DiscretizationOptions opts;
  opts.gamma = {0.8};
  opts.quadrature_points = 6;
  opts.off_process = mode;
  const Discretization disc(comm, nodes, opts);
  const auto form = JetKernel<testing::Poisson<false>>::descriptor("heat", kSourceConstant, 1);
  Assembler assembler(disc, form);
  assembler.set_constant("source", 1.0);
  auto [K, b, T] = testing::assemble_linear_system(assembler);
  apply_dirichlet(K, b, T, owned_dofs_of_nodes(disc, hull_boundary_nodes(nodes), 1));  // T = 0 on the boundary
  testing::solve_direct(K, b, T);
  return to_original(disc, T, 1);
}

TEST(AssemblyMpi, SolverRefactorsAfterADirectFill) {
  DiscretizationOptions opts;
  opts.gamma = {1.6};
  opts.quadrature_points = 3;
  const Discretization disc(PETSC_COMM_WORLD, test_nodes(), opts);
  testing::expect_solver_refactors_after_direct_fill(disc, JetKernel<testing::Nonlinear>::descriptor("nonlinear", nullptr, 0));
}

TEST(AssemblyMpi, HeatSolutionIsTheSameOnOneAndTwoRanks) {
  const NodeSet nodes = test_nodes();
  const auto serial = solve_poisson(PETSC_COMM_SELF, nodes, OffProcessMode::ZeroCommunication);
  for (const auto mode : {OffProcessMode::ZeroCommunication, OffProcessMode::PetscExchange}) {
    const auto parallel = solve_poisson(PETSC_COMM_WORLD, nodes, mode);
    EXPECT_LE(testing::max_abs_difference(parallel, serial), 1e-12 * testing::max_abs(serial)) << to_string(mode);
  }
  EXPECT_GT(testing::max_abs(serial), 1e-3);
}

}  // namespace
}  // namespace lmeform
