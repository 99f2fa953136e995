#include "lmeform/form_check.hpp"
#include "lmeform/contractions.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <functional>
#include <limits>
#include <optional>
#include <sstream>
#include <stdexcept>

#include <fmt/format.h>

namespace lmeform::formcheck {

using kernel::FunctionalKind;
using kernel::jet_size;

Cell Cell::restricted(int order) const {
  if (order > basis_order) {
    throw std::invalid_argument("Cell::restricted: tabulation has order " + std::to_string(basis_order) +
                                ", asked for " + std::to_string(order));
  }
  if (order == basis_order) return *this;
  Cell c = *this;
  const int J = jet_size(dim, basis_order), Jr = jet_size(dim, order);
  c.basis_order = order;
  c.basis.assign(static_cast<std::size_t>(nq) * Jr * n, 0.0);
  for (int q = 0; q < nq; ++q)
    for (int s = 0; s < Jr; ++s)
      for (int a = 0; a < n; ++a)
        c.basis[(static_cast<std::size_t>(q) * Jr + s) * n + a] = basis[(static_cast<std::size_t>(q) * J + s) * n + a];
  return c;
}

double Cell::jet(int q, int slot, const double* nodal, int stride, int c) const {
  const int J = jet_size(dim, basis_order);
  const double* B = basis.data() + (static_cast<std::size_t>(q) * J + slot) * n;
  double s = 0.0;
  for (int a = 0; a < n; ++a) s += B[a] * nodal[a * stride + c];
  return s;
}

Evaluator::Evaluator(const kernel::FormKernels& form, const Cell& cell, const State& state)
    : form_(form), state_(state) {
  const std::string label = std::string(form.module) + "::" + form.name;
  if (form.contract_version != kernel::kContractVersion)
    throw std::invalid_argument(fmt::format("form {}: contract version {}, expected {}", label, form.contract_version,
                                            kernel::kContractVersion));
  if (form.dim != cell.dim)
    throw std::invalid_argument(fmt::format("form {} is for dim {}, cell has dim {}", label, form.dim, cell.dim));
  cell_ = cell.restricted(std::max(form.basis_order, form.coefficient_basis_order));
  ndofs_ = cell.n * form.dofs_per_node;
  auto need = [&](std::size_t have, std::size_t want, const char* what) {
    if (have != want)
      throw std::invalid_argument(fmt::format("form {}: {} has {} values, kernel needs {}", label, what, have, want));
  };
  need(state.unknowns.size(), static_cast<std::size_t>(ndofs_), "unknowns");
  need(state.coefficients.size(), static_cast<std::size_t>(cell.n) * form.coefficient_components_per_node,
       "coefficients");
  need(state.qdata.size(), static_cast<std::size_t>(cell.nq) * form.qdata_per_point, "qdata");
  need(state.constants.size(), static_cast<std::size_t>(form.n_constants), "constants");
  if (form.workspace_doubles) workspace_.assign(form.workspace_doubles(cell.n, cell.nq) + 1, 0.0);
}

kernel::CellInputs Evaluator::inputs(const std::vector<double>& u) {
  kernel::CellInputs in;
  in.contractions = &dense_contractions();
  in.n_nodes = cell_.n;
  in.n_points = cell_.nq;
  in.basis_order = cell_.basis_order;
  in.weights = cell_.weights.data();
  in.points = cell_.points.data();
  in.basis = cell_.basis.data();
  in.unknowns = u.data();
  in.coefficients = state_.coefficients.empty() ? nullptr : state_.coefficients.data();
  in.qdata = state_.qdata.empty() ? nullptr : state_.qdata.data();
  in.constants = state_.constants.empty() ? nullptr : state_.constants.data();
  in.workspace = workspace_.empty() ? nullptr : workspace_.data();
  in.normals = cell_.normals.empty() ? nullptr : cell_.normals.data();
  if (form_.reads_spacing) {
    // A requirement on the resolution is checked at nodes; here each point's distance to its
    // nearest cell node stands in for a node's distance to its nearest neighbour.
    if (spacing_.empty())
      for (int q = 0; q < cell_.nq; ++q) {
        double nearest = std::numeric_limits<double>::infinity();
        for (int a = 0; a < cell_.n; ++a) {
          double d2 = 0;
          for (int i = 0; i < cell_.dim; ++i) {
            const double d = cell_.points[std::size_t(q * cell_.dim + i)] - cell_.nodes[std::size_t(a * cell_.dim + i)];
            d2 += d * d;
          }
          nearest = std::min(nearest, std::sqrt(d2));
        }
        spacing_.push_back(nearest);
      }
    in.spacing = spacing_.data();
  }
  return in;
}

double Evaluator::value(const std::vector<double>& u) {
  if (!form_.value) throw std::invalid_argument(std::string(form_.module) + "::" + form_.name + ": no value kernel");
  return form_.value(inputs(u));
}

std::vector<double> Evaluator::vector(const std::vector<double>& u) {
  if (!form_.vector) throw std::invalid_argument(std::string(form_.module) + "::" + form_.name + ": no vector kernel");
  std::vector<double> g(static_cast<std::size_t>(ndofs_), 0.0);
  form_.vector(inputs(u), g.data());
  return g;
}

std::vector<double> Evaluator::matrix(const std::vector<double>& u) {
  if (!form_.matrix) throw std::invalid_argument(std::string(form_.module) + "::" + form_.name + ": no matrix kernel");
  std::vector<double> H(static_cast<std::size_t>(ndofs_) * ndofs_, 0.0);
  form_.matrix(inputs(u), H.data());
  return H;
}

std::vector<double> Evaluator::point(const std::vector<double>& u) {
  const std::string label = std::string(form_.module) + "::" + form_.name;
  if (!form_.point) throw std::invalid_argument(label + ": no point kernel");
  // Unwritten values stay NaN (and fail the finiteness check); a guard after them catches a kernel
  // that writes more than n_values per point.
  constexpr std::size_t kGuard = 16;
  constexpr double kSentinel = -1.2345e300;
  const std::size_t size = static_cast<std::size_t>(cell_.nq) * static_cast<std::size_t>(std::max(form_.n_values, 0));
  std::vector<double> values(size, std::numeric_limits<double>::quiet_NaN());
  values.resize(size + kGuard, kSentinel);
  form_.point(inputs(u), values.data());
  for (std::size_t i = size; i < values.size(); ++i)
    if (values[i] != kSentinel)
      throw std::runtime_error(fmt::format("{}: the point kernel writes beyond n_values = {} per point", label, form_.n_values));
  values.resize(size);
  return values;
}

double fitted_slope(const std::vector<double>& h, const std::vector<double>& r) {
  const std::size_t m = h.size();
  if (m < 2) return std::numeric_limits<double>::quiet_NaN();
  double sx = 0, sy = 0, sxx = 0, sxy = 0;
  for (std::size_t i = 0; i < m; ++i) {
    const double x = std::log(h[i]), y = std::log(r[i]);
    sx += x; sy += y; sxx += x * x; sxy += x * y;
  }
  return (m * sxy - sx * sy) / (m * sxx - sx * sx);
}

namespace {

constexpr double kEps = std::numeric_limits<double>::epsilon();

double max_abs(const std::vector<double>& v) {
  double m = 0.0;
  for (double x : v) m = std::max(m, std::abs(x));
  return m;
}

double dot(const std::vector<double>& a, const std::vector<double>& b) {
  double s = 0.0;
  for (std::size_t i = 0; i < a.size(); ++i) s += a[i] * b[i];
  return s;
}

std::vector<double> axpy(const std::vector<double>& u, double h, const std::vector<double>& v) {
  std::vector<double> w(u);
  for (std::size_t i = 0; i < w.size(); ++i) w[i] += h * v[i];
  return w;
}

std::vector<double> unit_step(const std::vector<double>& u, int i, double t) {
  std::vector<double> w(u);
  w[static_cast<std::size_t>(i)] += t;
  return w;
}

// ---- Kink detection ------------------------------------------------------------------------------
//
// Along a line t -> u + t d the kernel outputs ("streams": the value, the gradient or residual) are
// sampled at equal spacing. Where a stream is smooth its second differences are O(spacing^2); a jump
// of the stream (a kink of the value, e.g. abs) keeps them O(1), a kink of the stream O(spacing).
// A candidate [t_{j-1}, t_{j+1}] is resampled at the same count, a spacing 16 times finer, twice:
// a kink keeps its second differences within a factor 32 per refinement, a smooth stream loses
// a factor 256.

using Streams = std::vector<std::vector<double>>;
using LineFunction = std::function<Streams(double)>;

struct KinkBracket {
  double lo = 0, hi = 0;  // the kink lies in [lo, hi]
  double t = 0;           // best estimate
  double jump = 0;        // second difference at the finest refinement
};

struct Samples {
  std::vector<double> t;
  std::vector<Streams> s;
};

constexpr int kScanIntervals = 32;
constexpr double kKinkRatio = 1.0 / 64.0;  // between a kink (>= 1/32 per refinement) and smooth (1/256)
constexpr double kSignificance = 100.0;    // second differences must exceed this many floors

Samples sample(const LineFunction& f, double a, double b) {
  Samples S;
  for (int k = 0; k <= kScanIntervals; ++k) {
    const double t = a + (b - a) * k / kScanIntervals;
    S.t.push_back(t);
    S.s.push_back(f(t));
  }
  return S;
}

/// Round-off floor of each stream's second differences.
std::vector<double> stream_floors(const Samples& S) {
  std::vector<double> fl(S.s.front().size(), 0.0);
  for (const Streams& x : S.s)
    for (std::size_t s = 0; s < x.size(); ++s) fl[s] = std::max(fl[s], 1e3 * kEps * max_abs(x[s]));
  for (double& f : fl) f = std::max(f, std::numeric_limits<double>::min());
  return fl;
}

/// D[j][s] = max_i |x_{j+2} - 2 x_{j+1} + x_j| of stream s, for the interior sample j + 1.
std::vector<std::vector<double>> second_differences(const Samples& S) {
  std::vector<std::vector<double>> D;
  for (std::size_t k = 1; k + 1 < S.s.size(); ++k) {
    std::vector<double> d(S.s[k].size(), 0.0);
    for (std::size_t s = 0; s < d.size(); ++s)
      for (std::size_t i = 0; i < S.s[k][s].size(); ++i)
        d[s] = std::max(d[s], std::abs(S.s[k + 1][s][i] - 2.0 * S.s[k][s][i] + S.s[k - 1][s][i]));
    D.push_back(std::move(d));
  }
  return D;
}

/// Refines [t[j], t[j+2]] twice; the kink bracket if the second differences stay large.
std::optional<KinkBracket> confirm_kink(const LineFunction& f, double lo, double hi, std::vector<double> reference,
                                        const std::vector<double>& floors) {
  KinkBracket found;
  for (int level = 0; level < 2; ++level) {
    const Samples S = sample(f, lo, hi);
    const auto D = second_differences(S);
    int best_stream = -1, best_j = -1;
    double best_ratio = 0.0;
    for (std::size_t s = 0; s < floors.size(); ++s) {
      std::size_t jmax = 0;
      for (std::size_t j = 1; j < D.size(); ++j)
        if (D[j][s] > D[jmax][s]) jmax = j;
      const double m = D[jmax][s];
      if (!(m > kSignificance * floors[s]) || !(reference[s] > 0)) continue;
      const double ratio = m / reference[s];
      if (ratio > kKinkRatio && ratio > best_ratio) {
        best_ratio = ratio;
        best_stream = static_cast<int>(s);
        best_j = static_cast<int>(jmax);
      }
    }
    if (best_stream < 0) return std::nullopt;
    found.lo = S.t[static_cast<std::size_t>(best_j)];
    found.hi = S.t[static_cast<std::size_t>(best_j) + 2];
    found.t = S.t[static_cast<std::size_t>(best_j) + 1];
    found.jump = D[static_cast<std::size_t>(best_j)][static_cast<std::size_t>(best_stream)];
    // Next level: the refined bracket, against the refined second differences around it.
    for (std::size_t s = 0; s < reference.size(); ++s) {
      double r = 0.0;
      for (int dj = -1; dj <= 1; ++dj) {
        const int j = best_j + dj;
        if (j >= 0 && j < static_cast<int>(D.size())) r = std::max(r, D[static_cast<std::size_t>(j)][s]);
      }
      reference[s] = r;
    }
    lo = found.lo;
    hi = found.hi;
  }
  return found;
}

/// The kink on [a, b] nearest to t = 0, if any.
std::optional<KinkBracket> nearest_kink(const LineFunction& f, double a, double b) {
  const Samples S = sample(f, a, b);
  const std::vector<double> floors = stream_floors(S);
  const auto D = second_differences(S);
  std::vector<double> score(D.size(), 0.0);
  for (std::size_t j = 0; j < D.size(); ++j)
    for (std::size_t s = 0; s < floors.size(); ++s) score[j] = std::max(score[j], D[j][s] / floors[s]);
  std::vector<double> sorted(score);
  std::nth_element(sorted.begin(), sorted.begin() + static_cast<long>(sorted.size() / 2), sorted.end());
  const double median = sorted[sorted.size() / 2];
  const std::size_t top = static_cast<std::size_t>(std::max_element(score.begin(), score.end()) - score.begin());
  // Candidates: significant, and spikes over the smooth background (or the largest of all).
  std::vector<std::size_t> candidates;
  for (std::size_t j = 0; j < score.size(); ++j)
    if (score[j] > kSignificance && (score[j] > 10.0 * median || j == top)) candidates.push_back(j);
  std::sort(candidates.begin(), candidates.end(),
            [&](std::size_t x, std::size_t y) { return std::abs(S.t[x + 1]) < std::abs(S.t[y + 1]); });
  constexpr std::size_t kMaxCandidates = 6;
  if (candidates.size() > kMaxCandidates) candidates.resize(kMaxCandidates);
  for (const std::size_t j : candidates) {
    std::vector<double> reference(floors.size(), 0.0);
    for (std::size_t s = 0; s < floors.size(); ++s)
      for (std::size_t k = (j > 0 ? j - 1 : 0); k <= std::min(j + 1, D.size() - 1); ++k)
        reference[s] = std::max(reference[s], D[k][s]);
    if (auto kink = confirm_kink(f, S.t[j], S.t[j + 2], reference, floors)) return kink;
  }
  return std::nullopt;
}

/// Distance from t = 0 to a kink bracket (0 when the bracket contains it).
double distance_from_state(const KinkBracket& k) {
  if (k.lo <= 0.0 && k.hi >= 0.0) return 0.0;
  return std::min(std::abs(k.lo), std::abs(k.hi));
}

std::string sci(double x) { return fmt::format("{:.3e}", x); }

// ---- Taylor remainders ---------------------------------------------------------------------------

void finish(Remainder& rem) {
  // The asymptotic order shows at small h: fit over the (at most kFitPoints) smallest steps below
  // the kink limit whose remainder stands 100x clear of the round-off floor. Few points keep
  // larger steps out, where the next order can still compete (or cancel) along a direction.
  constexpr std::size_t kFitPoints = 4;
  std::vector<double> hs, rs;
  bool any_above = false, any_usable = false;
  for (std::size_t i = rem.h.size(); i-- > 0;) {
    if (!(rem.h[i] < rem.h_limit)) continue;
    any_usable = true;
    if (!(rem.r[i] > 100.0 * rem.floor[i])) continue;
    any_above = true;
    if (hs.size() < kFitPoints) { hs.push_back(rem.h[i]); rs.push_back(rem.r[i]); }
  }
  rem.points_used = static_cast<int>(hs.size());
  rem.exact = any_usable && !any_above;
  // A non-finite remainder is neither exact nor fittable: the expectations turn it into a failure.
  if (std::any_of(rem.r.begin(), rem.r.end(), [](double r) { return !std::isfinite(r); })) {
    rem.exact = false;
    rem.points_used = 0;
    rem.slope = std::numeric_limits<double>::quiet_NaN();
    return;
  }
  rem.slope = hs.size() >= 2 ? fitted_slope(hs, rs) : std::numeric_limits<double>::quiet_NaN();
}

/// Steps of a remainder below its kink limit.
int usable_steps(const Remainder& r) {
  int n = 0;
  for (const double h : r.h) n += h < r.h_limit ? 1 : 0;
  return n;
}

bool is_scalar_functional(FunctionalKind k) { return k == FunctionalKind::Energy || k == FunctionalKind::Constraint; }

/// Everything check_form needs while it runs.
class Checker {
 public:
  Checker(const kernel::FormKernels& form, const Cell& cell, const State& state, const Options& options)
      : form_(form), cell_(cell), state_(state), opt_(options), ev_(form, cell, state), u_(state.unknowns) {
    N_ = ev_.ndofs();
    steps_.assign(static_cast<std::size_t>(N_), opt_.fd_step);
    if (!opt_.dof_scales.empty()) {
      if (static_cast<int>(opt_.dof_scales.size()) != N_)
        throw std::invalid_argument("check_form: dof_scales has the wrong size");
      for (int i = 0; i < N_; ++i) steps_[static_cast<std::size_t>(i)] *= opt_.dof_scales[static_cast<std::size_t>(i)];
    }
    rep_.kind = form.kind;
  }

  Report run(const std::vector<double>& direction) {
    const FunctionalKind kind = form_.kind;
    if (is_scalar_functional(kind)) {
      check_scalar_functional(direction);
    } else if (kind == FunctionalKind::Point) {
      check_point_values();
    } else if (kind == FunctionalKind::Residual) {
      check_residual(direction);
    } else {
      check_linear_in_test();
      check_state_independence();
    }
    return std::move(rep_);
  }

 private:
  // Streams a kink would show in, along u + t d.
  Streams outputs_at(const std::vector<double>& u) {
    Streams s;
    if (form_.value && is_scalar_functional(form_.kind)) s.push_back({ev_.value(u)});
    if (form_.vector) s.push_back(ev_.vector(u));
    return s;
  }
  LineFunction line(const std::vector<double>& d) {
    return [this, d](double t) { return outputs_at(axpy(u_, t, d)); };
  }
  LineFunction dof_line(int i, bool vector_only) {
    return [this, i, vector_only](double t) {
      const std::vector<double> w = unit_step(u_, i, t);
      if (vector_only) return Streams{ev_.vector(w)};
      return outputs_at(w);
    };
  }

  /// Relative error of dof i's FD entry for a difference of `step`: central (side 0) or
  /// second-order one-sided towards side = +-1.
  using EntryError = std::function<double(int i, double step, int side)>;

  /// Re-examines the dofs whose FD entry fails (rel[i] > tol). A kink crossed by the +-step
  /// perturbation is recorded and the entry re-differenced where the line is smooth: centrally
  /// with a step short of the kink, or, for a kink at the state itself, one-sidedly away from it.
  /// rel[i] becomes the error of the re-differenced entry, or NaN where no difference avoids kinks
  /// (kinks on both sides within round-off of the state: derivatives do not exist there). Stops
  /// at the first entry that no kink explains: that is a failure.
  void explain_by_kinks(std::vector<double>& rel, double tol, const EntryError& error, bool vector_only,
                        const char* what) {
    std::vector<int> failing;
    for (int i = 0; i < N_; ++i)
      if (!(rel[static_cast<std::size_t>(i)] <= tol)) failing.push_back(i);
    std::sort(failing.begin(), failing.end(),
              [&](int a, int b) { return rel[static_cast<std::size_t>(a)] > rel[static_cast<std::size_t>(b)]; });
    // Each examination costs ~100 kernel calls: many failing dofs are one kink near the state.
    constexpr std::size_t kMaxExamined = 48;
    for (std::size_t n = 0; n < failing.size(); ++n) {
      const int i = failing[n];
      double& entry = rel[static_cast<std::size_t>(i)];
      if (n == kMaxExamined) {
        rep_.kinks.push_back({what, -1, std::nan(""), 0.0, std::nan(""),
                              fmt::format("{} further failing dofs not examined (the first {} all crossed kinks), "
                                          "left out",
                                          failing.size() - kMaxExamined, kMaxExamined)});
        for (std::size_t m = n; m < failing.size(); ++m) rel[static_cast<std::size_t>(failing[m])] = std::nan("");
        return;
      }
      const double step0 = steps_[static_cast<std::size_t>(i)];
      double step = step0;
      bool explained = false;
      // A dof may cross several kinks (several quadrature points): follow them inward.
      for (int attempt = 0; attempt < 4 && !explained; ++attempt) {
        const auto kink = nearest_kink(dof_line(i, vector_only), -step, step);
        if (!kink) break;
        const double d = distance_from_state(*kink);
        if (d >= 1e-3 * step0) {
          step = 0.5 * d;
          const double err = error(i, step, 0);
          if (err <= tol) {
            rep_.kinks.push_back({what, i, kink->t, kink->jump, err,
                                  fmt::format("re-differenced with step {} short of it: rel. error {}", sci(step),
                                              sci(err))});
            entry = err;
            explained = true;
          }
          continue;
        }
        // At the state: the kernel evaluates one branch; one of the one-sided differences sees it.
        const int away = kink->t > 0 ? -1 : 1;
        for (const int side : {away, -away}) {
          const double err = error(i, step0, side);
          if (err <= tol) {
            rep_.kinks.push_back({what, i, kink->t, kink->jump, err,
                                  fmt::format("at the state: one-sided difference towards {}: rel. error {}",
                                              side > 0 ? "+" : "-", sci(err))});
            entry = err;
            explained = true;
            break;
          }
        }
        if (!explained) {
          rep_.kinks.push_back({what, i, kink->t, kink->jump, std::nan(""),
                                "at the state, kinks on both sides: no derivative there, left out"});
          entry = std::nan("");
          explained = true;
        }
      }
      if (!explained) return;  // a genuine failure: no need to look further
    }
  }

  static bool finite(const std::vector<double>& v) {
    return std::all_of(v.begin(), v.end(), [](double x) { return std::isfinite(x); });
  }

  /// Largest error over the entries that could be verified (NaN when none could).
  static double max_verified(const std::vector<double>& rel) {
    double m = std::nan("");
    for (const double e : rel)
      if (!std::isnan(e)) m = std::isnan(m) ? e : std::max(m, e);
    return m;
  }

  /// Differences of f (a scalar or vector function of the step along a dof) of `step`, central or
  /// second-order one-sided.
  template <class F>
  static auto difference(const F& f, double step, int side) {
    if (side == 0) {
      auto fp = f(step), fm = f(-step);
      return combine(fp, fm, 1.0 / (2.0 * step), -1.0 / (2.0 * step));
    }
    const double h = side * step;
    auto f0 = f(0.0), f1 = f(h), f2 = f(2.0 * h);
    return combine(combine(f0, f1, -3.0 / (2.0 * h), 4.0 / (2.0 * h)), f2, 1.0, -1.0 / (2.0 * h));
  }
  static double combine(double a, double b, double ca, double cb) { return ca * a + cb * b; }
  static std::vector<double> combine(const std::vector<double>& a, const std::vector<double>& b, double ca, double cb) {
    std::vector<double> c(a.size());
    for (std::size_t k = 0; k < a.size(); ++k) c[k] = ca * a[k] + cb * b[k];
    return c;
  }

  void check_gradient() {
    const std::vector<double> g = ev_.vector(u_);
    rep_.grad_max = max_abs(g);
    const double E = rep_.value;
    auto rel_error = [&](int i, double step, int side) {
      const double fd = difference([&](double t) { return ev_.value(unit_step(u_, i, t)); }, step, side);
      // Differences of E lose |E| eps / step to round-off.
      const double scale = std::max(rep_.grad_max, std::abs(E) * kEps / step * 10.0);
      const double e = std::abs(g[static_cast<std::size_t>(i)] - fd);
      return scale > 0 ? e / scale : e;
    };
    std::vector<double> rel(static_cast<std::size_t>(N_));
    for (int i = 0; i < N_; ++i) rel[static_cast<std::size_t>(i)] = rel_error(i, steps_[static_cast<std::size_t>(i)], 0);
    rep_.grad_err = max_verified(rel);
    if (!finite(g) || !finite(rel)) {
      rep_.failures.push_back("the gradient or its finite differences are not finite");
      return;
    }
    if (!(rep_.grad_err <= opt_.grad_tol) && opt_.detect_kinks) {
      explain_by_kinks(rel, opt_.grad_tol, rel_error, false, "FD of the value");
      rep_.grad_err = max_verified(rel);
    }
    if (rep_.grad_err > opt_.grad_tol)
      rep_.failures.push_back(fmt::format("gradient vs central FD of the value: rel. error {} > {:.1e}",
                                          sci(rep_.grad_err), opt_.grad_tol));
  }

  /// The matrix against central differences of the vector kernel; symmetry when `symmetric`.
  void check_matrix(bool symmetric, const char* matrix_name, const char* vector_name) {
    H_ = ev_.matrix(u_);
    rep_.has_hessian = true;
    rep_.hess_max = max_abs(H_);
    const std::vector<double> g = ev_.vector(u_);
    if (!is_scalar_functional(form_.kind)) rep_.grad_max = max_abs(g);
    auto column_error = [&](int j, double step, int side) {
      const std::vector<double> fd = difference([&](double t) { return ev_.vector(unit_step(u_, j, t)); }, step, side);
      double e = 0.0;
      for (int i = 0; i < N_; ++i)
        e = std::max(e, std::abs(H_[static_cast<std::size_t>(i) * N_ + j] - fd[static_cast<std::size_t>(i)]));
      const double scale = std::max(rep_.hess_max, rep_.grad_max * kEps / step * 10.0);
      return scale > 0 ? e / scale : e;
    };
    std::vector<double> rel(static_cast<std::size_t>(N_));
    for (int j = 0; j < N_; ++j) rel[static_cast<std::size_t>(j)] = column_error(j, steps_[static_cast<std::size_t>(j)], 0);
    rep_.hess_err = max_verified(rel);
    if (!finite(H_) || !finite(rel)) {
      rep_.failures.push_back(fmt::format("the {} or its finite differences are not finite", matrix_name));
      return;
    }
    if (!(rep_.hess_err <= opt_.hess_tol) && opt_.detect_kinks) {
      explain_by_kinks(rel, opt_.hess_tol, column_error, true,
                       is_scalar_functional(form_.kind) ? "FD of the gradient" : "FD of the residual");
      rep_.hess_err = max_verified(rel);
    }
    if (rep_.hess_err > opt_.hess_tol)
      rep_.failures.push_back(fmt::format("{} vs central FD of the {}: rel. error {} > {:.1e}", matrix_name,
                                          vector_name, sci(rep_.hess_err), opt_.hess_tol));
    if (symmetric) {
      double asym = 0.0;
      for (int i = 0; i < N_; ++i)
        for (int j = i + 1; j < N_; ++j)
          asym = std::max(asym, std::abs(H_[static_cast<std::size_t>(i) * N_ + j] - H_[static_cast<std::size_t>(j) * N_ + i]));
      rep_.hess_asym = rep_.hess_max > 0 ? asym / rep_.hess_max : asym;
      if (!(rep_.hess_asym <= opt_.sym_tol))
        rep_.failures.push_back(fmt::format("{} not symmetric: rel. asymmetry {}", matrix_name, sci(rep_.hess_asym)));
    }
  }

  /// The remainders along one direction and what they show.
  struct Taylor {
    Remainder r1, r2, r3;
    std::vector<Kink> kinks;
    std::vector<std::string> failures;
  };

  /// The first kink along the Taylor direction: steps at or above it are not fitted.
  void limit_taylor_steps_by_kinks(const std::vector<double>& v, Taylor& t) {
    if (!opt_.detect_kinks) return;
    const LineFunction f = line(v);
    // Finest range first: the nearest kink decides which steps stay smooth.
    for (const double range : {opt_.taylor_h0 / 1024.0, opt_.taylor_h0 / 32.0, opt_.taylor_h0}) {
      if (const auto kink = nearest_kink(f, 0.0, range)) {
        const double limit = kink->lo;
        for (Remainder* r : {&t.r1, &t.r2, &t.r3}) r->h_limit = limit;
        int fitted = 0;
        for (int k = 0; k < opt_.taylor_levels; ++k) fitted += opt_.taylor_h0 * std::ldexp(1.0, -k) < limit ? 1 : 0;
        t.kinks.push_back({"Taylor direction", -1, kink->t, kink->jump, std::nan(""),
                              fitted >= 3 ? fmt::format("remainders fitted over the {} steps h < {}", fitted, sci(limit))
                                          : fmt::format("at the state (every step h >= {} crosses it): remainders "
                                                        "not fitted",
                                                        sci(limit))});
        return;
      }
    }
  }

  Taylor taylor_along(const std::vector<double>& v, bool with_value) {
    Taylor t;
    limit_taylor_steps_by_kinks(v, t);
    const std::vector<double> g = ev_.vector(u_);
    const double gv = dot(g, v);
    std::vector<double> Hv(static_cast<std::size_t>(N_), 0.0);
    double vHv = 0.0;
    if (rep_.has_hessian) {
      for (int i = 0; i < N_; ++i) {
        double s = 0.0;
        for (int j = 0; j < N_; ++j) s += H_[static_cast<std::size_t>(i) * N_ + j] * v[static_cast<std::size_t>(j)];
        Hv[static_cast<std::size_t>(i)] = s;
      }
      vHv = dot(v, Hv);
    }
    const double E0 = with_value ? rep_.value : 0.0;
    const auto r3_at = [&](const std::vector<double>& g1, double h) {
      double r = 0.0;
      for (int i = 0; i < N_; ++i)
        r = std::max(r, std::abs(g1[static_cast<std::size_t>(i)] - g[static_cast<std::size_t>(i)] -
                                 h * Hv[static_cast<std::size_t>(i)]));
      return r;
    };
    // Round-off floor of the remainders, measured: at steps so small that every smooth term is
    // far below round-off, a remainder is pure round-off of the kernels (sums over points and
    // nodes can lose far more, or far less, than a few ulps of the result).
    double value_noise = 0.0, vector_noise = 0.0;
    for (const double fraction : {1e-9, 1e-10, 1e-11, 1e-12}) {
      const double h = opt_.taylor_h0 * fraction;
      const std::vector<double> uh = axpy(u_, h, v);
      if (with_value) value_noise = std::max(value_noise, std::abs(ev_.value(uh) - E0 - h * gv));
      if (rep_.has_hessian) vector_noise = std::max(vector_noise, r3_at(ev_.vector(uh), h));
    }
    const double gmax = max_abs(g);
    for (int k = 0; k < opt_.taylor_levels; ++k) {
      const double h = opt_.taylor_h0 * std::ldexp(1.0, -k);
      const std::vector<double> uh = axpy(u_, h, v);
      if (with_value) {
        const double E1 = ev_.value(uh);
        const double d1 = E1 - E0 - h * gv;
        // At least an ulp or two of every term summed here; the measured noise, with a margin.
        const double f1 = std::max(4.0 * value_noise, 2.0 * kEps * (std::abs(E0) + std::abs(E1) + std::abs(h * gv)));
        t.r1.h.push_back(h);
        t.r1.r.push_back(std::abs(d1));
        t.r1.floor.push_back(f1);
        if (rep_.has_hessian) {
          t.r2.h.push_back(h);
          t.r2.r.push_back(std::abs(d1 - 0.5 * h * h * vHv));
          t.r2.floor.push_back(f1 + 2.0 * kEps * std::abs(0.5 * h * h * vHv));
        }
      }
      if (rep_.has_hessian) {
        const std::vector<double> g1 = ev_.vector(uh);
        t.r3.h.push_back(h);
        t.r3.r.push_back(r3_at(g1, h));
        t.r3.floor.push_back(
            std::max(4.0 * vector_noise, 2.0 * kEps * (std::max(gmax, max_abs(g1)) + h * max_abs(Hv))));
      }
    }
    for (Remainder* r : {&t.r1, &t.r2, &t.r3})
      if (r->computed()) finish(*r);
    t.failures = judge(t);
    return t;
  }

  /// Taylor remainders along v. A slope can miss its order along one direction without any error
  /// (the leading coefficient is tiny and the next order cancels it over the visible steps): up
  /// to two more directions (v with pseudo-random signs flipped) are tried before failing. A wrong
  /// derivative lowers the order along every direction.
  void taylor(const std::vector<double>& v, bool with_value) {
    if (static_cast<int>(v.size()) != N_) throw std::invalid_argument("check_form: direction has the wrong size");
    Taylor first = taylor_along(v, with_value);
    Taylor chosen = first;
    constexpr int kDirections = 3;
    for (int attempt = 1; attempt < kDirections && !chosen.failures.empty(); ++attempt) {
      std::vector<double> w(v);
      for (std::size_t i = 0; i < w.size(); ++i)
        if (((i * 2654435761u) >> (3 + attempt)) & 1u) w[i] = -w[i];
      chosen = taylor_along(w, with_value);
      if (chosen.failures.empty())
        rep_.notes.push_back(fmt::format("Taylor remainders along direction {} of {}: along the first, {}", attempt + 1,
                                         kDirections, first.failures.front()));
    }
    if (!chosen.failures.empty()) {
      chosen = first;
      for (auto& f : chosen.failures) f += fmt::format(" (and along {} more directions)", kDirections - 1);
    }
    rep_.r1 = std::move(chosen.r1);
    rep_.r2 = std::move(chosen.r2);
    rep_.r3 = std::move(chosen.r3);
    rep_.kinks.insert(rep_.kinks.end(), chosen.kinks.begin(), chosen.kinks.end());
    rep_.failures.insert(rep_.failures.end(), chosen.failures.begin(), chosen.failures.end());
  }

  std::vector<std::string> judge(const Taylor& t) const {
    std::vector<std::string> failures;
    auto kinked = [](const Remainder& r) { return std::isfinite(r.h_limit) && usable_steps(r) < 3; };
    auto expect_slope = [&](const Remainder& r, double order, const std::string& name) {
      if (!r.computed() || kinked(r)) return;
      if (r.exact) {
        failures.push_back(name + ": remainder at round-off for every h, but the functional is "
                                "expected to be nonlinear of this order (direction or h range too small?)");
        return;
      }
      if (r.points_used < 3) {
        failures.push_back(fmt::format("{}: only {} steps above the round-off floor; cannot fit a slope", name,
                                            r.points_used));
        return;
      }
      // A wrong derivative lowers the order; a higher one only means the leading term of the
      // remainder happens to be small along v.
      if (!(r.slope >= order - opt_.slope_tol))
        failures.push_back(fmt::format("{}: fitted slope {:.3f}, expected {:.0f}", name, r.slope, order));
    };
    auto expect_exact = [&](const Remainder& r, const std::string& name) {
      if (!r.computed() || kinked(r) || r.exact) return;
      failures.push_back(fmt::format("{}: expected exact (polynomial functional) but remainder {} exceeds 100x "
                                          "round-off",
                                          name, sci(*std::max_element(r.r.begin(), r.r.end()))));
    };
    auto slope_or_exact = [&](const Remainder& r, double order, const std::string& name) {
      if (r.exact) return;
      expect_slope(r, order, name);
    };
    const bool residual = form_.kind == FunctionalKind::Residual;
    const std::string n1 = "Taylor r1 = |E(u+hv)-E-h g.v|";
    const std::string n2 = "Taylor r2 = |E(u+hv)-E-h g.v-h^2/2 vHv|";
    const std::string n3 = residual ? "Taylor r3 = |R(u+hv)-R-h J v|" : "Taylor r3 = |g(u+hv)-g-h Hv|";
    switch (opt_.expect_degree) {
      case Degree::linear:
        expect_exact(t.r1, n1 + " (linear)");
        expect_exact(t.r2, n2 + " (linear)");
        expect_exact(t.r3, n3 + " (linear)");
        break;
      case Degree::quadratic:
        expect_slope(t.r1, 2.0, n1);
        expect_exact(t.r2, n2 + " (quadratic)");
        expect_exact(t.r3, n3 + " (quadratic)");
        break;
      case Degree::nonlinear:
        expect_slope(t.r1, 2.0, n1);
        expect_slope(t.r2, 3.0, n2);
        expect_slope(t.r3, 2.0, n3);
        break;
      case Degree::detect:
        slope_or_exact(t.r1, 2.0, n1);
        slope_or_exact(t.r2, 3.0, n2);
        slope_or_exact(t.r3, 2.0, n3);
        // A polynomial along v is one degree throughout: value, gradient and Hessian must agree.
        if (t.r1.exact && t.r3.computed() && !t.r3.exact && !kinked(t.r3))
          failures.push_back("the value is affine along v (r1 exact) but the gradient is not constant (r3 not exact)");
        if (t.r3.exact && t.r2.computed() && !t.r2.exact && !kinked(t.r2))
          failures.push_back("the Hessian is constant along v (r3 exact) but the value is not quadratic (r2 not exact)");
        break;
    }
    return failures;
  }

  void check_scalar_functional(const std::vector<double>& v) {
    if (!form_.value || !form_.vector)
      throw std::invalid_argument(std::string(form_.module) + "::" + form_.name + " lacks value/gradient kernels");
    rep_.value = ev_.value(u_);
    if (!std::isfinite(rep_.value)) {
      rep_.failures.push_back(fmt::format("the value is not finite ({})", rep_.value));
      return;
    }
    check_gradient();
    if (form_.matrix) check_matrix(true, "Hessian", "gradient");
    taylor(v, true);
  }

  void check_residual(const std::vector<double>& v) {
    if (!form_.vector || !form_.matrix)
      throw std::invalid_argument(std::string(form_.module) + "::" + form_.name + " lacks residual/Jacobian kernels");
    check_matrix(false, "Jacobian", "residual");
    taylor(v, false);
    check_linear_in_test();
  }

  /// Scaling test function a by s (basis column a times s, nodal values of a divided by s, so every
  /// interpolated field is unchanged) must scale node a's entries by s.
  void check_linear_in_test() {
    const int n = cell_.n, dpn = form_.dofs_per_node, cpn = form_.coefficient_components_per_node;
    const std::vector<double> R = form_.vector ? ev_.vector(u_) : std::vector<double>{};
    const std::vector<double> A = form_.matrix ? ev_.matrix(u_) : std::vector<double>{};
    const double Rmax = max_abs(R), Amax = max_abs(A);
    double err = 0.0;
    const std::pair<int, double> scalings[] = {{0, 1.7}, {n / 2, -0.45}};
    for (const auto& [node, s] : scalings) {
      Cell scaled = cell_;
      const int J = jet_size(cell_.dim, cell_.basis_order);
      for (int q = 0; q < cell_.nq; ++q)
        for (int slot = 0; slot < J; ++slot) scaled.basis[(static_cast<std::size_t>(q) * J + slot) * n + node] *= s;
      State st = state_;
      for (int c = 0; c < dpn; ++c) st.unknowns[static_cast<std::size_t>(node * dpn + c)] /= s;
      for (int c = 0; c < cpn; ++c) st.coefficients[static_cast<std::size_t>(node * cpn + c)] /= s;
      Evaluator ev(form_, scaled, st);
      auto factor = [&](int dof) { return dof / dpn == node ? s : 1.0; };
      if (form_.vector) {
        const std::vector<double> Rs = ev.vector(st.unknowns);
        for (int i = 0; i < N_; ++i)
          err = std::max(err, std::abs(Rs[static_cast<std::size_t>(i)] - factor(i) * R[static_cast<std::size_t>(i)]) /
                                  std::max(Rmax, std::numeric_limits<double>::min()));
      }
      if (form_.matrix) {
        // Residual: J' = S J S (the unknowns scale inversely); bilinear: A' = S A S (trial and test).
        const std::vector<double> As = ev.matrix(st.unknowns);
        for (int i = 0; i < N_; ++i)
          for (int j = 0; j < N_; ++j) {
            const std::size_t ij = static_cast<std::size_t>(i) * N_ + j;
            err = std::max(err, std::abs(As[ij] - factor(i) * factor(j) * A[ij]) /
                                    std::max(Amax, std::numeric_limits<double>::min()));
          }
      }
    }
    rep_.linearity_err = err;
    if (!(err <= opt_.linearity_tol))
      rep_.failures.push_back(fmt::format("not linear in the test{} function: scaling one test function changes the "
                                          "output by rel. {} beyond the scaling",
                                          form_.kind == FunctionalKind::Bilinear ? " and trial" : "", sci(err)));
  }

  /// A point output has no derivatives: its kernel must write n_values finite values per point.
  void check_point_values() {
    if (form_.n_values <= 0) {
      rep_.failures.push_back(fmt::format("point output with n_values = {}", form_.n_values));
      return;
    }
    const std::vector<double> values = ev_.point(u_);
    const auto bad = std::find_if(values.begin(), values.end(), [](double x) { return !std::isfinite(x); });
    if (bad != values.end()) {
      const auto at = static_cast<int>(bad - values.begin());
      rep_.failures.push_back(fmt::format("point value {} of point {} is {} (not written, or not finite)", at % form_.n_values,
                                          at / form_.n_values, *bad));
    }
  }

  /// Bilinear and linear forms read no unknowns: other nodal values must give the same output.
  void check_state_independence() {
    std::vector<double> w(u_);
    for (std::size_t i = 0; i < w.size(); ++i) w[i] += 0.37 + 0.11 * static_cast<double>(i % 7);
    double err = 0.0;
    if (form_.vector) {
      const auto a = ev_.vector(u_), b = ev_.vector(w);
      rep_.grad_max = max_abs(a);
      for (std::size_t i = 0; i < a.size(); ++i)
        err = std::max(err, std::abs(a[i] - b[i]) / std::max(rep_.grad_max, std::numeric_limits<double>::min()));
    }
    if (form_.matrix) {
      const auto a = ev_.matrix(u_), b = ev_.matrix(w);
      rep_.hess_max = max_abs(a);
      for (std::size_t i = 0; i < a.size(); ++i)
        err = std::max(err, std::abs(a[i] - b[i]) / std::max(rep_.hess_max, std::numeric_limits<double>::min()));
    }
    rep_.state_dependence = err;
    if (!(err <= opt_.linearity_tol))
      rep_.failures.push_back(fmt::format("depends on the unknowns' nodal values (rel. change {})", sci(err)));
  }

  const kernel::FormKernels& form_;
  const Cell& cell_;
  const State& state_;
  const Options& opt_;
  Evaluator ev_;
  const std::vector<double>& u_;
  int N_ = 0;
  std::vector<double> steps_;
  std::vector<double> H_;
  Report rep_;
};

std::string slope_text(const Remainder& r) {
  if (!r.computed()) return "  n/a ";
  if (std::isfinite(r.h_limit) && usable_steps(r) < 3) return " kink ";
  if (r.exact) return "exact ";
  return fmt::format("{:6.3f}", r.slope);
}

std::string number_text(double x) { return std::isnan(x) ? "n/a" : fmt::format("{:.2e}", x); }

}  // namespace

Report check_form(const kernel::FormKernels& form, const Cell& cell, const State& state,
                  const std::vector<double>& direction, const Options& options) {
  Checker checker(form, cell, state, options);
  return checker.run(direction);
}

std::vector<std::string> describe_kinks(const std::vector<Kink>& kinks) {
  std::vector<std::string> lines;
  std::vector<std::string> families;
  for (const Kink& k : kinks)
    if (std::find(families.begin(), families.end(), k.perturbation) == families.end()) families.push_back(k.perturbation);
  for (const std::string& family : families) {
    std::vector<const Kink*> dofs;
    for (const Kink& k : kinks) {
      if (k.perturbation != family) continue;
      if (k.dof < 0) {
        lines.push_back(std::isnan(k.t) ? fmt::format("{}: {}", family, k.effect)
                                        : fmt::format("{} crosses a kink at t = {} (jump {}): {}", family, sci(k.t),
                                                      sci(k.jump), k.effect));
      } else {
        dofs.push_back(&k);
      }
    }
    if (dofs.size() == 1) {
      lines.push_back(fmt::format("{} of dof {} crosses a kink at t = {} (jump {}): {}", family, dofs[0]->dof,
                                  sci(dofs[0]->t), sci(dofs[0]->jump), dofs[0]->effect));
    } else if (dofs.size() > 1) {
      double nearest = std::numeric_limits<double>::infinity(), worst = 0.0;
      int at_state = 0;
      for (const Kink* k : dofs) {
        nearest = std::min(nearest, std::abs(k->t));
        if (std::isnan(k->recheck_error)) ++at_state;
        else worst = std::max(worst, k->recheck_error);
      }
      std::string line = fmt::format("{}: {} dofs cross kinks within the step (nearest at |t| = {})", family,
                                     dofs.size(), sci(nearest));
      if (at_state < static_cast<int>(dofs.size()))
        line += fmt::format("; re-differenced on their kink-free side, max rel. error {}", sci(worst));
      if (at_state > 0) line += fmt::format("; {} at the state itself, left out", at_state);
      lines.push_back(line);
    }
  }
  return lines;
}

std::string Report::summary(const std::string& label) const {
  std::ostringstream os;
  os << fmt::format("{:<34} E={:>13}  |g|={:.2e} grad_err={}  |H|={:.2e} hess_err={} asym={} lin={}  slopes r1={} "
                    "r2={} r3={}",
                    label, std::isnan(value) ? std::string("n/a") : fmt::format("{: .6e}", value), grad_max,
                    number_text(grad_err), hess_max, number_text(hess_err), number_text(hess_asym),
                    number_text(std::isnan(linearity_err) ? state_dependence : linearity_err), slope_text(r1),
                    slope_text(r2), slope_text(r3));
  for (const auto& n : notes) os << "\n    note: " << n;
  for (const auto& k : describe_kinks(kinks)) os << "\n    kink: " << k;
  for (const auto& f : failures) os << "\n    FAIL: " << f;
  return os.str();
}

}  // namespace lmeform::formcheck
