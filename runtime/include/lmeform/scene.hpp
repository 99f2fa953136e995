// Scenes: the TOML files that describe a run (docs/scenes.md lists every key).
//
// A scene says what a run needs and nothing more: coordinates and domain, the node set, the initial
// phase field, the model constants, the constraints with their targets, solver settings, an optional
// CVT adaptivity schedule, an optional reference energy and optional outputs. An absent optional
// section means "not used" (no [adaptivity]: the uniform grid; no moment constraint: none).
//
// Reading is strict: a key that is missing, unknown (with a did-you-mean suggestion) or of the wrong
// type, and every number out of range, throws SceneError "FILE:LINE: <what is wrong with which key>".
#pragma once

#include <array>
#include <filesystem>
#include <optional>
#include <span>
#include <stdexcept>
#include <string>
#include <string_view>
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
  std::filesystem::path file;          ///< Kind::file: read_points() file, resolved against the scene's folder
  double gamma = 0.8;                  ///< LME locality gamma (seed: 0.8)
  int spacing_smoothing = 5;           ///< smoothing passes on the nodal spacing h_a (smooth_spacing)
  int quadrature_points = 6;           ///< points of the simplex rule per background cell
  double resolution_factor = 2.0;      ///< eps >= resolution_factor * h_min is required (seed App. B)
};

/// [initial]: phi0(x) = tanh(d(x) / (sqrt(2) eps)), d the signed distance to the shape, > 0 inside.
struct SceneInitial {
  enum class Shape { sphere, ellipsoid };
  Shape shape = Shape::ellipsoid;
  std::array<double, 3> center{};
  std::array<double, 3> semi_axes{};   ///< sphere: every entry is the radius
  std::optional<double> eps;           ///< interface width of the profile; unset: model.eps
};

/// [model]: the phase-field Helfrich model (forms helfrich / helfrich_axisymmetric).
struct SceneModel {
  std::string form;                    ///< compiled energy form, e.g. "helfrich_axisymmetric"
  double k = 1.0;                      ///< bending modulus
  double eps = 0;                      ///< interface width (first solve; adaptivity stages lower it)
  double C0 = 0.0;                     ///< spontaneous curvature
  double boundary_phi = -1.0;          ///< phi imposed on the outer boundary (not on the axis r = 0)
};

struct SceneMoment {
  double target = 0.0;                 ///< M0
  double z_center = 0.0;               ///< zc in M = int phi (z - zc)
};

/// [constraints]: every target resolved to a number; unset: the constraint is not used.
struct SceneConstraints {
  std::optional<double> area;          ///< A0
  std::optional<double> volume;        ///< V0
  std::optional<SceneMoment> moment;
  std::optional<double> reduced_volume;  ///< v = V0 / V_sphere(A0) when area and volume are both set
};

/// [solver]: defaults are those of ConstrainedMinimizerOptions.
struct SceneSolver {
  double penalty = 1e-3;
  double augmented_tolerance = 1e-4;
  double inner_tolerance = 1e-6;
  int max_outer_iterations = 40;
  int max_inner_iterations = 25;
  double newton_tolerance = 1e-9;
  double constraint_tolerance = 1e-10;
  int max_newton_iterations = 25;
};

/// One stage of the progressive CVT schedule (seed Table B.6): relocate the nodes by Lloyd
/// iterations for the density rho = 1 + f |grad phi| of the current solution, then solve at eps.
/// lloyd_iterations = 0: no relocation, the stage only lowers eps on the current grid.
struct AdaptivityStage {
  double eps = 0;
  double f = 0;
  int lloyd_iterations = 20;
  /// A side solve: it starts from the previous stage like any other, but later stages that are not
  /// branches continue from the last stage that is not one (seed Table 3 reports O12 at eps = 0.02,
  /// while O13 is adapted with the phase field of O12 at eps = 0.025).
  bool branch = false;
};

struct SceneAdaptivity {
  std::vector<AdaptivityStage> stages;  ///< non-empty, eps non-increasing
  /// Where each stage's Lloyd iterations start: from the current nodes (the seed: "CVT starting
  /// from grid O1") or from nodes re-placed with the CVT node density of rho (CvtStart::density).
  bool start_from_density = false;
  double samples_per_node = 64;          ///< CVT samples per node
};

struct SceneOutput {
  std::filesystem::path directory;     ///< relative paths: against the working directory
  bool hdf5 = true;                    ///< HDF5 + XDMF sidecar
  bool png = true;                     ///< node set coloured by phi with the phi = 0 contour
};

struct Scene {
  std::string source;                  ///< the file name used in messages
  std::string name;
  Coordinates coordinates = Coordinates::axisymmetric;
  Box domain;                          ///< dim 2 or 3 (axisymmetric: 2, (r, z))
  SceneNodes nodes;
  SceneInitial initial;
  SceneModel model;
  SceneConstraints constraints;
  SceneSolver solver;
  std::optional<SceneAdaptivity> adaptivity;
  std::optional<double> reference_energy;
  std::optional<SceneOutput> output;

  [[nodiscard]] int dim() const noexcept { return domain.dim; }
  [[nodiscard]] bool axisymmetric() const noexcept { return coordinates == Coordinates::axisymmetric; }
  /// eps of the last solve: the last adaptivity stage's, else model.eps.
  [[nodiscard]] double final_eps() const noexcept;
  /// The smallest spacing of the uniform grid the node keys describe; nullopt for a node file or a
  /// CVT node count (checked by the run once the nodes exist).
  [[nodiscard]] std::optional<double> uniform_min_spacing() const;
  /// Signed distance to the initial shape at x (dim entries), > 0 inside.
  [[nodiscard]] double initial_distance(std::span<const double> x) const;
  /// The initial phase field tanh(d / (sqrt(2) eps)) at x, eps = initial.eps or model.eps.
  [[nodiscard]] double initial_phi(std::span<const double> x) const;
};

/// Reads and validates a scene file. Throws SceneError.
[[nodiscard]] Scene load_scene(const std::filesystem::path& path);

/// Parses scene text; source_name is used in messages and its folder resolves relative node files.
[[nodiscard]] Scene parse_scene(std::string_view text, std::string source_name);

/// The largest volume bounded by area A0 (the sphere's): A0^{3/2} / (6 sqrt(pi)).
/// dim = 2 (Cartesian 2D): the largest area bounded by a curve of length A0, A0^2 / (4 pi).
[[nodiscard]] double max_volume_for_area(double A0, int dim = 3);

/// Throws SceneError unless 0 < V0 <= max_volume_for_area(A0, dim); the message gives V0, V_max, A0 and
/// the reduced volume V0 / V_max.
void check_feasible(double A0, double V0, int dim = 3);

/// Signed distance from x to the ellipsoid with the given center and semi-axes (dim 1-3), > 0 inside.
[[nodiscard]] double ellipsoid_signed_distance(std::span<const double> x, std::span<const double> center,
                                               std::span<const double> semi_axes);

}  // namespace lmeform
