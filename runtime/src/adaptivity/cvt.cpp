// CVT node relocation (Lloyd iterations on a sampled density), nodal spacing and the eps >= 2 h_min
// resolution check. See lmeform/cvt.hpp and docs/adaptivity.md.
#include "lmeform/cvt.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <sstream>
#include <stdexcept>
#include <string>
#include <unordered_map>
#include <utility>
#include <vector>

#include "lmeform/delaunay.hpp"
#include "lmeform/neighbour_search.hpp"

namespace lmeform {
namespace {

std::string fmt(double v) {
  std::ostringstream os;
  os.precision(6);
  os << v;
  return os.str();
}

void check_coincident(const KdTree& tree, const char* who) {
  const NodeSet& nodes = tree.nodes();
  std::vector<int> idx;
  std::vector<double> dist;
  for (std::size_t a = 0; a < nodes.size(); ++a) {
    tree.knn(nodes.point(a), 2, idx, &dist);
    for (std::size_t j = 0; j < idx.size(); ++j) {
      if (idx[j] != static_cast<int>(a) && !(dist[j] > 0.0)) {
        throw std::invalid_argument(std::string(who) + ": nodes " + std::to_string(a) + " and " +
                                    std::to_string(idx[j]) + " coincide");
      }
    }
  }
}

// Circumcentre of a simplex (dim + 1 vertices): solve 2 (x_k - x_0) . c = |x_k|^2 - |x_0|^2.
std::array<double, 3> circumcentre(const NodeSet& nodes, std::span<const int> v) {
  const int d = nodes.dim;
  std::array<std::array<double, 4>, 3> m{};
  auto x0 = nodes.point(static_cast<std::size_t>(v[0]));
  double n0 = 0.0;
  for (int i = 0; i < d; ++i) n0 += x0[static_cast<std::size_t>(i)] * x0[static_cast<std::size_t>(i)];
  for (int k = 1; k <= d; ++k) {
    auto xk = nodes.point(static_cast<std::size_t>(v[static_cast<std::size_t>(k)]));
    double nk = 0.0;
    for (int i = 0; i < d; ++i) {
      const auto ii = static_cast<std::size_t>(i);
      m[static_cast<std::size_t>(k - 1)][ii] = 2.0 * (xk[ii] - x0[ii]);
      nk += xk[ii] * xk[ii];
    }
    m[static_cast<std::size_t>(k - 1)][3] = nk - n0;
  }
  const auto du = static_cast<std::size_t>(d);
  for (std::size_t c = 0; c < du; ++c) {  // Gaussian elimination with partial pivoting
    std::size_t p = c;
    for (std::size_t r = c + 1; r < du; ++r) {
      if (std::abs(m[r][c]) > std::abs(m[p][c])) p = r;
    }
    std::swap(m[c], m[p]);
    for (std::size_t r = c + 1; r < du; ++r) {
      const double f = m[r][c] / m[c][c];
      for (std::size_t j = c; j < du; ++j) m[r][j] -= f * m[c][j];
      m[r][3] -= f * m[c][3];
    }
  }
  std::array<double, 3> x{};
  for (std::size_t c = du; c-- > 0;) {
    double s = m[c][3];
    for (std::size_t j = c + 1; j < du; ++j) s -= m[c][j] * x[j];
    x[c] = s / m[c][c];
  }
  return x;
}

}  // namespace

// ---------------------------------------------------------------------------------------------
// CVT

NodeSet cvt_relocate(const NodeSet& nodes, const Box& box, const Density& density, const CvtOptions& options,
                     CvtReport* report) {
  const char* who = "cvt_relocate";
  box.validate(who);
  const int d = nodes.dim;
  if (d != box.dim) {
    throw std::invalid_argument(std::string(who) + ": node dimension " + std::to_string(d) +
                                " differs from box dimension " + std::to_string(box.dim));
  }
  if (!density) throw std::invalid_argument(std::string(who) + ": no density given");
  if (options.iterations < 0) throw std::invalid_argument(std::string(who) + ": iterations must be >= 0");
  if (!(options.samples_per_node >= 1.0) || !std::isfinite(options.samples_per_node)) {
    throw std::invalid_argument(std::string(who) + ": samples_per_node must be >= 1, got " +
                                fmt(options.samples_per_node));
  }
  if (!(options.tolerance >= 0.0)) throw std::invalid_argument(std::string(who) + ": tolerance must be >= 0");
  const std::size_t n = nodes.size();
  if (n < 2) throw std::invalid_argument(std::string(who) + ": need at least 2 nodes, got " + std::to_string(n));
  const auto du = static_cast<std::size_t>(d);

  double volume = 1.0, diag2 = 0.0;
  for (std::size_t i = 0; i < du; ++i) {
    const double L = box.hi[i] - box.lo[i];
    volume *= L;
    diag2 += L * L;
  }
  const double btol = options.boundary_tolerance * std::sqrt(diag2);

  // Boundary membership: fixed[a*d+i] is true when coordinate i of node a lies on a face.
  std::vector<char> fixed(n * du, 0);
  NodeSet current = nodes;
  for (std::size_t a = 0; a < n; ++a) {
    for (std::size_t i = 0; i < du; ++i) {
      double& x = current.coords[a * du + i];
      if (!(x >= box.lo[i] - btol && x <= box.hi[i] + btol)) {
        throw std::invalid_argument(std::string(who) + ": node " + std::to_string(a) + " lies outside the box (coordinate " +
                                    std::to_string(i) + " = " + fmt(x) + ")");
      }
      if (std::abs(x - box.lo[i]) <= btol) {
        fixed[a * du + i] = 1;
        x = box.lo[i];
      } else if (std::abs(x - box.hi[i]) <= btol) {
        fixed[a * du + i] = 1;
        x = box.hi[i];
      }
    }
  }
  check_coincident(KdTree(current), who);

  // Samples: one jittered point per cell of a lattice with about samples_per_node * n cells.
  const double target = options.samples_per_node * static_cast<double>(n);
  const double s = std::pow(volume / target, 1.0 / d);
  std::array<std::size_t, 3> counts{1, 1, 1};
  std::array<double, 3> cell{};
  std::size_t m = 1;
  for (std::size_t i = 0; i < du; ++i) {
    const double L = box.hi[i] - box.lo[i];
    counts[i] = static_cast<std::size_t>(std::max(1.0, std::ceil(L / s)));
    cell[i] = L / static_cast<double>(counts[i]);
    m *= counts[i];
  }
  const double cell_volume = volume / static_cast<double>(m);
  std::vector<double> samples(m * du);
  std::vector<double> weight(m);
  SplitMix64 rng(options.seed);
  std::array<double, 3> x{};
  for (std::size_t q = 0; q < m; ++q) {
    std::size_t rest = q;
    for (std::size_t i = 0; i < du; ++i) {  // x varies fastest
      const std::size_t k = rest % counts[i];
      rest /= counts[i];
      x[i] = box.lo[i] + (static_cast<double>(k) + rng.uniform()) * cell[i];
      samples[q * du + i] = x[i];
    }
    const double rho = density(std::span<const double>(x.data(), du));
    if (!(rho > 0.0) || !std::isfinite(rho)) {
      throw std::invalid_argument(std::string(who) + ": the density must be positive and finite, got " + fmt(rho) +
                                  " at sample " + std::to_string(q));
    }
    weight[q] = rho * cell_volume;
  }

  CvtReport local;
  local.samples = m;
  local.h_bar = std::pow(volume / static_cast<double>(n), 1.0 / d);

  std::vector<double> wsum(n), xsum(n * du);
  std::vector<int> idx;
  for (int it = 0; it < options.iterations; ++it) {
    const KdTree tree(current);
    std::fill(wsum.begin(), wsum.end(), 0.0);
    std::fill(xsum.begin(), xsum.end(), 0.0);
    for (std::size_t q = 0; q < m; ++q) {
      tree.knn(std::span<const double>(samples.data() + q * du, du), 1, idx);
      const auto a = static_cast<std::size_t>(idx[0]);
      wsum[a] += weight[q];
      for (std::size_t i = 0; i < du; ++i) xsum[a * du + i] += weight[q] * samples[q * du + i];
    }
    CvtIteration rec;
    double total = 0.0;
    for (std::size_t a = 0; a < n; ++a) {
      if (!(wsum[a] > 0.0)) {
        ++rec.empty_cells;
        continue;
      }
      double d2 = 0.0;
      for (std::size_t i = 0; i < du; ++i) {
        if (fixed[a * du + i]) continue;
        double& xi = current.coords[a * du + i];
        const double c = std::clamp(xsum[a * du + i] / wsum[a], box.lo[i], box.hi[i]);
        d2 += (c - xi) * (c - xi);
        xi = c;
      }
      const double disp = std::sqrt(d2);
      total += disp;
      rec.max_displacement = std::max(rec.max_displacement, disp);
    }
    rec.mean_displacement = total / static_cast<double>(n);
    local.iterations.push_back(rec);
    if (options.tolerance > 0.0 && rec.mean_displacement < options.tolerance * local.h_bar) {
      local.converged = true;
      break;
    }
  }
  if (report) *report = std::move(local);
  return current;
}

// ---------------------------------------------------------------------------------------------
// Densities

Density phase_field_density(double f, std::function<double(std::span<const double>)> grad_norm) {
  if (!(f >= 0.0) || !std::isfinite(f)) {
    throw std::invalid_argument("phase_field_density: the amplification factor f must be >= 0, got " + fmt(f));
  }
  if (!grad_norm) throw std::invalid_argument("phase_field_density: no |grad phi| given");
  return [f, g = std::move(grad_norm)](std::span<const double> x) {
    const double v = g(x);
    if (!(v >= 0.0) || !std::isfinite(v)) {
      throw std::invalid_argument("phase_field_density: |grad phi| must be >= 0 and finite, got " + fmt(v));
    }
    return 1.0 + f * v;
  };
}

namespace {
struct NodalInterpolant {
  NodeSet nodes;
  BackgroundCells cells;
  std::vector<double> values;
  KdTree tree;
  std::unique_ptr<CellLocator> locator;
  NodalInterpolant(const NodeSet& n, std::span<const double> v)
      : nodes(n), cells(delaunay(n)), values(v.begin(), v.end()), tree(n) {
    locator = std::make_unique<CellLocator>(cells, nodes);
  }
  double operator()(std::span<const double> x) const {
    const long c = locator->locate(x, 1e-10);
    if (c < 0) {
      std::vector<int> idx;
      tree.knn(x, 1, idx);
      return values[static_cast<std::size_t>(idx[0])];
    }
    const auto lam = barycentric(cells, nodes, static_cast<std::size_t>(c), x);
    const auto cv = cells.cell(static_cast<std::size_t>(c));
    double s = 0.0;
    for (std::size_t k = 0; k < cv.size(); ++k) s += lam[k] * values[static_cast<std::size_t>(cv[k])];
    return std::max(0.0, s);
  }
};
}  // namespace

Density phase_field_density(double f, const NodeSet& nodes, std::span<const double> grad_norm_at_nodes) {
  if (grad_norm_at_nodes.size() != nodes.size()) {
    throw std::invalid_argument("phase_field_density: " + std::to_string(grad_norm_at_nodes.size()) +
                                " values of |grad phi| for " + std::to_string(nodes.size()) + " nodes");
  }
  for (std::size_t a = 0; a < grad_norm_at_nodes.size(); ++a) {
    if (!(grad_norm_at_nodes[a] >= 0.0) || !std::isfinite(grad_norm_at_nodes[a])) {
      throw std::invalid_argument("phase_field_density: |grad phi| at node " + std::to_string(a) +
                                  " must be >= 0 and finite, got " + fmt(grad_norm_at_nodes[a]));
    }
  }
  auto interp = std::make_shared<const NodalInterpolant>(nodes, grad_norm_at_nodes);
  return phase_field_density(f, [interp](std::span<const double> x) { return (*interp)(x); });
}

// ---------------------------------------------------------------------------------------------
// Nodal spacing and the resolution check

std::vector<double> voronoi_ring_spacing(const NodeSet& nodes) {
  const char* who = "voronoi_ring_spacing";
  const int d = nodes.dim;
  const std::size_t n = nodes.size();
  if (d < 1 || n < static_cast<std::size_t>(d) + 1) {
    throw std::invalid_argument(std::string(who) + ": need at least dim + 1 nodes, got " + std::to_string(n));
  }
  check_coincident(KdTree(nodes), who);
  const BackgroundCells cells = delaunay(nodes);
  const auto du = static_cast<std::size_t>(d);

  // The Voronoi facet dual to a Delaunay edge is the convex hull of the circumcentres of the cells
  // around the edge, extended (for an edge on the convex hull) by rays along the normals of its
  // hull facets; it is clipped by the domain. The edge joins Voronoi neighbours when that facet has
  // positive measure: in 2D when the circumcentres are not one point or the edge is on the hull
  // (one cell: the facet is a ray), in 3D when the points (rays included) are not collinear. The
  // diagonals of the squares / cubes of regular grids fail this: their facets are points/segments.
  struct EdgeInfo {
    std::vector<std::array<double, 3>> points;
    double length = 0.0;
    int cells = 0;
  };
  std::unordered_map<std::uint64_t, EdgeInfo> edges;
  edges.reserve(n * 4 * du);
  auto edge_key = [](int i, int j) {
    return (static_cast<std::uint64_t>(std::min(i, j)) << 32) | static_cast<std::uint64_t>(std::max(i, j));
  };
  std::vector<std::array<double, 3>> centres(cells.size());
  for (std::size_t c = 0; c < cells.size(); ++c) {
    const auto v = cells.cell(c);
    centres[c] = d == 1 ? std::array<double, 3>{} : circumcentre(nodes, v);
    for (std::size_t i = 0; i < v.size(); ++i) {
      for (std::size_t j = i + 1; j < v.size(); ++j) {
        EdgeInfo& e = edges[edge_key(v[i], v[j])];
        if (e.cells == 0) {
          double l2 = 0.0;
          for (std::size_t k = 0; k < du; ++k) {
            const double t = nodes.coords[static_cast<std::size_t>(v[i]) * du + k] -
                             nodes.coords[static_cast<std::size_t>(v[j]) * du + k];
            l2 += t * t;
          }
          e.length = std::sqrt(l2);
        }
        if (d >= 2) e.points.push_back(centres[c]);
        ++e.cells;
      }
    }
  }
  if (d == 3) {
    // Hull facets: triangles of exactly one tetrahedron; each adds the point centre + L n to its edges.
    if (n >= (std::size_t{1} << 21)) throw std::invalid_argument(std::string(who) + ": too many nodes for 3D");
    auto facet_key = [](std::array<int, 3> t) {
      std::sort(t.begin(), t.end());
      return (static_cast<std::uint64_t>(t[0]) << 42) | (static_cast<std::uint64_t>(t[1]) << 21) |
             static_cast<std::uint64_t>(t[2]);
    };
    std::unordered_map<std::uint64_t, std::pair<int, std::size_t>> facets;  // count, owning cell
    facets.reserve(cells.size() * 4);
    for (std::size_t c = 0; c < cells.size(); ++c) {
      const auto v = cells.cell(c);
      for (std::size_t skip = 0; skip < 4; ++skip) {
        std::array<int, 3> t{};
        std::size_t k = 0;
        for (std::size_t i = 0; i < 4; ++i) {
          if (i != skip) t[k++] = v[i];
        }
        auto& f = facets[facet_key(t)];
        ++f.first;
        f.second = c;
      }
    }
    for (const auto& [key, f] : facets) {
      if (f.first != 1) continue;
      const std::array<std::size_t, 3> t{static_cast<std::size_t>(key >> 42),
                                         static_cast<std::size_t>((key >> 21) & 0x1fffffULL),
                                         static_cast<std::size_t>(key & 0x1fffffULL)};
      std::array<double, 3> u{}, w{};
      for (std::size_t k = 0; k < 3; ++k) {
        u[k] = nodes.coords[t[1] * 3 + k] - nodes.coords[t[0] * 3 + k];
        w[k] = nodes.coords[t[2] * 3 + k] - nodes.coords[t[0] * 3 + k];
      }
      std::array<double, 3> nrm{u[1] * w[2] - u[2] * w[1], u[2] * w[0] - u[0] * w[2], u[0] * w[1] - u[1] * w[0]};
      const double len = std::sqrt(nrm[0] * nrm[0] + nrm[1] * nrm[1] + nrm[2] * nrm[2]);
      for (std::size_t i = 0; i < 3; ++i) {
        for (std::size_t j = i + 1; j < 3; ++j) {
          EdgeInfo& e = edges.at(edge_key(static_cast<int>(t[i]), static_cast<int>(t[j])));
          std::array<double, 3> p = centres[f.second];
          for (std::size_t k = 0; k < 3; ++k) p[k] += e.length * nrm[k] / len;
          e.points.push_back(p);
        }
      }
    }
  }
  auto positive_facet = [d](const EdgeInfo& e) {
    if (d == 1) return true;
    const double tol = 1e-8 * e.length;
    const auto& p = e.points;
    auto dist2 = [](const std::array<double, 3>& x, const std::array<double, 3>& y) {
      return (x[0] - y[0]) * (x[0] - y[0]) + (x[1] - y[1]) * (x[1] - y[1]) + (x[2] - y[2]) * (x[2] - y[2]);
    };
    std::size_t far = 0;
    for (std::size_t k = 1; k < p.size(); ++k) {
      if (dist2(p[k], p[0]) > dist2(p[far], p[0])) far = k;
    }
    const double span = std::sqrt(dist2(p[far], p[0]));
    if (d == 2) return e.cells == 1 || span > tol;
    if (span <= tol) return false;
    std::array<double, 3> dir{};
    for (std::size_t k = 0; k < 3; ++k) dir[k] = (p[far][k] - p[0][k]) / span;
    for (const auto& q : p) {  // distance of q from the line through p[0] along dir
      std::array<double, 3> r{q[0] - p[0][0], q[1] - p[0][1], q[2] - p[0][2]};
      const double t = r[0] * dir[0] + r[1] * dir[1] + r[2] * dir[2];
      for (std::size_t k = 0; k < 3; ++k) r[k] -= t * dir[k];
      if (std::sqrt(r[0] * r[0] + r[1] * r[1] + r[2] * r[2]) > tol) return true;
    }
    return false;
  };
  std::vector<double> sum(n, 0.0);
  std::vector<int> count(n, 0);
  for (const auto& [key, e] : edges) {
    if (!positive_facet(e)) continue;
    const auto a = static_cast<std::size_t>(key >> 32);
    const auto b = static_cast<std::size_t>(key & 0xffffffffULL);
    sum[a] += e.length;
    sum[b] += e.length;
    ++count[a];
    ++count[b];
  }
  std::vector<double> h(n);
  for (std::size_t a = 0; a < n; ++a) {
    if (count[a] == 0) throw std::runtime_error(std::string(who) + ": node " + std::to_string(a) + " has no Voronoi neighbour");
    h[a] = sum[a] / count[a];
  }
  return h;
}

SpacingSummary spacing_summary(const NodeSet& nodes, const SpacingOptions& options) {
  if (!(options.h_min_quantile >= 0.0 && options.h_min_quantile <= 1.0)) {
    throw std::invalid_argument("spacing_summary: h_min_quantile must lie in [0, 1], got " + fmt(options.h_min_quantile));
  }
  SpacingSummary s;
  if (options.measure == SpacingMeasure::voronoi_ring) {
    s.h = voronoi_ring_spacing(nodes);
  } else {
    s.h = nodal_spacing(KdTree(nodes));
  }
  std::vector<double> sorted = s.h;
  std::sort(sorted.begin(), sorted.end());
  const double pos = options.h_min_quantile * static_cast<double>(sorted.size() - 1);
  const auto lo = static_cast<std::size_t>(std::floor(pos));
  const std::size_t hi = std::min(lo + 1, sorted.size() - 1);
  s.h_min = sorted[lo] + (pos - static_cast<double>(lo)) * (sorted[hi] - sorted[lo]);
  s.h_max = sorted.back();
  double total = 0.0;
  for (double v : sorted) total += v;
  s.h_mean = total / static_cast<double>(sorted.size());
  s.eps_min = 2.0 * s.h_min;
  return s;
}

double min_admissible_eps(const NodeSet& nodes, const SpacingOptions& options) {
  return spacing_summary(nodes, options).eps_min;
}

void check_resolution(double eps, const SpacingSummary& spacing) {
  if (!(eps > 0.0) || !std::isfinite(eps)) {
    throw std::invalid_argument("check_resolution: eps must be positive and finite, got " + fmt(eps));
  }
  if (eps < spacing.eps_min * (1.0 - 1e-12)) {
    throw std::invalid_argument("eps = " + fmt(eps) + " is under-resolved by this node set (" +
                                std::to_string(spacing.h.size()) + " nodes): h_min = " + fmt(spacing.h_min) +
                                ", the smallest admissible eps is 2 h_min = " + fmt(spacing.eps_min) +
                                " (criterion eps >= 2 h_min, seed Appendix B); refine or adapt the nodes, or raise eps");
  }
}

void check_resolution(double eps, const NodeSet& nodes, const SpacingOptions& options) {
  check_resolution(eps, spacing_summary(nodes, options));
}

// ---------------------------------------------------------------------------------------------
// Table B.6

std::vector<ScheduleStage> table_b6_schedule(const std::string& start) {
  if (start == "O1") return {{"O11", 10.0, 0.04}, {"O12", 100.0, 0.03}, {"O13", 1000.0, 0.025}};
  if (start == "O2") return {{"O21", 10.0, 0.03}, {"O22", 100.0, 0.025}, {"O23", 1000.0, 0.015}};
  if (start == "O3") return {{"O31", 10.0, 0.03}, {"O32", 100.0, 0.015}};
  if (start == "P1") return {{"P11", 10.0, 0.04}, {"P12", 100.0, 0.03}, {"P13", 1000.0, 0.025}};
  throw std::invalid_argument("table_b6_schedule: no adapted grids start from '" + start +
                              "' in Table B.6 (known: O1, O2, O3, P1)");
}

}  // namespace lmeform
