// The topology of the zero level set {f = 0} of a nodal scalar field on simplicial cells: how many
// pieces it has and, for surfaces, the genus of each. The field is taken linear on each cell
// between its vertices' values, so the level set is a polygon curve (triangles) or a polygonal
// surface (tetrahedra, marching tetrahedra), and its topology follows from the cells and the signs
// of the values alone, whatever the node positions.
//
// Resolution: the linear field sees what the nodes see. Two sheets of {f = 0} closer than about
// one cell, with no node between them of the sign between them, are one sheet to it; a hole or a
// neck narrower than a cell is closed. A value exactly 0 counts as positive: the level set is that
// of f at the level 0⁻, an infinitesimal offset applied the same way at every node, so that a
// level set through a node is still a manifold.
#pragma once

#include <array>
#include <cstddef>
#include <span>
#include <string>
#include <vector>

#include "lmeform/delaunay.hpp"
#include "lmeform/node_set.hpp"

namespace lmeform {

/// What the cells and the level set stand for.
enum class LevelSetGeometry {
  planar,        ///< 2D cells: {f = 0} is a set of curves in the plane
  axisymmetric,  ///< 2D cells in the meridian half-plane (r, z), r = x[0] ≥ 0: the curves revolve into surfaces
  spatial,       ///< 3D cells: {f = 0} is a set of surfaces
};

/// One connected piece of the level set.
struct LevelSetComponent {
  /// false: it reaches the boundary of the cells' hull (an axisymmetric meridian ending on the axis
  /// does not count: the revolved surface closes there).
  bool closed = true;
  /// Surfaces (axisymmetric and spatial), closed ones: the number of handles (0 a sphere, 1 a torus).
  /// -1 for open surfaces and for curves.
  int genus = -1;
  /// Of the triangulated piece: spatial, V − E + F of its polygons; planar and axisymmetric, of its
  /// meridian or plane curve (0 a closed curve, 1 an arc).
  int euler_characteristic = 0;
  std::size_t crossings = 0;          ///< cell edges it crosses (its vertices): a measure of its size
  std::array<double, 3> lo{}, hi{};   ///< its bounding box (of the crossing points)
};

struct LevelSetTopology {
  LevelSetGeometry geometry = LevelSetGeometry::planar;
  std::vector<LevelSetComponent> components;  ///< ordered by their bounding boxes' lower corners

  /// Whether two level sets have the same topology: the same geometry and the same components up
  /// to their order (closed or not, genus).
  [[nodiscard]] bool same_as(const LevelSetTopology& other) const;
  /// One line: "1 component, genus 0 (a sphere)", "2 components, genus 0, 1 (a sphere and a
  /// torus)", "1 closed curve", "no interface (the field has one sign)".
  [[nodiscard]] std::string describe() const;
  /// What the pieces are, briefly: "a sphere", "a torus", "2 spheres", "a sphere and a torus",
  /// "1 closed curve", "none".
  [[nodiscard]] std::string shapes() const;
};

/// The topology of {f = 0} of the nodal values `values` on `cells` over `nodes`. Axisymmetric: a
/// meridian ends on the axis where it crosses a hull edge whose two nodes lie at r = 0 (within 1e-9
/// of the nodes' extent). Throws std::invalid_argument for sizes that do not
/// match, a geometry that does not fit the cells' dimension, or a value that is not finite.
[[nodiscard]] LevelSetTopology level_set_topology(const NodeSet& nodes, const BackgroundCells& cells, std::span<const double> values,
                                                  LevelSetGeometry geometry);

}  // namespace lmeform
