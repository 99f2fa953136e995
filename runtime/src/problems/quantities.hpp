// Quantities of interest of a solved state ([quantities]): reactions on Dirichlet parts, probes of a
// field at a point, integrals of expressions over the domain or a boundary part, and constants.
// Each becomes one or more named columns (a reaction and a vector probe: one per component,
// NAME[0], NAME[1], ...), in the closing table, the JSON and a load-stepped run's history.
#pragma once

#include <string>
#include <utility>
#include <vector>

#include "bound_scene.hpp"
#include "problem_space.hpp"
#include "report.hpp"

namespace lmeform::problems {

struct ProblemResult;

/// A named value.
using QuantityValues = std::vector<std::pair<std::string, double>>;

/// The quantities at the solved state u. Collective over the space's communicator.
[[nodiscard]] QuantityValues evaluate_quantities(const BoundScene& bound, ProblemSpace& space, Vec u, const ProblemResult& result);

/// The closing rows and JSON object "quantities" of some values.
void describe_quantities(const QuantityValues& values, RunReport& report);

}  // namespace lmeform::problems
