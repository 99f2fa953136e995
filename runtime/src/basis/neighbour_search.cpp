#include "lmeform/neighbour_search.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <numeric>
#include <stdexcept>
#include <string>
#include <utility>

#include <nanoflann.hpp>

namespace lmeform {

void CsrLists::push_back(std::span<const int> list) {
  if (offsets.empty()) offsets.push_back(0);
  indices.insert(indices.end(), list.begin(), list.end());
  offsets.push_back(static_cast<int>(indices.size()));
}

void CsrLists::validate() const {
  if (offsets.empty() || offsets.front() != 0) {
    throw std::invalid_argument("CsrLists: offsets must start with 0");
  }
  for (std::size_t i = 1; i < offsets.size(); ++i) {
    if (offsets[i] < offsets[i - 1]) {
      throw std::invalid_argument("CsrLists: offsets decrease at list " + std::to_string(i - 1));
    }
  }
  if (static_cast<std::size_t>(offsets.back()) != indices.size()) {
    throw std::invalid_argument("CsrLists: last offset " + std::to_string(offsets.back()) + " != " +
                                std::to_string(indices.size()) + " indices");
  }
}

namespace {

struct Cloud {
  NodeSet nodes;
  [[nodiscard]] std::size_t kdtree_get_point_count() const { return nodes.size(); }
  [[nodiscard]] double kdtree_get_pt(std::size_t a, std::size_t i) const {
    return nodes.coords[a * static_cast<std::size_t>(nodes.dim) + i];
  }
  template <class BBox>
  bool kdtree_get_bbox(BBox& /*bb*/) const { return false; }
};

using Index = nanoflann::KDTreeSingleIndexAdaptor<nanoflann::L2_Simple_Adaptor<double, Cloud, double, std::uint32_t>,
                                                  Cloud, -1, std::uint32_t>;

void check_point(std::span<const double> x, int dim, const char* who) {
  if (static_cast<int>(x.size()) != dim) {
    throw std::invalid_argument(std::string(who) + ": query point has " + std::to_string(x.size()) +
                                " coordinates, the tree has dimension " + std::to_string(dim));
  }
}

}  // namespace

struct KdTree::Impl {
  Cloud cloud;
  Index index;
  Impl(const NodeSet& nodes, int leaf)
      : cloud{nodes},
        index(static_cast<Index::Dimension>(nodes.dim), cloud,
              nanoflann::KDTreeSingleIndexAdaptorParams(static_cast<std::size_t>(std::max(leaf, 1)))) {}
  [[nodiscard]] double dist2(std::span<const double> x, std::size_t a) const {
    double s = 0.0;
    for (std::size_t i = 0; i < x.size(); ++i) {
      const double d = x[i] - cloud.kdtree_get_pt(a, i);
      s += d * d;
    }
    return s;
  }
};

KdTree::KdTree(const NodeSet& nodes, int leaf_size) {
  if (nodes.dim < 1 || nodes.dim > 3) {
    throw std::invalid_argument("KdTree: node set dimension must be 1, 2 or 3, got " + std::to_string(nodes.dim));
  }
  if (nodes.size() == 0) throw std::invalid_argument("KdTree: empty node set");
  impl_ = std::make_unique<Impl>(nodes, leaf_size);
}
KdTree::KdTree(KdTree&&) noexcept = default;
KdTree& KdTree::operator=(KdTree&&) noexcept = default;
KdTree::~KdTree() = default;

int KdTree::dim() const noexcept { return impl_->cloud.nodes.dim; }
std::size_t KdTree::size() const noexcept { return impl_->cloud.nodes.size(); }
const NodeSet& KdTree::nodes() const noexcept { return impl_->cloud.nodes; }

void KdTree::radius_search(std::span<const double> x, double radius, std::vector<int>& out) const {
  check_point(x, dim(), "KdTree::radius_search");
  out.clear();
  if (!(radius >= 0.0)) return;
  // nanoflann 1.4 takes the SQUARED radius for L2 and keeps only d2 < r2 (strict); widen by a few
  // ulps and filter exactly below so that the documented inclusive test holds.
  const double r2 = radius * radius;
  thread_local std::vector<std::pair<std::uint32_t, double>> hits;
  hits.clear();
  impl_->index.radiusSearch(x.data(), r2 * (1.0 + 1e-12) + std::numeric_limits<double>::min(), hits,
                            nanoflann::SearchParams(32, 0.0F, false));
  out.reserve(hits.size());
  for (const auto& [a, d2] : hits) {
    if (impl_->dist2(x, a) <= r2) out.push_back(static_cast<int>(a));
  }
  std::sort(out.begin(), out.end());
}

std::vector<int> KdTree::radius_search(std::span<const double> x, double radius) const {
  std::vector<int> out;
  radius_search(x, radius, out);
  return out;
}

void KdTree::knn(std::span<const double> x, int k, std::vector<int>& out, std::vector<double>* distances) const {
  check_point(x, dim(), "KdTree::knn");
  out.clear();
  if (distances) distances->clear();
  const std::size_t kk = std::min<std::size_t>(static_cast<std::size_t>(std::max(k, 0)), size());
  if (kk == 0) return;
  std::vector<std::uint32_t> idx(kk);
  std::vector<double> d2(kk);
  const std::size_t found = impl_->index.knnSearch(x.data(), kk, idx.data(), d2.data());
  std::vector<std::size_t> order(found);
  std::iota(order.begin(), order.end(), std::size_t{0});
  std::sort(order.begin(), order.end(), [&](std::size_t u, std::size_t v) {
    return d2[u] != d2[v] ? d2[u] < d2[v] : idx[u] < idx[v];
  });
  out.reserve(found);
  for (const std::size_t o : order) {
    out.push_back(static_cast<int>(idx[o]));
    if (distances) distances->push_back(std::sqrt(d2[o]));
  }
}

std::vector<double> smooth_spacing(const KdTree& tree, std::vector<double> h, int passes, double radius_factor) {
  const std::size_t n = tree.size();
  if (h.size() != n) {
    throw std::invalid_argument("smooth_spacing: " + std::to_string(h.size()) + " spacings for " + std::to_string(n) +
                                " nodes");
  }
  if (!(radius_factor > 0.0)) throw std::invalid_argument("smooth_spacing: radius_factor must be positive");
  if (passes <= 0 || n < 2) return h;
  // Neighbourhoods by radius, not by count: equidistant nodes (a lattice) are all in or all out,
  // so the smoothing keeps the node set's symmetries.
  std::vector<int> offsets(n + 1, 0), lists;
  std::vector<int> idx;
  const NodeSet& nodes = tree.nodes();
  for (std::size_t a = 0; a < n; ++a) {
    tree.radius_search(nodes.point(a), radius_factor * h[a], idx);
    for (const int b : idx) {
      if (b != static_cast<int>(a)) lists.push_back(b);
    }
    offsets[a + 1] = static_cast<int>(lists.size());
  }
  std::vector<double> next(n);
  for (int pass = 0; pass < passes; ++pass) {
    for (std::size_t a = 0; a < n; ++a) {
      const int count = offsets[a + 1] - offsets[a];
      if (count == 0) {
        next[a] = h[a];
        continue;
      }
      double mean = 0.0;
      for (int k = offsets[a]; k < offsets[a + 1]; ++k) mean += h[static_cast<std::size_t>(lists[static_cast<std::size_t>(k)])];
      next[a] = 0.5 * (h[a] + mean / count);
    }
    h.swap(next);
  }
  return h;
}

std::vector<double> nodal_spacing(const KdTree& tree, int neighbours) {
  const int k = neighbours > 0 ? neighbours : 2 * tree.dim();
  const std::size_t n = tree.size();
  if (n < 2) throw std::invalid_argument("nodal_spacing: need at least 2 nodes, got " + std::to_string(n));
  std::vector<double> h(n);
  std::vector<int> idx;
  std::vector<double> dist;
  const NodeSet& nodes = tree.nodes();
  for (std::size_t a = 0; a < n; ++a) {
    // k + 1 because the node itself is its own nearest neighbour.
    tree.knn(nodes.point(a), k + 1, idx, &dist);
    double sum = 0.0;
    int count = 0;
    for (std::size_t j = 0; j < idx.size() && count < k; ++j) {
      if (idx[j] == static_cast<int>(a)) continue;
      sum += dist[j];
      ++count;
    }
    h[a] = sum / count;
    if (!(h[a] > 0.0)) {
      throw std::invalid_argument("nodal_spacing: node " + std::to_string(a) +
                                  " has zero spacing (coincident nodes)");
    }
  }
  return h;
}

double support_radius(double beta, double tol0) {
  if (!(beta > 0.0) || !(tol0 > 0.0 && tol0 < 1.0)) {
    throw std::invalid_argument("support_radius: need beta > 0 and 0 < tol0 < 1, got beta = " +
                                std::to_string(beta) + ", tol0 = " + std::to_string(tol0));
  }
  return std::sqrt(-std::log(tol0) / beta);
}

namespace {

// The lists of points 0..n-1, list_of(q, list) writing point q's. The index array of many points is
// reserved from a sample of them: grown by doubling it would leave freed copies of up to its whole
// size in the heap (which PETSc's SuperLU_DIST keeps from being returned to the system). A few
// points are not sampled, which would search each of them twice.
template <class ListOf>
CsrLists lists_of_points(std::size_t n, ListOf&& list_of) {
  CsrLists lists;
  lists.offsets.reserve(n + 1);
  std::vector<int> list;
  const std::size_t samples = n >= 4096 ? 256 : 0;
  std::size_t sampled = 0;
  for (std::size_t k = 0; k < samples; ++k) {
    list_of(k * n / samples, list);
    sampled += list.size();
  }
  if (samples > 0) lists.indices.reserve(static_cast<std::size_t>(1.1 * double(sampled) * double(n) / double(samples)) + 64);
  for (std::size_t q = 0; q < n; ++q) {
    list_of(q, list);
    lists.indices.insert(lists.indices.end(), list.begin(), list.end());
    lists.offsets.push_back(static_cast<int>(lists.indices.size()));
  }
  return lists;
}

}  // namespace

RadiusRange radius_range(std::span<const double> radii) {
  if (radii.empty()) return {};
  const auto [smallest, largest] = std::minmax_element(radii.begin(), radii.end());
  return {*smallest, *largest};
}

CsrLists primal_lists(const KdTree& tree, std::span<const double> points, std::span<const double> radii) {
  return primal_lists(tree, points, radii, radius_range(radii));
}

CsrLists primal_lists(const KdTree& tree, std::span<const double> points, std::span<const double> radii, RadiusRange range) {
  const auto d = static_cast<std::size_t>(tree.dim());
  if (points.size() % d != 0) {
    throw std::invalid_argument("primal_lists: " + std::to_string(points.size()) +
                                " coordinates are not a multiple of dimension " + std::to_string(d));
  }
  if (radii.size() != 1 && radii.size() != tree.size()) {
    throw std::invalid_argument("primal_lists: " + std::to_string(radii.size()) + " radii for " +
                                std::to_string(tree.size()) + " nodes (need 1 or one per node)");
  }
  const double rmax = range.largest, rmin = range.smallest;
  const NodeSet& nodes = tree.nodes();
  const std::size_t nq = points.size() / d;
  std::vector<int> cand;
  const auto within_own_support = [&](std::span<const double> x, int b) {
    const auto xb = nodes.point(static_cast<std::size_t>(b));
    double d2 = 0.0;
    for (std::size_t i = 0; i < d; ++i) d2 += (x[i] - xb[i]) * (x[i] - xb[i]);
    const double rb = radii[static_cast<std::size_t>(b)];
    return d2 <= rb * rb;
  };
  // On a graded node set one search with the largest radius gathers, at every fine point, every
  // node within a coarse support (an octree with spacings 1:8 in 3D: thousands of candidates for a
  // list of hundreds). Nodes are searched instead in classes of radii within a factor 1.5, each with
  // its own tree and largest radius. Building those trees costs about one search per node, so a
  // few points (one node's list, a probe) keep the single search.
  constexpr double class_ratio = 1.5;
  if (radii.size() > 1 && rmin > 0 && rmax > class_ratio * rmin && 8 * nq >= tree.size()) {
    struct RadiusClass {
      std::vector<int> members;   // node indices
      std::vector<double> coords;
      double radius = 0;
      std::unique_ptr<KdTree> tree;
    };
    const auto class_count = static_cast<std::size_t>(std::floor(std::log(rmax / rmin) / std::log(class_ratio))) + 1;
    std::vector<RadiusClass> classes(class_count);
    for (std::size_t b = 0; b < radii.size(); ++b) {
      const auto c = std::min(class_count - 1, static_cast<std::size_t>(std::floor(std::log(radii[b] / rmin) / std::log(class_ratio))));
      classes[c].members.push_back(static_cast<int>(b));
      const auto xb = nodes.point(b);
      classes[c].coords.insert(classes[c].coords.end(), xb.begin(), xb.end());
      classes[c].radius = std::max(classes[c].radius, radii[b]);
    }
    std::erase_if(classes, [](const RadiusClass& c) { return c.members.empty(); });
    for (RadiusClass& c : classes) c.tree = std::make_unique<KdTree>(NodeSet(tree.dim(), std::move(c.coords)));
    return lists_of_points(nq, [&](std::size_t q, std::vector<int>& list) {
      const auto x = points.subspan(q * d, d);
      list.clear();
      for (const RadiusClass& c : classes) {
        c.tree->radius_search(x, c.radius, cand);
        for (const int local : cand) {
          const int b = c.members[static_cast<std::size_t>(local)];
          if (within_own_support(x, b)) list.push_back(b);
        }
      }
      std::sort(list.begin(), list.end());
    });
  }
  return lists_of_points(nq, [&](std::size_t q, std::vector<int>& list) {
    const auto x = points.subspan(q * d, d);
    tree.radius_search(x, rmax, cand);
    list.clear();
    if (radii.size() == 1) {
      list.assign(cand.begin(), cand.end());
    } else {
      for (const int b : cand)
        if (within_own_support(x, b)) list.push_back(b);
    }
  });
}

}  // namespace lmeform
