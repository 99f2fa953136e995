// Load steps for any stationary problem (minimization, residual, linear): a scene with a [steps]
// table ramps constants — a load factor, an imposed displacement, a plate position — over N steps.
// Each step sets the constants (Dirichlet values that are expressions of them follow), starts
// from the last converged state, solves with the scene's stationary solver, records the scene's
// [quantities] in <output>/history.csv and history.json, writes the state as one entry of an XDMF
// series and a checkpoint. A step that does not converge is retried with its increment halved, up
// to `max_cuts` times; if the smallest increment fails, the run stops with the last converged
// state on disk, and `lmeform run --restart` continues from it. With `fallback` constants (a
// regularized model: a smoothed kink, a larger residual stiffness) such a step is first solved
// with them and then solved again with the scene's constants from that solution: the regularized
// model is a path to the scene's solution. If the second solve fails too, the step keeps the
// regularized solution, the run says so (history column `fallback` = 2, a warning) and goes on.
//
//   [steps]
//   count = 20
//   ramp = { delta = [0.0, 0.01] }        # linear in the step: delta_k = 0 + 0.01 k / count
//   values = { load = [0.0, 0.2, ...] }   # or one value per step, step 0 first (count + 1 values)
//   fallback = { split_width = 0.01 }     # constants for a step that fails with every cut
#pragma once

#include <mpi.h>

#include <filesystem>
#include <iosfwd>
#include <map>
#include <string>
#include <utility>
#include <vector>

#include "lmeform/scene.hpp"
#include "problem_registry.hpp"
#include "step_history.hpp"

namespace lmeform::problems {

inline constexpr std::string_view kStepsTable = "steps";

/// A constant's value at each step (count + 1 values, step 0 first).
struct SteppedConstant {
  std::string name;
  std::vector<double> values;
  std::string where;
  /// The value at a fractional step λ ∈ [0, count]: linear between the steps.
  [[nodiscard]] double at(double lambda) const;
};

struct LoadStepSettings {
  int count = 1;
  std::vector<SteppedConstant> constants;
  double cut = 0.5;             ///< a failed increment is multiplied by this for the retry
  int max_cuts = 4;             ///< retries of one step before the run stops
  bool solve_start = true;      ///< solve at step 0 too (else step 0 is the initial state)
  int checkpoint_every = 1;     ///< steps between checkpoints (0: none)
  int until = 0;                ///< the last step of this run (count: all; fewer: continue later with --restart)
  /// Constants of a regularized model for a step that fails with every cut (empty: none).
  std::vector<std::pair<std::string, double>> fallback;
  std::vector<std::string> fallback_where;  ///< where each fallback constant is, for messages
};

/// How a step was solved, in the history's `fallback` column (runs with fallback constants).
enum class FallbackUse { none = 0, resolved = 1, kept = 2 };

/// Reads [steps]; throws SceneError naming the key.
[[nodiscard]] LoadStepSettings read_steps(const Scene& scene);

struct LoadStepRun {
  std::vector<StepRow> history;     ///< position: the load λ ∈ [0, count]; counts: iterations, cuts
  std::string failure;          ///< empty when every step converged
  std::vector<std::string> warnings;  ///< a state requirement that stopped holding at a step
  int refinements = 0;          ///< new node sets ([nodes] adapt), each followed by a step solved again
  /// Steps that kept the fallback constants' solution, with why the scene's constants failed (a
  /// step solved again on refined nodes forgets what its earlier solves did).
  std::map<int, std::string> fallback_kept;
  double wall_s = 0;
};

/// The driver of scenes with a [steps] table.
[[nodiscard]] const ProblemDriver& load_steps_driver();

}  // namespace lmeform::problems
