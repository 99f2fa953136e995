// Node sets that follow a field through load steps ([nodes] adapt): where the field falls below a
// threshold (a crack's damage), the spacing becomes the adaptation's within its width. The rule is
// a function of the nodes and the state alone — no history — so a run resumed from a checkpoint
// refines exactly where the uninterrupted one does.
#pragma once

#include <cstddef>
#include <span>
#include <string>
#include <vector>

#include "lmeform/domain.hpp"
#include "lmeform/lme_basis.hpp"
#include "lmeform/node_set.hpp"
#include "lmeform/scene.hpp"
#include "toolkit.hpp"

namespace lmeform::problems {

/// The spacing of generated nodes: nodes.spacing, finer near each refinement's part or path. Its
/// h_min (the sampling lattice) includes the adaptation's spacing, so that nodes generated before
/// and after a refinement coincide wherever the spacing did not change.
[[nodiscard]] SpacingFunction scene_spacing(const Scene& scene);

/// The scene's spacing, and the adaptation's within its width of the marked points.
[[nodiscard]] SpacingFunction adapted_spacing(const Scene& scene, const NodeSet& marked);

/// The nodes where the adapted field lies below the threshold (the field must be a scalar unknown).
[[nodiscard]] NodeSet marked_nodes(const SceneAdaptation& adapt, const StateLayout& layout, const NodeSet& nodes,
                                   std::span<const double> state);

/// Nodes within the adaptation's width of a marked point that are too coarse for it: their nearest
/// other node farther than `kCoarseRatio` times the adapted spacing there. A Poisson-disk sample at
/// spacing h keeps its nearest distances within 1.13–1.26 h (measured on the fracture demos): a
/// refinement keeps the old nodes within `kKeptRatio` of the new spacing, and is asked for only
/// beyond `kCoarseRatio`, so that the sample's own scatter never asks for one.
inline constexpr double kKeptRatio = 1.3;
inline constexpr double kCoarseRatio = 1.4;
/// On nested grids ([nodes] sampling = "grids") the refinement is exact instead: `count` is the
/// number of vertices the grids for the adapted spacing have and the nodes lack.
struct CoarseNodes {
  std::size_t count = 0;
  double coarsest = 0;  ///< the largest nearest distance among them (Poisson-disk sampling)
};
[[nodiscard]] CoarseNodes coarse_nodes(const Scene& scene, const NodeSet& nodes, const NodeSet& marked);

/// What `coarse_nodes` found, for the log: "v < 0.8 within 0.09 of 12 nodes coarser than 1.4 x
/// 0.027 (up to 0.05)", or on nested grids "v < 0.8: the grids refined to 0.027 within 0.09 of it
/// add 120 nodes".
[[nodiscard]] std::string describe(const Scene& scene, const CoarseNodes& coarse);

/// The nodes of a refinement: the old nodes where they are fine enough for the adapted spacing
/// (nearest other node within kKeptRatio times it), the boundary and the gaps sampled anew. On
/// nested grids, the grids of the adapted spacing, which hold the old ones where the marked points
/// only grew (an irreversible crack).
[[nodiscard]] NodeSet refined_nodes(const Scene& scene, const NodeSet& nodes, const NodeSet& marked);

/// The nested grids of the scene's box for a spacing, level 0 at nodes.spacing for every spacing
/// (so that a finer spacing's grids contain a coarser one's).
[[nodiscard]] NodeSet scene_grids(const Scene& scene, const SpacingFunction& spacing);

/// A state (dofs interleaved, `dofs_per_node` per node) carried to other nodes: a node at the place
/// of an old one keeps its coefficients (counted in `kept_nodes`); the others get the old field's
/// values there, then coefficients fitted to them (`fit_iterations` Richardson iterations: LME is
/// not interpolating), each within the least and largest old coefficient weighting its node.
[[nodiscard]] std::vector<double> transfer_state(const NodeSet& from, std::span<const double> state, int dofs_per_node, double gamma,
                                                 const LmeOptions& lme, const NodeSet& to, int fit_iterations,
                                                 std::size_t* kept_nodes = nullptr);

}  // namespace lmeform::problems
