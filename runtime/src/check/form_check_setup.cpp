#include "lmeform/form_check_setup.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>

#include <Eigen/Dense>
#include <fmt/format.h>

#include "lmeform/node_sets.hpp"

namespace lmeform::formcheck {

using kernel::hessian_slot;
using kernel::jet_size;

const char* to_string(Coordinates c) noexcept { return c == Coordinates::axisymmetric ? "axisymmetric" : "cartesian"; }

namespace {

double smoothstep(double s) {
  s = std::clamp(s, 0.0, 1.0);
  return s * s * (3.0 - 2.0 * s);
}

double distance_to_center(const double* x, const Feature& f) {
  double d2 = 0.0;
  for (int i = 0; i < f.dim; ++i) d2 += (x[i] - f.center[static_cast<std::size_t>(i)]) * (x[i] - f.center[static_cast<std::size_t>(i)]);
  return std::sqrt(d2);
}

struct Grading {
  Feature feature;
  double h_min, h_max, transition;
  [[nodiscard]] double spacing(const double* x) const {
    const double d = std::abs(distance_to_center(x, feature) - feature.radius);
    return h_min + (h_max - h_min) * smoothstep(d / transition);
  }
};

/// 1D: nodes marched from 0 to 1 by the local spacing, stretched to end at 1.
NodeSet graded_line(const Grading& g) {
  std::vector<double> x{0.0};
  while (x.back() < 1.0) x.push_back(x.back() + g.spacing(&x.back()));
  const double stretch = 1.0 / x.back();
  for (double& v : x) v *= stretch;
  return NodeSet(1, std::move(x));
}

/// 3D (or any dimension): greedy Poisson-disk sampling of a jittered candidate lattice at h_min / 2
/// on the unit box; a candidate is taken when no node is closer than the local spacing. Candidates
/// on the faces are not jittered across them, so the box is the hull of the nodes.
NodeSet graded_cloud(int dim, const Grading& g, std::uint64_t seed) {
  const double c = g.h_min / 2.0;
  const int m = static_cast<int>(std::ceil(1.0 / c));
  const double bucket = g.h_max;
  const int nb = static_cast<int>(std::ceil(1.0 / bucket)) + 1;
  std::vector<std::vector<std::size_t>> buckets(static_cast<std::size_t>(std::pow(nb, dim)));
  auto bucket_index = [&](const double* x, std::array<int, 3>& b) {
    std::size_t id = 0;
    for (int i = dim - 1; i >= 0; --i) {
      b[static_cast<std::size_t>(i)] = std::clamp(static_cast<int>(x[i] / bucket), 0, nb - 1);
      id = id * static_cast<std::size_t>(nb) + static_cast<std::size_t>(b[static_cast<std::size_t>(i)]);
    }
    return id;
  };
  std::vector<double> pts;
  SplitMix64 rng(seed);
  std::array<int, 3> idx{0, 0, 0};
  const long total = static_cast<long>(std::pow(m + 1, dim));
  for (long lin = 0; lin < total; ++lin) {
    long rest = lin;
    std::array<double, 3> x{};
    for (int i = 0; i < dim; ++i) {
      idx[static_cast<std::size_t>(i)] = static_cast<int>(rest % (m + 1));
      rest /= (m + 1);
      const int k = idx[static_cast<std::size_t>(i)];
      const double jitter = (k == 0 || k == m) ? 0.0 : 0.7 * (rng.uniform() - 0.5) * c;
      x[static_cast<std::size_t>(i)] = std::min(1.0, k * c + jitter);
    }
    const double r = g.spacing(x.data());
    std::array<int, 3> b{};
    bucket_index(x.data(), b);
    bool free = true;
    std::array<int, 3> lo{0, 0, 0}, hi{0, 0, 0}, q{0, 0, 0};
    for (int i = 0; i < dim; ++i) {
      lo[static_cast<std::size_t>(i)] = std::max(0, b[static_cast<std::size_t>(i)] - 1);
      hi[static_cast<std::size_t>(i)] = std::min(nb - 1, b[static_cast<std::size_t>(i)] + 1);
    }
    q = lo;
    while (free) {
      std::size_t id = 0;
      for (int i = dim - 1; i >= 0; --i) id = id * static_cast<std::size_t>(nb) + static_cast<std::size_t>(q[static_cast<std::size_t>(i)]);
      for (const std::size_t p : buckets[id]) {
        double d2 = 0.0;
        for (int i = 0; i < dim; ++i) d2 += (pts[p * dim + i] - x[static_cast<std::size_t>(i)]) * (pts[p * dim + i] - x[static_cast<std::size_t>(i)]);
        if (d2 < r * r) { free = false; break; }
      }
      int i = 0;
      while (i < dim && ++q[static_cast<std::size_t>(i)] > hi[static_cast<std::size_t>(i)]) {
        q[static_cast<std::size_t>(i)] = lo[static_cast<std::size_t>(i)];
        ++i;
      }
      if (i == dim) break;
    }
    if (!free) continue;
    const std::size_t id = pts.size() / static_cast<std::size_t>(dim);
    pts.insert(pts.end(), x.begin(), x.begin() + dim);
    buckets[bucket_index(x.data(), b)].push_back(id);
  }
  return NodeSet(dim, std::move(pts));
}

}  // namespace

CheckGeometry::CheckGeometry(const GeometryOptions& o) : coordinates_(o.coordinates) {
  const int d = o.dim;
  if (d < 1 || d > 3) throw std::invalid_argument(fmt::format("CheckGeometry: dimension must be 1, 2 or 3, got {}", d));
  const bool axi = o.coordinates == Coordinates::axisymmetric;
  const double h_min = o.h_min > 0 ? o.h_min : d == 1 ? 0.04 : d == 2 ? 0.03 : 0.07;
  const double h_max = o.h_max > 0 ? o.h_max : (d == 2 ? 4.0 : 3.0) * h_min;
  feature_.dim = d;
  feature_.radius = o.radius;
  if (o.center) {
    feature_.center = *o.center;
  } else {
    feature_.center = {0.5, 0.5, 0.5};
    if (axi) feature_.center[0] = 0.0;
  }
  const Grading grading{feature_, h_min, h_max, o.transition};
  if (d == 2) {
    GradedGridOptions go;
    go.h_min = h_min;
    go.h_max = h_max;
    go.center = {feature_.center[0], feature_.center[1]};
    go.radius = o.radius;
    go.transition = o.transition;
    go.seed = o.seed;
    nodes_ = graded_grid_2d(go);
  } else if (d == 1) {
    nodes_ = graded_line(grading);
  } else {
    nodes_ = graded_cloud(d, grading, o.seed);
  }
  cells_ = delaunay(nodes_);
  LmeOptions lme;
  lme.consistency = o.basis;
  if (axi) {
    // Bodies of revolution: the basis is even across the axis, as in the runtime's axisymmetric runs.
    lme.mirrors = {MirrorPlane{0, 0.0}};
  }
  const double gamma = o.gamma > 0 ? o.gamma : d == 3 && o.basis == LmeConsistency::first ? 1.8 : 0.8;
  basis_ = std::make_shared<const LmeBasis>(nodes_, std::span<const double>(&gamma, 1), lme);
  h_min_ = *std::min_element(basis_->spacing().begin(), basis_->spacing().end());
  rule_ = d == 1 ? gauss_legendre(3) : simplex_rule(d, 4);
}

Cell CheckGeometry::cell(std::size_t c, int order) const {
  const int d = dim();
  const auto v = cells_.cell(c);
  Cell cell;
  cell.dim = d;
  cell.nq = static_cast<int>(rule_.size());
  cell.basis_order = order;
  const double scale = cells_.measures[c] / reference_measure(d);
  const double* x0 = &nodes_.coords[static_cast<std::size_t>(v[0]) * d];
  for (std::size_t q = 0; q < rule_.size(); ++q) {
    cell.weights.push_back(rule_.weights[q] * scale);
    for (int i = 0; i < d; ++i) {
      double x = x0[i];
      for (int k = 0; k < d; ++k)
        x += rule_.points[q * d + static_cast<std::size_t>(k)] *
             (nodes_.coords[static_cast<std::size_t>(v[static_cast<std::size_t>(k) + 1]) * d + i] - x0[i]);
      cell.points.push_back(x);
    }
  }
  const CsrLists lists = basis_->neighbour_lists(cell.points);
  std::vector<int> ids(lists.indices.begin(), lists.indices.end());
  std::sort(ids.begin(), ids.end());
  ids.erase(std::unique(ids.begin(), ids.end()), ids.end());
  cell.n = static_cast<int>(ids.size());
  for (const int a : ids) {
    const auto p = nodes_.point(static_cast<std::size_t>(a));
    cell.nodes.insert(cell.nodes.end(), p.begin(), p.end());
  }
  cell.basis.assign(static_cast<std::size_t>(cell.nq) * jet_size(d, order) * cell.n, 0.0);
  LmeWorkspace ws;
  basis_->tabulate_cell(cell.points, ids, order, cell.basis, ws);
  return cell;
}

std::size_t CheckGeometry::cell_near(std::span<const double> x) const {
  const long found = locate_cell_brute_force(cells_, nodes_, x);
  if (found >= 0) return static_cast<std::size_t>(found);
  const int d = dim();
  std::size_t best = 0;
  double best_d2 = std::numeric_limits<double>::max();
  for (std::size_t c = 0; c < cells_.size(); ++c) {
    double d2 = 0.0;
    for (int i = 0; i < d; ++i) {
      double centroid = 0.0;
      for (const int v : cells_.cell(c)) centroid += nodes_.coords[static_cast<std::size_t>(v) * d + i] / (d + 1);
      d2 += (centroid - x[static_cast<std::size_t>(i)]) * (centroid - x[static_cast<std::size_t>(i)]);
    }
    if (d2 < best_d2) { best_d2 = d2; best = c; }
  }
  return best;
}

std::vector<Cell> CheckGeometry::check_cells(int order, bool vector_fields) const {
  const int d = dim();
  const auto& c = feature_.center;
  const double R = feature_.radius;
  // A generic direction (no axis-aligned symmetry) for the interface cell.
  static constexpr std::array<std::array<double, 3>, 4> directions{{{1, 0, 0}, {1, 0, 0}, {0.6, 0.8, 0}, {0.48, 0.6, 0.64}}};
  const auto& u = directions[static_cast<std::size_t>(d)];
  std::vector<std::array<double, 3>> targets;
  std::array<double, 3> on{}, second{};
  for (int i = 0; i < d; ++i) on[static_cast<std::size_t>(i)] = c[static_cast<std::size_t>(i)] + R * u[static_cast<std::size_t>(i)];
  targets.push_back(on);
  if (coordinates_ == Coordinates::axisymmetric && d >= 2) {
    // Where the interface meets the axis: the points closest to r = 0 that a form meets (a row
    // off the axis for vector fields, which the even basis cannot give a radial derivative there).
    second = c;
    second[0] = (vector_fields ? 1.5 : 0.5) * h_min_;
    second[1] = c[1] + R;
  } else {
    for (int i = 0; i < d; ++i) second[static_cast<std::size_t>(i)] = c[static_cast<std::size_t>(i)] - 0.5 * R * u[static_cast<std::size_t>(d - 1 - i)];
  }
  targets.push_back(second);
  std::vector<Cell> out;
  for (const auto& t : targets) out.push_back(cell(cell_near(std::span<const double>(t.data(), static_cast<std::size_t>(d))), order));
  return out;
}

std::vector<double> smooth_scalar_field(const Cell& cell, const Feature& feature, double width, double noise,
                                        std::mt19937_64& rng) {
  std::uniform_real_distribution<double> U(-1.0, 1.0);
  std::vector<double> f(static_cast<std::size_t>(cell.n));
  for (int a = 0; a < cell.n; ++a) {
    const double r = distance_to_center(&cell.nodes[static_cast<std::size_t>(a) * cell.dim], feature);
    f[static_cast<std::size_t>(a)] = 0.9 * std::tanh((feature.radius - r) / (std::sqrt(2.0) * width)) + noise * U(rng);
  }
  return f;
}

std::vector<double> near_identity_field(const Cell& cell, double amplitude, double noise, Coordinates coordinates,
                                        std::mt19937_64& rng) {
  std::uniform_real_distribution<double> U(-1.0, 1.0);
  const int d = cell.dim;
  double M[3][3], phase[3];
  for (auto& row : M)
    for (double& m : row) m = U(rng);
  for (double& p : phase) p = 3.0 * U(rng);
  const bool axi = coordinates == Coordinates::axisymmetric && d >= 2;
  std::vector<double> y(static_cast<std::size_t>(d) * cell.n);
  for (int a = 0; a < cell.n; ++a) {
    const double* x = &cell.nodes[static_cast<std::size_t>(a) * d];
    for (int i = 0; i < d; ++i) {
      double yi = 0.0;
      if (axi && i == 0) {
        // The radius: y_r = r (1 + ...) keeps the axis in place and y_r > 0.
        yi = x[0] * (1.0 + amplitude * (M[0][1] * x[1] + std::sin(3.0 * x[1] + phase[0]) / 3.0));
      } else {
        // A non-symmetric linear part and a wave along another axis: grad y - I = O(amplitude).
        // Axisymmetric: r enters as r^2, so the field stays even across the axis.
        auto coordinate = [&](int k) { return axi && k == 0 ? x[0] * x[0] : x[k]; };
        double p = std::sin(3.0 * coordinate((i + 1) % d) + phase[i]) / 3.0;
        for (int k = 0; k < d; ++k) p += M[i][k] * coordinate(k);
        yi = x[i] + amplitude * p;
      }
      y[static_cast<std::size_t>(a) * d + i] = yi + noise * U(rng) * (axi && i == 0 ? x[0] : 1.0);
    }
  }
  return y;
}

double min_det_grad(const Cell& cell, const std::vector<double>& nodal, int stride, int offset) {
  const int d = cell.dim;
  double m = std::numeric_limits<double>::max();
  Eigen::MatrixXd F(d, d);
  for (int q = 0; q < cell.nq; ++q) {
    for (int i = 0; i < d; ++i)
      for (int I = 0; I < d; ++I) F(i, I) = cell.jet(q, 1 + I, nodal.data(), stride, offset + i);
    m = std::min(m, F.determinant());
  }
  return m;
}

std::vector<double> jet_qdata(const Cell& cell, const std::vector<std::vector<double>>& fields,
                              const std::vector<int>& sizes, std::mt19937_64& rng) {
  std::uniform_real_distribution<double> U(-1.0, 1.0);
  const int d = cell.dim;
  const bool hessians = cell.basis_order >= 2;
  // Per point, every datum in order; each size-1 datum moves on to the next field.
  std::vector<int> field_of(sizes.size(), 0);
  int field = -1;
  for (std::size_t k = 0; k < sizes.size(); ++k) {
    if (sizes[k] == 1 || field < 0) ++field;
    field_of[k] = fields.empty() ? 0 : field % static_cast<int>(fields.size());
  }
  std::vector<double> qd;
  for (int q = 0; q < cell.nq; ++q)
    for (std::size_t k = 0; k < sizes.size(); ++k) {
      const double* f = fields.empty() ? nullptr : fields[static_cast<std::size_t>(field_of[k])].data();
      const int s = sizes[k];
      if (f && s == 1) {
        qd.push_back(cell.jet(q, 0, f, 1, 0));
      } else if (f && s == d) {
        for (int I = 0; I < d; ++I) qd.push_back(cell.jet(q, 1 + I, f, 1, 0));
      } else if (f && s == d * d && hessians) {
        for (int I = 0; I < d; ++I)
          for (int K = 0; K < d; ++K) qd.push_back(cell.jet(q, hessian_slot(I, K, d), f, 1, 0));
      } else {
        for (int i = 0; i < s; ++i) qd.push_back(0.1 * U(rng));
      }
    }
  return qd;
}

std::vector<double> reference_qdata(const Cell& cell, const std::vector<double>& phi0) {
  std::mt19937_64 unused(0);
  return jet_qdata(cell, {phi0}, {1, cell.dim, cell.dim * cell.dim}, unused);
}

std::vector<double> random_vector(std::size_t n, double scale, std::mt19937_64& rng) {
  std::uniform_real_distribution<double> U(-1.0, 1.0);
  std::vector<double> v(n);
  for (auto& x : v) x = scale * U(rng);
  return v;
}

namespace {

/// Fills the fields of one layout (unknowns or coefficients) at nodal[a * stride + offset + c].
/// Returns min det grad y over its vector fields (infinity when there are none).
double fill_fields(const kernel::FieldInfo* fields, int n_fields, int stride, const Cell& cell,
                   const CheckGeometry& geometry, const StateOptions& options, double amplitude, std::mt19937_64& rng,
                   std::vector<double>& nodal, std::vector<double>* scales) {
  const int d = cell.dim;
  const double width = options.width > 0 ? options.width : 2.0 * geometry.h_min();
  nodal.assign(static_cast<std::size_t>(stride) * cell.n, 0.0);
  if (scales) scales->assign(nodal.size(), 1.0);
  double min_det = std::numeric_limits<double>::infinity();
  int offset = 0;
  for (int f = 0; f < n_fields; ++f) {
    const int comps = fields[f].components;
    const bool vector = comps == d && d > 1;
    if (vector) {
      const auto y = near_identity_field(cell, amplitude, 0.05 * geometry.h_min(), geometry.coordinates(), rng);
      for (int a = 0; a < cell.n; ++a)
        for (int c = 0; c < d; ++c) {
          const std::size_t at = static_cast<std::size_t>(a) * stride + offset + c;
          nodal[at] = y[static_cast<std::size_t>(a) * d + c];
          if (scales) (*scales)[at] = geometry.h_min();
        }
      min_det = std::min(min_det, min_det_grad(cell, nodal, stride, offset));
    } else {
      for (int c = 0; c < comps; ++c) {
        const auto s = smooth_scalar_field(cell, geometry.feature(), width, options.noise, rng);
        for (int a = 0; a < cell.n; ++a) nodal[static_cast<std::size_t>(a) * stride + offset + c] = s[static_cast<std::size_t>(a)];
      }
    }
    offset += comps;
  }
  return min_det;
}

}  // namespace

std::vector<double> radial_normals(const Cell& cell, const Feature& feature) {
  const std::size_t d = static_cast<std::size_t>(cell.dim);
  std::vector<double> normals(static_cast<std::size_t>(cell.nq) * d, 0.0);
  for (std::size_t q = 0; q < static_cast<std::size_t>(cell.nq); ++q) {
    const double* x = cell.points.data() + q * d;
    double* nq = normals.data() + q * d;
    const double r = distance_to_center(x, feature);
    if (!(r > 0.0)) {
      nq[0] = 1.0;
      continue;
    }
    for (std::size_t i = 0; i < d; ++i) nq[i] = (x[i] - feature.center[i]) / r;
  }
  return normals;
}

CheckCase generic_case(const kernel::FormKernels& form, const Cell& cell, const CheckGeometry& geometry,
                       const std::vector<double>& constants, const StateOptions& options, std::mt19937_64& rng) {
  CheckCase cc;
  cc.state.constants = constants;
  // The random draws of one attempt are reproducible from its seed; a smaller amplitude is tried
  // until every vector field keeps det grad y above the bound.
  const std::uint64_t seed = rng();
  double amplitude = options.perturbation;
  for (int attempt = 0;; ++attempt) {
    std::mt19937_64 draw(seed);
    const double det_u = fill_fields(form.unknowns, form.n_unknowns, form.dofs_per_node, cell, geometry, options,
                                     amplitude, draw, cc.state.unknowns, &cc.dof_scales);
    const double det_c = fill_fields(form.coefficients, form.n_coefficients, form.coefficient_components_per_node,
                                     cell, geometry, options, amplitude, draw, cc.state.coefficients, nullptr);
    const double det = std::min(det_u, det_c);
    if (!(det < options.min_det)) {
      cc.min_det = std::isfinite(det) ? det : std::numeric_limits<double>::quiet_NaN();
      std::vector<std::vector<double>> fields;
      const double width = options.width > 0 ? options.width : 2.0 * geometry.h_min();
      for (int k = 0; k < std::max(1, form.n_qdata); ++k)
        fields.push_back(smooth_scalar_field(cell, geometry.feature(), width, options.noise, draw));
      std::vector<int> sizes;
      for (int k = 0; k < form.n_qdata; ++k) sizes.push_back(form.qdata[k].size);
      cc.state.qdata = jet_qdata(cell, fields, sizes, draw);
      if (cc.state.qdata.size() != static_cast<std::size_t>(cell.nq) * form.qdata_per_point)
        throw std::runtime_error(fmt::format("{}::{}: qdata sizes add up to {} per point, the kernel reads {}", form.module,
                                             form.name, cc.state.qdata.size() / std::max(1, cell.nq),
                                             form.qdata_per_point));
      cc.direction.resize(cc.state.unknowns.size());
      std::uniform_real_distribution<double> U(-1.0, 1.0);
      for (std::size_t i = 0; i < cc.direction.size(); ++i) cc.direction[i] = cc.dof_scales[i] * U(draw);
      return cc;
    }
    if (attempt == 6)
      throw std::runtime_error(fmt::format("{}::{}: no near-identity state keeps det grad y >= {} on the check cell "
                                           "(min {:.3g} at amplitude {:.3g})",
                                           form.module, form.name, options.min_det, det, amplitude));
    amplitude *= 0.5;
  }
}

}  // namespace lmeform::formcheck
