// Problem drivers behind one interface, and the registry that picks the one that runs a scene.
//
// A driver is one kind of run: a single stationary solve (minimization, residual, linear), a
// schedule of solves (the phase-field vesicle's adaptivity), a time integration (dynamics), load
// steps, ... Each lives in its own file, reads its own scene table, says which roles the forms'
// outputs play, and returns a RunReport that `lmeform run` prints and writes without knowing the
// driver. The registry asks the drivers in order; the first that claims the scene runs it. A new
// driver is a file, one line in the registry's list, its scene table and its docs.
//
// The stationary drivers also solve a problem space once for the drivers built on them (a stage,
// a load step): which one does is decided by the outputs the scene's [model] names.
#pragma once

#include <mpi.h>

#include <filesystem>
#include <iosfwd>
#include <span>
#include <string_view>
#include <vector>

#include "bound_scene.hpp"
#include "report.hpp"
#include "lmeform/scene.hpp"

namespace lmeform::problems {

struct ProblemSpace;
struct ProblemInput;
struct ProblemResult;

/// What a driver runs with.
struct DriverContext {
  MPI_Comm comm = MPI_COMM_WORLD;
  const Scene* scene = nullptr;
  std::ostream* log = nullptr;               ///< progress lines (rank 0); nullptr: silent
  std::filesystem::path output_directory;    ///< where a driver writes series and checkpoints ("": nowhere)
  bool restart = false;                      ///< resume from the checkpoint in output_directory
};

class ProblemDriver {
 public:
  virtual ~ProblemDriver() = default;
  /// The problem it solves, as reports and messages name it ("minimization", "dynamics", ...).
  [[nodiscard]] virtual std::string_view name() const = 0;
  /// The scene table the driver reads ("": none): the scene reader keeps it for the driver.
  [[nodiscard]] virtual std::string_view table() const { return {}; }
  [[nodiscard]] virtual bool claims(const Scene& scene) const = 0;
  /// Whether `lmeform run --restart` can resume it from a checkpoint.
  [[nodiscard]] virtual bool restartable() const { return false; }
  /// Binds the scene and checks everything that can be checked before a solve (names, values,
  /// sizes against the domain), without solving. Throws SceneError naming file and key.
  virtual void check(const DriverContext& ctx) const = 0;
  /// Runs the scene (collective over ctx.comm). Throws SceneError / FormLoadError for a scene that
  /// cannot run; a run that stops early says so in its report.
  [[nodiscard]] virtual RunReport run(const DriverContext& ctx) const = 0;
};

/// A driver whose problem is one solve of a problem space: the building block of the others.
class StationaryDriver : public ProblemDriver {
 public:
  /// The outputs of the scene's [model] this driver solves with.
  [[nodiscard]] virtual OutputRoles roles(const Scene& scene) const = 0;
  /// Solves the space once from u (the start, Dirichlet values imposed), leaving the solution in
  /// u and filling the solver's part of `result` (converged, message, iterations, ...).
  virtual void solve(MPI_Comm comm, const BoundScene& bound, ProblemSpace& space, const ProblemInput& input, Vec u,
                     ProblemResult& result) const = 0;
  /// The residual of the problem at u, Dirichlet rows included: at a fixed dof, the force the
  /// support exerts there (a reaction). Minimization: ∇E − Σ σ_i ∇C_i; residual: R(u); linear:
  /// A u − b, all before boundary conditions are applied.
  virtual void residual(const BoundScene& bound, ProblemSpace& space, Vec u, const ProblemResult& result, Vec out) const = 0;
  /// The solver's rows of the closing table and its keys of the JSON document for a result.
  virtual void describe(const BoundScene& bound, const ProblemResult& result, RunReport& report) const = 0;

  /// One solve on the scene's nodes.
  void check(const DriverContext& ctx) const override;
  [[nodiscard]] RunReport run(const DriverContext& ctx) const override;
};

/// Every driver, in the order they are asked to claim a scene.
[[nodiscard]] std::span<const ProblemDriver* const> problem_drivers();
/// The driver that runs the scene.
[[nodiscard]] const ProblemDriver& driver_for(const Scene& scene);
/// The stationary driver of the scene's [model] outputs.
[[nodiscard]] const StationaryDriver& stationary_driver_for(const Scene& scene);
/// The scene tables the drivers read (pass to load_scene).
[[nodiscard]] std::span<const std::string_view> driver_tables();

/// Binds and checks a scene with the driver that claims it, without solving (lmeform run --check).
void check_scene(MPI_Comm comm, const Scene& scene, std::ostream* log);

}  // namespace lmeform::problems
