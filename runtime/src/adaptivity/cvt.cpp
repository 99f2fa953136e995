// CVT node relocation (Lloyd iterations on a sampled density), nodal spacing and the eps >= 2 h_min
// resolution check. See lmeform/cvt.hpp and docs/adaptivity.md.
#include "lmeform/cvt.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <limits>
#include <map>
#include <numeric>
#include <sstream>
#include <stdexcept>
#include <string>
#include <unordered_map>
#include <utility>
#include <vector>

#include "lmeform/delaunay.hpp"
#include "lmeform/neighbour_search.hpp"
#include "lmeform/quadrature.hpp"

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

double checked_density(const Density& density, const std::array<double, 3>& x, std::size_t du, const char* who) {
  const double rho = density(std::span<const double>(x.data(), du));
  if (!(rho > 0.0) || !std::isfinite(rho)) {
    std::string where = "(";
    for (std::size_t i = 0; i < du; ++i) where += (i ? ", " : "") + fmt(x[i]);
    throw std::invalid_argument(std::string(who) + ": the density must be positive and finite, got " + fmt(rho) +
                                " at " + where + ")");
  }
  return rho;
}

// A regular lattice of cells over the box (x fastest), with about `target` cells.
class Lattice {
 public:
  Lattice(const Box& box, double target) : box_(box), du_(static_cast<std::size_t>(box.dim)) {
    double volume = 1.0;
    for (std::size_t i = 0; i < du_; ++i) volume *= box.hi[i] - box.lo[i];
    const double s = std::pow(volume / target, 1.0 / box.dim);
    for (std::size_t i = 0; i < du_; ++i) {
      const double L = box.hi[i] - box.lo[i];
      counts_[i] = static_cast<std::size_t>(std::max(1.0, std::ceil(L / s)));
      width_[i] = L / static_cast<double>(counts_[i]);
      size_ *= counts_[i];
    }
    cell_volume_ = volume / static_cast<double>(size_);
  }
  std::size_t size() const { return size_; }
  double cell_volume() const { return cell_volume_; }
  std::array<std::size_t, 3> index(std::size_t c) const {
    std::array<std::size_t, 3> k{};
    for (std::size_t i = 0; i < du_; ++i) {
      k[i] = c % counts_[i];
      c /= counts_[i];
    }
    return k;
  }
  void centre(std::size_t c, std::array<double, 3>& x) const {
    const auto k = index(c);
    for (std::size_t i = 0; i < du_; ++i) x[i] = box_.lo[i] + (static_cast<double>(k[i]) + 0.5) * width_[i];
  }
  void random_point(std::size_t c, SplitMix64& rng, std::array<double, 3>& x) const {
    const auto k = index(c);
    for (std::size_t i = 0; i < du_; ++i) x[i] = box_.lo[i] + (static_cast<double>(k[i]) + rng.uniform()) * width_[i];
  }
  // Cells sorted by the Morton (Z-order) code of their indices: consecutive cells are close in
  // space, so systematic sampling along this order spreads draws evenly in every direction.
  std::vector<std::size_t> morton_order() const {
    std::vector<std::pair<std::uint64_t, std::size_t>> keyed(size_);
    for (std::size_t c = 0; c < size_; ++c) {
      const auto k = index(c);
      std::uint64_t code = 0;
      for (unsigned bit = 0; bit < 21; ++bit) {
        for (std::size_t i = 0; i < du_; ++i) {
          code |= ((static_cast<std::uint64_t>(k[i]) >> bit) & 1ULL) << (bit * du_ + i);
        }
      }
      keyed[c] = {code, c};
    }
    std::sort(keyed.begin(), keyed.end());
    std::vector<std::size_t> order(size_);
    for (std::size_t c = 0; c < size_; ++c) order[c] = keyed[c].second;
    return order;
  }

 private:
  Box box_;
  std::size_t du_;
  std::array<std::size_t, 3> counts_{1, 1, 1};
  std::array<double, 3> width_{};
  std::size_t size_ = 1;
  double cell_volume_ = 0.0;
};

// CvtStart::density: re-place the interior nodes by systematic sampling of the lattice proposal
// (rho^(dim/(dim+2)) per cell) along Morton order, and the nodes on each edge of the box (one free
// coordinate) by equidistributing rho^(1/(dim+2)) along the edge - the linear node density of a CVT
// whose spacing is proportional to rho^(-1/(dim+2)). Corners and 3D face nodes keep their places.
// Node order and boundary membership are preserved. Returns the number of nodes re-placed.
std::size_t place_by_density(NodeSet& nodes, const std::vector<char>& fixed, const Box& box, const Lattice& lattice,
                             const std::vector<double>& proposal, const Density& density, SplitMix64& rng,
                             const char* who) {
  const std::size_t du = static_cast<std::size_t>(nodes.dim);
  const std::size_t n = nodes.size();
  std::vector<std::size_t> interior;
  std::map<std::vector<double>, std::vector<std::size_t>> edges;  // key: free axis, then the fixed coordinates
  for (std::size_t a = 0; a < n; ++a) {
    std::size_t free_count = 0, free_axis = 0;
    for (std::size_t i = 0; i < du; ++i) {
      if (!fixed[a * du + i]) {
        ++free_count;
        free_axis = i;
      }
    }
    if (free_count == du && du > 1) {
      interior.push_back(a);
    } else if (free_count == 1) {
      std::vector<double> key{static_cast<double>(free_axis)};
      for (std::size_t i = 0; i < du; ++i) key.push_back(i == free_axis ? 0.0 : nodes.coords[a * du + i]);
      edges[key].push_back(a);
    }
  }
  std::size_t replaced = 0;
  // Edges: nodes keep their order along the edge; positions at equal steps of the cumulative
  // rho^(1/(dim+2)) between the edge's ends (the corners, which stay).
  const double edge_exponent = 1.0 / static_cast<double>(du + 2);
  for (auto& [key, members] : edges) {
    const auto axis = static_cast<std::size_t>(key[0]);
    std::sort(members.begin(), members.end(), [&](std::size_t p, std::size_t q) {
      return nodes.coords[p * du + axis] < nodes.coords[q * du + axis];
    });
    const double lo = box.lo[axis], hi = box.hi[axis];
    const std::size_t k = 64 * (members.size() + 1);
    std::vector<double> cumulative(k + 1, 0.0);
    std::array<double, 3> x{};
    for (std::size_t i = 0; i < du; ++i) x[i] = nodes.coords[members.front() * du + i];
    auto g = [&](double t) {
      x[axis] = lo + t * (hi - lo);
      return std::pow(checked_density(density, x, du, who), edge_exponent);
    };
    double previous = g(0.0);
    for (std::size_t j = 1; j <= k; ++j) {
      const double current = g(static_cast<double>(j) / static_cast<double>(k));
      cumulative[j] = cumulative[j - 1] + 0.5 * (previous + current);
      previous = current;
    }
    const double total = cumulative[k];
    for (std::size_t m = 0; m < members.size(); ++m) {
      const double level = total * static_cast<double>(m + 1) / static_cast<double>(members.size() + 1);
      const auto it = std::lower_bound(cumulative.begin(), cumulative.end(), level);
      const auto j = static_cast<std::size_t>(std::max<std::ptrdiff_t>(1, it - cumulative.begin()));
      const double t = (static_cast<double>(j - 1) + (level - cumulative[j - 1]) / (cumulative[j] - cumulative[j - 1])) /
                       static_cast<double>(k);
      nodes.coords[members[m] * du + axis] = lo + t * (hi - lo);
      ++replaced;
    }
  }
  // Interior: systematic sampling along Morton order, one uniform point in each drawn cell.
  if (!interior.empty()) {
    const double total = std::accumulate(proposal.begin(), proposal.end(), 0.0);
    const double step = total / static_cast<double>(interior.size());
    double next = rng.uniform() * step, cumulative = 0.0;
    std::size_t placed = 0;
    std::array<double, 3> x{};
    for (const std::size_t c : lattice.morton_order()) {
      cumulative += proposal[c];
      while (next < cumulative && placed < interior.size()) {
        lattice.random_point(c, rng, x);
        for (std::size_t i = 0; i < du; ++i) nodes.coords[interior[placed] * du + i] = x[i];
        ++placed;
        next += step;
      }
    }
    replaced += placed;
  }
  return replaced;
}

// The Voronoi cell of node a clipped to the box: the box rectangle cut by the bisector
// half-plane of each Delaunay neighbour (Voronoi neighbours are among them, so the result is
// exact). Sutherland-Hodgman on a convex polygon; `poly` and `scratch` are reused buffers.
void voronoi_cell_2d(const NodeSet& nodes, std::size_t a, std::span<const int> neighbours, const Box& box,
                     std::vector<std::array<double, 2>>& poly, std::vector<std::array<double, 2>>& scratch) {
  poly = {{box.lo[0], box.lo[1]}, {box.hi[0], box.lo[1]}, {box.hi[0], box.hi[1]}, {box.lo[0], box.hi[1]}};
  const double xa = nodes.coords[2 * a], ya = nodes.coords[2 * a + 1];
  for (const int nb : neighbours) {
    const double xb = nodes.coords[2 * static_cast<std::size_t>(nb)], yb = nodes.coords[2 * static_cast<std::size_t>(nb) + 1];
    // Keep p with (p - m) . (b - a) <= 0, m the midpoint.
    const double nx = xb - xa, ny = yb - ya;
    const double c = 0.5 * (nx * (xa + xb) + ny * (ya + yb));
    auto side = [&](const std::array<double, 2>& p) { return nx * p[0] + ny * p[1] - c; };
    scratch.clear();
    for (std::size_t i = 0; i < poly.size(); ++i) {
      const auto& p = poly[i];
      const auto& q = poly[(i + 1) % poly.size()];
      const double sp = side(p), sq = side(q);
      if (sp <= 0) scratch.push_back(p);
      if ((sp < 0 && sq > 0) || (sp > 0 && sq < 0)) {
        const double t = sp / (sp - sq);
        scratch.push_back({p[0] + t * (q[0] - p[0]), p[1] + t * (q[1] - p[1])});
      }
    }
    poly.swap(scratch);
    if (poly.size() < 3) break;
  }
}

}  // namespace

// ---------------------------------------------------------------------------------------------
// CVT

namespace {

/// Exact Voronoi centroids (2D) or sampled ones.
bool exact_voronoi(int dim, const CvtOptions& options) { return dim == 2 && options.centroids == CvtCentroids::voronoi; }

void check_cvt_inputs(const NodeSet& nodes, const Box& box, const Density& density, const CvtOptions& options, const char* who) {
  box.validate(who);
  if (nodes.dim != box.dim) {
    throw std::invalid_argument(std::string(who) + ": node dimension " + std::to_string(nodes.dim) + " differs from box dimension " +
                                std::to_string(box.dim));
  }
  if (!density) throw std::invalid_argument(std::string(who) + ": no density given");
  if (options.iterations < 0) throw std::invalid_argument(std::string(who) + ": iterations must be >= 0");
  if (!(options.samples_per_node >= 1.0) || !std::isfinite(options.samples_per_node)) {
    throw std::invalid_argument(std::string(who) + ": samples_per_node must be >= 1, got " + fmt(options.samples_per_node));
  }
  if (!(options.tolerance >= 0.0)) throw std::invalid_argument(std::string(who) + ": tolerance must be >= 0");
  if (nodes.size() < 2) throw std::invalid_argument(std::string(who) + ": need at least 2 nodes, got " + std::to_string(nodes.size()));
  if (exact_voronoi(nodes.dim, options) && options.voronoi_subdivision < 1) {
    throw std::invalid_argument(std::string(who) + ": voronoi_subdivision must be >= 1, got " + std::to_string(options.voronoi_subdivision));
  }
}

/// The state of a Lloyd iteration: the nodes, which of their coordinates lie on a face of the box
/// (fixed), and the mass and first moment of each node's region.
struct LloydState {
  NodeSet current;
  std::vector<char> fixed;  ///< fixed[a*d+i]: coordinate i of node a lies on a face
  std::vector<double> wsum, xsum;
  CvtReport report;
};

/// Nodes within the boundary tolerance of a face are put on it and keep that coordinate.
LloydState start_state(const NodeSet& nodes, const Box& box, const CvtOptions& options, const char* who) {
  const auto du = static_cast<std::size_t>(nodes.dim);
  const std::size_t n = nodes.size();
  double diag2 = 0.0;
  for (std::size_t i = 0; i < du; ++i) diag2 += (box.hi[i] - box.lo[i]) * (box.hi[i] - box.lo[i]);
  const double btol = options.boundary_tolerance * std::sqrt(diag2);
  LloydState s{nodes, std::vector<char>(n * du, 0), std::vector<double>(n), std::vector<double>(n * du), {}};
  for (std::size_t a = 0; a < n; ++a) {
    for (std::size_t i = 0; i < du; ++i) {
      double& x = s.current.coords[a * du + i];
      if (!(x >= box.lo[i] - btol && x <= box.hi[i] + btol)) {
        throw std::invalid_argument(std::string(who) + ": node " + std::to_string(a) + " lies outside the box (coordinate " +
                                    std::to_string(i) + " = " + fmt(x) + ")");
      }
      if (std::abs(x - box.lo[i]) <= btol) {
        s.fixed[a * du + i] = 1;
        x = box.lo[i];
      } else if (std::abs(x - box.hi[i]) <= btol) {
        s.fixed[a * du + i] = 1;
        x = box.hi[i];
      }
    }
  }
  check_coincident(KdTree(s.current), who);
  return s;
}

/// Moves every node to its centroid (free coordinates only, clamped to the box); records the
/// iteration and returns true when the displacement tolerance is met.
bool move_to_centroids(LloydState& s, const Box& box, const CvtOptions& options) {
  const auto du = static_cast<std::size_t>(s.current.dim);
  const std::size_t n = s.current.size();
  CvtIteration rec;
  double total = 0.0;
  for (std::size_t a = 0; a < n; ++a) {
    if (!(s.wsum[a] > 0.0)) {
      ++rec.empty_cells;
      continue;
    }
    double d2 = 0.0;
    for (std::size_t i = 0; i < du; ++i) {
      if (s.fixed[a * du + i]) continue;
      double& xi = s.current.coords[a * du + i];
      const double c = std::clamp(s.xsum[a * du + i] / s.wsum[a], box.lo[i], box.hi[i]);
      d2 += (c - xi) * (c - xi);
      xi = c;
    }
    const double disp = std::sqrt(d2);
    total += disp;
    rec.max_displacement = std::max(rec.max_displacement, disp);
  }
  rec.mean_displacement = total / static_cast<double>(n);
  s.report.iterations.push_back(rec);
  return options.tolerance > 0.0 && rec.mean_displacement < options.tolerance * s.report.h_bar;
}

/// The mass and first moment of ρ over one 2D Voronoi cell `poly`: a fan from vertex 0, each fan
/// triangle split into s² similar triangles with a degree-7 rule on each.
void voronoi_cell_moments(const std::vector<std::array<double, 2>>& poly, const Density& density, const QuadratureRule& rule, int s,
                          const char* who, double& w, double& wx, double& wy, std::size_t& evaluations) {
  std::array<double, 3> x{};
  w = wx = wy = 0.0;
  for (std::size_t k = 1; k + 1 < poly.size(); ++k) {
    const auto& p0 = poly[0];
    const std::array<double, 2> e1{(poly[k][0] - p0[0]) / s, (poly[k][1] - p0[1]) / s};
    const std::array<double, 2> e2{(poly[k + 1][0] - p0[0]) / s, (poly[k + 1][1] - p0[1]) / s};
    const double jac = std::abs(e1[0] * e2[1] - e1[1] * e2[0]);
    for (int i = 0; i < s; ++i)
      for (int j = 0; i + j < s; ++j)
        for (int flip = 0; flip < (i + j + 1 < s ? 2 : 1); ++flip) {
          // Sub-triangle with corner (i, j) in the e1/e2 lattice; flip: the inverted one.
          for (std::size_t q = 0; q < rule.size(); ++q) {
            const double u = rule.points[2 * q], v = rule.points[2 * q + 1];
            const double ci = flip == 1 ? i + 1 - u : i + u, cj = flip == 1 ? j + 1 - v : j + v;
            x[0] = p0[0] + ci * e1[0] + cj * e2[0];
            x[1] = p0[1] + ci * e1[1] + cj * e2[1];
            const double wq = rule.weights[q] * jac * checked_density(density, x, 2, who);
            w += wq;
            wx += wq * x[0];
            wy += wq * x[1];
            ++evaluations;
          }
        }
  }
}

/// 2D Lloyd iterations with the exact Voronoi cells of the nodes (clipped to the box).
void lloyd_voronoi(LloydState& s, const Box& box, const Density& density, const CvtOptions& options, const char* who) {
  const std::size_t n = s.current.size();
  const QuadratureRule rule = triangle_rule(7);
  std::vector<std::array<double, 2>> poly, scratch;
  std::vector<std::vector<int>> adjacency(n);
  std::size_t evaluations = 0;
  for (int it = 0; it < options.iterations; ++it) {
    const BackgroundCells cells = delaunay(s.current);
    for (auto& list : adjacency) list.clear();
    for (std::size_t c = 0; c < cells.size(); ++c) {
      const auto v = cells.cell(c);
      for (std::size_t i = 0; i < 3; ++i)
        for (std::size_t j = 0; j < 3; ++j)
          if (i != j) adjacency[static_cast<std::size_t>(v[i])].push_back(v[j]);
    }
    evaluations = 0;
    for (std::size_t a = 0; a < n; ++a) {
      auto& list = adjacency[a];
      std::sort(list.begin(), list.end());
      list.erase(std::unique(list.begin(), list.end()), list.end());
      voronoi_cell_2d(s.current, a, list, box, poly, scratch);
      voronoi_cell_moments(poly, density, rule, options.voronoi_subdivision, who, s.wsum[a], s.xsum[2 * a], s.xsum[2 * a + 1], evaluations);
    }
    if (move_to_centroids(s, box, options)) {
      s.report.converged = true;
      break;
    }
  }
  s.report.samples = evaluations;
}

/// Samples: systematic sampling of the lattice cells along Morton order with probability
/// proportional to the proposal, one uniform point in the cell per draw, importance weight
/// ρ(x) / proposal density. Drawn once: each Lloyd step is a fixed-point step of one sampled CVT
/// energy, and the run is deterministic.
void draw_samples(const Lattice& lattice, const std::vector<double>& proposal, const Density& density, std::size_t m, std::size_t du,
                  SplitMix64& rng, const char* who, std::vector<double>& samples, std::vector<double>& weight) {
  samples.reserve(m * du);
  weight.reserve(m);
  const double total = std::accumulate(proposal.begin(), proposal.end(), 0.0);
  const double step = total / static_cast<double>(m);
  double next = rng.uniform() * step, cumulative = 0.0;
  std::array<double, 3> x{};
  for (const std::size_t c : lattice.morton_order()) {
    cumulative += proposal[c];
    while (next < cumulative && weight.size() < m) {
      lattice.random_point(c, rng, x);
      const double rho = checked_density(density, x, du, who);
      // Expected draws in cell c are proposal[c] / step; the cell's mass is rho * volume.
      weight.push_back(rho * lattice.cell_volume() * step / proposal[c]);
      for (std::size_t i = 0; i < du; ++i) samples.push_back(x[i]);
      next += step;
    }
  }
}

/// Lloyd iterations with the regions' moments estimated from weighted samples (any dimension).
void lloyd_sampled(LloydState& s, const Box& box, const std::vector<double>& samples, const std::vector<double>& weight,
                   const CvtOptions& options) {
  const auto du = static_cast<std::size_t>(s.current.dim);
  s.report.samples = weight.size();
  std::vector<int> idx;
  for (int it = 0; it < options.iterations; ++it) {
    const KdTree tree(s.current);
    std::fill(s.wsum.begin(), s.wsum.end(), 0.0);
    std::fill(s.xsum.begin(), s.xsum.end(), 0.0);
    for (std::size_t q = 0; q < weight.size(); ++q) {
      tree.knn(std::span<const double>(samples.data() + q * du, du), 1, idx);
      const auto a = static_cast<std::size_t>(idx[0]);
      s.wsum[a] += weight[q];
      for (std::size_t i = 0; i < du; ++i) s.xsum[a * du + i] += weight[q] * samples[q * du + i];
    }
    if (move_to_centroids(s, box, options)) {
      s.report.converged = true;
      break;
    }
  }
}

}  // namespace

NodeSet cvt_relocate(const NodeSet& nodes, const Box& box, const Density& density, const CvtOptions& options, CvtReport* report) {
  const char* who = "cvt_relocate";
  check_cvt_inputs(nodes, box, density, options, who);
  const int d = nodes.dim;
  const auto du = static_cast<std::size_t>(d);
  const std::size_t n = nodes.size();
  LloydState s = start_state(nodes, box, options, who);

  // The lattice: about samples_per_node * n cells over the box.
  const double target = options.samples_per_node * static_cast<double>(n);
  const Lattice lattice(box, target);
  SplitMix64 rng(options.seed);

  // The proposal: rho^(dim/(dim+2)) at the cell centres, the node density of a CVT of rho.
  const double node_exponent = static_cast<double>(d) / static_cast<double>(d + 2);
  const bool exact_centroids = exact_voronoi(d, options);
  std::vector<double> proposal(options.start == CvtStart::density || !exact_centroids ? lattice.size() : 0);
  std::array<double, 3> x{};
  for (std::size_t c = 0; c < proposal.size(); ++c) {
    lattice.centre(c, x);
    proposal[c] = std::pow(checked_density(density, x, du, who), node_exponent);
  }
  if (options.start == CvtStart::density) {
    s.report.replaced = place_by_density(s.current, s.fixed, box, lattice, proposal, density, rng, who);
    check_coincident(KdTree(s.current), who);
  }
  double volume = 1.0;
  for (std::size_t i = 0; i < du; ++i) volume *= box.hi[i] - box.lo[i];
  s.report.h_bar = std::pow(volume / static_cast<double>(n), 1.0 / d);

  if (exact_centroids) {
    lloyd_voronoi(s, box, density, options, who);
  } else {
    std::vector<double> samples, weight;
    draw_samples(lattice, proposal, density, static_cast<std::size_t>(std::ceil(target)), du, rng, who, samples, weight);
    lloyd_sampled(s, box, samples, weight, options);
  }
  if (report) *report = std::move(s.report);
  return std::move(s.current);
}

NodeSet uniform_cvt(const Box& box, std::size_t count, const CvtOptions& options, CvtReport* report) {
  const char* who = "uniform_cvt";
  box.validate(who);
  if (box.dim != 2) throw std::invalid_argument(std::string(who) + ": 2D boxes only, got dimension " + std::to_string(box.dim));
  const double lx = box.hi[0] - box.lo[0], ly = box.hi[1] - box.lo[1];
  const double h = std::sqrt(2.0 * lx * ly / (std::sqrt(3.0) * static_cast<double>(count)));
  const auto sx = static_cast<std::size_t>(std::max(1.0, std::round(lx / h)));
  const auto sy = static_cast<std::size_t>(std::max(1.0, std::round(ly / h)));
  const std::size_t boundary = 2 * (sx + sy);
  if (count < boundary + 1) {
    throw std::invalid_argument(std::string(who) + ": " + std::to_string(count) + " nodes cannot hold the " +
                                std::to_string(boundary) + " edge nodes and one interior node");
  }
  std::vector<double> xy;
  xy.reserve(2 * count);
  for (std::size_t i = 0; i < sx; ++i) {  // bottom and top edges, corners at i = 0
    const double x = box.lo[0] + lx * static_cast<double>(i) / static_cast<double>(sx);
    xy.insert(xy.end(), {x, box.lo[1], box.hi[0] - (x - box.lo[0]), box.hi[1]});
  }
  for (std::size_t j = 0; j < sy; ++j) {  // right and left edges
    const double y = box.lo[1] + ly * static_cast<double>(j) / static_cast<double>(sy);
    xy.insert(xy.end(), {box.hi[0], y, box.lo[0], box.hi[1] - (y - box.lo[1])});
  }
  // Interior nodes: a hexagonal lattice of m rows alternating k - 1 and k nodes, stretched to fit
  // the box, with (k, m) chosen near the lattice spacing h to need the fewest removals; the
  // surplus is removed evenly along the lattice. Lloyd then relaxes the rows next to the edges
  // and the few vacancies (a random start would leave a 5-7 defect at about every fifth node).
  const std::size_t interior = count - boundary;
  const long k0 = std::lround(lx / h), m0 = std::lround(ly / (h * std::sqrt(3.0) / 2.0)) - 1;
  long best_k = 0, best_m = 0;
  std::size_t best_total = 0;
  double best_score = std::numeric_limits<double>::infinity();
  for (long k = std::max(2L, k0 - 4); k <= k0 + 4; ++k) {
    for (long m = std::max(1L, m0 - 4); m <= m0 + 4; ++m) {
      const auto total = static_cast<std::size_t>(m * k - (m + 1) / 2);  // rows j = 1..m, odd rows k - 1 nodes
      if (total < interior) continue;
      // Aspect of the stretched lattice against a hexagonal one, and the removals it needs.
      const double ax = lx / static_cast<double>(k), ay = ly / static_cast<double>(m + 1);
      const double aspect = std::abs(std::log(ay / (ax * std::sqrt(3.0) / 2.0)));
      const double score = static_cast<double>(total - interior) / static_cast<double>(interior) + aspect;
      if (score < best_score) {
        best_score = score;
        best_k = k;
        best_m = m;
        best_total = total;
      }
    }
  }
  if (best_total == 0) throw std::invalid_argument(std::string(who) + ": no lattice fits " + std::to_string(count) + " nodes");
  const double ax = lx / static_cast<double>(best_k), ay = ly / static_cast<double>(best_m + 1);
  const std::size_t surplus = best_total - interior;
  std::size_t index = 0, removed = 0;
  for (long j = 1; j <= best_m; ++j) {
    const bool odd = j % 2 == 1;
    for (long i = odd ? 1 : 0; i < best_k; ++i, ++index) {
      // Remove lattice points index = floor((r + 1/2) total / surplus), r = 0..surplus-1.
      if (removed < surplus &&
          index == static_cast<std::size_t>((static_cast<double>(removed) + 0.5) * static_cast<double>(best_total) /
                                            static_cast<double>(surplus))) {
        ++removed;
        continue;
      }
      xy.push_back(box.lo[0] + ax * (static_cast<double>(i) + (odd ? 0.0 : 0.5)));
      xy.push_back(box.lo[1] + ay * static_cast<double>(j));
    }
  }
  if (xy.size() != 2 * count) {
    throw std::logic_error(std::string(who) + ": built " + std::to_string(xy.size() / 2) + " nodes instead of " +
                           std::to_string(count));
  }
  return cvt_relocate(NodeSet(2, std::move(xy)), box, [](std::span<const double>) { return 1.0; }, options, report);
}

// ---------------------------------------------------------------------------------------------
// Node sets for a spacing field

namespace {
double checked_spacing(const SpacingFunction& spacing, std::span<const double> x, const char* who) {
  const double h = spacing.h(x);
  if (!(h > 0.0) || !std::isfinite(h)) {
    throw std::invalid_argument(std::string(who) + ": the spacing must be positive and finite, got " + fmt(h) + " at (" +
                                fmt(x[0]) + ", " + fmt(x[1]) + ")");
  }
  return h;
}

// The k-th point of the Halton sequence in bases 2 and 3: distinct points strictly inside (0, 1)^2.
std::array<double, 2> halton(std::size_t k) {
  std::array<double, 2> out{};
  const std::array<std::size_t, 2> bases{2, 3};
  for (std::size_t i = 0; i < 2; ++i) {
    double f = 1.0, r = 0.0;
    for (std::size_t m = k; m > 0; m /= bases[i]) {
      f /= static_cast<double>(bases[i]);
      r += f * static_cast<double>(m % bases[i]);
    }
    out[i] = r;
  }
  return out;
}
}  // namespace

SpacingNodeCount count_nodes_for_spacing(const Box& box, const SpacingFunction& spacing) {
  const char* who = "count_nodes_for_spacing";
  box.validate(who);
  if (box.dim != 2) throw std::invalid_argument(std::string(who) + ": 2D boxes only, got dimension " + std::to_string(box.dim));
  if (!spacing.h) throw std::invalid_argument(std::string(who) + ": no spacing given");
  if (!(spacing.h_min > 0.0) || !std::isfinite(spacing.h_min))
    throw std::invalid_argument(std::string(who) + ": h_min must be positive and finite, got " + fmt(spacing.h_min));
  const double lx = box.hi[0] - box.lo[0], ly = box.hi[1] - box.lo[1];
  // Midpoint rule on cells of h_min / 2: the spacing field varies by at most its grading across one.
  const double step = 0.5 * spacing.h_min;
  const double cells = std::ceil(lx / step) * std::ceil(ly / step);
  if (cells > 1e8) throw std::invalid_argument(std::string(who) + ": h_min " + fmt(spacing.h_min) + " is too small for the box");
  const auto nx = static_cast<std::size_t>(std::ceil(lx / step)), ny = static_cast<std::size_t>(std::ceil(ly / step));
  const double dx = lx / static_cast<double>(nx), dy = ly / static_cast<double>(ny);
  double nodes = 0.0;
  std::array<double, 2> x{};
  for (std::size_t j = 0; j < ny; ++j) {
    x[1] = box.lo[1] + (static_cast<double>(j) + 0.5) * dy;
    for (std::size_t i = 0; i < nx; ++i) {
      x[0] = box.lo[0] + (static_cast<double>(i) + 0.5) * dx;
      const double h = checked_spacing(spacing, x, who);
      nodes += dx * dy * 2.0 / (std::sqrt(3.0) * h * h);
    }
  }
  // Edges in the order bottom, right, top, left: start point, direction, length.
  SpacingNodeCount count;
  const std::array<std::array<double, 5>, 4> edges{{{box.lo[0], box.lo[1], 1, 0, lx},
                                                    {box.hi[0], box.lo[1], 0, 1, ly},
                                                    {box.lo[0], box.hi[1], 1, 0, lx},
                                                    {box.lo[0], box.lo[1], 0, 1, ly}}};
  std::size_t on_edges = 4;
  for (std::size_t e = 0; e < 4; ++e) {
    const auto& [x0, y0, tx, ty, length] = edges[e];
    const auto n = static_cast<std::size_t>(std::ceil(length / step));
    double segments = 0.0;
    for (std::size_t i = 0; i < n; ++i) {
      const double t = (static_cast<double>(i) + 0.5) * length / static_cast<double>(n);
      x = {x0 + t * tx, y0 + t * ty};
      segments += length / static_cast<double>(n) / checked_spacing(spacing, x, who);
    }
    count.edges[e] = static_cast<std::size_t>(std::max(1.0, std::round(segments))) - 1;
    on_edges += count.edges[e];
  }
  // The area integral counts the boundary nodes about half (their cells are half outside).
  count.interior = static_cast<std::size_t>(std::max(1.0, std::round(nodes - 0.5 * static_cast<double>(on_edges))));
  count.total = count.interior + on_edges;
  return count;
}

NodeSet cvt_for_spacing(const Box& box, const SpacingFunction& spacing, std::size_t max_nodes, const CvtOptions& options,
                        CvtReport* report) {
  const char* who = "cvt_for_spacing";
  const SpacingNodeCount count = count_nodes_for_spacing(box, spacing);
  if (count.total > max_nodes) {
    throw std::invalid_argument(std::string(who) + ": the spacing needs " + std::to_string(count.total) +
                                " nodes, more than the limit of " + std::to_string(max_nodes));
  }
  const double lx = box.hi[0] - box.lo[0], ly = box.hi[1] - box.lo[1];
  std::vector<double> xy;
  xy.reserve(2 * count.total);
  xy.insert(xy.end(), {box.lo[0], box.lo[1], box.hi[0], box.lo[1], box.hi[0], box.hi[1], box.lo[0], box.hi[1]});
  // Edge nodes evenly spaced and interior nodes anywhere distinct: the density placement of
  // cvt_relocate re-places both, keeping only the counts.
  for (std::size_t e = 0; e < 4; ++e) {
    for (std::size_t i = 1; i <= count.edges[e]; ++i) {
      const double t = static_cast<double>(i) / static_cast<double>(count.edges[e] + 1);
      switch (e) {
        case 0: xy.insert(xy.end(), {box.lo[0] + t * lx, box.lo[1]}); break;
        case 1: xy.insert(xy.end(), {box.hi[0], box.lo[1] + t * ly}); break;
        case 2: xy.insert(xy.end(), {box.lo[0] + t * lx, box.hi[1]}); break;
        default: xy.insert(xy.end(), {box.lo[0], box.lo[1] + t * ly}); break;
      }
    }
  }
  for (std::size_t k = 1; k <= count.interior; ++k) {
    const auto u = halton(k);
    xy.insert(xy.end(), {box.lo[0] + u[0] * lx, box.lo[1] + u[1] * ly});
  }
  CvtOptions placed = options;
  placed.start = CvtStart::density;
  const Density density = [spacing, who](std::span<const double> x) {
    const double h = checked_spacing(spacing, x, who);
    return 1.0 / (h * h * h * h);
  };
  return cvt_relocate(NodeSet(2, std::move(xy)), box, density, placed, report);
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

void check_resolution(double eps, double h_min, double factor, std::string_view what) {
  const std::string prefix = what.empty() ? std::string() : std::string(what) + ": ";
  if (!(eps > 0.0) || !std::isfinite(eps)) {
    throw std::invalid_argument(prefix + "eps must be positive and finite, got " + fmt(eps));
  }
  if (!(h_min > 0.0) || !std::isfinite(h_min) || !(factor > 0.0) || !std::isfinite(factor)) {
    throw std::invalid_argument(prefix + "h_min = " + fmt(h_min) + " and factor = " + fmt(factor) +
                                " must be positive and finite");
  }
  if (eps >= factor * h_min * (1.0 - 1e-12)) return;
  throw std::invalid_argument(prefix + "eps = " + fmt(eps) + " is under-resolved: h_min = " + fmt(h_min) +
                              ", the smallest admissible eps is " + fmt(factor) + " h_min = " + fmt(factor * h_min) +
                              " (criterion eps >= " + fmt(factor) +
                              " h_min, seed Appendix B); refine or adapt the nodes, or raise eps");
}

void check_resolution(double eps, const SpacingSummary& spacing, double factor, std::string_view what) {
  const std::string context = std::string(what.empty() ? std::string_view("node set") : what) + " (" +
                              std::to_string(spacing.h.size()) + " nodes)";
  check_resolution(eps, spacing.h_min, factor, context);
}

void check_resolution(double eps, const NodeSet& nodes, const SpacingOptions& options) {
  check_resolution(eps, spacing_summary(nodes, options));
}

}  // namespace lmeform
