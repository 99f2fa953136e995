// Minimization of a sum of energies under the scene's constraints (the constrained Newton
// minimizer): the stationary driver of scenes that name energies, or no output at all.
#pragma once

#include <map>
#include <optional>
#include <string>
#include <string_view>

#include "problem_registry.hpp"
#include "stationary.hpp"

namespace lmeform::problems {

/// What the constraint multipliers mean physically (e.g. "tension"), by constraint name.
using MultiplierMeanings = std::map<std::string, std::string, std::less<>>;

/// The closing rows and JSON keys of a minimization: energy against the reference, constraints with
/// their multipliers, Newton iterations, and whether the result is a minimum (a warning at a
/// saddle, which ends with `perturbation`: how a start of this model is moved off its symmetry).
void describe_minimization(const std::optional<double>& reference_energy, const ProblemResult& result, RunReport& report,
                           const MultiplierMeanings& meanings = {}, std::string_view perturbation = {});

[[nodiscard]] const StationaryDriver& minimization_driver();

}  // namespace lmeform::problems
