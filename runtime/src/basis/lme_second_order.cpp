// Second-order max-ent basis functions (docs/lme_basis.md, "Second-order basis").
//
// At x, with y_a = x - x_a (scaled by the local length l, as the first-order basis does):
//   p_a = exp(-beta_a |y_a|^2 + mu . phi_a) / Z,   phi_a = (y_a, vech(y_a y_a^T - G_a)),
// mu = argmin ln Z, so that sum p_a phi_a = 0: affine consistency and the second moments equal to
// the nodal gaps. Non-negative weights cannot reproduce x x^T itself (sum p_a |y_a|^2 = 0 would
// put all weight at x); the gap moves the quadratic into the coefficients instead.
//
// Derivatives by implicit differentiation of sum p_a phi_a = 0, for any features phi(x):
//   a_a = d/dx (c_a + mu . phi_a) at fixed mu,  abar = sum p a,  H = sum p phi phi^T,
//   dmu/dx_i = -H^-1 sum_a p_a [(a_a,i - abar_i) phi_a + d_i phi_a],
//   g_a = grad ln p_a = a_a - abar + (dmu/dx)^T phi_a,
//   s_a,ij = d_ij c_a + mu . d_ij phi_a + dmu/dx_j . d_i phi_a + dmu/dx_i . d_j phi_a,
//   d2mu/dx_i dx_j = -H^-1 sum_a p_a [g_a,i g_a,j phi_a + g_a,j d_i phi_a + g_a,i d_j phi_a + s_a,ij phi_a + d_ij phi_a],
//   H ln p_a = s_a + phi_a . d2mu/dx2 - Sbar,  Sbar = sum p (s + g g^T),
// and grad p_a = p_a g_a, H p_a = p_a (g_a g_a^T + H ln p_a).
#include "lme_second_order.hpp"

#include <algorithm>
#include <optional>
#include <array>
#include <cmath>
#include <sstream>
#include <stdexcept>
#include <string>
#include <utility>

#include <Eigen/Dense>

#include "lmeform/convex_hull.hpp"
#include "lmeform/kernel.hpp"
#include "lmeform/neighbour_search.hpp"
#include "maxent_dual.hpp"

namespace lmeform::detail {

namespace {

template <int D>
struct SecondOrder {
  static constexpr int S = D * (D + 1) / 2;
  static constexpr int K = D + S;
  using V = Eigen::Matrix<double, D, 1>;
  using M = Eigen::Matrix<double, D, D>;
  using Dual = MaxEntDual<K>;
  using FV = typename Dual::V;
  using FM = typename Dual::M;
  using FX = Eigen::Matrix<double, K, D>;
  using FS = Eigen::Matrix<double, K, S>;
  // Record offsets (lme_second_order_record_size).
  static constexpr int kLen = 0, kLnz = 1, kMu = 2, kAbar = 2 + K, kMuX = 2 + K + D, kMuXX = kMuX + K * D,
                       kSbar = kMuXX + K * S;

  static constexpr int sym(int i, int j) noexcept { return kernel::hessian_slot(i, j, D) - 1 - D; }

  // Features of a neighbour from its scaled y and its gap (physical units, times inv2 = 1/l^2).
  static void features(const double* y, const double* gap, double inv2, double* phi) {
    for (int i = 0; i < D; ++i) {
      phi[i] = y[i];
      for (int j = i; j < D; ++j) phi[D + sym(i, j)] = y[i] * y[j] - gap[sym(i, j)] * inv2;
    }
  }

  // The symmetric Q with y^T Q y = the quadratic part of w . phi(y).
  static M quad(const double* w) {
    M q;
    for (int i = 0; i < D; ++i)
      for (int j = i; j < D; ++j) q(i, j) = q(j, i) = (i == j ? 1.0 : 0.5) * w[D + sym(i, j)];
    return q;
  }

  // d phi / dx_i as a feature vector: e_i, then d(y_k y_l)/dx_i = delta_ik y_l + delta_il y_k.
  static FV dphi(const V& y, int i) {
    FV v = FV::Zero();
    v(i) = 1.0;
    const double* yk = y.data();
    for (int k = 0; k < D; ++k) v(D + sym(std::min(i, k), std::max(i, k))) += (k == i ? 2.0 : 1.0) * yk[k];
    return v;
  }

  // d2 phi / dx_i dx_j: 1 in the (i, j) feature, 2 when i == j.
  static FV ddphi(int i, int j) {
    FV v = FV::Zero();
    v(D + sym(i, j)) = i == j ? 2.0 : 1.0;
    return v;
  }

  // Scaled y, beta, c (as the first-order basis) and the features; returns l.
  static double prepare(const SecondOrderNodes& nodes, std::span<const double> x, std::span<const int> list,
                        LmeWorkspace& ws) {
    const double len = scaled_neighbourhood<D>(nodes.coords, nodes.beta, x, list, ws);
    if (!(len > 0.0)) return len;
    const double inv2 = 1.0 / (len * len);
    ws.phi.resize(list.size() * K);
    for (std::size_t a = 0; a < list.size(); ++a)
      features(ws.y.data() + a * D, nodes.gap + static_cast<std::size_t>(list[a]) * S, inv2, ws.phi.data() + a * K);
    return len;
  }

  static void check_geometry(std::span<const double> x, int n, double len, const LmeWorkspace& ws,
                             const LmeOptions& opt) {
    if (n < K + 1) {
      throw LmeEvaluationError(LmeFailure::too_few_neighbours, x, static_cast<std::size_t>(n), kNaN,
                               "got " + std::to_string(n) + ", the second-order basis needs " + std::to_string(K + 1));
    }
    check_affine_geometry<D>(x, n, len, ws, opt);
    // Neighbours on one conic (quadric) leave the second-moment features dependent.
    FV mean = FV::Zero();
    for (int a = 0; a < n; ++a) mean += Eigen::Map<const FV>(ws.phi.data() + a * K);
    mean /= n;
    FM cov = FM::Zero();
    for (int a = 0; a < n; ++a) {
      const FV d = Eigen::Map<const FV>(ws.phi.data() + a * K) - mean;
      cov += d * d.transpose();
    }
    const Eigen::SelfAdjointEigenSolver<FM> es(cov, Eigen::EigenvaluesOnly);
    const double lo = es.eigenvalues()(0), hi = es.eigenvalues()(K - 1), tol = opt.degeneracy_tolerance;
    if (!(hi > 0.0) || !(lo > tol * tol * hi)) {
      std::ostringstream os;
      os.precision(3);
      os << "the neighbours lie on one conic/quadric, so their second moments are dependent (spread ratio "
         << std::scientific << std::sqrt(std::max(lo, 0.0) / std::max(hi, 1e-300)) << " <= " << tol << ")";
      throw LmeEvaluationError(LmeFailure::degenerate, x, static_cast<std::size_t>(n), kNaN, os.str());
    }
  }

  [[noreturn]] static void infeasible(std::span<const double> x, int n, const LmeWorkspace& ws, const FV& u,
                                      double gnorm, double tol) {
    const V lin = u.template head<D>();
    if (lin.norm() > 0.0 && MaxEntDual<D>::max_projection(n, ws.y.data(), V(lin / lin.norm())) < -tol) {
      throw LmeEvaluationError(LmeFailure::outside_hull, x, static_cast<std::size_t>(n), gnorm,
                               "a plane through x separates it from all neighbours");
    }
    throw LmeEvaluationError(
        LmeFailure::infeasible_second_moment, x, static_cast<std::size_t>(n), gnorm,
        "no non-negative weights on these neighbours give sum p_a ((x - x_a)(x - x_a)^T - G_a) = 0: x is nearer "
        "the hull, or a hole in the nodes, than the nodal gaps G_a = h_a^2/(2 gamma_a) allow; use a smaller gamma "
        "(wider gaps and supports), more nodes there, or the first-order basis (LmeConsistency::first)");
  }

  // The neighbourhood's geometry (flat, or on one conic) is checked only when the solve or the
  // record fails, to say why: on a good neighbourhood the checks cost about a tenth of a basis
  // evaluation and never fire. A neighbourhood that passes them keeps the solve's own message.
  template <class Step>
  static auto explained(std::span<const double> x, int n, double len, const LmeWorkspace& ws, const LmeOptions& opt,
                        Step&& step) {
    try {
      return step();
    } catch (const LmeEvaluationError&) {
      check_geometry(x, n, len, ws, opt);
      throw;
    }
  }

  static FV solve(const SecondOrderNodes& nodes, const LmeOptions& opt, std::span<const double> x,
                  std::span<const int> list, LmeWorkspace& ws, double& len, double& lnz) {
    const int n = static_cast<int>(list.size());
    len = n > 0 ? prepare(nodes, x, list, ws) : 0.0;
    if (n < K + 1 || !(len > 0.0)) check_geometry(x, n, len, ws, opt);  // throws
    lnz = 0.0;
    return explained(x, n, len, ws, opt, [&] {
      return Dual::newton(x, n, ws.phi.data(), ws.c.data(), ws.p.data(), opt, lnz, [&](const FV& u, double gnorm) {
        infeasible(x, n, ws, u, gnorm, opt.newton_tolerance);
      });
    });
  }

  static void solve_and_record(const SecondOrderNodes& nodes, const LmeOptions& opt, std::span<const double> x,
                               std::span<const int> list, int order, LmeWorkspace& ws, double* record) {
    double len = 0.0, lnz = 0.0;
    const auto mu = solve(nodes, opt, x, list, ws, len, lnz);
    const int n = static_cast<int>(list.size());
    explained(x, n, len, ws, opt, [&] { build_record(x, n, ws, mu, lnz, len, order, opt.min_rcond, record); });
  }

  // a_a (derivative of the exponent at fixed mu) and its mean.
  static V exponent_gradient(const V& y, double beta, const FV& mu, const M& qmu) {
    return -2.0 * beta * y + mu.template head<D>() + 2.0 * qmu * y;
  }

  // T(i, j) = dmu/dx_j . d phi/dx_i, for s_a = -2 beta I + 2 Q(mu) + T + T^T.
  static M cross(const V& y, const FX& mux, const std::array<M, D>& qx) {
    M t;
    for (int j = 0; j < D; ++j) t.col(j) = mux.col(j).template head<D>() + 2.0 * qx[static_cast<std::size_t>(j)] * y;
    return t;
  }

  // Builds the record of `order` in scaled units from p at the solution.
  static void build_record(std::span<const double> x, int n, const LmeWorkspace& ws, const FV& mu, double lnz,
                           double len, int order, double min_rcond, double* rec) {
    rec[kLen] = len;
    rec[kLnz] = lnz;
    Eigen::Map<FV>(rec + kMu) = mu;
    if (order == 0) return;
    const double* p = ws.p.data();
    FM h = FM::Zero();
    for (int a = 0; a < n; ++a) {
      const auto phi = Eigen::Map<const FV>(ws.phi.data() + a * K);
      h.noalias() += p[a] * phi * phi.transpose();
    }
    FM hinv = FM::Zero();
    double rc = 0.0;
    if (!Dual::spd_inverse(h, hinv, rc)) rc = 0.0;
    if (!(rc >= min_rcond)) {
      std::ostringstream os;
      os.precision(3);
      os << "rcond(sum p_a phi_a phi_a^T) = " << std::scientific << rc << " < " << min_rcond
         << "; x is on the convex-hull boundary to machine precision, where derivatives are undefined";
      throw LmeEvaluationError(LmeFailure::singular_jacobian, x, static_cast<std::size_t>(n), kNaN, os.str());
    }
    const M qmu = quad(mu.data());
    V abar = V::Zero();
    for (int a = 0; a < n; ++a)
      abar += p[a] * exponent_gradient(Eigen::Map<const V>(ws.y.data() + a * D), ws.beta[static_cast<std::size_t>(a)], mu, qmu);
    FX rhs = FX::Zero();
    for (int a = 0; a < n; ++a) {
      const auto y = Eigen::Map<const V>(ws.y.data() + a * D);
      const auto phi = Eigen::Map<const FV>(ws.phi.data() + a * K);
      const V da = exponent_gradient(y, ws.beta[static_cast<std::size_t>(a)], mu, qmu) - abar;
      for (int i = 0; i < D; ++i) rhs.col(i) += p[a] * (da(i) * phi + dphi(y, i));
    }
    const FX mux = -hinv * rhs;
    Eigen::Map<V>(rec + kAbar) = abar;
    Eigen::Map<FX>(rec + kMuX) = mux;
    if (order == 1) return;
    std::array<M, D> qx;
    for (int j = 0; j < D; ++j) qx[static_cast<std::size_t>(j)] = quad(mux.col(j).data());
    FS rhs2 = FS::Zero();
    M sbar = M::Zero();
    for (int a = 0; a < n; ++a) {
      const auto y = Eigen::Map<const V>(ws.y.data() + a * D);
      const auto phi = Eigen::Map<const FV>(ws.phi.data() + a * K);
      const double beta = ws.beta[static_cast<std::size_t>(a)];
      const V g = exponent_gradient(y, beta, mu, qmu) - abar + mux.transpose() * phi;
      const M t = cross(y, mux, qx);
      M s = 2.0 * qmu + t + t.transpose();
      s.diagonal().array() -= 2.0 * beta;
      sbar += p[a] * (s + g * g.transpose());
      std::array<FV, D> dp;
      for (int i = 0; i < D; ++i) dp[static_cast<std::size_t>(i)] = dphi(y, i);
      for (int i = 0; i < D; ++i)
        for (int j = i; j < D; ++j)
          rhs2.col(sym(i, j)) += p[a] * ((g(i) * g(j) + s(i, j)) * phi + g(j) * dp[static_cast<std::size_t>(i)] +
                                         g(i) * dp[static_cast<std::size_t>(j)] + ddphi(i, j));
    }
    Eigen::Map<FS>(rec + kMuXX) = -hinv * rhs2;
    for (int i = 0; i < D; ++i)
      for (int j = i; j < D; ++j) rec[kSbar + sym(i, j)] = sbar(i, j);
  }

  // Jet of `order` from a record of `rec_order`, with y, beta and phi in the record's units (the
  // scaled ones); inv_len turns derivatives to physical units. p_given: values at the solution.
  static void jet(int n, const double* y, const double* beta, const double* phi, const double* rec, int rec_order,
                  int order, const double* p_given, double inv_len, double* out, std::size_t stride, const int* cols) {
    const auto mu = Eigen::Map<const FV>(rec + kMu);
    const double lnz = rec[kLnz];
    const M qmu = quad(rec + kMu);
    V abar = V::Zero();
    FX mux = FX::Zero();
    FS muxx = FS::Zero();
    M sbar = M::Zero();
    std::array<M, D> qx;
    for (auto& q : qx) q.setZero();
    if (order >= 1) {
      abar = Eigen::Map<const V>(rec + kAbar);
      mux = Eigen::Map<const FX>(rec + kMuX);
    }
    if (order >= 2 && rec_order >= 2) {
      muxx = Eigen::Map<const FS>(rec + kMuXX);
      for (int i = 0; i < D; ++i)
        for (int j = i; j < D; ++j) sbar(i, j) = sbar(j, i) = rec[kSbar + sym(i, j)];
      for (int j = 0; j < D; ++j) qx[static_cast<std::size_t>(j)] = quad(mux.col(j).data());
    }
    const double g1 = inv_len, g2 = inv_len * inv_len;
    for (int a = 0; a < n; ++a) {
      const std::size_t col = cols ? static_cast<std::size_t>(cols[a]) : static_cast<std::size_t>(a);
      const auto ya = Eigen::Map<const V>(y + a * D);
      const auto pha = Eigen::Map<const FV>(phi + a * K);
      const double pa = p_given ? p_given[a] : std::exp(-beta[a] * ya.squaredNorm() + mu.dot(pha) - lnz);
      out[col] = pa;
      if (order == 0) continue;
      const V g = exponent_gradient(ya, beta[a], mu, qmu) - abar + mux.transpose() * pha;
      for (int i = 0; i < D; ++i) out[static_cast<std::size_t>(1 + i) * stride + col] = pa * g(i) * g1;
      if (order == 1) continue;
      const M t = cross(ya, mux, qx);
      M h = g * g.transpose() + 2.0 * qmu + t + t.transpose() - sbar;
      h.diagonal().array() -= 2.0 * beta[a];
      const Eigen::Matrix<double, S, 1> dd = muxx.transpose() * pha;
      for (int i = 0; i < D; ++i)
        for (int j = i; j < D; ++j)
          out[static_cast<std::size_t>(kernel::hessian_slot(i, j, D)) * stride + col] = pa * (h(i, j) + dd(sym(i, j))) * g2;
    }
  }
};

void check_jet_order(int order, int rec_order) {
  if (order > rec_order) {
    throw std::invalid_argument("second-order LME: order " + std::to_string(order) + " from a record of order " +
                                std::to_string(rec_order));
  }
}

}  // namespace

void second_order_evaluate(int dim, const SecondOrderNodes& nodes, const LmeOptions& options, std::span<const double> x,
                           std::span<const int> list, int order, double* out, std::size_t stride, LmeWorkspace& ws) {
  dispatch(dim, [&](auto dc) {
    constexpr int D = decltype(dc)::value;
    using S = SecondOrder<D>;
    const int n = static_cast<int>(list.size());
    if (order == 0) {
      double len = 0.0, lnz = 0.0;
      S::solve(nodes, options, x, list, ws, len, lnz);
      std::copy(ws.p.begin(), ws.p.begin() + n, out);
      return;
    }
    ws.record.resize(static_cast<std::size_t>(lme_second_order_record_size(D, order)));
    S::solve_and_record(nodes, options, x, list, order, ws, ws.record.data());
    S::jet(n, ws.y.data(), ws.beta.data(), ws.phi.data(), ws.record.data(), order, order, ws.p.data(), 1.0 / ws.record[S::kLen],
           out, stride, nullptr);
  });
}

void second_order_solve_record(int dim, const SecondOrderNodes& nodes, const LmeOptions& options,
                               std::span<const double> x, std::span<const int> list, int order, double* record,
                               LmeWorkspace& ws) {
  dispatch(dim, [&](auto dc) {
    constexpr int D = decltype(dc)::value;
    using S = SecondOrder<D>;
    S::solve_and_record(nodes, options, x, list, order, ws, record);
  });
}

void second_order_reconstruct(int dim, const SecondOrderNodes& nodes, std::span<const double> x,
                              std::span<const int> list, int record_order, const double* record, int order,
                              double* out, std::size_t stride, const int* cols, LmeWorkspace& ws) {
  check_jet_order(order, record_order);
  dispatch(dim, [&](auto dc) {
    constexpr int D = decltype(dc)::value;
    using S = SecondOrder<D>;
    const std::size_t n = list.size();
    const double len = record[S::kLen], inv = 1.0 / len, inv2 = inv * inv;
    ws.y.resize(n * D);
    ws.beta.resize(n);
    ws.phi.resize(n * S::K);
    for (std::size_t a = 0; a < n; ++a) {
      const auto b = static_cast<std::size_t>(list[a]);
      for (std::size_t i = 0; i < D; ++i) ws.y[a * D + i] = (x[i] - nodes.coords[b * D + i]) * inv;
      ws.beta[a] = nodes.beta[b] * len * len;
      S::features(ws.y.data() + a * D, nodes.gap + b * S::S, inv2, ws.phi.data() + a * S::K);
    }
    S::jet(static_cast<int>(n), ws.y.data(), ws.beta.data(), ws.phi.data(), record, record_order, order, nullptr, inv,
           out, stride, cols);
  });
}

namespace {

// Gap rule constants (docs/lme_basis.md). Points between a hull face and the first nodes inside
// it need a node whose gap across the face exceeds its squared distance from them, so the first
// row of nodes along a face (within kReach h_a of it, and within kFirstRow of the least distance
// to it among the nodes within kRowWindow h_a) gets a gap of kWiden times its squared distance
// across the face. Faces count as one direction when their normals are within kSameDirection
// (cos 25 degrees: the facets of a curved hull, not corners). kFirstRow = 1.9 keeps the second row
// of a uniform grid (at twice the first's distance) out, and takes in the ragged first row of a CVT:
// with 1.5 the uniform CVTs of the box failed beside its corners (500 nodes at gamma 0.8 and 0.5,
// the Helfrich scenes' 1 600, 12 271 and 24 597 nodes); with 1.9 every one of them runs.
constexpr double kReach = 3.0, kRowWindow = 2.0, kFirstRow = 1.9, kWiden = 1.5, kSameDirection = 0.906;

struct Plane {
  std::array<double, 3> normal{};
  double offset = 0.0;
};

std::vector<Plane> hull_planes(const NodeSet& hull_nodes, double& extent) {
  const ConvexHull hull = convex_hull(hull_nodes);
  const auto d = static_cast<std::size_t>(hull_nodes.dim);
  extent = 0.0;
  for (std::size_t i = 0; i < d; ++i) {
    double lo = hull_nodes.coords[i], hi = lo;
    for (std::size_t a = 0; a < hull_nodes.size(); ++a) {
      lo = std::min(lo, hull_nodes.coords[a * d + i]);
      hi = std::max(hi, hull_nodes.coords[a * d + i]);
    }
    extent += (hi - lo) * (hi - lo);
  }
  extent = std::sqrt(extent);
  std::vector<Plane> planes;
  for (std::size_t k = 0; k < hull.offsets.size(); ++k) {
    Plane p;
    for (std::size_t i = 0; i < d; ++i) p.normal[i] = hull.normals[k * d + i];
    p.offset = hull.offsets[k];
    const bool seen = std::any_of(planes.begin(), planes.end(), [&](const Plane& q) {
      double dn = std::abs(q.offset - p.offset) / std::max(extent, 1e-300);
      for (std::size_t i = 0; i < d; ++i) dn += std::abs(q.normal[i] - p.normal[i]);
      return dn <= 1e-12;
    });
    if (!seen) planes.push_back(p);
  }
  return planes;
}

template <int D>
double plane_distance(const Plane& p, std::span<const double> x) {
  double dist = -p.offset;
  for (std::size_t i = 0; i < D; ++i) dist -= p.normal[i] * x[i];
  return dist;
}

// The hull planes a node lies on, and how many distinct directions they have (0: inside, 1: on a
// face, dim: a vertex of the hull).
struct FaceMembership {
  std::vector<int> planes;
  int directions = 0;
};

template <int D>
FaceMembership face_membership(const std::vector<Plane>& planes, std::span<const double> x, double on_face) {
  using V = Eigen::Matrix<double, D, 1>;
  FaceMembership m;
  std::vector<V> seen;
  for (std::size_t k = 0; k < planes.size(); ++k) {
    if (plane_distance<D>(planes[k], x) > on_face) continue;
    m.planes.push_back(static_cast<int>(k));
    const V n = Eigen::Map<const V>(planes[k].normal.data());
    if (std::all_of(seen.begin(), seen.end(), [&](const V& s) { return std::abs(n.dot(s)) < kSameDirection; })) seen.push_back(n);
  }
  m.directions = static_cast<int>(seen.size());
  return m;
}

// Gap of node a; `row` holds the nodes within kRowWindow h_a of it.
template <int D>
void node_gap(const NodeSet& nodes, std::size_t a, std::span<const int> row, double h, double gamma,
              const std::vector<Plane>& planes, double on_face, const NodeSet& hull_nodes,
              std::span<const FaceMembership> faces, std::span<const int> face_row, double* out) {
  using V = Eigen::Matrix<double, D, 1>;
  using M = Eigen::Matrix<double, D, D>;
  const double g0 = h * h / (2.0 * gamma);
  const auto x = nodes.point(a);
  std::vector<V> across;                     // normals already accounted for (distinct directions)
  std::vector<std::pair<double, V>> near;    // faces the node is in the first row of, by distance
  M proj = M::Identity();
  auto distinct = [&](const V& n) {
    return std::all_of(across.begin(), across.end(), [&](const V& m) { return std::abs(n.dot(m)) < kSameDirection; });
  };
  for (const Plane& p : planes) {
    const V n = Eigen::Map<const V>(p.normal.data());
    const double dist = plane_distance<D>(p, x);
    if (dist <= on_face) {
      // On this face: a point of the face sees only the face's nodes, so no gap across it.
      if (!distinct(n)) continue;
      across.push_back(n);
      V e = proj * n;
      if (e.norm() > 1e-8) {
        e.normalize();
        proj -= e * e.transpose();
      }
    } else if (dist < kReach * h) {
      double least = dist;
      for (const int b : row) {
        const double db = plane_distance<D>(p, nodes.point(static_cast<std::size_t>(b)));
        if (db > on_face) least = std::min(least, db);
      }
      if (dist <= kFirstRow * least) near.emplace_back(dist, n);
    }
  }
  std::sort(near.begin(), near.end(), [](const auto& l, const auto& r) { return l.first < r.first; });
  M gap = g0 * M::Identity();
  for (const auto& [dist, n] : near) {
    if (!distinct(n)) continue;
    across.push_back(n);
    gap += std::max(0.0, kWiden * dist * dist - g0) * n * n.transpose();
  }
  gap = proj * gap * proj;
  // Along a face the face's nodes alone carry the weight of points on it, and at a node with more
  // face directions (a hull vertex, in 3D also a hull edge) the gap vanishes along them. A point of
  // the face at distance t from such a node, between it and node a at distance s, can then only
  // meet the second moment if a's gap along the face towards it is at least s (s - t): the
  // nodal spacing h_a of a graded set is often shorter than s (a corner node of a coarse CVT has its
  // nearest neighbour inside), so the gap is widened to kWiden s^2 where it is below s^2.
  // Between two nodes of the same face at distance s (neither with more face directions), a point
  // at t from one needs (s - t) g_a + t g_b >= s t (s - t), which g_a, g_b >= s^2/4 guarantee; a
  // ragged CVT row along a face leaves gaps between face nodes longer than 2 h. Only the face
  // neighbours adjacent to a (no other face node within the ball on the segment) count, searched
  // within kReach h_a (`face_row`).
  const FaceMembership& mine = faces[a];
  if (mine.directions > 0 && mine.directions < D) {
    const V xa = Eigen::Map<const V>(x.data());
    auto on_my_faces = [&](int b) {
      const FaceMembership& other = faces[static_cast<std::size_t>(b)];
      return static_cast<std::size_t>(b) != a &&
             std::includes(other.planes.begin(), other.planes.end(), mine.planes.begin(), mine.planes.end());
    };
    auto widen_towards = [&](const V& xb, double fraction) {
      V u = proj * (xb - xa);
      const double s2 = u.squaredNorm();
      if (!(s2 > 0.0)) return;
      u /= std::sqrt(s2);
      const double along = u.dot(gap * u), needed = fraction * s2;
      if (along < needed) gap += (kWiden * needed - along) * u * u.transpose();
    };
    for (const int b : face_row) {
      if (!on_my_faces(b)) continue;
      const FaceMembership& other = faces[static_cast<std::size_t>(b)];
      if (other.directions < mine.directions) continue;
      const V xb = Eigen::Map<const V>(hull_nodes.point(static_cast<std::size_t>(b)).data());
      const V centre = 0.5 * (xa + xb);
      const double radius2 = 0.25 * (xb - xa).squaredNorm();
      const bool adjacent = std::none_of(face_row.begin(), face_row.end(), [&](int c) {
        return c != b && on_my_faces(c) &&
               (Eigen::Map<const V>(hull_nodes.point(static_cast<std::size_t>(c)).data()) - centre).squaredNorm() < radius2 * (1.0 - 1e-12);
      });
      if (adjacent) widen_towards(xb, other.directions > mine.directions ? 1.0 : 0.25);
    }
  }
  for (int i = 0; i < D; ++i)
    for (int j = i; j < D; ++j) out[kernel::hessian_slot(i, j, D) - 1 - D] = gap(i, j);
}

}  // namespace

std::vector<double> second_order_gaps(const NodeSet& nodes, std::span<const double> spacing,
                                      std::span<const double> gamma, const NodeSet& hull_nodes) {
  double extent = 0.0;
  const std::vector<Plane> planes = hull_planes(hull_nodes, extent);
  const KdTree tree(nodes);
  const int d = nodes.dim;
  const auto s = static_cast<std::size_t>(d * (d + 1) / 2);
  std::vector<double> gap(nodes.size() * s);
  std::vector<int> row;
  const double on_face = 1e-9 * extent;
  // Face neighbours are looked up among the hull's nodes, which with mirror symmetry include the
  // reflections (the folded basis then equals that of the whole symmetric set); its first
  // nodes.size() points are the nodes themselves.
  std::vector<FaceMembership> faces(hull_nodes.size());
  for (std::size_t a = 0; a < hull_nodes.size(); ++a)
    dispatch(d, [&](auto dc) { faces[a] = face_membership<decltype(dc)::value>(planes, hull_nodes.point(a), on_face); });
  // Without mirrors the hull's nodes are the nodes: their tree is the one above.
  std::optional<KdTree> reflected_tree;
  if (&hull_nodes != &nodes) reflected_tree.emplace(hull_nodes);
  const KdTree& hull_tree = reflected_tree ? *reflected_tree : tree;
  std::vector<int> face_row;
  for (std::size_t a = 0; a < nodes.size(); ++a) {
    tree.radius_search(nodes.point(a), kRowWindow * spacing[a], row);
    face_row.clear();
    if (faces[a].directions > 0) hull_tree.radius_search(nodes.point(a), kReach * spacing[a], face_row);
    dispatch(d, [&](auto dc) {
      node_gap<decltype(dc)::value>(nodes, a, row, spacing[a], gamma[a], planes, on_face, hull_nodes, faces, face_row,
                                    gap.data() + a * s);
    });
  }
  return gap;
}

}  // namespace lmeform::detail
