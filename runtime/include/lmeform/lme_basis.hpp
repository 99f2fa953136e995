// Local maximum-entropy (LME) basis functions: values, gradients and Hessians (seed A.1-A.3).
//
// For a point x and its neighbour list N_x (nodes a with |x - x_a| <= r_a),
//   p_a(x) = exp(-beta_a |x - x_a|^2 + lambda* . (x - x_a)) / Z,   lambda* = argmin ln Z(x, lambda),
// with beta_a = gamma_a / h_a^2 (h_a: nodal spacing, gamma_a: dimensionless locality).
//
// Output layout ("jet", identical to lmeform/kernel.hpp): for one point with n neighbours the
// result is a (jet_size(dim, order) x n) row-major block, jet[s * n + a]:
//   s = 0: p_a;  s = 1..dim: dp_a/dx_i;  s = hessian_slot(i, j, dim): d2p_a/dx_i dx_j (i <= j).
// Column a follows the order of the neighbour list given by the caller.
//
// Numerics (see docs/lme_basis.md):
// * Newton works in coordinates relative to x and scaled by the local length l = RMS distance of
//   the neighbours from x: y^ = (x - x_a)/l, beta^ = beta l^2, lambda^ = lambda l. Convergence is
//   ||grad_lambda^ ln Z|| = ||sum_a p_a y^_a|| <= newton_tolerance (unit-free; the first-order
//   consistency error |sum_a p_a x_a - x| is then <= newton_tolerance * l).
// * ln Z is evaluated with a log-sum-exp shift; each Newton direction is checked for descent and
//   globalised with an Armijo backtracking line search; when the Hessian J of ln Z cannot be
//   factorised the step falls back to steepest descent.
// * Failures throw LmeEvaluationError naming the point, the neighbour count and the reason.
#pragma once

#include <cstddef>
#include <optional>
#include <span>
#include <stdexcept>
#include <string>
#include <string_view>
#include <vector>

#include "lmeform/kernel.hpp"
#include "lmeform/neighbour_search.hpp"
#include "lmeform/node_set.hpp"

namespace lmeform {

/// Which polynomials the span of the basis holds exactly.
enum class LmeConsistency {
  /// Local max-ent (seed 2.2): sum p_a = 1, sum p_a x_a = x. Affine functions only; at fixed gamma
  /// the second moment J(x) = sum p_a (x_a - x)(x_a - x)^T is not in the span, and its Hessian,
  /// an O(1) error of every approximated Hessian, does not fall with h (docs/lme_basis.md).
  first,
  /// Second-order max-ent: also sum p_a ((x_a - x)(x_a - x)^T - G_a) = 0 with a nodal gap G_a
  /// (LmeBasis::gaps()). Non-negative, smooth, weak Kronecker on the hull; the coefficients
  /// c_a = q(x_a) - A : G_a / 2 reproduce every quadratic q (Hessian A) with its gradient and
  /// Hessian (LmeBasis::gap_corrected). Needs gamma_a <= lme_second_order_max_gamma.
  second,
};

/// "first" / "second".
[[nodiscard]] const char* to_string(LmeConsistency consistency) noexcept;
/// Inverse of to_string; also accepts "1" / "2". Throws std::invalid_argument naming the valid values.
[[nodiscard]] LmeConsistency parse_lme_consistency(std::string_view name);

/// Largest gamma_a of the second-order basis. Its nodal gap h_a^2 / (2 gamma_a) is the second moment
/// the weights must meet, so the nodes around every point must spread at least that wide in every
/// direction; at larger gamma the gaps between irregular nodes are too wide for it (measured in
/// docs/lme_basis.md, h = 0.025: a grid jittered by 0.3 h fails at 2 of 2000 points at gamma 1.0,
/// 13 at 1.2, 123 at 1.6; none at 0.8 and below).
inline constexpr double lme_second_order_max_gamma = 1.0;

/// A coordinate plane x[axis] = position across which a basis is mirrored (LmeOptions::mirrors).
struct MirrorPlane {
  int axis = 0;
  double position = 0.0;
};

struct LmeOptions {
  /// Cutoff on the Gaussian factor of p_a: node a is a neighbour of x iff
  /// exp(-beta_a |x - x_a|^2) >= tol0, i.e. |x - x_a| <= r_a = sqrt(-ln(tol0)/beta_a).
  double tol0 = 1e-6;
  /// Newton stops when ||sum_a p_a (x - x_a)|| / l <= newton_tolerance (scaled, unit-free).
  double newton_tolerance = 1e-12;
  /// Upper bound on Newton iterations (each with at most 60 backtracking halvings). Most points
  /// take fewer than 10; a point whose farthest neighbours weigh e^-80 or less (fine nodes joined to
  /// a list for their cell, near the boundary of the list's hull) was measured to need over 100.
  int max_iterations = 300;
  /// A neighbourhood whose thickness is below degeneracy_tolerance times its extent (square root
  /// of the ratio of the smallest to the largest eigenvalue of its scaled covariance) is affinely
  /// degenerate (collinear in 2D, coplanar in 3D): no LME basis exists there.
  double degeneracy_tolerance = 1e-10;
  /// Derivatives (order >= 1) need J^-1; they are refused when the reciprocal condition number of
  /// the scaled J is below this (the point sits on the convex-hull boundary to machine precision).
  double min_rcond = 1e-14;
  /// Nearest neighbours averaged into the nodal spacing h_a; 0 means 2 * dim.
  int spacing_neighbours = 0;
  /// Smoothing passes applied to that spacing (smooth_spacing); 0: none. Used by the constructor
  /// that computes h_a, not by the one given h_a.
  int spacing_smoothing = 0;
  /// Mirror symmetry (axisymmetric problems: axis 0 at r = 0; a symmetric 3D body: up to three
  /// coordinate planes). The basis is even under each reflection x_axis -> 2 position - x_axis:
  /// every node a gets an image a' across each non-empty subset S of the planes that its support
  /// reaches (its distance to their intersection below its support radius; same h, beta,
  /// support), the LME problem at x is solved on its neighbours and their images, and
  /// p_a := p_a + Σ p_a'. Then d phi_h / dx_axis = 0 on each plane exactly (for a body of
  /// revolution the condition that keeps phi_r / r finite), and the planes are no longer convex-hull
  /// boundaries. Nodes must lie on one side of each plane (or on it); the axes must differ.
  std::vector<MirrorPlane> mirrors;
  /// first (default): the LME basis. second: second-order max-ent, whose Hessians converge under
  /// refinement at fixed gamma (see LmeConsistency).
  LmeConsistency consistency = LmeConsistency::first;
};

enum class LmeFailure {
  too_few_neighbours,  ///< fewer than dim + 1 neighbours
  degenerate,          ///< neighbours lie in a lower-dimensional affine subspace
  outside_hull,        ///< x lies outside the convex hull of its neighbours
  not_converged,       ///< Newton did not reach the tolerance within max_iterations
  singular_jacobian,   ///< derivatives requested where J is singular (x on the hull boundary)
  /// Second-order basis: no non-negative weights on the neighbours meet the second-moment
  /// constraints (x too close to the hull for the gaps of the nodes around it, or too few nodes).
  infeasible_second_moment,
};

[[nodiscard]] const char* to_string(LmeFailure reason) noexcept;

/// A point where the LME basis cannot be evaluated. what() reads e.g.
/// "LME evaluation failed at x = (0.5, 1.2) with 12 neighbours: outside the convex hull of its
///  neighbours (||grad ln Z|| = 3.1e-01)".
class LmeEvaluationError : public std::runtime_error {
 public:
  LmeEvaluationError(LmeFailure reason, std::span<const double> x, std::size_t neighbours,
                     double gradient_norm, const std::string& detail);
  [[nodiscard]] LmeFailure reason() const noexcept { return reason_; }
  [[nodiscard]] const std::vector<double>& point() const noexcept { return point_; }
  [[nodiscard]] std::size_t neighbour_count() const noexcept { return neighbours_; }
  /// Final scaled ||grad_lambda ln Z|| (NaN where Newton was not started).
  [[nodiscard]] double gradient_norm() const noexcept { return gradient_norm_; }
  /// What the message adds to the reason (iterations, rcond, ...); the same error is rebuilt from
  /// these five (on the other ranks of a collective setup).
  [[nodiscard]] const std::string& detail() const noexcept { return detail_; }

 private:
  LmeFailure reason_;
  std::vector<double> point_;
  std::size_t neighbours_;
  double gradient_norm_;
  std::string detail_;
};

/// Size of one compressed-storage record (doubles) for derivative order 0, 1 or 2. Physical units;
/// symmetric d x d matrices packed as their row-wise upper triangle (s = d(d+1)/2 entries):
///   order 0: ln Z, lambda[d]                                               1 + d
///   order 1: ln Z, lambda[d], r_beta[d], Dlambda[d*d] (row-major)          1 + 2d + d^2
///   order 2: ln Z, lambda[d], r_beta[d], J_beta[s], beta_bar, J^-1[s], Q[s], T[d*s]
///            = 2 + 7d/2 + 2d^2 + d^3/2, the seed's M_OS per point (Table B.2).
/// Dlambda = (J_beta - I) J^-1 is not symmetric for non-uniform beta, so order 2 keeps the
/// symmetric J_beta in its place and forms Dlambda once per point when reconstructing.
[[nodiscard]] constexpr int lme_record_size(int dim, int order) noexcept {
  const int s = dim * (dim + 1) / 2;
  return order <= 0 ? 1 + dim : order == 1 ? 1 + 2 * dim + dim * dim : 2 + 2 * dim + 3 * s + dim * s;
}

/// Record size of the second-order basis (LmeConsistency::second), K = d + d(d+1)/2 constraint
/// features, s = d(d+1)/2, in units of the local length l (kept as the first entry):
///   order 0: l, ln Z, mu[K]                                       2 + K
///   order 1: ..., abar[d], dmu/dx[K*d]                            2 + K + d + K d
///   order 2: ..., d2mu/dx2[K*s], Sbar[s]                          2 + K + d + K d + K s + s
/// (1D: 4 / 7 / 10, 2D: 7 / 19 / 37, 3D: 11 / 41 / 101 doubles).
[[nodiscard]] constexpr int lme_second_order_record_size(int dim, int order) noexcept {
  const int s = dim * (dim + 1) / 2, k = dim + s;
  return order <= 0 ? 2 + k : order == 1 ? 2 + k + dim + k * dim : 2 + k + dim + k * dim + k * s + s;
}

/// Scratch buffers reused across evaluations (grow only; no allocation once warm). One per thread.
struct LmeWorkspace {
  std::vector<double> y;       ///< n * dim relative (scaled) coordinates
  std::vector<double> beta;    ///< n scaled beta
  std::vector<double> c;       ///< n exponents' lambda-free part -beta |y|^2
  std::vector<double> p;       ///< n basis values
  std::vector<double> record;  ///< one record
  std::vector<int> position;   ///< node -> column in the current cell list (-1: absent)
  std::vector<int> columns;    ///< a point's list mapped to cell columns
  std::vector<double> jet;     ///< one point's jet when scattering
  std::vector<int> extended;   ///< mirror symmetry: the neighbours followed by their images
  std::vector<double> mirror_jet;  ///< mirror symmetry: the jet over `extended` before folding
  std::vector<int> mirror_fold;    ///< mirror symmetry: for each image in `extended`, its node's column
  std::vector<double> phi;         ///< second-order basis: n * K constraint features
};

/// The LME basis of a node set: nodes, per-node gamma_a, spacing h_a, beta_a, support radius r_a
/// and a kd-tree for neighbour lists. Evaluation methods are const and thread-safe given one
/// workspace per thread.
class LmeBasis {
 public:
  /// gamma: one value for all nodes or one per node. Spacing from nodal_spacing().
  LmeBasis(NodeSet nodes, std::span<const double> gamma, LmeOptions options = {});
  /// Same with a caller-provided spacing h_a (one per node).
  LmeBasis(NodeSet nodes, std::span<const double> gamma, std::vector<double> spacing, LmeOptions options = {});

  [[nodiscard]] int dim() const noexcept { return nodes_.dim; }
  [[nodiscard]] std::size_t size() const noexcept { return nodes_.size(); }
  [[nodiscard]] const NodeSet& nodes() const noexcept { return nodes_; }
  [[nodiscard]] const KdTree& tree() const noexcept { return tree_; }
  [[nodiscard]] const LmeOptions& options() const noexcept { return options_; }
  [[nodiscard]] std::span<const double> gamma() const noexcept { return gamma_; }
  [[nodiscard]] std::span<const double> spacing() const noexcept { return spacing_; }
  [[nodiscard]] std::span<const double> beta() const noexcept { return beta_; }
  [[nodiscard]] std::span<const double> support_radii() const noexcept { return radius_; }
  [[nodiscard]] LmeConsistency consistency() const noexcept { return options_.consistency; }

  /// Second-order basis: the nodal gaps G_a, d(d+1)/2 doubles per node (upper triangle in
  /// kernel::hessian_slot order). G_a = h_a^2 / (2 gamma_a) I, projected onto the tangent space of
  /// the hull at hull nodes (a hull point sees only the nodes of its face) and, for the first row of
  /// nodes along a hull face, widened across it to 1.5 times the squared distance
  /// (docs/lme_basis.md). Empty for the first-order basis.
  [[nodiscard]] std::span<const double> gaps() const noexcept { return gap_; }
  /// Nodal coefficients c_a = values_a - hessians_a : G_a / 2 from a field's nodal values and
  /// Hessians (d(d+1)/2 per node, kernel::hessian_slot order): with them the basis reproduces
  /// quadratics exactly, and approximates smooth fields to third order. The first-order basis
  /// returns the values.
  [[nodiscard]] std::vector<double> gap_corrected(std::span<const double> values, std::span<const double> hessians) const;
  /// Doubles of one compressed record of this basis (lme_record_size or lme_second_order_record_size).
  [[nodiscard]] int record_size(int order) const noexcept;

  /// Images of nodes across the mirror planes (LmeOptions::mirrors): how many, and the node each
  /// image belongs to. Empty without mirror symmetry.
  [[nodiscard]] std::size_t image_count() const noexcept { return image_source_.size(); }
  [[nodiscard]] std::span<const int> image_sources() const noexcept { return image_source_; }

  /// Primal list of x: nodes b with |x - x_b| <= r_b (or, with mirror symmetry, |x - x_b'| <= r_b
  /// for its image b'), sorted by index.
  [[nodiscard]] std::vector<int> neighbours(std::span<const double> x) const;
  /// Primal lists of many points (point-major coordinates).
  [[nodiscard]] CsrLists neighbour_lists(std::span<const double> points) const;

  /// Values (order 0), + gradients (1), + Hessians (2) of the basis functions of `neighbours` at x,
  /// written to jet[s * n + a] (n = neighbours.size(), jet.size() >= jet_size(dim, order) * n).
  /// Throws LmeEvaluationError where x cannot be evaluated.
  void evaluate(std::span<const double> x, std::span<const int> neighbours, int order, std::span<double> jet,
                LmeWorkspace& ws) const;
  /// Convenience: allocates the jet.
  [[nodiscard]] std::vector<double> evaluate(std::span<const double> x, std::span<const int> neighbours,
                                             int order) const;

  /// Cell tabulation for the assembly: nq points (points[q * dim + i]) sharing ONE neighbour list
  /// `cell_nodes` (n nodes, e.g. a background cell's union list) are evaluated against that list and
  /// written in the kernel contract layout basis[(q * J + s) * n + a], J = jet_size(dim, order).
  /// basis.size() >= nq * J * n. No allocation once `ws` is warm.
  void tabulate_cell(std::span<const double> points, std::span<const int> cell_nodes, int order,
                     std::span<double> basis, LmeWorkspace& ws) const;

  /// Solves for lambda at x and writes the compressed record of `order` (record_size(order) doubles;
  /// first order: physical units; second order: see lme_second_order_record_size) to `record`.
  void solve_record(std::span<const double> x, std::span<const int> neighbours, int order, std::span<double> record,
                    LmeWorkspace& ws) const;

  /// Rebuilds the jet of `order` (<= record_order) at x from a record of `record_order`, writing
  /// p/grad/Hessian of neighbour k to jet[s * stride + column(k)], column(k) = columns[k] or k when
  /// `columns` is empty. Entries of other columns are left untouched.
  void reconstruct(std::span<const double> x, std::span<const int> neighbours, int record_order,
                   std::span<const double> record, int order, std::span<double> jet, std::size_t stride,
                   std::span<const int> columns, LmeWorkspace& ws) const;

 private:
  void init(std::span<const double> gamma, std::vector<double> spacing);
  void init_mirror();
  void check_mirrors() const;
  void init_gaps();
  void check_order(int order, const char* who) const;
  // The first-order kernels over `list` (with mirror symmetry: nodes and images, unfolded).
  void evaluate_first_order(std::span<const double> x, std::span<const int> list, int order, double* out,
                            std::size_t stride, LmeWorkspace& ws) const;
  void reconstruct_first_order(std::span<const double> x, std::span<const int> list, int record_order,
                               std::span<const double> record, int order, std::span<double> jet, std::size_t stride,
                               std::span<const int> columns, LmeWorkspace& ws) const;
  /// Mirror symmetry: fills ws.extended with `nbrs` followed by the images within reach of x;
  /// returns the extended size.
  std::size_t extend(std::span<const double> x, std::span<const int> nbrs, LmeWorkspace& ws) const;
  [[nodiscard]] bool mirrored() const noexcept { return !options_.mirrors.empty(); }
  // Coordinates and beta of every index a list may hold (with mirror symmetry: nodes then images).
  [[nodiscard]] const double* coords_data() const noexcept { return mirrored() ? all_coords_.data() : nodes_.coords.data(); }
  [[nodiscard]] const double* beta_data() const noexcept { return mirrored() ? all_beta_.data() : beta_.data(); }
  [[nodiscard]] const double* gap_data() const noexcept { return mirrored() ? all_gap_.data() : gap_.data(); }
  [[nodiscard]] bool second_order() const noexcept { return options_.consistency == LmeConsistency::second; }

  NodeSet nodes_;
  LmeOptions options_;
  KdTree tree_;
  std::vector<double> gamma_, spacing_, beta_, radius_;
  std::vector<double> gap_;  // second order: packed G_a per node
  // Mirror symmetry: nodes then images (coordinates, beta, radius) and the image -> node map.
  std::vector<int> image_source_;
  std::vector<int> image_offsets_;  // node a's images are image_offsets_[a] .. image_offsets_[a + 1]
  std::vector<double> all_coords_, all_beta_, all_radius_, all_gap_;
  std::optional<KdTree> all_tree_;
  RadiusRange radius_range_, all_radius_range_;  // of radius_ and all_radius_
};

}  // namespace lmeform
