#include "lmeform/sparsity_pattern.hpp"

#include <algorithm>
#include <bit>
#include <cstdint>
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

  // One bit per node marks the columns of the current row (a set bit is only read: an
  // unconditional OR would chain every visit on the store before it), and a row's columns come out
  // sorted by scanning the words between its smallest and largest column, cleared on the way. The nodes of an
  // element are visited once per row it holds, tens of times per column, so this per-visit cost is
  // the pattern's cost. A row whose column range spans more words than it had visits (an ordering
  // that scatters neighbours) collects its columns from the visits and sorts them instead.
  std::vector<std::uint64_t> bits((static_cast<std::size_t>(n_nodes) + 63) / 64, 0);
  std::vector<int> row_columns;
  for (int a = row_begin; a < row_end; ++a) {
    row_columns.clear();
    int lowest = n_nodes, highest = -1;
    std::size_t visits = 0;
    const auto dual_begin = static_cast<std::size_t>(node_offsets[static_cast<std::size_t>(a)]);
    const auto dual_end = static_cast<std::size_t>(node_offsets[static_cast<std::size_t>(a) + 1]);
    for (std::size_t k = dual_begin; k < dual_end; ++k) {
      const auto e = static_cast<std::size_t>(node_elements[k]);
      const auto first = static_cast<std::size_t>(element_offsets[e]), last = static_cast<std::size_t>(element_offsets[e + 1]);
      visits += last - first;
      for (std::size_t m = first; m < last; ++m) {
        const int b = element_nodes[m];
        std::uint64_t& word = bits[static_cast<std::size_t>(b) >> 6];
        const std::uint64_t mask = std::uint64_t{1} << (b & 63);
        if ((word & mask) == 0) {  // rarely taken: most visits find the bit set, and loads do not wait on stores
          word |= mask;
          lowest = std::min(lowest, b);
          highest = std::max(highest, b);
        }
      }
    }
    if (highest >= 0) {
      const std::size_t word_begin = static_cast<std::size_t>(lowest) >> 6, word_end = (static_cast<std::size_t>(highest) >> 6) + 1;
      if (word_end - word_begin <= visits) {
        for (std::size_t w = word_begin; w < word_end; ++w) {
          for (std::uint64_t word = bits[w]; word != 0; word &= word - 1)
            row_columns.push_back(static_cast<int>(w * 64 + static_cast<std::size_t>(std::countr_zero(word))));
          bits[w] = 0;
        }
      } else {
        for (std::size_t k = dual_begin; k < dual_end; ++k) {
          const auto e = static_cast<std::size_t>(node_elements[k]);
          for (auto m = static_cast<std::size_t>(element_offsets[e]); m < static_cast<std::size_t>(element_offsets[e + 1]); ++m) {
            const int b = element_nodes[m];
            std::uint64_t& word = bits[static_cast<std::size_t>(b) >> 6];
            const std::uint64_t mask = std::uint64_t{1} << (b & 63);
            if ((word & mask) != 0) {
              word &= ~mask;
              row_columns.push_back(b);
            }
          }
        }
        std::sort(row_columns.begin(), row_columns.end());
      }
    }
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
