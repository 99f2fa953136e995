// The sparsity pattern of a meshfree operator, built from element neighbour lists.
//
// An "element" is whatever the assembly loops over: a background cell (cell-based
// neighbourhoods, seed Algorithm 2) or a single quadrature point (Algorithm 1). Nodes a and b
// couple when some element's list holds both. Rows are node (block) rows; a rank builds only
// its own contiguous row range, and the counts feed MatXAIJSetPreallocation exactly.
#pragma once

#include <span>
#include <vector>

namespace lmeform {

struct SparsityPattern {
  int row_begin = 0;              ///< first owned node row (renumbered)
  int row_end = 0;                ///< one past the last owned node row
  int n_nodes = 0;                ///< global number of node rows/columns
  std::vector<int> offsets;       ///< (row_end - row_begin) + 1
  std::vector<int> columns;       ///< sorted node columns of each owned row
  std::vector<int> diagonal_counts;      ///< per owned row: columns in [row_begin, row_end)
  std::vector<int> off_diagonal_counts;  ///< per owned row: the others

  [[nodiscard]] int n_rows() const noexcept { return row_end - row_begin; }
  [[nodiscard]] std::span<const int> row(int owned_row) const noexcept {
    return {columns.data() + offsets[static_cast<std::size_t>(owned_row)],
            static_cast<std::size_t>(offsets[static_cast<std::size_t>(owned_row) + 1] - offsets[static_cast<std::size_t>(owned_row)])};
  }
  [[nodiscard]] long long nonzeros() const noexcept { return static_cast<long long>(columns.size()); }
};

/// Builds the rows [row_begin, row_end) of the node-to-node pattern. `element_offsets/nodes` are
/// the elements' node lists (CSR, renumbered nodes); `node_offsets/elements` the dual lists
/// (for each node, the elements whose list contains it). Only the elements of owned rows are
/// visited, each once per owned node it contains: the cost is what the two strategies compare.
SparsityPattern build_sparsity_pattern(std::span<const int> element_offsets, std::span<const int> element_nodes,
                                       std::span<const int> node_offsets, std::span<const int> node_elements,
                                       int n_nodes, int row_begin, int row_end);

}  // namespace lmeform
