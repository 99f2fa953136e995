#include "lmeform/node_sets.hpp"

#include "lmeform/domain.hpp"

#include <algorithm>
#include <charconv>
#include <cmath>
#include <fstream>
#include <iomanip>
#include <span>
#include <sstream>
#include <stdexcept>
#include <string>
#include <string_view>
#include <vector>

namespace lmeform {

namespace {

std::string fmt(double v) {
  std::ostringstream s;
  s << std::setprecision(17) << v;
  return s.str();
}

void check_dim(int dim, const char* who) {
  if (dim < 1 || dim > 3) throw std::invalid_argument(std::string(who) + ": dimension must be 1, 2 or 3, got " + std::to_string(dim));
}

double box_diagonal(const Box& box) {
  double s = 0;
  for (int i = 0; i < box.dim; ++i) s += (box.hi[static_cast<std::size_t>(i)] - box.lo[static_cast<std::size_t>(i)]) *
                                         (box.hi[static_cast<std::size_t>(i)] - box.lo[static_cast<std::size_t>(i)]);
  return std::sqrt(s);
}

}  // namespace

Box Box::unit(int dimension) {
  check_dim(dimension, "Box::unit");
  Box b;
  b.dim = dimension;
  for (int i = 0; i < dimension; ++i) b.hi[static_cast<std::size_t>(i)] = 1.0;
  return b;
}

void Box::validate(const char* who) const {
  check_dim(dim, who);
  for (std::size_t i = 0; i < static_cast<std::size_t>(dim); ++i) {
    if (!(std::isfinite(lo[i]) && std::isfinite(hi[i]) && lo[i] < hi[i])) {
      throw std::invalid_argument(std::string(who) + ": box axis " + std::to_string(i) + " needs lo < hi, got [" +
                                  fmt(lo[i]) + ", " + fmt(hi[i]) + "]");
    }
  }
}

NodeSet uniform_grid(const Box& box, std::array<int, 3> counts) {
  box.validate("uniform_grid");
  const auto d = static_cast<std::size_t>(box.dim);
  std::array<std::size_t, 3> n{1, 1, 1};
  for (std::size_t i = 0; i < d; ++i) {
    if (counts[i] < 2) {
      throw std::invalid_argument("uniform_grid: axis " + std::to_string(i) + " needs at least 2 nodes (both ends), got " +
                                  std::to_string(counts[i]));
    }
    n[i] = static_cast<std::size_t>(counts[i]);
  }
  auto coord = [&](std::size_t axis, std::size_t k) {
    // Written so that k = n - 1 gives exactly hi: boundary tests compare against the box faces.
    const double t = static_cast<double>(k) / static_cast<double>(n[axis] - 1);
    return k + 1 == n[axis] ? box.hi[axis] : box.lo[axis] + t * (box.hi[axis] - box.lo[axis]);
  };
  std::vector<double> x;
  x.reserve(n[0] * n[1] * n[2] * d);
  for (std::size_t k = 0; k < n[2]; ++k)
    for (std::size_t j = 0; j < n[1]; ++j)
      for (std::size_t i = 0; i < n[0]; ++i) {
        x.push_back(coord(0, i));
        if (d >= 2) x.push_back(coord(1, j));
        if (d >= 3) x.push_back(coord(2, k));
      }
  return NodeSet(box.dim, std::move(x));
}

NodeSet uniform_grid(const Box& box, double spacing) {
  box.validate("uniform_grid");
  if (!(spacing > 0) || !std::isfinite(spacing)) throw std::invalid_argument("uniform_grid: spacing must be positive, got " + fmt(spacing));
  std::array<int, 3> counts{2, 2, 2};
  for (std::size_t i = 0; i < static_cast<std::size_t>(box.dim); ++i) {
    const double segments = std::round((box.hi[i] - box.lo[i]) / spacing);
    if (segments > 1e7) throw std::invalid_argument("uniform_grid: spacing " + fmt(spacing) + " gives more than 1e7 segments on axis " + std::to_string(i));
    counts[i] = std::max(2, static_cast<int>(segments) + 1);
  }
  return uniform_grid(box, counts);
}

namespace {

/// `outside(p)`: why p lies outside the domain, or "" when it does not.
template <class Outside>
NodeSet read_points_checked(const std::filesystem::path& path, int dim, Outside&& outside) {
  if (dim != 0) check_dim(dim, "read_points");
  std::ifstream in(path);
  if (!in) throw std::runtime_error("read_points: cannot open " + path.string());
  std::vector<double> coords;
  std::string line;
  std::size_t lineno = 0;
  auto fail = [&](const std::string& what) {
    throw std::runtime_error(path.string() + ":" + std::to_string(lineno) + ": " + what);
  };
  while (std::getline(in, line)) {
    ++lineno;
    std::string_view rest(line);
    const auto first = rest.find_first_not_of(" \t\r");
    if (first == std::string_view::npos || rest[first] == '#') continue;
    std::vector<double> p;
    std::size_t pos = 0;
    while (pos < rest.size()) {
      while (pos < rest.size() && (rest[pos] == ' ' || rest[pos] == '\t' || rest[pos] == '\r')) ++pos;
      if (pos >= rest.size()) break;
      std::size_t end = pos;
      while (end < rest.size() && rest[end] != ',' && rest[end] != ';' && rest[end] != ' ' && rest[end] != '\t' && rest[end] != '\r') ++end;
      const std::string_view tok = rest.substr(pos, end - pos);
      if (tok.empty()) fail("empty field at column " + std::to_string(pos + 1));
      double v = 0;
      const char* b = tok.data();
      const char* e = tok.data() + tok.size();
      if (*b == '+') ++b;  // from_chars rejects a leading '+', which files written by other tools may carry
      const auto [ptr, ec] = std::from_chars(b, e, v);
      if (ec != std::errc() || ptr != e) fail("cannot read '" + std::string(tok) + "' as a number");
      if (!std::isfinite(v)) fail("non-finite coordinate '" + std::string(tok) + "'");
      p.push_back(v);
      pos = end;
      while (pos < rest.size() && (rest[pos] == ' ' || rest[pos] == '\t' || rest[pos] == '\r')) ++pos;
      if (pos < rest.size() && (rest[pos] == ',' || rest[pos] == ';')) {
        ++pos;
        const auto next = rest.find_first_not_of(" \t\r", pos);
        if (next == std::string_view::npos) fail("trailing separator");
      }
    }
    if (dim == 0) {
      if (p.empty() || p.size() > 3) fail("expected 1 to 3 coordinates, found " + std::to_string(p.size()));
      dim = static_cast<int>(p.size());
    }
    if (p.size() != static_cast<std::size_t>(dim)) {
      fail("expected " + std::to_string(dim) + " coordinates, found " + std::to_string(p.size()));
    }
    // A node outside the domain lies outside every boundary condition and every picture.
    if (const std::string why = outside(std::span<const double>(p)); !why.empty()) fail(why);
    coords.insert(coords.end(), p.begin(), p.end());
  }
  if (in.bad()) throw std::runtime_error("read_points: error reading " + path.string());
  if (coords.empty()) throw std::runtime_error("read_points: " + path.string() + " holds no points");
  return NodeSet(dim, std::move(coords));
}

std::string point_text(std::span<const double> p) {
  std::ostringstream what;
  what << "the point (";
  for (std::size_t k = 0; k < p.size(); ++k) what << (k ? ", " : "") << p[k];
  what << ")";
  return what.str();
}

}  // namespace

NodeSet read_points(const std::filesystem::path& path, int dim, const Box* domain) {
  return read_points_checked(path, dim, [&](std::span<const double> p) -> std::string {
    if (domain == nullptr) return {};
    double extent = 0;
    for (int i = 0; i < domain->dim; ++i) extent = std::max(extent, domain->hi[std::size_t(i)] - domain->lo[std::size_t(i)]);
    const double tol = 1e-9 * extent;
    for (std::size_t i = 0; i < p.size(); ++i)
      if (p[i] < domain->lo[i] - tol || p[i] > domain->hi[i] + tol) {
        std::ostringstream what;
        what << point_text(p) << " lies outside the domain: coordinate " << i << " is outside [" << domain->lo[i] << ", " << domain->hi[i] << "]";
        return what.str();
      }
    return {};
  });
}

NodeSet read_points(const std::filesystem::path& path, int dim, const Domain& domain) {
  const double tol = 1e-9 * domain.diameter();
  return read_points_checked(path, dim, [&](std::span<const double> p) -> std::string {
    if (static_cast<int>(p.size()) != domain.dim() || domain.contains(p, tol)) return {};
    std::ostringstream what;
    what << point_text(p) << " lies outside the domain (by " << -domain.depth(p) << ")";
    return what.str();
  });
}

void write_points(const std::filesystem::path& path, const NodeSet& nodes) {
  std::ofstream out(path);
  if (!out) throw std::runtime_error("write_points: cannot open " + path.string() + " for writing");
  out << std::setprecision(17);
  for (std::size_t a = 0; a < nodes.size(); ++a) {
    const auto x = nodes.point(a);
    for (std::size_t i = 0; i < x.size(); ++i) out << (i ? "," : "") << x[i];
    out << '\n';
  }
  out.flush();
  if (!out) throw std::runtime_error("write_points: error writing " + path.string());
}

double graded_spacing(const GradedGridOptions& o, double x, double y) {
  const double dist = std::abs(std::hypot(x - o.center[0], y - o.center[1]) - o.radius);
  const double s = std::clamp(dist / o.transition, 0.0, 1.0);
  return o.h_min + (o.h_max - o.h_min) * s * s * (3.0 - 2.0 * s);
}

NodeSet graded_grid_2d(const GradedGridOptions& o) {
  if (o.box.dim != 2) throw std::invalid_argument("graded_grid_2d: the box must be 2D, got dimension " + std::to_string(o.box.dim));
  o.box.validate("graded_grid_2d");
  if (!(o.h_min > 0 && o.h_max >= o.h_min && o.transition > 0)) {
    throw std::invalid_argument("graded_grid_2d: need 0 < h_min <= h_max and transition > 0, got h_min " + fmt(o.h_min) +
                                ", h_max " + fmt(o.h_max) + ", transition " + fmt(o.transition));
  }
  const double lx = o.box.hi[0] - o.box.lo[0], ly = o.box.hi[1] - o.box.lo[1];
  if (std::max(lx, ly) / o.h_min > 1e4) throw std::invalid_argument("graded_grid_2d: h_min " + fmt(o.h_min) + " is too small for the box");
  std::vector<double> pts;

  // Boundary: along each side, counter-clockwise from its start corner, nodes at equal increments of
  // the arc length measured in units of the local spacing (integral of ds / h). Each side contributes
  // its start corner, so all four corners are present once.
  const std::array<std::array<double, 2>, 4> corner{{{o.box.lo[0], o.box.lo[1]}, {o.box.hi[0], o.box.lo[1]},
                                                     {o.box.hi[0], o.box.hi[1]}, {o.box.lo[0], o.box.hi[1]}}};
  for (std::size_t side = 0; side < 4; ++side) {
    const auto& a = corner[side];
    const auto& b = corner[(side + 1) % 4];
    constexpr int m = 4096;
    std::vector<double> cum(m + 1, 0.0);
    auto at = [&](double t) { return graded_spacing(o, a[0] + t * (b[0] - a[0]), a[1] + t * (b[1] - a[1])); };
    const double len = std::hypot(b[0] - a[0], b[1] - a[1]);
    for (int k = 1; k <= m; ++k) {
      const double t0 = (k - 1.0) / m, t1 = static_cast<double>(k) / m;
      cum[static_cast<std::size_t>(k)] = cum[static_cast<std::size_t>(k - 1)] + 0.5 * (1.0 / at(t0) + 1.0 / at(t1)) * len / m;
    }
    const int segments = std::max(1, static_cast<int>(std::lround(cum[m])));
    std::size_t k = 0;
    for (int s = 0; s < segments; ++s) {
      const double target = cum[m] * s / segments;
      while (k + 1 < cum.size() && cum[k + 1] < target) ++k;
      const double t = s == 0 ? 0.0 : (k + (target - cum[k]) / (cum[k + 1] - cum[k])) / m;
      pts.push_back(s == 0 ? a[0] : a[0] + t * (b[0] - a[0]));
      pts.push_back(s == 0 ? a[1] : a[1] + t * (b[1] - a[1]));
    }
  }

  // Interior: greedy Poisson-disk sampling of a jittered candidate lattice at h_min / 4, scanned row by
  // row. Accepted nodes are bucketed on a grid of cell size `bucket` for the distance checks.
  const double bucket = std::sqrt(o.h_min * o.h_max);
  const auto nbx = static_cast<int>(std::ceil(lx / bucket)) + 1, nby = static_cast<int>(std::ceil(ly / bucket)) + 1;
  std::vector<std::vector<std::size_t>> buckets(static_cast<std::size_t>(nbx * nby));
  auto bucket_of = [&](double x, double y) {
    const int bx = std::clamp(static_cast<int>((x - o.box.lo[0]) / bucket), 0, nbx - 1);
    const int by = std::clamp(static_cast<int>((y - o.box.lo[1]) / bucket), 0, nby - 1);
    return std::array<int, 2>{bx, by};
  };
  auto insert = [&](std::size_t id) {
    const auto [bx, by] = bucket_of(pts[2 * id], pts[2 * id + 1]);
    buckets[static_cast<std::size_t>(by * nbx + bx)].push_back(id);
  };
  for (std::size_t id = 0; id < pts.size() / 2; ++id) insert(id);

  SplitMix64 rng(o.seed);
  const double c = o.h_min / 4.0;
  const auto ncx = static_cast<long>(std::floor(lx / c)), ncy = static_cast<long>(std::floor(ly / c));
  for (long j = 0; j < ncy; ++j) {
    for (long i = 0; i < ncx; ++i) {
      const double x = o.box.lo[0] + (static_cast<double>(i) + 0.5 + 0.8 * (rng.uniform() - 0.5)) * c;
      const double y = o.box.lo[1] + (static_cast<double>(j) + 0.5 + 0.8 * (rng.uniform() - 0.5)) * c;
      if (!(x > o.box.lo[0] && x < o.box.hi[0] && y > o.box.lo[1] && y < o.box.hi[1])) continue;
      const double r = graded_spacing(o, x, y);
      const int reach = static_cast<int>(std::ceil(r / bucket));
      const auto [bx, by] = bucket_of(x, y);
      bool free = true;
      for (int qy = std::max(0, by - reach); free && qy <= std::min(nby - 1, by + reach); ++qy)
        for (int qx = std::max(0, bx - reach); free && qx <= std::min(nbx - 1, bx + reach); ++qx)
          for (const std::size_t id : buckets[static_cast<std::size_t>(qy * nbx + qx)]) {
            const double dx = pts[2 * id] - x, dy = pts[2 * id + 1] - y;
            if (dx * dx + dy * dy < r * r) {
              free = false;
              break;
            }
          }
      if (!free) continue;
      pts.push_back(x);
      pts.push_back(y);
      insert(pts.size() / 2 - 1);
    }
  }
  return NodeSet(2, std::move(pts));
}

NodeSet jitter_interior(const NodeSet& nodes, const Box& box, double amplitude, std::uint64_t seed) {
  box.validate("jitter_interior");
  if (box.dim != nodes.dim) {
    throw std::invalid_argument("jitter_interior: box dimension " + std::to_string(box.dim) + " differs from node dimension " +
                                std::to_string(nodes.dim));
  }
  if (!(amplitude >= 0) || !std::isfinite(amplitude)) throw std::invalid_argument("jitter_interior: amplitude must be >= 0, got " + fmt(amplitude));
  const double tol = 1e-12 * box_diagonal(box);
  const auto d = static_cast<std::size_t>(nodes.dim);
  NodeSet out = nodes;
  SplitMix64 rng(seed);
  for (std::size_t a = 0; a < nodes.size(); ++a) {
    bool on_face = false;
    for (std::size_t i = 0; i < d; ++i) {
      const double x = nodes.coords[a * d + i];
      on_face = on_face || std::abs(x - box.lo[i]) <= tol || std::abs(x - box.hi[i]) <= tol;
    }
    // Draw for every node, moved or not, so a node's offset does not depend on which others are on faces.
    for (std::size_t i = 0; i < d; ++i) {
      const double offset = amplitude * (2.0 * rng.uniform() - 1.0);
      const double x = nodes.coords[a * d + i] + offset;
      // A move that would leave the open box is skipped on that axis rather than clamped: clamping
      // would put an interior node onto a face, possibly on top of a boundary node.
      if (!on_face && x > box.lo[i] + tol && x < box.hi[i] - tol) out.coords[a * d + i] = x;
    }
  }
  return out;
}

NodeSet fine_strip_beside_coarse_nodes() {
  std::vector<double> xy;
  for (int i = 0; i <= 5; ++i)
    for (int j = 0; j <= 50; ++j) xy.insert(xy.end(), {0.02 * i, 0.02 * j});
  for (int i = 0; i <= 3; ++i)
    for (int j = 0; j <= 5; ++j) xy.insert(xy.end(), {0.3 + 0.2 * i, 0.2 * j});
  return NodeSet(2, std::move(xy));
}

NodeSet random_points(const Box& box, std::size_t n, std::uint64_t seed) {
  box.validate("random_points");
  const auto d = static_cast<std::size_t>(box.dim);
  SplitMix64 rng(seed);
  std::vector<double> x(n * d);
  for (std::size_t a = 0; a < n; ++a)
    for (std::size_t i = 0; i < d; ++i) x[a * d + i] = box.lo[i] + rng.uniform() * (box.hi[i] - box.lo[i]);
  return NodeSet(box.dim, std::move(x));
}

}  // namespace lmeform
