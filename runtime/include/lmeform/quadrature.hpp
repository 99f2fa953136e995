// Quadrature rules on reference simplices and their images on background cells.
//
// Reference cells: the interval [0, 1] (measure 1), the triangle (0,0), (1,0), (0,1) (measure 1/2) and
// the tetrahedron (0,0,0), (1,0,0), (0,1,0), (0,0,1) (measure 1/6). Weights sum to the reference measure.
//
// No digits are copied from tables: every simplex rule is fixed by its symmetric orbit structure and
// solved from the moment equations (Gauss-Newton in long double, first use only), then checked; the
// Gauss-Legendre nodes are roots of P_n found by Newton. A rule whose solve does not reach its
// moments to round-off throws std::logic_error.
#pragma once

#include <cstddef>
#include <span>
#include <string>
#include <vector>

#include "lmeform/delaunay.hpp"
#include "lmeform/node_set.hpp"

namespace lmeform {

struct QuadratureRule {
  std::string name;             ///< e.g. "triangle-7 (degree 5)"
  int dim = 0;                  ///< 1, 2 or 3
  int degree = 0;               ///< exact for every polynomial of total degree <= degree
  std::vector<double> points;   ///< point-major reference coordinates: points[q * dim + i]
  std::vector<double> weights;  ///< sum to the reference measure

  [[nodiscard]] std::size_t size() const noexcept { return weights.size(); }
  [[nodiscard]] std::span<const double> point(std::size_t q) const noexcept {
    return {points.data() + q * static_cast<std::size_t>(dim), static_cast<std::size_t>(dim)};
  }
  [[nodiscard]] bool has_negative_weights() const noexcept;
};

/// 1, 1/2, 1/6 for dim = 1, 2, 3.
[[nodiscard]] double reference_measure(int dim);

/// n-point Gauss-Legendre on [0, 1], degree 2n - 1 (n >= 1).
[[nodiscard]] QuadratureRule gauss_legendre(int n);

/// Symmetric rules on the reference triangle; sizes 1, 3, 6, 7, 12, 16, 19 (degrees 1, 2, 4, 5, 6, 8, 9).
/// All have positive weights and interior points.
[[nodiscard]] QuadratureRule triangle_rule(int npoints);
[[nodiscard]] std::vector<int> triangle_rule_sizes();

/// Symmetric rules on the reference tetrahedron; sizes 1, 4, 5, 11, 14, 15, 24
/// (degrees 1, 2, 3, 4, 5, 5, 6). The 5- and 11-point rules have a negative centroid weight.
/// All points are interior.
[[nodiscard]] QuadratureRule tetrahedron_rule(int npoints);
[[nodiscard]] std::vector<int> tetrahedron_rule_sizes();

/// The rule with the fewest points of at least `degree` on the reference simplex of `dim`
/// (Gauss-Legendre in 1D). With positive_weights_only (the default) rules with a negative weight are
/// skipped: they can make a discrete energy or mass matrix indefinite. Throws if none is available.
[[nodiscard]] QuadratureRule simplex_rule(int dim, int degree, bool positive_weights_only = true);

/// A rule mapped onto cells of a BackgroundCells, in the order mapped: the k-th cell mapped owns
/// points [k*nq, (k+1)*nq).
struct CellQuadrature {
  int dim = 0;
  int points_per_cell = 0;
  std::vector<double> points;   ///< physical coordinates, point-major
  std::vector<double> weights;  ///< reference weight times |det J| of the cell map

  [[nodiscard]] std::size_t size() const noexcept { return weights.size(); }
  [[nodiscard]] std::size_t cells() const noexcept {
    return points_per_cell == 0 ? 0 : weights.size() / static_cast<std::size_t>(points_per_cell);
  }
  [[nodiscard]] std::span<const double> point(std::size_t q) const noexcept {
    return {points.data() + q * static_cast<std::size_t>(dim), static_cast<std::size_t>(dim)};
  }
};

/// Vertex k of a cell is the image of reference vertex k (origin first, then the unit vectors).
[[nodiscard]] CellQuadrature map_to_cells(const BackgroundCells& cells, const NodeSet& nodes,
                                          const QuadratureRule& rule);
/// The rule on the cells `which` only, in that order (a rank's share of the cells).
[[nodiscard]] CellQuadrature map_to_cells(const BackgroundCells& cells, const NodeSet& nodes, const QuadratureRule& rule,
                                          std::span<const int> which);

}  // namespace lmeform
