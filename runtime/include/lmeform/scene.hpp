// Scenes: the TOML files that describe a run of any model (docs/scenes.md lists every key).
//
// A scene names its forms (built-in modules or .form files), which outputs make the problem (a sum
// of energies with constraints, a residual, or a bilinear + linear pair), every constant by its
// name in the forms, constraint targets, Dirichlet conditions on named parts of the boundary,
// initial fields, runtime-supplied quadrature data, the node set and the coordinates. Reading is
// strict: a key that is missing, unknown (with a did-you-mean) or of the wrong type, and every
// number out of range, throws SceneError "FILE:LINE: <what is wrong with which key>". Names that
// refer to the forms (constants, outputs, unknowns, quadrature data) are checked when the forms are
// loaded (app::bind_scene), with the same kind of message.
//
// Model-specific conveniences live with their model, not here: a scene may carry extension tables
// (e.g. [vesicle]) that this reader keeps, unread, for the model that owns them (scene_table.hpp).
#pragma once

#include <array>
#include <filesystem>
#include <map>
#include <memory>
#include <optional>
#include <span>
#include <stdexcept>
#include <string>
#include <string_view>
#include <variant>
#include <vector>

#include "lmeform/node_sets.hpp"

namespace lmeform {

/// Every problem with a scene: the message names the file, the key path and, where known, the line.
class SceneError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

enum class Coordinates { cartesian, axisymmetric };

[[nodiscard]] const char* to_string(Coordinates c) noexcept;

/// [nodes]: exactly one of spacing / counts / count / file.
struct SceneNodes {
  enum class Kind { spacing, counts, count, file };
  Kind kind = Kind::spacing;
  double spacing = 0;                  ///< Kind::spacing: target spacing (uniform_grid(box, spacing))
  std::array<int, 3> counts{};         ///< Kind::counts: nodes per axis, both ends included
  int count = 0;                       ///< Kind::count: a uniform CVT of exactly this many nodes (uniform_cvt, 2D)
  int lloyd_iterations = 100;          ///< Kind::count: Lloyd iterations of that CVT
  std::filesystem::path file;          ///< Kind::file: read_points() file, or a run's HDF5 output (its nodes); resolved against the scene's folder
  double gamma = 0.8;                  ///< LME locality gamma (seed: 0.8)
  int spacing_smoothing = 5;           ///< smoothing passes on the nodal spacing h_a (smooth_spacing)
  int quadrature_points = 6;           ///< points of the simplex rule per background cell
};

/// A name as written in the scene, with where it was written (for messages about it).
struct SceneName {
  std::string name;
  std::string where;                   ///< "FILE:LINE: key 'model.energy[1]'"
};

/// [model]: the forms and the outputs that make the problem. At most one kind of output is named
/// (the reader refuses a residual beside an energy, say); the problem drivers claim a scene by them.
struct SceneModel {
  /// Built-in module names, or paths of .form files (resolved against the scene's folder).
  std::vector<SceneName> forms;
  /// Energy outputs summed; empty (and no residual or bilinear form named) means every energy
  /// output of the forms.
  std::vector<SceneName> energy;
  std::optional<SceneName> residual;
  std::optional<SceneName> bilinear, linear;
  /// Unknowns determined by the equations only up to a constant (the pressure of enclosed Stokes
  /// flow): the solve adds the condition ∫ u dx = 0 for each (linear problems only).
  std::vector<SceneName> zero_mean;
};

/// A value given as a number or as an expression of the coordinates `x` and the scene's constants
/// (compiled by lmeformc at run time, e.g. "sin(pi*x[0]) * e(0)").
struct SceneValue {
  std::variant<double, std::string> value;
  std::string where;
  [[nodiscard]] bool is_number() const noexcept { return value.index() == 0; }
  [[nodiscard]] double number() const { return std::get<double>(value); }
  [[nodiscard]] const std::string& expression() const { return std::get<std::string>(value); }
};

/// [constraints.NAME]: the target of the form's `constraint NAME` (the constant it compares with).
struct SceneConstraint {
  std::string name;
  std::string where;
  std::optional<double> target;        ///< unset: the form's target constant, as given in [constants]
  std::optional<double> scale;         ///< |C − c| / scale is the relative residual; unset: |target| or 1
  bool initial = false;                ///< "initial": the target is the constraint's value at the start state
};

/// [[dirichlet]]: prescribed nodal values of chosen components of an unknown on parts of the boundary.
struct SceneDirichlet {
  /// Box sides ("x_min", "x_max", "y_min", ..., axisymmetric "r_max", "z_min", "z_max"), "hull" (every
  /// node of the convex hull), "axis" (r = 0 of an axisymmetric scene).
  std::vector<std::string> boundary;
  std::string unknown;
  std::vector<int> components;         ///< empty: every component
  SceneValue value;                    ///< one number for every component, or an expression (scalar or vector)
  std::string where;
};

/// [initial]: the starting value of one unknown.
struct SceneInitialField {
  std::string unknown;
  enum class Kind { value, file } kind = Kind::value;
  SceneValue value;                    ///< Kind::value
  std::filesystem::path file;          ///< Kind::file: a previous run's HDF5 output
  std::string field;                   ///< Kind::file: its dataset name (default: the unknown's name)
  std::string where;
};

/// [qdata]: runtime-supplied quadrature data by the name the form declares.
struct SceneQdata {
  std::string name;
  enum class Source {
    /// ρ̄, the nodal spacing of the point's LME neighbours weighted by their basis values
    support_size,
    /// zeros (e.g. a reference field set by a model)
    zero,
    /// `value` (a number, or an expression of x and the constants) at every quadrature point
    value,
    /// the value, gradient or Hessian of a scalar nodal field of [coefficients] interpolated with
    /// the LME basis at every quadrature point (a Lagrangian form's reference field φ0, ∇φ0, ∇∇φ0)
    field,
  };
  Source source = Source::zero;
  SceneValue value;                    ///< provider "value"
  std::string field;                   ///< provider "field": the [coefficients] entry
  int derivative = 0;                  ///< provider "field": 0 value, 1 gradient, 2 Hessian
  std::string where;
};

/// [solver]: the constrained minimizer, the Newton iteration and PETSc options.
struct SceneSolver {
  bool kkt_first = true;               ///< start = "kkt" (default) or "augmented" (ConstrainedMinimizerOptions::kkt_first)
  double penalty = 1e-3;
  double augmented_tolerance = 1e-4;
  double inner_tolerance = 1e-6;
  int max_outer_iterations = 40;
  int max_inner_iterations = 25;
  double newton_tolerance = 1e-9;
  double constraint_tolerance = 1e-10;
  int max_newton_iterations = 25;
  bool inertia_correction = true;      ///< ConstrainedMinimizerOptions::inertia_correction
  /// Print every Newton iteration of a time step (static solves always print them).
  bool monitor = false;
  /// Appended to the PETSc options database before the solve ("-ksp_type gmres -pc_type ...").
  std::string petsc_options;
};

/// [reference]: what the result is compared with.
struct SceneReference {
  std::optional<double> energy;        ///< e.g. the sharp-interface energy
  /// Exact solution per unknown (expressions of x): the run reports L2 and H1 errors.
  std::vector<std::pair<std::string, SceneValue>> solution;
};

struct SceneOutput {
  std::filesystem::path directory;     ///< relative paths: against the working directory
  bool hdf5 = true;                    ///< HDF5 + XDMF sidecar
  bool png = false;                    ///< a figure of the first scalar field (2D; needs Python + matplotlib)
};

struct SceneDocument;  // the parsed TOML, for model extensions (scene_table.hpp)

struct Scene {
  std::string source;                  ///< the file name used in messages
  std::filesystem::path folder;        ///< the scene's folder: relative paths resolve against it
  std::string name;
  Coordinates coordinates = Coordinates::cartesian;
  Box domain;                          ///< dim 1, 2 or 3 (axisymmetric: 2, (r, z))
  SceneNodes nodes;
  SceneModel model;
  std::map<std::string, double, std::less<>> constants;  ///< [constants], by name
  std::map<std::string, std::string, std::less<>> constant_where;
  std::vector<SceneConstraint> constraints;
  std::vector<SceneDirichlet> dirichlet;
  std::vector<SceneInitialField> initial;
  /// [coefficients]: the known nodal fields the forms read (`coefficient NAME` in a form), by the
  /// same kinds of value as [initial] (`unknown` holds the coefficient's name).
  std::vector<SceneInitialField> coefficients;
  std::vector<SceneQdata> qdata;
  SceneSolver solver;
  SceneReference reference;
  std::optional<SceneOutput> output;
  /// Extension tables (e.g. "vesicle") kept for the model that reads them.
  std::vector<std::string> extensions;
  std::shared_ptr<const SceneDocument> document;

  [[nodiscard]] int dim() const noexcept { return domain.dim; }
  [[nodiscard]] bool axisymmetric() const noexcept { return coordinates == Coordinates::axisymmetric; }
  [[nodiscard]] bool has_extension(std::string_view table) const;
  /// "FILE:LINE: key 'constants.eps'" for messages about a constant (FILE alone if absent).
  [[nodiscard]] std::string where_constant(std::string_view name) const;
};

/// Reads and validates a scene file. Throws SceneError. `extensions`: top-level tables a model
/// reads itself (kept unread here).
[[nodiscard]] Scene load_scene(const std::filesystem::path& path, std::span<const std::string_view> extensions = {});

/// Parses scene text; source_name is used in messages and its folder resolves relative paths.
[[nodiscard]] Scene parse_scene(std::string_view text, std::string source_name,
                                std::span<const std::string_view> extensions = {});

/// The signed distance from x to the ellipsoid with the given center and semi-axes (dim 1-3), > 0 inside.
[[nodiscard]] double ellipsoid_signed_distance(std::span<const double> x, std::span<const double> center,
                                               std::span<const double> semi_axes);

/// The edit-distance suggestion among candidates ("" when none is close): the did-you-mean of every
/// name check.
[[nodiscard]] std::string closest_name(std::string_view word, std::span<const std::string> candidates);

}  // namespace lmeform
