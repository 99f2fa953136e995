// bench_plate_order: the simply supported Kirchhoff plate with a manufactured solution, solved with
// the first- and the second-order LME basis through the runtime's pipeline (Discretization with
// DiscretizationOptions::lme, cell tabulation from full storage, Assembler, PETSc LU).
//   bench_plate_order [--quick] [--out DIR]   writes DIR/plate_order.json
//
// Unit square, E(w) = 1/2 D (lap w)^2 - q w with D = 1, q = 4 pi^4 sin(pi x) sin(pi y), w = 0 on the
// hull (zero coefficients of the hull nodes: both bases vanish there except for hull nodes' functions),
// exact w = sin(pi x) sin(pi y); Delaunay cells with 6 points each (as `lmeform run`), and 12 on
// jittered nodes, where 6 limit the second-order basis. Errors:
// ||w_h - w|| in L2, and the H1 and H2 semi-norms, on uniform and jittered (0.3 h) nodes.
#include <petscsys.h>

#include <cmath>
#include <cstdio>
#include <numbers>
#include <string>
#include <vector>

#include "bench_common.hpp"
#include "lmeform/assembler.hpp"
#include "lmeform/convex_hull.hpp"
#include "lmeform/discretization.hpp"
#include "lmeform/node_sets.hpp"
#include "lmeform/petsc.hpp"

namespace {

using namespace lmeform;
using bench::JsonRecord;

constexpr double kPi = std::numbers::pi;

// w, grad w, Hessian of w (packed xx, xy, yy).
void exact(const double* x, double* j) {
  const double sx = std::sin(kPi * x[0]), sy = std::sin(kPi * x[1]), cx = std::cos(kPi * x[0]), cy = std::cos(kPi * x[1]);
  j[0] = sx * sy;
  j[1] = kPi * cx * sy;
  j[2] = kPi * sx * cy;
  j[3] = j[5] = -kPi * kPi * sx * sy;
  j[4] = kPi * kPi * cx * cy;
}

// The jet (u, grad u, Hessian) of the field at point q of a cell.
void field_jet(const kernel::CellInputs& in, int q, double* jet) {
  const double* b = in.basis + static_cast<std::size_t>(q) * 6 * static_cast<std::size_t>(in.n_nodes);
  for (int s = 0; s < 6; ++s) {
    double v = 0;
    for (int a = 0; a < in.n_nodes; ++a) v += b[s * in.n_nodes + a] * in.unknowns[a];
    jet[s] = v;
  }
}

std::size_t no_workspace(int, int) { return 0; }

// E = sum_q w_q (1/2 (lap w)^2 - q w): value, gradient, Hessian (K_ab = sum w lap p_a lap p_b).
double plate_value(const kernel::CellInputs& in) {
  double e = 0, jet[6], ex[6];
  for (int q = 0; q < in.n_points; ++q) {
    field_jet(in, q, jet);
    exact(in.points + 2 * q, ex);
    const double load = 4 * std::pow(kPi, 4) * ex[0];
    e += in.weights[q] * (0.5 * (jet[3] + jet[5]) * (jet[3] + jet[5]) - load * jet[0]);
  }
  return e;
}
void plate_vector(const kernel::CellInputs& in, double* g) {
  double jet[6], ex[6];
  const auto n = static_cast<std::size_t>(in.n_nodes);
  for (int q = 0; q < in.n_points; ++q) {
    field_jet(in, q, jet);
    exact(in.points + 2 * q, ex);
    const double load = 4 * std::pow(kPi, 4) * ex[0], lap = jet[3] + jet[5];
    const double* b = in.basis + static_cast<std::size_t>(q) * 6 * n;
    for (std::size_t a = 0; a < n; ++a) g[a] += in.weights[q] * (lap * (b[3 * n + a] + b[5 * n + a]) - load * b[a]);
  }
}
void plate_matrix(const kernel::CellInputs& in, double* k) {
  const auto n = static_cast<std::size_t>(in.n_nodes);
  std::vector<double> lap(n);
  for (int q = 0; q < in.n_points; ++q) {
    const double* b = in.basis + static_cast<std::size_t>(q) * 6 * n;
    for (std::size_t a = 0; a < n; ++a) lap[a] = b[3 * n + a] + b[5 * n + a];
    for (std::size_t a = 0; a < n; ++a)
      for (std::size_t c = 0; c < n; ++c) k[a * n + c] += in.weights[q] * lap[a] * lap[c];
  }
}

// Squared errors of the value (0), the gradient (1) or the Hessian (2) as "energies".
template <int Order>
double error_value(const kernel::CellInputs& in) {
  double e = 0, jet[6], ex[6];
  for (int q = 0; q < in.n_points; ++q) {
    field_jet(in, q, jet);
    exact(in.points + 2 * q, ex);
    double s = 0;
    if constexpr (Order == 0) s = (jet[0] - ex[0]) * (jet[0] - ex[0]);
    if constexpr (Order == 1) s = (jet[1] - ex[1]) * (jet[1] - ex[1]) + (jet[2] - ex[2]) * (jet[2] - ex[2]);
    if constexpr (Order == 2)
      s = (jet[3] - ex[3]) * (jet[3] - ex[3]) + 2 * (jet[4] - ex[4]) * (jet[4] - ex[4]) + (jet[5] - ex[5]) * (jet[5] - ex[5]);
    e += in.weights[q] * s;
  }
  return e;
}

kernel::FormKernels form(const char* name, kernel::ValueKernel value, kernel::VectorKernel vector,
                         kernel::MatrixKernel matrix) {
  static const kernel::FieldInfo unknown{"w", 1};
  kernel::FormKernels k;
  k.module = "plate_bench";
  k.name = name;
  k.kind = kernel::FunctionalKind::Energy;
  k.dim = 2;
  k.basis_order = 2;
  k.unknowns = &unknown;
  k.n_unknowns = 1;
  k.dofs_per_node = 1;
  k.workspace_doubles = &no_workspace;
  k.value = value;
  k.vector = vector;
  k.matrix = matrix;
  return k;
}

struct PlateResult {
  std::size_t nodes = 0;
  double nbar = 0, l2 = 0, h1 = 0, h2 = 0, seconds = 0;
};

PlateResult solve_plate(const NodeSet& nodes, double gamma, LmeConsistency consistency, int quadrature_points) {
  bench::Stopwatch clock;
  DiscretizationOptions o;
  o.gamma = {gamma};
  o.lme.consistency = consistency;
  o.quadrature_points = quadrature_points;
  o.basis_order = 2;
  const Discretization disc(PETSC_COMM_SELF, nodes, o);
  const kernel::FormKernels energy = form("energy", plate_value, plate_vector, plate_matrix);
  Assembler assembler(disc, energy);
  PetscMatrix k = assembler.create_matrix();
  PetscVector b = assembler.create_vector(), w = assembler.create_vector();
  assembler.matrix(w, k);
  assembler.vector(w, b);
  LMEFORM_PETSC_CHECK(VecScale(b, -1.0));
  apply_dirichlet(k, b, w, owned_dofs_of_nodes(disc, hull_boundary_nodes(nodes), 1));
  PetscLinearSolver ksp;
  LMEFORM_PETSC_CHECK(KSPCreate(PETSC_COMM_SELF, ksp.out()));
  LMEFORM_PETSC_CHECK(KSPSetOperators(ksp, k, k));
  LMEFORM_PETSC_CHECK(KSPSetType(ksp, KSPPREONLY));
  PC pc = nullptr;
  LMEFORM_PETSC_CHECK(KSPGetPC(ksp, &pc));
  LMEFORM_PETSC_CHECK(PCSetType(pc, PCLU));
  LMEFORM_PETSC_CHECK(KSPSolve(ksp, b, w));
  PlateResult r;
  r.nodes = nodes.size();
  r.nbar = disc.mean_point_neighbours();
  const kernel::FormKernels e0 = form("l2", error_value<0>, nullptr, nullptr), e1 = form("h1", error_value<1>, nullptr, nullptr),
                            e2 = form("h2", error_value<2>, nullptr, nullptr);
  Assembler a0(disc, e0), a1(disc, e1), a2(disc, e2);
  r.l2 = std::sqrt(a0.value(w));
  r.h1 = std::sqrt(a1.value(w));
  r.h2 = std::sqrt(a2.value(w));
  r.seconds = clock.seconds();
  return r;
}

}  // namespace

int main(int argc, char** argv) {
  const bench::BenchOptions options = bench::parse_bench_options(argc, argv);
  LMEFORM_PETSC_CHECK(PetscInitialize(&argc, &argv, nullptr, nullptr));
  {
    const std::vector<double> hs = options.quick ? std::vector<double>{0.1, 0.05, 0.025}
                                                 : std::vector<double>{0.1, 0.05, 0.025, 0.0125};
    struct Case {
      const char* nodes;
      LmeConsistency consistency;
      double gamma;
      int quadrature_points;
    };
    constexpr auto first = LmeConsistency::first, second = LmeConsistency::second;
    // On jittered nodes the 6-point rule limits the second-order basis (measured): 12 points too.
    const std::vector<Case> cases = {
        {"uniform", first, 0.5, 6},   {"uniform", first, 0.8, 6},   {"uniform", first, 1.8, 6},
        {"uniform", second, 0.5, 6},  {"uniform", second, 0.8, 6},  {"jittered", first, 0.8, 6},
        {"jittered", first, 0.8, 12}, {"jittered", second, 0.8, 6}, {"jittered", second, 0.8, 12},
        {"jittered", second, 0.8, 19}, {"jittered", second, 0.5, 12}};
    std::vector<JsonRecord> records;
    std::printf("Kirchhoff plate, simply supported, w = sin(pi x) sin(pi y): errors of w_h\n");
    std::printf("%-8s %-7s %5s %3s %7s %6s %6s %10s %10s %10s %7s\n", "nodes", "basis", "gamma", "qp", "h", "N", "nbar", "L2",
                "H1 semi", "H2 semi", "s");
    for (const Case& c : cases) {
      for (const double h : hs) {
        const Box box = Box::unit(2);
        const NodeSet grid = uniform_grid(box, h);
        const NodeSet nodes = std::string(c.nodes) == "uniform" ? grid : jitter_interior(grid, box, 0.3 * h, 11);
        const PlateResult r = solve_plate(nodes, c.gamma, c.consistency, c.quadrature_points);
        std::printf("%-8s %-7s %5.1f %3d %7.4f %6zu %6.1f %10.3e %10.3e %10.3e %7.1f\n", c.nodes, to_string(c.consistency),
                    c.gamma, c.quadrature_points, h, r.nodes, r.nbar, r.l2, r.h1, r.h2, r.seconds);
        std::fflush(stdout);
        records.push_back(JsonRecord().set("nodes", c.nodes).set("basis", to_string(c.consistency)).set("gamma", c.gamma)
                              .set("quadrature_points", c.quadrature_points).set("h", h).set("node_count", r.nodes).set("mean_neighbours", r.nbar).set("l2", r.l2)
                              .set("h1", r.h1).set("h2", r.h2).set("seconds", r.seconds));
      }
    }
    bench::write_json(options.out / "plate_order.json", "plate_order", options.quick, JsonRecord(), records);
    std::printf("wrote %s\n", (options.out / "plate_order.json").string().c_str());
  }
  LMEFORM_PETSC_CHECK(PetscFinalize());
  return 0;
}
