// One reference configuration of a Lagrangian motion: its problem space, the minimizer of a time
// step and the vectors of a step; and what the motion does at its quadrature points (positions,
// F, D²y), from which the deformation is measured and a reset carries the quadrature.
#pragma once

#include <array>
#include <map>
#include <memory>
#include <span>
#include <string>
#include <vector>

#include "dynamics_integrator.hpp"
#include "lmeform/constrained_minimizer.hpp"
#include "lmeform/petsc.hpp"
#include "problem_space.hpp"

namespace lmeform::problems {

struct ReferenceConfiguration {
  ReferenceConfiguration(MPI_Comm comm, const BoundScene& b, const ProblemInput& input, const ConstrainedMinimizerOptions& options,
                         bool forward_euler, const std::string& deformation);

  ProblemSpace space;
  std::unique_ptr<ConstrainedMinimizer> minimizer;
  PetscVector u, yn, trial, gradient, w;
  std::vector<PetscVector> G, Z;       ///< forward Euler: constraint gradients and K⁻¹ G
  PetscMatrix K;                       ///< the dissipation's Hessian at yⁿ
  PetscLinearSolver euler_ksp;
  Vec dissipation_coefficients = nullptr;  ///< the dissipation's coefficient fields (owned by space)
  int coefficient_offset = -1;         ///< of the deformation among them
  int coefficients_per_node = 0;
  NodeSet nodes;                       ///< the reference nodes (original order)
  int deformation_offset = 0;          ///< of the deformation within a node's dofs
  const FormModule* kinematics = nullptr;  ///< generated: position, F, H of the deformation
};

/// The position y(X), F and ∂²y/∂X∂X at one quadrature point.
struct PointKinematics {
  int point = 0;                       ///< this rank's quadrature point (Discretization::quadrature())
  std::array<double, 3> position{};
  std::array<double, 9> F{};           ///< F[k * dim + I] = ∂y_k / ∂X_I
  std::array<double, 27> H{};          ///< H[(k * dim + I) * dim + J] = ∂²y_k / ∂X_I ∂X_J
};

/// The kinematics of the motion y (original order, dofs interleaved) at the quadrature points of
/// this rank's owned elements (each point on one rank); order 1: position and F, 2: also D²y.
[[nodiscard]] std::vector<PointKinematics> point_kinematics(const ReferenceConfiguration& ref, const std::vector<double>& y, int order);

/// Axisymmetric: F of the body of revolution, whose hoop stretch y_r / R joins the (r, z) block,
/// so that a map carrying points across the axis counts as folded.
[[nodiscard]] DeformationMeasures deformation_measures(const ReferenceConfiguration& ref, const std::vector<double>& y, bool axisymmetric);

/// Per-point values of this rank's points (`size` each) for every point, numbered as a carried
/// quadrature (Discretization::global_point): each point from the rank owning its element, summed
/// over the ranks. What a reset, a re-mesh or a checkpoint needs of the points all at once.
[[nodiscard]] std::vector<double> every_point_values(const Discretization& disc, std::span<const double> local, std::size_t size);
/// The quadrature of every point (positions and weights) with the cells (original numbering).
[[nodiscard]] CarriedQuadrature every_point_quadrature(const Discretization& disc, const BackgroundCells& cells);

/// A reset's new reference: the quadrature points carried (x̂ → y(x̂), w → w det F), the field
/// jets at the points pushed forward (values kept, gradients F⁻ᵀ ∇φ0, Hessians with the D²y term).
struct CarriedReference {
  CarriedQuadrature quadrature;
  std::map<std::string, std::vector<double>, std::less<>> jets;
};
[[nodiscard]] CarriedReference carry_reference(const ReferenceConfiguration& ref, const BackgroundCells& cells, const std::vector<double>& y,
                                               const std::map<std::string, FieldJets>& jets);

}  // namespace lmeform::problems
