#include "lmeform/domain.hpp"

#include <algorithm>
#include <cmath>
#include <numbers>
#include <sstream>
#include <stdexcept>
#include <limits>
#include <map>

#include "lmeform/delaunay.hpp"
#include "lmeform/quadrature.hpp"

namespace lmeform {

namespace {

using Point = std::array<double, 3>;

std::string text(double v) {
  std::ostringstream s;
  s.precision(10);
  s << v;
  return s.str();
}

Point sub(const Point& a, const Point& b) { return {a[0] - b[0], a[1] - b[1], a[2] - b[2]}; }
double dot3(const Point& a, const Point& b) { return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]; }
double length(const Point& a) { return std::sqrt(dot3(a, a)); }
Point scaled(const Point& a, double s) { return {a[0] * s, a[1] * s, a[2] * s}; }

Point point_of(std::span<const double> x) {
  Point p{};
  for (std::size_t i = 0; i < x.size() && i < 3; ++i) p[i] = x[i];
  return p;
}

Box bounds_of(const std::vector<Point>& vertices, int dim) {
  Box b;
  b.dim = dim;
  for (std::size_t i = 0; i < std::size_t(dim); ++i) {
    b.lo[i] = b.hi[i] = vertices.front()[i];
    for (const Point& v : vertices) b.lo[i] = std::min(b.lo[i], v[i]), b.hi[i] = std::max(b.hi[i], v[i]);
  }
  return b;
}

/// Newell's normal of a loop of points (length: twice the loop's area).
Point newell(const std::vector<Point>& vertices, const std::vector<int>& loop) {
  Point n{};
  for (std::size_t i = 0; i < loop.size(); ++i) {
    const Point& a = vertices[std::size_t(loop[i])];
    const Point& b = vertices[std::size_t(loop[(i + 1) % loop.size()])];
    n[0] += (a[1] - b[1]) * (a[2] + b[2]);
    n[1] += (a[2] - b[2]) * (a[0] + b[0]);
    n[2] += (a[0] - b[0]) * (a[1] + b[1]);
  }
  return n;
}

std::vector<std::string> parts_or_unnamed(const std::vector<std::string>& parts, std::size_t count, const char* what) {
  if (parts.empty()) return std::vector<std::string>(count, "");
  if (parts.size() != count)
    throw std::invalid_argument(std::string(what) + ": " + std::to_string(parts.size()) + " part names for " + std::to_string(count) +
                                " faces (give one per face, \"\" for an unnamed one)");
  return parts;
}

}  // namespace

Domain Domain::box(const Box& box, bool axisymmetric) {
  box.validate("Domain::box");
  Domain d;
  d.dim_ = box.dim;
  d.is_box_ = true;
  d.axisymmetric_ = axisymmetric;
  d.bounds_ = box;
  static const char* names[3][2] = {{"x_min", "x_max"}, {"y_min", "y_max"}, {"z_min", "z_max"}};
  const int corners = 1 << box.dim;
  for (int c = 0; c < corners; ++c) {
    Point p{};
    for (int i = 0; i < box.dim; ++i) p[std::size_t(i)] = (c >> i) & 1 ? box.hi[std::size_t(i)] : box.lo[std::size_t(i)];
    d.vertices_.push_back(p);
  }
  for (int i = 0; i < box.dim; ++i)
    for (int side = 0; side < 2; ++side) {
      DomainFace f;
      f.part = names[i][side];
      f.normal[std::size_t(i)] = side == 0 ? -1.0 : 1.0;
      f.offset = side == 0 ? -box.lo[std::size_t(i)] : box.hi[std::size_t(i)];
      // The corners of the face as a loop: along the first free axis, then back along the second
      // (bit order would cross the square into a bow tie of zero area).
      const int a = (i + 1) % box.dim, b = (i + 2) % box.dim;
      const int fixed = side << i;
      if (box.dim == 2) {
        f.vertices = {fixed, fixed | (1 << a)};
      } else {
        f.vertices = {fixed, fixed | (1 << a), fixed | (1 << a) | (1 << b), fixed | (1 << b)};
      }
      d.faces_.push_back(std::move(f));
    }
  return d;
}

Domain Domain::polygon(const std::vector<std::array<double, 2>>& input, const std::vector<std::string>& edge_parts) {
  const char* who = "polygon";
  const std::size_t n = input.size();
  if (n < 3) throw std::invalid_argument(std::string(who) + ": a polygon needs at least 3 vertices, got " + std::to_string(n));
  std::vector<std::string> parts = parts_or_unnamed(edge_parts, n, who);
  std::vector<Point> v;
  for (const auto& p : input) {
    if (!std::isfinite(p[0]) || !std::isfinite(p[1])) throw std::invalid_argument(std::string(who) + ": a vertex is not finite");
    v.push_back({p[0], p[1], 0.0});
  }
  double area2 = 0, scale = 0;
  for (std::size_t i = 0; i < n; ++i) {
    const Point& a = v[i];
    const Point& b = v[(i + 1) % n];
    area2 += a[0] * b[1] - b[0] * a[1];
    scale = std::max(scale, length(sub(b, a)));
  }
  if (!(std::abs(area2) > 1e-12 * scale * scale))
    throw std::invalid_argument(std::string(who) + ": the vertices enclose no area (collinear or repeated)");
  if (area2 < 0) {  // counter-clockwise from here on: edge j of the reversed loop is edge n-2-j reversed
    std::reverse(v.begin(), v.end());
    std::vector<std::string> reversed(n);
    for (std::size_t j = 0; j < n; ++j) reversed[j] = parts[(2 * n - 2 - j) % n];
    parts = std::move(reversed);
  }
  double turning = 0;
  for (std::size_t i = 0; i < n; ++i) {
    const Point e0 = sub(v[i], v[(i + n - 1) % n]), e1 = sub(v[(i + 1) % n], v[i]);
    if (!(length(e1) > 1e-12 * scale))
      throw std::invalid_argument(std::string(who) + ": vertex " + std::to_string(i) + " repeats the next one");
    const double c = e0[0] * e1[1] - e0[1] * e1[0];
    if (!(c > 1e-12 * length(e0) * length(e1)))
      throw std::invalid_argument(std::string(who) + ": not convex at vertex (" + text(v[i][0]) + ", " + text(v[i][1]) +
                                  ")" + (std::abs(c) <= 1e-12 * length(e0) * length(e1) ? " (collinear with its neighbours: leave it out)"
                                                                                          : " (a re-entrant corner; model a notch by an initial field)"));
    turning += std::atan2(c, dot3(e0, e1));
  }
  if (std::abs(turning - 2 * std::numbers::pi) > 1e-6)
    throw std::invalid_argument(std::string(who) + ": the loop intersects itself (it turns " + text(turning / (2 * std::numbers::pi)) +
                                " times around)");
  Domain d;
  d.dim_ = 2;
  d.vertices_ = v;
  d.bounds_ = bounds_of(v, 2);
  for (std::size_t i = 0; i < n; ++i) {
    const Point e = sub(v[(i + 1) % n], v[i]);
    DomainFace f;
    f.part = parts[i];
    f.normal = {e[1] / length(e), -e[0] / length(e), 0.0};  // outward for a counter-clockwise loop
    f.offset = dot3(f.normal, v[i]);
    f.vertices = {int(i), int((i + 1) % n)};
    d.faces_.push_back(std::move(f));
  }
  return d;
}

Domain Domain::polyhedron(const std::vector<std::array<double, 3>>& vertices, const std::vector<std::vector<int>>& faces,
                          const std::vector<std::string>& face_parts) {
  const char* who = "polyhedron";
  if (vertices.size() < 4 || faces.size() < 4)
    throw std::invalid_argument(std::string(who) + ": needs at least 4 vertices and 4 faces");
  const std::vector<std::string> parts = parts_or_unnamed(face_parts, faces.size(), who);
  Domain d;
  d.dim_ = 3;
  d.vertices_.assign(vertices.begin(), vertices.end());
  d.bounds_ = bounds_of(d.vertices_, 3);
  Point centroid{};
  for (const Point& p : d.vertices_) centroid = {centroid[0] + p[0], centroid[1] + p[1], centroid[2] + p[2]};
  centroid = scaled(centroid, 1.0 / double(d.vertices_.size()));
  const double tol = 1e-9 * d.diameter();
  std::map<std::pair<int, int>, int> edge_use;
  for (std::size_t k = 0; k < faces.size(); ++k) {
    std::vector<int> loop = faces[k];
    if (loop.size() < 3) throw std::invalid_argument(std::string(who) + ": face " + std::to_string(k) + " has fewer than 3 vertices");
    for (const int i : loop)
      if (i < 0 || std::size_t(i) >= vertices.size())
        throw std::invalid_argument(std::string(who) + ": face " + std::to_string(k) + " names vertex " + std::to_string(i));
    Point n = newell(d.vertices_, loop);
    if (!(length(n) > tol * tol)) throw std::invalid_argument(std::string(who) + ": face " + std::to_string(k) + " has no area");
    n = scaled(n, 1.0 / length(n));
    double offset = dot3(n, d.vertices_[std::size_t(loop[0])]);
    if (dot3(n, centroid) > offset) {  // orient outward
      std::reverse(loop.begin(), loop.end());
      n = scaled(n, -1.0);
      offset = -offset;
    }
    for (const int i : loop)
      if (std::abs(dot3(n, d.vertices_[std::size_t(i)]) - offset) > tol)
        throw std::invalid_argument(std::string(who) + ": face " + std::to_string(k) + " is not planar");
    for (std::size_t i = 0; i < loop.size(); ++i) {
      const int a = loop[i], b = loop[(i + 1) % loop.size()];
      ++edge_use[{std::min(a, b), std::max(a, b)}];
    }
    d.faces_.push_back({parts[k], n, offset, loop});
  }
  for (const auto& [edge, count] : edge_use)
    if (count != 2)
      throw std::invalid_argument(std::string(who) + ": the faces do not close: edge " + std::to_string(edge.first) + "-" +
                                  std::to_string(edge.second) + " belongs to " + std::to_string(count) + " face(s)");
  for (const Point& p : d.vertices_)
    if (d.depth(p) < -tol) throw std::invalid_argument(std::string(who) + ": not convex (a vertex lies outside a face's plane)");
  return d;
}

std::vector<std::string> Domain::part_names() const {
  std::vector<std::string> out;
  for (const auto& f : faces_)
    if (!f.part.empty() && std::find(out.begin(), out.end(), f.part) == out.end()) out.push_back(f.part);
  return out;
}

std::vector<int> Domain::faces_of(const std::string& part) const {
  std::vector<int> out;
  // The axisymmetric aliases of the box's faces: the axis r = 0, then r and z for x and y.
  std::string name = part;
  if (is_box_ && axisymmetric_) {
    if (part == "axis") name = "x_min";
    else if (part.starts_with("r_")) name = "x_" + part.substr(2);
    else if (part.starts_with("z_")) name = "y_" + part.substr(2);
  }
  for (std::size_t f = 0; f < faces_.size(); ++f)
    if (part.empty() || part == "hull" || faces_[f].part == name) out.push_back(int(f));
  return out;
}

bool Domain::has_part(const std::string& part) const { return !faces_of(part).empty(); }

double Domain::face_measure(int face) const {
  const DomainFace& f = faces_.at(std::size_t(face));
  if (dim_ == 2) return length(sub(vertices_[std::size_t(f.vertices[1])], vertices_[std::size_t(f.vertices[0])]));
  return 0.5 * length(newell(vertices_, f.vertices));
}

double Domain::part_measure(const std::string& part) const {
  double m = 0;
  for (const int f : faces_of(part)) m += face_measure(f);
  return m;
}

double Domain::measure() const {
  // Divergence theorem: |Ω| = (1/dim) Σ_f |f| (n_f · x_f).
  double m = 0;
  for (std::size_t f = 0; f < faces_.size(); ++f) m += face_measure(int(f)) * faces_[f].offset;
  return m / dim_;
}

double Domain::diameter() const {
  double d = 0;
  for (const Point& a : vertices_)
    for (const Point& b : vertices_) d = std::max(d, length(sub(a, b)));
  return d;
}

double Domain::depth(std::span<const double> x) const {
  const Point p = point_of(x);
  double m = std::numeric_limits<double>::infinity();
  for (const auto& f : faces_) m = std::min(m, f.offset - dot3(f.normal, p));
  return m;
}

bool Domain::contains(std::span<const double> x, double tolerance) const { return depth(x) >= -tolerance; }

bool Domain::on_face(int face, std::span<const double> x, double tolerance) const {
  const DomainFace& f = faces_.at(std::size_t(face));
  return std::abs(dot3(f.normal, point_of(x)) - f.offset) <= tolerance && contains(x, tolerance);
}

namespace {

double segment_distance(const Point& x, const Point& a, const Point& b) {
  const Point ab = sub(b, a), ax = sub(x, a);
  const double l2 = dot3(ab, ab);
  const double t = l2 > 0 ? std::clamp(dot3(ax, ab) / l2, 0.0, 1.0) : 0.0;
  return length(sub(ax, scaled(ab, t)));
}

}  // namespace

double Domain::distance_to_part(std::span<const double> x, const std::string& part) const {
  const Point p = point_of(x);
  double best = std::numeric_limits<double>::infinity();
  for (const int fi : faces_of(part)) {
    const DomainFace& f = faces_[std::size_t(fi)];
    const std::size_t n = f.vertices.size();
    if (dim_ == 2) {
      best = std::min(best, segment_distance(p, vertices_[std::size_t(f.vertices[0])], vertices_[std::size_t(f.vertices[1])]));
      continue;
    }
    // Inside the face's outline: the distance to its plane; else to its nearest edge.
    const double height = dot3(f.normal, p) - f.offset;
    const Point projected = sub(p, scaled(f.normal, height));
    bool inside = true;
    double edge = std::numeric_limits<double>::infinity();
    for (std::size_t i = 0; i < n; ++i) {
      const Point& a = vertices_[std::size_t(f.vertices[i])];
      const Point& b = vertices_[std::size_t(f.vertices[(i + 1) % n])];
      const Point c{(b[1] - a[1]) * f.normal[2] - (b[2] - a[2]) * f.normal[1], (b[2] - a[2]) * f.normal[0] - (b[0] - a[0]) * f.normal[2],
                    (b[0] - a[0]) * f.normal[1] - (b[1] - a[1]) * f.normal[0]};  // n × (b − a): inward for a counter-clockwise loop
      inside = inside && dot3(sub(projected, a), c) >= 0;
      edge = std::min(edge, segment_distance(p, a, b));
    }
    best = std::min(best, inside ? std::abs(height) : edge);
  }
  return best;
}

double distance_to_polyline(std::span<const double> x, const std::vector<std::array<double, 3>>& path, int dim) {
  Point p{};
  for (int i = 0; i < dim; ++i) p[std::size_t(i)] = x[std::size_t(i)];
  if (path.size() == 1) return length(sub(p, path.front()));
  double best = std::numeric_limits<double>::infinity();
  for (std::size_t i = 0; i + 1 < path.size(); ++i) best = std::min(best, segment_distance(p, path[i], path[i + 1]));
  return best;
}

std::vector<int> Domain::nodes_on(const NodeSet& nodes, const std::string& part, double relative_tolerance) const {
  const double tol = relative_tolerance * diameter();
  const std::vector<int> faces = faces_of(part);
  std::vector<int> out;
  for (std::size_t a = 0; a < nodes.size(); ++a)
    if (std::any_of(faces.begin(), faces.end(), [&](int f) { return on_face(f, nodes.point(a), tol); })) out.push_back(int(a));
  return out;
}

}  // namespace lmeform
