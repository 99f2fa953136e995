#include "cell_fixture.hpp"

#include <lmeform/kernel.hpp>

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>

namespace lmeform::formcheck {

using kernel::hessian_slot;
using kernel::jet_size;

NodeCloud graded_cloud(int nx, int ny, double x0, double x1, double y0, double y1, double grading, double jitter,
                       std::uint64_t seed) {
  if (nx < 2 || ny < 2) throw std::invalid_argument("graded_cloud: need at least 2x2 nodes");
  // Geometric spacing: the last interval is `grading` times the first.
  auto axis = [grading](int m, double a, double b) {
    std::vector<double> t(static_cast<std::size_t>(m));
    const double q = std::pow(grading, 1.0 / std::max(1, m - 2));
    double s = 0.0, len = 1.0;
    std::vector<double> acc{0.0};
    for (int i = 1; i < m; ++i) { s += len; acc.push_back(s); len *= q; }
    for (int i = 0; i < m; ++i) t[i] = a + (b - a) * acc[i] / s;
    return t;
  };
  const std::vector<double> xs = axis(nx, x0, x1), ys = axis(ny, y0, y1);
  NodeCloud c;
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> U(-1.0, 1.0);
  for (int j = 0; j < ny; ++j)
    for (int i = 0; i < nx; ++i) {
      double x = xs[i], y = ys[j];
      if (i > 0 && i < nx - 1) x += jitter * U(rng) * std::min(xs[i] - xs[i - 1], xs[i + 1] - xs[i]);
      if (j > 0 && j < ny - 1) y += jitter * U(rng) * std::min(ys[j] - ys[j - 1], ys[j + 1] - ys[j]);
      c.x.push_back(x);
      c.x.push_back(y);
    }
  const int N = nx * ny;
  c.h.assign(N, std::numeric_limits<double>::max());
  for (int a = 0; a < N; ++a)
    for (int b = 0; b < N; ++b)
      if (a != b) c.h[a] = std::min(c.h[a], std::hypot(c.x[2 * a] - c.x[2 * b], c.x[2 * a + 1] - c.x[2 * b + 1]));
  for (int j = 0; j + 1 < ny; ++j)
    for (int i = 0; i + 1 < nx; ++i) {
      const int v00 = j * nx + i, v10 = v00 + 1, v01 = v00 + nx, v11 = v01 + 1;
      c.triangles.push_back({v00, v10, v11});
      c.triangles.push_back({v00, v11, v01});
    }
  return c;
}

BasisChoice gaussian_basis(double gamma) {
  BasisChoice b;
  b.name = "shepard-gaussian";
  // p_a = w_a / S, w_a = exp(-beta_a |x - x_a|^2), S = sum_b w_b: a partition of unity with exact
  // first and second derivatives (linear fields are reproduced only approximately).
  b.tabulate = [gamma](const NodeCloud& c, const std::vector<int>& ids, const double* x, int order, double* out) {
    const int n = static_cast<int>(ids.size());
    const int J = jet_size(2, order);
    std::vector<double> w(static_cast<std::size_t>(J) * n, 0.0);
    double S[6] = {0, 0, 0, 0, 0, 0};
    for (int k = 0; k < n; ++k) {
      const int a = ids[k];
      const double beta = gamma / (c.h[a] * c.h[a]);
      const double d[2] = {x[0] - c.x[2 * a], x[1] - c.x[2 * a + 1]};
      const double p = std::exp(-beta * (d[0] * d[0] + d[1] * d[1]));
      w[k] = p;
      if (order >= 1)
        for (int i = 0; i < 2; ++i) w[(1 + i) * n + k] = -2.0 * beta * d[i] * p;
      if (order >= 2)
        for (int i = 0; i < 2; ++i)
          for (int j = i; j < 2; ++j)
            w[hessian_slot(i, j, 2) * n + k] = (4.0 * beta * beta * d[i] * d[j] - (i == j ? 2.0 * beta : 0.0)) * p;
      for (int s = 0; s < J; ++s) S[s] += w[s * n + k];
    }
    if (!(S[0] > 0.0)) return false;
    for (int k = 0; k < n; ++k) {
      const double p = w[k] / S[0];
      out[k] = p;
      double g[2] = {0, 0};
      if (order >= 1)
        for (int i = 0; i < 2; ++i) out[(1 + i) * n + k] = g[i] = (w[(1 + i) * n + k] - p * S[1 + i]) / S[0];
      if (order >= 2)
        for (int i = 0; i < 2; ++i)
          for (int j = i; j < 2; ++j) {
            const int s = hessian_slot(i, j, 2);
            out[s * n + k] = (w[s * n + k] - g[i] * S[1 + j] - g[j] * S[1 + i] - p * S[s]) / S[0];
          }
    }
    return true;
  };
  b.radius = [gamma](const NodeCloud& c, int a) { return c.h[a] * std::sqrt(-std::log(1e-6) / gamma); };
  return b;
}

Cell make_cell(const NodeCloud& cloud, int t, const BasisChoice& basis, int order) {
  const auto& tri = cloud.triangles.at(static_cast<std::size_t>(t));
  const double* A = &cloud.x[2 * tri[0]];
  const double* B = &cloud.x[2 * tri[1]];
  const double* C = &cloud.x[2 * tri[2]];
  const double area = 0.5 * std::abs((B[0] - A[0]) * (C[1] - A[1]) - (C[0] - A[0]) * (B[1] - A[1]));
  // Strang-Fix / Dunavant degree-4 rule, 6 points.
  const double a1 = 0.445948490915965, w1 = 0.223381589678011;
  const double a2 = 0.091576213509771, w2 = 0.109951743655322;
  const double bary[6][3] = {{a1, a1, 1 - 2 * a1}, {a1, 1 - 2 * a1, a1}, {1 - 2 * a1, a1, a1},
                             {a2, a2, 1 - 2 * a2}, {a2, 1 - 2 * a2, a2}, {1 - 2 * a2, a2, a2}};
  const double wts[6] = {w1, w1, w1, w2, w2, w2};
  Cell cell;
  cell.dim = 2;
  cell.nq = 6;
  cell.basis_order = order;
  for (int q = 0; q < 6; ++q) {
    cell.weights.push_back(wts[q] * area);
    for (int i = 0; i < 2; ++i) cell.points.push_back(bary[q][0] * A[i] + bary[q][1] * B[i] + bary[q][2] * C[i]);
  }
  std::vector<int> ids;
  for (int a = 0; a < cloud.size(); ++a) {
    const double R = basis.radius(cloud, a);
    for (int q = 0; q < 6; ++q)
      if (std::hypot(cell.points[2 * q] - cloud.x[2 * a], cell.points[2 * q + 1] - cloud.x[2 * a + 1]) <= R) {
        ids.push_back(a);
        break;
      }
  }
  cell.n = static_cast<int>(ids.size());
  for (int a : ids) {
    cell.nodes.push_back(cloud.x[2 * a]);
    cell.nodes.push_back(cloud.x[2 * a + 1]);
  }
  const int J = jet_size(2, order);
  cell.basis.assign(static_cast<std::size_t>(6) * J * cell.n, 0.0);
  for (int q = 0; q < 6; ++q)
    if (!basis.tabulate(cloud, ids, &cell.points[2 * q], order, &cell.basis[static_cast<std::size_t>(q) * J * cell.n]))
      throw std::runtime_error("make_cell: basis '" + basis.name + "' failed at a quadrature point of triangle " +
                               std::to_string(t));
  return cell;
}

int triangle_near(const NodeCloud& cloud, double px, double py) {
  int best = 0;
  double bd = std::numeric_limits<double>::max();
  for (std::size_t t = 0; t < cloud.triangles.size(); ++t) {
    double cx = 0, cy = 0;
    for (int v : cloud.triangles[t]) { cx += cloud.x[2 * v] / 3.0; cy += cloud.x[2 * v + 1] / 3.0; }
    const double d = std::hypot(cx - px, cy - py);
    if (d < bd) { bd = d; best = static_cast<int>(t); }
  }
  return best;
}

std::vector<double> phase_field(const Cell& cell, double cx, double cy, double R, double eps, double noise,
                                std::mt19937_64& rng) {
  std::uniform_real_distribution<double> U(-1.0, 1.0);
  std::vector<double> phi(static_cast<std::size_t>(cell.n));
  for (int a = 0; a < cell.n; ++a) {
    const double d = std::hypot(cell.nodes[2 * a] - cx, cell.nodes[2 * a + 1] - cy);
    phi[a] = std::tanh((R - d) / (std::sqrt(2.0) * eps)) + noise * U(rng);
  }
  return phi;
}

std::vector<double> deformation(const Cell& cell, double amplitude, double noise, std::mt19937_64& rng) {
  std::uniform_real_distribution<double> U(-1.0, 1.0);
  // A fixed non-symmetric affine part (stretch + shear + rotation) plus a smooth wave.
  const double A[2][2] = {{1.15, 0.20}, {-0.10, 0.90}};
  std::vector<double> y(static_cast<std::size_t>(2 * cell.n));
  for (int a = 0; a < cell.n; ++a) {
    const double x0 = cell.nodes[2 * a], x1 = cell.nodes[2 * a + 1];
    y[2 * a] = A[0][0] * x0 + A[0][1] * x1 + 0.3 + amplitude * std::sin(3.0 * x1) + noise * U(rng);
    y[2 * a + 1] = A[1][0] * x0 + A[1][1] * x1 + amplitude * std::cos(2.0 * x0) + noise * U(rng);
  }
  return y;
}

double min_det_F(const Cell& cell, const std::vector<double>& y) {
  double m = std::numeric_limits<double>::max();
  for (int q = 0; q < cell.nq; ++q) {
    double F[2][2];
    for (int i = 0; i < 2; ++i)
      for (int I = 0; I < 2; ++I) F[i][I] = cell.jet(q, 1 + I, y.data(), 2, i);
    m = std::min(m, F[0][0] * F[1][1] - F[0][1] * F[1][0]);
  }
  return m;
}

std::vector<double> reference_qdata(const Cell& cell, const std::vector<double>& phi0) {
  std::vector<double> qd;
  for (int q = 0; q < cell.nq; ++q) {
    qd.push_back(cell.jet(q, 0, phi0.data(), 1, 0));
    for (int I = 0; I < cell.dim; ++I) qd.push_back(cell.jet(q, 1 + I, phi0.data(), 1, 0));
    for (int I = 0; I < cell.dim; ++I)
      for (int K = 0; K < cell.dim; ++K) qd.push_back(cell.jet(q, hessian_slot(I, K, cell.dim), phi0.data(), 1, 0));
  }
  return qd;
}

std::vector<double> random_vector(std::size_t n, double scale, std::mt19937_64& rng) {
  std::uniform_real_distribution<double> U(-1.0, 1.0);
  std::vector<double> v(n);
  for (auto& x : v) x = scale * U(rng);
  return v;
}

}  // namespace lmeform::formcheck
