// The convex hull of a node set: which nodes lie on its boundary (Dirichlet conditions, the weak
// Kronecker-delta property of LME functions), its facets and measure.
#pragma once

#include <cstddef>
#include <vector>

#include "lmeform/node_set.hpp"
#include "lmeform/node_sets.hpp"

namespace lmeform {

struct ConvexHull {
  int dim = 0;
  std::vector<int> vertices;   ///< extreme nodes (corners of the hull), sorted
  /// Boundary simplices (dim nodes each: end points in 2D, triangles in 3D, one node in 1D),
  /// oriented with the outward normal (counter-clockwise seen from outside).
  std::vector<int> facets;
  /// Supporting hyperplanes, one per (merged) hull face: normal n (unit, outward, dim entries)
  /// and offset b, with n.x + b = 0 on the face and n.x + b < 0 inside.
  std::vector<double> normals;
  std::vector<double> offsets;
  double measure = 0.0;        ///< length / area / volume of the hull

  [[nodiscard]] std::size_t facet_count() const noexcept {
    return dim == 0 ? 0 : facets.size() / static_cast<std::size_t>(dim);
  }
};

/// Convex hull by qhull (2D/3D) or min/max (1D). Same errors as delaunay() for degenerate input.
[[nodiscard]] ConvexHull convex_hull(const NodeSet& nodes);

/// Sorted indices of the nodes within `relative_tolerance` * (bounding-box diagonal) of a supporting
/// hyperplane of the hull: the corners and every node on a hull edge or face.
[[nodiscard]] std::vector<int> hull_boundary_nodes(const NodeSet& nodes, double relative_tolerance = 1e-9);
[[nodiscard]] std::vector<int> hull_boundary_nodes(const NodeSet& nodes, const ConvexHull& hull,
                                                   double relative_tolerance = 1e-9);

/// Sorted indices of the nodes within `tolerance` (absolute) of a face of the box.
[[nodiscard]] std::vector<int> box_boundary_nodes(const NodeSet& nodes, const Box& box, double tolerance = 1e-12);

/// One flag per node: 1 if its index is in `indices`.
[[nodiscard]] std::vector<char> index_mask(std::size_t size, const std::vector<int>& indices);

}  // namespace lmeform
