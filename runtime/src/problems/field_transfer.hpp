// Fields carried between node sets: a nodal field evaluated at other points with the LME basis of
// its nodes, nodal coefficients fitted to values (LME is not interpolating), and the projection
// onto an LME space of a field known only at weighted points (a material field after a motion).
#pragma once

#include <algorithm>
#include <array>
#include <cstddef>
#include <span>
#include <vector>

#include "lmeform/lme_basis.hpp"
#include "lmeform/node_set.hpp"

namespace lmeform::problems {

// On a strongly graded node set a point of a long cell can lie outside the hull of the nodes whose
// supports reach it, or see only collinear ones (measured: carried and new quadrature points beside
// the waist of the eps = 0.01 prolate at a re-mesh, 41 neighbours all on the fine side). The
// vertices of a cell holding the point restore the hull, as the discretization's own point lists
// do. `cell_vertices` is asked only then; it returns the vertices in the basis' numbering, or none.
template <class CellVertices>
std::vector<double> evaluate_with_cell_fallback(const LmeBasis& basis, std::span<const double> x, std::vector<int>& list, int order,
                                                CellVertices&& cell_vertices) {
  try {
    return basis.evaluate(x, list, order);
  } catch (const LmeEvaluationError& e) {
    const auto r = e.reason();
    // not_converged: x on the boundary of its neighbours' hull (every neighbour on one side of a
    // line through it), where the multipliers grow without bound; the cell's vertices add the other side.
    if (r != LmeFailure::outside_hull && r != LmeFailure::degenerate && r != LmeFailure::too_few_neighbours &&
        r != LmeFailure::singular_jacobian && r != LmeFailure::not_converged)
      throw;
    const std::vector<int> vertices = cell_vertices();
    const std::size_t before = list.size();
    for (const int v : vertices)
      if (std::find(list.begin(), list.end(), v) == list.end()) list.push_back(v);
    if (list.size() == before) throw;  // the same neighbours again would fail the same way
    std::sort(list.begin(), list.end());
    return basis.evaluate(x, list, order);
  }
}

/// |∇f| of a scalar nodal field at the basis's nodes (field in the basis's node order; 0 where
/// skip[a] != 0, when skip is given). Derivatives are undefined at a vertex of the node's
/// neighbours' convex hull (a corner of the domain, or a node a motion left there): such a node takes
/// the largest value among its neighbours, counted in `undefined`.
[[nodiscard]] std::vector<double> nodal_gradient_norm(const LmeBasis& basis, std::span<const double> field, std::span<const char> skip,
                                                      std::size_t* undefined = nullptr);

/// A scalar nodal field (values at old_nodes) evaluated at new points with the LME basis of the old
/// nodes (values only): a field carried to another node set (an adapted grid, a re-mesh).
/// A point the old basis cannot evaluate (outside the hull of its neighbours, where a motion tore
/// the old nodes apart) throws LmeEvaluationError, unless `nearest_fallbacks` is given: then it
/// takes the value of its nearest old node, counted there (for a start guess, not a result).
/// `local_range` (optional) receives, per new node, the least and the largest φ among the old
/// nodes weighting it (the bounds a monotone transfer keeps).
[[nodiscard]] std::vector<double> interpolate_nodal_field(const NodeSet& old_nodes, std::span<const double> phi, double gamma,
                                                          const LmeOptions& lme, const NodeSet& new_nodes,
                                                          std::size_t* nearest_fallbacks = nullptr,
                                                          std::vector<std::array<double, 2>>* local_range = nullptr);

/// Nodal coefficients whose LME field takes the given values at the nodes themselves: LME is not
/// interpolating (Σ_a p_a(x_b) φ_a ≠ φ_b), so using values as coefficients smooths the field once
/// more (an interface widens). Richardson iterations on P φ = g, P_ba = p_a(x_b), an averaging
/// operator with eigenvalues in (0, 1]; 0 iterations returns the values.
/// `held` (optional, one per node): coefficients known already (a node kept from the set the
/// values came from), NaN for the free ones; only the free ones are iterated.
[[nodiscard]] std::vector<double> fit_nodal_values(const NodeSet& nodes, std::span<const double> values, double gamma,
                                                   const LmeOptions& lme, int iterations, std::span<const double> held = {});

/// The L2 projection onto the LME space of `nodes` of a field known only at weighted points (a
/// field carried by quadrature points, as a material field after a motion): the coefficients c
/// minimizing Σ_q w_q (Σ_a p_a(x_q) c_a − v_q)². The mass matrix is never formed (a point sees
/// O(100) nodes at small γ): Jacobi-preconditioned conjugate gradients from `start`, to a relative
/// residual `tolerance`. Points with w_q ≤ 0 are skipped. Throws std::runtime_error if a node has
/// no point in its support.
struct PointProjection {
  std::vector<double> values;
  int iterations = 0;
  double relative_residual = 0;
};
/// The field's gradient at the same points (dim values per point) and a length ℓ: the projection
/// then minimizes Σ_q w_q [(φ(x_q) − v_q)² + ℓ² |∇φ(x_q) − g_q|²], an H1 fit for fields whose use
/// depends on their derivatives. ℓ = 0 or no values: the L2 projection.
struct PointGradients {
  std::span<const double> values;
  double length = 0;
};
[[nodiscard]] PointProjection project_point_values(const NodeSet& nodes, double gamma, const LmeOptions& lme,
                                                   std::span<const double> points, std::span<const double> weights,
                                                   std::span<const double> values, std::span<const double> start,
                                                   double tolerance = 1e-8, int max_iterations = 5000,
                                                   PointGradients gradients = {});

}  // namespace lmeform::problems
