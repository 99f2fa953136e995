// Second-order max-ent basis (LmeConsistency::second), internal to lmeform_basis: LmeBasis calls
// these for its evaluation, records and reconstruction; neighbour lists, mirror images and the
// folding of images stay in LmeBasis, shared with the first-order basis.
#pragma once

#include <cstddef>
#include <span>
#include <vector>

#include "lmeform/lme_basis.hpp"
#include "lmeform/node_set.hpp"

namespace lmeform::detail {

/// What a second-order evaluation reads of every index a list may hold (nodes, then mirror images):
/// coordinates, beta and the packed nodal gap (d(d+1)/2 doubles).
struct SecondOrderNodes {
  const double* coords = nullptr;
  const double* beta = nullptr;
  const double* gap = nullptr;
};

/// The jet of `order` at x over `list`, written to out[s * stride + k].
void second_order_evaluate(int dim, const SecondOrderNodes& nodes, const LmeOptions& options, std::span<const double> x,
                           std::span<const int> list, int order, double* out, std::size_t stride, LmeWorkspace& ws);

/// The record of `order` (lme_second_order_record_size) at x over `list`.
void second_order_solve_record(int dim, const SecondOrderNodes& nodes, const LmeOptions& options,
                               std::span<const double> x, std::span<const int> list, int order, double* record,
                               LmeWorkspace& ws);

/// The jet of `order` rebuilt from a record of `record_order`, to out[s * stride + column(k)] with
/// column(k) = cols[k], or k when cols is null.
void second_order_reconstruct(int dim, const SecondOrderNodes& nodes, std::span<const double> x,
                              std::span<const int> list, int record_order, const double* record, int order,
                              double* out, std::size_t stride, const int* cols, LmeWorkspace& ws);

/// The nodal gaps of `nodes` (see LmeBasis::gaps), bounded by the convex hull of `hull_nodes` (the
/// nodes themselves, or with mirror symmetry the nodes and their reflections).
[[nodiscard]] std::vector<double> second_order_gaps(const NodeSet& nodes, std::span<const double> spacing,
                                                    std::span<const double> gamma, const NodeSet& hull_nodes);

}  // namespace lmeform::detail
