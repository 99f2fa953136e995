// The facets of the background cells with a quadrature rule on each: what the cell-wise gradient
// correction of DiscretizationOptions::consistent_integration integrates the basis over.
//
// A Gauss rule does not integrate LME gradients exactly (they are not polynomials, and the support
// cutoff makes them jump by about tol0), so ∑_q w_q ∇N_a(x_q) differs from ∮_∂C N_a n ds and the
// Galerkin solution misses even a linear field (measured: 5e-7 in L2 with the 6-point rule, 5e-8
// with 19 points, for u = x on a 0.1 grid). Adding to ∇N_a in cell C the constant
//     c_aC = (∮_∂C N_a n ds − ∑_q w_q ∇N_a(x_q)) / |C|
// makes the rule satisfy the divergence theorem cell by cell, with the same facet rule on both
// sides of an interior facet (their terms cancel) and the boundary rule of `ds` on the hull. The
// correction keeps the basis' linear consistency (∑_a c_aC = 0 and ∑_a x_a ⊗ c_aC = 0 because the
// facet rule integrates x ⊗ n exactly and the weights sum to |C|), so a linear field still has a
// constant gradient, and the symmetric Galerkin solution reproduces it: the patch test passes to the
// LME Newton tolerance with any interior rule. This is the variationally consistent integration of
// Chen, Hillman and Rüter (2013), applied per cell to the test and trial functions alike. When the
// forms need second derivatives the Hessians get the same treatment one order up,
//     C_aC = sym(∮_∂C ∇N_a ⊗ n ds − ∑_q w_q ∇∇N_a(x_q)) / |C|,
// with the uncorrected gradients on the facets (so interior facets still cancel): a fourth-order
// form is then integrated consistently for quadratic fields, and the Kirchhoff plate on irregular
// nodes converges where the Gauss rule alone stalled (docs/convergence.md).
#pragma once

#include <cstddef>
#include <span>
#include <vector>

#include "lmeform/delaunay.hpp"
#include "lmeform/node_set.hpp"
#include "lmeform/quadrature.hpp"

namespace lmeform::detail {

/// The facets of some of the cells (a rank's share and a layer around it; all of them on one rank).
struct CellFacets {
  int dim = 0;
  int points_per_facet = 0;
  std::vector<int> cells;         ///< the cells whose facets these are, ascending (global numbers)
  std::vector<int> vertices;      ///< facet f: vertices[f * dim + k], sorted
  std::vector<double> points;     ///< facet f, point g: points[(f * ng + g) * dim + i]
  std::vector<double> weights;    ///< [f * ng + g]
  std::vector<double> normals;    ///< facet f: unit normal, outward of the first of `cells` that has it
  std::vector<int> cell_facets;   ///< cells[s], facet k (opposite vertex k): cell_facets[s * (dim + 1) + k]
  std::vector<signed char> cell_signs;  ///< +1 where the facet's normal points out of cells[s], -1 otherwise
  /// Facet f lies between cells sharing[2f] and sharing[2f + 1] of all the cells (global numbers,
  /// -1 on the hull), whether or not both are among `cells`.
  std::vector<int> sharing;

  [[nodiscard]] std::size_t size() const noexcept { return normals.size() / static_cast<std::size_t>(dim); }
  [[nodiscard]] std::span<const int> facet_vertices(std::size_t f) const noexcept {
    return {vertices.data() + f * static_cast<std::size_t>(dim), static_cast<std::size_t>(dim)};
  }
  /// The position of global cell c in `cells`; throws std::out_of_range if it is not there.
  [[nodiscard]] std::size_t slot(int c) const;
  /// 1 for a hull facet, 2 for an interior one.
  [[nodiscard]] int cells_sharing(std::size_t f) const noexcept { return (sharing[2 * f] >= 0 ? 1 : 0) + (sharing[2 * f + 1] >= 0 ? 1 : 0); }
};

/// Every facet of the cells `which` (ascending) once, with `rule` (Gauss–Legendre on [0, 1] in 2D,
/// a triangle rule in 3D) mapped onto it: segment points x_0 + ξ (x_1 − x_0) and weights w |e|, as
/// the boundary quadrature of the domain maps them, so that a hull facet carries the points of `ds`.
/// Whichever of its two cells a facet is first met from, its points and the products of its
/// normal with the cells' signs are the same to the last bit.
[[nodiscard]] CellFacets cell_facets(const BackgroundCells& cells, const NodeSet& nodes, const QuadratureRule& rule,
                                     std::span<const int> which);

}  // namespace lmeform::detail
