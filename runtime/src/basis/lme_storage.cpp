#include "lmeform/lme_storage.hpp"

#include <algorithm>
#include <stdexcept>
#include <string>
#include <utility>

namespace lmeform {

namespace {

void check_points(const LmeBasis& basis, std::span<const double> points, const CsrLists& lists, int order,
                  const char* who) {
  lists.validate();
  const auto d = static_cast<std::size_t>(basis.dim());
  if (points.size() != lists.size() * d) {
    throw std::invalid_argument(std::string(who) + ": " + std::to_string(points.size()) + " coordinates for " +
                                std::to_string(lists.size()) + " lists in dimension " + std::to_string(d));
  }
  if (order < 0 || order > 2) {
    throw std::invalid_argument(std::string(who) + ": order must be 0, 1 or 2, got " + std::to_string(order));
  }
}

// Marks the cell's nodes in ws.position for the lifetime of the guard (and clears them again,
// also when an exception leaves the scatter early).
class CellMap {
 public:
  CellMap(LmeWorkspace& ws, std::size_t num_nodes, std::span<const int> cell_nodes) : ws_(ws), cell_(cell_nodes) {
    if (ws_.position.size() != num_nodes) ws_.position.assign(num_nodes, -1);
    for (std::size_t c = 0; c < cell_.size(); ++c) ws_.position[static_cast<std::size_t>(cell_[c])] = static_cast<int>(c);
  }
  ~CellMap() {
    for (const int a : cell_) ws_.position[static_cast<std::size_t>(a)] = -1;
  }
  CellMap(const CellMap&) = delete;
  CellMap& operator=(const CellMap&) = delete;

  // Columns of a point's list in the cell list, into ws.columns.
  std::span<const int> columns(std::span<const int> list, int point) {
    ws_.columns.resize(list.size());
    for (std::size_t k = 0; k < list.size(); ++k) {
      const int col = ws_.position[static_cast<std::size_t>(list[k])];
      if (col < 0) {
        throw std::invalid_argument("LME cell tabulation: node " + std::to_string(list[k]) + " of point " +
                                    std::to_string(point) + " is not in the cell's node list");
      }
      ws_.columns[k] = col;
    }
    return ws_.columns;
  }

 private:
  LmeWorkspace& ws_;
  std::span<const int> cell_;
};

void check_cell(std::size_t npts, std::span<const int> cell_nodes, int dim, int order, int stored_order,
                std::size_t buffer, std::size_t num_nodes) {
  if (order < 0 || order > stored_order) {
    throw std::invalid_argument("LME storage: order " + std::to_string(order) + " not available (stored order " +
                                std::to_string(stored_order) + ")");
  }
  const std::size_t need = npts * static_cast<std::size_t>(kernel::jet_size(dim, order)) * cell_nodes.size();
  if (buffer < need) {
    throw std::invalid_argument("LME storage: cell buffer holds " + std::to_string(buffer) + " doubles, need " +
                                std::to_string(need));
  }
  for (const int a : cell_nodes) {
    if (a < 0 || static_cast<std::size_t>(a) >= num_nodes) {
      throw std::invalid_argument("LME storage: cell node " + std::to_string(a) + " out of range");
    }
  }
}

}  // namespace

LmeFullStorage::LmeFullStorage(const LmeBasis& basis, std::span<const double> points, CsrLists lists, int order)
    : dim_(basis.dim()), order_(order), num_nodes_(basis.size()), lists_(std::move(lists)) {
  check_points(basis, points, lists_, order, "LmeFullStorage");
  const auto jn = static_cast<std::size_t>(kernel::jet_size(dim_, order_));
  const auto d = static_cast<std::size_t>(dim_);
  data_.resize(lists_.total() * jn);
  LmeWorkspace ws;
  for (std::size_t q = 0; q < lists_.size(); ++q) {
    const auto list = lists_[q];
    basis.evaluate(points.subspan(q * d, d), list, order_,
                   std::span<double>(data_).subspan(static_cast<std::size_t>(lists_.offsets[q]) * jn, jn * list.size()),
                   ws);
  }
}

std::span<const double> LmeFullStorage::jet(std::size_t q) const {
  const auto jn = static_cast<std::size_t>(kernel::jet_size(dim_, order_));
  return std::span<const double>(data_).subspan(static_cast<std::size_t>(lists_.offsets[q]) * jn,
                                                jn * lists_[q].size());
}

void LmeFullStorage::point_jet(std::size_t q, int order, std::span<double> out) const {
  if (order < 0 || order > order_) {
    throw std::invalid_argument("LmeFullStorage::point_jet: order " + std::to_string(order) +
                                " not stored (order " + std::to_string(order_) + ")");
  }
  const auto src = jet(q);
  const std::size_t count = static_cast<std::size_t>(kernel::jet_size(dim_, order)) * lists_[q].size();
  if (out.size() < count) throw std::invalid_argument("LmeFullStorage::point_jet: output too small");
  // Rows are slot-major, so lower orders are a prefix of the stored block.
  std::copy_n(src.begin(), count, out.begin());
}

void LmeFullStorage::tabulate_cell(std::span<const int> point_ids, std::span<const int> cell_nodes, int order,
                                   std::span<double> basis, LmeWorkspace& ws) const {
  check_cell(point_ids.size(), cell_nodes, dim_, order, order_, basis.size(), num_nodes_);
  const auto jn = static_cast<std::size_t>(kernel::jet_size(dim_, order));
  const std::size_t n = cell_nodes.size();
  std::fill_n(basis.begin(), point_ids.size() * jn * n, 0.0);
  CellMap map(ws, num_nodes_, cell_nodes);
  for (std::size_t k = 0; k < point_ids.size(); ++k) {
    const auto q = static_cast<std::size_t>(point_ids[k]);
    const auto list = lists_[q];
    const auto cols = map.columns(list, point_ids[k]);
    const auto src = jet(q);
    const std::size_t m = list.size();
    double* dst = basis.data() + k * jn * n;
    for (std::size_t s = 0; s < jn; ++s)
      for (std::size_t a = 0; a < m; ++a) dst[s * n + static_cast<std::size_t>(cols[a])] = src[s * m + a];
  }
}

LmeCompressedStorage::LmeCompressedStorage(const LmeBasis& basis, std::span<const double> points, CsrLists lists,
                                           int order)
    : dim_(basis.dim()), order_(order), num_nodes_(basis.size()), lists_(std::move(lists)),
      points_(points.begin(), points.end()) {
  check_points(basis, points, lists_, order, "LmeCompressedStorage");
  record_size_ = basis.record_size(order_);
  consistency_ = basis.consistency();
  const auto rs = static_cast<std::size_t>(record_size_);
  const auto d = static_cast<std::size_t>(dim_);
  records_.resize(lists_.size() * rs);
  LmeWorkspace ws;
  for (std::size_t q = 0; q < lists_.size(); ++q) {
    basis.solve_record(points.subspan(q * d, d), lists_[q], order_, std::span<double>(records_).subspan(q * rs, rs), ws);
  }
}

void LmeCompressedStorage::check_same_basis(const LmeBasis& basis) const {
  if (basis.size() != num_nodes_ || basis.dim() != dim_ || basis.consistency() != consistency_) {
    throw std::invalid_argument("LmeCompressedStorage: basis differs from the one the storage was built from");
  }
}

std::span<const double> LmeCompressedStorage::record(std::size_t q) const {
  const auto rs = static_cast<std::size_t>(record_size_);
  return std::span<const double>(records_).subspan(q * rs, rs);
}

std::span<const double> LmeCompressedStorage::point(std::size_t q) const {
  const auto d = static_cast<std::size_t>(dim_);
  return std::span<const double>(points_).subspan(q * d, d);
}

void LmeCompressedStorage::point_jet(const LmeBasis& basis, std::size_t q, int order, std::span<double> out,
                                     LmeWorkspace& ws) const {
  check_same_basis(basis);
  const auto list = lists_[q];
  if (out.size() < static_cast<std::size_t>(kernel::jet_size(dim_, std::max(order, 0))) * list.size()) {
    throw std::invalid_argument("LmeCompressedStorage::point_jet: output too small");
  }
  basis.reconstruct(point(q), list, order_, record(q), order, out, list.size(), {}, ws);
}

void LmeCompressedStorage::tabulate_cell(const LmeBasis& basis, std::span<const int> point_ids,
                                         std::span<const int> cell_nodes, int order, std::span<double> basis_out,
                                         LmeWorkspace& ws) const {
  check_same_basis(basis);
  check_cell(point_ids.size(), cell_nodes, dim_, order, order_, basis_out.size(), num_nodes_);
  const auto jn = static_cast<std::size_t>(kernel::jet_size(dim_, order));
  const std::size_t n = cell_nodes.size();
  std::fill_n(basis_out.begin(), point_ids.size() * jn * n, 0.0);
  CellMap map(ws, num_nodes_, cell_nodes);
  for (std::size_t k = 0; k < point_ids.size(); ++k) {
    const auto q = static_cast<std::size_t>(point_ids[k]);
    const auto cols = map.columns(lists_[q], point_ids[k]);
    basis.reconstruct(point(q), lists_[q], order_, record(q), order, basis_out.subspan(k * jn * n, jn * n), n, cols,
                      ws);
  }
}

}  // namespace lmeform
