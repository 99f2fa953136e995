// The README demo (`make demo`) until the vesicle scene runs: the local maximum-entropy basis.
//
//   lme_basis_demo --out DIR
//
// writes
//   DIR/lme_basis_gamma08.csv  1D uniform grid (11 nodes on [0, 1], gamma = 0.8): p_a, p_a', p_a'' of
//                              every node at 801 points (seed Fig. 2.3);
//   DIR/lme_transition.csv     21 nodes with gamma_a linear from 0.6 (x = 0) to 6 (x = 1): p_a at 801
//                              points (seed Fig. 2.2);
// and prints the consistency errors of the basis (zeroth and first order reproduction and the
// identities derived from them for gradients and Hessians) for gamma in {0.6, 0.8, 1.6, 4, 6} in 1D
// and on a jittered 2D grid, with the evaluation rate. demos/plot_lme_basis.py turns the CSVs into PNGs.
//
// Files are written to a temporary name in DIR and renamed, so a reader never sees half a file.
#include <algorithm>
#include <array>
#include <chrono>
#include <cerrno>
#include <cmath>
#include <cstddef>
#include <cstdio>
#include <cstring>
#include <exception>
#include <filesystem>
#include <fstream>
#include <functional>
#include <span>
#include <stdexcept>
#include <string>
#include <system_error>
#include <vector>

#include "lmeform/kernel.hpp"
#include "lmeform/lme_basis.hpp"
#include "lmeform/node_sets.hpp"

namespace {

namespace fs = std::filesystem;
using lmeform::LmeBasis;
using lmeform::LmeWorkspace;
using lmeform::NodeSet;
using lmeform::kernel::hessian_slot;
using lmeform::kernel::jet_size;

constexpr int kSamples1d = 801;

// ---------------------------------------------------------------------------------------------
// Output

fs::path prepare_output_directory(const fs::path& dir) {
  std::error_code ec;
  fs::create_directories(dir, ec);
  if (ec) throw std::runtime_error("cannot create output directory '" + dir.string() + "': " + ec.message());
  if (!fs::is_directory(dir, ec)) {
    throw std::runtime_error("output path '" + dir.string() + "' exists and is not a directory");
  }
  return dir;
}

/// Writes `path` atomically: the content goes to a temporary file beside it, which is renamed onto
/// `path` once complete. Throws std::runtime_error naming the file on any failure.
void write_atomically(const fs::path& path, const std::function<void(std::ostream&)>& body) {
  fs::path tmp = path;
  tmp += ".tmp";
  {
    std::ofstream out(tmp, std::ios::out | std::ios::trunc);
    if (!out) {
      const int err = errno;
      throw std::runtime_error("cannot open '" + tmp.string() + "' for writing: " + std::strerror(err));
    }
    body(out);
    out.flush();
    if (!out) {
      out.close();
      std::error_code ignored;
      fs::remove(tmp, ignored);
      throw std::runtime_error("error while writing '" + tmp.string() + "' (disk full?)");
    }
  }
  std::error_code ec;
  fs::rename(tmp, path, ec);
  if (ec) {
    std::error_code ignored;
    fs::remove(tmp, ignored);
    throw std::runtime_error("cannot rename '" + tmp.string() + "' to '" + path.string() + "': " + ec.message());
  }
}

std::string num(double v) {
  std::array<char, 32> buf{};
  std::snprintf(buf.data(), buf.size(), "%.17g", v);
  return buf.data();
}

// ---------------------------------------------------------------------------------------------
// 1D tabulation

NodeSet uniform_1d(int n) { return lmeform::uniform_grid(lmeform::Box::unit(1), {n, 1, 1}); }

/// x_k = k / (samples - 1), k = 0 .. samples - 1.
std::vector<double> sample_points_1d(int samples) {
  std::vector<double> x(static_cast<std::size_t>(samples));
  for (int k = 0; k < samples; ++k) {
    x[static_cast<std::size_t>(k)] = k + 1 == samples ? 1.0 : static_cast<double>(k) / (samples - 1);
  }
  return x;
}

/// True where x lies on the boundary of the nodes' convex hull in 1D (x <= min or x >= max node).
/// There the basis is 1 for the end node and 0 for the others, but the derivatives have no
/// numerical value (J = 0), so the demo evaluates values only.
bool on_hull_boundary_1d(const LmeBasis& basis, double x) {
  const auto& c = basis.nodes().coords;
  const auto [lo, hi] = std::minmax_element(c.begin(), c.end());
  return x <= *lo || x >= *hi;
}

/// Dense table over all nodes: table[(s * samples + k) * N + a] for jet slot s at sample x_k.
/// Derivatives at the two hull end points are NaN (plots leave them out).
std::vector<double> tabulate_1d(const LmeBasis& basis, const std::vector<double>& x, int order) {
  const std::size_t N = basis.size();
  const int J = jet_size(1, order);
  const std::size_t samples = x.size();
  std::vector<double> table(static_cast<std::size_t>(J) * samples * N, 0.0);
  LmeWorkspace ws;
  std::vector<double> jet;
  for (std::size_t k = 0; k < samples; ++k) {
    const std::span<const double> xk(&x[k], 1);
    const std::vector<int> nb = basis.neighbours(xk);
    const std::size_t n = nb.size();
    const int got = on_hull_boundary_1d(basis, x[k]) ? 0 : order;
    jet.assign(static_cast<std::size_t>(jet_size(1, got)) * n, 0.0);
    basis.evaluate(xk, nb, got, jet, ws);
    for (int s = 0; s < J; ++s) {
      double* row = &table[(static_cast<std::size_t>(s) * samples + k) * N];
      if (s > 0 && got == 0) {
        std::fill(row, row + N, std::nan(""));
        continue;
      }
      for (std::size_t a = 0; a < n; ++a) row[static_cast<std::size_t>(nb[a])] = jet[static_cast<std::size_t>(s) * n + a];
    }
  }
  return table;
}

void write_table_1d(const fs::path& path, const LmeBasis& basis, const std::vector<double>& x,
                    const std::vector<double>& table, int order, const std::string& title) {
  const std::size_t N = basis.size();
  const std::size_t samples = x.size();
  static const std::array<const char*, 3> prefix{"p", "dp", "d2p"};
  write_atomically(path, [&](std::ostream& out) {
    out << "# " << title << "\n";
    out << "# nodes=";
    for (std::size_t a = 0; a < N; ++a) out << (a ? "," : "") << num(basis.nodes().coords[a]);
    out << "\n# gamma=";
    for (std::size_t a = 0; a < N; ++a) out << (a ? "," : "") << num(basis.gamma()[a]);
    out << "\n# spacing=";
    for (std::size_t a = 0; a < N; ++a) out << (a ? "," : "") << num(basis.spacing()[a]);
    out << "\nx";
    for (int s = 0; s <= order; ++s)
      for (std::size_t a = 0; a < N; ++a) out << ',' << prefix[static_cast<std::size_t>(s)] << a;
    out << '\n';
    for (std::size_t k = 0; k < samples; ++k) {
      out << num(x[k]);
      for (int s = 0; s <= order; ++s)
        for (std::size_t a = 0; a < N; ++a) out << ',' << num(table[(static_cast<std::size_t>(s) * samples + k) * N + a]);
      out << '\n';
    }
  });
}

// ---------------------------------------------------------------------------------------------
// Consistency errors

struct Consistency {
  double sum_p = 0;        ///< max |sum p_a - 1|
  double first = 0;        ///< max |sum p_a x_a - x|
  double sum_grad = 0;     ///< max |sum grad p_a|
  double first_grad = 0;   ///< max |sum x_a (x) grad p_a - I|
  double sum_hess = 0;     ///< max |sum H p_a|
  double first_hess = 0;   ///< max |sum x_a (x) H p_a|
  double min_p = 1;        ///< min p_a (non-negativity)
  double mean_neighbours = 0;
  std::size_t points = 0;       ///< all points (values: e0, e1, min p)
  std::size_t boundary = 0;     ///< of which on the hull boundary: no derivatives there
  double values_per_s = 0;
  double hessians_per_s = 0;
};

/// Errors over all `points` (point-major): values at every point, gradients and Hessians (order-2
/// jets) at the points not flagged in `boundary`. The rates time neighbour search plus evaluation
/// (order 0, order 2) over the unflagged points, repeated to at least 0.2 s.
Consistency measure(const LmeBasis& basis, const std::vector<double>& points, const std::vector<char>& boundary) {
  const int d = basis.dim();
  const auto ud = static_cast<std::size_t>(d);
  const std::size_t np = points.size() / ud;
  const auto& X = basis.nodes().coords;
  Consistency c;
  LmeWorkspace ws;
  std::vector<double> jet;
  std::size_t total_neighbours = 0;
  for (std::size_t q = 0; q < np; ++q) {
    const std::span<const double> x(&points[q * ud], ud);
    const std::vector<int> nb = basis.neighbours(x);
    const std::size_t n = nb.size();
    const bool values_only = boundary[q] != 0;
    const int order = values_only ? 0 : 2;
    jet.assign(static_cast<std::size_t>(jet_size(d, order)) * n, 0.0);
    basis.evaluate(x, nb, order, jet, ws);
    ++c.points;
    c.boundary += values_only ? 1 : 0;
    total_neighbours += n;
    auto p = [&](int s, std::size_t a) { return jet[static_cast<std::size_t>(s) * n + a]; };
    double s0 = 0;
    std::array<double, 3> s1{}, g{};
    std::array<std::array<double, 3>, 3> xg{}, xh_sum{};
    std::array<std::array<std::array<double, 3>, 3>, 3> xh{};
    for (std::size_t a = 0; a < n; ++a) {
      const double* xa = &X[static_cast<std::size_t>(nb[a]) * ud];
      s0 += p(0, a);
      c.min_p = std::min(c.min_p, p(0, a));
      for (int i = 0; i < d; ++i) {
        const auto ui = static_cast<std::size_t>(i);
        s1[ui] += p(0, a) * xa[i];
        if (values_only) continue;
        g[ui] += p(1 + i, a);
        for (int j = 0; j < d; ++j) xg[ui][static_cast<std::size_t>(j)] += xa[i] * p(1 + j, a);
        for (int j = i; j < d; ++j) {
          const double hij = p(hessian_slot(i, j, d), a);
          xh_sum[ui][static_cast<std::size_t>(j)] += hij;
          for (int m = 0; m < d; ++m) xh[static_cast<std::size_t>(m)][ui][static_cast<std::size_t>(j)] += xa[m] * hij;
        }
      }
    }
    c.sum_p = std::max(c.sum_p, std::abs(s0 - 1));
    for (std::size_t i = 0; i < ud; ++i) {
      c.first = std::max(c.first, std::abs(s1[i] - x[i]));
      if (values_only) continue;
      c.sum_grad = std::max(c.sum_grad, std::abs(g[i]));
      for (std::size_t j = 0; j < ud; ++j) c.first_grad = std::max(c.first_grad, std::abs(xg[i][j] - (i == j ? 1.0 : 0.0)));
      for (std::size_t j = i; j < ud; ++j) {
        c.sum_hess = std::max(c.sum_hess, std::abs(xh_sum[i][j]));
        for (std::size_t m = 0; m < ud; ++m) c.first_hess = std::max(c.first_hess, std::abs(xh[m][i][j]));
      }
    }
  }
  c.mean_neighbours = c.points ? static_cast<double>(total_neighbours) / static_cast<double>(c.points) : 0.0;

  // Timing: the same points, neighbour search + evaluation into a reused workspace.
  auto rate = [&](int order) {
    using clock = std::chrono::steady_clock;
    std::vector<int> nb;
    std::size_t evals = 0;
    double sink = 0;
    const auto start = clock::now();
    double elapsed = 0;
    do {
      for (std::size_t q = 0; q < np; ++q) {
        if (boundary[q]) continue;
        const std::span<const double> x(&points[q * ud], ud);
        nb = basis.neighbours(x);
        jet.resize(static_cast<std::size_t>(jet_size(d, order)) * nb.size());
        basis.evaluate(x, nb, order, jet, ws);
        sink += jet[0];
        ++evals;
      }
      elapsed = std::chrono::duration<double>(clock::now() - start).count();
    } while (elapsed < 0.2);
    if (sink == -1.0) std::puts("");  // keeps the work observable
    return static_cast<double>(evals) / elapsed;
  };
  c.values_per_s = rate(0);
  c.hessians_per_s = rate(2);
  return c;
}

void print_row(const char* set, double gamma, const Consistency& c) {
  std::printf("%-22s %5.2g %5zu %5.1f %9.1e %9.1e %9.1e %9.1e %9.1e %9.1e %9.1e %9.2e %9.2e\n", set, gamma, c.points,
              c.mean_neighbours, c.sum_p, c.first, c.sum_grad, c.first_grad, c.sum_hess, c.first_hess, c.min_p,
              c.values_per_s, c.hessians_per_s);
}

// ---------------------------------------------------------------------------------------------

int run(const fs::path& out) {
  prepare_output_directory(out);

  // (1) Seed Fig. 2.3: 11 uniform nodes, gamma = 0.8, h_a = 0.1 for every node (the grid step; the
  // default nodal_spacing would give the two end nodes 1.5 h, the mean distance to their 2 nearest).
  {
    const int N = 11;
    const std::vector<double> gamma{0.8};
    LmeBasis basis(uniform_1d(N), gamma, std::vector<double>(N, 1.0 / (N - 1)));
    const std::vector<double> x = sample_points_1d(kSamples1d);
    const std::vector<double> table = tabulate_1d(basis, x, 2);
    const fs::path file = out / "lme_basis_gamma08.csv";
    write_table_1d(file, basis, x, table, 2, "LME basis, 1D uniform grid, 11 nodes on [0,1], gamma = 0.8, h = 0.1");
    std::printf("wrote %s (%d nodes x %d points: p, p', p'')\n", file.string().c_str(), N, kSamples1d);
  }

  // (2) Seed Fig. 2.2: 21 nodes, gamma_a linear from 0.6 at x = 0 to 6 at x = 1, values only.
  {
    const int N = 21;
    std::vector<double> gamma(N);
    for (int a = 0; a < N; ++a) gamma[static_cast<std::size_t>(a)] = 0.6 + (6.0 - 0.6) * a / (N - 1);
    LmeBasis basis(uniform_1d(N), gamma, std::vector<double>(N, 1.0 / (N - 1)));
    const std::vector<double> x = sample_points_1d(kSamples1d);
    const std::vector<double> table = tabulate_1d(basis, x, 0);
    const fs::path file = out / "lme_transition.csv";
    write_table_1d(file, basis, x, table, 0,
                   "LME basis, 1D uniform grid, 21 nodes on [0,1], gamma_a linear from 0.6 to 6, h = 0.05");
    std::printf("wrote %s (%d nodes x %d points: p)\n", file.string().c_str(), N, kSamples1d);
  }

  // (3) Consistency table.
  std::printf("\nConsistency errors (max over all sample points; derivative identities from order-2 jets):\n");
  std::printf("  e0 = |sum p_a - 1|      e1 = |sum p_a x_a - x|\n");
  std::printf("  g0 = |sum grad p_a|     g1 = |sum x_a (x) grad p_a - I|\n");
  std::printf("  h0 = |sum H p_a|        h1 = |sum x_a (x) H p_a|       min p = smallest p_a\n");
  std::printf("  rates: neighbour search + evaluation per point, values only / values+gradients+Hessians\n\n");
  std::printf("%-22s %5s %5s %5s %9s %9s %9s %9s %9s %9s %9s %9s %9s\n", "node set", "gamma", "pts", "nbrs", "e0", "e1",
              "g0", "g1", "h0", "h1", "min p", "values/s", "hess/s");
  const std::array<double, 5> gammas{0.6, 0.8, 1.6, 4.0, 6.0};
  std::size_t boundary_1d = 0;
  {
    const int N = 11;
    const std::vector<double> x = sample_points_1d(kSamples1d);
    for (double g : gammas) {
      const std::vector<double> gamma{g};
      LmeBasis basis(uniform_1d(N), gamma, std::vector<double>(N, 1.0 / (N - 1)));
      std::vector<char> boundary(x.size());
      for (std::size_t k = 0; k < x.size(); ++k) boundary[k] = on_hull_boundary_1d(basis, x[k]) ? 1 : 0;
      const Consistency c = measure(basis, x, boundary);
      boundary_1d = c.boundary;
      print_row("1D uniform, 11 nodes", g, c);
    }
  }
  {
    // 21 x 21 grid on the unit square, interior nodes jittered by up to 0.25 h per coordinate;
    // default spacing (mean distance to the 4 nearest nodes); 2000 random points in the square.
    const lmeform::Box box = lmeform::Box::unit(2);
    const NodeSet nodes = lmeform::jitter_interior(lmeform::uniform_grid(box, {21, 21, 1}), box, 0.25 / 20, 7);
    const NodeSet points = lmeform::random_points(box, 2000, 11);
    for (double g : gammas) {
      const std::vector<double> gamma{g};
      LmeBasis basis(nodes, gamma);
      const Consistency c = measure(basis, points.coords, std::vector<char>(points.size(), 0));
      print_row("2D jittered, 21x21", g, c);
    }
  }
  std::printf("\n1D: %d points x_k = k/%d; the %zu end points x = 0, 1 lie on the hull boundary, where the\n"
              "    derivatives do not exist numerically (J = 0): they count for e0, e1, min p only.\n"
              "2D: 2000 random points in the unit square, all interior.\n",
              kSamples1d, kSamples1d - 1, boundary_1d);
  return 0;
}

void usage(std::FILE* to) {
  std::fprintf(to,
               "usage: lme_basis_demo --out DIR\n"
               "  writes DIR/lme_basis_gamma08.csv and DIR/lme_transition.csv and prints a table of\n"
               "  consistency errors of the LME basis; plot with demos/plot_lme_basis.py DIR\n");
}

}  // namespace

int main(int argc, char** argv) {
  std::string out;
  for (int i = 1; i < argc; ++i) {
    const std::string arg = argv[i];
    if (arg == "--help" || arg == "-h") {
      usage(stdout);
      return 0;
    }
    if (arg == "--out" && i + 1 < argc) {
      out = argv[++i];
    } else if (arg.rfind("--out=", 0) == 0) {
      out = arg.substr(6);
    } else {
      std::fprintf(stderr, "lme_basis_demo: unexpected argument '%s'\n", arg.c_str());
      usage(stderr);
      return 2;
    }
  }
  if (out.empty()) {
    std::fprintf(stderr, "lme_basis_demo: --out DIR is required\n");
    usage(stderr);
    return 2;
  }
  try {
    return run(out);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "lme_basis_demo: error: %s\n", e.what());
    return 1;
  }
}
