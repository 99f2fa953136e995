#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <random>
#include <set>
#include <vector>

#include "lme_test_util.hpp"
#include "lmeform/kernel.hpp"
#include "lmeform/lme_storage.hpp"

namespace lmeform {
namespace {

using kernel::jet_size;

NodeSet set_for(int dim) {
  return dim == 1 ? test::grid(1, 21, 1.0, 0.25) : dim == 2 ? test::grid(2, 11, 1.0, 0.2) : test::grid(3, 7, 1.0, 0.2);
}

std::vector<double> varying_gamma(const NodeSet& nodes) {
  std::mt19937 rng(23);
  std::uniform_real_distribution<double> u(0.6, 6.0);
  std::vector<double> g(nodes.size());
  for (double& v : g) v = u(rng);
  return g;
}

// |a - b| <= 1e-12 * max(1, max |b| over the same derivative order) for every slot.
void expect_jets_equal(const std::vector<double>& a, const std::vector<double>& b, int dim, int order, std::size_t n,
                       const char* what) {
  ASSERT_EQ(a.size(), b.size());
  const int slots = jet_size(dim, order);
  for (int s = 0; s < slots; ++s) {
    const int first = s == 0 ? 0 : s <= dim ? 1 : 1 + dim;
    const int last = s == 0 ? 1 : s <= dim ? 1 + dim : slots;
    double scale = 1.0;
    for (int t = first; t < last; ++t)
      for (std::size_t k = 0; k < n; ++k) scale = std::max(scale, std::abs(b[static_cast<std::size_t>(t) * n + k]));
    for (std::size_t k = 0; k < n; ++k) {
      const std::size_t i = static_cast<std::size_t>(s) * n + k;
      EXPECT_LE(std::abs(a[i] - b[i]), 1e-12 * scale) << what << " slot " << s << " column " << k;
    }
  }
}

class Storage : public ::testing::TestWithParam<int> {};

TEST_P(Storage, FullAndCompressedAgreeForEveryOrder) {
  const int dim = GetParam();
  const NodeSet nodes = set_for(dim);
  const LmeBasis basis(nodes, varying_gamma(nodes));
  const int nq = 25;
  const auto pts = test::random_points(dim, nq, 0.05, 0.95, 31);
  const CsrLists lists = basis.neighbour_lists(pts);
  LmeWorkspace ws;
  for (int order = 0; order <= 2; ++order) {
    const LmeFullStorage full(basis, pts, lists, order);
    const LmeCompressedStorage comp(basis, pts, lists, order);
    EXPECT_EQ(full.doubles(), lists.total() * static_cast<std::size_t>(jet_size(dim, order)));
    EXPECT_EQ(comp.doubles(), static_cast<std::size_t>(nq * lme_record_size(dim, order)));
    for (int want = 0; want <= order; ++want) {
      for (std::size_t q = 0; q < lists.size(); ++q) {
        const std::size_t n = lists[q].size();
        std::vector<double> a(static_cast<std::size_t>(jet_size(dim, want)) * n), b(a.size());
        full.point_jet(q, want, a);
        comp.point_jet(basis, q, want, b, ws);
        expect_jets_equal(b, a, dim, want, n, "compressed vs full");
        // And both against a fresh evaluation of the point.
        const auto fresh = basis.evaluate(comp.point(q), lists[q], want);
        expect_jets_equal(a, fresh, dim, want, n, "full vs evaluate");
      }
    }
    std::vector<double> big(10000);
    EXPECT_THROW(full.point_jet(0, order + 1, big), std::invalid_argument);
  }
}

INSTANTIATE_TEST_SUITE_P(Dims, Storage, ::testing::Values(1, 2, 3));

TEST(Storage, RecordSizeIsTheSeedsOptimalStorage) {
  for (int d = 1; d <= 3; ++d) {
    // M_OS / L = 2 + 7d/2 + 2d^2 + d^3/2 (seed Table B.2), in integers: (4 + 7d + 4d^2 + d^3) / 2.
    EXPECT_EQ(lme_record_size(d, 2), (4 + 7 * d + 4 * d * d + d * d * d) / 2) << d;
    EXPECT_EQ(lme_record_size(d, 0), 1 + d);
  }
}

TEST(CellTabulation, SharedListEqualsPerPointEvaluation) {
  for (int dim = 1; dim <= 3; ++dim) {
    const NodeSet nodes = set_for(dim);
    const LmeBasis basis(nodes, varying_gamma(nodes));
    const int nq = 6;
    const auto pts = test::random_points(dim, nq, 0.3, 0.6, 41);
    // The cell list: union of the points' own lists (what the assembly builds from cell vertices).
    const CsrLists lists = basis.neighbour_lists(pts);
    std::set<int> uni(lists.indices.begin(), lists.indices.end());
    const std::vector<int> cell(uni.begin(), uni.end());
    const std::size_t n = cell.size();
    for (int order = 0; order <= 2; ++order) {
      const auto jn = static_cast<std::size_t>(jet_size(dim, order));
      std::vector<double> tab(nq * jn * n, -7.0);
      LmeWorkspace ws;
      basis.tabulate_cell(pts, cell, order, tab, ws);
      for (int q = 0; q < nq; ++q) {
        const auto x = std::span<const double>(pts).subspan(static_cast<std::size_t>(q * dim), static_cast<std::size_t>(dim));
        const auto ref = basis.evaluate(x, cell, order);
        const std::vector<double> got(tab.begin() + static_cast<std::ptrdiff_t>(q * jn * n),
                                      tab.begin() + static_cast<std::ptrdiff_t>((q + 1) * jn * n));
        EXPECT_EQ(got, ref) << dim << "D order " << order << " point " << q;
      }
    }
  }
}

TEST(CellTabulation, FromStoragesScattersIntoTheCellList) {
  for (int dim = 1; dim <= 3; ++dim) {
    const NodeSet nodes = set_for(dim);
    const LmeBasis basis(nodes, varying_gamma(nodes));
    const int nq = 7;
    const auto pts = test::random_points(dim, nq, 0.3, 0.6, 43);
    const CsrLists lists = basis.neighbour_lists(pts);
    std::set<int> uni(lists.indices.begin(), lists.indices.end());
    std::vector<int> cell(uni.begin(), uni.end());
    std::reverse(cell.begin(), cell.end());  // any order of the cell list works
    const std::size_t n = cell.size();
    const LmeFullStorage full(basis, pts, lists, 2);
    const LmeCompressedStorage comp(basis, pts, lists, 2);
    const std::vector<int> ids = {4, 0, 6, 2};  // a cell's points need not be contiguous
    LmeWorkspace ws;
    for (int order = 0; order <= 2; ++order) {
      const auto jn = static_cast<std::size_t>(jet_size(dim, order));
      std::vector<double> tf(ids.size() * jn * n, -7.0), tc(tf.size(), -7.0);
      full.tabulate_cell(ids, cell, order, tf, ws);
      comp.tabulate_cell(basis, ids, cell, order, tc, ws);
      for (std::size_t k = 0; k < ids.size(); ++k) {
        const auto q = static_cast<std::size_t>(ids[k]);
        const auto list = lists[q];
        std::vector<double> own(jn * list.size());
        full.point_jet(q, order, own);
        std::vector<double> expect(jn * n, 0.0);
        for (std::size_t a = 0; a < list.size(); ++a) {
          const auto col = static_cast<std::size_t>(std::find(cell.begin(), cell.end(), list[a]) - cell.begin());
          for (std::size_t s = 0; s < jn; ++s) expect[s * n + col] = own[s * list.size() + a];
        }
        const std::vector<double> gf(tf.begin() + static_cast<std::ptrdiff_t>(k * jn * n),
                                     tf.begin() + static_cast<std::ptrdiff_t>((k + 1) * jn * n));
        const std::vector<double> gc(tc.begin() + static_cast<std::ptrdiff_t>(k * jn * n),
                                     tc.begin() + static_cast<std::ptrdiff_t>((k + 1) * jn * n));
        EXPECT_EQ(gf, expect) << dim << "D order " << order;
        expect_jets_equal(gc, expect, dim, order, n, "compressed cell tabulation");
      }
    }
    // A cell list missing one of a point's nodes is refused, and the workspace stays usable.
    std::vector<int> short_cell(cell.begin() + 1, cell.end());
    std::vector<double> buf(ids.size() * 6 * n);
    bool missing = false;
    for (const int q : ids)
      for (const int a : lists[static_cast<std::size_t>(q)]) missing = missing || a == cell.front();
    if (missing) {
      EXPECT_THROW(full.tabulate_cell(ids, short_cell, 0, buf, ws), std::invalid_argument);
      EXPECT_THROW(comp.tabulate_cell(basis, ids, short_cell, 0, buf, ws), std::invalid_argument);
    }
    for (const int v : ws.position) EXPECT_EQ(v, -1);
  }
}

}  // namespace
}  // namespace lmeform
