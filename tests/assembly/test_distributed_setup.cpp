// Run with 3 ranks: the distributed setup (each rank searches the neighbours of the points of the
// cells that can reach its nodes only) gives every element the basis the serial setup gives it,
// to 1e-12 at every point, for every partition method, both neighbourhood strategies, the
// second-order basis, a mirrored (axisymmetric) basis and the consistent integration's corrections;
// and the points, their lists and the facets really are split.
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <span>
#include <map>
#include <string>

#include "assembly_fixtures.hpp"
#include "lmeform/kernel.hpp"
#include "lmeform/node_sets.hpp"

namespace lmeform {
namespace {

NodeSet graded_nodes() {
  // Strongly graded (h from 0.01 to 0.08): supports of very different sizes meet at the parts'
  // borders, where a too-small search radius would miss a cell.
  GradedGridOptions g;
  g.h_min = 0.01;
  g.h_max = 0.08;
  g.transition = 0.1;
  return graded_grid_2d(g);
}

struct Setting {
  const char* name;
  PartitionMethod partition;
  NeighbourhoodStrategy strategy;
  LmeConsistency consistency;
  bool mirrored;
  int consistent_integration = 0;  ///< facet points (0: Gauss rule alone)
  double tol0 = 1e-6;              ///< support cutoff
  int basis_order = 2;             ///< derivatives tabulated and compared
};

DiscretizationOptions options_of(const Setting& s) {
  DiscretizationOptions o;
  o.gamma = {s.consistency == LmeConsistency::second ? 0.5 : 1.6};
  o.quadrature_points = 3;
  o.strategy = s.strategy;
  o.partition = s.partition;
  o.lme.consistency = s.consistency;
  o.consistent_integration = s.consistent_integration;
  o.lme.tol0 = s.tol0;
  o.basis_order = s.basis_order;
  if (s.mirrored) o.lme.mirrors = {MirrorPlane{0, 0.0}};
  return o;
}

// The number every rank gives the first point of element e (ranks number the points they hold
// locally): cell × points per cell for a cell, the point's own for a per-point element.
int global_first_point(const Discretization& disc, const ElementSet& domain, int e) {
  const bool per_point = disc.options().strategy == NeighbourhoodStrategy::PerPoint;
  return per_point ? domain.element_id(e) : domain.element_id(e) * disc.quadrature().points_per_cell;
}

// Element e's jet per original node: (global point, original node) -> jet entries.
std::map<std::pair<int, int>, std::vector<double>> jets_of(const Discretization& disc, const ElementSet& domain, int e) {
  const auto nodes = domain.element_nodes(e);
  const int points = domain.element_point_count(e);
  const int order = disc.options().basis_order;
  const auto J = static_cast<std::size_t>(kernel::jet_size(disc.dim(), order));
  const bool per_point = disc.options().strategy == NeighbourhoodStrategy::PerPoint;
  const auto first = domain.element_first_point(e);
  const int global_first = global_first_point(disc, domain, e);
  // Per-point elements are tabulated against the point's own list.
  const auto columns = per_point ? domain.point_lists()[static_cast<std::size_t>(first)] : nodes;
  std::vector<double> tab(static_cast<std::size_t>(points) * J * columns.size());
  LmeWorkspace ws;
  domain.tabulate(e, order, tab, ws);
  std::map<std::pair<int, int>, std::vector<double>> out;
  for (int k = 0; k < points; ++k)
    for (std::size_t a = 0; a < columns.size(); ++a) {
      std::vector<double> jet(J);
      for (std::size_t s = 0; s < J; ++s) jet[s] = tab[(static_cast<std::size_t>(k) * J + s) * columns.size() + a];
      out[{global_first + k, disc.original_index()[static_cast<std::size_t>(columns[a])]}] = std::move(jet);
    }
  return out;
}

// Compares element e of the distributed setup with the serial element of the same first point:
// node lists, points and weights (to the last bit) and jets (their largest difference and entry go
// into worst and largest). Returns what differs, or nothing.
std::string compare_element(const Discretization& parallel, const ElementSet& pd, int e, const Discretization& serial,
                            const std::map<int, int>& serial_element_of_point, double& worst, double& largest) {
  const ElementSet& sd = serial.cells_domain();
  const int point = global_first_point(parallel, pd, e);
  const auto it = serial_element_of_point.find(point);
  if (it == serial_element_of_point.end()) return "no serial element of point " + std::to_string(point);
  // The same node list, in original numbering.
  std::vector<int> mine, theirs;
  for (const int v : pd.element_nodes(e)) mine.push_back(parallel.original_index()[static_cast<std::size_t>(v)]);
  for (const int v : sd.element_nodes(it->second)) theirs.push_back(serial.original_index()[static_cast<std::size_t>(v)]);
  std::sort(mine.begin(), mine.end());
  std::sort(theirs.begin(), theirs.end());
  if (mine != theirs) return "another node list at the element of point " + std::to_string(point);
  // The same points and weights, to the last bit.
  const auto d = static_cast<std::size_t>(parallel.dim());
  for (int k = 0; k < pd.element_point_count(e); ++k) {
    const auto q = static_cast<std::size_t>(pd.element_first_point(e) + k), r = static_cast<std::size_t>(point + k);
    bool same = pd.weights()[q] == sd.weights()[r];
    for (std::size_t i = 0; i < d; ++i) same = same && pd.points()[q * d + i] == sd.points()[r * d + i];
    if (!same) return "another point or weight at point " + std::to_string(point + k);
  }
  const auto a = jets_of(parallel, pd, e), b = jets_of(serial, sd, it->second);
  if (a.size() != b.size()) return "another number of jets at the element of point " + std::to_string(point);
  for (const auto& [key, jet] : a) {
    const auto ref = b.find(key);
    if (ref == b.end()) return "a jet of node " + std::to_string(key.second) + " the serial element lacks";
    for (std::size_t k = 0; k < jet.size(); ++k) {
      worst = std::max(worst, std::abs(jet[k] - ref->second[k]));
      largest = std::max(largest, std::abs(ref->second[k]));
    }
  }
  return {};
}

TEST(DistributedSetup, RunsOnThreeRanks) { EXPECT_EQ(PetscSession::size(), 3); }

TEST(DistributedSetup, EveryElementHasTheSerialBasis) {
  const NodeSet nodes = graded_nodes();
  const Setting settings[] = {
      {"metis, cells", PartitionMethod::Metis, NeighbourhoodStrategy::CellBased, LmeConsistency::first, false},
      {"hilbert, cells", PartitionMethod::Hilbert, NeighbourhoodStrategy::CellBased, LmeConsistency::first, false},
      {"block, per point", PartitionMethod::Block, NeighbourhoodStrategy::PerPoint, LmeConsistency::first, false},
      {"hilbert, second order", PartitionMethod::Hilbert, NeighbourhoodStrategy::CellBased, LmeConsistency::second, false},
      {"metis, mirrored", PartitionMethod::Metis, NeighbourhoodStrategy::CellBased, LmeConsistency::first, true},
      // Gradients and Hessians corrected cell by cell against facet rules: a rank builds the facets
      // of its cells and their neighbours only.
      {"hilbert, consistent integration", PartitionMethod::Hilbert, NeighbourhoodStrategy::CellBased, LmeConsistency::first, false, 2},
      {"metis, second order, consistent integration", PartitionMethod::Metis, NeighbourhoodStrategy::CellBased, LmeConsistency::second,
       false, 3},
      // A compact support: facet points see few nodes, and their lists take the vertices of the
      // cells beside them, which can reach a rank's nodes from a cell no support reaches. Gradients
      // only: the Hessian correction evaluates hull facets just inside the hull, where the dual
      // problem is ill-conditioned, and the serial and distributed setups, which sum over the nodes
      // in different orders, then differ by 5e-10 of the largest entry (measured, before and after
      // the points were distributed).
      {"hilbert, compact support, consistent integration", PartitionMethod::Hilbert, NeighbourhoodStrategy::CellBased,
       LmeConsistency::first, false, 2, 1e-3, 1},
  };
  for (const Setting& s : settings) {
    const DiscretizationOptions o = options_of(s);
    const Discretization serial(PETSC_COMM_SELF, nodes, o);
    const Discretization parallel(PETSC_COMM_WORLD, nodes, o);
    // Every rank holds the same partition (one rank computes it and sends it).
    long long hash = 0;
    for (std::size_t a = 0; a < parallel.partition().part_of.size(); ++a) hash = (hash * 31 + parallel.partition().part_of[a] + 1) % 1000000007;
    long long lowest = hash, highest = hash;
    MPI_Allreduce(MPI_IN_PLACE, &lowest, 1, MPI_LONG_LONG, MPI_MIN, PETSC_COMM_WORLD);
    MPI_Allreduce(MPI_IN_PLACE, &highest, 1, MPI_LONG_LONG, MPI_MAX, PETSC_COMM_WORLD);
    EXPECT_EQ(lowest, highest) << s.name << ": the ranks disagree on the partition";
    const ElementSet& sd = serial.cells_domain();
    const ElementSet& pd = parallel.cells_domain();
    // The serial run has every element, in point order: the element of point q is found by q.
    std::map<int, int> serial_element_of_point;
    for (int e = 0; e < sd.n_elements(); ++e) {
      EXPECT_EQ(sd.element_first_point(e), global_first_point(serial, sd, e)) << s.name << ": one rank numbers points as the cells";
      serial_element_of_point[sd.element_first_point(e)] = e;
    }
    double worst = 0, largest = 0;
    long long owned = 0;
    for (int e = 0; e < pd.n_elements(); ++e) {
      owned += pd.element_owned(e) ? 1 : 0;
      // A mismatch fails the test without leaving the loop early: every rank must reach the
      // collective calls below, or the others would wait for it forever.
      if (const std::string m = compare_element(parallel, pd, e, serial, serial_element_of_point, worst, largest); !m.empty()) {
        ADD_FAILURE() << s.name << ": " << m;
        break;
      }
    }
    EXPECT_LE(worst, 1e-12 * largest) << s.name;
    // Every element of the serial setup is owned by exactly one rank.
    long long total = owned;
    MPI_Allreduce(MPI_IN_PLACE, &total, 1, MPI_LONG_LONG, MPI_SUM, PETSC_COMM_WORLD);
    EXPECT_EQ(total, sd.n_elements()) << s.name;
  }
}

TEST(DistributedSetup, NoRankHoldsEveryPointsList) {
  // The quadrature points, their weights and lists are the per-point arrays of the setup: on 3
  // ranks each holds those of its own cells and a halo one support wide, well under the serial
  // total; what every rank holds (nodes and cells) weighs less than the points of one rank alone.
  const Box box = Box::unit(2);
  const NodeSet nodes = jitter_interior(uniform_grid(box, {61, 61, 1}), box, 0.2 / 60, 3);
  for (const auto& [partition, facet_points] : {std::pair{PartitionMethod::Metis, 0}, std::pair{PartitionMethod::Hilbert, 0},
                                                std::pair{PartitionMethod::Hilbert, 2}}) {
    DiscretizationOptions o;
    o.gamma = {1.6};
    o.partition = partition;
    o.consistent_integration = facet_points;  // the facets and their points' lists are split too
    const Discretization serial(PETSC_COMM_SELF, nodes, o);
    const Discretization parallel(PETSC_COMM_WORLD, nodes, o);
    const double share = double(parallel.point_lists().total()) / double(serial.point_lists().total());
    const double cells = double(parallel.cells_searched()) / double(serial.cells().size());
    EXPECT_LT(share, 0.5) << to_string(partition) << ": this rank holds " << share << " of the lists";
    EXPECT_LT(cells, 0.5) << to_string(partition);
    EXPECT_EQ(serial.cells_searched(), serial.cells().size());
    EXPECT_TRUE(serial.points_on_every_rank());
    EXPECT_FALSE(parallel.points_on_every_rank());
    EXPECT_EQ(parallel.quadrature().size(), parallel.cells_searched() * std::size_t(parallel.quadrature().points_per_cell));
    EXPECT_LT(double(parallel.quadrature().size()), 0.5 * double(serial.quadrature().size())) << to_string(partition);
    EXPECT_EQ(parallel.cells_domain().n_points(), parallel.quadrature().size());
    const auto memory = parallel.memory_report(), whole = serial.memory_report();
    EXPECT_LT(memory.local_bytes, 0.5 * whole.local_bytes) << to_string(partition);
    EXPECT_EQ(memory.replicated_bytes, whole.replicated_bytes);
    const double serial_points_bytes = double(serial.quadrature().points.size() + serial.quadrature().weights.size()) * sizeof(double);
    EXPECT_LT(memory.replicated_bytes, serial_points_bytes) << to_string(partition) << ": replicated arrays outweigh the points";
  }
}

// A Lagrangian run's reset carries the quadrature points to the deformed nodes: the points of
// every cell come in, and each rank keeps those of its cells. A smooth map moves nodes and points;
// a few points are pushed out of their cells as a compressive map does (their lists then take the
// vertices of an enclosing cell of the current nodes, which any rank may own).
TEST(DistributedSetup, CarriedPointsAreSplitAndKeepTheSerialBasis) {
  const Box box = Box::unit(2);
  const NodeSet original = jitter_interior(uniform_grid(box, {41, 41, 1}), box, 0.2 / 40, 5);
  DiscretizationOptions o;
  o.gamma = {1.6};
  o.quadrature_points = 3;
  o.basis_order = 2;
  const Discretization start(PETSC_COMM_SELF, original, o);  // one rank: cells and points in the original numbering
  const auto map = [](std::span<const double> x, double* y) {
    y[0] = x[0] + 0.04 * std::sin(M_PI * x[0]) * std::sin(M_PI * x[1]);
    y[1] = x[1] + 0.03 * std::sin(2 * M_PI * x[0]) * std::sin(M_PI * x[1]);
  };
  std::vector<double> moved(original.coords.size());
  for (std::size_t a = 0; a < original.size(); ++a) map(original.point(a), moved.data() + 2 * a);
  const NodeSet nodes(2, moved);
  CarriedQuadrature carried;
  carried.cells = start.cells();
  carried.quadrature = start.quadrature();
  const auto per_cell = static_cast<std::size_t>(carried.quadrature.points_per_cell);
  std::size_t pushed = 0;
  for (std::size_t c = 0; c < carried.cells.size(); ++c) {
    for (std::size_t k = 0; k < per_cell; ++k) {
      const std::size_t q = c * per_cell + k;
      std::array<double, 2> x{carried.quadrature.points[2 * q], carried.quadrature.points[2 * q + 1]};
      map(x, carried.quadrature.points.data() + 2 * q);
    }
    // Every 29th cell well inside: its first point beyond its first vertex, out of the cell.
    const auto v = carried.cells.cell(c);
    const auto x0 = nodes.point(std::size_t(v[0]));
    double centroid[2] = {0, 0};
    for (const int w : v)
      for (int i = 0; i < 2; ++i) centroid[i] += nodes.point(std::size_t(w))[std::size_t(i)] / 3;
    if (c % 29 == 0 && centroid[0] > 0.2 && centroid[0] < 0.8 && centroid[1] > 0.2 && centroid[1] < 0.8) {
      for (int i = 0; i < 2; ++i) carried.quadrature.points[2 * c * per_cell + std::size_t(i)] = x0[std::size_t(i)] + 0.3 * (x0[std::size_t(i)] - centroid[i]);
      ++pushed;
    }
  }
  ASSERT_GT(pushed, 5u);
  o.carried = carried;
  o.partition = PartitionMethod::Metis;
  const Discretization serial(PETSC_COMM_SELF, nodes, o);
  const Discretization parallel(PETSC_COMM_WORLD, nodes, o);
  // Every rank holds the cells of the points pushed out: each counts them all.
  EXPECT_EQ(serial.points_outside_carried_cells(), pushed);
  EXPECT_EQ(parallel.points_outside_carried_cells(), pushed);
  EXPECT_FALSE(parallel.points_on_every_rank());
  EXPECT_LT(double(parallel.quadrature().size()), 0.5 * double(serial.quadrature().size()));
  EXPECT_LT(double(parallel.point_lists().total()), 0.5 * double(serial.point_lists().total()));
  const ElementSet& sd = serial.cells_domain();
  const ElementSet& pd = parallel.cells_domain();
  std::map<int, int> serial_element_of_point;
  for (int e = 0; e < sd.n_elements(); ++e) serial_element_of_point[sd.element_first_point(e)] = e;
  double worst = 0, largest = 0;
  long long owned = 0;
  for (int e = 0; e < pd.n_elements(); ++e) {
    owned += pd.element_owned(e) ? 1 : 0;
    if (const std::string m = compare_element(parallel, pd, e, serial, serial_element_of_point, worst, largest); !m.empty()) {
      ADD_FAILURE() << "carried: " << m;
      break;
    }
  }
  EXPECT_LE(worst, 1e-12 * largest);
  long long total = owned;
  MPI_Allreduce(MPI_IN_PLACE, &total, 1, MPI_LONG_LONG, MPI_SUM, PETSC_COMM_WORLD);
  EXPECT_EQ(total, sd.n_elements());
  // A rank's point q is point global_point(q) of the carried quadrature.
  for (std::size_t q = 0; q < parallel.quadrature().size(); ++q) {
    const std::size_t g = parallel.global_point(q);
    ASSERT_EQ(parallel.quadrature().weights[q], carried.quadrature.weights[g]);
    ASSERT_EQ(parallel.quadrature().points[2 * q + 1], carried.quadrature.points[2 * g + 1]);
  }
}

}  // namespace
}  // namespace lmeform
