// The topology of a phase field's interface φ = 0 in a run: where the field is evaluated, how the
// topology is reported (log, JSON), and the warning when it differs from the start's.
//
// The field is the LME field of its nodal coefficients, evaluated at the nodes (LME does not
// interpolate: a node's value is not its coefficient) and taken linear on the Delaunay cells
// between them; level_set_topology does the counting. What is finer than the cells is not seen
// (lmeform/level_set_topology.hpp): with ε ≥ 2 h_min, two sheets of the membrane are told apart
// where a node between them lies on the outside, which needs a gap of about one local spacing.
#pragma once

#include <span>
#include <string>
#include <vector>

#include <mpi.h>
#include <nlohmann/json.hpp>

#include "lmeform/discretization.hpp"
#include "lmeform/level_set_topology.hpp"
#include "lmeform/lme_basis.hpp"

namespace lmeform::problems {

/// The geometry of a scene's level sets: plane curves (2D), surfaces of revolution
/// (axisymmetric) or surfaces (3D).
[[nodiscard]] LevelSetGeometry level_set_geometry(int dim, bool axisymmetric);

/// The field of `coefficients` (in the basis' node order) at the basis' own nodes. Where the basis
/// cannot be evaluated at a node (a vertex of its neighbours' hull: a corner of the box, where the
/// LME basis function is the node's own), the value is the node's coefficient. Collective: each rank
/// of comm evaluates a block of the nodes, and all receive every value.
[[nodiscard]] std::vector<double> lme_values_at_nodes(MPI_Comm comm, const LmeBasis& basis, std::span<const double> coefficients);

/// The topology of φ = 0 for the scalar coefficients of a solve's discretization (original node
/// order, one per node). Collective over the discretization's communicator. With planes of
/// symmetry (the scene's [domain] mirror), the nodes are a part of a symmetric body: the level set
/// is that of the whole body, the part and its mirror images (symmetric_level_set_topology).
[[nodiscard]] LevelSetTopology field_topology(const Discretization& disc, std::span<const double> coefficients,
                                              LevelSetGeometry geometry, std::span<const MirrorPlane> symmetry_planes = {});

/// The topology of {f = 0} of the whole body of which `nodes` with `values` are the part on one
/// side of each plane: the nodes and their images across every combination of the planes (a node
/// on a plane is its own image there) are triangulated anew and counted by level_set_topology.
/// Without planes, the Delaunay cells of the nodes.
[[nodiscard]] LevelSetTopology symmetric_level_set_topology(const NodeSet& nodes, std::span<const double> values,
                                                            std::span<const MirrorPlane> symmetry_planes, LevelSetGeometry geometry);

/// The same on nodes with their cells and a basis built for them (γ, options), collective over comm.
[[nodiscard]] LevelSetTopology field_topology(MPI_Comm comm, const NodeSet& nodes, const BackgroundCells& cells, std::span<const double> coefficients,
                                              double gamma, const LmeOptions& lme, LevelSetGeometry geometry);

/// {"components": n, "closed": [...], "genus": [...] (null for an open surface; surfaces only),
/// "summary": describe()}.
[[nodiscard]] nlohmann::json topology_json(const LevelSetTopology& topology);

/// The inverse of topology_json for what it compares (same_as): components, closed, genus.
[[nodiscard]] LevelSetTopology topology_from_json(const nlohmann::json& js, LevelSetGeometry geometry);

/// The warning for a change of topology from `initial` to `now` at `where` ("stage 3", "step 40"),
/// or "" when they are the same:
/// "the membrane's topology changed at stage 3: 1 component, genus 0 (a sphere) -> 1 component, genus 1 (a torus)".
[[nodiscard]] std::string topology_change_warning(const LevelSetTopology& initial, const LevelSetTopology& now, const std::string& where);

}  // namespace lmeform::problems
