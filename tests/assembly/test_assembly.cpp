// Serial tests of the assembly engine with hand-written reference kernels.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <numbers>
#include <random>
#include <set>

#include "assembly_fixtures.hpp"
#include "lmeform/convex_hull.hpp"
#include "lmeform/node_sets.hpp"
#include "lmeform/quadrature_adequacy.hpp"
#include "reference_kernels.hpp"

namespace lmeform {
namespace {

using testing::Bilaplacian;
using testing::JetKernel;
using testing::ManufacturedError;
using testing::Nonlinear;
using testing::Poisson;
using testing::VectorField;

const char* const kSourceConstant[] = {"source"};

NodeSet jittered_grid(int per_axis, double amplitude, std::uint64_t seed) {
  const Box box = Box::unit(2);
  const NodeSet grid = uniform_grid(box, {per_axis, per_axis, 1});
  return jitter_interior(grid, box, amplitude / (per_axis - 1), seed);
}

std::vector<double> random_values(std::size_t n, std::uint64_t seed, double scale = 1.0) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> u(-scale, scale);
  std::vector<double> v(n);
  for (double& x : v) x = u(rng);
  return v;
}

DiscretizationOptions options(double gamma, int points, NeighbourhoodStrategy strategy,
                              BasisStorage storage = BasisStorage::Full, int order = 1) {
  DiscretizationOptions o;
  o.gamma = {gamma};
  o.quadrature_points = points;
  o.strategy = strategy;
  o.storage = storage;
  o.basis_order = order;
  return o;
}

using testing::assemble_all;

TEST(Assembly, PatternCoversEveryKernelContribution) {
  // A dense reference assembled element by element must equal the PETSc matrix, which was
  // preallocated from the pattern with new nonzeros forbidden.
  const NodeSet nodes = jittered_grid(11, 0.3, 3);
  const Discretization disc(PETSC_COMM_SELF, nodes, options(0.8, 6, NeighbourhoodStrategy::CellBased));
  const auto form = JetKernel<Poisson<false>>::descriptor("poisson", kSourceConstant, 1);
  const double source = 1.0;
  const auto assembled = assemble_all(disc, form, std::vector<double>(nodes.size(), 0.0), {&source, 1});

  const int n = disc.n_nodes();
  std::vector<double> dense(static_cast<std::size_t>(n * n), 0.0);
  std::vector<double> tab(static_cast<std::size_t>(disc.max_element_points() * 3 * disc.max_element_nodes()));
  std::vector<double> local;
  std::vector<double> zeros(static_cast<std::size_t>(disc.max_element_nodes()), 0.0);
  LmeWorkspace ws;
  for (int e = 0; e < disc.n_elements(); ++e) {
    const auto list = disc.element_nodes(e);
    const int m = static_cast<int>(list.size());
    disc.tabulate(e, 1, tab, ws);
    kernel::CellInputs in;
    in.n_nodes = m;
    in.n_points = disc.element_point_count(e);
    in.basis_order = 1;
    in.weights = disc.quadrature().weights.data() + disc.element_first_point(e);
    in.points = disc.quadrature().points.data() + 2 * disc.element_first_point(e);
    in.basis = tab.data();
    in.unknowns = zeros.data();
    in.constants = &source;
    local.assign(static_cast<std::size_t>(m * m), 0.0);
    form.matrix(in, local.data());
    for (int a = 0; a < m; ++a) {
      for (int b = 0; b < m; ++b) {
        const int oa = disc.original_index()[static_cast<std::size_t>(list[static_cast<std::size_t>(a)])];
        const int ob = disc.original_index()[static_cast<std::size_t>(list[static_cast<std::size_t>(b)])];
        dense[static_cast<std::size_t>(oa * n + ob)] += local[static_cast<std::size_t>(a * m + b)];
      }
    }
  }
  const double scale = testing::max_abs(dense);
  EXPECT_GT(scale, 0.0);
  EXPECT_LE(testing::max_abs_difference(dense, assembled.hessian), 1e-13 * scale);
  // The pattern holds exactly the pairs that share an element list: checked against a brute-force
  // set. (Pairs that share a cell but no quadrature point are in it with value 0: the price of
  // cell-based coarsening.)
  std::set<std::pair<int, int>> pairs;
  for (int e = 0; e < disc.n_elements(); ++e) {
    for (const int a : disc.element_nodes(e)) {
      for (const int b : disc.element_nodes(e)) pairs.emplace(a, b);
    }
  }
  std::set<std::pair<int, int>> pattern;
  for (int r = 0; r < disc.pattern().n_rows(); ++r) {
    for (const int b : disc.pattern().row(r)) pattern.emplace(r + disc.pattern().row_begin, b);
  }
  EXPECT_EQ(pattern, pairs);
  long long structural = 0;
  for (const double v : dense) structural += v != 0.0 ? 1 : 0;
  EXPECT_LE(structural, disc.pattern().nonzeros());
  std::printf("pattern %lld entries, %lld structurally non-zero (%.1f %%)\n", disc.pattern().nonzeros(), structural,
              100.0 * static_cast<double>(structural) / static_cast<double>(disc.pattern().nonzeros()));
}

TEST(Assembly, CellBasedAndPerPointAssembleTheSameOperator) {
  const NodeSet nodes = jittered_grid(10, 0.3, 5);
  const auto form = JetKernel<Nonlinear>::descriptor("nonlinear", nullptr, 0);
  const auto u = random_values(nodes.size(), 11);
  for (const BasisStorage storage : {BasisStorage::Full, BasisStorage::Compressed}) {
    const Discretization cell(PETSC_COMM_SELF, nodes, options(1.6, 6, NeighbourhoodStrategy::CellBased, storage));
    const Discretization point(PETSC_COMM_SELF, nodes, options(1.6, 6, NeighbourhoodStrategy::PerPoint, storage));
    const auto a = assemble_all(cell, form, u);
    const auto b = assemble_all(point, form, u);
    EXPECT_NEAR(a.energy, b.energy, 1e-12 * std::abs(a.energy)) << to_string(storage);
    EXPECT_LE(testing::max_abs_difference(a.gradient, b.gradient), 1e-12 * testing::max_abs(a.gradient));
    EXPECT_LE(testing::max_abs_difference(a.hessian, b.hessian), 1e-12 * testing::max_abs(a.hessian));
    EXPECT_LT(cell.n_elements(), point.n_elements());
  }
}

TEST(Assembly, EveryPointListHoldsItsCellVertices) {
  // So that each quadrature point lies in the convex hull of its list, also on a strongly graded
  // node set where a fine node's support can end short of a point of a long cell.
  GradedGridOptions g;
  g.h_min = 0.004;
  g.h_max = 0.08;
  g.transition = 0.05;
  const NodeSet nodes = graded_grid_2d(g);
  const Discretization disc(PETSC_COMM_SELF, nodes, options(0.5, 6, NeighbourhoodStrategy::CellBased));
  const auto& lists = disc.point_lists();
  const int nq = disc.quadrature().points_per_cell;
  for (std::size_t q = 0; q < lists.size(); ++q) {
    const auto list = lists[q];
    for (const int v : disc.cells().cell(q / static_cast<std::size_t>(nq))) {
      ASSERT_TRUE(std::binary_search(list.begin(), list.end(), v)) << "point " << q << " misses vertex " << v;
    }
  }
}

TEST(Assembly, AFacetPointWhoseSupportsAllLieOnOneSideIsEvaluated) {
  // Coarse nodes (h = 0.1) up to y = 0.5, fine ones (h = 0.01) from y = 0.6. A facet from a coarse
  // node to a fine one has every node whose support reaches its middle below it (gamma 4: the fine
  // supports end short of it), so the middle lies on the boundary of its list's hull; the vertices
  // of the cell above join, at Gaussian factors of e^-80 there. The dual Newton then needs more
  // than 100 iterations (measured: failed at 100 with the facet's vertices alone and with the
  // cell's, passes at 200 with either).
  std::vector<double> coords;
  for (int i = 0; i <= 4; ++i)
    for (int j = 0; j <= 5; ++j) coords.insert(coords.end(), {0.6 + 0.1 * i, 0.1 * j});
  for (int i = 0; i <= 40; ++i)
    for (int j = 0; j <= 10; ++j) coords.insert(coords.end(), {0.6 + 0.01 * i, 0.6 + 0.01 * j});
  const NodeSet nodes(2, std::move(coords));
  DiscretizationOptions opts = options(4.0, 6, NeighbourhoodStrategy::CellBased);
  opts.consistent_integration = 3;  // a point at each facet's middle
  const Discretization disc(PETSC_COMM_SELF, nodes, opts);
  // The corrected gradients still reproduce affine fields: sum_a grad p_a x_a = I at every point.
  LmeWorkspace ws;
  double worst = 0;
  for (int e = 0; e < disc.n_elements(); ++e) {
    const auto list = disc.element_nodes(e);
    const int points = disc.element_point_count(e);
    const std::size_t J = 3;
    std::vector<double> tab(static_cast<std::size_t>(points) * J * list.size());
    disc.tabulate(e, 1, tab, ws);
    for (int q = 0; q < points; ++q)
      for (std::size_t i = 0; i < 2; ++i)
        for (std::size_t j = 0; j < 2; ++j) {
          double g = 0;
          for (std::size_t m = 0; m < list.size(); ++m)
            g += tab[(static_cast<std::size_t>(q) * J + 1 + i) * list.size() + m] * disc.nodes().point(static_cast<std::size_t>(list[m]))[j];
          worst = std::max(worst, std::abs(g - (i == j ? 1.0 : 0.0)));
        }
  }
  EXPECT_LT(worst, 1e-8);
}

TEST(Assembly, ACarriedPointOutsideItsCellTakesAnEnclosingCellsVertices) {
  // Carried quadrature points move with a map that is not affine on a cell, and can leave it. On a
  // fine strip (h = 0.02, x <= 0.1) beside coarse nodes (h = 0.2, x >= 0.3) the points of the gap
  // lie outside the hull of the nodes whose supports reach them (gamma 4): there only the cell's
  // vertices make them evaluable. Carried by the wrong cells (the points of the first and last
  // gap cells exchanged), they get the vertices of a Delaunay cell holding them instead.
  const NodeSet nodes = fine_strip_beside_coarse_nodes();
  CarriedQuadrature carried;
  carried.cells = delaunay(nodes);
  carried.quadrature = map_to_cells(carried.cells, nodes, triangle_rule(6));
  const LmeBasis basis(nodes, std::vector<double>(nodes.size(), 4.0), LmeOptions{});
  const std::size_t per_cell = 6;
  std::vector<std::size_t> unevaluable_cells;
  for (std::size_t c = 0; c < carried.cells.size(); ++c) {
    for (std::size_t k = 0; k < per_cell; ++k) {
      const auto x = carried.quadrature.point(c * per_cell + k);
      try {
        (void)basis.evaluate(x, basis.neighbours(x), 0);
      } catch (const LmeEvaluationError&) {
        unevaluable_cells.push_back(c);
        break;
      }
    }
  }
  ASSERT_GE(unevaluable_cells.size(), 2u);
  const std::size_t a = unevaluable_cells.front(), b = unevaluable_cells.back();
  for (std::size_t k = 0; k < per_cell * 2; ++k)
    std::swap(carried.quadrature.points[a * per_cell * 2 + k], carried.quadrature.points[b * per_cell * 2 + k]);
  for (std::size_t k = 0; k < per_cell; ++k)
    std::swap(carried.quadrature.weights[a * per_cell + k], carried.quadrature.weights[b * per_cell + k]);

  DiscretizationOptions opts = options(4.0, 6, NeighbourhoodStrategy::CellBased);
  opts.carried = carried;
  const Discretization disc(PETSC_COMM_SELF, nodes, opts);
  std::printf("%zu cells with unevaluable points; %zu carried points outside their cells\n", unevaluable_cells.size(),
              disc.points_outside_carried_cells());
  EXPECT_GE(disc.points_outside_carried_cells(), 2 * per_cell - 2);
  // Every point's shape functions reproduce affine fields: Σ p_a = 1 and Σ p_a x_a = x.
  LmeWorkspace ws;
  for (int e = 0; e < disc.n_elements(); ++e) {
    const auto list = disc.element_nodes(e);
    const int points = disc.element_point_count(e);
    const std::size_t J = 3;  // value and gradient in 2D
    std::vector<double> tab(static_cast<std::size_t>(points) * J * list.size());
    disc.tabulate(e, 1, tab, ws);
    for (int q = 0; q < points; ++q) {
      const auto x = disc.quadrature().point(static_cast<std::size_t>(disc.element_first_point(e) + q));
      double sum = 0, sx = 0, sy = 0;
      for (std::size_t m = 0; m < list.size(); ++m) {
        const double p = tab[(static_cast<std::size_t>(q) * J) * list.size() + m];
        sum += p;
        sx += p * disc.nodes().point(static_cast<std::size_t>(list[m]))[0];
        sy += p * disc.nodes().point(static_cast<std::size_t>(list[m]))[1];
      }
      ASSERT_NEAR(sum, 1.0, 1e-10);
      ASSERT_NEAR(sx, x[0], 1e-8);
      ASSERT_NEAR(sy, x[1], 1e-8);
    }
  }
}

TEST(Assembly, DirectAndSetValuesInsertionGiveTheSameMatrix) {
  const NodeSet nodes = jittered_grid(10, 0.3, 21);
  const auto scalar = JetKernel<Nonlinear>::descriptor("nonlinear", nullptr, 0);
  const auto vector = JetKernel<VectorField>::descriptor("vector", nullptr, 0);
  const Discretization disc(PETSC_COMM_SELF, nodes, options(0.8, 6, NeighbourhoodStrategy::CellBased));
  for (const auto* form : {&scalar, &vector}) {
    const auto u = random_values(nodes.size() * static_cast<std::size_t>(form->dofs_per_node), 13);
    const auto direct = assemble_all(disc, *form, u, {}, Assembler::MatrixInsertion::Direct);
    const auto reference = assemble_all(disc, *form, u, {}, Assembler::MatrixInsertion::SetValues);
    ASSERT_GT(testing::max_abs(reference.hessian), 0.0);
    EXPECT_LE(testing::max_abs_difference(direct.hessian, reference.hessian), 1e-14 * testing::max_abs(reference.hessian))
        << form->name;
  }
}

TEST(Assembly, AHessianOfSomeComponentsEqualsTheFullOneWithTheOthersFixed) {
  const NodeSet nodes = jittered_grid(9, 0.3, 17);
  const auto form = JetKernel<VectorField>::descriptor("vector", nullptr, 0);
  const Discretization disc(PETSC_COMM_SELF, nodes, options(1.6, 6, NeighbourhoodStrategy::CellBased));
  Assembler assembler(disc, form);
  PetscVector u = assembler.create_vector();
  set_from_original(disc, random_values(nodes.size() * 2, 5, 0.5), 2, u);
  for (const std::vector<int>& coupled : {std::vector<int>{0}, std::vector<int>{1}}) testing::expect_coupled_hessian_equals_full(assembler, u, coupled);
  testing::expect_coupled_hessian_equals_full(assembler, u, {1}, Assembler::MatrixInsertion::SetValues);
  // Every component coupled: no restriction, whatever the list says.
  EXPECT_TRUE(coupled_components(disc, 2, {}).empty());
  EXPECT_THROW((void)assembler.create_matrix(Assembler::MatrixInsertion::Direct, std::vector<int>{2}), std::invalid_argument);
}

TEST(Assembly, SolverRefactorsAfterADirectFill) {
  const NodeSet nodes = jittered_grid(9, 0.3, 4);
  const Discretization disc(PETSC_COMM_SELF, nodes, options(1.6, 6, NeighbourhoodStrategy::CellBased));
  testing::expect_solver_refactors_after_direct_fill(disc, JetKernel<Nonlinear>::descriptor("nonlinear", nullptr, 0));
}

TEST(Assembly, MatrixSumEqualsSeparateAssemblies) {
  // A second-order form (Nonlinear) summed with a fourth-order one (Bilaplacian): the sum is
  // tabulated once at order 2, and the first form must read that tabulation correctly.
  const NodeSet nodes = jittered_grid(9, 0.3, 6);
  const Discretization disc(PETSC_COMM_SELF, nodes,
                            options(1.6, 6, NeighbourhoodStrategy::CellBased, BasisStorage::Full, 2));
  const auto first = JetKernel<Nonlinear>::descriptor("nonlinear", nullptr, 0);
  const auto second = JetKernel<Bilaplacian>::descriptor("bilaplacian", nullptr, 0);
  Assembler a(disc, first), b(disc, second);
  PetscVector u = a.create_vector();
  set_from_original(disc, random_values(nodes.size(), 8, 0.5), 1, u);
  PetscMatrix sum = a.create_matrix();
  const std::vector<Assembler::MatrixTerm> terms{{&a, 1.5}, {&b, -0.7}};
  a.matrix_sum(u, terms, sum);
  PetscMatrix separate = a.create_matrix(Assembler::MatrixInsertion::SetValues);
  a.matrix(u, separate);
  LMEFORM_PETSC_CHECK(MatScale(separate, 1.5));
  b.add_matrix(u, separate, -0.7);
  const auto s = testing::dense_original(disc, sum, 1), r = testing::dense_original(disc, separate, 1);
  ASSERT_GT(testing::max_abs(r), 0.0);
  EXPECT_LE(testing::max_abs_difference(s, r), 1e-13 * testing::max_abs(r));
}

TEST(Assembly, StructurallyZeroMatrixIsSkipped) {
  const NodeSet nodes = jittered_grid(8, 0.3, 2);
  const Discretization disc(PETSC_COMM_SELF, nodes, options(1.6, 3, NeighbourhoodStrategy::CellBased));
  auto form = JetKernel<Nonlinear>::descriptor("nonlinear", nullptr, 0);
  Assembler real(disc, form);
  auto flagged_form = form;
  flagged_form.matrix_structurally_zero = true;  // its kernel would add something: the flag must win
  Assembler flagged(disc, flagged_form);
  PetscVector u = real.create_vector();
  set_from_original(disc, random_values(nodes.size(), 1, 0.5), 1, u);
  PetscMatrix H = real.create_matrix();
  real.matrix(u, H);
  const auto before = testing::dense_original(disc, H, 1);
  flagged.add_matrix(u, H, 3.0);
  EXPECT_EQ(testing::max_abs_difference(testing::dense_original(disc, H, 1), before), 0.0);
  flagged.matrix(u, H);
  EXPECT_EQ(testing::max_abs(testing::dense_original(disc, H, 1)), 0.0);
}

TEST(Assembly, CompressedAndFullStorageAgree) {
  const NodeSet nodes = jittered_grid(9, 0.3, 8);
  const auto form = JetKernel<Bilaplacian>::descriptor("bilaplacian", nullptr, 0);
  const auto u = random_values(nodes.size(), 12);
  const Discretization full(PETSC_COMM_SELF, nodes, options(1.6, 6, NeighbourhoodStrategy::CellBased, BasisStorage::Full, 2));
  const Discretization compressed(PETSC_COMM_SELF, nodes,
                                  options(1.6, 6, NeighbourhoodStrategy::CellBased, BasisStorage::Compressed, 2));
  const auto a = assemble_all(full, form, u);
  const auto b = assemble_all(compressed, form, u);
  EXPECT_LE(testing::max_abs_difference(a.hessian, b.hessian), 1e-10 * testing::max_abs(a.hessian));
  EXPECT_LT(compressed.basis_storage_doubles() * 5, full.basis_storage_doubles());
}

// The second-order basis (LmeOptions::consistency) reaches both storages through the
// discretization options unchanged: the same operator from full and compressed storage, and not
// the first-order one.
TEST(Assembly, SecondOrderBasisReachesBothStorages) {
  const NodeSet nodes = jittered_grid(11, 0.3, 8);
  const auto form = JetKernel<Bilaplacian>::descriptor("bilaplacian", nullptr, 0);
  const auto u = random_values(nodes.size(), 12);
  auto second = [](BasisStorage storage) {
    DiscretizationOptions o = options(0.8, 6, NeighbourhoodStrategy::CellBased, storage, 2);
    o.lme.consistency = LmeConsistency::second;
    return o;
  };
  const Discretization full(PETSC_COMM_SELF, nodes, second(BasisStorage::Full));
  const Discretization compressed(PETSC_COMM_SELF, nodes, second(BasisStorage::Compressed));
  const Discretization first(PETSC_COMM_SELF, nodes, options(0.8, 6, NeighbourhoodStrategy::CellBased, BasisStorage::Full, 2));
  EXPECT_EQ(full.basis().consistency(), LmeConsistency::second);
  EXPECT_EQ(compressed.basis().consistency(), LmeConsistency::second);
  const auto a = assemble_all(full, form, u);
  const auto b = assemble_all(compressed, form, u);
  const auto c = assemble_all(first, form, u);
  EXPECT_LE(testing::max_abs_difference(a.hessian, b.hessian), 1e-10 * testing::max_abs(a.hessian));
  EXPECT_GT(testing::max_abs_difference(a.hessian, c.hessian), 1e-3 * testing::max_abs(a.hessian));
  // 37 doubles per point against 21 for the first-order record.
  EXPECT_EQ(compressed.basis_storage_doubles() % static_cast<std::size_t>(lme_second_order_record_size(2, 2)), 0u);
}

// The simply supported Kirchhoff plate, E = 1/2 (lap w)^2 - 4 pi^4 sin(pi x) sin(pi y) w, w = 0 on
// the hull: with the second-order basis the L2 error falls at about h^3 (bench_plate_order has the
// tables; the first-order basis stalls at 2e-4 for gamma 0.8).
struct ManufacturedPlate {
  static constexpr int components = 1;
  static constexpr int order = 2;
  static double load(const double* x) {
    const double pi = std::numbers::pi;
    return 4 * std::pow(pi, 4) * std::sin(pi * x[0]) * std::sin(pi * x[1]);
  }
  static double f(const double* j, const double* x, const double*) {
    return 0.5 * (j[3] + j[5]) * (j[3] + j[5]) - load(x) * j[0];
  }
  static void df(const double* j, const double* x, const double*, double* d) {
    for (int i = 0; i < 6; ++i) d[i] = 0;
    d[0] = -load(x);
    d[3] = d[5] = j[3] + j[5];
  }
  static void d2f(const double*, const double*, const double*, double* d) {
    for (int i = 0; i < 36; ++i) d[i] = 0;
    d[3 * 6 + 3] = d[3 * 6 + 5] = d[5 * 6 + 3] = d[5 * 6 + 5] = 1;
  }
};

double plate_l2_error(int per_axis, LmeConsistency consistency) {
  const NodeSet nodes = uniform_grid(Box::unit(2), {per_axis, per_axis, 1});
  DiscretizationOptions o = options(0.8, 6, NeighbourhoodStrategy::PerPoint, BasisStorage::Full, 2);
  o.lme.consistency = consistency;
  const Discretization disc(PETSC_COMM_SELF, nodes, o);
  const auto form = JetKernel<ManufacturedPlate>::descriptor("plate", nullptr, 0);
  Assembler assembler(disc, form);
  auto [K, b, w] = testing::assemble_linear_system(assembler);
  apply_dirichlet(K, b, w, owned_dofs_of_nodes(disc, hull_boundary_nodes(nodes), 1));
  testing::solve_direct(K, b, w);
  const auto l2_form = JetKernel<ManufacturedError<false>>::descriptor("l2", nullptr, 0);
  Assembler l2(disc, l2_form);
  return std::sqrt(l2.value(w));
}

TEST(Assembly, KirchhoffPlateConvergesWithTheSecondOrderBasis) {
  const double coarse = plate_l2_error(11, LmeConsistency::second), fine = plate_l2_error(21, LmeConsistency::second);
  std::printf("plate, second-order basis, gamma 0.8: L2 %.3e (h 0.1) -> %.3e (h 0.05)\n", coarse, fine);
  EXPECT_GT(std::log2(coarse / fine), 2.5);
  EXPECT_LT(fine, 2e-4);
}

// Directional finite differences of the global energy and gradient: g·v and H v.
template <class Integrand>
void check_global_derivatives(const NodeSet& nodes, const DiscretizationOptions& opts, std::uint64_t seed) {
  const Discretization disc(PETSC_COMM_SELF, nodes, opts);
  const auto form = JetKernel<Integrand>::descriptor("fd", nullptr, 0);
  const int bs = form.dofs_per_node;
  Assembler assembler(disc, form);
  const std::size_t n = nodes.size() * static_cast<std::size_t>(bs);
  const auto u0 = random_values(n, seed, 0.8);
  const auto v = random_values(n, seed + 1);
  PetscVector u = assembler.create_vector(), g = assembler.create_vector(), gp = assembler.create_vector(),
              gm = assembler.create_vector(), Hv = assembler.create_vector(), dir = assembler.create_vector();
  PetscMatrix H = assembler.create_matrix();
  set_from_original(disc, u0, bs, u);
  set_from_original(disc, v, bs, dir);
  assembler.vector(u, g);
  assembler.matrix(u, H);
  LMEFORM_PETSC_CHECK(MatMult(H, dir, Hv));
  PetscScalar gv = 0;
  LMEFORM_PETSC_CHECK(VecDot(g, dir, &gv));

  const double h = 1e-5;
  std::vector<double> up(n), um(n);
  for (std::size_t i = 0; i < n; ++i) {
    up[i] = u0[i] + h * v[i];
    um[i] = u0[i] - h * v[i];
  }
  set_from_original(disc, up, bs, u);
  const double ep = assembler.value(u);
  assembler.vector(u, gp);
  set_from_original(disc, um, bs, u);
  const double em = assembler.value(u);
  assembler.vector(u, gm);
  const double fd_gv = (ep - em) / (2 * h);
  EXPECT_NEAR(gv, fd_gv, 1e-6 * std::abs(gv));

  const auto hv = to_original(disc, Hv, bs);
  const auto gpo = to_original(disc, gp, bs);
  const auto gmo = to_original(disc, gm, bs);
  std::vector<double> fd_hv(n);
  for (std::size_t i = 0; i < n; ++i) fd_hv[i] = (gpo[i] - gmo[i]) / (2 * h);
  EXPECT_LE(testing::max_abs_difference(hv, fd_hv), 1e-6 * testing::max_abs(hv));
}

TEST(Assembly, GlobalGradientAndHessianMatchFiniteDifferences) {
  GradedGridOptions graded;
  graded.h_min = 0.02;
  graded.h_max = 0.2;
  const NodeSet nodes = graded_grid_2d(graded);
  check_global_derivatives<Nonlinear>(nodes, options(1.6, 6, NeighbourhoodStrategy::CellBased), 21);
}

TEST(Assembly, VectorUnknownBlocksMatchFiniteDifferences) {
  check_global_derivatives<VectorField>(jittered_grid(9, 0.3, 4), options(1.6, 3, NeighbourhoodStrategy::CellBased), 31);
  check_global_derivatives<VectorField>(jittered_grid(9, 0.3, 4), options(1.6, 3, NeighbourhoodStrategy::PerPoint), 41);
}

TEST(Assembly, DirichletRowsAndColumnsAreIdentity) {
  const NodeSet nodes = uniform_grid(Box::unit(2), {9, 9, 1});
  const Discretization disc(PETSC_COMM_SELF, nodes, options(1.6, 6, NeighbourhoodStrategy::CellBased));
  const auto form = JetKernel<Poisson<false>>::descriptor("poisson", kSourceConstant, 1);
  Assembler assembler(disc, form);
  assembler.set_constant("source", 1.0);
  auto [K, b, x] = testing::assemble_linear_system(assembler);
  const auto boundary = hull_boundary_nodes(nodes);
  std::vector<double> prescribed(nodes.size(), 0.0);
  for (const int a : boundary) prescribed[static_cast<std::size_t>(a)] = 1.0 + nodes.coords[2 * static_cast<std::size_t>(a)];
  set_from_original(disc, prescribed, 1, x);
  const auto dofs = owned_dofs_of_nodes(disc, boundary, 1);
  ASSERT_EQ(dofs.size(), boundary.size());
  apply_dirichlet(K, b, x, dofs);
  const auto dense = testing::dense_original(disc, K, 1);
  const auto rhs = to_original(disc, b, 1);
  const auto n = static_cast<std::size_t>(disc.n_nodes());
  for (const int a : boundary) {
    const auto i = static_cast<std::size_t>(a);
    EXPECT_EQ(rhs[i], prescribed[i]);
    for (std::size_t j = 0; j < n; ++j) {
      EXPECT_EQ(dense[i * n + j], i == j ? 1.0 : 0.0);
      EXPECT_EQ(dense[j * n + i], i == j ? 1.0 : 0.0);
    }
  }
  testing::solve_direct(K, b, x);
  const auto solution = to_original(disc, x, 1);
  for (const int a : boundary) EXPECT_NEAR(solution[static_cast<std::size_t>(a)], prescribed[static_cast<std::size_t>(a)], 1e-12);
}

TEST(Assembly, FormNeedingHessiansRejectsATabulationWithout) {
  const NodeSet nodes = uniform_grid(Box::unit(2), {6, 6, 1});
  const Discretization disc(PETSC_COMM_SELF, nodes, options(1.6, 3, NeighbourhoodStrategy::CellBased));
  const auto form = JetKernel<Bilaplacian>::descriptor("bilaplacian", nullptr, 0);
  try {
    Assembler assembler(disc, form);
    FAIL() << "expected an error";
  } catch (const std::invalid_argument& e) {
    const std::string message = e.what();
    EXPECT_NE(message.find("needs basis Hessians"), std::string::npos) << message;
    EXPECT_NE(message.find("basis_order = 2"), std::string::npos) << message;
  }
}

TEST(Assembly, BoundaryAndPointKernelsAreRefused) {
  const NodeSet nodes = uniform_grid(Box::unit(2), {6, 6, 1});
  const Discretization disc(PETSC_COMM_SELF, nodes, options(1.6, 3, NeighbourhoodStrategy::CellBased));
  auto boundary = JetKernel<Poisson<false>>::descriptor("poisson", kSourceConstant, 1);
  boundary.domain = lmeform::kernel::IntegralDomain::Boundary;
  boundary.boundary_part = "top";
  try {
    Assembler assembler(disc, boundary);
    FAIL() << "expected an error";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("integrates over the boundary part 'top', which the discretization has no quadrature for"), std::string::npos) << e.what();
  }
  auto point = JetKernel<Poisson<false>>::descriptor("poisson", kSourceConstant, 1);
  point.kind = lmeform::kernel::FunctionalKind::Point;
  EXPECT_THROW({ Assembler assembler(disc, point); }, std::invalid_argument);
}

TEST(Assembly, UnsetConstantIsAnError) {
  const NodeSet nodes = uniform_grid(Box::unit(2), {6, 6, 1});
  const Discretization disc(PETSC_COMM_SELF, nodes, options(1.6, 3, NeighbourhoodStrategy::CellBased));
  const auto form = JetKernel<Poisson<false>>::descriptor("poisson", kSourceConstant, 1);
  Assembler assembler(disc, form);
  PetscVector u = assembler.create_vector();
  try {
    (void)assembler.value(u);
    FAIL() << "expected an error";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("constant 'source' was not set"), std::string::npos) << e.what();
  }
  EXPECT_THROW(assembler.set_constant("sourse", 1.0), std::invalid_argument);
}

struct ErrorNorms {
  double h, l2, h1;
};

ErrorNorms solve_manufactured(int per_axis, double gamma) {
  const NodeSet nodes = uniform_grid(Box::unit(2), {per_axis, per_axis, 1});
  const Discretization disc(PETSC_COMM_SELF, nodes, options(gamma, 6, NeighbourhoodStrategy::CellBased));
  const auto form = JetKernel<Poisson<true>>::descriptor("manufactured", kSourceConstant, 1);
  Assembler assembler(disc, form);
  assembler.set_constant("source", 1.0);
  auto [K, b, T] = testing::assemble_linear_system(assembler);
  apply_dirichlet(K, b, T, owned_dofs_of_nodes(disc, hull_boundary_nodes(nodes), 1));  // T = 0 on the boundary
  testing::solve_direct(K, b, T);
  const auto l2_form = JetKernel<ManufacturedError<false>>::descriptor("l2", nullptr, 0);
  const auto h1_form = JetKernel<ManufacturedError<true>>::descriptor("h1", nullptr, 0);
  Assembler l2(disc, l2_form), h1(disc, h1_form);
  return {1.0 / (per_axis - 1), std::sqrt(l2.value(T)), std::sqrt(h1.value(T))};
}

TEST(Assembly, ManufacturedPoissonConvergesAtSecondOrderInL2) {
  for (const double gamma : {0.8, 1.6, 4.0}) {
    std::vector<ErrorNorms> e;
    for (const int n : {11, 21, 41}) e.push_back(solve_manufactured(n, gamma));
    for (std::size_t k = 1; k < e.size(); ++k) {
      const double rate_l2 = std::log(e[k - 1].l2 / e[k].l2) / std::log(e[k - 1].h / e[k].h);
      const double rate_h1 = std::log(e[k - 1].h1 / e[k].h1) / std::log(e[k - 1].h / e[k].h);
      std::printf("gamma %.1f  h %.4f -> %.4f  L2 %.3e -> %.3e (rate %.2f)  H1 %.3e -> %.3e (rate %.2f)\n", gamma,
                  e[k - 1].h, e[k].h, e[k - 1].l2, e[k].l2, rate_l2, e[k - 1].h1, e[k].h1, rate_h1);
      if (gamma == 0.8) {
        EXPECT_GE(rate_l2, 1.8) << "h " << e[k].h;
      }
      EXPECT_GE(rate_h1, 0.9) << "gamma " << gamma << " h " << e[k].h;
    }
  }
}

}  // namespace
}  // namespace lmeform

namespace lmeform {
namespace {

// A phase-field-like state: a tanh interface of width eps around a circle.
std::vector<double> interface_state(const NodeSet& nodes, double eps) {
  std::vector<double> u(nodes.size());
  for (std::size_t a = 0; a < nodes.size(); ++a) {
    const double x = nodes.coords[2 * a] - 0.5, y = nodes.coords[2 * a + 1] - 0.5;
    u[a] = std::tanh((0.3 - std::sqrt(x * x + y * y)) / (std::sqrt(2.0) * eps));
  }
  return u;
}

TEST(QuadratureAdequacy, ThreePointsAreNotEnoughForAFourthOrderForm) {
  const NodeSet nodes = uniform_grid(Box::unit(2), {26, 26, 1});
  DiscretizationOptions opts;
  opts.gamma = {1.6};
  opts.basis_order = 2;
  const Discretization disc(PETSC_COMM_SELF, nodes, opts);
  const auto form = testing::JetKernel<testing::Bilaplacian>::descriptor("bilaplacian", nullptr, 0);
  const auto u = interface_state(nodes, 0.06);
  const auto three = check_quadrature(disc, form, u, {}, 3);
  const auto twelve = check_quadrature(disc, form, u, {}, 12);
  std::printf("bilaplacian on a tanh interface: %d vs %d points: energy %.2e gradient %.2e; %d vs %d: energy %.2e gradient %.2e (%d cells)\n",
              three.points, three.richer_points, three.energy_relative_difference, three.gradient_relative_difference,
              twelve.points, twelve.richer_points, twelve.energy_relative_difference, twelve.gradient_relative_difference,
              twelve.cells_sampled);
  EXPECT_EQ(three.richer_points, 6);
  EXPECT_EQ(twelve.richer_points, 16);
  // 3 points miss the energy by more than a percent; 12 points are ten times closer.
  EXPECT_GT(three.energy_relative_difference, 1e-2);
  EXPECT_LT(twelve.energy_relative_difference * 10, three.energy_relative_difference);
  EXPECT_LT(twelve.gradient_relative_difference * 10, three.gradient_relative_difference);
}

TEST(QuadratureAdequacy, SecondOrderFormIsWellIntegratedBySixPoints) {
  const NodeSet nodes = uniform_grid(Box::unit(2), {21, 21, 1});
  DiscretizationOptions opts;
  opts.gamma = {1.6};
  const Discretization disc(PETSC_COMM_SELF, nodes, opts);
  const auto form = testing::JetKernel<testing::Nonlinear>::descriptor("nonlinear", nullptr, 0);
  const auto u = interface_state(nodes, 0.1);
  const auto six = check_quadrature(disc, form, u, {}, 6, 0, 3);
  EXPECT_EQ(six.richer_points, 7);
  EXPECT_LT(six.energy_relative_difference, 1e-3);
  EXPECT_THROW((void)check_quadrature(disc, form, u, {}, 19), std::invalid_argument);
}

}  // namespace
}  // namespace lmeform
