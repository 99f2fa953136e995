#include "problem_registry.hpp"

#include <array>
#include <stdexcept>

#include <fmt/format.h>

#include "dynamics.hpp"
#include "flow_steps.hpp"
#include "load_steps.hpp"
#include "minimization.hpp"
#include "saddle_point.hpp"
#include "vesicle.hpp"

namespace lmeform::problems {

// Defined in their drivers' files.
const StationaryDriver& residual_driver();
const StationaryDriver& linear_driver();
const StationaryDriver& staggered_driver();

namespace {

/// Drivers of a table first (they build on a stationary solve), then the stationary drivers, the
/// minimization last (it claims every scene that names no residual or linear problem).
const std::array<const ProblemDriver*, 9>& all_drivers() {
  static const std::array<const ProblemDriver*, 9> drivers{&dynamics_driver(), &vesicle_driver(),       &flow_steps_driver(), &load_steps_driver(),
                                                           &staggered_driver(), &residual_driver(),     &linear_driver(),
                                                           &saddle_point_driver(), &minimization_driver()};
  return drivers;
}

/// The solves of the [model] outputs themselves.
const std::array<const StationaryDriver*, 4>& basic_stationary_drivers() {
  static const std::array<const StationaryDriver*, 4> drivers{&residual_driver(), &linear_driver(), &saddle_point_driver(),
                                                              &minimization_driver()};
  return drivers;
}

}  // namespace

std::span<const ProblemDriver* const> problem_drivers() { return all_drivers(); }

const ProblemDriver& driver_for(const Scene& scene) {
  for (const ProblemDriver* d : all_drivers())
    if (d->claims(scene)) {
      if (scene.nodes.adapt && d != &load_steps_driver())
        throw SceneError(fmt::format("{}: key 'nodes.adapt': nodes follow a field through load steps ([steps]); this scene is solved by the {} "
                                     "driver", scene.nodes.adapt->where, d->name()));
      return *d;
    }
  throw std::logic_error("no problem driver claims the scene " + scene.source);
}

const StationaryDriver& basic_stationary_driver_for(const Scene& scene) {
  for (const StationaryDriver* d : basic_stationary_drivers())
    if (d->claims(scene)) return *d;
  throw std::logic_error("no stationary driver claims the scene " + scene.source);
}

const StationaryDriver& stationary_driver_for(const Scene& scene) {
  if (staggered_driver().claims(scene)) return staggered_driver();
  return basic_stationary_driver_for(scene);
}

std::span<const std::string_view> driver_tables() {
  static const std::vector<std::string_view> tables = [] {
    std::vector<std::string_view> out;
    for (const ProblemDriver* d : all_drivers())
      if (!d->table().empty()) out.push_back(d->table());
    return out;
  }();
  return tables;
}

void check_scene(MPI_Comm comm, const Scene& scene, std::ostream* log) {
  DriverContext ctx;
  ctx.comm = comm;
  ctx.scene = &scene;
  ctx.log = log;
  driver_for(scene).check(ctx);
}

}  // namespace lmeform::problems
