#include "requirements.hpp"

#include <ostream>
#include <set>

#include <fmt/format.h>
#include <fmt/ranges.h>

#include "lmeform/neighbour_search.hpp"
#include "point_values.hpp"

namespace lmeform::problems {

namespace {

enum class Which { All, StateDependent };

/// Every requirement of the forms the problem uses (in `which`), evaluated on `state` (original
/// order); the failing ones.
std::vector<RequirementFailure> failures(const BoundScene& b, const ProblemSpace& space, std::span<const double> original_state,
                                         Which which, const std::string& state_name) {
  std::vector<RequirementFailure> out;
  std::vector<double> state;  // renumbered for the basis
  std::vector<double> node_spacing;
  // A form listed in model.forms whose outputs the problem does not use binds no constants: its
  // requirements are not the problem's.
  std::set<std::string> used;
  for (const BoundOutput* o : b.outputs()) used.insert(o->first().module);
  for (const FormModule* module : b.modules)
    for (const kernel::FormKernels* k : module->kernels) {
      if (!used.contains(module->name)) continue;
      if (k->kind != kernel::FunctionalKind::Point || k->requirement == nullptr || k->dim != b.dim) continue;
      if (which == Which::StateDependent && k->n_unknowns == 0) continue;
      if (!PointEvaluator::can_evaluate(*k, b.layout))
        throw SceneError(fmt::format("{}: the requirement '{}' of form {} reads fields that are not unknowns of this problem", b.source,
                                     k->requirement_condition, module->name));
      const PointEvaluator evaluator(*k, b.layout, space.constants, &b.geometry);
      if (state.empty()) state = renumbered_state(*space.disc, original_state, b.layout.dofs_per_node);
      const NodeSet& nodes = space.nodes;
      const std::size_t count = k->requirement_pointwise ? nodes.size() : 1;
      const auto dim = static_cast<std::size_t>(nodes.dim);
      std::size_t failed = 0, first = 0;
      double holds = 0;
      // The spacing a node set is made with: each node's distance to its nearest other node (what
      // [nodes] spacing and refine set; the basis' h_a, a mean over 2d neighbours, is 10-20 %
      // larger on irregular sets).
      if (k->reads_spacing && node_spacing.empty()) node_spacing = nodal_spacing(KdTree(nodes), 1);
      if (k->requirement_pointwise) {
        for (std::size_t i = 0; i < count; ++i) {
          evaluator.evaluate(space.disc->basis(), std::span<const double>(nodes.coords.data() + i * dim, dim), state, std::span<double>(&holds, 1),
                             k->reads_spacing ? node_spacing[i] : -1.0);
          if (holds < 0.5 && failed++ == 0) first = i;
        }
      } else {
        // A condition on the constants holds or fails anywhere: a quadrature point, where the basis
        // is always defined (a node can be a corner whose neighbours a motion made collinear).
        evaluator.evaluate(space.disc->basis(), space.disc->cells_domain().point(0), state, std::span<double>(&holds, 1));
        if (holds < 0.5) failed = 1;
      }
      if (failed == 0) continue;
      std::vector<std::string> constants;
      for (int c = 0; c < k->n_constants; ++c)
        if (const auto it = space.constants.find(k->constants[c]); it != space.constants.end())
          constants.push_back(fmt::format("{} = {:g}", it->first, it->second));
      std::string where;
      if (k->requirement_pointwise) {
        std::vector<std::string> x;
        for (std::size_t d = 0; d < dim; ++d) x.push_back(fmt::format("{:g}", nodes.coords[first * dim + d]));
        where = fmt::format(" at {}: it fails at node ({}){}", state_name, fmt::join(x, ", "),
                            failed > 1 ? fmt::format(" and {} other nodes", failed - 1) : std::string());
        if (k->reads_spacing) where += fmt::format(" (spacing {:.4g}: the distance to its nearest node)", node_spacing[first]);
      }
      out.push_back({fmt::format("{}: form {} {} {} ({}){}{}", b.source, module->name, k->requirement_advisory ? "recommends" : "requires", k->requirement_condition, k->requirement, where,
                                 constants.empty() ? std::string() : fmt::format("; constants: {}", fmt::join(constants, ", "))),
                     k->requirement_condition, failed, k->requirement_advisory});
    }
  return out;
}

}  // namespace

void check_requirements(const BoundScene& b, const ProblemSpace& space, std::ostream* log) {
  const auto failed = failures(b, space, space.state, Which::All, "the start state");
  for (const RequirementFailure& f : failed)
    if (!f.advisory) throw SceneError(f.message);
  if (log != nullptr)
    for (const RequirementFailure& f : failed) *log << "lmeform: warning: " << f.message << std::endl;
}

std::vector<RequirementFailure> failed_state_requirements(const BoundScene& b, const ProblemSpace& space, std::span<const double> state,
                                                          const std::string& state_name) {
  return failures(b, space, state, Which::StateDependent, state_name);
}

}  // namespace lmeform::problems
