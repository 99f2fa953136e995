// Node sets and boundary quadrature of convex domains (domain.hpp).
#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <unordered_map>

#include "lmeform/delaunay.hpp"
#include "lmeform/domain.hpp"
#include "lmeform/quadrature.hpp"

namespace lmeform {

namespace {

using Point = std::array<double, 3>;

Point sub(const Point& a, const Point& b) { return {a[0] - b[0], a[1] - b[1], a[2] - b[2]}; }
double dot3(const Point& a, const Point& b) { return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]; }
Point cross(const Point& a, const Point& b) { return {a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]}; }
Point unit(const Point& a) {
  const double l = std::sqrt(dot3(a, a));
  return {a[0] / l, a[1] / l, a[2] / l};
}
Point along(const Point& a, const Point& b, double t) { return {a[0] + t * (b[0] - a[0]), a[1] + t * (b[1] - a[1]), a[2] + t * (b[2] - a[2])}; }

/// Accepted nodes with a bucket grid for "is a node closer than r to x".
class NodeCloud {
 public:
  NodeCloud(const Box& bounds, double bucket, std::size_t max_nodes) : dim_(bounds.dim), bounds_(bounds), bucket_(bucket), max_(max_nodes) {}
  [[nodiscard]] bool free(const Point& x, double r) const {
    const auto c = cell(x);
    const int reach = static_cast<int>(std::ceil(r / bucket_));
    std::array<long, 3> lo{}, hi{};
    for (int i = 0; i < 3; ++i) {
      lo[std::size_t(i)] = i < dim_ ? c[std::size_t(i)] - reach : 0;
      hi[std::size_t(i)] = i < dim_ ? c[std::size_t(i)] + reach : 0;
    }
    for (long k = lo[2]; k <= hi[2]; ++k)
      for (long j = lo[1]; j <= hi[1]; ++j)
        for (long i = lo[0]; i <= hi[0]; ++i) {
          const auto it = buckets_.find(key({i, j, k}));
          if (it == buckets_.end()) continue;
          for (const std::size_t id : it->second) {
            double d2 = 0;
            for (std::size_t a = 0; a < std::size_t(dim_); ++a) d2 += (coords_[id * std::size_t(dim_) + a] - x[a]) * (coords_[id * std::size_t(dim_) + a] - x[a]);
            if (d2 < r * r) return false;
          }
        }
    return true;
  }
  void add(const Point& x) {
    const std::size_t id = coords_.size() / std::size_t(dim_);
    if (id >= max_)
      throw std::invalid_argument("domain_nodes: more than " + std::to_string(max_) + " nodes for this spacing; coarsen it or raise the limit");
    for (std::size_t a = 0; a < std::size_t(dim_); ++a) coords_.push_back(x[a]);
    buckets_[key(cell(x))].push_back(id);
  }
  [[nodiscard]] NodeSet nodes() && { return NodeSet(dim_, std::move(coords_)); }

 private:
  [[nodiscard]] std::array<long, 3> cell(const Point& x) const {
    std::array<long, 3> c{};
    for (std::size_t i = 0; i < std::size_t(dim_); ++i) c[i] = static_cast<long>(std::floor((x[i] - bounds_.lo[i]) / bucket_));
    return c;
  }
  static long long key(const std::array<long, 3>& c) { return (c[0] * 1000003LL + c[1]) * 1000003LL + c[2]; }
  int dim_;
  Box bounds_;
  double bucket_;
  std::size_t max_;
  std::vector<double> coords_;
  std::unordered_map<long long, std::vector<std::size_t>> buckets_;
};

double spacing_at(const SpacingFunction& s, const Point& x, int dim) {
  const double h = s.h(std::span<const double>(x.data(), std::size_t(dim)));
  if (!(h >= s.h_min * (1 - 1e-12)) || !std::isfinite(h))
    throw std::invalid_argument("domain_nodes: the spacing is " + std::to_string(h) + " at a point, below its h_min " + std::to_string(s.h_min));
  return h;
}

/// Nodes inside the edge a-b at equal increments of ∫ ds / h (its ends are vertices, added apart).
void add_edge_nodes(const Point& a, const Point& b, const SpacingFunction& s, int dim, NodeCloud& cloud) {
  constexpr int m = 4096;
  std::vector<double> cum(m + 1, 0.0);
  const double len = std::sqrt(dot3(sub(b, a), sub(b, a)));
  for (int k = 1; k <= m; ++k) {
    const double h0 = spacing_at(s, along(a, b, (k - 1.0) / m), dim), h1 = spacing_at(s, along(a, b, double(k) / m), dim);
    cum[std::size_t(k)] = cum[std::size_t(k - 1)] + 0.5 * (1 / h0 + 1 / h1) * len / m;
  }
  const int segments = std::max(1, static_cast<int>(std::lround(cum[m])));
  std::size_t k = 0;
  for (int seg = 1; seg < segments; ++seg) {
    const double target = cum[m] * seg / segments;
    while (k + 1 < cum.size() && cum[k + 1] < target) ++k;
    cloud.add(along(a, b, (double(k) + (target - cum[k]) / (cum[k + 1] - cum[k])) / m));
  }
}

/// A jittered candidate lattice of step c over [lo, lo + extent] in `axes` directions from origin,
/// visited in order; `visit` decides on each candidate.
template <class Visit>
void scan_lattice(const Point& origin, const std::vector<Point>& axes, const std::vector<double>& extent, double c, SplitMix64& rng,
                  Visit&& visit) {
  std::array<long, 3> count{1, 1, 1};
  double total = 1;
  for (std::size_t i = 0; i < axes.size(); ++i) {
    count[i] = static_cast<long>(std::floor(extent[i] / c));
    total *= double(std::max(count[i], 1L));
  }
  if (total > 2e8) throw std::invalid_argument("domain_nodes: the spacing is too small for the domain (over 2e8 candidates)");
  for (long k = 0; k < count[2]; ++k)
    for (long j = 0; j < count[1]; ++j)
      for (long i = 0; i < count[0]; ++i) {
        Point x = origin;
        const std::array<long, 3> idx{i, j, k};
        for (std::size_t a = 0; a < axes.size(); ++a) {
          const double t = (double(idx[a]) + 0.5 + 0.8 * (rng.uniform() - 0.5)) * c;
          for (std::size_t r = 0; r < 3; ++r) x[r] += t * axes[a][r];
        }
        visit(x);
      }
}

/// The boundary nodes of a 3D face's interior: in the face's plane, at least h/2 from its edges.
void add_face_nodes(const Domain& domain, const DomainFace& f, const SpacingFunction& s, SplitMix64& rng, NodeCloud& cloud) {
  const auto& v = domain.vertices();
  const Point origin = v[std::size_t(f.vertices[0])];
  const Point e1 = unit(sub(v[std::size_t(f.vertices[1])], origin)), e2 = cross(f.normal, e1);
  double u0 = 0, u1 = 0, w0 = 0, w1 = 0;
  for (const int i : f.vertices) {
    const Point d = sub(v[std::size_t(i)], origin);
    u0 = std::min(u0, dot3(d, e1)), u1 = std::max(u1, dot3(d, e1));
    w0 = std::min(w0, dot3(d, e2)), w1 = std::max(w1, dot3(d, e2));
  }
  const Point start = {origin[0] + u0 * e1[0] + w0 * e2[0], origin[1] + u0 * e1[1] + w0 * e2[1], origin[2] + u0 * e1[2] + w0 * e2[2]};
  auto inside_depth = [&](const Point& x) {  // distance to the face's edges, > 0 inside
    double m = std::numeric_limits<double>::infinity();
    for (std::size_t i = 0; i < f.vertices.size(); ++i) {
      const Point& a = v[std::size_t(f.vertices[i])];
      const Point& b = v[std::size_t(f.vertices[(i + 1) % f.vertices.size()])];
      m = std::min(m, dot3(sub(x, a), unit(cross(f.normal, sub(b, a)))));
    }
    return m;
  };
  scan_lattice(start, {e1, e2}, {u1 - u0, w1 - w0}, s.h_min / 4, rng, [&](const Point& x) {
    const double h = spacing_at(s, x, 3);
    if (inside_depth(x) >= 0.5 * h && cloud.free(x, h)) cloud.add(x);
  });
}

}  // namespace

NodeSet domain_nodes(const Domain& domain, const SpacingFunction& spacing, std::uint64_t seed, std::size_t max_nodes,
                     std::span<const double> kept) {
  if (!spacing.h || !(spacing.h_min > 0)) throw std::invalid_argument("domain_nodes: the spacing needs a function and h_min > 0");
  const int dim = domain.dim();
  const Box& box = domain.bounds();
  if (domain.diameter() / spacing.h_min > 1e5) throw std::invalid_argument("domain_nodes: h_min is too small for the domain");
  double largest = spacing.h_min;
  for (const auto& corner : domain.vertices()) largest = std::max(largest, spacing_at(spacing, corner, dim));
  NodeCloud cloud(box, std::sqrt(spacing.h_min * largest), max_nodes);
  for (const auto& corner : domain.vertices()) cloud.add(corner);
  // Edges: a polygon's faces, or the edges of a polyhedron's faces (each once).
  std::vector<std::pair<int, int>> edges;
  for (const auto& f : domain.faces())
    for (std::size_t i = 0; i < (dim == 2 ? 1 : f.vertices.size()); ++i) {
      const int a = f.vertices[i], b = f.vertices[(i + 1) % f.vertices.size()];
      if (std::find(edges.begin(), edges.end(), std::pair{std::max(a, b), std::min(a, b)}) == edges.end()) edges.emplace_back(std::max(a, b), std::min(a, b));
    }
  for (const auto& [a, b] : edges) add_edge_nodes(domain.vertices()[std::size_t(b)], domain.vertices()[std::size_t(a)], spacing, dim, cloud);
  SplitMix64 rng(seed);
  if (dim == 3)
    for (const auto& f : domain.faces()) add_face_nodes(domain, f, spacing, rng, cloud);
  // Interior nodes of an earlier set stay where they are (a field on them is carried exactly) where
  // the sample's own rule accepts them, in their order: in the earlier set's sampling order that
  // rule accepts them all wherever the spacing did not change.
  for (std::size_t a = 0; a * std::size_t(dim) < kept.size(); ++a) {
    Point x{};
    for (std::size_t i = 0; i < std::size_t(dim); ++i) x[i] = kept[a * std::size_t(dim) + i];
    const double h = spacing_at(spacing, x, dim);
    if (domain.depth(std::span<const double>(x.data(), std::size_t(dim))) >= 0.5 * h && cloud.free(x, h)) cloud.add(x);
  }
  std::vector<Point> axes;
  std::vector<double> extent;
  for (int i = 0; i < dim; ++i) {
    Point e{};
    e[std::size_t(i)] = 1;
    axes.push_back(e);
    extent.push_back(box.hi[std::size_t(i)] - box.lo[std::size_t(i)]);
  }
  const Point origin{box.lo[0], box.lo[1], dim == 3 ? box.lo[2] : 0.0};
  scan_lattice(origin, axes, extent, spacing.h_min / (dim == 3 ? 3 : 4), rng, [&](const Point& x) {
    const double h = spacing_at(spacing, x, dim);
    if (domain.depth(std::span<const double>(x.data(), std::size_t(dim))) >= 0.5 * h && cloud.free(x, h)) cloud.add(x);
  });
  return std::move(cloud).nodes();
}

namespace {

/// Segments between consecutive nodes along a 2D edge face, with a Gauss–Legendre rule each.
void edge_quadrature(const Domain& domain, int face, const NodeSet& nodes, const std::vector<int>& on, const QuadratureRule& rule,
                     BoundaryQuadrature& q) {
  const DomainFace& f = domain.faces()[std::size_t(face)];
  const Point a = domain.vertices()[std::size_t(f.vertices[0])], b = domain.vertices()[std::size_t(f.vertices[1])];
  const double len = std::sqrt(dot3(sub(b, a), sub(b, a)));
  const Point t = unit(sub(b, a));
  std::vector<std::pair<double, int>> along_edge;
  for (const int n : on) along_edge.emplace_back(dot3(sub({nodes.point(std::size_t(n))[0], nodes.point(std::size_t(n))[1], 0.0}, a), t), n);
  std::sort(along_edge.begin(), along_edge.end());
  const double tol = 1e-9 * domain.diameter();
  if (along_edge.size() < 2 || along_edge.front().first > tol || along_edge.back().first < len - tol)
    throw std::invalid_argument("boundary_quadrature: the nodes do not reach both ends of an edge of part '" + f.part +
                                "': a node set for a boundary integral needs the domain's corners");
  for (std::size_t s = 0; s + 1 < along_edge.size(); ++s) {
    const auto x0 = nodes.point(std::size_t(along_edge[s].second)), x1 = nodes.point(std::size_t(along_edge[s + 1].second));
    const double h = along_edge[s + 1].first - along_edge[s].first;
    for (std::size_t k = 0; k < rule.size(); ++k) {
      const double xi = rule.points[k];
      q.points.push_back(x0[0] + xi * (x1[0] - x0[0]));
      q.points.push_back(x0[1] + xi * (x1[1] - x0[1]));
      q.weights.push_back(rule.weights[k] * h);
      q.normals.push_back(f.normal[0]);
      q.normals.push_back(f.normal[1]);
    }
    q.facet_vertices.push_back(along_edge[s].second);
    q.facet_vertices.push_back(along_edge[s + 1].second);
  }
}

/// Triangles of a 3D face's nodes (a 2D Delaunay triangulation in the face's plane), a rule each.
void face_quadrature(const Domain& domain, int face, const NodeSet& nodes, const std::vector<int>& on, const QuadratureRule& rule,
                     BoundaryQuadrature& q) {
  const DomainFace& f = domain.faces()[std::size_t(face)];
  const auto& v = domain.vertices();
  const Point origin = v[std::size_t(f.vertices[0])];
  const Point e1 = unit(sub(v[std::size_t(f.vertices[1])], origin)), e2 = cross(f.normal, e1);
  std::vector<double> plane;
  for (const int n : on) {
    const auto x = nodes.point(std::size_t(n));
    const Point d = sub({x[0], x[1], x[2]}, origin);
    plane.push_back(dot3(d, e1));
    plane.push_back(dot3(d, e2));
  }
  const BackgroundCells triangles = delaunay(NodeSet(2, plane));
  double covered = 0;
  for (std::size_t c = 0; c < triangles.size(); ++c) {
    const auto tri = triangles.cell(c);
    std::array<Point, 3> p{};
    for (std::size_t k = 0; k < 3; ++k) {
      const auto x = nodes.point(std::size_t(on[std::size_t(tri[k])]));
      p[k] = {x[0], x[1], x[2]};
      q.facet_vertices.push_back(on[std::size_t(tri[k])]);
    }
    const Point n = cross(sub(p[1], p[0]), sub(p[2], p[0]));
    const double area = 0.5 * std::sqrt(dot3(n, n));
    covered += area;
    for (std::size_t k = 0; k < rule.size(); ++k) {
      const double r = rule.points[2 * k], s = rule.points[2 * k + 1];
      for (std::size_t i = 0; i < 3; ++i) q.points.push_back(p[0][i] + r * (p[1][i] - p[0][i]) + s * (p[2][i] - p[0][i]));
      q.weights.push_back(rule.weights[k] * 2 * area);  // the reference triangle's measure is 1/2
      for (std::size_t i = 0; i < 3; ++i) q.normals.push_back(f.normal[i]);
    }
  }
  if (std::abs(covered - domain.face_measure(face)) > 1e-9 * domain.face_measure(face))
    throw std::invalid_argument("boundary_quadrature: the nodes of a face of part '" + f.part + "' cover " + std::to_string(covered) + " of its area " +
                                std::to_string(domain.face_measure(face)) + ": a node set for a boundary integral needs the face's corners");
}

}  // namespace

BoundaryQuadrature boundary_quadrature(const Domain& domain, const NodeSet& nodes, const std::string& part, int points_per_segment) {
  if (nodes.dim != domain.dim())
    throw std::invalid_argument("boundary_quadrature: " + std::to_string(nodes.dim) + "D nodes in a " + std::to_string(domain.dim()) + "D domain");
  const std::vector<int> faces = domain.faces_of(part);
  if (faces.empty()) throw std::invalid_argument("boundary_quadrature: the domain has no part '" + part + "'");
  BoundaryQuadrature q;
  q.part = part;
  q.dim = domain.dim();
  q.vertices_per_facet = domain.dim();
  const QuadratureRule rule = domain.dim() == 2 ? gauss_legendre(points_per_segment) : triangle_rule(points_per_segment);
  q.points_per_facet = static_cast<int>(rule.size());
  const double tol = 1e-9 * domain.diameter();
  for (const int f : faces) {
    std::vector<int> on;
    for (std::size_t a = 0; a < nodes.size(); ++a)
      if (domain.on_face(f, nodes.point(a), tol)) on.push_back(int(a));
    if (domain.dim() == 2) edge_quadrature(domain, f, nodes, on, rule, q);
    else face_quadrature(domain, f, nodes, on, rule, q);
  }
  return q;
}

}  // namespace lmeform
