// Neighbour search over a NodeSet: a kd-tree (nanoflann), nodal spacing, LME support radii and
// compressed-row (CSR) neighbour lists.
//
// Conventions:
// * Radius search is inclusive (|x - x_a| <= r) and returns indices sorted ascending by index.
// * k-nearest search returns the k nearest nodes sorted by ascending distance, ties by index.
// * Evaluation points are passed point-major like NodeSet: coordinate i of point q is points[q*dim+i].
#pragma once

#include <cstddef>
#include <memory>
#include <span>
#include <vector>

#include "lmeform/node_set.hpp"

namespace lmeform {

/// Compressed-row lists: list i is indices[offsets[i] .. offsets[i+1]). Used for primal lists
/// (neighbour nodes of each evaluation point) and reusable for dual lists or cell lists.
struct CsrLists {
  std::vector<int> offsets{0};  ///< size() + 1 entries, offsets[0] == 0, non-decreasing
  std::vector<int> indices;

  [[nodiscard]] std::size_t size() const noexcept { return offsets.empty() ? 0 : offsets.size() - 1; }
  [[nodiscard]] std::span<const int> operator[](std::size_t i) const noexcept {
    return {indices.data() + offsets[i], static_cast<std::size_t>(offsets[i + 1] - offsets[i])};
  }
  /// Total number of entries over all lists.
  [[nodiscard]] std::size_t total() const noexcept { return indices.size(); }
  /// Mean list length (0 for no lists).
  [[nodiscard]] double mean_size() const noexcept {
    return size() == 0 ? 0.0 : static_cast<double>(indices.size()) / static_cast<double>(size());
  }
  /// Appends one list.
  void push_back(std::span<const int> list);
  /// Throws std::invalid_argument if offsets are not a valid CSR offset array for `indices`.
  void validate() const;
};

/// kd-tree over the nodes of a NodeSet. Owns a copy of the coordinates, so the NodeSet may die.
class KdTree {
 public:
  explicit KdTree(const NodeSet& nodes, int leaf_size = 16);
  KdTree(KdTree&&) noexcept;
  KdTree& operator=(KdTree&&) noexcept;
  KdTree(const KdTree&) = delete;
  KdTree& operator=(const KdTree&) = delete;
  ~KdTree();

  [[nodiscard]] int dim() const noexcept;
  [[nodiscard]] std::size_t size() const noexcept;
  [[nodiscard]] const NodeSet& nodes() const noexcept;

  /// Nodes with |x - x_a| <= radius (inclusive), sorted by index. `out` is overwritten.
  void radius_search(std::span<const double> x, double radius, std::vector<int>& out) const;
  [[nodiscard]] std::vector<int> radius_search(std::span<const double> x, double radius) const;

  /// The min(k, size()) nearest nodes, sorted by distance (ties by index); `distances` (optional)
  /// receives the Euclidean (not squared) distances.
  void knn(std::span<const double> x, int k, std::vector<int>& out, std::vector<double>* distances = nullptr) const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

/// Nodal spacing h_a: the mean distance from node a to its `neighbours` nearest other nodes.
/// neighbours <= 0 selects 2*dim (the axis neighbours of a regular grid: h_a = grid step there).
/// Throws std::invalid_argument if the set has fewer than 2 nodes or two nodes coincide (h_a = 0).
[[nodiscard]] std::vector<double> nodal_spacing(const KdTree& tree, int neighbours = 0);

/// `passes` Jacobi passes h_a <- (h_a + mean of h over the nodes within radius_factor * h_a of
/// node a) / 2. On graded node sets (CVT) the distances to a few nearest nodes scatter from node
/// to node, and so would beta_a = gamma / h_a^2; a smooth h keeps the basis regular. The default
/// radius takes the first ring of a square (1 and 1.41 h) or hexagonal (1 h) lattice; a constant
/// h is left unchanged, and so are the node set's symmetries.
[[nodiscard]] std::vector<double> smooth_spacing(const KdTree& tree, std::vector<double> h, int passes,
                                                 double radius_factor = 1.6);

/// Support radius of an LME basis function: the distance where the Gaussian factor
/// exp(-beta r^2) falls to tol0, r = sqrt(-ln(tol0) / beta).
[[nodiscard]] double support_radius(double beta, double tol0);

/// Primal lists: for each evaluation point x_q, the nodes b with |x_q - x_b| <= radii[b], sorted by
/// index. `radii` has one entry per node (per-node supports, filtered: for at least an eighth as
/// many points as nodes the nodes are searched in classes of radii within a factor 1.5, each with
/// its own tree and largest radius, else with the largest radius) or a single entry for all nodes.
[[nodiscard]] CsrLists primal_lists(const KdTree& tree, std::span<const double> points, std::span<const double> radii);

/// The smallest and largest of a set of support radii.
struct RadiusRange {
  double smallest = 0;
  double largest = 0;
};
[[nodiscard]] RadiusRange radius_range(std::span<const double> radii);
/// The same, with the radii's range known: a caller that asks point by point (one list at a time)
/// keeps it, instead of a scan of every radius per call.
[[nodiscard]] CsrLists primal_lists(const KdTree& tree, std::span<const double> points, std::span<const double> radii, RadiusRange range);

}  // namespace lmeform
