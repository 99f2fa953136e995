// The requirements a model states in its forms (`require CONDITION, "MESSAGE"`): conditions on the
// constants, the coordinate, the unknowns and the local node spacing, checked on the start state
// before any solve, so that a scene that breaks them (a negative toughness, a phase field outside
// [0, 1], a crack band narrower than the nodes can resolve) is refused with the model's own words
// instead of being solved into nonsense. Requirements that read the unknowns are checked again on
// later states (load steps), where a failure is a warning: the state moved where the model's rule
// no longer holds (a crack grown into coarse nodes).
#pragma once

#include <span>
#include <string>
#include <vector>

#include "bound_scene.hpp"
#include "problem_space.hpp"

namespace lmeform::problems {

/// A requirement that fails: the full message and how many nodes break it (1 for constants).
struct RequirementFailure {
  std::string message;
  std::string condition;  ///< as written in the form, identifies the requirement across states
  std::size_t nodes = 0;
  bool advisory = false;  ///< `recommend`: warned of, never refused
};

/// Throws SceneError naming the scene, the module, the condition and message, the constants it
/// reads and, for a pointwise requirement, the first node where it fails (and how many fail); a
/// failed recommendation is written to `log` as a warning.
void check_requirements(const BoundScene& b, const ProblemSpace& space, std::ostream* log);

/// The requirements that read the unknowns, checked on `state` (original node order, the layout's
/// dofs per node): the ones that fail, each with its message; `state_name` says where ("step 12").
[[nodiscard]] std::vector<RequirementFailure> failed_state_requirements(const BoundScene& b, const ProblemSpace& space,
                                                                        std::span<const double> state, const std::string& state_name);

}  // namespace lmeform::problems
