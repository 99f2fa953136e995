// Shared helpers for the basis tests: node sets and error measures.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <numbers>
#include <random>
#include <vector>

#include "lmeform/kernel.hpp"
#include "lmeform/node_set.hpp"

namespace lmeform::test {

/// Regular grid of `per_side` nodes per axis on [0, length]^dim, optionally jittered by
/// jitter * step (uniform in [-jitter, jitter]) except on the boundary, so the hull stays the box.
inline NodeSet grid(int dim, int per_side, double length = 1.0, double jitter = 0.0, unsigned seed = 7) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  const double step = length / (per_side - 1);
  std::vector<double> c;
  const int total = dim == 1 ? per_side : dim == 2 ? per_side * per_side : per_side * per_side * per_side;
  for (int k = 0; k < total; ++k) {
    int idx[3] = {k % per_side, (k / per_side) % per_side, k / (per_side * per_side)};
    bool boundary = false;
    for (int i = 0; i < dim; ++i) boundary = boundary || idx[i] == 0 || idx[i] == per_side - 1;
    for (int i = 0; i < dim; ++i) c.push_back(idx[i] * step + (boundary ? 0.0 : jitter * step * u(rng)));
  }
  return NodeSet(dim, std::move(c));
}

/// Strongly graded 2D set: a centre node and rings whose spacing grows linearly with the radius from
/// h0 to 10 h0 at radius R (ratio 10:1), then stays at 10 h0 for one more ring.
inline NodeSet graded_disc(double h0 = 0.01, double R = 0.5, unsigned seed = 3) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> u(0.0, 2.0 * std::numbers::pi);
  std::vector<double> c = {0.0, 0.0};
  auto h_of = [&](double r) { return h0 * (1.0 + 9.0 * std::min(r / R, 1.0)); };
  double r = h0;
  while (r <= R + 1.5 * h_of(R)) {
    const int m = std::max(6, static_cast<int>(std::lround(2.0 * std::numbers::pi * r / h_of(r))));
    const double phase = u(rng);
    for (int k = 0; k < m; ++k) {
      const double t = phase + 2.0 * std::numbers::pi * k / m;
      c.push_back(r * std::cos(t));
      c.push_back(r * std::sin(t));
    }
    r += h_of(r);
  }
  return NodeSet(2, std::move(c));
}

/// Uniform random points in [lo, hi]^dim.
inline std::vector<double> random_points(int dim, int count, double lo, double hi, unsigned seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> u(lo, hi);
  std::vector<double> p(static_cast<std::size_t>(dim * count));
  for (double& v : p) v = u(rng);
  return p;
}

/// max |a - b| / max(|b|) over a range: relative error against the magnitude of the reference.
inline double rel_err(const std::vector<double>& a, const std::vector<double>& b) {
  double num = 0.0, den = 0.0;
  for (std::size_t i = 0; i < a.size(); ++i) {
    num = std::max(num, std::abs(a[i] - b[i]));
    den = std::max(den, std::abs(b[i]));
  }
  return den > 0.0 ? num / den : num;
}

}  // namespace lmeform::test
