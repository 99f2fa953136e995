// What the form checker evaluates kernels on: cells cut from a small, strongly graded node set
// with the real LME basis (1D, 2D, 3D, and the axisymmetric variant with the basis mirrored across
// the axis r = x[0] = 0), and generic random states that need no knowledge of the form:
//
//   scalar fields  (unknowns, coefficients): 0.9 tanh((R - |x - c|) / (sqrt2 w)) plus nodal noise,
//                  values in (-1, 1), the interface on the sphere where the node set is finest;
//   vector fields  (dim components): y = x + a smooth non-identity perturbation, with min det grad y
//                  over the quadrature points checked against a bound (deformations, velocities);
//   quadrature data: the jet of a smooth scalar field at the points, in declaration order
//                  (a datum of size 1 starts a field and holds its value, size dim its gradient,
//                  size dim^2 its Hessian, row-major).
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <optional>
#include <random>
#include <span>
#include <string>
#include <vector>

#include "lmeform/delaunay.hpp"
#include "lmeform/form_check.hpp"
#include "lmeform/kernel.hpp"
#include "lmeform/lme_basis.hpp"
#include "lmeform/node_set.hpp"
#include "lmeform/quadrature.hpp"

namespace lmeform::formcheck {

enum class Coordinates { cartesian, axisymmetric };
[[nodiscard]] const char* to_string(Coordinates c) noexcept;

/// The sphere (circle in 2D, pair of points in 1D) the node set is graded towards; scalar fields
/// have their interface on it.
struct Feature {
  int dim = 2;
  std::array<double, 3> center{};
  double radius = 0.3;
};

struct GeometryOptions {
  int dim = 2;
  /// Axisymmetric: the box starts at r = x[0] = 0, the feature is centred on the axis and the LME
  /// basis is mirrored across it (LmeOptions::mirrors), as the runtime does for bodies of revolution.
  Coordinates coordinates = Coordinates::cartesian;
  double h_min = 0.0;        ///< spacing on the feature; 0: 0.04 (1D), 0.03 (2D), 0.07 (3D)
  double h_max = 0.0;        ///< spacing away from it; 0: 4 h_min (2D), 3 h_min (1D, 3D)
  double transition = 0.15;  ///< distance from the feature over which the spacing grows
  std::optional<std::array<double, 3>> center;  ///< default: box centre, on the axis when axisymmetric
  double radius = 0.3;
  double gamma = 0.0;        ///< LME locality; 0: 0.8 (1D, 2D), 1.8 (3D: keeps neighbourhoods small; 0.8 for the second-order basis)
  LmeConsistency basis = LmeConsistency::first;  ///< first- or second-order max-ent basis
  std::uint64_t seed = 11;
};

/// A small graded node set on the unit box with its Delaunay cells and LME basis.
class CheckGeometry {
 public:
  explicit CheckGeometry(const GeometryOptions& options);

  [[nodiscard]] int dim() const noexcept { return nodes_.dim; }
  [[nodiscard]] Coordinates coordinates() const noexcept { return coordinates_; }
  [[nodiscard]] const NodeSet& nodes() const noexcept { return nodes_; }
  [[nodiscard]] const BackgroundCells& cells() const noexcept { return cells_; }
  [[nodiscard]] const LmeBasis& basis() const noexcept { return *basis_; }
  [[nodiscard]] const Feature& feature() const noexcept { return feature_; }
  [[nodiscard]] const QuadratureRule& rule() const noexcept { return rule_; }
  /// Smallest nodal spacing of the basis (the finest length scale of every field).
  [[nodiscard]] double h_min() const noexcept { return h_min_; }

  /// Background cell c with the quadrature points of rule(), its neighbourhood (the union of the
  /// points' neighbour lists) and the basis tabulated up to `order`.
  [[nodiscard]] Cell cell(std::size_t c, int order = 2) const;
  /// The cell containing x, else the one whose centroid is nearest.
  [[nodiscard]] std::size_t cell_near(std::span<const double> x) const;
  /// The cells a check runs on: one crossing the feature at a generic angle, and one inside the
  /// feature (Cartesian) or where it meets the axis (axisymmetric). The mirrored basis is even in r,
  /// so no interpolated field has an r-derivative on the axis: a radius y_r = r there would have
  /// det grad y -> 0 (0.08 for y = x at r = 0.003 on the default 2D geometry). With `vector_fields`
  /// the axisymmetric second cell is the one a row off the axis (points at r >= h_min).
  [[nodiscard]] std::vector<Cell> check_cells(int order = 2, bool vector_fields = false) const;

 private:
  Coordinates coordinates_;
  NodeSet nodes_;
  BackgroundCells cells_;
  std::shared_ptr<const LmeBasis> basis_;
  Feature feature_;
  QuadratureRule rule_;
  double h_min_ = 0.0;
};

/// Nodal values 0.9 tanh((R - |x - c|) / (sqrt2 width)) + noise * U(-1, 1): a smooth field in (-1, 1).
[[nodiscard]] std::vector<double> smooth_scalar_field(const Cell& cell, const Feature& feature, double width,
                                                      double noise, std::mt19937_64& rng);

/// Nodal values (interleaved per node) of y(x) = x + amplitude * (a random non-symmetric linear map
/// plus a smooth wave) + noise * U(-1, 1). Axisymmetric: y_r = r (1 + ...) keeps the axis in place
/// and y_r > 0, and the perturbation is even in r.
[[nodiscard]] std::vector<double> near_identity_field(const Cell& cell, double amplitude, double noise,
                                                      Coordinates coordinates, std::mt19937_64& rng);

/// Unit normals at the cell's quadrature points ([nq * dim]) for boundary kernels: the outward
/// normals of the spheres about the feature's centre through the points, so that they turn over
/// the cell as on a curved boundary (e_0 at a point on the centre).
[[nodiscard]] std::vector<double> radial_normals(const Cell& cell, const Feature& feature);

/// min over the quadrature points of det(grad y) for the dim components of a nodal vector field
/// stored at nodal[a * stride + offset + i].
[[nodiscard]] double min_det_grad(const Cell& cell, const std::vector<double>& nodal, int stride, int offset);

/// Quadrature data from the jet of nodal scalar fields: for each datum size in `sizes`, 1 takes the
/// next field (fields[k], cycling) and writes its value, dim its gradient, dim^2 its Hessian
/// (row-major); other sizes get small random values.
[[nodiscard]] std::vector<double> jet_qdata(const Cell& cell, const std::vector<std::vector<double>>& fields,
                                            const std::vector<int>& sizes, std::mt19937_64& rng);

/// [phi0, grad phi0, hess phi0] per point: the layout of `qdata phi0, gphi0 : vector, hphi0 : matrix`.
[[nodiscard]] std::vector<double> reference_qdata(const Cell& cell, const std::vector<double>& phi0);

[[nodiscard]] std::vector<double> random_vector(std::size_t n, double scale, std::mt19937_64& rng);

struct StateOptions {
  double width = 0.0;         ///< tanh width of scalar fields; 0: 2 h_min of the geometry
  double noise = 0.05;        ///< nodal noise of scalar fields
  double perturbation = 0.1;  ///< vector fields: size of the non-identity part of grad y
  double min_det = 0.5;       ///< vector fields: required min det grad y over the cell's points
};

/// A state, a Taylor direction and per-dof scales for any form on a cell.
struct CheckCase {
  State state;
  std::vector<double> direction;   ///< random, per dof of the size of its field's scale
  std::vector<double> dof_scales;  ///< 1 for scalar fields, h_min for vector fields
  double min_det = std::numeric_limits<double>::quiet_NaN();  ///< over the vector fields (NaN: none)
};

/// Generic state for `form` on `cell`: fields by shape (FormKernels::unknowns, ::coefficients),
/// quadrature data by size (FormKernels::qdata), the given constants. Throws std::runtime_error if
/// no perturbation amplitude keeps det grad y above options.min_det.
[[nodiscard]] CheckCase generic_case(const kernel::FormKernels& form, const Cell& cell, const CheckGeometry& geometry,
                                     const std::vector<double>& constants, const StateOptions& options,
                                     std::mt19937_64& rng);

}  // namespace lmeform::formcheck
