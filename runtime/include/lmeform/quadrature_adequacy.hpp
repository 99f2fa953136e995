// Is a Gauss rule rich enough for a form? LME basis functions are not polynomials, so no degree
// argument answers it. This check integrates the form's energy and gradient on a sample of
// background cells with a rule and with the next richer one, and reports how much they differ:
// a scene can then pick the cheapest adequate rule.
#pragma once

#include <span>
#include <vector>

#include "lmeform/discretization.hpp"
#include "lmeform/kernel.hpp"

namespace lmeform {

struct QuadratureAdequacy {
  int points = 0;                      ///< the rule checked
  int richer_points = 0;               ///< the reference rule
  int cells_sampled = 0;
  double energy_relative_difference = 0;    ///< |E_k − E_ref| / |E_ref| over the sampled cells
  double gradient_relative_difference = 0;  ///< ||g_k − g_ref|| / ||g_ref|| over the sampled cells
};

/// The next larger rule size on the simplex of `dim` after `points` (throws if none).
[[nodiscard]] int next_richer_rule(int dim, int points);

/// Checks `points` against `richer_points` (0: the next richer rule) on every `stride`-th cell.
/// `u_original` holds the nodal unknowns in the original node order (dofs_per_node per node);
/// `constants` in the form's order. Each sampled cell's points (of both rules) are evaluated
/// against one list, the union of their primal lists, so both integrals see the same basis.
[[nodiscard]] QuadratureAdequacy check_quadrature(const Discretization& disc, const kernel::FormKernels& form,
                                                  std::span<const double> u_original, std::span<const double> constants,
                                                  int points, int richer_points = 0, int stride = 1);

}  // namespace lmeform
