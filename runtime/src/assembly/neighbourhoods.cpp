#include "lmeform/neighbourhoods.hpp"

#include <algorithm>
#include <stdexcept>
#include <string>
#include <vector>

namespace lmeform {

CsrLists dual_lists(const CsrLists& primal, int n_nodes) {
  CsrLists dual;
  dual.offsets.assign(static_cast<std::size_t>(n_nodes) + 1, 0);
  for (const int a : primal.indices) {
    if (a < 0 || a >= n_nodes) {
      throw std::invalid_argument("dual_lists: node " + std::to_string(a) + " outside [0, " +
                                  std::to_string(n_nodes) + ")");
    }
    ++dual.offsets[static_cast<std::size_t>(a) + 1];
  }
  for (std::size_t a = 0; a < static_cast<std::size_t>(n_nodes); ++a) dual.offsets[a + 1] += dual.offsets[a];
  dual.indices.resize(primal.indices.size());
  std::vector<int> next(dual.offsets.begin(), dual.offsets.end() - 1);
  // Elements are visited in increasing order, so each dual list comes out sorted.
  for (std::size_t e = 0; e < primal.size(); ++e) {
    for (const int a : primal[e]) dual.indices[static_cast<std::size_t>(next[static_cast<std::size_t>(a)]++)] = static_cast<int>(e);
  }
  return dual;
}

namespace {
// Marker-based union: no sort of duplicates, one sort of the result.
template <class ForEachList>
void append_union(CsrLists& out, std::vector<int>& marker, int stamp, std::vector<int>& scratch, ForEachList&& lists) {
  scratch.clear();
  lists([&](std::span<const int> list) {
    for (const int a : list) {
      if (marker[static_cast<std::size_t>(a)] != stamp) {
        marker[static_cast<std::size_t>(a)] = stamp;
        scratch.push_back(a);
      }
    }
  });
  std::sort(scratch.begin(), scratch.end());
  out.indices.insert(out.indices.end(), scratch.begin(), scratch.end());
  out.offsets.push_back(static_cast<int>(out.indices.size()));
}
}  // namespace

CsrLists union_of_groups(const CsrLists& lists, int group_size, int n_nodes) {
  if (group_size <= 0 || lists.size() % static_cast<std::size_t>(group_size) != 0) {
    throw std::invalid_argument("union_of_groups: " + std::to_string(lists.size()) +
                                " lists do not split into groups of " + std::to_string(group_size));
  }
  const std::size_t groups = lists.size() / static_cast<std::size_t>(group_size);
  CsrLists out;
  out.offsets.reserve(groups + 1);
  std::vector<int> marker(static_cast<std::size_t>(n_nodes), -1);
  std::vector<int> scratch;
  for (std::size_t g = 0; g < groups; ++g) {
    append_union(out, marker, static_cast<int>(g), scratch, [&](auto&& visit) {
      for (int k = 0; k < group_size; ++k) visit(lists[g * static_cast<std::size_t>(group_size) + static_cast<std::size_t>(k)]);
    });
  }
  return out;
}

CsrLists union_of_members(const CsrLists& lists, const CsrLists& members, int n_nodes) {
  CsrLists out;
  out.offsets.reserve(members.size() + 1);
  std::vector<int> marker(static_cast<std::size_t>(n_nodes), -1);
  std::vector<int> scratch;
  for (std::size_t g = 0; g < members.size(); ++g) {
    append_union(out, marker, static_cast<int>(g), scratch, [&](auto&& visit) {
      for (const int m : members[g]) visit(lists[static_cast<std::size_t>(m)]);
    });
  }
  return out;
}

CsrLists renumber_lists(const CsrLists& lists, std::span<const int> new_index) {
  CsrLists out;
  out.offsets = lists.offsets;
  out.indices.resize(lists.indices.size());
  for (std::size_t i = 0; i < lists.indices.size(); ++i) {
    out.indices[i] = new_index[static_cast<std::size_t>(lists.indices[i])];
  }
  for (std::size_t e = 0; e < out.size(); ++e) {
    std::sort(out.indices.begin() + out.offsets[e], out.indices.begin() + out.offsets[e + 1]);
  }
  return out;
}

}  // namespace lmeform
