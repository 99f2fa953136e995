// A meshfree discretization distributed over MPI ranks: the pipeline every assembly runs on.
//
//   nodes ─► LME basis (spacing h_a, β_a = γ_a/h_a², kd-tree, support radii)
//         ─► partition (METIS on rank 0, or a Hilbert curve), renumbering to contiguous row ranges
//         ─► Delaunay background cells ─► the cells near this rank's nodes
//         ─► their Gauss points and the points' primal lists ─► elements
//         ─► this rank's elements, ghost nodes, sparsity pattern of its rows
//         ─► basis storage (full or compressed) for the points of this rank's elements
//
// Elements are what the assembly loops over. With cell-based neighbourhoods an element is a
// background cell whose node list is the union of its quadrature points' lists; with per-point
// neighbourhoods (the standard meshfree scheme) an element is one quadrature point. Both
// evaluate every point against its own primal list, so they assemble the same operator and a
// comparison between them measures the algorithm alone.
//
// Replicated on every rank: the nodes (coordinates, spacing, β, support radii, kd-tree) and the
// background cells (connectivity and measures), a few numbers per node or cell. Distributed: the
// quadrature points, their weights and primal lists (a rank maps the rule onto the cells that can
// reach one of its nodes only, and numbers their points locally), elements, pattern, basis storage
// and assembly. A rank works only on the elements that touch its rows. Points carried from an
// earlier reference configuration (DiscretizationOptions::carried) come in for every cell; a rank
// keeps those of its cells.
#pragma once

#include <mpi.h>

#include <memory>
#include <optional>
#include <string>
#include <string_view>
#include <span>
#include <variant>
#include <vector>

#include "lmeform/delaunay.hpp"
#include "lmeform/domain.hpp"
#include "lmeform/lme_basis.hpp"
#include "lmeform/lme_storage.hpp"
#include "lmeform/neighbour_search.hpp"
#include "lmeform/node_set.hpp"
#include "lmeform/partition.hpp"
#include "lmeform/quadrature.hpp"
#include "lmeform/sparsity_pattern.hpp"

namespace lmeform {

namespace detail {
struct CellFacets;
}

enum class NeighbourhoodStrategy {
  CellBased,  ///< one element per background cell (seed Algorithm 2)
  PerPoint,   ///< one element per quadrature point (seed Algorithm 1)
};

enum class BasisStorage {
  Full,        ///< p, ∇p, Hp of every neighbour of every point
  Compressed,  ///< per point Z, λ, r_β, Dλ, β̄, J, Q, T; rebuilt at each assembly
};

enum class OffProcessMode {
  ZeroCommunication,  ///< each rank computes every element touching its rows and keeps its own rows
  PetscExchange,      ///< each element is computed once; PETSc sends off-process rows
};

[[nodiscard]] const char* to_string(NeighbourhoodStrategy s) noexcept;
[[nodiscard]] const char* to_string(BasisStorage s) noexcept;
[[nodiscard]] const char* to_string(OffProcessMode m) noexcept;

/// Background cells and quadrature points given instead of built from the nodes: a Lagrangian
/// run's reset of the reference configuration carries its quadrature points (x̂ → y(x̂), weights
/// × det F) to the new nodes, keeping the cells' connectivity (the nodes keep their identity).
struct CarriedQuadrature {
  BackgroundCells cells;     ///< connectivity in the original node numbering
  CellQuadrature quadrature; ///< points grouped by cell (points_per_cell per cell, cell order)
};

struct DiscretizationOptions {
  std::vector<double> gamma{1.6};  ///< one γ for all nodes, or one per node (original numbering)
  LmeOptions lme{};                ///< passed to the basis unchanged (mirror, spacing smoothing, consistency)
  int quadrature_points = 6;       ///< Gauss points per background cell (a rule size of quadrature.hpp)
  int basis_order = 1;             ///< derivative order tabulated: the highest the forms need
  NeighbourhoodStrategy strategy = NeighbourhoodStrategy::CellBased;
  BasisStorage storage = BasisStorage::Full;
  OffProcessMode off_process = OffProcessMode::ZeroCommunication;
  /// How the nodes are split among ranks (partition.hpp). METIS needs every node's list on every
  /// rank first; the Hilbert curve needs the coordinates only.
  PartitionMethod partition = PartitionMethod::Metis;
  /// Set: these cells and points, no triangulation. The points of every cell come in (numbered
  /// cell × points_per_cell + k, on every rank); the rank keeps those of its cells and the options
  /// keep the cells alone.
  std::optional<CarriedQuadrature> carried;
  /// Background cells flatter than this (area over longest edge squared, DelaunayOptions) are
  /// dropped. Nodes that moved off a straight boundary leave slivers along it whose quadrature
  /// points lie on the hull to round-off, where the LME derivatives are undefined: a moving node
  /// set drops them with a larger tolerance.
  double flat_cell_tolerance = 1e-12;
  /// Boundary parts that forms integrate over (ds(part)): their quadrature, facet vertices in the
  /// original node numbering. Each becomes an integration domain of its own.
  std::vector<BoundaryQuadrature> boundary;
  /// 0: the basis gradients as evaluated. n > 0: corrected cell by cell so that the rule satisfies
  /// the divergence theorem on every cell against a facet rule of n points (Gauss–Legendre points
  /// per edge in 2D, a triangle rule in 3D: give the boundary quadrature's rule, so that hull facets
  /// carry the points of `ds`). Linear fields are then reproduced exactly (the patch test) with any
  /// interior rule. Cell-based neighbourhoods, 2D and 3D, triangulated cells only
  /// (src/assembly/cell_facets.hpp).
  int consistent_integration = 0;
};

/// Wall-clock seconds of each stage (this rank).
struct StageTimes {
  double neighbour_search = 0;  ///< LME setup, node lists, partition, point lists, element lists
  double cells = 0;             ///< Delaunay and quadrature
  double basis = 0;             ///< basis evaluation into storage
  double structure = 0;         ///< local elements, ghosts, sparsity pattern
};

/// The elements of one integration domain on this rank, what an assembly loops over: the
/// background cells (or their single points), or the facets of a boundary part. Every point is
/// evaluated against its own primal list, and an element's list is the union of its points'.
class ElementSet {
 public:
  /// "cells", or the boundary part's name ("" for the whole boundary).
  [[nodiscard]] const std::string& name() const noexcept { return name_; }
  [[nodiscard]] bool boundary() const noexcept { return boundary_; }

  /// The points of the domain this rank holds: for the cells, those of Discretization::local_cells()
  /// (every point on one rank); for a boundary part, every point (the same on every rank).
  [[nodiscard]] std::size_t n_points() const noexcept { return weights_.size(); }
  [[nodiscard]] std::span<const double> points() const noexcept { return points_; }
  [[nodiscard]] std::span<const double> weights() const noexcept { return weights_; }
  /// Outward unit normals (boundary domains; empty for the cells).
  [[nodiscard]] std::span<const double> normals() const noexcept { return normals_; }
  [[nodiscard]] std::span<const double> point(std::size_t q) const noexcept {
    return {points_.data() + q * static_cast<std::size_t>(dim_), static_cast<std::size_t>(dim_)};
  }
  [[nodiscard]] const CsrLists& point_lists() const noexcept { return *point_lists_; }

  /// This rank's elements.
  [[nodiscard]] int n_elements() const noexcept { return static_cast<int>(element_nodes_.size()); }
  /// Renumbered global nodes of element e, sorted.
  [[nodiscard]] std::span<const int> element_nodes(int e) const noexcept { return element_nodes_[static_cast<std::size_t>(e)]; }
  /// The same nodes as positions in the local (owned + ghost) numbering.
  [[nodiscard]] std::span<const int> element_local_nodes(int e) const noexcept { return element_local_[static_cast<std::size_t>(e)]; }
  /// The element's number on every rank: its cell (cell-based) or point (per point, as the cells
  /// number their points: cell × points per cell + k), or its facet or facet point on a boundary.
  [[nodiscard]] int element_id(int e) const noexcept { return element_id_[static_cast<std::size_t>(e)]; }
  /// Points of element e, in this rank's numbering of the domain's points: [first, first + count).
  [[nodiscard]] int element_first_point(int e) const noexcept { return element_first_point_[static_cast<std::size_t>(e)]; }
  [[nodiscard]] int element_point_count(int e) const noexcept { return element_point_count_[static_cast<std::size_t>(e)]; }
  /// True on exactly one rank per element: that rank counts it for energies and, in
  /// PetscExchange mode, is the only one to compute it.
  [[nodiscard]] bool element_owned(int e) const noexcept { return element_owned_[static_cast<std::size_t>(e)] != 0; }
  [[nodiscard]] int max_element_nodes() const noexcept { return max_element_nodes_; }
  [[nodiscard]] int max_element_points() const noexcept { return max_element_points_; }
  [[nodiscard]] const CsrLists& element_lists() const noexcept { return element_nodes_; }

  /// Writes element e's basis tabulation in the kernel layout basis[(q*J + s)*n + a],
  /// J = jet_size(dim, order). Throws if order exceeds the tabulated order.
  void tabulate(int e, int order, std::span<double> out, LmeWorkspace& ws) const;
  /// Doubles held by the basis storage of this rank's points.
  [[nodiscard]] std::size_t storage_doubles() const noexcept;

 private:
  friend class Discretization;
  /// `ids`: the elements' numbers on every rank (empty: their positions in `all_elements`).
  void select_local_elements(const CsrLists& all_elements, int points_per_element, int begin, int end, std::span<const int> ids = {});
  void number_locally(std::span<const int> ghosts, int begin, int end);
  void build_storage(const LmeBasis& basis, BasisStorage storage, int order, NeighbourhoodStrategy strategy);

  std::string name_;
  bool boundary_ = false;
  int dim_ = 0;
  int basis_order_ = 0;
  NeighbourhoodStrategy strategy_ = NeighbourhoodStrategy::CellBased;
  const LmeBasis* basis_ = nullptr;
  // Views of the points and their lists, owned by the Discretization.
  std::span<const double> points_, weights_, normals_;
  const CsrLists* point_lists_ = nullptr;
  CsrLists element_nodes_;
  CsrLists element_local_;
  std::vector<int> element_id_;
  std::vector<int> element_first_point_;
  std::vector<int> element_point_count_;
  std::vector<char> element_owned_;
  std::vector<int> element_first_local_point_;  // into the storage's local points
  int max_element_nodes_ = 0;
  int max_element_points_ = 0;
  std::vector<int> storage_point_ids_;  // 0, 1, 2, ...: element e's storage points are a slice
  std::variant<std::monostate, LmeFullStorage, LmeCompressedStorage> storage_;
  /// Boundary domains, derivatives tabulated: the jets at the points moved inward by a thousandth
  /// of their facet's size. Exactly on the hull of the nodes the LME derivatives are the limit of
  /// an ill-conditioned solve (J is singular across the boundary): the radial stress of the thick
  /// cylinder at r = 1 came out as 40 instead of -1, and -1.05, -1.046, -0.99 at 1e-4, 1e-3, 1e-2
  /// inside. The values stay at the points (a traction's load is exact).
  std::variant<std::monostate, LmeFullStorage, LmeCompressedStorage> inner_storage_;
  std::vector<double> inner_points_;
  /// Consistent integration: per element node (element_nodes_ order) dim values added to the
  /// gradient at every point of the element; empty otherwise.
  std::vector<double> gradient_correction_;
  std::vector<double> hessian_correction_;  ///< packed d(d+1)/2 per element node (basis_order >= 2)
};

class Discretization {
 public:
  /// Builds everything from a node set given identically on every rank of `comm`.
  Discretization(MPI_Comm comm, const NodeSet& nodes, DiscretizationOptions options);
  // The domains point into the basis: neither copied nor moved.
  Discretization(const Discretization&) = delete;
  Discretization& operator=(const Discretization&) = delete;

  [[nodiscard]] MPI_Comm comm() const noexcept { return comm_; }
  [[nodiscard]] int rank() const noexcept { return rank_; }
  [[nodiscard]] int ranks() const noexcept { return size_; }
  [[nodiscard]] int dim() const noexcept { return nodes_.dim; }
  [[nodiscard]] const DiscretizationOptions& options() const noexcept { return options_; }

  /// Nodes in the renumbered order (rank r owns [owned_begin(), owned_end()) on rank r).
  [[nodiscard]] const NodeSet& nodes() const noexcept { return nodes_; }
  [[nodiscard]] int n_nodes() const noexcept { return static_cast<int>(nodes_.size()); }
  [[nodiscard]] const NodePartition& partition() const noexcept { return partition_; }
  [[nodiscard]] int owned_begin() const noexcept { return partition_.offsets[static_cast<std::size_t>(rank_)]; }
  [[nodiscard]] int owned_end() const noexcept { return partition_.offsets[static_cast<std::size_t>(rank_) + 1]; }
  [[nodiscard]] int n_owned() const noexcept { return owned_end() - owned_begin(); }
  [[nodiscard]] bool owns(int node) const noexcept { return node >= owned_begin() && node < owned_end(); }

  [[nodiscard]] const LmeBasis& basis() const noexcept { return *basis_; }
  /// Background cells with renumbered connectivity (triangulated in the original numbering, so
  /// the same cells and quadrature points whatever the number of ranks), all of them on every rank.
  [[nodiscard]] const BackgroundCells& cells() const noexcept { return cells_; }
  [[nodiscard]] const QuadratureRule& rule() const noexcept { return rule_; }
  /// The cells whose points this rank holds, ascending: those that can reach one of its nodes
  /// (every cell on one rank).
  [[nodiscard]] std::span<const int> local_cells() const noexcept { return local_cells_; }
  /// True when this rank holds every cell's points, numbered as the cells number them.
  [[nodiscard]] bool points_on_every_rank() const noexcept { return local_cells_.size() == cells_.size(); }
  /// The points of local_cells(), cell after cell: local point q lies in cell point_cell(q).
  [[nodiscard]] const CellQuadrature& quadrature() const noexcept { return quadrature_; }
  [[nodiscard]] int point_cell(std::size_t q) const noexcept {
    return local_cells_[q / static_cast<std::size_t>(quadrature_.points_per_cell)];
  }
  /// The number every rank gives local point q: cell × points per cell + its place in the cell
  /// (the numbering of a carried quadrature).
  [[nodiscard]] std::size_t global_point(std::size_t q) const noexcept {
    const auto per_cell = static_cast<std::size_t>(quadrature_.points_per_cell);
    return static_cast<std::size_t>(point_cell(q)) * per_cell + q % per_cell;
  }
  /// Primal list (renumbered nodes) of every point of quadrature().
  [[nodiscard]] const CsrLists& point_lists() const noexcept { return point_lists_; }
  /// Carried quadrature: points the map moved out of their cells, whose lists were given the
  /// vertices of a Delaunay cell of the current nodes holding them.
  [[nodiscard]] std::size_t points_outside_carried_cells() const noexcept { return points_outside_carried_cells_; }

  // --- integration domains: the cells, then the boundary parts -------------------------------
  [[nodiscard]] std::span<const ElementSet> domains() const noexcept { return domains_; }
  [[nodiscard]] const ElementSet& cells_domain() const noexcept { return domains_.front(); }
  /// The domain of boundary part `part` (as given in options().boundary); throws std::out_of_range.
  [[nodiscard]] const ElementSet& boundary_domain(std::string_view part) const;

  // --- this rank's elements of the cells -------------------------------------------------
  [[nodiscard]] int n_elements() const noexcept { return cells_domain().n_elements(); }
  [[nodiscard]] std::span<const int> element_nodes(int e) const noexcept { return cells_domain().element_nodes(e); }
  [[nodiscard]] std::span<const int> element_local_nodes(int e) const noexcept { return cells_domain().element_local_nodes(e); }
  [[nodiscard]] int element_first_point(int e) const noexcept { return cells_domain().element_first_point(e); }
  [[nodiscard]] int element_point_count(int e) const noexcept { return cells_domain().element_point_count(e); }
  [[nodiscard]] bool element_owned(int e) const noexcept { return cells_domain().element_owned(e); }
  [[nodiscard]] const CsrLists& element_lists() const noexcept { return cells_domain().element_lists(); }
  /// The largest element over every domain (the scratch an assembly needs).
  [[nodiscard]] int max_element_nodes() const noexcept { return max_element_nodes_; }
  [[nodiscard]] int max_element_points() const noexcept { return max_element_points_; }

  /// Ghost nodes (renumbered, sorted): used by this rank's elements, owned elsewhere. The local
  /// numbering is [owned nodes..., ghost nodes...].
  [[nodiscard]] std::span<const int> ghost_nodes() const noexcept { return ghosts_; }

  /// Node-to-node pattern of this rank's rows.
  [[nodiscard]] const SparsityPattern& pattern() const noexcept { return pattern_; }

  /// Writes cell element e's basis tabulation in the kernel layout basis[(q*J + s)*n + a],
  /// J = jet_size(dim, order). Throws if order exceeds the tabulated order.
  void tabulate(int e, int order, std::span<double> out, LmeWorkspace& ws) const { cells_domain().tabulate(e, order, out, ws); }

  /// Doubles held by the basis storage of this rank (every domain).
  [[nodiscard]] std::size_t basis_storage_doubles() const noexcept;
  /// Mean number of nodes per list of the quadrature points this rank searched.
  [[nodiscard]] double mean_point_neighbours() const noexcept;

  [[nodiscard]] const StageTimes& times() const noexcept { return times_; }

  /// Bytes this rank holds, by kind: what every rank holds whatever the number of ranks (nodes,
  /// cells, partition), and what falls with the ranks (quadrature points, weights and primal lists
  /// of this rank's cells, the facets of consistent integration, elements, pattern, basis storage).
  struct MemoryReport {
    double replicated_bytes = 0;
    double local_bytes = 0;
  };
  [[nodiscard]] MemoryReport memory_report() const noexcept;
  /// Cells whose points this rank holds and searched the neighbours of (all of them on one rank).
  [[nodiscard]] std::size_t cells_searched() const noexcept { return local_cells_.size(); }

  /// Original index of each renumbered node, and the reverse.
  [[nodiscard]] std::span<const int> original_index() const noexcept { return partition_.old_index; }
  [[nodiscard]] std::span<const int> renumbered_index() const noexcept { return partition_.new_index; }

 private:
  void select_local_cells();
  [[nodiscard]] std::vector<char> cells_reaching_owned_nodes() const;
  void search_cells_whose_facets_list_owned_nodes(std::vector<char>& searched) const;
  void build_cell_domain();
  void build_boundary_domain(const BoundaryQuadrature& q);
  void build_gradient_correction();
  void build_ghosts_and_pattern();

  MPI_Comm comm_;
  int rank_ = 0;
  int size_ = 1;
  DiscretizationOptions options_;
  NodeSet nodes_;
  NodePartition partition_;
  std::optional<LmeBasis> basis_;  // built after renumbering
  BackgroundCells cells_;
  std::vector<int> local_cells_;
  QuadratureRule rule_;
  CellQuadrature quadrature_;
  CsrLists point_lists_;
  std::size_t points_outside_carried_cells_ = 0;
  std::vector<CsrLists> boundary_point_lists_;  // per options_.boundary entry
  std::shared_ptr<const detail::CellFacets> facets_;  // consistent integration only
  CsrLists facet_point_lists_;

  std::vector<ElementSet> domains_;  // the cells, then the boundary parts
  int max_element_nodes_ = 0;
  int max_element_points_ = 0;
  std::vector<int> ghosts_;
  SparsityPattern pattern_;
  StageTimes times_;
};

}  // namespace lmeform
