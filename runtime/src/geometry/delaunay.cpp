#include "lmeform/delaunay.hpp"

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <numeric>
#include <sstream>
#include <stdexcept>
#include <string>

#include "qhull_run.hpp"

namespace lmeform {

namespace {

double longest_edge(const NodeSet& nodes, std::span<const int> v) {
  double l2 = 0;
  for (std::size_t a = 0; a < v.size(); ++a)
    for (std::size_t b = a + 1; b < v.size(); ++b) {
      const auto xa = nodes.point(static_cast<std::size_t>(v[a])), xb = nodes.point(static_cast<std::size_t>(v[b]));
      double s = 0;
      for (std::size_t i = 0; i < xa.size(); ++i) s += (xa[i] - xb[i]) * (xa[i] - xb[i]);
      l2 = std::max(l2, s);
    }
  return std::sqrt(l2);
}

std::string describe_node(const NodeSet& nodes, std::size_t a) {
  std::ostringstream s;
  s.precision(17);
  s << "node " << a << " (";
  const auto x = nodes.point(a);
  for (std::size_t i = 0; i < x.size(); ++i) s << (i ? ", " : "") << x[i];
  s << ")";
  return s.str();
}

BackgroundCells delaunay_1d(const NodeSet& nodes, const DelaunayOptions& options) {
  std::vector<int> order(nodes.size());
  std::iota(order.begin(), order.end(), 0);
  std::stable_sort(order.begin(), order.end(), [&](int a, int b) { return nodes.coords[static_cast<std::size_t>(a)] < nodes.coords[static_cast<std::size_t>(b)]; });
  BackgroundCells cells;
  cells.dim = 1;
  cells.vertices_per_cell = 2;
  const double span = nodes.coords[static_cast<std::size_t>(order.back())] - nodes.coords[static_cast<std::size_t>(order.front())];
  int prev = order.front();
  for (std::size_t k = 1; k < order.size(); ++k) {
    const double len = nodes.coords[static_cast<std::size_t>(order[k])] - nodes.coords[static_cast<std::size_t>(prev)];
    if (len <= options.flat_tolerance * span) {
      if (!options.allow_unused_nodes) {
        throw std::invalid_argument("delaunay: " + describe_node(nodes, static_cast<std::size_t>(order[k])) + " coincides with " +
                                    describe_node(nodes, static_cast<std::size_t>(prev)));
      }
      continue;
    }
    cells.connectivity.push_back(prev);
    cells.connectivity.push_back(order[k]);
    cells.measures.push_back(len);
    prev = order[k];
  }
  return cells;
}


// ---------------------------------------------------------------------------------------------------
// Triangulating qhull's merged Delaunay cells.
//
// Uniform grids are degenerate: their Delaunay cells are squares and cubes (cocircular / cospherical
// vertex groups), which qhull returns as merged, non-simplicial facets. qhull's own 'Qt' cones each
// merged facet from one vertex over its simplicial ridges and, for cubes, emits zero-volume tetrahedra
// whose removal leaves a non-conforming mesh. Instead each merged cell is split here by the pulling
// triangulation with respect to the global node order: cone the cell's lowest-numbered vertex over the
// faces that do not contain it, each face (a polygon in 3D) split the same way by its own lowest vertex.
// A shared face is split identically from both sides, so the result is conforming; and no simplex is
// flat, because a vertex of a convex cell never lies in the plane of a face that does not contain it.
// (All vertices of a Delaunay cell lie on its circumsphere, so none lies inside a face or an edge.)

using Vec3 = std::array<double, 3>;

Vec3 node_vec(const NodeSet& nodes, int id) {
  Vec3 x{};
  const auto p = nodes.point(static_cast<std::size_t>(id));
  for (std::size_t i = 0; i < p.size(); ++i) x[i] = p[i];
  return x;
}
Vec3 sub(const Vec3& a, const Vec3& b) { return {a[0] - b[0], a[1] - b[1], a[2] - b[2]}; }
double dot(const Vec3& a, const Vec3& b) { return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]; }
Vec3 cross(const Vec3& a, const Vec3& b) { return {a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]}; }

// Vertices of a planar convex polygon in cyclic order, seen along `normal` (any fixed normal of its plane).
std::vector<int> cyclic_order(const NodeSet& nodes, std::vector<int> poly, const Vec3& normal) {
  Vec3 c{};
  for (int id : poly) {
    const Vec3 x = node_vec(nodes, id);
    for (std::size_t i = 0; i < 3; ++i) c[i] += x[i] / static_cast<double>(poly.size());
  }
  Vec3 e1 = sub(node_vec(nodes, poly[0]), c);
  const Vec3 e2 = cross(normal, e1);
  std::vector<std::pair<double, int>> keyed;
  for (int id : poly) {
    const Vec3 r = sub(node_vec(nodes, id), c);
    keyed.emplace_back(std::atan2(dot(r, e2), dot(r, e1)), id);
  }
  std::sort(keyed.begin(), keyed.end());
  for (std::size_t k = 0; k < poly.size(); ++k) poly[k] = keyed[k].second;
  return poly;
}

// Pulling fan of a cyclically ordered polygon from its lowest-numbered vertex: triangles (w, a, b).
void pull_polygon(const std::vector<int>& cyc, std::vector<std::array<int, 3>>& out) {
  const auto m = cyc.size();
  const auto start = static_cast<std::size_t>(std::min_element(cyc.begin(), cyc.end()) - cyc.begin());
  for (std::size_t k = 1; k + 1 < m; ++k) out.push_back({cyc[start], cyc[(start + k) % m], cyc[(start + k + 1) % m]});
}

// Faces (vertex sets) of a small convex polyhedron, by testing every vertex triple for a supporting plane.
std::vector<std::vector<int>> polyhedron_faces(const NodeSet& nodes, const std::vector<int>& verts, double tol,
                                               std::vector<Vec3>& normals) {
  std::vector<std::vector<int>> faces;
  const auto k = verts.size();
  for (std::size_t i = 0; i < k; ++i)
    for (std::size_t j = i + 1; j < k; ++j)
      for (std::size_t l = j + 1; l < k; ++l) {
        const Vec3 xi = node_vec(nodes, verts[i]);
        Vec3 n = cross(sub(node_vec(nodes, verts[j]), xi), sub(node_vec(nodes, verts[l]), xi));
        const double len = std::sqrt(dot(n, n));
        if (len <= tol * tol) continue;  // (nearly) collinear triple: spans no plane
        for (double& v : n) v /= len;
        bool pos = false, neg = false;
        std::vector<int> on;
        for (int id : verts) {
          const double s = dot(n, sub(node_vec(nodes, id), xi));
          if (s > tol) pos = true;
          else if (s < -tol) neg = true;
          else on.push_back(id);
        }
        if (pos && neg) continue;
        std::sort(on.begin(), on.end());
        if (std::find(faces.begin(), faces.end(), on) == faces.end()) {
          faces.push_back(std::move(on));
          normals.push_back(n);
        }
      }
  return faces;
}

// Pulling triangulation of one merged Delaunay cell (its vertex set) into simplices of dim + 1 vertices.
void pull_cell(const NodeSet& nodes, std::vector<int> verts, std::vector<std::vector<int>>& out) {
  const int d = nodes.dim;
  std::sort(verts.begin(), verts.end());
  const int apex = verts.front();
  double diam = 0;
  for (int a : verts)
    for (int b : verts) {
      const Vec3 r = sub(node_vec(nodes, a), node_vec(nodes, b));
      diam = std::max(diam, std::sqrt(dot(r, r)));
    }
  if (d == 2) {
    const auto cyc = cyclic_order(nodes, verts, Vec3{0, 0, 1});
    std::vector<std::array<int, 3>> tris;
    pull_polygon(cyc, tris);
    for (const auto& t : tris) out.push_back({t[0], t[1], t[2]});
    return;
  }
  std::vector<Vec3> normals;
  std::vector<std::vector<int>> faces;
  if (verts.size() <= 24) {
    faces = polyhedron_faces(nodes, verts, 1e-10 * diam, normals);
  } else {
    // Large cospherical groups (e.g. nodes sampled on a sphere): the triple test is quartic, so take
    // the faces from qhull's merged hull facets of the cell's vertices instead.
    std::vector<double> sub_coords;
    for (int id : verts) {
      const auto x = nodes.point(static_cast<std::size_t>(id));
      sub_coords.insert(sub_coords.end(), x.begin(), x.end());
    }
    detail::QhullRun hull(NodeSet(3, std::move(sub_coords)), "", "delaunay (faces of a cospherical cell)");
    qhT* qh = hull.get();
    facetT* facet = nullptr;
    vertexT* vertex = nullptr;
    vertexT** vertexp = nullptr;
    FORALLfacets {
      std::vector<int> f;
      FOREACHvertex_(facet->vertices) { f.push_back(verts[static_cast<std::size_t>(qh_pointid(qh, vertex->point))]); }
      std::sort(f.begin(), f.end());
      faces.push_back(std::move(f));
      normals.push_back({facet->normal[0], facet->normal[1], facet->normal[2]});
    }
  }
  for (std::size_t f = 0; f < faces.size(); ++f) {
    if (std::binary_search(faces[f].begin(), faces[f].end(), apex)) continue;
    std::vector<std::array<int, 3>> tris;
    pull_polygon(cyclic_order(nodes, faces[f], normals[f]), tris);
    for (const auto& t : tris) out.push_back({apex, t[0], t[1], t[2]});
  }
}

}  // namespace

double BackgroundCells::total_measure() const noexcept {
  // Neumaier summation: the total is compared with the hull measure to round-off in tests.
  double sum = 0, comp = 0;
  for (const double m : measures) {
    const double t = sum + m;
    comp += std::abs(sum) >= std::abs(m) ? (sum - t) + m : (m - t) + sum;
    sum = t;
  }
  return sum + comp;
}

double simplex_signed_measure(const NodeSet& nodes, std::span<const int> v) {
  const auto d = static_cast<std::size_t>(nodes.dim);
  if (v.size() != d + 1) throw std::invalid_argument("simplex_signed_measure: need " + std::to_string(d + 1) + " vertices, got " + std::to_string(v.size()));
  const auto x0 = nodes.point(static_cast<std::size_t>(v[0]));
  Eigen::Matrix3d J = Eigen::Matrix3d::Identity();
  for (std::size_t k = 0; k < d; ++k) {
    const auto xk = nodes.point(static_cast<std::size_t>(v[k + 1]));
    for (std::size_t i = 0; i < d; ++i) J(static_cast<Eigen::Index>(i), static_cast<Eigen::Index>(k)) = xk[i] - x0[i];
  }
  const double det = d == 1 ? J(0, 0) : d == 2 ? J.topLeftCorner<2, 2>().determinant() : J.determinant();
  return det / (d == 1 ? 1.0 : d == 2 ? 2.0 : 6.0);
}

BackgroundCells delaunay(const NodeSet& nodes, const DelaunayOptions& options) {
  detail::require_full_dimensional(nodes, "delaunay");
  if (nodes.dim == 1) return delaunay_1d(nodes, options);

  // d: Delaunay via the lifted convex hull; Qbb: scale the lifted coordinate (precision);
  // Qz: a point at infinity, which keeps qhull robust for cospherical input (uniform grids).
  // No 'Qt': merged (cospherical) cells are triangulated by pull_cell() above, conformingly.
  detail::QhullRun run(nodes, "d Qbb Qz", "delaunay");
  qhT* qh = run.get();
  const int d = nodes.dim;
  BackgroundCells cells;
  cells.dim = d;
  cells.vertices_per_cell = d + 1;
  std::vector<char> used(nodes.size(), 0);
  facetT* facet = nullptr;
  vertexT* vertex = nullptr;
  vertexT** vertexp = nullptr;
  std::vector<int> verts;
  std::vector<std::vector<int>> simplices;
  FORALLfacets {
    if (facet->upperdelaunay) continue;
    verts.clear();
    FOREACHvertex_(facet->vertices) { verts.push_back(qh_pointid(qh, vertex->point)); }
    for (int id : verts) {
      if (id < 0 || id >= run.point_count()) throw std::logic_error("delaunay: qhull cell refers to point " + std::to_string(id) + " beyond the input");
    }
    if (static_cast<int>(verts.size()) < d + 1) {
      throw std::logic_error("delaunay: qhull returned a cell with " + std::to_string(verts.size()) + " vertices");
    }
    simplices.clear();
    if (static_cast<int>(verts.size()) == d + 1) simplices.push_back(verts);
    else pull_cell(nodes, verts, simplices);
    for (auto& v : simplices) {
      double m = simplex_signed_measure(nodes, v);
      const double scale = std::pow(longest_edge(nodes, v), d);
      if (std::abs(m) <= options.flat_tolerance * scale) {
        ++cells.dropped_flat_cells;
        continue;
      }
      if (m < 0) {
        std::swap(v[1], v[2]);
        m = -m;
      }
      for (int id : v) used[static_cast<std::size_t>(id)] = 1;
      cells.connectivity.insert(cells.connectivity.end(), v.begin(), v.end());
      cells.measures.push_back(m);
    }
  }
  if (!options.allow_unused_nodes) {
    const auto it = std::find(used.begin(), used.end(), 0);
    if (it != used.end()) {
      const auto count = static_cast<std::size_t>(std::count(used.begin(), used.end(), 0));
      throw std::invalid_argument("delaunay: " + std::to_string(count) + " of " + std::to_string(nodes.size()) +
                                  " nodes are vertices of no cell, first " +
                                  describe_node(nodes, static_cast<std::size_t>(it - used.begin())) +
                                  " (duplicate or nearly coincident nodes?)");
    }
  }
  return cells;
}

std::array<double, 4> barycentric(const BackgroundCells& cells, const NodeSet& nodes, std::size_t c, std::span<const double> x) {
  // Cramer's rule on the d x d edge matrix: called per cell in point location, so kept allocation- and
  // pivoting-free (cells are non-degenerate by construction).
  const auto d = static_cast<std::size_t>(cells.dim);
  const auto v = cells.cell(c);
  const auto x0 = nodes.point(static_cast<std::size_t>(v[0]));
  double J[3][3] = {{1, 0, 0}, {0, 1, 0}, {0, 0, 1}};
  double r[3] = {0, 0, 0};
  for (std::size_t k = 0; k < d; ++k) {
    const auto xk = nodes.point(static_cast<std::size_t>(v[k + 1]));
    for (std::size_t i = 0; i < d; ++i) J[i][k] = xk[i] - x0[i];
  }
  for (std::size_t i = 0; i < d; ++i) r[i] = x[i] - x0[i];
  auto det3 = [](const double (&m)[3][3]) {
    return m[0][0] * (m[1][1] * m[2][2] - m[1][2] * m[2][1]) - m[0][1] * (m[1][0] * m[2][2] - m[1][2] * m[2][0]) +
           m[0][2] * (m[1][0] * m[2][1] - m[1][1] * m[2][0]);
  };
  const double det = det3(J);
  std::array<double, 4> out{};
  double s = 0;
  for (std::size_t k = 0; k < d; ++k) {
    double Jk[3][3];
    for (std::size_t i = 0; i < 3; ++i)
      for (std::size_t j = 0; j < 3; ++j) Jk[i][j] = j == k ? (i < d ? r[i] : 0.0) : J[i][j];
    out[k + 1] = det3(Jk) / det;
    s += out[k + 1];
  }
  out[0] = 1.0 - s;
  return out;
}

namespace {
bool inside(const BackgroundCells& cells, const NodeSet& nodes, std::size_t c, std::span<const double> x, double tol) {
  const auto l = barycentric(cells, nodes, c, x);
  for (int k = 0; k <= cells.dim; ++k)
    if (l[static_cast<std::size_t>(k)] < -tol) return false;
  return true;
}
}  // namespace

long locate_cell_brute_force(const BackgroundCells& cells, const NodeSet& nodes, std::span<const double> x, double tolerance) {
  if (x.size() != static_cast<std::size_t>(cells.dim)) throw std::invalid_argument("locate_cell_brute_force: point has " + std::to_string(x.size()) + " coordinates, cells are " + std::to_string(cells.dim) + "D");
  for (std::size_t c = 0; c < cells.size(); ++c)
    if (inside(cells, nodes, c, x, tolerance)) return static_cast<long>(c);
  return -1;
}

CellLocator::CellLocator(const BackgroundCells& cells, const NodeSet& nodes) : cells_(&cells), nodes_(&nodes) {
  if (cells.dim != nodes.dim) throw std::invalid_argument("CellLocator: cells are " + std::to_string(cells.dim) + "D, nodes " + std::to_string(nodes.dim) + "D");
  const auto d = static_cast<std::size_t>(cells.dim);
  std::array<double, 3> hi{};
  lo_.fill(0.0);
  hi.fill(1.0);
  if (nodes.size() > 0) {
    for (std::size_t i = 0; i < d; ++i) lo_[i] = hi[i] = nodes.coords[i];
    for (std::size_t a = 0; a < nodes.size(); ++a)
      for (std::size_t i = 0; i < d; ++i) {
        lo_[i] = std::min(lo_[i], nodes.coords[a * d + i]);
        hi[i] = std::max(hi[i], nodes.coords[a * d + i]);
      }
  }
  double vol = 1.0, diag2 = 0.0;
  for (std::size_t i = 0; i < d; ++i) {
    vol *= std::max(hi[i] - lo_[i], 1e-300);
    diag2 += (hi[i] - lo_[i]) * (hi[i] - lo_[i]);
  }
  const double bucket = std::pow(vol / static_cast<double>(std::max<std::size_t>(cells.size(), 1)), 1.0 / static_cast<double>(d));
  std::size_t total = 1;
  for (std::size_t i = 0; i < d; ++i) {
    bins_[i] = std::clamp(static_cast<int>((hi[i] - lo_[i]) / bucket), 1, 4096);
    width_[i] = std::max((hi[i] - lo_[i]) / bins_[i], 1e-300);
    total *= static_cast<std::size_t>(bins_[i]);
  }
  // Cell boxes are padded so that a point within the location tolerance of a cell is in one of its buckets.
  const double pad = 1e-9 * std::sqrt(diag2);
  auto range = [&](std::size_t c, std::array<int, 3>& b0, std::array<int, 3>& b1) {
    b0 = {0, 0, 0};
    b1 = {0, 0, 0};
    const auto v = cells.cell(c);
    for (std::size_t i = 0; i < d; ++i) {
      double mn = nodes.coords[static_cast<std::size_t>(v[0]) * d + i], mx = mn;
      for (int k : v) {
        mn = std::min(mn, nodes.coords[static_cast<std::size_t>(k) * d + i]);
        mx = std::max(mx, nodes.coords[static_cast<std::size_t>(k) * d + i]);
      }
      b0[i] = std::clamp(static_cast<int>(std::floor((mn - pad - lo_[i]) / width_[i])), 0, bins_[i] - 1);
      b1[i] = std::clamp(static_cast<int>(std::floor((mx + pad - lo_[i]) / width_[i])), 0, bins_[i] - 1);
    }
  };
  offsets_.assign(total + 1, 0);
  std::array<int, 3> b0{}, b1{};
  for (int pass = 0; pass < 2; ++pass) {
    std::vector<std::size_t> fill;
    if (pass == 1) {
      for (std::size_t b = 0; b < total; ++b) offsets_[b + 1] += offsets_[b];
      ids_.resize(offsets_[total]);
      fill.assign(offsets_.begin(), offsets_.end() - 1);
    }
    for (std::size_t c = 0; c < cells.size(); ++c) {
      range(c, b0, b1);
      for (int k = b0[2]; k <= b1[2]; ++k)
        for (int j = b0[1]; j <= b1[1]; ++j)
          for (int i = b0[0]; i <= b1[0]; ++i) {
            const auto b = static_cast<std::size_t>((k * bins_[1] + j) * bins_[0] + i);
            if (pass == 0) ++offsets_[b + 1];
            else ids_[fill[b]++] = static_cast<int>(c);
          }
    }
  }
}

long CellLocator::locate(std::span<const double> x, double tolerance) const {
  const auto d = static_cast<std::size_t>(cells_->dim);
  if (x.size() != d) throw std::invalid_argument("CellLocator::locate: point has " + std::to_string(x.size()) + " coordinates, cells are " + std::to_string(d) + "D");
  std::array<int, 3> b{0, 0, 0};
  for (std::size_t i = 0; i < d; ++i) {
    const double t = std::floor((x[i] - lo_[i]) / width_[i]);
    // Points beyond the box by more than a bucket cannot be in any cell; nearer ones may be within tolerance.
    if (t < -1.0 || t > bins_[i]) return -1;
    b[i] = std::clamp(static_cast<int>(t), 0, bins_[i] - 1);
  }
  const auto bucket = static_cast<std::size_t>((b[2] * bins_[1] + b[1]) * bins_[0] + b[0]);
  for (std::size_t k = offsets_[bucket]; k < offsets_[bucket + 1]; ++k) {
    const auto c = static_cast<std::size_t>(ids_[k]);
    if (inside(*cells_, *nodes_, c, x, tolerance)) return static_cast<long>(c);
  }
  return -1;
}

}  // namespace lmeform
