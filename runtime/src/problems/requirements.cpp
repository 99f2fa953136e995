#include "requirements.hpp"

#include <set>

#include <fmt/format.h>
#include <fmt/ranges.h>

#include "point_values.hpp"

namespace lmeform::problems {

void check_requirements(const BoundScene& b, const ProblemSpace& space) {
  std::vector<double> state;  // the start, renumbered for the basis
  // A form listed in model.forms whose outputs the problem does not use binds no constants: its
  // requirements are not the problem's.
  std::set<std::string> used;
  for (const BoundOutput* o : b.outputs()) used.insert(o->first().module);
  for (const FormModule* module : b.modules)
    for (const kernel::FormKernels* k : module->kernels) {
      if (!used.contains(module->name)) continue;
      if (k->kind != kernel::FunctionalKind::Point || k->requirement == nullptr || k->dim != b.dim) continue;
      if (!PointEvaluator::can_evaluate(*k, b.layout))
        throw SceneError(fmt::format("{}: the requirement '{}' of form {} reads fields that are not unknowns of this problem", b.source,
                                     k->requirement_condition, module->name));
      const PointEvaluator evaluator(*k, b.layout, space.constants, &b.geometry);
      if (state.empty()) state = renumbered_state(*space.disc, space.state, b.layout.dofs_per_node);
      const NodeSet& nodes = space.nodes;
      const std::size_t count = k->requirement_pointwise ? nodes.size() : 1;
      const auto dim = static_cast<std::size_t>(nodes.dim);
      std::size_t failures = 0, first = 0;
      double holds = 0;
      if (k->requirement_pointwise) {
        for (std::size_t i = 0; i < count; ++i) {
          evaluator.evaluate(space.disc->basis(), std::span<const double>(nodes.coords.data() + i * dim, dim), state, std::span<double>(&holds, 1));
          if (holds < 0.5 && failures++ == 0) first = i;
        }
      } else {
        // A condition on the constants holds or fails anywhere: a quadrature point, where the basis
        // is always defined (a node can be a corner whose neighbours a motion made collinear).
        evaluator.evaluate(space.disc->basis(), space.disc->cells_domain().point(0), state, std::span<double>(&holds, 1));
        if (holds < 0.5) failures = 1;
      }
      if (failures == 0) continue;
      std::vector<std::string> constants;
      for (int c = 0; c < k->n_constants; ++c)
        if (const auto it = space.constants.find(k->constants[c]); it != space.constants.end())
          constants.push_back(fmt::format("{} = {:g}", it->first, it->second));
      std::string where;
      if (k->requirement_pointwise) {
        std::vector<std::string> x;
        for (std::size_t d = 0; d < dim; ++d) x.push_back(fmt::format("{:g}", nodes.coords[first * dim + d]));
        where = fmt::format(" at the start state: it fails at node ({}){}", fmt::join(x, ", "),
                            failures > 1 ? fmt::format(" and {} other nodes", failures - 1) : std::string());
      }
      throw SceneError(fmt::format("{}: form {} requires {} ({}){}{}", b.source, module->name, k->requirement_condition, k->requirement,
                                   where, constants.empty() ? std::string() : fmt::format("; constants: {}", fmt::join(constants, ", "))));
    }
}

}  // namespace lmeform::problems
