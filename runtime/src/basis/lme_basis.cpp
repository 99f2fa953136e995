#include "lmeform/lme_basis.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <iomanip>
#include <limits>
#include <sstream>
#include <string>
#include <utility>

#include <Eigen/Dense>

#include "lme_second_order.hpp"
#include "maxent_dual.hpp"

namespace lmeform {

const char* to_string(LmeFailure reason) noexcept {
  switch (reason) {
    case LmeFailure::too_few_neighbours: return "too few neighbours (need at least dim + 1)";
    case LmeFailure::degenerate: return "affinely degenerate neighbourhood (neighbours collinear/coplanar)";
    case LmeFailure::outside_hull: return "point outside the convex hull of its neighbours";
    case LmeFailure::not_converged: return "Newton iteration on lambda did not converge";
    case LmeFailure::singular_jacobian: return "singular J = sum p_a (x - x_a)(x - x_a)^T: derivatives undefined";
    case LmeFailure::infeasible_second_moment: return "second-order constraints infeasible";
  }
  return "unknown failure";
}

const char* to_string(LmeConsistency consistency) noexcept {
  return consistency == LmeConsistency::second ? "second" : "first";
}

LmeConsistency parse_lme_consistency(std::string_view name) {
  if (name == "first" || name == "1") return LmeConsistency::first;
  if (name == "second" || name == "2") return LmeConsistency::second;
  throw std::invalid_argument("LME consistency \"" + std::string(name) + "\": expected \"first\" (the LME basis) or "
                              "\"second\" (second-order max-ent, converging Hessians)");
}

namespace {

std::string describe(LmeFailure reason, std::span<const double> x, std::size_t neighbours, double gnorm,
                     const std::string& detail) {
  std::ostringstream os;
  os.precision(15);
  os << "LME evaluation failed at x = (";
  for (std::size_t i = 0; i < x.size(); ++i) os << (i ? ", " : "") << x[i];
  os << ") with " << neighbours << " neighbour" << (neighbours == 1 ? "" : "s") << ": " << to_string(reason);
  if (!detail.empty()) os << "; " << detail;
  if (!std::isnan(gnorm)) {
    os.precision(3);
    os << " (final scaled ||grad ln Z|| = " << std::scientific << gnorm << ")";
  }
  return os.str();
}

}  // namespace

LmeEvaluationError::LmeEvaluationError(LmeFailure reason, std::span<const double> x, std::size_t neighbours,
                                       double gradient_norm, const std::string& detail)
    : std::runtime_error(describe(reason, x, neighbours, gradient_norm, detail)),
      reason_(reason),
      point_(x.begin(), x.end()),
      neighbours_(neighbours),
      gradient_norm_(gradient_norm),
      detail_(detail) {}

namespace {

using detail::kNaN;

constexpr int sym_index(int i, int j, int d) noexcept { return kernel::hessian_slot(i, j, d) - 1 - d; }

template <int D>
using Vec = Eigen::Matrix<double, D, 1>;
template <int D>
using Mat = Eigen::Matrix<double, D, D>;

template <int D>
void pack(const Mat<D>& m, double* out) {
  for (int i = 0; i < D; ++i)
    for (int j = i; j < D; ++j) out[sym_index(i, j, D)] = m(i, j);
}

template <int D>
Mat<D> unpack(const double* in) {
  Mat<D> m;
  for (int i = 0; i < D; ++i)
    for (int j = i; j < D; ++j) m(i, j) = m(j, i) = in[sym_index(i, j, D)];
  return m;
}

// Record offsets (see lme_record_size).
template <int D>
struct Layout {
  static constexpr int s = D * (D + 1) / 2;
  static constexpr int lnz = 0, lambda = 1, rbeta = 1 + D;
  static constexpr int dlambda = 1 + 2 * D;  // order 1
  static constexpr int jbeta = 1 + 2 * D, betabar = 1 + 2 * D + s, jinv = 2 + 2 * D + s, q = 2 + 2 * D + 2 * s,
                       t = 2 + 2 * D + 3 * s;  // order 2
};

template <int D>
struct Lme {
  using V = Vec<D>;
  using M = Mat<D>;
  using Dual = detail::MaxEntDual<D>;

  /// The multipliers λ at x for the neighbours `list`: the point scaled by the local length (len),
  /// its geometry checked, the Newton iteration on ln Z (ln Z at the solution in lnz).
  static V solve(const double* coords, const double* beta, std::span<const double> x, std::span<const int> list, LmeWorkspace& ws,
                 const LmeOptions& opt, double& len, double& lnz) {
    const int n = static_cast<int>(list.size());
    len = detail::scaled_neighbourhood<D>(coords, beta, x, list, ws);
    detail::check_affine_geometry<D>(x, n, len, ws, opt);
    lnz = 0.0;
    return Dual::newton(x, n, ws.y.data(), ws.c.data(), ws.p.data(), opt, lnz, [&](const V&, double gnorm) {
      throw LmeEvaluationError(LmeFailure::outside_hull, x, static_cast<std::size_t>(n), gnorm,
                               "a plane through x separates it from all neighbours");
    });
  }

  // Builds the record of `order` from p at the solution, in the units of y and beta.
  static void build_record(std::span<const double> x, int n, const LmeWorkspace& ws, const V& lam, double lnz,
                           int order, double min_rcond, double* rec) {
    using L = Layout<D>;
    const double* y = ws.y.data();
    const double* beta = ws.beta.data();
    const double* p = ws.p.data();
    rec[L::lnz] = lnz;
    for (int i = 0; i < D; ++i) rec[L::lambda + i] = lam(i);
    if (order == 0) return;
    V rb = V::Zero();
    M jac = M::Zero(), jb = M::Zero();
    double bbar = 0.0;
    for (int a = 0; a < n; ++a) {
      const auto ya = Eigen::Map<const V>(y + a * D);
      const V pya = p[a] * ya;
      rb += (2.0 * beta[a]) * pya;
      const M outer = pya * ya.transpose();
      jac += outer;
      jb += (2.0 * beta[a]) * outer;
      bbar += beta[a] * p[a];
    }
    M jinv = M::Zero();
    double rc = 0.0;
    // At a vertex of the hull J vanishes in every direction (the vertex's own function is 1), so
    // its condition number says nothing; J is formed in coordinates scaled by the local spacing,
    // so an absolute bound on its trace is unit-free.
    if (!(jac.trace() > 1e-10)) {
      std::ostringstream os;
      os.precision(3);
      os << "trace(J) = " << std::scientific << jac.trace()
         << " (scaled by the local spacing): x is at a vertex of the convex hull, where derivatives are undefined";
      throw LmeEvaluationError(LmeFailure::singular_jacobian, x, static_cast<std::size_t>(n), kNaN, os.str());
    }
    if (!Dual::spd_inverse(jac, jinv, rc)) rc = 0.0;
    if (!(rc >= min_rcond)) {
      std::ostringstream os;
      os.precision(3);
      os << "rcond(J) = " << std::scientific << rc << " < " << min_rcond
         << "; x is on the convex-hull boundary to machine precision";
      throw LmeEvaluationError(LmeFailure::singular_jacobian, x, static_cast<std::size_t>(n), kNaN, os.str());
    }
    const M dl = (jb - M::Identity()) * jinv;  // the seed's D lambda (transpose of d lambda/dx)
    for (int i = 0; i < D; ++i) rec[L::rbeta + i] = rb(i);
    if (order == 1) {
      for (int i = 0; i < D; ++i)
        for (int j = 0; j < D; ++j) rec[L::dlambda + i * D + j] = dl(i, j);
      return;
    }
    M q = M::Zero();
    std::array<M, D> t;
    for (auto& tk : t) tk.setZero();
    for (int a = 0; a < n; ++a) {
      const auto ya = Eigen::Map<const V>(y + a * D);
      const V m = (2.0 * beta[a]) * ya - dl * ya;
      const M pmm = p[a] * (m * m.transpose());
      q += pmm;
      for (int k = 0; k < D; ++k) t[k] += ya(k) * pmm;
    }
    pack<D>(jb, rec + L::jbeta);
    rec[L::betabar] = bbar;
    pack<D>(jinv, rec + L::jinv);
    pack<D>(q, rec + L::q);
    for (int k = 0; k < D; ++k) pack<D>(t[k], rec + L::t + k * L::s);
  }

  // Scaled record (lengths in units of len) to physical units: each entry carries len^-k.
  static void unscale_record(int order, double len, double* rec) {
    using L = Layout<D>;
    const double i1 = 1.0 / len, i2 = i1 * i1;
    for (int i = 0; i < D; ++i) rec[L::lambda + i] *= i1;
    if (order == 0) return;
    for (int i = 0; i < D; ++i) rec[L::rbeta + i] *= i1;
    if (order == 1) {
      for (int i = 0; i < D * D; ++i) rec[L::dlambda + i] *= i2;
      return;
    }
    // J_beta is dimensionless.
    rec[L::betabar] *= i2;
    for (int i = 0; i < L::s; ++i) rec[L::jinv + i] *= i2;
    for (int i = 0; i < L::s; ++i) rec[L::q + i] *= i2;
    for (int i = 0; i < D * L::s; ++i) rec[L::t + i] *= i1;
  }

  // Jet of `order` from a record of `rec_order` (A.1-A.3). With y, beta, record in units of len,
  // inv_len = 1/len turns gradients and Hessians to physical units (1 for physical input).
  // p_given (optional) are the values at the solution, saving the exponentials.
  static void jet(int n, const double* y, const double* beta, const double* rec, int rec_order, int order,
                  const double* p_given, double inv_len, double* out, std::size_t stride, const int* cols) {
    using L = Layout<D>;
    const double lnz = rec[L::lnz];
    const V lam = Eigen::Map<const V>(rec + L::lambda);
    V rb = V::Zero();
    M dl = M::Zero(), jinv = M::Zero(), q = M::Zero();
    double bbar = 0.0;
    std::array<M, D> t;
    for (auto& tk : t) tk.setZero();
    if (order >= 1) {
      rb = Eigen::Map<const V>(rec + L::rbeta);
      if (rec_order == 1) {
        for (int i = 0; i < D; ++i)
          for (int j = 0; j < D; ++j) dl(i, j) = rec[L::dlambda + i * D + j];
      } else {
        jinv = unpack<D>(rec + L::jinv);
        dl = (unpack<D>(rec + L::jbeta) - M::Identity()) * jinv;
        if (order == 2) {
          bbar = rec[L::betabar];
          q = unpack<D>(rec + L::q);
          for (int k = 0; k < D; ++k) t[k] = unpack<D>(rec + L::t + k * L::s);
        }
      }
    }
    const M rr = rb * rb.transpose();
    const double g1 = inv_len, g2 = inv_len * inv_len;
    for (int a = 0; a < n; ++a) {
      const std::size_t col = cols ? static_cast<std::size_t>(cols[a]) : static_cast<std::size_t>(a);
      const auto ya = Eigen::Map<const V>(y + a * D);
      const double pa = p_given ? p_given[a] : std::exp(-beta[a] * ya.squaredNorm() + lam.dot(ya) - lnz);
      out[col] = pa;
      if (order == 0) continue;
      // g = grad ln p_a = r_beta - M_a y_a, M_a = 2 beta_a I - D lambda.
      const V g = rb - (2.0 * beta[a]) * ya + dl * ya;
      for (int i = 0; i < D; ++i) out[static_cast<std::size_t>(1 + i) * stride + col] = pa * g(i) * g1;
      if (order == 1) continue;
      const V ja = jinv * ya;
      // Hessian of ln p_a; H p_a = p_a (g g^T + that).
      M h = g * g.transpose() + rr + rb * ja.transpose() + ja * rb.transpose() - q;
      h.diagonal().array() += 2.0 * (bbar - beta[a]) + rb.dot(ja);
      for (int k = 0; k < D; ++k) h -= ja(k) * t[k];
      for (int i = 0; i < D; ++i)
        for (int j = i; j < D; ++j)
          out[static_cast<std::size_t>(kernel::hessian_slot(i, j, D)) * stride + col] = pa * h(i, j) * g2;
    }
  }
};

// Mirror symmetry: the jet over [neighbours..., images...] (stride n_ext) folded into the n
// neighbour columns of `out` (column(k) = cols[k], or k): own entries set, images added.
void fold_images(const double* ext, std::size_t n_ext, std::size_t n, int rows, const int* image_columns, double* out,
                 std::size_t stride, const int* cols) {
  for (int s = 0; s < rows; ++s) {
    const double* src = ext + static_cast<std::size_t>(s) * n_ext;
    double* dst = out + static_cast<std::size_t>(s) * stride;
    for (std::size_t k = 0; k < n; ++k) dst[cols ? static_cast<std::size_t>(cols[k]) : k] = src[k];
    for (std::size_t k = n; k < n_ext; ++k) {
      const auto own = static_cast<std::size_t>(image_columns[k - n]);
      dst[cols ? static_cast<std::size_t>(cols[own]) : own] += src[k];
    }
  }
}


}  // namespace

LmeBasis::LmeBasis(NodeSet nodes, std::span<const double> gamma, LmeOptions options)
    : nodes_(std::move(nodes)), options_(options), tree_(nodes_) {
  init(gamma, smooth_spacing(tree_, nodal_spacing(tree_, options_.spacing_neighbours), options_.spacing_smoothing));
}

LmeBasis::LmeBasis(NodeSet nodes, std::span<const double> gamma, std::vector<double> spacing, LmeOptions options)
    : nodes_(std::move(nodes)), options_(options), tree_(nodes_) {
  init(gamma, std::move(spacing));
}

void LmeBasis::init(std::span<const double> gamma, std::vector<double> spacing) {
  const std::size_t n = nodes_.size();
  if (gamma.size() != 1 && gamma.size() != n) {
    throw std::invalid_argument("LmeBasis: " + std::to_string(gamma.size()) + " gamma values for " +
                                std::to_string(n) + " nodes (need 1 or one per node)");
  }
  if (spacing.size() != n) {
    throw std::invalid_argument("LmeBasis: " + std::to_string(spacing.size()) + " spacings for " +
                                std::to_string(n) + " nodes");
  }
  if (!(options_.tol0 > 0.0 && options_.tol0 < 1.0) || !(options_.newton_tolerance > 0.0) ||
      options_.max_iterations < 1) {
    throw std::invalid_argument("LmeBasis: need 0 < tol0 < 1, newton_tolerance > 0, max_iterations >= 1");
  }
  spacing_ = std::move(spacing);
  gamma_.resize(n);
  beta_.resize(n);
  radius_.resize(n);
  for (std::size_t a = 0; a < n; ++a) {
    gamma_[a] = gamma.size() == 1 ? gamma[0] : gamma[a];
    if (!(gamma_[a] > 0.0) || !(spacing_[a] > 0.0)) {
      throw std::invalid_argument("LmeBasis: node " + std::to_string(a) + " has gamma = " + std::to_string(gamma_[a]) +
                                  ", h = " + std::to_string(spacing_[a]) + " (both must be > 0)");
    }
    beta_[a] = gamma_[a] / (spacing_[a] * spacing_[a]);
    radius_[a] = support_radius(beta_[a], options_.tol0);
  }
  if (second_order()) init_gaps();
  if (mirrored()) init_mirror();
  radius_range_ = radius_range(radius_);
  all_radius_range_ = radius_range(all_radius_);
}

void LmeBasis::init_gaps() {
  for (std::size_t a = 0; a < gamma_.size(); ++a) {
    if (gamma_[a] > lme_second_order_max_gamma) {
      std::ostringstream os;
      os << "LmeBasis: the second-order basis needs gamma <= " << lme_second_order_max_gamma << ", node " << a
         << " has gamma = " << gamma_[a]
         << ": its second moment h^2/(2 gamma) must exceed the squared distance from a point to the nodes around it; "
            "use a smaller gamma or the first-order basis (LmeConsistency::first)";
      throw std::invalid_argument(os.str());
    }
  }
  const std::size_t n = nodes_.size(), d = static_cast<std::size_t>(dim());
  if (!mirrored()) {
    gap_ = detail::second_order_gaps(nodes_, spacing_, gamma_, nodes_);
    return;
  }
  check_mirrors();
  // With mirror symmetry the planes are no hull boundaries: the hull is that of the nodes and their
  // reflections across every subset of the planes.
  std::vector<double> all = nodes_.coords;
  const std::size_t subsets = std::size_t(1) << options_.mirrors.size();
  for (std::size_t mask = 1; mask < subsets; ++mask)
    for (std::size_t a = 0; a < n; ++a) {
      std::array<double, 3> x{};
      for (std::size_t i = 0; i < d; ++i) x[i] = nodes_.coords[a * d + i];
      for (std::size_t p = 0; p < options_.mirrors.size(); ++p)
        if (mask & (std::size_t(1) << p)) {
          const auto axis = std::size_t(options_.mirrors[p].axis);
          x[axis] = 2.0 * options_.mirrors[p].position - x[axis];
        }
      all.insert(all.end(), x.begin(), x.begin() + std::ptrdiff_t(d));
    }
  gap_ = detail::second_order_gaps(nodes_, spacing_, gamma_, NodeSet(dim(), std::move(all)));
}

void LmeBasis::check_mirrors() const {
  const std::size_t n = nodes_.size(), d = static_cast<std::size_t>(dim());
  std::vector<int> axes;
  for (const MirrorPlane& m : options_.mirrors) {
    if (m.axis < 0 || m.axis >= dim())
      throw std::invalid_argument("LmeBasis: a mirror plane on axis " + std::to_string(m.axis) + " in dimension " + std::to_string(dim()));
    if (std::find(axes.begin(), axes.end(), m.axis) != axes.end())
      throw std::invalid_argument("LmeBasis: two mirror planes on axis " + std::to_string(m.axis));
    axes.push_back(m.axis);
    double extent = 0.0, lo = 0.0, hi = 0.0;
    for (std::size_t a = 0; a < n; ++a) {
      const double delta = nodes_.coords[a * d + std::size_t(m.axis)] - m.position;
      extent = std::max(extent, std::abs(delta));
      lo = std::min(lo, delta);
      hi = std::max(hi, delta);
    }
    // Every node on the same side: the reflection of one side is the other.
    const double on_plane = 1e-12 * std::max(extent, 1e-300);
    if (lo < -on_plane && hi > on_plane) {
      throw std::invalid_argument("LmeBasis: mirror symmetry about x[" + std::to_string(m.axis) + "] = " + std::to_string(m.position) +
                                  " needs every node on one side of the plane (they span " + std::to_string(m.position + lo) + " .. " +
                                  std::to_string(m.position + hi) + ")");
    }
  }
}

void LmeBasis::init_mirror() {
  check_mirrors();
  const std::size_t n = nodes_.size(), d = static_cast<std::size_t>(dim()), planes = options_.mirrors.size();
  std::vector<double> on_plane(planes);
  for (std::size_t p = 0; p < planes; ++p) {
    double extent = 0.0;
    for (std::size_t a = 0; a < n; ++a) extent = std::max(extent, std::abs(nodes_.coords[a * d + std::size_t(options_.mirrors[p].axis)] - options_.mirrors[p].position));
    on_plane[p] = 1e-12 * std::max(extent, 1e-300);
  }
  all_coords_ = nodes_.coords;
  all_beta_ = beta_;
  all_radius_ = radius_;
  all_gap_ = gap_;
  const std::size_t s = second_order() ? d * (d + 1) / 2 : 0;
  image_offsets_.assign(n + 1, 0);
  for (std::size_t a = 0; a < n; ++a) {
    // Across each subset of the planes its support reaches (the distance to their intersection
    // below the radius); a node on a plane is its own image across it.
    for (std::size_t mask = 1; mask < (std::size_t(1) << planes); ++mask) {
      double reach2 = 0.0;
      bool image = true;
      std::array<bool, 3> flipped{};
      for (std::size_t p = 0; p < planes && image; ++p) {
        if (!(mask & (std::size_t(1) << p))) continue;
        const double delta = nodes_.coords[a * d + std::size_t(options_.mirrors[p].axis)] - options_.mirrors[p].position;
        image = std::abs(delta) > on_plane[p];
        reach2 += delta * delta;
        flipped[std::size_t(options_.mirrors[p].axis)] = true;
      }
      if (!image || reach2 >= radius_[a] * radius_[a]) continue;
      image_source_.push_back(static_cast<int>(a));
      for (std::size_t i = 0; i < d; ++i) all_coords_.push_back(nodes_.coords[a * d + i]);
      for (std::size_t p = 0; p < planes; ++p)
        if (mask & (std::size_t(1) << p)) {
          double& c = all_coords_[all_coords_.size() - d + std::size_t(options_.mirrors[p].axis)];
          c = 2.0 * options_.mirrors[p].position - c;
        }
      all_beta_.push_back(beta_[a]);
      all_radius_.push_back(radius_[a]);
      // The reflected gap: entries coupling a reflected axis with one that is not change sign.
      for (std::size_t i = 0; i < d && s > 0; ++i)
        for (std::size_t j = i; j < d; ++j) {
          const double g = gap_[a * s + static_cast<std::size_t>(kernel::hessian_slot(int(i), int(j), dim()) - 1 - dim())];
          all_gap_.push_back(flipped[i] != flipped[j] ? -g : g);
        }
    }
    image_offsets_[a + 1] = static_cast<int>(image_source_.size());
  }
  all_tree_.emplace(NodeSet(dim(), all_coords_));
}

std::size_t LmeBasis::extend(std::span<const double> x, std::span<const int> nbrs, LmeWorkspace& ws) const {
  const std::size_t n = nodes_.size(), d = static_cast<std::size_t>(dim());
  ws.extended.assign(nbrs.begin(), nbrs.end());
  ws.mirror_fold.clear();
  for (std::size_t k = 0; k < nbrs.size(); ++k) {
    const auto a = static_cast<std::size_t>(nbrs[k]);
    for (int image = image_offsets_[a]; image < image_offsets_[a + 1]; ++image) {
      const std::size_t e = n + static_cast<std::size_t>(image);
      double r2 = 0.0;
      for (std::size_t i = 0; i < d; ++i) {
        const double t = x[i] - all_coords_[e * d + i];
        r2 += t * t;
      }
      if (r2 > all_radius_[e] * all_radius_[e]) continue;
      ws.extended.push_back(static_cast<int>(e));
      ws.mirror_fold.push_back(static_cast<int>(k));
    }
  }
  return ws.extended.size();
}

void LmeBasis::check_order(int order, const char* who) const {
  if (order < 0 || order > 2) {
    throw std::invalid_argument(std::string(who) + ": derivative order must be 0, 1 or 2, got " +
                                std::to_string(order));
  }
}

int LmeBasis::record_size(int order) const noexcept {
  return second_order() ? lme_second_order_record_size(dim(), order) : lme_record_size(dim(), order);
}

std::vector<double> LmeBasis::gap_corrected(std::span<const double> values, std::span<const double> hessians) const {
  const std::size_t n = nodes_.size(), d = static_cast<std::size_t>(dim()), s = d * (d + 1) / 2;
  if (values.size() != n || hessians.size() != n * s) {
    throw std::invalid_argument("LmeBasis::gap_corrected: " + std::to_string(values.size()) + " values and " +
                                std::to_string(hessians.size()) + " Hessian entries for " + std::to_string(n) +
                                " nodes (need one value and " + std::to_string(s) + " entries per node)");
  }
  std::vector<double> out(values.begin(), values.end());
  if (!second_order()) return out;
  for (std::size_t a = 0; a < n; ++a)
    for (std::size_t i = 0; i < d; ++i)
      for (std::size_t j = i; j < d; ++j) {
        const std::size_t k = a * s + static_cast<std::size_t>(kernel::hessian_slot(int(i), int(j), dim()) - 1 - dim());
        out[a] -= (i == j ? 0.5 : 1.0) * hessians[k] * gap_[k];
      }
  return out;
}

std::vector<int> LmeBasis::neighbours(std::span<const double> x) const {
  return neighbour_lists(x).indices;
}

CsrLists LmeBasis::neighbour_lists(std::span<const double> points) const {
  if (!mirrored()) return primal_lists(tree_, points, radius_, radius_range_);
  // Lists over nodes and images, images mapped to their nodes (a node may reach x twice).
  const CsrLists all = primal_lists(*all_tree_, points, all_radius_, all_radius_range_);
  const auto n = static_cast<int>(nodes_.size());
  CsrLists out;
  out.offsets.assign(all.offsets.size(), 0);
  out.indices.reserve(all.indices.size());
  std::vector<int> row;
  for (std::size_t q = 0; q + 1 < all.offsets.size(); ++q) {
    row.clear();
    for (int k = all.offsets[q]; k < all.offsets[q + 1]; ++k) {
      const int b = all.indices[static_cast<std::size_t>(k)];
      row.push_back(b < n ? b : image_source_[static_cast<std::size_t>(b - n)]);
    }
    std::sort(row.begin(), row.end());
    row.erase(std::unique(row.begin(), row.end()), row.end());
    out.indices.insert(out.indices.end(), row.begin(), row.end());
    out.offsets[q + 1] = static_cast<int>(out.indices.size());
  }
  return out;
}

void LmeBasis::evaluate(std::span<const double> x, std::span<const int> nbrs, int order, std::span<double> jet,
                        LmeWorkspace& ws) const {
  check_order(order, "LmeBasis::evaluate");
  const std::size_t n = nbrs.size();
  if (x.size() != static_cast<std::size_t>(dim()) ||
      jet.size() < static_cast<std::size_t>(kernel::jet_size(dim(), order)) * n) {
    throw std::invalid_argument("LmeBasis::evaluate: point has " + std::to_string(x.size()) +
                                " coordinates (dim " + std::to_string(dim()) + "), jet buffer holds " +
                                std::to_string(jet.size()) + " doubles");
  }
  const std::size_t n_all = mirrored() ? extend(x, nbrs, ws) : n;
  const std::span<const int> list = mirrored() ? std::span<const int>(ws.extended) : nbrs;
  const int rows = kernel::jet_size(dim(), order);
  double* out = jet.data();
  std::size_t stride = n;
  if (mirrored()) {
    ws.mirror_jet.resize(static_cast<std::size_t>(rows) * n_all);
    out = ws.mirror_jet.data();
    stride = n_all;
  }
  if (second_order()) {
    detail::second_order_evaluate(dim(), {coords_data(), beta_data(), gap_data()}, options_, x, list, order, out, stride, ws);
  } else {
    evaluate_first_order(x, list, order, out, stride, ws);
  }
  if (mirrored()) fold_images(out, n_all, n, rows, ws.mirror_fold.data(), jet.data(), n, nullptr);
}

void LmeBasis::evaluate_first_order(std::span<const double> x, std::span<const int> list, int order, double* out,
                                    std::size_t stride, LmeWorkspace& ws) const {
  const std::size_t n_all = list.size();
  detail::dispatch(dim(), [&](auto dc) {
    constexpr int D = decltype(dc)::value;
    using K = Lme<D>;
    const int ni = static_cast<int>(n_all);
    double len = 0.0, lnz = 0.0;
    const Vec<D> lam = K::solve(coords_data(), beta_data(), x, list, ws, options_, len, lnz);
    if (order == 0) {
      std::copy(ws.p.begin(), ws.p.begin() + static_cast<std::ptrdiff_t>(n_all), out);
      return;
    }
    ws.record.resize(static_cast<std::size_t>(lme_record_size(D, order)));
    K::build_record(x, ni, ws, lam, lnz, order, options_.min_rcond, ws.record.data());
    K::jet(ni, ws.y.data(), ws.beta.data(), ws.record.data(), order, order, ws.p.data(), 1.0 / len, out, stride,
           nullptr);
  });
}

std::vector<double> LmeBasis::evaluate(std::span<const double> x, std::span<const int> nbrs, int order) const {
  check_order(order, "LmeBasis::evaluate");
  std::vector<double> jet(static_cast<std::size_t>(kernel::jet_size(dim(), order)) * nbrs.size());
  LmeWorkspace ws;
  evaluate(x, nbrs, order, jet, ws);
  return jet;
}

void LmeBasis::tabulate_cell(std::span<const double> points, std::span<const int> cell_nodes, int order,
                             std::span<double> basis, LmeWorkspace& ws) const {
  check_order(order, "LmeBasis::tabulate_cell");
  const auto d = static_cast<std::size_t>(dim());
  const std::size_t nq = points.size() / d;
  const std::size_t block = static_cast<std::size_t>(kernel::jet_size(dim(), order)) * cell_nodes.size();
  if (points.size() % d != 0 || basis.size() < nq * block) {
    throw std::invalid_argument("LmeBasis::tabulate_cell: " + std::to_string(points.size()) + " coordinates, buffer " +
                                std::to_string(basis.size()) + " < " + std::to_string(nq * block) + " doubles");
  }
  for (std::size_t q = 0; q < nq; ++q) {
    evaluate(points.subspan(q * d, d), cell_nodes, order, basis.subspan(q * block, block), ws);
  }
}

void LmeBasis::solve_record(std::span<const double> x, std::span<const int> nbrs, int order, std::span<double> record,
                            LmeWorkspace& ws) const {
  check_order(order, "LmeBasis::solve_record");
  if (x.size() != static_cast<std::size_t>(dim()) ||
      record.size() < static_cast<std::size_t>(record_size(order))) {
    throw std::invalid_argument("LmeBasis::solve_record: bad point or record size");
  }
  const std::size_t n_all = mirrored() ? extend(x, nbrs, ws) : nbrs.size();
  const std::span<const int> list = mirrored() ? std::span<const int>(ws.extended) : nbrs;
  if (second_order()) {
    detail::second_order_solve_record(dim(), {coords_data(), beta_data(), gap_data()}, options_, x, list, order,
                                      record.data(), ws);
    return;
  }
  detail::dispatch(dim(), [&](auto dc) {
    constexpr int D = decltype(dc)::value;
    using K = Lme<D>;
    const int ni = static_cast<int>(n_all);
    double len = 0.0, lnz = 0.0;
    const Vec<D> lam = K::solve(coords_data(), beta_data(), x, list, ws, options_, len, lnz);
    K::build_record(x, ni, ws, lam, lnz, order, options_.min_rcond, record.data());
    K::unscale_record(order, len, record.data());
  });
}

void LmeBasis::reconstruct(std::span<const double> x, std::span<const int> nbrs, int record_order,
                           std::span<const double> record, int order, std::span<double> jet, std::size_t stride,
                           std::span<const int> columns, LmeWorkspace& ws) const {
  check_order(order, "LmeBasis::reconstruct");
  if (order > record_order) {
    throw std::invalid_argument("LmeBasis::reconstruct: order " + std::to_string(order) +
                                " exceeds the record's order " + std::to_string(record_order));
  }
  if (!columns.empty() && columns.size() != nbrs.size()) {
    throw std::invalid_argument("LmeBasis::reconstruct: columns and neighbours differ in size");
  }
  const std::size_t n_all = mirrored() ? extend(x, nbrs, ws) : nbrs.size();
  const std::span<const int> list = mirrored() ? std::span<const int>(ws.extended) : nbrs;
  const int rows = kernel::jet_size(dim(), order);
  if (mirrored()) ws.mirror_jet.resize(static_cast<std::size_t>(rows) * n_all);
  if (second_order()) {
    double* out = mirrored() ? ws.mirror_jet.data() : jet.data();
    detail::second_order_reconstruct(dim(), {coords_data(), beta_data(), gap_data()}, x, list, record_order,
                                     record.data(), order, out, mirrored() ? n_all : stride,
                                     mirrored() || columns.empty() ? nullptr : columns.data(), ws);
  } else {
    reconstruct_first_order(x, list, record_order, record, order, jet, stride, columns, ws);
  }
  if (mirrored()) {
    fold_images(ws.mirror_jet.data(), n_all, nbrs.size(), rows, ws.mirror_fold.data(), jet.data(), stride,
                columns.empty() ? nullptr : columns.data());
  }
}

void LmeBasis::reconstruct_first_order(std::span<const double> x, std::span<const int> list, int record_order,
                                       std::span<const double> record, int order, std::span<double> jet,
                                       std::size_t stride, std::span<const int> columns, LmeWorkspace& ws) const {
  const std::size_t n_all = list.size();
  detail::dispatch(dim(), [&](auto dc) {
    constexpr int D = decltype(dc)::value;
    const double* coords = coords_data();
    const double* beta = beta_data();
    ws.y.resize(n_all * D);
    ws.beta.resize(n_all);
    for (std::size_t a = 0; a < n_all; ++a) {
      const auto b = static_cast<std::size_t>(list[a]);
      for (std::size_t i = 0; i < D; ++i) ws.y[a * D + i] = x[i] - coords[b * D + i];
      ws.beta[a] = beta[b];
    }
    if (mirrored()) {
      Lme<D>::jet(static_cast<int>(n_all), ws.y.data(), ws.beta.data(), record.data(), record_order, order, nullptr,
                  1.0, ws.mirror_jet.data(), n_all, nullptr);
    } else {
      Lme<D>::jet(static_cast<int>(n_all), ws.y.data(), ws.beta.data(), record.data(), record_order, order, nullptr,
                  1.0, jet.data(), stride, columns.empty() ? nullptr : columns.data());
    }
  });
}

}  // namespace lmeform
