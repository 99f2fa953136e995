// Stored LME basis data for a fixed set of evaluation points (e.g. quadrature points), each with its
// own neighbour list (CsrLists, e.g. from LmeBasis::neighbour_lists):
//
// * LmeFullStorage: the jet of every point (p, grad p, Hessian upper triangle for every neighbour,
//   up to the order asked): L * nbar * jet_size(d, order) doubles.
// * LmeCompressedStorage: one record per point (LmeBasis::record_size(order) doubles: for the
//   first-order basis ln Z, lambda, r_beta, ...; for the second-order basis l, ln Z, mu, ...; see
//   lme_basis.hpp), from which the jet is rebuilt on demand without Newton.
//
// Both give a point's jet (layout jet[s * n_q + a], columns in list order) and a cell tabulation for
// the assembly in the kernel contract layout basis[(k * J + s) * n + c], where the k-th point of the
// cell is scattered into the cell list `cell_nodes` (n nodes; each point's list must be a subset of
// it; columns of nodes outside a point's list are zero).
#pragma once

#include <cstddef>
#include <span>
#include <vector>

#include "lmeform/lme_basis.hpp"
#include "lmeform/neighbour_search.hpp"

namespace lmeform {

class LmeFullStorage {
 public:
  LmeFullStorage() = default;
  /// Evaluates every point (points[q * dim + i]) against lists[q] up to `order`.
  LmeFullStorage(const LmeBasis& basis, std::span<const double> points, CsrLists lists, int order);

  [[nodiscard]] int dim() const noexcept { return dim_; }
  [[nodiscard]] int order() const noexcept { return order_; }
  [[nodiscard]] std::size_t size() const noexcept { return lists_.size(); }
  [[nodiscard]] const CsrLists& lists() const noexcept { return lists_; }
  /// Stored basis doubles (L * nbar * jet_size), lists and points not counted.
  [[nodiscard]] std::size_t doubles() const noexcept { return data_.size(); }

  /// Point q's stored jet: jet_size(dim, order()) rows of lists()[q].size() entries.
  [[nodiscard]] std::span<const double> jet(std::size_t q) const;
  /// Point q's jet up to `order` (<= order()) copied to out[s * n_q + a].
  void point_jet(std::size_t q, int order, std::span<double> out) const;
  /// Cell tabulation (see top of file) of the points `point_ids` into `basis`.
  void tabulate_cell(std::span<const int> point_ids, std::span<const int> cell_nodes, int order,
                     std::span<double> basis, LmeWorkspace& ws) const;

 private:
  int dim_ = 0;
  int order_ = 0;
  std::size_t num_nodes_ = 0;
  CsrLists lists_;
  std::vector<double> data_;  // point q's block starts at lists_.offsets[q] * jet_size
};

class LmeCompressedStorage {
 public:
  LmeCompressedStorage() = default;
  /// Solves every point (points[q * dim + i]) against lists[q] and keeps its record for `order`.
  LmeCompressedStorage(const LmeBasis& basis, std::span<const double> points, CsrLists lists, int order);

  [[nodiscard]] int dim() const noexcept { return dim_; }
  [[nodiscard]] int order() const noexcept { return order_; }
  [[nodiscard]] std::size_t size() const noexcept { return lists_.size(); }
  [[nodiscard]] const CsrLists& lists() const noexcept { return lists_; }
  /// Stored record doubles (L * record size), as the seed counts M_OS; the copy of the points
  /// (L * dim doubles, needed to rebuild x - x_a) and the lists are not counted.
  [[nodiscard]] std::size_t doubles() const noexcept { return records_.size(); }
  [[nodiscard]] std::span<const double> record(std::size_t q) const;
  [[nodiscard]] std::span<const double> point(std::size_t q) const;

  /// Rebuilds point q's jet up to `order` (<= order()) into out[s * n_q + a]. `basis` must be the
  /// basis the storage was built from (same nodes and beta).
  void point_jet(const LmeBasis& basis, std::size_t q, int order, std::span<double> out, LmeWorkspace& ws) const;
  /// Cell tabulation (see top of file) rebuilt from the records of `point_ids`.
  void tabulate_cell(const LmeBasis& basis, std::span<const int> point_ids, std::span<const int> cell_nodes,
                     int order, std::span<double> basis_out, LmeWorkspace& ws) const;

 private:
  void check_same_basis(const LmeBasis& basis) const;

  int dim_ = 0;
  int order_ = 0;
  int record_size_ = 0;
  LmeConsistency consistency_ = LmeConsistency::first;
  std::size_t num_nodes_ = 0;
  CsrLists lists_;
  std::vector<double> points_;
  std::vector<double> records_;
};

}  // namespace lmeform
