// The three Stokes problems of demos/ (colliding flow, Poiseuille, a manufactured solution) as
// scene texts for forms/stokes.form, and the node sets of the convergence studies: uniform grids
// and graded, jittered ones. Shared by test_stokes and bench_stokes, so that both solve exactly the
// problems of the demo scenes.
#pragma once

#include <algorithm>
#include <cmath>
#include <numbers>
#include <random>
#include <sstream>
#include <string>
#include <vector>

#include "lmeform/node_set.hpp"

namespace lmeform::stokes_problems {

struct Problem {
  std::string name;                 ///< "colliding_flow", "poiseuille", "manufactured"
  double lower, upper;              ///< the square [lower, upper]^2
  std::string u, p, f;              ///< exact velocity and pressure, body force ("zero" or an expression)
};

inline std::vector<Problem> demo_problems() {
  return {
      {"colliding_flow", -1.0, 1.0, "20*x[0]*x[1]^3*e(0) + (5*x[0]^4 - 5*x[1]^4)*e(1)", "60*x[0]^2*x[1] - 20*x[1]^3",
       "zero"},
      {"poiseuille", 0.0, 1.0, "4*x[1]*(1 - x[1])*e(0)", "8*nu*(0.5 - x[0])", "zero"},
      {"manufactured", 0.0, 1.0, "pi*sin(pi*x[0])^2*sin(2*pi*x[1])*e(0) - pi*sin(2*pi*x[0])*sin(pi*x[1])^2*e(1)",
       "cos(pi*x[0])*cos(pi*x[1])",
       "(-2*nu*pi^3*sin(2*pi*x[1])*(2*cos(2*pi*x[0]) - 1) - pi*sin(pi*x[0])*cos(pi*x[1]))*e(0)"
       " + (2*nu*pi^3*sin(2*pi*x[0])*(2*cos(2*pi*x[1]) - 1) - pi*cos(pi*x[0])*sin(pi*x[1]))*e(1)"},
  };
}

/// (alpha, beta) of the unified stabilization; "none" is GLS with C = 0.
struct Stabilization {
  std::string name;
  double alpha, beta;
};
inline std::vector<Stabilization> stabilizations() {
  return {{"none", 1, 1}, {"gls", 1, 1}, {"supg", 0, 1}, {"douglas_wang", -1, 1}};
}

/// The scene text of a problem (the node set is given to solve_problem directly).
/// `nodes_extra`: more [nodes] keys (e.g. the basis), `extra`: more tables.
inline std::string scene_text(const Problem& pb, double gamma, const std::string& extra = "", const std::string& nodes_extra = "") {
  std::ostringstream s;
  s << "[scene]\nname = \"" << pb.name << "\"\ncoordinates = \"cartesian\"\n"
    << "[domain]\nlower = [" << pb.lower << ", " << pb.lower << "]\nupper = [" << pb.upper << ", " << pb.upper << "]\n"
    << "[nodes]\ncounts = [9, 9]\ngamma = " << gamma << "\nquadrature_points = 6\n" << nodes_extra
    << "[model]\nforms = [\"stokes\"]\nbilinear = \"a\"\nlinear = \"l\"\nzero_mean = [\"p\"]\n"
    << "[constants]\nnu = 1.0\nC = 0.1\nalpha = 1.0\nbeta = 1.0\n"
    << "[qdata]\nrho_bar = \"support_size\"\nf = \"" << pb.f << "\"\n"
    << "[[dirichlet]]\nboundary = [\"hull\"]\nunknown = \"u\"\nvalue = \"" << pb.u << "\"\n"
    << "[reference.solution]\nu = \"" << pb.u << "\"\np = \"" << pb.p << "\"\n"
    << extra;
  return s.str();
}

/// n x n nodes on [lower, upper]^2.
inline NodeSet uniform_nodes(const Problem& pb, int n) {
  NodeSet nodes;
  nodes.dim = 2;
  for (int j = 0; j < n; ++j)
    for (int i = 0; i < n; ++i) {
      const double h = (pb.upper - pb.lower) / (n - 1);
      nodes.coords.push_back(pb.lower + i * h);
      nodes.coords.push_back(pb.lower + j * h);
    }
  return nodes;
}

/// n x n nodes graded (spacing 1 : 4 between the sides and the middle of the square) and jittered
/// by up to 0.2 of the local spacing in the interior, so that the set is neither uniform nor a
/// tensor-product grid. The boundary nodes stay on the boundary (the hull is the square).
inline NodeSet graded_nodes(const Problem& pb, int n, unsigned seed = 7) {
  // g(s) = s - a sin(2 pi s) / (2 pi): g' = 1 - a cos(2 pi s) in [1 - a, 1 + a], a = 0.6: ratio 1:4,
  // the fine spacing at the sides, the coarse in the middle.
  const double a = 0.6;
  auto g = [&](double s) { return s - a * std::sin(2 * std::numbers::pi * s) / (2 * std::numbers::pi); };
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> jitter(-0.2, 0.2);
  NodeSet nodes;
  nodes.dim = 2;
  const double length = pb.upper - pb.lower;
  for (int j = 0; j < n; ++j)
    for (int i = 0; i < n; ++i) {
      const double s = double(i) / (n - 1), t = double(j) / (n - 1);
      double x = g(s), y = g(t);
      const double hx = (1 - a * std::cos(2 * std::numbers::pi * s)) / (n - 1);
      const double hy = (1 - a * std::cos(2 * std::numbers::pi * t)) / (n - 1);
      const double jx = jitter(rng), jy = jitter(rng);
      if (i > 0 && i < n - 1) x += jx * hx;
      if (j > 0 && j < n - 1) y += jy * hy;
      nodes.coords.push_back(pb.lower + length * std::clamp(x, 0.0, 1.0));
      nodes.coords.push_back(pb.lower + length * std::clamp(y, 0.0, 1.0));
    }
  return nodes;
}

}  // namespace lmeform::stokes_problems
