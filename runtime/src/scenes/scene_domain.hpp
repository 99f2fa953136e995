// The scene reader's [domain] and [nodes] refine entries (scene_domain.cpp).
#pragma once

#include <vector>

#include "lmeform/scene.hpp"
#include "lmeform/scene_table.hpp"

namespace lmeform::scene_detail {

/// [domain]: a box (lower, upper), a convex `polygon` with `parts`, or a convex `polyhedron`
/// { vertices, faces, parts }; sets Scene::domain (the box or the bounding box) and Scene::geometry.
void read_domain(const SceneTable& root, Scene& s);

/// [quantities] (after [domain] and [[dirichlet]]): NAME = { reaction = PART, unknown }, { probe =
/// POINT, field, component }, { integral = EXPR, part }, { constant = NAME }.
void read_quantities(const SceneTable& root, Scene& s);

/// [bounds]: UNKNOWN = { lower = ..., upper = ... } (numbers, expressions or "previous").
void read_bounds(const SceneTable& root, Scene& s);

/// The `refine` entries of [nodes] (after [domain]).
[[nodiscard]] std::vector<SceneRefinement> read_refinements(const SceneTable& nodes, const Scene& s);

/// The `adapt` table of [nodes] (present).
[[nodiscard]] SceneAdaptation read_adaptation(const SceneTable& nodes);

}  // namespace lmeform::scene_detail
