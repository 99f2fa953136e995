// Point outputs of the forms (`point NAME = EXPR`) evaluated at any point with the LME basis of a
// node set: the values a form computes at a quadrature point (a stress, F, det F), written at the
// nodes with a solution and read by probes. The generated point kernel does the arithmetic; this
// file supplies the basis jet, the nodal values in the form's order and the constants.
#pragma once

#include <map>
#include <span>
#include <string>
#include <vector>

#include "lmeform/discretization.hpp"
#include "lmeform/domain.hpp"
#include "lmeform/kernel.hpp"
#include "lmeform/lme_basis.hpp"
#include "toolkit.hpp"

namespace lmeform::problems {

/// The basis jet at x on `list` when `list` alone cannot give it: its nodes lie on one line (plane),
/// are too few, or all on one side of x. The next nearest other nodes join `list` one by one until
/// the evaluation succeeds (at most 32). For a boundary node whose supports reach only its own
/// edge's nodes (a boundary refined more finely than the nodes beside it), or only itself (a
/// compact support). Throws the LME error when no node helps.
[[nodiscard]] std::vector<double> evaluate_with_nearest_nodes(const LmeBasis& basis, std::span<const double> x,
                                                                   std::vector<int>& list, int order);

class PointEvaluator {
 public:
  /// `output`: a Point kernel whose unknowns are fields of `layout` (by name and shape) and which
  /// reads no coefficients or quadrature data (can_evaluate says); `constants`: every constant
  /// by name, resolved.
  /// `domain`: where points on its boundary are moved inward for derivatives (null: none are).
  PointEvaluator(const kernel::FormKernels& output, const StateLayout& layout, const std::map<std::string, double, std::less<>>& constants,
                 const Domain* domain = nullptr);

  /// Whether a point output can be evaluated from the unknowns of `layout` alone.
  [[nodiscard]] static bool can_evaluate(const kernel::FormKernels& output, const StateLayout& layout);

  [[nodiscard]] int n_values() const noexcept { return kernel_->n_values; }
  [[nodiscard]] const kernel::FormKernels& output() const noexcept { return *kernel_; }

  /// The values at x (n_values()); `state`: the problem's unknowns at the basis' nodes
  /// (layout.dofs_per_node per node, in the basis' node order). On the hull of the nodes the LME
  /// derivatives are the limit of an ill-conditioned solve (J is singular across the boundary;
  /// at a vertex in every direction): a point of the domain's boundary is moved a thousandth of
  /// the local spacing towards its neighbours when the output reads derivatives, a hundredth
  /// where derivatives are still undefined. `spacing`: the local node spacing at x, for an output
  /// that reads it (a requirement on the resolution, checked at nodes); such an output without it
  /// is an error.
  void evaluate(const LmeBasis& basis, std::span<const double> x, std::span<const double> state, std::span<double> values,
                double spacing = -1.0) const;

 private:
  const kernel::FormKernels* kernel_;
  const Domain* domain_;
  int dofs_per_node_;
  std::vector<int> offsets_;     ///< per form unknown: its offset in the problem's dofs of a node
  std::vector<int> components_;  ///< per form unknown
  std::vector<double> constants_;
};

/// A point output at the quadrature points of this rank's owned cells (each point on one rank).
struct CellPointValues {
  std::vector<int> points;     ///< global quadrature point of each row
  std::vector<double> values;  ///< [row * n_values + i]
};

/// `output` (a Point kernel of one vector or scalar unknown and constants) evaluated at the points
/// of the cells with the discretization's tabulation: the unknown's values are state[node *
/// dofs_per_node + offset + c] (nodes in original order).
[[nodiscard]] CellPointValues point_values_on_cells(const Discretization& disc, const kernel::FormKernels& output,
                                                    std::span<const double> state, int dofs_per_node, int offset,
                                                    std::span<const double> constants = {});

/// A state in the nodes' original order renumbered to the discretization's (its basis' order).
[[nodiscard]] std::vector<double> renumbered_state(const Discretization& disc, std::span<const double> original, int dofs_per_node);

}  // namespace lmeform::problems
