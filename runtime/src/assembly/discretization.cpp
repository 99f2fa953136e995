#include "lmeform/discretization.hpp"

#include "cell_facets.hpp"
#include "lmeform/stopwatch.hpp"

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <exception>
#include <stdexcept>
#include <string>

#include "lmeform/collective_error.hpp"
#include "lmeform/delaunay.hpp"
#include "lmeform/kernel.hpp"
#include "lmeform/neighbourhoods.hpp"

namespace lmeform {

const char* to_string(NeighbourhoodStrategy s) noexcept {
  return s == NeighbourhoodStrategy::CellBased ? "cell" : "point";
}
const char* to_string(BasisStorage s) noexcept { return s == BasisStorage::Full ? "full" : "compressed"; }
const char* to_string(OffProcessMode m) noexcept {
  return m == OffProcessMode::ZeroCommunication ? "zero-communication" : "petsc-exchange";
}

namespace {

class StageClock {
 public:
  explicit StageClock(double& accumulator) : acc_(accumulator) {}
  ~StageClock() { acc_ += clock_.seconds(); }
  StageClock(const StageClock&) = delete;
  StageClock& operator=(const StageClock&) = delete;

 private:
  double& acc_;
  Stopwatch clock_;
};

QuadratureRule rule_for(int dim, int points) {
  switch (dim) {
    case 1: return gauss_legendre(points);
    case 2: return triangle_rule(points);
    case 3: return tetrahedron_rule(points);
    default: throw std::invalid_argument("Discretization: no quadrature for dimension " + std::to_string(dim));
  }
}

std::vector<double> expand_gamma(const std::vector<double>& gamma, std::size_t n_nodes) {
  if (gamma.size() == 1) return std::vector<double>(n_nodes, gamma.front());
  if (gamma.size() != n_nodes) {
    throw std::invalid_argument("Discretization: gamma has " + std::to_string(gamma.size()) +
                                " values; give one for all nodes or one per node (" + std::to_string(n_nodes) + ")");
  }
  return gamma;
}

// Each list with the vertices `extra(q)` merged in (sorted, without repeats).
template <class ExtraVertices>
CsrLists with_vertices(const CsrLists& lists, ExtraVertices&& extra) {
  CsrLists out;
  out.offsets.assign(lists.offsets.size(), 0);
  out.indices.reserve(lists.indices.size());
  std::vector<int> row;
  for (std::size_t q = 0; q < lists.size(); ++q) {
    const auto own = lists[q];
    row.assign(own.begin(), own.end());
    bool added = false;
    for (const int v : extra(q)) {
      if (!std::binary_search(own.begin(), own.end(), v)) {
        row.push_back(v);
        added = true;
      }
    }
    if (added) {
      std::sort(row.begin(), row.end());
      row.erase(std::unique(row.begin(), row.end()), row.end());
    }
    out.indices.insert(out.indices.end(), row.begin(), row.end());
    out.offsets[q + 1] = static_cast<int>(out.indices.size());
  }
  return out;
}

// Each cell's list with the lists of its facets' points merged in: a node whose support reaches a
// facet of the cell but none of its interior points still gets the cell's gradient correction.
CsrLists with_facet_lists(const CsrLists& cell_lists, const detail::CellFacets& facets, const CsrLists& facet_point_lists,
                          std::span<const int> local_cells) {
  const auto per_cell = static_cast<std::size_t>(facets.dim + 1), per_facet = static_cast<std::size_t>(facets.points_per_facet);
  return with_vertices(cell_lists, [&, row = std::vector<int>()](std::size_t local) mutable {
    const std::size_t slot = facets.slot(local_cells[local]);
    row.clear();
    for (std::size_t k = 0; k < per_cell; ++k) {
      const auto f = static_cast<std::size_t>(facets.cell_facets[slot * per_cell + k]);
      for (std::size_t g = 0; g < per_facet; ++g) {
        const auto list = facet_point_lists[f * per_facet + g];
        row.insert(row.end(), list.begin(), list.end());
      }
    }
    return std::span<const int>(row);
  });
}

bool outside_its_cell(const BackgroundCells& cells, const NodeSet& nodes, std::size_t cell, std::span<const double> x) {
  const auto b = barycentric(cells, nodes, cell, x);
  return std::any_of(b.begin(), b.begin() + static_cast<std::ptrdiff_t>(nodes.dim + 1), [](double v) { return v < -1e-10; });
}

// Carried quadrature points move with the map and their cells with its nodal values, but the map
// is not affine on a cell: where it compresses strongly, a point leaves its cell and can lie
// outside the hull of its list (measured: beside the axis, where the neck of the eps = 0.01
// prolate after C0 R0 = 10 squeezes the map, a reset stopped on a point at r = 0.005 with 12
// neighbours all on one side). Such a point gets the vertices of the cell of a Delaunay
// triangulation of the current nodes (in the original numbering, so independent of the ranks)
// that holds it. Returns the number of points given them.
std::size_t add_enclosing_cells(CsrLists& lists, const CellQuadrature& quadrature, const BackgroundCells& cells,
                                std::span<const int> local_cells, const NodeSet& nodes, const NodeSet& original_nodes,
                                std::span<const int> new_index) {
  const auto dim = static_cast<std::size_t>(nodes.dim);
  std::vector<std::size_t> outside;
  for (std::size_t q = 0; q < quadrature.size(); ++q) {
    const auto cell = static_cast<std::size_t>(local_cells[q / static_cast<std::size_t>(quadrature.points_per_cell)]);
    if (outside_its_cell(cells, nodes, cell, quadrature.point(q))) outside.push_back(q);
  }
  if (outside.empty()) return 0;
  const BackgroundCells current = delaunay(original_nodes);
  const CellLocator locator(current, original_nodes);
  std::vector<std::vector<int>> extra(lists.size());
  std::size_t added = 0;
  for (const std::size_t q : outside) {
    const std::span<const double> x(quadrature.points.data() + q * dim, dim);
    const long c = locator.locate(x, 1e-10);
    if (c < 0) continue;  // outside the nodes' hull: the basis reports it
    for (const int v : current.cell(static_cast<std::size_t>(c))) extra[q].push_back(new_index[static_cast<std::size_t>(v)]);
    ++added;
  }
  lists = with_vertices(lists, [&](std::size_t q) { return std::span<const int>(extra[q]); });
  return added;
}

// The primal list of every point of `quadrature` (the points of `local_cells`), each with its
// cell's vertices, so that the point lies in the convex hull of its list and the LME problem there
// has a solution. The support cutoff alone does not guarantee it on strongly graded grids: a fine
// node's support can end short of a point in a long triangle it shares with coarse nodes
// (measured: a dumbbell CVT with h from 0.004 to 0.09, "point outside the convex hull of its
// neighbours" at 41 neighbours). A vertex added this way contributes its Gaussian factor, below
// tol0 there.
CsrLists point_lists_of_cells(const LmeBasis& basis, const CellQuadrature& quadrature, const BackgroundCells& cells,
                              std::span<const int> local_cells) {
  const auto per_cell = static_cast<std::size_t>(quadrature.points_per_cell);
  return with_vertices(basis.neighbour_lists(quadrature.points),
                       [&](std::size_t q) { return cells.cell(static_cast<std::size_t>(local_cells[q / per_cell])); });
}

// Every facet point's neighbours and its facet's vertices. The point lies inside its facet, so it
// is strictly inside the hull of its list when the list holds nodes on both sides of the facet's
// plane. Where a side has none — a hull facet whose points see only nodes of its own face (a
// boundary refined more finely than the nodes beside it), or an interior facet whose nodes on one
// side are fine and their supports end short of it (measured: SENT on following nodes, a facet
// point 0.01 from the right edge between a node of the edge and one of the refined band, every
// other neighbour below) — the point lies on the boundary of that hull, where the dual problem has
// no solution: the vertices of the cell on that side join, as a quadrature point's own cell's do.
CsrLists facet_point_lists(const LmeBasis& basis, const detail::CellFacets& facets, const BackgroundCells& cells, const NodeSet& nodes) {
  const CsrLists own = basis.neighbour_lists(facets.points);
  const auto per_facet = static_cast<std::size_t>(facets.points_per_facet);
  const auto dim = static_cast<std::size_t>(nodes.dim);
  // -1, 0 or +1: the side of the facet's plane a node lies on (0 within rounding of the plane).
  auto side = [&](std::size_t f, int node) {
    const auto v0 = nodes.point(static_cast<std::size_t>(facets.facet_vertices(f)[0])), x = nodes.point(static_cast<std::size_t>(node));
    double distance = 0, size = 0;
    for (std::size_t i = 0; i < dim; ++i) {
      distance += (x[i] - v0[i]) * facets.normals[f * dim + i];
      size = std::max(size, std::abs(x[i] - v0[i]));
    }
    if (std::abs(distance) <= 1e-10 * std::max(size, 1e-300)) return 0;
    return distance > 0 ? 1 : -1;
  };
  return with_vertices(own, [&](std::size_t p) {
    const std::size_t f = p / per_facet;
    const auto facet = facets.facet_vertices(f);
    std::vector<int> extra(facet.begin(), facet.end());
    bool above = false, below = false;
    for (const int a : own[p]) {
      const int s = side(f, a);
      above = above || s > 0;
      below = below || s < 0;
    }
    for (const int c : {facets.sharing[2 * f], facets.sharing[2 * f + 1]}) {
      if (c < 0) continue;
      const auto vertices = cells.cell(static_cast<std::size_t>(c));
      int cell_side = 0;
      for (const int v : vertices) cell_side = cell_side != 0 ? cell_side : side(f, v);
      if ((cell_side > 0 && !above) || (cell_side < 0 && !below)) extra.insert(extra.end(), vertices.begin(), vertices.end());
    }
    return extra;
  });
}

}  // namespace

void Discretization::search_cells_whose_facets_list_owned_nodes(std::vector<char>& searched) const {
  // A facet point's list can hold the vertices of the facet's first cell (a flat neighbourhood,
  // facet_point_lists), which the other cell sharing the facet merges into its element: that
  // element can reach an owned node no support of its own reaches (measured: SENT on 2 ranks with
  // support_tolerance = 1e-3, a cell point with an empty list). Its points are searched too.
  // Such a cell shares a facet with a cell that has an owned vertex, which the centroid test has
  // searched: it is among the cells whose facets were built (the searched ones and their neighbours).
  const auto per_cell = static_cast<std::size_t>(dim() + 1), per_facet = static_cast<std::size_t>(facets_->points_per_facet);
  for (std::size_t slot = 0; slot < facets_->cells.size(); ++slot) {
    const auto c = static_cast<std::size_t>(facets_->cells[slot]);
    if (searched[c]) continue;
    for (std::size_t k = 0; k < per_cell && !searched[c]; ++k) {
      const auto f = static_cast<std::size_t>(facets_->cell_facets[slot * per_cell + k]);
      for (std::size_t g = 0; g < per_facet && !searched[c]; ++g)
        for (const int a : facet_point_lists_[f * per_facet + g])
          if (owns(a)) {
            searched[c] = 1;
            break;
          }
    }
  }
}

std::vector<char> Discretization::cells_reaching_owned_nodes() const {
  // A point x lists node a when |x - x_a| <= r_a (or its mirror image does). A cell's points lie
  // within R_c of its centroid (R_c: the centroid's largest vertex distance), so a cell none of
  // whose points lists an owned node has no owned node a with |centroid - x_a| <= r_a + R_c: the
  // test below keeps every cell with an element on this rank, and a few more.
  const int begin = owned_begin(), end = owned_end();
  const auto d = static_cast<std::size_t>(dim());
  std::vector<char> searched(cells_.size(), 0);
  if (begin == end) return searched;
  std::vector<double> owned(nodes_.coords.begin() + std::ptrdiff_t(std::size_t(begin) * d),
                            nodes_.coords.begin() + std::ptrdiff_t(std::size_t(end) * d));
  const KdTree tree(NodeSet(dim(), std::move(owned)));
  const auto radius = basis_->support_radii();
  const double largest = *std::max_element(radius.begin() + begin, radius.begin() + end);
  const auto& mirrors = options_.lme.mirrors;
  std::vector<int> near;
  std::array<double, 3> centroid{}, image{};
  // With carried points the quadrature still holds every cell's points here (select_local_cells).
  const auto per_cell = static_cast<std::size_t>(quadrature_.points_per_cell);
  for (std::size_t c = 0; c < cells_.size(); ++c) {
    const auto vertices = cells_.cell(c);
    centroid.fill(0);
    for (const int v : vertices)
      for (std::size_t i = 0; i < d; ++i) centroid[i] += nodes_.coords[std::size_t(v) * d + i] / double(vertices.size());
    double extent = 0;
    for (const int v : vertices) {
      double r2 = 0;
      for (std::size_t i = 0; i < d; ++i) r2 += std::pow(nodes_.coords[std::size_t(v) * d + i] - centroid[i], 2);
      extent = std::max(extent, std::sqrt(r2));
    }
    if (options_.carried) {
      // Carried points need not lie in their cells (add_enclosing_cells). One outside its cell
      // takes the vertices of a cell of the current triangulation, which any rank may own: every
      // rank searches such a cell.
      bool outside = false;
      for (std::size_t k = 0; k < per_cell; ++k) {
        const auto x = quadrature_.point(c * per_cell + k);
        double r2 = 0;
        for (std::size_t i = 0; i < d; ++i) r2 += std::pow(x[i] - centroid[i], 2);
        extent = std::max(extent, std::sqrt(r2));
        outside = outside || outside_its_cell(cells_, nodes_, c, x);
      }
      if (outside) {
        searched[c] = 1;
        continue;
      }
    }
    const auto reaches = [&](const std::array<double, 3>& x) {
      tree.radius_search(std::span<const double>(x.data(), d), largest + extent, near);
      for (const int k : near) {
        const auto a = std::size_t(begin + k);
        double r2 = 0;
        for (std::size_t i = 0; i < d; ++i) r2 += std::pow(nodes_.coords[a * d + i] - x[i], 2);
        if (std::sqrt(r2) <= radius[a] + extent) return true;
      }
      return false;
    };
    bool hit = reaches(centroid);
    // Its images across every subset of the mirror planes reach the owned nodes' images.
    for (std::size_t mask = 1; !hit && mask < (std::size_t(1) << mirrors.size()); ++mask) {
      image = centroid;
      for (std::size_t p = 0; p < mirrors.size(); ++p)
        if (mask & (std::size_t(1) << p)) image[std::size_t(mirrors[p].axis)] = 2 * mirrors[p].position - centroid[std::size_t(mirrors[p].axis)];
      hit = reaches(image);
    }
    searched[c] = hit ? 1 : 0;
  }
  return searched;
}

double Discretization::mean_point_neighbours() const noexcept {
  std::size_t searched = 0;
  for (std::size_t q = 0; q < point_lists_.size(); ++q) searched += point_lists_.offsets[q + 1] > point_lists_.offsets[q] ? 1 : 0;
  return searched == 0 ? 0.0 : static_cast<double>(point_lists_.total()) / static_cast<double>(searched);
}

Discretization::MemoryReport Discretization::memory_report() const noexcept {
  constexpr double kDouble = sizeof(double), kInt = sizeof(int);
  MemoryReport m;
  const double n = n_nodes(), d = dim();
  // Coordinates (the node set, the basis' copy, the kd-tree's copy), gamma, spacing, beta, radius,
  // the partition's three maps.
  m.replicated_bytes = n * (3 * d + 4) * kDouble + n * 3 * kInt;
  m.replicated_bytes += double(cells_.connectivity.size()) * kInt + double(cells_.measures.size()) * kDouble;
  m.local_bytes = double(quadrature_.points.size() + quadrature_.weights.size()) * kDouble;
  m.local_bytes += double(point_lists_.offsets.size() + point_lists_.indices.size() + local_cells_.size()) * kInt;
  m.local_bytes += double(basis_storage_doubles()) * kDouble;
  if (facets_) {
    const detail::CellFacets& f = *facets_;
    m.local_bytes += double(f.points.size() + f.weights.size() + f.normals.size()) * kDouble;
    m.local_bytes += double(f.cells.size() + f.vertices.size() + f.cell_facets.size() + f.sharing.size()) * kInt + double(f.cell_signs.size());
    m.local_bytes += double(facet_point_lists_.offsets.size() + facet_point_lists_.indices.size()) * kInt;
  }
  for (const ElementSet& e : domains_)
    m.local_bytes += double(e.element_lists().indices.size() * 2 + e.element_lists().offsets.size() * 2) * kInt +
                     double(e.n_elements()) * (3 * kInt + 1);
  m.local_bytes += double(pattern_.nonzeros()) * kInt + double(ghosts_.size()) * kInt;
  return m;
}

Discretization::Discretization(MPI_Comm comm, const NodeSet& nodes, DiscretizationOptions options)
    : comm_(comm), options_(std::move(options)) {
  MPI_Comm_rank(comm_, &rank_);
  MPI_Comm_size(comm_, &size_);
  if (options_.basis_order < 0 || options_.basis_order > 2) {
    throw std::invalid_argument("Discretization: basis_order must be 0, 1 or 2, got " +
                                std::to_string(options_.basis_order));
  }
  const int n = static_cast<int>(nodes.size());
  if (size_ > n)
    throw std::invalid_argument("Discretization: " + std::to_string(size_) + " MPI ranks for " + std::to_string(n) +
                                " nodes; every rank needs at least one node: run on at most " + std::to_string(n) + " ranks");
  const std::vector<double> gamma = expand_gamma(options_.gamma, nodes.size());
  if (options_.consistent_integration != 0) {
    if (options_.consistent_integration < 0) throw std::invalid_argument("Discretization: consistent_integration must be >= 0");
    if (nodes.dim < 2) throw std::invalid_argument("Discretization: consistent integration needs 2D or 3D cells");
    if (options_.strategy != NeighbourhoodStrategy::CellBased)
      throw std::invalid_argument("Discretization: consistent integration corrects gradients cell by cell: it needs cell-based neighbourhoods");
    if (options_.carried)
      throw std::invalid_argument("Discretization: consistent integration needs the cells' own simplex rule, not carried quadrature points");
  }

  // Stage: neighbours in the original numbering (spacing, β, supports) and the partition.
  std::vector<double> spacing;
  {
    StageClock clock(times_.neighbour_search);
    LmeBasis original(nodes, gamma, options_.lme);
    spacing.assign(original.spacing().begin(), original.spacing().end());
    if (size_ > 1 && options_.partition == PartitionMethod::Metis) {
      // Nodes couple when their supports overlap a common point; the node-to-node lists of the
      // supports are the graph the matrix will have, up to the quadrature points. Rank 0
      // partitions and sends the parts: ranks that each ran METIS on the same graph were measured
      // to disagree (3D, 8 parts: two ranks owned the same rows and the ghosted vector failed).
      std::vector<int> parts(static_cast<std::size_t>(n));
      std::exception_ptr failure;
      if (rank_ == 0) {
        try {
          const CsrLists node_lists = original.neighbour_lists(nodes.coords);
          parts = partition_nodes(node_lists.offsets, node_lists.indices, size_).part_of;
        } catch (const std::exception& e) {
          failure = std::make_exception_ptr(std::runtime_error(std::string("Discretization: partitioning the nodes: ") + e.what()));
        }
      }
      // Every rank throws rank 0's error, none waits for parts forever.
      throw_on_every_rank(comm_, failure);
      MPI_Bcast(parts.data(), n, MPI_INT, 0, comm_);
      partition_ = partition_from_parts(std::move(parts), size_);
    } else if (size_ > 1 && options_.partition == PartitionMethod::Hilbert) {
      partition_ = hilbert_partition(nodes.coords, nodes.dim, size_);
    } else {
      partition_ = block_partition(n, size_);
    }
    if (size_ == 1) basis_.emplace(std::move(original));
  }

  // Stage: cells. Triangulated in the original numbering so that cells, and hence quadrature
  // points, do not depend on the number of ranks (cocircular grids have several Delaunay
  // triangulations and qhull's choice depends on the input order).
  {
    StageClock clock(times_.cells);
    rule_ = rule_for(nodes.dim, options_.quadrature_points);
    if (options_.carried) {
      const CarriedQuadrature& c = *options_.carried;
      if (c.cells.dim != nodes.dim || c.quadrature.dim != nodes.dim || c.quadrature.cells() != c.cells.size())
        throw std::invalid_argument("Discretization: carried quadrature of " + std::to_string(c.quadrature.cells()) +
                                    " cells for " + std::to_string(c.cells.size()) + " background cells");
      for (const int v : c.cells.connectivity)
        if (v < 0 || v >= n) throw std::invalid_argument("Discretization: a carried cell names node " + std::to_string(v));
      // Moved, not copied: the options keep the cells, not every point.
      quadrature_ = std::move(options_.carried->quadrature);
      cells_ = c.cells;
    } else {
      DelaunayOptions delaunay_options;
      delaunay_options.flat_tolerance = options_.flat_cell_tolerance;
      // A node whose only cells were dropped as flat still has its support: other cells' points.
      delaunay_options.allow_unused_nodes = options_.flat_cell_tolerance > DelaunayOptions{}.flat_tolerance;
      cells_ = delaunay(nodes, delaunay_options);
    }
    for (int& v : cells_.connectivity) v = partition_.new_index[static_cast<std::size_t>(v)];
  }

  // Renumbered nodes and basis.
  {
    StageClock clock(times_.neighbour_search);
    std::vector<double> coords(nodes.coords.size());
    std::vector<double> renumbered_gamma(static_cast<std::size_t>(n));
    std::vector<double> renumbered_spacing(static_cast<std::size_t>(n));
    const auto d = static_cast<std::size_t>(nodes.dim);
    for (int b = 0; b < n; ++b) {
      const auto old = static_cast<std::size_t>(partition_.old_index[static_cast<std::size_t>(b)]);
      std::copy_n(nodes.coords.begin() + static_cast<std::ptrdiff_t>(old * d), d,
                  coords.begin() + static_cast<std::ptrdiff_t>(static_cast<std::size_t>(b) * d));
      renumbered_gamma[static_cast<std::size_t>(b)] = gamma[old];
      renumbered_spacing[static_cast<std::size_t>(b)] = spacing[old];
    }
    nodes_ = NodeSet(nodes.dim, std::move(coords));
    if (!basis_) basis_.emplace(nodes_, renumbered_gamma, std::move(renumbered_spacing), options_.lme);
    select_local_cells();
  }
  if (!options_.carried) {
    StageClock clock(times_.cells);
    // The renumbered connectivity lists each cell's vertices in the triangulation's order: the
    // points are those of the original numbering to the last bit.
    quadrature_ = map_to_cells(cells_, nodes_, rule_, local_cells_);
  }
  {
    StageClock clock(times_.neighbour_search);
    point_lists_ = point_lists_of_cells(*basis_, quadrature_, cells_, local_cells_);
    if (options_.carried)
      points_outside_carried_cells_ =
          add_enclosing_cells(point_lists_, quadrature_, cells_, local_cells_, nodes_, nodes, partition_.new_index);
  }

  // Elements of every integration domain; ghosts and the pattern of their union; basis storage.
  {
    StageClock clock(times_.neighbour_search);
    build_cell_domain();
    boundary_point_lists_.reserve(options_.boundary.size());  // the domains view them: no reallocation
    for (const BoundaryQuadrature& q : options_.boundary) build_boundary_domain(q);
  }
  {
    StageClock clock(times_.structure);
    build_ghosts_and_pattern();
  }
  {
    StageClock clock(times_.basis);
    std::exception_ptr failure;
    try {
      for (ElementSet& d : domains_) d.build_storage(*basis_, options_.storage, options_.basis_order, options_.strategy);
      if (facets_ && options_.basis_order >= 1) build_gradient_correction();
    } catch (...) {
      failure = std::current_exception();
    }
    // Each rank evaluates the basis at its own elements' points only: a point one rank cannot
    // evaluate must stop every rank here, not leave the others waiting in the next collective call
    // (measured: SENT on 2 ranks hung in MatDestroy on the failing rank, in VecCreateGhost on the other).
    throw_on_every_rank(comm_, failure);
  }
}

// The cells whose points this rank holds (local_cells_): those that can reach one of its nodes, and
// with consistent integration those that reach one through a facet point's list, whose facets it
// builds with the searched cells' neighbours (facets_, facet_point_lists_).
void Discretization::select_local_cells() {
  // The neighbour search is the costliest part of the setup, and the points and their lists the
  // largest per-point arrays: a rank maps the rule onto the cells where its elements can be only.
  const bool every_cell = size_ == 1;
  std::vector<char> searched = every_cell ? std::vector<char>(cells_.size(), 1) : cells_reaching_owned_nodes();
  const auto marked = [&] {
    std::vector<int> ids;
    for (std::size_t c = 0; c < cells_.size(); ++c)
      if (searched[c]) ids.push_back(static_cast<int>(c));
    return ids;
  };
  if (options_.consistent_integration > 0) {
    // The facets of the searched cells and of their neighbours, with their points' lists.
    const int m = options_.consistent_integration;
    const QuadratureRule facet_rule = dim() == 2 ? gauss_legendre(m) : triangle_rule(m);
    std::vector<int> near = marked();
    if (!every_cell) {
      const detail::CellFacets inner = detail::cell_facets(cells_, nodes_, facet_rule, near);
      near.insert(near.end(), inner.sharing.begin(), inner.sharing.end());
      std::sort(near.begin(), near.end());
      near.erase(std::unique(near.begin(), near.end()), near.end());
      if (!near.empty() && near.front() < 0) near.erase(near.begin());
    }
    facets_ = std::make_shared<const detail::CellFacets>(detail::cell_facets(cells_, nodes_, facet_rule, near));
    facet_point_lists_ = facet_point_lists(*basis_, *facets_, cells_, nodes_);
    if (!every_cell) search_cells_whose_facets_list_owned_nodes(searched);
  }
  local_cells_ = marked();
  if (options_.carried && !every_cell) {
    // The carried points of every cell came in; this rank keeps those of its cells.
    CellQuadrature mine;
    mine.dim = quadrature_.dim;
    mine.points_per_cell = quadrature_.points_per_cell;
    const auto per_cell = static_cast<std::size_t>(quadrature_.points_per_cell), d = static_cast<std::size_t>(dim());
    mine.points.reserve(local_cells_.size() * per_cell * d);
    mine.weights.reserve(local_cells_.size() * per_cell);
    for (const int c : local_cells_) {
      const auto first = std::size_t(c) * per_cell;
      mine.points.insert(mine.points.end(), quadrature_.points.begin() + std::ptrdiff_t(first * d),
                         quadrature_.points.begin() + std::ptrdiff_t((first + per_cell) * d));
      mine.weights.insert(mine.weights.end(), quadrature_.weights.begin() + std::ptrdiff_t(first),
                          quadrature_.weights.begin() + std::ptrdiff_t(first + per_cell));
    }
    quadrature_ = std::move(mine);
  }
}

void Discretization::build_cell_domain() {
  ElementSet cells;
  cells.name_ = "cells";
  cells.dim_ = dim();
  cells.points_ = quadrature_.points;
  cells.weights_ = quadrature_.weights;
  cells.point_lists_ = &point_lists_;
  // Elements: cells (union of their points' lists) or single points.
  const bool cell_based = options_.strategy == NeighbourhoodStrategy::CellBased;
  const int points_per_element = cell_based ? quadrature_.points_per_cell : 1;
  CsrLists all_elements = cell_based ? union_of_groups(point_lists_, points_per_element, n_nodes()) : point_lists_;
  std::vector<int> ids(all_elements.size());
  const auto per_cell = static_cast<std::size_t>(quadrature_.points_per_cell);
  for (std::size_t e = 0; e < ids.size(); ++e)
    ids[e] = cell_based ? local_cells_[e] : local_cells_[e / per_cell] * static_cast<int>(per_cell) + static_cast<int>(e % per_cell);
  if (facets_) all_elements = with_facet_lists(all_elements, *facets_, facet_point_lists_, local_cells_);
  cells.select_local_elements(all_elements, points_per_element, owned_begin(), owned_end(), ids);
  domains_.push_back(std::move(cells));
}

void Discretization::build_gradient_correction() {
  ElementSet& cells = domains_.front();
  const detail::CellFacets& facets = *facets_;
  const auto d = static_cast<std::size_t>(dim());
  const auto per_cell = d + 1, per_facet = static_cast<std::size_t>(facets.points_per_facet);
  const auto points_per_cell = static_cast<std::size_t>(quadrature_.points_per_cell);
  // With Hessians tabulated, they are corrected as well: sum_q w_q HN_a(x_q) = sym(oint grad N_a (x) n ds)
  // cell by cell, the divergence theorem a fourth-order form needs to be integrated consistently.
  const bool hessians = options_.basis_order >= 2;
  const int order = hessians ? 2 : 1;
  const auto jet = static_cast<std::size_t>(kernel::jet_size(dim(), order));
  const std::size_t packed = d * (d + 1) / 2;
  std::vector<double> correction(cells.element_nodes_.indices.size() * d, 0.0);
  std::vector<double> hessian_correction(hessians ? cells.element_nodes_.indices.size() * packed : 0, 0.0);
  // Hull facets belong to one cell. Exactly on the hull the derivatives are the limit of a singular
  // solve: their gradients are taken a thousandth of the facet inside, as on the boundary domains.
  std::vector<double> tabulation, inner(d);
  LmeWorkspace ws;
  for (int e = 0; e < cells.n_elements(); ++e) {
    const auto element = cells.element_nodes(e);
    const std::size_t n = element.size();
    const auto offset = static_cast<std::size_t>(cells.element_nodes_.offsets[std::size_t(e)]);
    const std::span<double> c(correction.data() + offset * d, n * d);
    const std::span<double> h(hessians ? hessian_correction.data() + offset * packed : nullptr, hessians ? n * packed : 0);
    tabulation.assign(points_per_cell * jet * n, 0.0);
    cells.tabulate(e, order, tabulation, ws);
    const auto first = static_cast<std::size_t>(cells.element_first_point(e));
    double measure = 0;
    for (std::size_t k = 0; k < points_per_cell; ++k) {
      const double w = quadrature_.weights[first + k];
      measure += w;
      for (std::size_t i = 0; i < d; ++i)
        for (std::size_t a = 0; a < n; ++a) c[a * d + i] -= w * tabulation[(k * jet + 1 + i) * n + a];
      for (std::size_t slot = 0; slot < (hessians ? packed : 0); ++slot)
        for (std::size_t a = 0; a < n; ++a) h[a * packed + slot] -= w * tabulation[(k * jet + 1 + d + slot) * n + a];
    }
    const std::size_t cell_slot = facets.slot(point_cell(first));
    for (std::size_t k = 0; k < per_cell; ++k) {
      const auto f = static_cast<std::size_t>(facets.cell_facets[cell_slot * per_cell + k]);
      const double sign = facets.cell_signs[cell_slot * per_cell + k];
      const bool hull = facets.cells_sharing(f) == 1;
      const double* normal = facets.normals.data() + f * d;
      for (std::size_t g = 0; g < per_facet; ++g) {
        const std::size_t p = f * per_facet + g;
        const auto list = facet_point_lists_[p];
        const std::size_t m_count = list.size();
        const std::span<const double> x(facets.points.data() + p * d, d);
        std::vector<double> values = basis_->evaluate(x, list, hessians && !hull ? 1 : 0);
        if (hessians && hull) {
          double size = 0;
          for (std::size_t q = 0; q < per_facet; ++q) size += facets.weights[f * per_facet + q];
          for (std::size_t i = 0; i < d; ++i) inner[i] = x[i] - 1e-3 * std::pow(size, 1.0 / double(d - 1)) * sign * normal[i];
          std::vector<double> jets = basis_->evaluate(inner, list, 1);
          std::copy(values.begin(), values.end(), jets.begin());  // values on the hull itself
          values = std::move(jets);
        }
        const double w = sign * facets.weights[p];
        for (std::size_t m = 0; m < m_count; ++m) {
          const auto a = static_cast<std::size_t>(std::lower_bound(element.begin(), element.end(), list[m]) - element.begin());
          for (std::size_t i = 0; i < d; ++i) c[a * d + i] += w * values[m] * normal[i];
          if (!hessians) continue;
          for (std::size_t i = 0; i < d; ++i)
            for (std::size_t j = i; j < d; ++j) {
              const auto slot = static_cast<std::size_t>(kernel::hessian_slot(int(i), int(j), dim()) - 1 - dim());
              h[a * packed + slot] += w * 0.5 * (values[(1 + j) * m_count + m] * normal[i] + values[(1 + i) * m_count + m] * normal[j]);
            }
        }
      }
    }
    for (double& v : c) v /= measure;
    for (double& v : h) v /= measure;
  }
  cells.gradient_correction_ = std::move(correction);
  cells.hessian_correction_ = std::move(hessian_correction);
}

void Discretization::build_boundary_domain(const BoundaryQuadrature& q) {
  if (q.dim != dim() || q.points.size() != q.weights.size() * std::size_t(dim()) || q.normals.size() != q.points.size() ||
      q.points_per_facet <= 0 || q.weights.size() % std::size_t(q.points_per_facet) != 0 ||
      q.facet_vertices.size() != q.facets() * std::size_t(q.vertices_per_facet))
    throw std::invalid_argument("Discretization: the boundary quadrature of part '" + q.part + "' is inconsistent");
  for (const int v : q.facet_vertices)
    if (v < 0 || v >= n_nodes()) throw std::invalid_argument("Discretization: a facet of part '" + q.part + "' names node " + std::to_string(v));
  // As for the cells, every point's list holds its facet's vertices: the point lies in the hull
  // of its list (a boundary point is a vertex of that hull at worst).
  const auto per_facet = static_cast<std::size_t>(q.points_per_facet), vertices = static_cast<std::size_t>(q.vertices_per_facet);
  std::vector<int> renumbered(q.facet_vertices.size());
  for (std::size_t k = 0; k < renumbered.size(); ++k) renumbered[k] = partition_.new_index[static_cast<std::size_t>(q.facet_vertices[k])];
  boundary_point_lists_.push_back(with_vertices(basis_->neighbour_lists(q.points), [&](std::size_t p) {
    return std::span<const int>(renumbered.data() + (p / per_facet) * vertices, vertices);
  }));
  ElementSet d;
  d.name_ = q.part;
  d.boundary_ = true;
  d.dim_ = dim();
  d.points_ = q.points;
  d.weights_ = q.weights;
  d.normals_ = q.normals;
  d.point_lists_ = &boundary_point_lists_.back();
  d.inner_points_.resize(q.points.size());
  for (std::size_t p = 0; p < q.weights.size(); ++p) {
    // The facet's size: its length (2D) or the square root of its area (3D), from the rule's weights.
    double measure = 0;
    for (std::size_t g = (p / per_facet) * per_facet; g < (p / per_facet + 1) * per_facet; ++g) measure += q.weights[g];
    const double size = dim() == 2 ? measure : std::sqrt(measure);
    for (std::size_t i = 0; i < std::size_t(dim()); ++i)
      d.inner_points_[p * std::size_t(dim()) + i] = q.points[p * std::size_t(dim()) + i] - 1e-3 * size * q.normals[p * std::size_t(dim()) + i];
  }
  const bool cell_based = options_.strategy == NeighbourhoodStrategy::CellBased;
  const int points_per_element = cell_based ? q.points_per_facet : 1;
  const CsrLists all_elements = cell_based ? union_of_groups(*d.point_lists_, points_per_element, n_nodes()) : *d.point_lists_;
  d.select_local_elements(all_elements, points_per_element, owned_begin(), owned_end());
  domains_.push_back(std::move(d));
}

const ElementSet& Discretization::boundary_domain(std::string_view part) const {
  for (std::size_t k = 1; k < domains_.size(); ++k)
    if (domains_[k].name() == part) return domains_[k];
  throw std::out_of_range("Discretization: no boundary domain '" + std::string(part) + "'");
}

void ElementSet::select_local_elements(const CsrLists& all_elements, int points_per_element, int begin, int end,
                                       std::span<const int> ids) {
  element_nodes_ = CsrLists{};
  element_id_.clear();
  element_first_point_.clear();
  element_point_count_.clear();
  element_owned_.clear();
  max_element_nodes_ = 0;
  max_element_points_ = points_per_element;
  for (std::size_t e = 0; e < all_elements.size(); ++e) {
    const auto list = all_elements[e];
    // Lists are sorted: the element touches this rank's rows if some node falls in [begin, end).
    const auto it = std::lower_bound(list.begin(), list.end(), begin);
    const bool touches = it != list.end() && *it < end;
    if (!touches) continue;
    // Exactly one rank owns each element: the owner of its smallest node, which by construction
    // holds the element. It counts the element's energy and, in PetscExchange mode, is the only
    // rank that computes it.
    element_nodes_.push_back(list);
    element_id_.push_back(ids.empty() ? static_cast<int>(e) : ids[e]);
    element_first_point_.push_back(static_cast<int>(e) * points_per_element);
    element_point_count_.push_back(points_per_element);
    element_owned_.push_back(list.front() >= begin ? 1 : 0);
    max_element_nodes_ = std::max(max_element_nodes_, static_cast<int>(list.size()));
  }
}

void ElementSet::number_locally(std::span<const int> ghosts, int begin, int end) {
  element_local_ = CsrLists{};
  element_local_.offsets = element_nodes_.offsets;
  element_local_.indices.resize(element_nodes_.indices.size());
  const int n_owned_nodes = end - begin;
  for (std::size_t k = 0; k < element_nodes_.indices.size(); ++k) {
    const int b = element_nodes_.indices[k];
    if (b >= begin && b < end) {
      element_local_.indices[k] = b - begin;
    } else {
      const auto it = std::lower_bound(ghosts.begin(), ghosts.end(), b);
      element_local_.indices[k] = n_owned_nodes + static_cast<int>(it - ghosts.begin());
    }
  }
}

void Discretization::build_ghosts_and_pattern() {
  const int begin = owned_begin();
  const int end = owned_end();
  ghosts_.clear();
  max_element_nodes_ = max_element_points_ = 0;
  // The pattern of the union of every domain's elements: a boundary facet can couple nodes that
  // no cell's points do.
  CsrLists all;
  for (const ElementSet& d : domains_) {
    for (const int b : d.element_nodes_.indices)
      if (b < begin || b >= end) ghosts_.push_back(b);
    max_element_nodes_ = std::max(max_element_nodes_, d.max_element_nodes());
    max_element_points_ = std::max(max_element_points_, d.max_element_points());
    if (domains_.size() > 1)
      for (std::size_t e = 0; e < d.element_nodes_.size(); ++e) all.push_back(d.element_nodes_[e]);
  }
  std::sort(ghosts_.begin(), ghosts_.end());
  ghosts_.erase(std::unique(ghosts_.begin(), ghosts_.end()), ghosts_.end());
  for (ElementSet& d : domains_) d.number_locally(ghosts_, begin, end);
  const CsrLists& elements = domains_.size() > 1 ? all : domains_.front().element_nodes_;
  const CsrLists dual = dual_lists(elements, n_nodes());
  pattern_ = build_sparsity_pattern(elements.offsets, elements.indices, dual.offsets, dual.indices, n_nodes(), begin, end);
}

namespace {

using BasisStorageVariant = std::variant<std::monostate, LmeFullStorage, LmeCompressedStorage>;

void emplace_storage(BasisStorageVariant& storage, const LmeBasis& basis, std::span<const double> coords, CsrLists lists, int order,
                     BasisStorage kind) {
  if (kind == BasisStorage::Full) storage.emplace<LmeFullStorage>(basis, coords, std::move(lists), order);
  else storage.emplace<LmeCompressedStorage>(basis, coords, std::move(lists), order);
}

void tabulate_from(const BasisStorageVariant& storage, const LmeBasis& basis, bool per_point, std::size_t first,
                   std::span<const int> point_ids, std::span<const int> nodes, int order, std::span<double> out, LmeWorkspace& ws) {
  if (per_point) {
    if (const auto* full = std::get_if<LmeFullStorage>(&storage)) full->point_jet(first, order, out);
    else std::get<LmeCompressedStorage>(storage).point_jet(basis, first, order, out, ws);
    return;
  }
  if (const auto* full = std::get_if<LmeFullStorage>(&storage)) full->tabulate_cell(point_ids, nodes, order, out, ws);
  else std::get<LmeCompressedStorage>(storage).tabulate_cell(basis, point_ids, nodes, order, out, ws);
}

}  // namespace

void ElementSet::build_storage(const LmeBasis& basis, BasisStorage storage, int order, NeighbourhoodStrategy strategy) {
  basis_ = &basis;
  basis_order_ = order;
  strategy_ = strategy;
  // The storage holds the points of this rank's elements, element after element, each point
  // with its own primal list.
  std::vector<int> local_points;
  element_first_local_point_.clear();
  for (int e = 0; e < n_elements(); ++e) {
    element_first_local_point_.push_back(static_cast<int>(local_points.size()));
    for (int q = 0; q < element_point_count(e); ++q) local_points.push_back(element_first_point(e) + q);
  }
  element_first_local_point_.push_back(static_cast<int>(local_points.size()));
  storage_point_ids_.resize(local_points.size());
  for (std::size_t k = 0; k < storage_point_ids_.size(); ++k) storage_point_ids_[k] = static_cast<int>(k);
  const auto d = static_cast<std::size_t>(dim_);
  std::vector<double> coords(local_points.size() * d);
  CsrLists lists;
  lists.offsets.reserve(local_points.size() + 1);
  for (std::size_t k = 0; k < local_points.size(); ++k) {
    const auto q = static_cast<std::size_t>(local_points[k]);
    std::copy_n(points_.begin() + static_cast<std::ptrdiff_t>(q * d), d, coords.begin() + static_cast<std::ptrdiff_t>(k * d));
    lists.push_back((*point_lists_)[q]);
  }
  if (!boundary_ || order == 0) {
    emplace_storage(storage_, basis, coords, std::move(lists), order, storage);
    return;
  }
  std::vector<double> inner(coords.size());
  for (std::size_t k = 0; k < local_points.size(); ++k) {
    const auto q = static_cast<std::size_t>(local_points[k]);
    for (std::size_t i = 0; i < d; ++i) inner[k * d + i] = inner_points_[q * d + i];
  }
  emplace_storage(inner_storage_, basis, inner, lists, order, storage);
  emplace_storage(storage_, basis, coords, std::move(lists), 0, storage);
}

void ElementSet::tabulate(int e, int order, std::span<double> out, LmeWorkspace& ws) const {
  if (order > basis_order_) {
    throw std::invalid_argument("Discretization::tabulate: derivative order " + std::to_string(order) +
                                " requested but the basis was tabulated to order " + std::to_string(basis_order_) +
                                " (set DiscretizationOptions::basis_order to the highest order the forms need)");
  }
  const auto first = static_cast<std::size_t>(element_first_local_point_[static_cast<std::size_t>(e)]);
  const auto count = static_cast<std::size_t>(element_point_count_[static_cast<std::size_t>(e)]);
  const bool per_point = strategy_ == NeighbourhoodStrategy::PerPoint;
  const std::span<const int> point_ids(storage_point_ids_.data() + first, count);
  const std::span<const int> nodes = per_point ? std::span<const int>() : element_nodes(e);
  if (order == 0 || std::holds_alternative<std::monostate>(inner_storage_)) {
    tabulate_from(storage_, *basis_, per_point, first, point_ids, nodes, order, out, ws);
  } else {
    // Derivatives at the inner points, values at the points themselves.
    tabulate_from(inner_storage_, *basis_, per_point, first, point_ids, nodes, order, out, ws);
    const std::size_t n = per_point ? (*point_lists_)[static_cast<std::size_t>(element_first_point(e))].size() : nodes.size();
    const auto jet = static_cast<std::size_t>(kernel::jet_size(dim_, order));
    std::vector<double> values(count * n);
    tabulate_from(storage_, *basis_, per_point, first, point_ids, nodes, 0, values, ws);
    for (std::size_t k = 0; k < count; ++k) std::copy_n(values.begin() + std::ptrdiff_t(k * n), n, out.begin() + std::ptrdiff_t(k * jet * n));
  }
  if (gradient_correction_.empty() || order < 1) return;
  const auto d = static_cast<std::size_t>(dim_), n = element_nodes(e).size();
  const auto jet = static_cast<std::size_t>(kernel::jet_size(dim_, order));
  const double* c = gradient_correction_.data() + static_cast<std::size_t>(element_nodes_.offsets[static_cast<std::size_t>(e)]) * d;
  for (std::size_t k = 0; k < count; ++k)
    for (std::size_t i = 0; i < d; ++i)
      for (std::size_t a = 0; a < n; ++a) out[(k * jet + 1 + i) * n + a] += c[a * d + i];
  if (hessian_correction_.empty() || order < 2) return;
  const std::size_t packed = d * (d + 1) / 2;
  const double* hc = hessian_correction_.data() + static_cast<std::size_t>(element_nodes_.offsets[static_cast<std::size_t>(e)]) * packed;
  for (std::size_t k = 0; k < count; ++k)
    for (std::size_t slot = 0; slot < packed; ++slot)
      for (std::size_t a = 0; a < n; ++a) out[(k * jet + 1 + d + slot) * n + a] += hc[a * packed + slot];
}

std::size_t ElementSet::storage_doubles() const noexcept {
  if (const auto* full = std::get_if<LmeFullStorage>(&storage_)) return full->doubles();
  if (const auto* compressed = std::get_if<LmeCompressedStorage>(&storage_)) return compressed->doubles();
  return 0;
}

std::size_t Discretization::basis_storage_doubles() const noexcept {
  std::size_t total = 0;
  for (const ElementSet& d : domains_) total += d.storage_doubles();
  return total;
}

}  // namespace lmeform
