// Adaptivity: node relocation by a centroidal Voronoi tessellation (CVT) with a density, the
// phase-field density rho = 1 + f |grad phi|, nodal spacing statistics and the resolution check
// eps >= 2 h_min of the seed (Appendix B, Table B.6). See docs/adaptivity.md.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <functional>
#include <memory>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include "lmeform/domain.hpp"
#include "lmeform/node_set.hpp"
#include "lmeform/node_sets.hpp"

namespace lmeform {

/// A density on the box: rho(x) > 0 and finite at every sample point (x has dim entries).
using Density = std::function<double(std::span<const double>)>;

/// Where the Lloyd iterations start.
enum class CvtStart {
  /// From the given nodes (seed Table B.6: "CVT starting from grid O1"). Lloyd moves nodes about
  /// one cell per iteration, so a strong grading needs many iterations from a uniform start.
  given,
  /// From nodes re-placed with the asymptotic CVT node density, proportional to rho^(dim/(dim+2)):
  /// interior nodes by systematic sampling along a Morton order of a fine lattice, nodes on an
  /// edge of the box (one free coordinate) by equidistributing rho^(1/(dim+2)) along the edge.
  /// Corners, and 3D face nodes, keep their places. Lloyd then only smooths locally.
  density,
};

/// How the rho-weighted centroids of the Voronoi cells are computed.
enum class CvtCentroids {
  /// 2D: the exact Voronoi cell of each node clipped to the box (the box cut by the bisectors with
  /// its Delaunay neighbours), fanned into triangles from its first vertex, each split into
  /// `voronoi_subdivision`^2 triangles integrated with a 7-point rule. No sampling noise: Lloyd
  /// converges to a CVT (a uniform density gives a near-hexagonal grid). Other dimensions: sampled.
  voronoi,
  /// Monte Carlo: a fixed set of samples (see samples_per_node) assigned to their nearest node.
  sampled,
};

struct CvtOptions {
  int iterations = 50;            ///< maximum number of Lloyd iterations
  CvtCentroids centroids = CvtCentroids::voronoi;
  int voronoi_subdivision = 2;    ///< CvtCentroids::voronoi: each fan triangle split into this^2
  /// Sample points per node. Samples are drawn from a lattice over the box with probability
  /// proportional to rho^(dim/(dim+2)) (the node density of a CVT) and weighted by rho over that
  /// proposal, so every Voronoi cell receives about this many samples however strong the grading.
  double samples_per_node = 64;
  CvtStart start = CvtStart::given;
  /// Stop when the mean node displacement of an iteration is below tolerance * h_bar, with
  /// h_bar = (box volume / node count)^(1/dim) the spacing of a uniform set. 0 runs all iterations.
  double tolerance = 1e-3;
  std::uint64_t seed = 1;         ///< seeds the stratified jitter of the samples (deterministic)
  /// Nodes closer than this (relative to the box diagonal) to a face of the box are boundary nodes.
  double boundary_tolerance = 1e-10;
};

struct CvtIteration {
  double mean_displacement = 0.0;
  double max_displacement = 0.0;
  std::size_t empty_cells = 0;    ///< nodes that received no sample (they stay where they are)
};

struct CvtReport {
  std::vector<CvtIteration> iterations;
  bool converged = false;         ///< the tolerance was met before the iteration limit
  std::size_t samples = 0;        ///< sample points (sampled), density evaluations per iteration (voronoi)
  std::size_t replaced = 0;       ///< nodes re-placed by CvtStart::density (0 for CvtStart::given)
  double h_bar = 0.0;             ///< (volume / nodes)^(1/dim), the scale of the tolerance
};

/// Lloyd iterations towards a CVT of the box with density rho, in 1, 2 or 3 dimensions: each node
/// moves to the rho-weighted centroid of its Voronoi cell, computed exactly by quadrature on the
/// clipped cell in 2D (CvtCentroids::voronoi) or from a fixed set of samples assigned to their
/// nearest node (CvtCentroids::sampled, and 1D/3D).
/// Boundary rule: a node on some faces of the box keeps those coordinates and moves only along the
/// free ones (to the corresponding components of its weighted cell centroid), so corners are
/// fixed, edge nodes slide along their edge and (3D) face nodes slide in their face. Node count,
/// order and boundary membership are preserved. A node whose cell has no sample stays in place.
/// Deterministic: the same input and seed give bit-identical nodes.
/// Throws std::invalid_argument for a node outside the box, coincident nodes, a dimension
/// mismatch, bad options, or a density that is not positive and finite at a sample.
[[nodiscard]] NodeSet cvt_relocate(const NodeSet& nodes, const Box& box, const Density& density,
                                   const CvtOptions& options = {}, CvtReport* report = nullptr);

/// A uniform CVT of exactly `count` nodes in a 2D box, the seed's "uniform" grids (O1: 6124 nodes,
/// mean spacing 0.024, "almost perfectly uniform" but not a lattice): nodes on the four edges at
/// the spacing of a hexagonal lattice of that density, h = sqrt(2 A / (sqrt(3) count)) (corners
/// included), the others on a hexagonal lattice stretched to the box (the few surplus lattice
/// points removed evenly), relaxed by Lloyd iterations (options; edge nodes slide along their
/// edge). Throws std::invalid_argument for a box that is not 2D or a count too small to hold the
/// edge nodes and one interior node.
[[nodiscard]] NodeSet uniform_cvt(const Box& box, std::size_t count, const CvtOptions& options = {},
                                  CvtReport* report = nullptr);

// A target spacing is a SpacingFunction (domain.hpp): a CVT whose density is h^-(dim+2) has spacing
// proportional to h, and h_min sets the resolution of the integrals over h.

/// The number of nodes a CVT with spacing h needs: interior nodes at the density of a hexagonal
/// lattice of spacing h(x) (2 / (sqrt(3) h^2) per unit area), edge nodes at 1 / h(x) per unit length.
struct SpacingNodeCount {
  std::size_t total = 0;
  std::size_t interior = 0;
  std::array<std::size_t, 4> edges{};   ///< edge nodes without the corners: bottom, right, top, left
};
[[nodiscard]] SpacingNodeCount count_nodes_for_spacing(const Box& box, const SpacingFunction& spacing);

/// A node set of a 2D box whose spacing follows h(x): the node budget from count_nodes_for_spacing,
/// placed by the density h^-4 (CvtStart::density is implied) and relaxed by options.iterations Lloyd
/// iterations. Throws std::invalid_argument for a box that is not 2D, a spacing that is not positive
/// and finite, or a budget above max_nodes (the message gives the budget).
[[nodiscard]] NodeSet cvt_for_spacing(const Box& box, const SpacingFunction& spacing, std::size_t max_nodes,
                                      const CvtOptions& options = {}, CvtReport* report = nullptr);

/// rho(x) = 1 + f * grad_norm(x) (seed Section 3.13). f >= 0; grad_norm(x) must be >= 0.
[[nodiscard]] Density phase_field_density(double f, std::function<double(std::span<const double>)> grad_norm);

/// rho from nodal values of |grad phi|: the values are interpolated piecewise linearly on the
/// Delaunay cells of `nodes` (nearest node outside the hull). grad_norm_at_nodes has one entry per node.
[[nodiscard]] Density phase_field_density(double f, const NodeSet& nodes, std::span<const double> grad_norm_at_nodes);

// ---------------------------------------------------------------------------------------------
// Nodal spacing and the resolution criterion eps >= 2 h_min (seed Appendix B).

enum class SpacingMeasure {
  /// Seed Appendix B: h_a = mean distance from x_a to its first ring of Voronoi neighbours, i.e. the
  /// Delaunay neighbours whose Voronoi cells share a facet of positive measure (the diagonals of the
  /// squares/cubes of a regular grid share only a vertex/edge and are left out).
  voronoi_ring,
  /// nodal_spacing() of neighbour_search.hpp: mean distance to the 2*dim nearest nodes.
  nearest,
};

struct SpacingOptions {
  SpacingMeasure measure = SpacingMeasure::voronoi_ring;
  /// h_min is this quantile of the h_a (0 = the smallest h_a). The seed takes "the nodal spacing of
  /// the left peak" of the histogram; a low quantile lies in that peak whenever the refined region
  /// holds more than this fraction of the nodes, and is insensitive to a few isolated close nodes.
  double h_min_quantile = 0.05;
};

struct SpacingSummary {
  std::vector<double> h;          ///< h_a per node
  double h_min = 0.0;             ///< the h_min_quantile quantile of h
  double h_mean = 0.0;
  double h_max = 0.0;
  double eps_min = 0.0;           ///< 2 * h_min: the smallest admissible eps
  SpacingSummary() = default;
};

/// Nodal spacing per node and its statistics. Throws std::invalid_argument for fewer than dim + 1
/// nodes, coincident nodes, or a quantile outside [0, 1].
[[nodiscard]] SpacingSummary spacing_summary(const NodeSet& nodes, const SpacingOptions& options = {});

/// h_a by the Voronoi ring (see SpacingMeasure::voronoi_ring).
[[nodiscard]] std::vector<double> voronoi_ring_spacing(const NodeSet& nodes);

/// The smallest admissible eps for the node set: 2 * h_min.
[[nodiscard]] double min_admissible_eps(const NodeSet& nodes, const SpacingOptions& options = {});

/// The one resolution check of the project (seed Appendix B): throws std::invalid_argument when
/// eps < factor * h_min; the message gives eps, h_min and the smallest admissible eps, prefixed by
/// `what` (e.g. "stage 2") when not empty. Also refuses eps or h_min that is not positive and finite.
void check_resolution(double eps, double h_min, double factor = 2.0, std::string_view what = {});
/// The same with h_min from spacing_summary (factor 2, as the seed).
void check_resolution(double eps, const NodeSet& nodes, const SpacingOptions& options = {});
void check_resolution(double eps, const SpacingSummary& spacing, double factor = 2.0, std::string_view what = {});

}  // namespace lmeform
