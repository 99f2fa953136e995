// Node partitioning for distributed assembly: METIS on the node adjacency graph, then a
// renumbering so that every rank owns one contiguous range of nodes (and so of matrix rows).
#pragma once

#include <span>
#include <string_view>
#include <vector>

namespace lmeform {

/// How the nodes are split among ranks.
enum class PartitionMethod {
  Metis,    ///< METIS on the graph of overlapping supports (smallest cut; needs every node's list)
  Hilbert,  ///< consecutive runs along a Hilbert curve (no graph)
  Block,    ///< contiguous blocks of the input order (a baseline)
};
[[nodiscard]] const char* to_string(PartitionMethod m) noexcept;
/// "metis", "hilbert" or "block"; anything else throws std::invalid_argument naming the choices.
[[nodiscard]] PartitionMethod parse_partition_method(std::string_view name);

struct NodePartition {
  int n_parts = 1;
  std::vector<int> part_of;    ///< part of each node, original numbering
  std::vector<int> new_index;  ///< original node -> renumbered node
  std::vector<int> old_index;  ///< renumbered node -> original node
  std::vector<int> offsets;    ///< n_parts + 1: renumbered nodes of part p are [offsets[p], offsets[p+1])

  [[nodiscard]] int size() const noexcept { return static_cast<int>(part_of.size()); }
  [[nodiscard]] int owner(int renumbered_node) const;
  [[nodiscard]] int edge_cut(std::span<const int> adjacency_offsets, std::span<const int> adjacency) const;
};

/// Partitions a graph given in CSR form (symmetric; self-loops are ignored) into n_parts with METIS
/// and renumbers the nodes part by part, keeping their original order inside a part.
/// n_parts == 1 gives the identity (METIS itself crashes on one part).
NodePartition partition_nodes(std::span<const int> adjacency_offsets, std::span<const int> adjacency, int n_parts);

/// Parts of consecutive nodes along a Hilbert space-filling curve through the nodes' bounding box
/// (coords point-major, `dim` per node), of nearly equal size. Needs no graph: every rank can
/// compute it from the coordinates alone, in O(n log n), where METIS needs every node's
/// neighbour list first. Parts are compact but their boundaries are longer than METIS's.
NodePartition hilbert_partition(std::span<const double> coords, int dim, int n_parts);

/// The partition with these parts (one per node, in [0, n_parts)), renumbered part by part.
NodePartition partition_from_parts(std::vector<int> part_of, int n_parts);

/// The identity partition into contiguous blocks of nearly equal size (no graph needed);
/// useful as a baseline against METIS.
NodePartition block_partition(int n_nodes, int n_parts);

}  // namespace lmeform
