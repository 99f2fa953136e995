// Saddle points of an energy: min over some unknowns, max over others (model.maximize), the
// electric enthalpy of a dielectric being the example (min in the displacement, max in the
// potential). Newton's method on the symmetric indefinite Hessian, each step one MUMPS LDLᵀ
// factorization whose inertia says whether the point is the min-max saddle the scene declares.
//
// With it come equipotential parts ([[equipotential]]): a scalar unknown held equal on the nodes of
// some boundary parts at a value the solve finds (a floating electrode), eliminated master–slave
// (u = P û: every node of a part follows its first node), with the part's total charge given.
#pragma once

#include <string>
#include <vector>

#include "bound_scene.hpp"
#include "lmeform/petsc.hpp"
#include "problem_space.hpp"
#include "quantities.hpp"

namespace lmeform::problems {

class StationaryDriver;

/// Checks model.maximize and [[equipotential]] against the bound unknowns and Dirichlet entries
/// (called by bind_scene). Throws SceneError naming the key.
void bind_saddle_point(const Scene& scene, BoundScene& b);

/// The nodes of one [[equipotential]] entry on a node set.
struct EquipotentialGroup {
  const BoundEquipotential* entry = nullptr;
  std::vector<int> nodes;        ///< original numbering, sorted
  PetscInt master_dof = -1;      ///< global (renumbered) dof every other node of the group follows
  std::vector<PetscInt> dofs;    ///< global dofs of every node of the group (the master's included)
};

/// The groups of the bound scene's [[equipotential]] entries on the space's nodes. Throws
/// SceneError for a part without nodes, a node held by a [[dirichlet]] entry of the same unknown,
/// or a node in two groups.
[[nodiscard]] std::vector<EquipotentialGroup> equipotential_groups(const BoundScene& b, const ProblemSpace& space);

/// <name>_potential (the common value) and <name>_charge (minus the residual summed over the
/// group's nodes, the prescribed charge at a solution) of every [[equipotential]] entry.
void add_equipotential_quantities(const BoundScene& b, ProblemSpace& space, Vec u, Vec residual, QuantityValues& out);

/// The driver of scenes that name model.maximize.
[[nodiscard]] const StationaryDriver& saddle_point_driver();

}  // namespace lmeform::problems
