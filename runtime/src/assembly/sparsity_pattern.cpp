#include "lmeform/sparsity_pattern.hpp"

#include <algorithm>
#include <stdexcept>
#include <string>

namespace lmeform {

SparsityPattern build_sparsity_pattern(std::span<const int> element_offsets, std::span<const int> element_nodes,
                                       std::span<const int> node_offsets, std::span<const int> node_elements,
                                       int n_nodes, int row_begin, int row_end) {
  if (row_begin < 0 || row_end < row_begin || row_end > n_nodes) {
    throw std::invalid_argument("build_sparsity_pattern: row range [" + std::to_string(row_begin) + ", " +
                                std::to_string(row_end) + ") is not inside [0, " + std::to_string(n_nodes) + ")");
  }
  if (node_offsets.size() != static_cast<std::size_t>(n_nodes) + 1) {
    throw std::invalid_argument("build_sparsity_pattern: dual lists have " + std::to_string(node_offsets.size()) +
                                " offsets for " + std::to_string(n_nodes) + " nodes");
  }
  SparsityPattern p;
  p.row_begin = row_begin;
  p.row_end = row_end;
  p.n_nodes = n_nodes;
  const int n_rows = row_end - row_begin;
  p.offsets.assign(static_cast<std::size_t>(n_rows) + 1, 0);
  p.diagonal_counts.assign(static_cast<std::size_t>(n_rows), 0);
  p.off_diagonal_counts.assign(static_cast<std::size_t>(n_rows), 0);

  // Marker array: marker[b] == a means column b is already in row a. One pass per row over the
  // elements containing it; no search per entry, no per-row set.
  std::vector<int> marker(static_cast<std::size_t>(n_nodes), -1);
  std::vector<int> row_columns;
  for (int a = row_begin; a < row_end; ++a) {
    row_columns.clear();
    for (int k = node_offsets[static_cast<std::size_t>(a)]; k < node_offsets[static_cast<std::size_t>(a) + 1]; ++k) {
      const int e = node_elements[static_cast<std::size_t>(k)];
      for (int m = element_offsets[static_cast<std::size_t>(e)]; m < element_offsets[static_cast<std::size_t>(e) + 1]; ++m) {
        const int b = element_nodes[static_cast<std::size_t>(m)];
        if (marker[static_cast<std::size_t>(b)] != a) {
          marker[static_cast<std::size_t>(b)] = a;
          row_columns.push_back(b);
        }
      }
    }
    std::sort(row_columns.begin(), row_columns.end());
    const auto r = static_cast<std::size_t>(a - row_begin);
    for (const int b : row_columns) {
      if (b >= row_begin && b < row_end) {
        ++p.diagonal_counts[r];
      } else {
        ++p.off_diagonal_counts[r];
      }
    }
    p.columns.insert(p.columns.end(), row_columns.begin(), row_columns.end());
    p.offsets[r + 1] = static_cast<int>(p.columns.size());
  }
  return p;
}

}  // namespace lmeform
