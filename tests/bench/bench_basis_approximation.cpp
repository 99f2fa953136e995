// bench_basis_approximation: do the basis' second derivatives converge as the node spacing h falls at
// fixed gamma? (docs/lme_basis.md, "Order of the basis").
//   bench_basis_approximation [--quick] [--out DIR]   writes DIR/basis_approximation.json
//
// 1. Approximation: f_h = sum_a p_a c_a of f = sin(pi x) sin(pi y) (the plate's solution) and of a
//    generic smooth f (no symmetry at the boundary), with c_a = f(x_a) (first order) or the
//    gap-corrected c_a = f(x_a) - H f(x_a) : G_a / 2 (second order), against h at gamma = 0.5, 0.8,
//    1.8: max errors of f, grad f and the Hessian, relative to max |f|, |grad f|, |H f| on the
//    square, at points of the interior ([0.25, 0.75]^2) and near the hull (0.02 h .. h from a side),
//    on uniform, jittered (0.3 h) and graded (graded_grid_2d, h/2 .. 2h) node sets of [0, 1]^2.
// 2. The floor: E_kl = Hessian of the approximant of x_k x_l minus its exact Hessian (the Hessian
//    of the second-moment error J_kl = sum p_a (x_a - x)_k (x_a - x)_l; with the gap subtracted for
//    the second order), and the Hessian error it predicts for f, P = 1/2 sum_kl (H f)_kl E_kl. What
//    remains, H f_h - H f - P, is the Taylor remainder.
// 3. Feasibility of the second-order constraints against gamma (points that fail, per node set).
// 4. Cost: microseconds per point (values; values, gradients, Hessians), neighbours per point,
//    compressed record size, for both bases.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <numbers>
#include <optional>
#include <string>
#include <vector>

#include "bench_common.hpp"
#include "lmeform/kernel.hpp"
#include "lmeform/lme_basis.hpp"
#include "lmeform/node_sets.hpp"

namespace {

using namespace lmeform;
using bench::JsonRecord;

constexpr double kPi = std::numbers::pi;

enum class NodeKind { uniform, jittered, graded };

const char* name(NodeKind k) { return k == NodeKind::uniform ? "uniform" : k == NodeKind::jittered ? "jittered" : "graded"; }

NodeSet make_nodes(NodeKind kind, double h) {
  const Box box = Box::unit(2);
  if (kind == NodeKind::graded) {
    GradedGridOptions o;
    o.h_min = 0.5 * h;
    o.h_max = 2.0 * h;
    o.seed = 5;
    return graded_grid_2d(o);
  }
  const NodeSet grid = uniform_grid(box, h);
  return kind == NodeKind::uniform ? grid : jitter_interior(grid, box, 0.3 * h, 11);
}

// A smooth test function: value, gradient and packed Hessian (kernel::hessian_slot order), and the
// maxima of |f|, |grad f|, |H f| on the square that errors are measured against.
struct TestFunction {
  const char* name;
  double (*value)(double, double);
  void (*derivatives)(double, double, double* grad, double* hess);
  double scale[3];
};

double sinsin(double x, double y) { return std::sin(kPi * x) * std::sin(kPi * y); }
void sinsin_d(double x, double y, double* g, double* h) {
  const double sx = std::sin(kPi * x), sy = std::sin(kPi * y), cx = std::cos(kPi * x), cy = std::cos(kPi * y);
  g[0] = kPi * cx * sy;
  g[1] = kPi * sx * cy;
  h[0] = -kPi * kPi * sx * sy;
  h[1] = kPi * kPi * cx * cy;
  h[2] = h[0];
}
// sin(a.x + 1) cos(b.x + 0.5), a = (2, 0.7), b = (-0.8, 1.5).
double generic(double x, double y) { return std::sin(2 * x + 0.7 * y + 1) * std::cos(-0.8 * x + 1.5 * y + 0.5); }
void generic_d(double x, double y, double* g, double* h) {
  const double a[2] = {2.0, 0.7}, b[2] = {-0.8, 1.5};
  const double u = a[0] * x + a[1] * y + 1, v = b[0] * x + b[1] * y + 0.5;
  const double su = std::sin(u), cu = std::cos(u), sv = std::sin(v), cv = std::cos(v);
  for (int i = 0; i < 2; ++i) g[i] = cu * cv * a[i] - su * sv * b[i];
  int k = 0;
  for (int i = 0; i < 2; ++i)
    for (int j = i; j < 2; ++j) h[k++] = -su * cv * (a[i] * a[j] + b[i] * b[j]) - cu * sv * (a[i] * b[j] + b[i] * a[j]);
}

TestFunction make_generic() {
  TestFunction f{"generic", generic, generic_d, {0, 0, 0}};
  for (int i = 0; i <= 200; ++i)
    for (int j = 0; j <= 200; ++j) {
      double g[2], h[3];
      const double x = i / 200.0, y = j / 200.0;
      generic_d(x, y, g, h);
      f.scale[0] = std::max(f.scale[0], std::abs(generic(x, y)));
      f.scale[1] = std::max(f.scale[1], std::hypot(g[0], g[1]));
      f.scale[2] = std::max({f.scale[2], std::abs(h[0]), std::abs(h[1]), std::abs(h[2])});
    }
  return f;
}

std::vector<double> interior_points(int count) {
  SplitMix64 rng(17);
  std::vector<double> p;
  for (int k = 0; k < 2 * count; ++k) p.push_back(0.25 + 0.5 * rng.uniform());
  return p;
}

// Points 0.02 h .. h from a side of the square (corners excluded: 0.05 .. 0.95 along the side).
std::vector<double> hull_points(int count, double h) {
  SplitMix64 rng(23);
  std::vector<double> p;
  for (int k = 0; k < count; ++k) {
    const double delta = h * (0.02 + 0.98 * rng.uniform()), t = 0.05 + 0.9 * rng.uniform();
    const int side = k % 4;
    const double x = side == 0 ? delta : side == 1 ? 1 - delta : t, y = side == 2 ? delta : side == 3 ? 1 - delta : t;
    p.push_back(x);
    p.push_back(y);
  }
  return p;
}

// Max-norm errors over points (relative to the function's scales), and the floor analysis.
struct Errors {
  double f = 0, grad = 0, hess = 0;
  double quad = 0;   // max |E_kl| (second moment's Hessian error), absolute
  double floor = 0;  // max |P| / scale[2]
  double rest = 0;   // max |H f_h - H f - P| / scale[2]
  int failed = 0;
  std::string first_failure;
};

Errors measure(const LmeBasis& basis, const std::vector<double>& points, const TestFunction& fn, bool corrected) {
  const NodeSet& nodes = basis.nodes();
  const std::size_t n_nodes = nodes.size();
  std::vector<double> values(n_nodes), hessians(n_nodes * 3);
  for (std::size_t a = 0; a < n_nodes; ++a) {
    double g[2];
    values[a] = fn.value(nodes.coords[2 * a], nodes.coords[2 * a + 1]);
    fn.derivatives(nodes.coords[2 * a], nodes.coords[2 * a + 1], g, &hessians[3 * a]);
  }
  const std::vector<double> c = corrected ? basis.gap_corrected(values, hessians) : values;
  const auto gaps = basis.gaps();
  Errors e;
  LmeWorkspace ws;
  std::vector<double> jet;
  for (std::size_t q = 0; q < points.size() / 2; ++q) {
    const std::span<const double> x(&points[2 * q], 2);
    const std::vector<int> nbrs = basis.neighbours(x);
    const std::size_t n = nbrs.size();
    jet.resize(6 * n);
    try {
      basis.evaluate(x, nbrs, 2, jet, ws);
    } catch (const LmeEvaluationError& err) {
      if (e.failed++ == 0) e.first_failure = err.what();
      continue;
    }
    double fh[6] = {0, 0, 0, 0, 0, 0}, quad[3][3] = {};
    for (std::size_t a = 0; a < n; ++a) {
      const auto b = static_cast<std::size_t>(nbrs[a]);
      for (int s = 0; s < 6; ++s) fh[s] += jet[static_cast<std::size_t>(s) * n + a] * c[b];
      const double y[2] = {nodes.coords[2 * b] - x[0], nodes.coords[2 * b + 1] - x[1]};
      for (int k = 0; k < 2; ++k)
        for (int l = k; l < 2; ++l) {
          const double m = y[k] * y[l] - (gaps.empty() || !corrected ? 0.0 : gaps[3 * b + std::size_t(k + l)]);
          for (int s = 0; s < 3; ++s) quad[k + l][s] += jet[static_cast<std::size_t>(3 + s) * n + a] * m;
        }
    }
    // E_kl = that minus the Hessian of x_k x_l (e_k e_l^T + e_l e_k^T, packed).
    quad[0][0] -= 2;
    quad[1][1] -= 1;
    quad[2][2] -= 2;
    double g[2], hf[3];
    fn.derivatives(x[0], x[1], g, hf);
    e.f = std::max(e.f, std::abs(fh[0] - fn.value(x[0], x[1])) / fn.scale[0]);
    e.grad = std::max(e.grad, std::hypot(fh[1] - g[0], fh[2] - g[1]) / fn.scale[1]);
    for (int s = 0; s < 3; ++s) {
      // P = 1/2 sum_kl F_kl E_kl, the off-diagonal pair counted twice.
      const double p = 0.5 * (hf[0] * quad[0][s] + 2 * hf[1] * quad[1][s] + hf[2] * quad[2][s]);
      e.hess = std::max(e.hess, std::abs(fh[3 + s] - hf[s]) / fn.scale[2]);
      e.floor = std::max(e.floor, std::abs(p) / fn.scale[2]);
      e.rest = std::max(e.rest, std::abs(fh[3 + s] - hf[s] - p) / fn.scale[2]);
      for (int kl = 0; kl < 3; ++kl) e.quad = std::max(e.quad, std::abs(quad[kl][s]));
    }
  }
  return e;
}

std::optional<LmeBasis> make_basis(const NodeSet& nodes, double gamma, LmeConsistency consistency, std::string& refusal) {
  LmeOptions o;
  o.consistency = consistency;
  try {
    return LmeBasis(nodes, std::vector<double>{gamma}, o);
  } catch (const std::invalid_argument& err) {
    refusal = err.what();
    return std::nullopt;
  }
}

// Section 1 and 2: the error tables.
void convergence(bool quick, std::vector<JsonRecord>& records) {
  const std::vector<double> hs = quick ? std::vector<double>{0.1, 0.05, 0.025} : std::vector<double>{0.1, 0.05, 0.025, 0.0125};
  const TestFunction functions[] = {{"sinsin", sinsin, sinsin_d, {1.0, kPi * std::sqrt(2.0), kPi * kPi}}, make_generic()};
  const int count = quick ? 200 : 400;
  const std::vector<double> interior = interior_points(count);
  std::printf("\n1-2. Approximation errors (max over points, relative) and the second-moment floor\n");
  std::printf("%-8s %-7s %5s %-8s %-8s %7s %9s %9s %9s %9s %9s %9s %4s\n", "nodes", "basis", "gamma", "function",
              "region", "h", "err f", "err grad", "err hess", "|E_kl|", "floor P", "H - P", "fail");
  for (const NodeKind kind : {NodeKind::uniform, NodeKind::jittered, NodeKind::graded}) {
    for (const double gamma : {0.5, 0.8, 1.8}) {
      for (const LmeConsistency consistency : {LmeConsistency::first, LmeConsistency::second}) {
        for (const double h : hs) {
          const NodeSet nodes = make_nodes(kind, h);
          std::string refusal;
          const auto basis = make_basis(nodes, gamma, consistency, refusal);
          if (!basis) {
            if (h == hs.front()) std::printf("%-8s %-7s %5.1f refused: %s\n", name(kind), to_string(consistency), gamma, refusal.c_str());
            records.push_back(JsonRecord().set("section", "convergence").set("nodes", name(kind)).set("basis", to_string(consistency))
                                  .set("gamma", gamma).set("h", h).set("refused", refusal));
            continue;
          }
          const std::vector<double> near = hull_points(count, h);
          for (const TestFunction& fn : functions) {
            for (const bool at_hull : {false, true}) {
              const bool corrected = consistency == LmeConsistency::second;
              const Errors e = measure(*basis, at_hull ? near : interior, fn, corrected);
              std::printf("%-8s %-7s %5.1f %-8s %-8s %7.4f %9.2e %9.2e %9.2e %9.2e %9.2e %9.2e %4d\n", name(kind),
                          to_string(consistency), gamma, fn.name, at_hull ? "hull" : "interior", h, e.f, e.grad, e.hess,
                          e.quad, e.floor, e.rest, e.failed);
              JsonRecord r;
              r.set("section", "convergence").set("nodes", name(kind)).set("basis", to_string(consistency)).set("gamma", gamma)
                  .set("function", fn.name).set("region", at_hull ? "hull" : "interior").set("h", h).set("nodes_count", nodes.size())
                  .set("err_f", e.f).set("err_grad", e.grad).set("err_hess", e.hess).set("quad_hessian_error", e.quad)
                  .set("floor", e.floor).set("remainder", e.rest).set("failed", e.failed);
              if (e.failed) r.set("first_failure", e.first_failure);
              records.push_back(r);
            }
          }
        }
      }
    }
  }
}

// Section 3: points (all over the square and near the hull) the second-order basis cannot evaluate.
void feasibility(bool quick, std::vector<JsonRecord>& records) {
  const double h = 0.025;
  const int count = quick ? 1000 : 4000;
  std::vector<double> points = interior_points(count);
  for (double& v : points) v = (v - 0.25) * 2.0;  // the whole square
  const std::vector<double> near = hull_points(count, h);
  points.insert(points.end(), near.begin(), near.end());
  std::printf("\n3. Second-order basis: points that cannot be evaluated (of %zu, half within h of the hull), h = %.3f\n",
              points.size() / 2, h);
  std::printf("%-8s", "gamma");
  for (const NodeKind kind : {NodeKind::uniform, NodeKind::jittered, NodeKind::graded}) std::printf(" %10s", name(kind));
  std::printf("\n");
  for (const double gamma : {0.3, 0.5, 0.8, 0.9, 1.0, 1.2}) {
    std::printf("%-8.1f", gamma);
    for (const NodeKind kind : {NodeKind::uniform, NodeKind::jittered, NodeKind::graded}) {
      std::string refusal;
      const auto basis = make_basis(make_nodes(kind, h), gamma, LmeConsistency::second, refusal);
      if (!basis) {
        std::printf(" %10s", "refused");
        records.push_back(JsonRecord().set("section", "feasibility").set("nodes", name(kind)).set("gamma", gamma).set("refused", refusal));
        continue;
      }
      const Errors e = measure(*basis, points, {"sinsin", sinsin, sinsin_d, {1.0, 1.0, 1.0}}, true);
      std::printf(" %10d", e.failed);
      JsonRecord r;
      r.set("section", "feasibility").set("nodes", name(kind)).set("gamma", gamma).set("h", h)
          .set("points", points.size() / 2).set("failed", e.failed);
      if (e.failed) r.set("first_failure", e.first_failure);
      records.push_back(r);
    }
    std::printf("\n");
  }
}

// Section 4: cost per point and neighbourhood size on the jittered set.
void cost(bool quick, std::vector<JsonRecord>& records) {
  const double h = quick ? 0.025 : 0.0125;
  const NodeSet nodes = make_nodes(NodeKind::jittered, h);
  const std::vector<double> points = interior_points(quick ? 2000 : 10000);
  std::printf("\n4. Cost per point (one core, CPU time), jittered nodes h = %.4f, interior points\n", h);
  std::printf("%-7s %5s %9s %11s %11s %9s %9s %6s\n", "basis", "gamma", "nbar", "us/pt p", "us/pt Hp", "record", "full",
              "failed");
  for (const double gamma : {0.5, 0.8, 1.0, 1.8}) {
    for (const LmeConsistency consistency : {LmeConsistency::first, LmeConsistency::second}) {
      std::string refusal;
      const auto basis = make_basis(nodes, gamma, consistency, refusal);
      if (!basis) continue;
      const CsrLists lists = basis->neighbour_lists(points);
      std::size_t nmax = 0;
      for (std::size_t q = 0; q < lists.size(); ++q) nmax = std::max(nmax, lists[q].size());
      std::vector<double> jet(6 * nmax);
      LmeWorkspace ws;
      double us[3] = {0, 0, 0}, checksum = 0;
      int failed = 0;
      for (const int order : {0, 2}) {
        bench::CpuStopwatch clock;
        for (std::size_t q = 0; q < lists.size(); ++q) {
          try {
            basis->evaluate(std::span<const double>(&points[2 * q], 2), lists[q], order, jet, ws);
            checksum += jet[0];
          } catch (const LmeEvaluationError&) {
            failed += order == 0;
          }
        }
        us[order] = 1e6 * clock.seconds() / static_cast<double>(lists.size());
      }
      const double nbar = lists.mean_size();
      std::printf("%-7s %5.1f %9.1f %11.2f %11.2f %9d %9.0f %6d   (checksum %.3g)\n", to_string(consistency), gamma, nbar,
                  us[0], us[2], basis->record_size(2), 6 * nbar, failed, checksum);
      records.push_back(JsonRecord().set("section", "cost").set("basis", to_string(consistency)).set("gamma", gamma).set("h", h)
                            .set("mean_neighbours", nbar).set("us_per_point_values", us[0]).set("us_per_point_hessians", us[2])
                            .set("record_doubles", basis->record_size(2)).set("full_doubles_per_point", 6 * nbar)
                            .set("failed", failed));
    }
  }
}

}  // namespace

int main(int argc, char** argv) {
  const bench::BenchOptions options = bench::parse_bench_options(argc, argv);
  for (const auto& u : options.unknown) std::fprintf(stderr, "bench_basis_approximation: ignoring %s\n", u.c_str());
  std::vector<JsonRecord> records;
  convergence(options.quick, records);
  feasibility(options.quick, records);
  cost(options.quick, records);
  JsonRecord meta;
  meta.set("tol0", LmeOptions{}.tol0).set("second_order_max_gamma", lme_second_order_max_gamma);
  bench::write_json(options.out / "basis_approximation.json", "basis_approximation", options.quick, meta, records);
  std::printf("\nwrote %s\n", (options.out / "basis_approximation.json").string().c_str());
  return 0;
}
