#include "form_check.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <sstream>
#include <stdexcept>

namespace lmeform::formcheck {

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
  if (form.contract_version != kernel::kContractVersion)
    throw std::invalid_argument(std::string("form ") + form.module + "::" + form.name + ": contract version " +
                                std::to_string(form.contract_version) + ", expected " +
                                std::to_string(kernel::kContractVersion));
  if (form.dim != cell.dim)
    throw std::invalid_argument(std::string("form ") + form.module + "::" + form.name + " is for dim " +
                                std::to_string(form.dim) + ", cell has dim " + std::to_string(cell.dim));
  const int order = std::max(form.basis_order, form.coefficient_basis_order);
  cell_ = cell.restricted(order);
  ndofs_ = cell.n * form.dofs_per_node;
  auto need = [&](std::size_t have, std::size_t want, const char* what) {
    if (have != want)
      throw std::invalid_argument(std::string("form ") + form.module + "::" + form.name + ": " + what + " has " +
                                  std::to_string(have) + " values, kernel needs " + std::to_string(want));
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
  return in;
}

double Evaluator::value(const std::vector<double>& u) {
  if (!form_.value) throw std::invalid_argument(std::string(form_.module) + "::" + form_.name + ": no value kernel");
  return form_.value(inputs(u));
}

std::vector<double> Evaluator::gradient(const std::vector<double>& u) {
  if (!form_.vector) throw std::invalid_argument(std::string(form_.module) + "::" + form_.name + ": no gradient kernel");
  std::vector<double> g(static_cast<std::size_t>(ndofs_), 0.0);
  form_.vector(inputs(u), g.data());
  return g;
}

std::vector<double> Evaluator::hessian(const std::vector<double>& u) {
  if (!form_.matrix) throw std::invalid_argument(std::string(form_.module) + "::" + form_.name + ": no Hessian kernel");
  std::vector<double> H(static_cast<std::size_t>(ndofs_) * ndofs_, 0.0);
  form_.matrix(inputs(u), H.data());
  return H;
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

void finish(Remainder& rem) {
  // The asymptotic order shows at small h: fit over the (at most kFitPoints) smallest steps whose
  // remainder stands 100x clear of the round-off floor.
  constexpr std::size_t kFitPoints = 5;
  std::vector<double> hs, rs;
  bool any = false;
  for (std::size_t i = rem.h.size(); i-- > 0;) {
    if (!(rem.r[i] > 100.0 * rem.floor[i])) continue;
    any = true;
    if (hs.size() < kFitPoints) { hs.push_back(rem.h[i]); rs.push_back(rem.r[i]); }
  }
  rem.points_used = static_cast<int>(hs.size());
  rem.exact = !any;
  rem.slope = hs.size() >= 2 ? fitted_slope(hs, rs) : std::numeric_limits<double>::quiet_NaN();
}

std::string fmt(const char* f, double x) {
  char b[64];
  std::snprintf(b, sizeof b, f, x);
  return b;
}

}  // namespace

Report check_form(const kernel::FormKernels& form, const Cell& cell, const State& state,
                  const std::vector<double>& direction, const Options& opt) {
  Evaluator ev(form, cell, state);
  Report rep;
  const std::vector<double>& u = state.unknowns;
  const int N = ev.ndofs();
  if (static_cast<int>(direction.size()) != N) throw std::invalid_argument("check_form: direction has wrong size");

  rep.energy = ev.value(u);
  const std::vector<double> g = ev.gradient(u);
  rep.grad_max = max_abs(g);
  rep.has_hessian = form.matrix != nullptr;

  // (a) gradient against central differences of the value.
  const double hfd = opt.fd_step;
  std::vector<double> gfd(static_cast<std::size_t>(N));
  for (int i = 0; i < N; ++i) {
    std::vector<double> up(u), um(u);
    up[i] += hfd;
    um[i] -= hfd;
    gfd[i] = (ev.value(up) - ev.value(um)) / (2.0 * hfd);
  }
  {
    double e = 0.0;
    for (int i = 0; i < N; ++i) e = std::max(e, std::abs(g[i] - gfd[i]));
    const double scale = std::max(rep.grad_max, std::abs(rep.energy) * kEps / hfd * 10.0);
    rep.grad_err = scale > 0 ? e / scale : e;
    if (!(rep.grad_err <= opt.grad_tol))
      rep.failures.push_back("gradient vs central FD of the value: rel. error " + fmt("%.3e", rep.grad_err) +
                             " > " + fmt("%.1e", opt.grad_tol));
  }

  std::vector<double> H;
  if (rep.has_hessian) {
    // (b) Hessian against central differences of the gradient, and symmetry.
    H = ev.hessian(u);
    rep.hess_max = max_abs(H);
    double e = 0.0, asym = 0.0;
    for (int j = 0; j < N; ++j) {
      std::vector<double> up(u), um(u);
      up[j] += hfd;
      um[j] -= hfd;
      const std::vector<double> gp = ev.gradient(up), gm = ev.gradient(um);
      for (int i = 0; i < N; ++i) {
        const double fd = (gp[i] - gm[i]) / (2.0 * hfd);
        e = std::max(e, std::abs(H[static_cast<std::size_t>(i) * N + j] - fd));
        asym = std::max(asym, std::abs(H[static_cast<std::size_t>(i) * N + j] - H[static_cast<std::size_t>(j) * N + i]));
      }
    }
    const double scale = std::max(rep.hess_max, rep.grad_max * kEps / hfd * 10.0);
    rep.hess_err = scale > 0 ? e / scale : e;
    rep.hess_asym = rep.hess_max > 0 ? asym / rep.hess_max : asym;
    if (!(rep.hess_err <= opt.hess_tol))
      rep.failures.push_back("Hessian vs central FD of the gradient: rel. error " + fmt("%.3e", rep.hess_err) +
                             " > " + fmt("%.1e", opt.hess_tol));
    if (!(rep.hess_asym <= opt.sym_tol))
      rep.failures.push_back("Hessian not symmetric: rel. asymmetry " + fmt("%.3e", rep.hess_asym));
  }

  // (c) Taylor remainders along the direction.
  const std::vector<double>& v = direction;
  const double E0 = rep.energy;
  const double gv = dot(g, v);
  std::vector<double> Hv(static_cast<std::size_t>(N), 0.0);
  double vHv = 0.0;
  if (rep.has_hessian) {
    for (int i = 0; i < N; ++i) {
      double s = 0.0;
      for (int j = 0; j < N; ++j) s += H[static_cast<std::size_t>(i) * N + j] * v[j];
      Hv[i] = s;
    }
    vHv = dot(v, Hv);
  }
  const double gmax = rep.grad_max;
  for (int k = 0; k < opt.taylor_levels; ++k) {
    const double h = opt.taylor_h0 * std::ldexp(1.0, -k);
    const std::vector<double> uh = axpy(u, h, v);
    const double E1 = ev.value(uh);
    const double d1 = E1 - E0 - h * gv;
    // Round-off floor: a few ulps of every term that was summed (N accumulations at most).
    const double f1 = 16.0 * kEps * (std::abs(E0) + std::abs(E1) + std::abs(h * gv));
    rep.r1.h.push_back(h);
    rep.r1.r.push_back(std::abs(d1));
    rep.r1.floor.push_back(f1);
    if (rep.has_hessian) {
      rep.r2.h.push_back(h);
      rep.r2.r.push_back(std::abs(d1 - 0.5 * h * h * vHv));
      rep.r2.floor.push_back(f1 + 16.0 * kEps * std::abs(0.5 * h * h * vHv));
      const std::vector<double> g1 = ev.gradient(uh);
      double r3 = 0.0;
      for (int i = 0; i < N; ++i) r3 = std::max(r3, std::abs(g1[i] - g[i] - h * Hv[i]));
      rep.r3.h.push_back(h);
      rep.r3.r.push_back(r3);
      rep.r3.floor.push_back(16.0 * kEps * (2.0 * std::max(gmax, max_abs(g1)) + h * max_abs(Hv)));
    }
  }
  finish(rep.r1);
  if (rep.has_hessian) {
    finish(rep.r2);
    finish(rep.r3);
  }

  auto expect_slope = [&](const Remainder& r, double order, const char* name) {
    if (r.exact) {
      rep.failures.push_back(std::string(name) + ": remainder at round-off for every h, but the functional is "
                             "expected to be nonlinear of this order (direction or h range too small?)");
      return;
    }
    if (r.points_used < 3) {
      rep.failures.push_back(std::string(name) + ": only " + std::to_string(r.points_used) +
                             " steps above the round-off floor; cannot fit a slope");
      return;
    }
    if (!(std::abs(r.slope - order) <= opt.slope_tol))
      rep.failures.push_back(std::string(name) + ": fitted slope " + fmt("%.3f", r.slope) + ", expected " +
                             fmt("%.0f", order));
  };
  auto expect_exact = [&](const Remainder& r, const char* name) {
    if (!r.exact)
      rep.failures.push_back(std::string(name) + ": expected exact (polynomial functional) but remainder " +
                             fmt("%.3e", *std::max_element(r.r.begin(), r.r.end())) + " exceeds 100x round-off");
  };
  if (opt.expect_degree == 1) {
    expect_exact(rep.r1, "Taylor r1 (value, linear)");
    if (rep.has_hessian) { expect_exact(rep.r2, "Taylor r2"); expect_exact(rep.r3, "Taylor r3"); }
  } else if (opt.expect_degree == 2) {
    expect_slope(rep.r1, 2.0, "Taylor r1 = |E(u+hv)-E-h g.v|");
    if (rep.has_hessian) { expect_exact(rep.r2, "Taylor r2 (quadratic)"); expect_exact(rep.r3, "Taylor r3 (quadratic)"); }
  } else {
    expect_slope(rep.r1, 2.0, "Taylor r1 = |E(u+hv)-E-h g.v|");
    if (rep.has_hessian) {
      expect_slope(rep.r2, 3.0, "Taylor r2 = |E(u+hv)-E-h g.v-h^2/2 vHv|");
      expect_slope(rep.r3, 2.0, "Taylor r3 = |g(u+hv)-g-h Hv|");
    }
  }
  return rep;
}

std::string Report::summary(const std::string& label) const {
  std::ostringstream os;
  auto sl = [](const Remainder& r) {
    if (r.h.empty()) return std::string("   -  ");
    if (r.exact) return std::string(" exact");
    char b[32];
    std::snprintf(b, sizeof b, "%6.3f", r.slope);
    return std::string(b);
  };
  char line[512];
  std::snprintf(line, sizeof line,
                "%-34s E=% .6e  |g|=%.2e grad_err=%.2e  |H|=%.2e hess_err=%.2e asym=%.1e  slopes r1=%s r2=%s r3=%s",
                label.c_str(), energy, grad_max, grad_err, hess_max, hess_err, hess_asym, sl(r1).c_str(),
                sl(r2).c_str(), sl(r3).c_str());
  os << line;
  for (const auto& f : failures) os << "\n    FAIL: " << f;
  return os.str();
}

}  // namespace lmeform::formcheck
