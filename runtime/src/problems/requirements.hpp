// The requirements a model states in its forms (`require CONDITION, "MESSAGE"`): conditions on the
// constants, the coordinate and the unknowns, checked on the start state before any solve, so that
// a scene that breaks them (a negative toughness, a phase field outside [0, 1]) is refused with the
// model's own words instead of being solved into nonsense.
#pragma once

#include "bound_scene.hpp"
#include "problem_space.hpp"

namespace lmeform::problems {

/// Throws SceneError naming the scene, the module, the condition and message, the constants it
/// reads and, for a pointwise requirement, the first node where it fails (and how many fail).
void check_requirements(const BoundScene& b, const ProblemSpace& space);

}  // namespace lmeform::problems
