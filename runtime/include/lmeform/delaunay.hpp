// Background cells: a Delaunay triangulation of the nodes (segments in 1D, triangles in 2D,
// tetrahedra in 3D) that carries the quadrature, and point location in it.
#pragma once

#include <array>
#include <cstddef>
#include <span>
#include <vector>

#include "lmeform/node_set.hpp"

namespace lmeform {

/// Simplicial cells over a NodeSet. Every cell has positive signed measure (counter-clockwise
/// triangles, right-handed tetrahedra, increasing segments).
struct BackgroundCells {
  int dim = 0;
  int vertices_per_cell = 0;       ///< dim + 1
  std::vector<int> connectivity;   ///< cell c: connectivity[c * vertices_per_cell + k]
  std::vector<double> measures;    ///< length / area / volume of each cell
  std::size_t dropped_flat_cells = 0;  ///< flat simplices qhull emitted and delaunay() dropped (diagnostic)

  [[nodiscard]] std::size_t size() const noexcept { return measures.size(); }
  [[nodiscard]] std::span<const int> cell(std::size_t c) const noexcept {
    return {connectivity.data() + c * static_cast<std::size_t>(vertices_per_cell),
            static_cast<std::size_t>(vertices_per_cell)};
  }
  [[nodiscard]] double total_measure() const noexcept;
};

struct DelaunayOptions {
  /// Cells with |measure| <= tolerance * (longest edge)^dim are flat and dropped (counted in
  /// dropped_flat_cells). The triangulation of merged cospherical cells emits none; this is a guard.
  double flat_tolerance = 1e-12;
  /// A node that is no vertex of any cell (a duplicate, or one qhull dropped as coplanar) is an
  /// error unless allowed: every node must be covered by the background mesh.
  bool allow_unused_nodes = false;
};

/// Delaunay cells of the nodes, by qhull ("d Qbb Qz") in 2D/3D and by sorting in 1D. Degenerate
/// (cocircular / cospherical) groups such as the squares and cubes of uniform grids are split by a
/// pulling triangulation in the global node order: conforming, and without flat cells (qhull's own
/// 'Qt' leaves zero-volume tetrahedra in cubic grids).
/// Throws std::invalid_argument for fewer than dim + 1 nodes or nodes in a lower-dimensional
/// affine subspace (collinear in 2D, coplanar in 3D), std::runtime_error when qhull fails.
[[nodiscard]] BackgroundCells delaunay(const NodeSet& nodes, const DelaunayOptions& options = {});

/// Signed length / area / volume of the simplex with the given node indices (dim + 1 of them).
[[nodiscard]] double simplex_signed_measure(const NodeSet& nodes, std::span<const int> vertices);

/// Barycentric coordinates of x in cell c (dim + 1 entries, the first belonging to vertex 0).
[[nodiscard]] std::array<double, 4> barycentric(const BackgroundCells& cells, const NodeSet& nodes,
                                                std::size_t c, std::span<const double> x);

/// Point location on a uniform bucket grid over the cells' bounding boxes (about one cell per bucket).
class CellLocator {
 public:
  CellLocator(const BackgroundCells& cells, const NodeSet& nodes);

  /// Index of a cell that contains x (barycentric coordinates >= -tolerance), or -1 when none does.
  /// A point on a shared face may be reported in any of the cells that share it.
  [[nodiscard]] long locate(std::span<const double> x, double tolerance = 1e-12) const;

 private:
  const BackgroundCells* cells_;
  const NodeSet* nodes_;
  std::array<double, 3> lo_{}, width_{};
  std::array<int, 3> bins_{1, 1, 1};
  std::vector<std::size_t> offsets_;   // CSR: cells of bucket b are ids_[offsets_[b] .. offsets_[b+1])
  std::vector<int> ids_;
};

/// Brute-force point location over all cells (for tests and small meshes).
[[nodiscard]] long locate_cell_brute_force(const BackgroundCells& cells, const NodeSet& nodes,
                                           std::span<const double> x, double tolerance = 1e-12);

}  // namespace lmeform
