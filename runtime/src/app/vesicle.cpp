#include "vesicle.hpp"

#include <algorithm>
#include <cmath>
#include <numeric>
#include <stdexcept>

#include "area_axisymmetric_kernels.hpp"
#include "helfrich_axisymmetric_kernels.hpp"
#include "lmeform/assembler.hpp"
#include "lmeform/cvt.hpp"
#include "lmeform/discretization.hpp"
#include "lmeform/node_sets.hpp"
#include "lmeform/scene.hpp"
#include "moment_axisymmetric_kernels.hpp"
#include "volume_axisymmetric_kernels.hpp"

namespace lmeform::app {

double ellipsoid_profile(double r, double z, std::array<double, 2> semi_axes, double z_center, double eps) {
  // The exact signed distance to the ellipse (positive inside), as the scenes use it.
  const std::array<double, 2> x{r, z}, center{0.0, z_center};
  const double inside = ellipsoid_signed_distance(x, center, semi_axes);
  return std::tanh(inside / (std::sqrt(2.0) * eps));
}

std::vector<double> rescale_interface(std::span<const double> phi, double eps_from, double eps_to) {
  if (!(eps_from > 0) || !(eps_to > 0)) throw std::invalid_argument("rescale_interface: eps must be positive");
  const double ratio = eps_from / eps_to, bound = 1.0 - 1e-15;
  std::vector<double> out(phi.size());
  for (std::size_t a = 0; a < phi.size(); ++a) out[a] = std::tanh(ratio * std::atanh(std::clamp(phi[a], -bound, bound)));
  return out;
}

LmeOptions axisymmetric_lme_options(int spacing_smoothing) {
  // φ of a body of revolution is even in r: the basis is mirrored across the axis r = 0, so
  // φ_r = 0 there exactly and φ_r / r stays finite (without it φ_r(0, z) ≠ 0 and the bending
  // density ε² φ_r² / r grows without bound as quadrature points approach the axis).
  LmeOptions o;
  o.mirror_axis = 0;
  o.mirror_position = 0.0;
  // On CVT-graded node sets the distance to the few nearest nodes scatters from node to node;
  // a smooth h_a keeps beta_a = gamma / h_a^2, and so the basis, regular (measured: the discocyte
  // at eps = 0.04 on a graded 6124-node grid, +0.36 % from the converged energy with the raw
  // spacing, +0.10 % with 5 passes; neutral on uniform grids).
  o.spacing_smoothing = spacing_smoothing;
  return o;
}

VesicleFunctionals evaluate_vesicle(MPI_Comm comm, const VesicleSetup& setup) {
  Box box;
  box.dim = 2;
  box.lo = {setup.lower[0], setup.lower[1], 0};
  box.hi = {setup.upper[0], setup.upper[1], 0};
  const NodeSet nodes = setup.nodes.size() > 0 ? setup.nodes : uniform_grid(box, setup.spacing);
  DiscretizationOptions options;
  options.gamma = {setup.gamma};
  options.lme = axisymmetric_lme_options(setup.spacing_smoothing);
  options.quadrature_points = setup.quadrature_points;
  options.basis_order = 2;
  const Discretization disc(comm, nodes, options);
  std::vector<double> phi0(nodes.size());
  for (std::size_t a = 0; a < nodes.size(); ++a) {
    phi0[a] = setup.initial_phi.empty()
                  ? ellipsoid_profile(nodes.coords[2 * a], nodes.coords[2 * a + 1], setup.semi_axes, setup.z_center, setup.eps)
                  : setup.initial_phi[a];
  }
  Assembler energy(disc, helfrich_axisymmetric_bending_2d);
  energy.set_constants(std::vector<double>{setup.k, setup.eps, setup.C0});
  Assembler area(disc, area_axisymmetric_area_2d);
  area.set_constant("eps", setup.eps);
  area.set_constant("A0", 0.0);
  Assembler volume(disc, volume_axisymmetric_volume_2d);
  volume.set_constant("V0", 0.0);
  Assembler moment(disc, moment_axisymmetric_moment_2d);
  moment.set_constant("zc", setup.z_center);
  moment.set_constant("M0", 0.0);
  PetscVector phi = energy.create_vector();
  set_from_original(disc, phi0, 1, phi);
  return {energy.value(phi), area.value(phi), volume.value(phi), moment.value(phi)};
}

VesicleResult solve_vesicle(MPI_Comm comm, const VesicleSetup& setup) {
  const double t0 = MPI_Wtime();
  VesicleResult result;
  Box box;
  box.dim = 2;
  box.lo = {setup.lower[0], setup.lower[1], 0};
  box.hi = {setup.upper[0], setup.upper[1], 0};
  result.nodes = setup.nodes.size() > 0 ? setup.nodes : uniform_grid(box, setup.spacing);
  const NodeSet& nodes = result.nodes;
  result.nodes_count = static_cast<int>(nodes.size());

  DiscretizationOptions options;
  options.gamma = {setup.gamma};
  options.lme = axisymmetric_lme_options(setup.spacing_smoothing);
  options.quadrature_points = setup.quadrature_points;
  options.basis_order = 2;  // the Helfrich energy needs Laplacians of φ
  const Discretization disc(comm, nodes, options);
  {
    const auto h = disc.basis().spacing();
    result.h_min = *std::min_element(h.begin(), h.end());
    result.h_mean = std::accumulate(h.begin(), h.end(), 0.0) / static_cast<double>(h.size());
  }

  Assembler energy(disc, helfrich_axisymmetric_bending_2d);
  energy.set_constant("k", setup.k);
  energy.set_constant("eps", setup.eps);
  energy.set_constant("C0", setup.C0);

  // Only the constraints the setup declares are built.
  std::vector<std::unique_ptr<Assembler>> functionals;
  std::vector<ScalarConstraint> constraints;
  if (setup.area_target) {
    functionals.push_back(std::make_unique<Assembler>(disc, area_axisymmetric_area_2d));
    functionals.back()->set_constant("eps", setup.eps);
    functionals.back()->set_constant("A0", *setup.area_target);
    constraints.push_back({"area", functionals.back().get(), *setup.area_target, std::abs(*setup.area_target)});
  }
  if (setup.volume_target) {
    functionals.push_back(std::make_unique<Assembler>(disc, volume_axisymmetric_volume_2d));
    functionals.back()->set_constant("V0", *setup.volume_target);
    constraints.push_back({"volume", functionals.back().get(), *setup.volume_target, std::abs(*setup.volume_target)});
  }
  if (setup.moment_target) {
    functionals.push_back(std::make_unique<Assembler>(disc, moment_axisymmetric_moment_2d));
    functionals.back()->set_constant("zc", setup.z_center);
    functionals.back()->set_constant("M0", *setup.moment_target);
    // The moment's natural size: the vesicle volume times its half-height.
    const double size = setup.volume_target ? std::abs(*setup.volume_target) : 1.0;
    constraints.push_back({"moment", functionals.back().get(), *setup.moment_target, size});
  }
  for (const auto& c : constraints) result.constraint_names.push_back(c.name);

  // Initial field and the Dirichlet nodes: φ = −1 on r = r_max, z = z_min, z = z_max.
  std::vector<double> phi0(nodes.size());
  std::vector<int> boundary;
  const double tol = 1e-9 * std::max(setup.upper[0] - setup.lower[0], setup.upper[1] - setup.lower[1]);
  for (std::size_t a = 0; a < nodes.size(); ++a) {
    const double r = nodes.coords[2 * a], z = nodes.coords[2 * a + 1];
    phi0[a] = setup.initial_phi.empty() ? ellipsoid_profile(r, z, setup.semi_axes, setup.z_center, setup.eps)
                                        : setup.initial_phi[a];
    if (r >= setup.upper[0] - tol || z <= setup.lower[1] + tol || z >= setup.upper[1] - tol) {
      boundary.push_back(static_cast<int>(a));
      phi0[a] = -1.0;
    }
  }
  PetscVector phi = energy.create_vector();
  set_from_original(disc, phi0, 1, phi);

  ConstrainedMinimizer minimizer(energy, constraints, setup.solver);
  minimizer.set_fixed_dofs(owned_dofs_of_nodes(disc, boundary, 1));
  result.seconds_setup = MPI_Wtime() - t0;
  const double t1 = MPI_Wtime();
  std::vector<double> nu;  // the minimizer works with multipliers of the scaled constraints
  if (!setup.initial_multipliers.empty()) {
    if (setup.initial_multipliers.size() != constraints.size()) {
      throw std::invalid_argument("solve_vesicle: " + std::to_string(setup.initial_multipliers.size()) +
                                  " starting multipliers for " + std::to_string(constraints.size()) + " constraints");
    }
    for (std::size_t i = 0; i < constraints.size(); ++i) nu.push_back(setup.initial_multipliers[i] * constraints[i].scale);
  }
  result.solve = minimizer.minimize(phi, nu);
  result.seconds_solve = MPI_Wtime() - t1;

  result.phi = to_original(disc, phi, 1);
  // |∇φ| at the nodes (0 on the Dirichlet boundary, where φ is fixed; the axis is no boundary
  // of the mirrored basis).
  result.grad_phi_norm.assign(nodes.size(), 0.0);
  std::vector<int> boundary_mask(nodes.size(), 0);
  for (const int a : boundary) boundary_mask[static_cast<std::size_t>(a)] = 1;
  for (std::size_t b = 0; b < nodes.size(); ++b) {
    const auto o = static_cast<std::size_t>(disc.original_index()[b]);
    if (boundary_mask[o] != 0) continue;
    const auto x = disc.nodes().point(b);
    const auto list = disc.basis().neighbours(x);
    const auto jet = disc.basis().evaluate(x, list, 1);
    double gr = 0, gz = 0;
    for (std::size_t m = 0; m < list.size(); ++m) {
      const double value = result.phi[static_cast<std::size_t>(disc.original_index()[static_cast<std::size_t>(list[m])])];
      gr += jet[1 * list.size() + m] * value;
      gz += jet[2 * list.size() + m] * value;
    }
    result.grad_phi_norm[o] = std::sqrt(gr * gr + gz * gz);
  }
  result.cells = delaunay(nodes);
  return result;
}

std::vector<double> transfer_phi(const NodeSet& old_nodes, std::span<const double> phi, double gamma,
                                 int spacing_smoothing, const NodeSet& new_nodes) {
  const std::vector<double> gammas(old_nodes.size(), gamma);
  const LmeBasis basis(old_nodes, gammas, axisymmetric_lme_options(spacing_smoothing));
  std::vector<double> out(new_nodes.size());
  for (std::size_t a = 0; a < new_nodes.size(); ++a) {
    const auto x = new_nodes.point(a);
    const auto list = basis.neighbours(x);
    const auto p = basis.evaluate(x, list, 0);
    double v = 0;
    for (std::size_t m = 0; m < list.size(); ++m) v += p[m] * phi[static_cast<std::size_t>(list[m])];
    out[a] = v;
  }
  return out;
}

NodeSet adapt_nodes(const VesicleResult& solved, std::array<double, 2> lower, std::array<double, 2> upper, double f,
                    const CvtOptions& cvt, CvtReport* report) {
  Box box;
  box.dim = 2;
  box.lo = {lower[0], lower[1], 0};
  box.hi = {upper[0], upper[1], 0};
  const auto density = phase_field_density(f, solved.nodes, solved.grad_phi_norm);
  return cvt_relocate(solved.nodes, box, density, cvt, report);
}

}  // namespace lmeform::app
