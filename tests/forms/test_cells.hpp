// The cells of the form tests and of the kernel benchmark: the runtime's graded LME geometry
// (lmeform/form_check_setup.hpp) with the parameters these tests were written for — finest
// (h_min 0.03, h_max 0.09) on the circle (cx, cy, R), gamma 0.8, a Cartesian (unmirrored) basis
// also for the axisymmetric forms, whose circle is centred on the axis x = 0.
#pragma once

#include <lmeform/form_check_setup.hpp>

#include <array>
#include <map>
#include <memory>
#include <random>
#include <vector>

namespace lmeform::formcheck::testing {

inline const CheckGeometry& test_geometry(double cx = 0.45, double cy = 0.45, double R = 0.3) {
  static std::map<std::array<double, 3>, std::unique_ptr<CheckGeometry>> cache;
  auto& g = cache[{cx, cy, R}];
  if (!g) {
    GeometryOptions o;
    o.dim = 2;
    o.h_min = 0.03;
    o.h_max = 0.09;
    o.transition = 0.15;
    o.center = std::array<double, 3>{cx, cy, 0.0};
    o.radius = R;
    o.gamma = 0.8;
    o.seed = 11;
    g = std::make_unique<CheckGeometry>(o);
  }
  return *g;
}

/// The cell containing (x, y), tabulated to `order`.
inline Cell cell_at(const CheckGeometry& g, double x, double y, int order) {
  const std::array<double, 2> p{x, y};
  return g.cell(g.cell_near(p), order);
}

/// A phase field with its tanh interface (width eps) on the circle (cx, cy, R), plus noise.
inline std::vector<double> phase_field(const Cell& cell, double cx, double cy, double R, double eps, double noise,
                                       std::mt19937_64& rng) {
  return smooth_scalar_field(cell, Feature{2, {cx, cy, 0.0}, R}, eps, noise, rng);
}

/// A non-identity deformation with det F well away from 0 (checked by the callers).
inline std::vector<double> deformation(const Cell& cell, std::mt19937_64& rng) {
  return near_identity_field(cell, 0.1, 0.002, Coordinates::cartesian, rng);
}

}  // namespace lmeform::formcheck::testing
