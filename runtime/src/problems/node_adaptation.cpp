#include "node_adaptation.hpp"

#include <algorithm>
#include <cmath>
#include <memory>

#include <fmt/format.h>

#include "field_transfer.hpp"
#include "lmeform/neighbour_search.hpp"

namespace lmeform::problems {

SpacingFunction scene_spacing(const Scene& scene) {
  const double h0 = scene.nodes.spacing;
  double h_min = h0;
  for (const auto& r : scene.nodes.refine) h_min = std::min(h_min, r.spacing);
  if (scene.nodes.adapt) h_min = std::min(h_min, scene.nodes.adapt->spacing);
  const Domain& geometry = scene.geometry;
  const int dim = scene.dim();
  const std::vector<SceneRefinement> refine = scene.nodes.refine;
  return {[h0, refine, &geometry, dim](std::span<const double> x) {
            double h = h0;
            for (const auto& r : refine) {
              const double d = r.part.empty() ? distance_to_polyline(x, r.path, dim) : geometry.distance_to_part(x, r.part);
              h = std::min(h, r.spacing + r.grading * std::max(0.0, d - r.width));
            }
            return h;
          },
          h_min};
}

namespace {

/// The distance from x to the nearest marked point (infinite without marks).
class MarkedDistance {
 public:
  explicit MarkedDistance(const NodeSet& marked) {
    if (marked.size() > 0) tree_ = std::make_shared<KdTree>(marked);
  }
  double operator()(std::span<const double> x) const {
    if (!tree_) return INFINITY;
    std::vector<int> nearest;
    std::vector<double> distance;
    tree_->knn(x, 1, nearest, &distance);
    return distance.front();
  }

 private:
  std::shared_ptr<const KdTree> tree_;  // shared: a SpacingFunction is copied
};

}  // namespace

SpacingFunction adapted_spacing(const Scene& scene, const NodeSet& marked) {
  SpacingFunction h = scene_spacing(scene);
  if (!scene.nodes.adapt || marked.size() == 0) return h;
  const SceneAdaptation a = *scene.nodes.adapt;
  h.h = [base = h.h, a, distance = MarkedDistance(marked)](std::span<const double> x) {
    return std::min(base(x), a.spacing + a.grading * std::max(0.0, distance(x) - a.width));
  };
  return h;
}

NodeSet marked_nodes(const SceneAdaptation& adapt, const StateLayout& layout, const NodeSet& nodes, std::span<const double> state) {
  const UnknownField& f = layout.field(adapt.field);
  NodeSet marked(nodes.dim, {});
  for (std::size_t a = 0; a < nodes.size(); ++a)
    if (state[a * std::size_t(layout.dofs_per_node) + std::size_t(f.offset)] < adapt.below) {
      const auto x = nodes.point(a);
      marked.coords.insert(marked.coords.end(), x.begin(), x.end());
    }
  return marked;
}

namespace {

bool on_nested_grids(const Scene& scene) { return scene.nodes.sampling == SceneNodes::Sampling::nested_grids; }

/// The points of `candidates` that no node of `nodes` sits on (to a relative 1e-12).
std::size_t points_missing(const NodeSet& candidates, const NodeSet& nodes) {
  double scale = 1;
  for (const double c : nodes.coords) scale = std::max(scale, std::abs(c));
  const KdTree tree(nodes);
  std::vector<int> nearest;
  std::vector<double> d;
  std::size_t missing = 0;
  for (std::size_t a = 0; a < candidates.size(); ++a) {
    tree.knn(candidates.point(a), 1, nearest, &d);
    if (d.front() > 1e-12 * scale) ++missing;
  }
  return missing;
}

}  // namespace

NodeSet scene_grids(const Scene& scene, const SpacingFunction& spacing) {
  return nested_grids(scene.domain, spacing, 2'000'000, scene.nodes.spacing);
}

CoarseNodes coarse_nodes(const Scene& scene, const NodeSet& nodes, const NodeSet& marked) {
  CoarseNodes out;
  if (!scene.nodes.adapt || marked.size() == 0) return out;
  const SpacingFunction h = adapted_spacing(scene, marked);
  if (on_nested_grids(scene)) {
    out.count = points_missing(scene_grids(scene, h), nodes);
    return out;
  }
  const MarkedDistance distance(marked);
  const KdTree tree(nodes);
  std::vector<int> nearest;
  std::vector<double> d;
  for (std::size_t a = 0; a < nodes.size(); ++a) {
    const auto x = nodes.point(a);
    if (distance(x) > scene.nodes.adapt->width) continue;
    tree.knn(x, 2, nearest, &d);
    const double spacing = d.back();
    if (spacing > kCoarseRatio * h.h(x)) {
      ++out.count;
      out.coarsest = std::max(out.coarsest, spacing);
    }
  }
  return out;
}

std::string describe(const Scene& scene, const CoarseNodes& coarse) {
  const SceneAdaptation& a = *scene.nodes.adapt;
  if (on_nested_grids(scene))
    return fmt::format("{} < {:.3g}: the grids refined to {:.3g} within {:.3g} of it add {} nodes", a.field, a.below, a.spacing, a.width, coarse.count);
  return fmt::format("{} < {:.3g} within {:.3g} of {} nodes coarser than {} x {:.3g} (up to {:.3g})", a.field, a.below, a.width, coarse.count,
                     kCoarseRatio, a.spacing, coarse.coarsest);
}

NodeSet refined_nodes(const Scene& scene, const NodeSet& nodes, const NodeSet& marked) {
  const SpacingFunction h = adapted_spacing(scene, marked);
  if (on_nested_grids(scene)) return scene_grids(scene, h);
  const KdTree tree(nodes);
  std::vector<int> nearest;
  std::vector<double> d;
  std::vector<double> kept;
  for (std::size_t a = 0; a < nodes.size(); ++a) {
    const auto x = nodes.point(a);
    tree.knn(x, 2, nearest, &d);
    if (d.back() <= kKeptRatio * h.h(x)) kept.insert(kept.end(), x.begin(), x.end());
  }
  return domain_nodes(scene.geometry, h, 1, 2'000'000, kept);
}

std::vector<double> transfer_state(const NodeSet& from, std::span<const double> state, int dofs_per_node, double gamma,
                                   const LmeOptions& lme, const NodeSet& to, int fit_iterations, std::size_t* kept_nodes) {
  const auto bs = std::size_t(dofs_per_node);
  // A node generated again at the same place keeps its coefficients: where a support holds only
  // such nodes the carried field is the old one exactly.
  const KdTree tree(from);
  std::vector<long> kept(to.size(), -1);
  std::vector<int> nearest;
  std::vector<double> d;
  double scale = 0;
  for (const double c : from.coords) scale = std::max(scale, std::abs(c));
  std::size_t count = 0;
  for (std::size_t a = 0; a < to.size(); ++a) {
    tree.knn(to.point(a), 1, nearest, &d);
    if (d.front() <= 1e-12 * std::max(scale, 1.0)) kept[a] = nearest.front(), ++count;
  }
  if (kept_nodes != nullptr) *kept_nodes = count;
  std::vector<double> out(to.size() * bs);
  std::vector<double> component(from.size()), held(to.size());
  for (std::size_t c = 0; c < bs; ++c) {
    for (std::size_t a = 0; a < from.size(); ++a) component[a] = state[a * bs + c];
    for (std::size_t a = 0; a < to.size(); ++a) held[a] = kept[a] >= 0 ? component[std::size_t(kept[a])] : std::nan("");
    std::vector<std::array<double, 2>> range;
    const std::vector<double> values = interpolate_nodal_field(from, component, gamma, lme, to, nullptr, &range);
    const std::vector<double> fitted = fit_nodal_values(to, values, gamma, lme, fit_iterations, held);
    // Fitting sharpens, and overshoots next to a jump (v = 1.0000002 beside a crack): a new
    // coefficient stays within the old ones that weight its node, so that a field in [0, 1] stays.
    for (std::size_t a = 0; a < to.size(); ++a) out[a * bs + c] = kept[a] >= 0 ? fitted[a] : std::clamp(fitted[a], range[a][0], range[a][1]);
  }
  return out;
}

}  // namespace lmeform::problems
