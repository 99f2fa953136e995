// Neighbour lists for assembly: dual lists and cell-based neighbourhoods (seed Algorithm 2).
#pragma once

#include <span>

#include "lmeform/neighbour_search.hpp"

namespace lmeform {

/// For each node, the elements whose list contains it (sorted by element). `n_nodes` nodes.
[[nodiscard]] CsrLists dual_lists(const CsrLists& primal, int n_nodes);

/// For each group of consecutive lists [g * group_size, (g + 1) * group_size), the sorted union
/// of its lists: the cell neighbourhood of a background cell from the primal lists of its
/// quadrature points. The union covers every node that touches any of the cell's points, so
/// evaluating each point against its own list and scattering into the cell's list loses nothing.
[[nodiscard]] CsrLists union_of_groups(const CsrLists& lists, int group_size, int n_nodes);

/// The union of the lists named by `members` for each group (e.g. the vertices of each cell:
/// the seed's union of vertex lists).
[[nodiscard]] CsrLists union_of_members(const CsrLists& lists, const CsrLists& members, int n_nodes);

/// Replaces every index i by new_index[i] and re-sorts each list.
[[nodiscard]] CsrLists renumber_lists(const CsrLists& lists, std::span<const int> new_index);

}  // namespace lmeform
