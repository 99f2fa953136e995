// Updated-Lagrangian flow: a scene with a [flow] table solves its stationary problem (a Stokes or
// viscoplastic flow, any [model] that the stationary drivers solve) on the current nodes, moves
// every node with the computed velocity, rebuilds the basis, the background cells and the
// quadrature on the moved nodes, and solves again: the meshfree flow formulation of forming
// processes (no mesh to distort, no remeshing). Boundary parts follow their nodes; rigid plates
// move with their prescribed velocity and capture the nodes that reach them (a free surface
// folding onto a plate joins the plate's part, and its Dirichlet entries).
//
//   [flow]
//   velocity = "v"               # the vector unknown the nodes move with
//   time_step = 0.005
//   count = 100                  # steps; step k is at time k * time_step
//   plates = [{ part = "top", axis = 1, side = "upper" }]
//   continuation = { m = 1.0 }   # a failed solve is retried from m = 1 to the scene's m
//
// Node motion is the midpoint rule on the node positions (integrator = "midpoint", the default):
// x* = x + dt/2 v_h(x), a solve on x*, then x += dt v_h*(x*); "euler" is x += dt v_h(x), one solve
// a step but a volume error of O(dt) over a run (3/4 (V dt/h)^2 a step in the homogeneous
// compression of a billet of height h, against O(dt^2) for the midpoint rule). A step is cut
// into sub-steps (each with its own solve) when a node would move more than max_motion times its
// nodal spacing. A step that cannot be solved is not applied: the run stops with the last
// converged step on disk, and `lmeform run --restart` continues from it.
#pragma once

#include <string>
#include <string_view>
#include <vector>

#include "lmeform/scene.hpp"
#include "problem_registry.hpp"

namespace lmeform::problems {

inline constexpr std::string_view kFlowTable = "flow";

/// A rigid plate: the plane normal to `axis` through its part's nodes, moving with their
/// prescribed velocity; the material lies below it (side = +1, "upper") or above it (side = -1).
struct FlowPlate {
  std::string part;
  int axis = 0;
  int side = 1;
  std::string where;
};

struct FlowSettings {
  std::string velocity;
  double time_step = 0;
  int count = 1;
  int until = 0;                 ///< the last step of this run (count: all)
  int checkpoint_every = 1;
  double max_motion = 0.5;       ///< largest node displacement per sub-step, in nodal spacings
  int max_substeps = 64;         ///< of one step, before the run stops
  double contact_tolerance = 0.05;  ///< a node within this many nodal spacings of a plate touches it
  /// Background cells flatter than this (area / longest edge²) are dropped. A free surface does not
  /// stay straight to round-off: its nodes move with velocities from a solve whose conditioning
  /// amplifies round-off to about 1e-7 of a spacing, and a gently curved one (a barrel) has hull
  /// cells of area / edge² about h / (8 R_curvature). Both put quadrature points within a
  /// thousandth of a spacing of the hull, where the LME Jacobian is near-singular and the basis
  /// gradients huge: measured, Newton fails at 6 % height reduction of a sticking upsetting with
  /// 1e-6 or 1e-3, at 25 % with 1e-2. Cells inside a moved node set are not that flat (a grid
  /// compressed 4:1 has 0.12); a dropped hull cell loses its flatness times its edge² of area.
  double sliver_tolerance = 1e-2;
  /// When a step leaves the nodes more anisotropic than this (NodeQuality::anisotropy: the principal
  /// spreads of a node's nearest neighbours), the interior nodes are replaced by a regular grid of
  /// the initial spacing inside the hull, the surface nodes kept with their parts, and the state
  /// carried by evaluating the old field (the flow has no history: it is the next solve's start).
  /// 0: never.
  double redistribute_anisotropy = 3.0;
  bool midpoint = true;          ///< the midpoint rule for the node motion (two solves a step), else forward Euler
  std::vector<FlowPlate> plates;
  /// A solve that fails is retried by continuation: these constants start from the given values
  /// (where the problem is easy: a Newtonian m = 1) and reach the scene's in `continuation_stages`
  /// solves, each from the last.
  std::vector<std::pair<std::string, double>> continuation;
  int continuation_stages = 4;
  std::string where;
};

/// Reads [flow]; throws SceneError naming the key.
[[nodiscard]] FlowSettings read_flow(const Scene& scene);

/// The driver of scenes with a [flow] table.
[[nodiscard]] const ProblemDriver& flow_steps_driver();

}  // namespace lmeform::problems
