// Convex domains with named boundary parts: a box, a convex polygon (2D) or a convex polyhedron
// (3D). The boundary is a set of flat faces (a polygon's edges, a polyhedron's faces), each with its
// outward unit normal and an optional part name; `ds(part)` of a form integrates over the faces of
// that part, `ds` over all of them, and boundary conditions name the same parts.
//
// Only convex domains: an LME basis couples every node within its support, so across a
// re-entrant corner it would couple the two sides of a notch through the void. Cracks and notches
// are modelled by an initial field instead.
//
// Node sets for a domain put nodes on every edge (corners included) and fill the interior by a
// deterministic variable-radius Poisson-disk sample of a spacing field, so that the nodes can be
// graded toward a part or a path. A boundary quadrature has one Gauss rule per segment between
// consecutive boundary nodes (2D) or per triangle of the boundary nodes of a face (3D); its weights
// sum to each face's length or area to round-off.
#pragma once

#include <array>
#include <functional>
#include <span>
#include <string>
#include <vector>

#include "lmeform/node_set.hpp"
#include "lmeform/node_sets.hpp"

namespace lmeform {

/// A flat face of the boundary: an edge of a polygon, a face of a polyhedron or a box.
struct DomainFace {
  std::string part;                    ///< its part name ("" when unnamed)
  std::array<double, 3> normal{};      ///< outward unit normal
  double offset = 0;                   ///< normal · x = offset on the face
  std::vector<int> vertices;           ///< into Domain::vertices(): an edge's two ends, a face's loop (counter-clockwise from outside)
};

class Domain {
 public:
  /// The box; its faces are named x_min, x_max, y_min, y_max, z_min, z_max. An axisymmetric box's
  /// faces answer also to axis (r = 0), r_max, z_min, z_max.
  static Domain box(const Box& box, bool axisymmetric = false);
  /// A convex polygon: vertices in order (either orientation), edge i from vertex i to i + 1 (the
  /// last closes the loop) named edge_parts[i] ("" unnamed; an empty list names none). Throws
  /// std::invalid_argument for fewer than 3 vertices, a repeated or collinear vertex, a self-
  /// intersecting or non-convex loop, or a part list of the wrong length.
  static Domain polygon(const std::vector<std::array<double, 2>>& vertices, const std::vector<std::string>& edge_parts = {});
  /// A convex polyhedron: vertices, and faces as loops of vertex indices (either orientation), face
  /// i named face_parts[i]. Throws std::invalid_argument for a non-planar or non-convex face, a
  /// polyhedron that is not closed and convex, or bad indices.
  static Domain polyhedron(const std::vector<std::array<double, 3>>& vertices, const std::vector<std::vector<int>>& faces,
                           const std::vector<std::string>& face_parts = {});

  [[nodiscard]] int dim() const noexcept { return dim_; }
  [[nodiscard]] bool is_box() const noexcept { return is_box_; }
  [[nodiscard]] bool axisymmetric() const noexcept { return axisymmetric_; }
  /// The bounding box.
  [[nodiscard]] const Box& bounds() const noexcept { return bounds_; }
  [[nodiscard]] const std::vector<std::array<double, 3>>& vertices() const noexcept { return vertices_; }
  [[nodiscard]] const std::vector<DomainFace>& faces() const noexcept { return faces_; }
  /// The part names, each once, in face order (box aliases not included).
  [[nodiscard]] std::vector<std::string> part_names() const;
  /// Whether `part` names faces: a part name, a box alias, or "hull" / "" (the whole boundary).
  [[nodiscard]] bool has_part(const std::string& part) const;
  /// The faces of a part ("hull" and "" select every face).
  [[nodiscard]] std::vector<int> faces_of(const std::string& part) const;
  /// Area (2D) or volume (3D); the length or area of a part's faces.
  [[nodiscard]] double measure() const;
  [[nodiscard]] double face_measure(int face) const;
  [[nodiscard]] double part_measure(const std::string& part) const;
  /// The largest distance between two vertices.
  [[nodiscard]] double diameter() const;
  /// min over faces of (offset − n·x): > 0 inside, the distance to the boundary for inside points.
  [[nodiscard]] double depth(std::span<const double> x) const;
  /// Inside or within `tolerance` (absolute) of the boundary.
  [[nodiscard]] bool contains(std::span<const double> x, double tolerance) const;
  /// Whether x lies on face f (within tolerance of its plane and of its extent).
  [[nodiscard]] bool on_face(int face, std::span<const double> x, double tolerance) const;
  /// The distance from x to the faces of `part`.
  [[nodiscard]] double distance_to_part(std::span<const double> x, const std::string& part) const;
  /// The indices of the nodes on the faces of `part`, sorted (tolerance: relative to the diameter).
  [[nodiscard]] std::vector<int> nodes_on(const NodeSet& nodes, const std::string& part, double relative_tolerance = 1e-9) const;

 private:
  int dim_ = 0;
  bool is_box_ = false;
  bool axisymmetric_ = false;
  Box bounds_;
  std::vector<std::array<double, 3>> vertices_;
  std::vector<DomainFace> faces_;
};

/// The distance from x to a polyline (one point: the distance to it), dim 2 or 3.
[[nodiscard]] double distance_to_polyline(std::span<const double> x, const std::vector<std::array<double, 3>>& path, int dim);

/// A node spacing over a domain: h(x) > 0, and its smallest value (the sampling resolution).
struct SpacingFunction {
  std::function<double(std::span<const double>)> h;
  double h_min = 0;
};

/// Nodes for a domain: every vertex, nodes along every edge at the local spacing, (3D) on every
/// face, then the interior by a greedy variable-radius Poisson-disk sample of a jittered candidate
/// lattice at h_min / 4, a candidate taken when no node is closer than h(x) and it lies at least
/// h(x) / 2 inside. Deterministic for a given seed. Throws std::invalid_argument for a spacing that
/// would give more than `max_nodes` nodes.
/// `kept`: points of an earlier set (coordinates interleaved, in its order) offered before the
/// lattice, each taken by the sample's rule (h(x) / 2 inside, no node closer than h(x)) — a
/// refinement that keeps the nodes where the spacing did not change.
[[nodiscard]] NodeSet domain_nodes(const Domain& domain, const SpacingFunction& spacing, std::uint64_t seed = 1,
                                   std::size_t max_nodes = 2'000'000, std::span<const double> kept = {});

/// The vertices of an octree (quadtree in 2D) of a box whose cells follow a spacing: level 0 is a
/// uniform grid whose spacing is about the largest h(x), and a cell of size s is halved on every
/// axis where h at its centre is below s, down to the first level at or below spacing.h_min. Within
/// each level the nodes form a uniform grid (the LME basis of a fourth-order energy wants regular
/// neighbourhoods, which a Poisson-disk sample is not), and a point where h(x) ≤ h_min sees the
/// finest grid in every direction. Deterministic; nodes ordered x fastest. Throws
/// std::invalid_argument for a box that is not 2D or 3D, a spacing that is not positive and finite,
/// or more than max_nodes nodes (the message gives the count).
/// `level0_spacing` (> 0) fixes level 0 instead of the largest sampled h: sets made for spacings
/// that differ only where they are finer (a refinement that follows a field) then share their
/// grids, so each contains the nodes of every coarser one.
[[nodiscard]] NodeSet nested_grids(const Box& box, const SpacingFunction& spacing, std::size_t max_nodes = 2'000'000,
                                   double level0_spacing = 0);

/// Quadrature on the faces of a boundary part: points grouped into facets (segments between
/// consecutive boundary nodes in 2D, triangles of a face's boundary nodes in 3D), each with its
/// weights (facet measure included), the face's outward normal, and the facet's vertices (node
/// indices), which the LME lists of its points must include.
struct BoundaryQuadrature {
  std::string part;
  int dim = 0;
  int points_per_facet = 0;
  int vertices_per_facet = 0;
  std::vector<double> points;          ///< [Q * dim]
  std::vector<double> weights;         ///< [Q]
  std::vector<double> normals;         ///< [Q * dim]
  std::vector<int> facet_vertices;     ///< [F * vertices_per_facet], node indices
  [[nodiscard]] std::size_t size() const noexcept { return weights.size(); }
  [[nodiscard]] std::size_t facets() const noexcept {
    return points_per_facet == 0 ? 0 : weights.size() / static_cast<std::size_t>(points_per_facet);
  }
};

/// The quadrature of `part` ("" or "hull": the whole boundary) over the boundary nodes of `nodes`
/// with a Gauss–Legendre rule of `points_per_segment` points per segment (2D) or a triangle rule of
/// that many points per triangle (3D). Throws std::invalid_argument when a face of the part holds
/// fewer nodes than its vertices (nodes must include every corner).
[[nodiscard]] BoundaryQuadrature boundary_quadrature(const Domain& domain, const NodeSet& nodes, const std::string& part,
                                                     int points_per_segment);

}  // namespace lmeform
