// The axisymmetric phase-field vesicle (seed statics, eq. (1) of Paper A): minimize the Helfrich
// energy of φ on a (r, z) box subject to area, volume and static-moment constraints, φ = −1 on
// the outer boundary (r = r_max, z = z_min, z = z_max; the axis r = 0 is free).
#pragma once

#include <array>
#include <iosfwd>
#include <optional>
#include <span>
#include <string>
#include <vector>

#include "lmeform/cvt.hpp"
#include "lmeform/lme_basis.hpp"
#include "lmeform/constrained_minimizer.hpp"
#include "lmeform/delaunay.hpp"
#include "lmeform/node_set.hpp"

namespace lmeform::app {

struct VesicleSetup {
  std::array<double, 2> lower{0.0, 0.0}, upper{1.5, 2.0};  ///< (r, z) box
  NodeSet nodes;                                           ///< given, or a uniform grid of `spacing`
  double spacing = 0.03;
  double gamma = 1.6;
  int spacing_smoothing = 5;                               ///< LmeOptions::spacing_smoothing
  int quadrature_points = 6;
  // Model.
  double k = 1.0, eps = 0.04, C0 = 0.0;
  // Constraints (those not wanted are std::nullopt: nothing is computed for them).
  std::optional<double> area_target, volume_target, moment_target;
  double z_center = 1.0;
  // Initial field: tanh profile of an ellipsoid with semi-axes (a_r, a_z) centred on the axis.
  std::array<double, 2> semi_axes{0.55, 0.25};
  std::vector<double> initial_phi;                         ///< overrides the ellipsoid when set
  /// Starting Lagrange multipliers in physical units, one per declared constraint in the order
  /// area, volume, moment (a previous solve's ConstrainedResult::multipliers); empty: zero.
  std::vector<double> initial_multipliers;
  ConstrainedMinimizerOptions solver{};
};

struct VesicleResult {
  ConstrainedResult solve;
  NodeSet nodes;                 ///< original order
  BackgroundCells cells;         ///< original numbering
  std::vector<double> phi;       ///< original order
  std::vector<double> grad_phi_norm;  ///< |∇φ| at the nodes (for adaptivity)
  std::vector<std::string> constraint_names;
  double h_min = 0, h_mean = 0;
  double seconds_setup = 0, seconds_solve = 0;
  int nodes_count = 0;
};

/// Energy and constraint values of the setup's initial field, without minimizing.
struct VesicleFunctionals {
  double energy = 0, area = 0, volume = 0, moment = 0;
};
VesicleFunctionals evaluate_vesicle(MPI_Comm comm, const VesicleSetup& setup);

/// Builds the discretization and forms for the setup and minimizes. Collective over `comm`.
VesicleResult solve_vesicle(MPI_Comm comm, const VesicleSetup& setup);

/// A phase field of interface width eps_from re-profiled to eps_to: tanh(atanh(phi) eps_from / eps_to)
/// (phi clamped into (-1, 1)). Exact for a tanh profile; the start of a continuation in eps.
[[nodiscard]] std::vector<double> rescale_interface(std::span<const double> phi, double eps_from, double eps_to);

/// The LME options of every axisymmetric basis: mirror symmetry across the axis r = 0, and
/// `spacing_smoothing` passes on the nodal spacing.
[[nodiscard]] LmeOptions axisymmetric_lme_options(int spacing_smoothing);

/// φ_h of a finished solve evaluated at new points (values only): the starting field on an
/// adapted grid.
[[nodiscard]] std::vector<double> transfer_phi(const NodeSet& old_nodes, std::span<const double> phi, double gamma,
                                               int spacing_smoothing, const NodeSet& new_nodes);

/// One CVT adaptation of a solved state: Lloyd iterations (cvt.iterations, from cvt.start) with
/// density ρ = 1 + f·|∇φ| on the box.
[[nodiscard]] NodeSet adapt_nodes(const VesicleResult& solved, std::array<double, 2> lower, std::array<double, 2> upper,
                                  double f, const CvtOptions& cvt, CvtReport* report = nullptr);

/// tanh(d / (√2 ε)) with d ≈ the signed distance to the ellipse (a_r, a_z) centred at (0, z_c).
[[nodiscard]] double ellipsoid_profile(double r, double z, std::array<double, 2> semi_axes, double z_center, double eps);

}  // namespace lmeform::app
