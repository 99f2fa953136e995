// Test cells for the form checks: a graded 2D node set, a triangulation of it, Gauss points of a
// few triangles, the neighbourhood of each cell and a basis tabulation in the kernel jet layout.
#pragma once

#include "form_check.hpp"

#include <array>
#include <cstdint>
#include <functional>
#include <random>
#include <string>
#include <vector>

namespace lmeform::formcheck {

/// A 2D node cloud with nodal spacings h_a (distance to the nearest neighbour).
struct NodeCloud {
  int dim = 2;
  std::vector<double> x;  ///< [N * dim]
  std::vector<double> h;  ///< [N]
  std::vector<std::array<int, 3>> triangles;
  [[nodiscard]] int size() const { return static_cast<int>(h.size()); }
};

/// Graded tensor grid on [x0,x1] x [y0,y1]: spacing grows by `grading` across the box (geometric),
/// finest near the lower-left corner, interior nodes jittered by `jitter` times the local spacing.
/// Triangles: each grid quad split along a diagonal (a valid triangulation of the nodes).
NodeCloud graded_cloud(int nx, int ny, double x0, double x1, double y0, double y1, double grading, double jitter,
                       std::uint64_t seed);

/// Fills out[(s * n) + a] (jet slot s, local node a) at point x for the nodes `ids` of the cloud,
/// derivative orders up to `order`. Returns false where the basis cannot be evaluated.
using Tabulator = std::function<bool(const NodeCloud& cloud, const std::vector<int>& ids, const double* x, int order,
                                     double* out)>;

/// Support radius of node a for the tabulator (nodes farther than this from every quadrature
/// point of a cell are left out of the cell's neighbourhood).
using SupportRadius = std::function<double(const NodeCloud& cloud, int a)>;

struct BasisChoice {
  std::string name;
  Tabulator tabulate;
  SupportRadius radius;
};

/// Gaussian bumps p_a = exp(-gamma |x - x_a|^2 / h_a^2) with exact derivatives (no partition of
/// unity): a smooth synthetic tabulation, used where the real LME basis is not available.
BasisChoice gaussian_basis(double gamma);

/// Cell from triangle t of the cloud with a 6-point (degree 4) Gauss rule; neighbourhood = nodes
/// whose support reaches one of the quadrature points. `order` = tabulated derivative order.
Cell make_cell(const NodeCloud& cloud, int t, const BasisChoice& basis, int order);

/// Index of the triangle containing (or nearest to, by centroid) point p.
int triangle_near(const NodeCloud& cloud, double px, double py);

/// Nodal phase field tanh((R - |x - c|) / (sqrt2 eps)) (+1 inside) plus uniform noise of size `noise`.
std::vector<double> phase_field(const Cell& cell, double cx, double cy, double R, double eps, double noise,
                                std::mt19937_64& rng);

/// Nodal deformation y(x) = x + A x + b sin(...) + noise (interleaved per node), non-identity,
/// with det F well away from 0 (checked by the caller with min_det_F).
std::vector<double> deformation(const Cell& cell, double amplitude, double noise, std::mt19937_64& rng);

/// min over quadrature points of det(grad y) for an interleaved nodal vector field y.
double min_det_F(const Cell& cell, const std::vector<double>& y);

/// Reference data at quadrature points of a nodal scalar field: [phi0, grad phi0 (dim), hess phi0 (dim*dim,
/// row-major)] per point, in that order (the layout of `data phi0`, `data grad_phi0`, `data hess_phi0`).
std::vector<double> reference_qdata(const Cell& cell, const std::vector<double>& phi0);

std::vector<double> random_vector(std::size_t n, double scale, std::mt19937_64& rng);

}  // namespace lmeform::formcheck
