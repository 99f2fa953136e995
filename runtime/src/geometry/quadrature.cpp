#include "lmeform/quadrature.hpp"

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <numbers>
#include <stdexcept>
#include <string>
#include <vector>

namespace lmeform {

namespace {

using Real = long double;  // the solves run in extended precision so that rounding to double is the only error
using MatrixR = Eigen::Matrix<Real, Eigen::Dynamic, Eigen::Dynamic>;
using VectorR = Eigen::Matrix<Real, Eigen::Dynamic, 1>;

// Fully symmetric orbits in barycentric coordinates. A pattern assigns each barycentric slot one of
// the orbit's distinct values; the orbit's points are the distinct permutations of the pattern.
enum class Orbit { Centroid, S21, S111, S31, S22, S211 };

struct OrbitGuess {
  Orbit kind;
  std::vector<Real> params;  // starting values of the free parameters (a, or a and b)
  Real weight;               // starting weight per point, normalised so that all weights sum to 1
  bool params_fixed = false; // pins a one-parameter family of solutions to one member
};

struct RuleSpec {
  int npoints;
  int degree;
  std::vector<OrbitGuess> orbits;
};

int param_count(Orbit kind) {
  switch (kind) {
    case Orbit::Centroid: return 0;
    case Orbit::S21: case Orbit::S31: case Orbit::S22: return 1;
    case Orbit::S111: case Orbit::S211: return 2;
  }
  return 0;
}

std::vector<int> pattern_of(Orbit kind, int nbary) {
  switch (kind) {
    case Orbit::Centroid: return std::vector<int>(static_cast<std::size_t>(nbary), 0);
    case Orbit::S21: return {0, 0, 1};
    case Orbit::S111: return {0, 1, 2};
    case Orbit::S31: return {0, 0, 0, 1};
    case Orbit::S22: return {0, 0, 1, 1};
    case Orbit::S211: return {0, 0, 1, 2};
  }
  return {};
}

std::vector<Real> values_of(Orbit kind, int nbary, const Real* p) {
  switch (kind) {
    case Orbit::Centroid: return {Real(1) / Real(nbary)};
    case Orbit::S21: return {p[0], 1 - 2 * p[0]};
    case Orbit::S111: return {p[0], p[1], 1 - p[0] - p[1]};
    case Orbit::S31: return {p[0], 1 - 3 * p[0]};
    case Orbit::S22: return {p[0], Real(0.5) - p[0]};
    case Orbit::S211: return {p[0], p[1], 1 - 2 * p[0] - p[1]};
  }
  return {};
}

// Reference coordinates of the orbit's points: barycentric slots 1..dim (slot 0 is the origin vertex).
std::vector<std::vector<Real>> orbit_points(Orbit kind, int dim, const Real* p) {
  const int nbary = dim + 1;
  auto pattern = pattern_of(kind, nbary);
  if (static_cast<int>(pattern.size()) != nbary) throw std::logic_error("quadrature: orbit does not fit the simplex");
  const auto vals = values_of(kind, nbary, p);
  std::sort(pattern.begin(), pattern.end());
  std::vector<std::vector<Real>> out;
  do {
    std::vector<Real> x(static_cast<std::size_t>(dim));
    for (int i = 0; i < dim; ++i) x[static_cast<std::size_t>(i)] = vals[static_cast<std::size_t>(pattern[static_cast<std::size_t>(i + 1)])];
    out.push_back(std::move(x));
  } while (std::next_permutation(pattern.begin(), pattern.end()));
  return out;
}

// Exponents of every monomial of total degree <= degree in dim variables.
std::vector<std::array<int, 3>> monomials(int dim, int degree) {
  std::vector<std::array<int, 3>> out;
  for (int i = 0; i <= degree; ++i)
    for (int j = 0; j <= (dim >= 2 ? degree - i : 0); ++j)
      for (int k = 0; k <= (dim >= 3 ? degree - i - j : 0); ++k) out.push_back({i, j, k});
  return out;
}

Real factorial(int n) {
  Real f = 1;
  for (int i = 2; i <= n; ++i) f *= i;
  return f;
}

// Mean of x^i y^j z^k over the reference simplex: (i! j! k! / (i+j+k+dim)!) / (1/dim!).
Real monomial_mean(int dim, const std::array<int, 3>& e) {
  return factorial(e[0]) * factorial(e[1]) * factorial(e[2]) * factorial(dim) / factorial(e[0] + e[1] + e[2] + dim);
}

Real eval_monomial(const std::vector<Real>& x, const std::array<int, 3>& e) {
  Real v = 1;
  for (std::size_t i = 0; i < x.size(); ++i) v *= std::pow(x[i], static_cast<Real>(e[i]));
  return v;
}

struct Layout {
  std::vector<int> first;  // index of the orbit's first unknown
};

VectorR residual(const RuleSpec& spec, int dim, const VectorR& u, const std::vector<std::array<int, 3>>& mono,
                 const std::vector<Real>& fixed_params, const Layout& layout) {
  VectorR r = VectorR::Zero(static_cast<Eigen::Index>(mono.size()));
  for (std::size_t o = 0; o < spec.orbits.size(); ++o) {
    const auto& orb = spec.orbits[o];
    const int np = param_count(orb.kind);
    std::array<Real, 2> p{};
    for (int k = 0; k < np; ++k)
      p[static_cast<std::size_t>(k)] = orb.params_fixed ? fixed_params[o * 2 + static_cast<std::size_t>(k)]
                                                        : u(layout.first[o] + k);
    const Real w = u(layout.first[o] + (orb.params_fixed ? 0 : np));
    for (const auto& x : orbit_points(orb.kind, dim, p.data()))
      for (std::size_t m = 0; m < mono.size(); ++m) r(static_cast<Eigen::Index>(m)) += w * eval_monomial(x, mono[m]);
  }
  for (std::size_t m = 0; m < mono.size(); ++m) r(static_cast<Eigen::Index>(m)) -= monomial_mean(dim, mono[m]);
  return r;
}

// Solves the moment equations of all monomials up to spec.degree (an overdetermined but consistent
// system) by damped Gauss-Newton from the rough starting values in spec.
QuadratureRule solve_rule(const RuleSpec& spec, int dim, const std::string& shape) {
  Layout layout;
  std::vector<Real> fixed(spec.orbits.size() * 2, 0);
  int n = 0;
  for (std::size_t o = 0; o < spec.orbits.size(); ++o) {
    layout.first.push_back(n);
    const auto& orb = spec.orbits[o];
    const int np = param_count(orb.kind);
    if (orb.params_fixed) {
      for (int k = 0; k < np; ++k) fixed[o * 2 + static_cast<std::size_t>(k)] = orb.params[static_cast<std::size_t>(k)];
      n += 1;
    } else {
      n += np + 1;
    }
  }
  VectorR u(n);
  for (std::size_t o = 0; o < spec.orbits.size(); ++o) {
    const auto& orb = spec.orbits[o];
    const int np = orb.params_fixed ? 0 : param_count(orb.kind);
    for (int k = 0; k < np; ++k) u(layout.first[o] + k) = orb.params[static_cast<std::size_t>(k)];
    u(layout.first[o] + np) = orb.weight;
  }
  const auto mono = monomials(dim, spec.degree);
  VectorR r = residual(spec, dim, u, mono, fixed, layout);
  const Real h = 1e-7L;
  for (int it = 0; it < 100 && r.lpNorm<Eigen::Infinity>() > 1e-18L; ++it) {
    MatrixR J(r.size(), n);
    for (int k = 0; k < n; ++k) {
      VectorR up = u, um = u;
      up(k) += h;
      um(k) -= h;
      J.col(k) = (residual(spec, dim, up, mono, fixed, layout) - residual(spec, dim, um, mono, fixed, layout)) / (2 * h);
    }
    const VectorR step = Eigen::CompleteOrthogonalDecomposition<MatrixR>(J).solve(-r);
    Real t = 1;
    for (; t > 1e-6L; t /= 2) {
      VectorR trial = u + t * step;
      VectorR rt = residual(spec, dim, trial, mono, fixed, layout);
      if (rt.norm() < r.norm()) {
        u = trial;
        r = rt;
        break;
      }
    }
    if (t <= 1e-6L) break;
  }
  const Real res = r.lpNorm<Eigen::Infinity>();
  const std::string name = shape + "-" + std::to_string(spec.npoints) + " (degree " + std::to_string(spec.degree) + ")";
  if (!(res < 1e-16L)) {
    throw std::logic_error("quadrature: moment equations of " + name + " did not converge (residual " +
                           std::to_string(static_cast<double>(res)) + ")");
  }
  QuadratureRule rule;
  rule.name = name;
  rule.dim = dim;
  rule.degree = spec.degree;
  const Real measure = 1 / factorial(dim);
  for (std::size_t o = 0; o < spec.orbits.size(); ++o) {
    const auto& orb = spec.orbits[o];
    const int np = param_count(orb.kind);
    std::array<Real, 2> p{};
    for (int k = 0; k < np; ++k)
      p[static_cast<std::size_t>(k)] = orb.params_fixed ? fixed[o * 2 + static_cast<std::size_t>(k)] : u(layout.first[o] + k);
    const Real w = u(layout.first[o] + (orb.params_fixed ? 0 : np));
    for (const auto& x : orbit_points(orb.kind, dim, p.data())) {
      for (const Real xi : x) rule.points.push_back(static_cast<double>(xi));
      rule.weights.push_back(static_cast<double>(w * measure));
    }
  }
  if (static_cast<int>(rule.size()) != spec.npoints) throw std::logic_error("quadrature: " + name + " has the wrong point count");
  return rule;
}

// Orbit structures and starting values (4 significant digits; the solve supplies the rest).
// The structures are those of the symmetric rules of Dunavant (triangle; Int. J. Numer. Meth. Eng.
// 21, 1985) and Keast (tetrahedron; CMAME 55, 1986), the 14-point tetrahedron one of Walkington's
// positive degree-5 rule; the counts of unknowns match the counts of symmetric invariants, so each
// solution is locally unique (the 15-point family is pinned by fixing its S22 parameter).
std::vector<RuleSpec> triangle_specs() {
  using O = Orbit;
  return {
      {1, 1, {{O::Centroid, {}, 1}}},
      {3, 2, {{O::S21, {0.1667L}, 0.3333L}}},
      {6, 4, {{O::S21, {0.4459L}, 0.2234L}, {O::S21, {0.09158L}, 0.1100L}}},
      {7, 5, {{O::Centroid, {}, 0.225L}, {O::S21, {0.1013L}, 0.1259L}, {O::S21, {0.4701L}, 0.1324L}}},
      {12, 6, {{O::S21, {0.06309L}, 0.05084L}, {O::S21, {0.2493L}, 0.1168L}, {O::S111, {0.05315L, 0.3104L}, 0.08285L}}},
      {16, 8, {{O::Centroid, {}, 0.1443L}, {O::S21, {0.4593L}, 0.09509L}, {O::S21, {0.1706L}, 0.1032L},
               {O::S21, {0.05055L}, 0.03246L}, {O::S111, {0.008395L, 0.2631L}, 0.02723L}}},
      {19, 9, {{O::Centroid, {}, 0.09714L}, {O::S21, {0.4897L}, 0.03133L}, {O::S21, {0.4371L}, 0.07783L},
               {O::S21, {0.1882L}, 0.07965L}, {O::S21, {0.04473L}, 0.02558L},
               {O::S111, {0.03684L, 0.2220L}, 0.04328L}}},
  };
}

std::vector<RuleSpec> tetrahedron_specs() {
  using O = Orbit;
  return {
      {1, 1, {{O::Centroid, {}, 1}}},
      {4, 2, {{O::S31, {0.1382L}, 0.25L}}},
      {5, 3, {{O::Centroid, {}, -0.8L}, {O::S31, {0.1667L}, 0.45L}}},
      {11, 4, {{O::Centroid, {}, -0.07893L}, {O::S31, {0.07143L}, 0.04573L}, {O::S22, {0.3994L}, 0.1493L}}},
      {14, 5, {{O::S31, {0.09274L}, 0.07349L}, {O::S31, {0.3109L}, 0.1127L}, {O::S22, {0.04550L}, 0.04255L}}},
      {15, 5, {{O::Centroid, {}, 0.1185L}, {O::S31, {0.09197L}, 0.07194L}, {O::S31, {0.3198L}, 0.06907L},
               {O::S22, {(1 - std::sqrt(0.6L)) / 4}, 0.05291L, true}}},
      {24, 6, {{O::S31, {0.2146L}, 0.03992L}, {O::S31, {0.04067L}, 0.01008L}, {O::S31, {0.3223L}, 0.05536L},
               {O::S211, {0.06366L, 0.2697L}, 0.04821L}}},
  };
}

template <class Specs>
std::vector<QuadratureRule> solve_all(const Specs& specs, int dim, const std::string& shape) {
  std::vector<QuadratureRule> rules;
  for (const auto& s : specs) rules.push_back(solve_rule(s, dim, shape));
  return rules;
}

const std::vector<QuadratureRule>& triangle_rules() {
  static const std::vector<QuadratureRule> rules = solve_all(triangle_specs(), 2, "triangle");
  return rules;
}

const std::vector<QuadratureRule>& tetrahedron_rules() {
  static const std::vector<QuadratureRule> rules = solve_all(tetrahedron_specs(), 3, "tetrahedron");
  return rules;
}

const QuadratureRule& find_rule(const std::vector<QuadratureRule>& rules, int npoints, const char* who) {
  for (const auto& r : rules)
    if (static_cast<int>(r.size()) == npoints) return r;
  std::string sizes;
  for (const auto& r : rules) sizes += (sizes.empty() ? "" : ", ") + std::to_string(r.size());
  throw std::invalid_argument(std::string(who) + ": no rule with " + std::to_string(npoints) +
                              " points (available: " + sizes + ")");
}

}  // namespace

bool QuadratureRule::has_negative_weights() const noexcept {
  return std::any_of(weights.begin(), weights.end(), [](double w) { return w < 0.0; });
}

double reference_measure(int dim) {
  switch (dim) {
    case 1: return 1.0;
    case 2: return 0.5;
    case 3: return 1.0 / 6.0;
    default: throw std::invalid_argument("reference_measure: dimension must be 1, 2 or 3, got " + std::to_string(dim));
  }
}

QuadratureRule gauss_legendre(int n) {
  if (n < 1) throw std::invalid_argument("gauss_legendre: need at least one point, got " + std::to_string(n));
  QuadratureRule rule;
  rule.name = "gauss-legendre-" + std::to_string(n) + " (degree " + std::to_string(2 * n - 1) + ")";
  rule.dim = 1;
  rule.degree = 2 * n - 1;
  rule.points.resize(static_cast<std::size_t>(n));
  rule.weights.resize(static_cast<std::size_t>(n));
  // P_n(x) and P_n'(x) by the three-term recurrence.
  const auto legendre = [n](Real x, Real& dp) {
    Real p0 = 1, p1 = x;
    for (int k = 2; k <= n; ++k) {
      const Real pk = ((2 * k - 1) * x * p1 - (k - 1) * p0) / k;
      p0 = p1;
      p1 = pk;
    }
    dp = n * (x * p1 - p0) / (x * x - 1);
    return p1;
  };
  for (int i = 0; i < n; ++i) {
    // Roots of P_n on [-1, 1] by Newton from the Chebyshev-like estimate.
    Real x = std::cos(std::numbers::pi_v<Real> * (i + Real(0.75)) / (n + Real(0.5)));
    Real dp = 1;
    for (int it = 0; it < 100; ++it) {
      const Real dx = legendre(x, dp) / dp;
      x -= dx;
      if (std::abs(dx) < 1e-19L) break;
    }
    (void)legendre(x, dp);
    const Real w = 2 / ((1 - x * x) * dp * dp);
    // Map [-1, 1] -> [0, 1]; points increase with i.
    rule.points[static_cast<std::size_t>(i)] = static_cast<double>((1 - x) / 2);
    rule.weights[static_cast<std::size_t>(i)] = static_cast<double>(w / 2);
  }
  return rule;
}

QuadratureRule triangle_rule(int npoints) { return find_rule(triangle_rules(), npoints, "triangle_rule"); }
QuadratureRule tetrahedron_rule(int npoints) { return find_rule(tetrahedron_rules(), npoints, "tetrahedron_rule"); }

std::vector<int> triangle_rule_sizes() {
  std::vector<int> s;
  for (const auto& spec : triangle_specs()) s.push_back(spec.npoints);
  return s;
}

std::vector<int> tetrahedron_rule_sizes() {
  std::vector<int> s;
  for (const auto& spec : tetrahedron_specs()) s.push_back(spec.npoints);
  return s;
}

QuadratureRule simplex_rule(int dim, int degree, bool positive_weights_only) {
  if (degree < 0) throw std::invalid_argument("simplex_rule: negative degree " + std::to_string(degree));
  if (dim == 1) return gauss_legendre(std::max(1, (degree + 2) / 2));
  if (dim != 2 && dim != 3) throw std::invalid_argument("simplex_rule: dimension must be 1, 2 or 3, got " + std::to_string(dim));
  const auto& rules = dim == 2 ? triangle_rules() : tetrahedron_rules();
  const QuadratureRule* best = nullptr;
  for (const auto& r : rules) {
    if (r.degree < degree || (positive_weights_only && r.has_negative_weights())) continue;
    if (best == nullptr || r.size() < best->size()) best = &r;
  }
  if (best == nullptr) {
    throw std::invalid_argument("simplex_rule: no " + std::string(dim == 2 ? "triangle" : "tetrahedron") +
                                " rule of degree " + std::to_string(degree) +
                                (positive_weights_only ? " with positive weights" : ""));
  }
  return *best;
}

CellQuadrature map_to_cells(const BackgroundCells& cells, const NodeSet& nodes, const QuadratureRule& rule) {
  std::vector<int> every(cells.size());
  for (std::size_t c = 0; c < every.size(); ++c) every[c] = static_cast<int>(c);
  return map_to_cells(cells, nodes, rule, every);
}

CellQuadrature map_to_cells(const BackgroundCells& cells, const NodeSet& nodes, const QuadratureRule& rule,
                            std::span<const int> which) {
  if (cells.dim != nodes.dim || rule.dim != cells.dim) {
    throw std::invalid_argument("map_to_cells: dimensions differ (cells " + std::to_string(cells.dim) + ", nodes " +
                                std::to_string(nodes.dim) + ", rule " + std::to_string(rule.dim) + ")");
  }
  const auto d = static_cast<std::size_t>(cells.dim);
  const std::size_t nq = rule.size();
  const double ref = reference_measure(cells.dim);
  CellQuadrature out;
  out.dim = cells.dim;
  out.points_per_cell = static_cast<int>(nq);
  out.points.resize(which.size() * nq * d);
  out.weights.resize(which.size() * nq);
  for (std::size_t slot = 0; slot < which.size(); ++slot) {
    if (which[slot] < 0 || static_cast<std::size_t>(which[slot]) >= cells.size())
      throw std::out_of_range("map_to_cells: no cell " + std::to_string(which[slot]) + " of " + std::to_string(cells.size()));
    const auto c = static_cast<std::size_t>(which[slot]);
    const auto v = cells.cell(c);
    for (int k : v) {
      if (k < 0 || static_cast<std::size_t>(k) >= nodes.size())
        throw std::out_of_range("map_to_cells: cell " + std::to_string(c) + " refers to node " + std::to_string(k) +
                                " of " + std::to_string(nodes.size()));
    }
    const auto x0 = nodes.point(static_cast<std::size_t>(v[0]));
    // The weights scale by |det J| = measure / reference measure; cells are positively oriented.
    const double scale = cells.measures[c] / ref;
    for (std::size_t q = 0; q < nq; ++q) {
      const auto xi = rule.point(q);
      double* x = out.points.data() + (slot * nq + q) * d;
      for (std::size_t i = 0; i < d; ++i) x[i] = x0[i];
      for (std::size_t k = 0; k < d; ++k) {
        const auto xk = nodes.point(static_cast<std::size_t>(v[k + 1]));
        for (std::size_t i = 0; i < d; ++i) x[i] += xi[k] * (xk[i] - x0[i]);
      }
      out.weights[slot * nq + q] = rule.weights[q] * scale;
    }
  }
  return out;
}

}  // namespace lmeform
