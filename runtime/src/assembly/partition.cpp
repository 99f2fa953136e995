#include "lmeform/partition.hpp"

#include <metis.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <numeric>
#include <stdexcept>
#include <string>

namespace lmeform {

namespace {
void renumber_by_part(NodePartition& p) {
  const int n = p.size();
  p.offsets.assign(static_cast<std::size_t>(p.n_parts) + 1, 0);
  for (int a = 0; a < n; ++a) ++p.offsets[static_cast<std::size_t>(p.part_of[static_cast<std::size_t>(a)]) + 1];
  for (int q = 0; q < p.n_parts; ++q) p.offsets[static_cast<std::size_t>(q) + 1] += p.offsets[static_cast<std::size_t>(q)];
  std::vector<int> next(p.offsets.begin(), p.offsets.end() - 1);
  p.new_index.assign(static_cast<std::size_t>(n), -1);
  p.old_index.assign(static_cast<std::size_t>(n), -1);
  for (int a = 0; a < n; ++a) {
    const int b = next[static_cast<std::size_t>(p.part_of[static_cast<std::size_t>(a)])]++;
    p.new_index[static_cast<std::size_t>(a)] = b;
    p.old_index[static_cast<std::size_t>(b)] = a;
  }
}
// Position along the Hilbert curve of a point with integer coordinates x[0..dim) of `bits` bits
// each (J. Skilling's transposition: undo the curve's rotations level by level, Gray-encode, then
// interleave the bits, the most significant level first).
std::uint64_t hilbert_key(std::array<std::uint32_t, 3> x, int dim, int bits) {
  const std::uint32_t top = 1u << (bits - 1);
  for (std::uint32_t q = top; q > 1; q >>= 1) {
    const std::uint32_t lower = q - 1;
    for (int i = 0; i < dim; ++i) {
      if (x[i] & q) {
        x[0] ^= lower;
      } else {
        const std::uint32_t t = (x[0] ^ x[i]) & lower;
        x[0] ^= t;
        x[i] ^= t;
      }
    }
  }
  for (int i = 1; i < dim; ++i) x[i] ^= x[i - 1];
  std::uint32_t t = 0;
  for (std::uint32_t q = top; q > 1; q >>= 1)
    if (x[dim - 1] & q) t ^= q - 1;
  for (int i = 0; i < dim; ++i) x[i] ^= t;
  std::uint64_t key = 0;
  for (int level = bits - 1; level >= 0; --level)
    for (int i = 0; i < dim; ++i) key = (key << 1) | ((x[i] >> level) & 1u);
  return key;
}

}  // namespace

const char* to_string(PartitionMethod m) noexcept {
  switch (m) {
    case PartitionMethod::Metis: return "metis";
    case PartitionMethod::Hilbert: return "hilbert";
    case PartitionMethod::Block: return "block";
  }
  return "?";
}

PartitionMethod parse_partition_method(std::string_view name) {
  if (name == "metis") return PartitionMethod::Metis;
  if (name == "hilbert") return PartitionMethod::Hilbert;
  if (name == "block") return PartitionMethod::Block;
  throw std::invalid_argument("unknown partition '" + std::string(name) + "': choose \"metis\", \"hilbert\" or \"block\"");
}

NodePartition hilbert_partition(std::span<const double> coords, int dim, int n_parts) {
  if (dim < 1 || dim > 3) throw std::invalid_argument("hilbert_partition: dimension " + std::to_string(dim));
  const auto d = static_cast<std::size_t>(dim);
  const int n = static_cast<int>(coords.size() / d);
  if (n_parts < 1) throw std::invalid_argument("hilbert_partition: need at least one part, got " + std::to_string(n_parts));
  if (n_parts > n)
    throw std::invalid_argument("hilbert_partition: " + std::to_string(n_parts) + " parts for only " + std::to_string(n) + " nodes");
  std::array<double, 3> lower{}, upper{};
  lower.fill(0);
  upper.fill(0);
  for (std::size_t i = 0; i < d; ++i) {
    lower[i] = upper[i] = n > 0 ? coords[i] : 0.0;
    for (int a = 0; a < n; ++a) {
      lower[i] = std::min(lower[i], coords[static_cast<std::size_t>(a) * d + i]);
      upper[i] = std::max(upper[i], coords[static_cast<std::size_t>(a) * d + i]);
    }
  }
  // One cube for all axes keeps the curve's cells square: a long box is walked along its length.
  double extent = 0;
  for (std::size_t i = 0; i < d; ++i) extent = std::max(extent, upper[i] - lower[i]);
  if (extent <= 0) extent = 1;
  const int bits = dim == 1 ? 32 : 63 / dim;
  const double cells = std::ldexp(1.0, bits) - 1;
  std::vector<std::uint64_t> key(static_cast<std::size_t>(n));
  for (int a = 0; a < n; ++a) {
    std::array<std::uint32_t, 3> x{};
    for (std::size_t i = 0; i < d; ++i)
      x[i] = static_cast<std::uint32_t>(std::clamp((coords[static_cast<std::size_t>(a) * d + i] - lower[i]) / extent, 0.0, 1.0) * cells);
    key[static_cast<std::size_t>(a)] = dim == 1 ? x[0] : hilbert_key(x, dim, bits);
  }
  std::vector<int> order(static_cast<std::size_t>(n));
  std::iota(order.begin(), order.end(), 0);
  std::stable_sort(order.begin(), order.end(), [&](int a, int b) { return key[static_cast<std::size_t>(a)] < key[static_cast<std::size_t>(b)]; });
  NodePartition p;
  p.n_parts = n_parts;
  p.part_of.resize(static_cast<std::size_t>(n));
  for (int k = 0; k < n; ++k)
    p.part_of[static_cast<std::size_t>(order[static_cast<std::size_t>(k)])] =
        static_cast<int>((static_cast<long long>(k) * n_parts) / n);
  renumber_by_part(p);
  return p;
}

int NodePartition::owner(int renumbered_node) const {
  const auto it = std::upper_bound(offsets.begin(), offsets.end(), renumbered_node);
  return static_cast<int>(it - offsets.begin()) - 1;
}

int NodePartition::edge_cut(std::span<const int> adjacency_offsets, std::span<const int> adjacency) const {
  int cut = 0;
  for (int a = 0; a < size(); ++a) {
    for (int k = adjacency_offsets[static_cast<std::size_t>(a)]; k < adjacency_offsets[static_cast<std::size_t>(a) + 1]; ++k) {
      const int b = adjacency[static_cast<std::size_t>(k)];
      if (b > a && part_of[static_cast<std::size_t>(a)] != part_of[static_cast<std::size_t>(b)]) ++cut;
    }
  }
  return cut;
}

NodePartition partition_from_parts(std::vector<int> part_of, int n_parts) {
  for (const int q : part_of)
    if (q < 0 || q >= n_parts) throw std::invalid_argument("partition_from_parts: part " + std::to_string(q) + " of " + std::to_string(n_parts));
  NodePartition p;
  p.n_parts = n_parts;
  p.part_of = std::move(part_of);
  renumber_by_part(p);
  return p;
}

NodePartition block_partition(int n_nodes, int n_parts) {
  if (n_parts < 1) throw std::invalid_argument("block_partition: need at least one part, got " + std::to_string(n_parts));
  NodePartition p;
  p.n_parts = n_parts;
  p.part_of.resize(static_cast<std::size_t>(n_nodes));
  for (int a = 0; a < n_nodes; ++a) {
    p.part_of[static_cast<std::size_t>(a)] =
        static_cast<int>((static_cast<long long>(a) * n_parts) / std::max(n_nodes, 1));
  }
  renumber_by_part(p);
  return p;
}

NodePartition partition_nodes(std::span<const int> adjacency_offsets, std::span<const int> adjacency, int n_parts) {
  if (adjacency_offsets.empty()) throw std::invalid_argument("partition_nodes: empty adjacency offsets");
  const int n = static_cast<int>(adjacency_offsets.size()) - 1;
  if (n_parts < 1) throw std::invalid_argument("partition_nodes: need at least one part, got " + std::to_string(n_parts));
  if (n_parts > n) {
    throw std::invalid_argument("partition_nodes: " + std::to_string(n_parts) + " parts for only " +
                                std::to_string(n) + " nodes");
  }
  if (n_parts == 1) return block_partition(n, 1);

  // METIS wants a symmetric graph without self-loops, in its own integer type.
  std::vector<idx_t> xadj(static_cast<std::size_t>(n) + 1, 0);
  std::vector<idx_t> adjncy;
  adjncy.reserve(adjacency.size());
  for (int a = 0; a < n; ++a) {
    for (int k = adjacency_offsets[static_cast<std::size_t>(a)]; k < adjacency_offsets[static_cast<std::size_t>(a) + 1]; ++k) {
      const int b = adjacency[static_cast<std::size_t>(k)];
      if (b < 0 || b >= n) {
        throw std::invalid_argument("partition_nodes: node " + std::to_string(a) + " has neighbour " +
                                    std::to_string(b) + " outside [0, " + std::to_string(n) + ")");
      }
      if (b != a) adjncy.push_back(static_cast<idx_t>(b));
    }
    xadj[static_cast<std::size_t>(a) + 1] = static_cast<idx_t>(adjncy.size());
  }

  idx_t nvtxs = n;
  idx_t ncon = 1;
  idx_t nparts = n_parts;
  idx_t objval = 0;
  std::vector<idx_t> part(static_cast<std::size_t>(n), 0);
  idx_t options[METIS_NOPTIONS];
  METIS_SetDefaultOptions(options);
  options[METIS_OPTION_SEED] = 7;  // deterministic partitions: runs must be reproducible
  options[METIS_OPTION_NUMBERING] = 0;
  const int status = n_parts <= 8
                         ? METIS_PartGraphRecursive(&nvtxs, &ncon, xadj.data(), adjncy.data(), nullptr, nullptr,
                                                    nullptr, &nparts, nullptr, nullptr, options, &objval, part.data())
                         : METIS_PartGraphKway(&nvtxs, &ncon, xadj.data(), adjncy.data(), nullptr, nullptr, nullptr,
                                               &nparts, nullptr, nullptr, options, &objval, part.data());
  if (status != METIS_OK) {
    throw std::runtime_error("partition_nodes: METIS failed with status " + std::to_string(status) + " for " +
                             std::to_string(n) + " nodes into " + std::to_string(n_parts) + " parts");
  }
  NodePartition p;
  p.n_parts = n_parts;
  p.part_of.assign(part.begin(), part.end());
  renumber_by_part(p);
  for (int q = 0; q < n_parts; ++q) {
    if (p.offsets[static_cast<std::size_t>(q)] == p.offsets[static_cast<std::size_t>(q) + 1]) {
      throw std::runtime_error("partition_nodes: METIS left part " + std::to_string(q) + " empty");
    }
  }
  return p;
}

}  // namespace lmeform
