// Node-set factories: uniform grids, point files, a graded 2D set and deterministic jitter.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <string>

#include "lmeform/node_set.hpp"

namespace lmeform {

/// An axis-aligned box; only the first `dim` entries of lo/hi are used.
struct Box {
  int dim = 0;
  std::array<double, 3> lo{};
  std::array<double, 3> hi{};

  static Box unit(int dimension);
  void validate(const char* who) const;   ///< throws std::invalid_argument unless lo < hi on every axis
};

/// counts[i] >= 2 nodes per axis including both ends; x varies fastest.
[[nodiscard]] NodeSet uniform_grid(const Box& box, std::array<int, 3> counts);

/// Axis i gets round(L_i / spacing) + 1 nodes (at least 2); the spacing is stretched to fit exactly.
[[nodiscard]] NodeSet uniform_grid(const Box& box, double spacing);

/// Reads one point per line: numbers separated by commas, semicolons, spaces or tabs. Blank lines and
/// lines starting with '#' are skipped. dim = 0 takes the dimension from the first point.
/// A bad line throws std::runtime_error "<file>:<line>: <what is wrong>".
/// With `domain`, a point outside it (beyond 1e-9 of its extent) is an error naming its line.
[[nodiscard]] NodeSet read_points(const std::filesystem::path& path, int dim = 0, const Box* domain = nullptr);

class Domain;
/// The same, every point checked against a polygon or polyhedron (beyond 1e-9 of its diameter).
[[nodiscard]] NodeSet read_points(const std::filesystem::path& path, int dim, const Domain& domain);

/// Writes one point per line, comma separated, with round-trip precision (17 significant digits).
void write_points(const std::filesystem::path& path, const NodeSet& nodes);

/// A strongly graded 2D node set, resembling the CVT grids adapted to a phase-field interface
/// (seed Table B.6): the target spacing is h_min on the circle (center, radius) and grows smoothly
/// (C^1 smoothstep over `transition` in distance) to h_max away from it.
/// Boundary nodes are spaced by the target spacing along each side, the four corners included;
/// interior nodes are a greedy variable-radius Poisson-disk sample of a fine candidate lattice
/// (a candidate is taken when no node is closer than the local target spacing), so the nearest-
/// neighbour distance follows h(x) within a factor of about two. Deterministic for a given seed.
struct GradedGridOptions {
  Box box = Box::unit(2);
  double h_min = 0.01;
  double h_max = 0.12;
  std::array<double, 2> center{0.5, 0.5};
  double radius = 0.3;
  double transition = 0.2;
  std::uint64_t seed = 1;
};
[[nodiscard]] NodeSet graded_grid_2d(const GradedGridOptions& options = {});

/// The target spacing of graded_grid_2d at x.
[[nodiscard]] double graded_spacing(const GradedGridOptions& options, double x, double y);

/// The hardest grading for LME point lists: a fine uniform strip (spacing 0.02, 0 <= x <= 0.1)
/// beside coarse uniform nodes (spacing 0.2, 0.3 <= x <= 0.9) on 0 <= y <= 1, nothing between.
/// At gamma 4 the fine supports end short of the gap, and many points of the long cells spanning
/// it lie outside the hull of the nodes whose supports reach them.
[[nodiscard]] NodeSet fine_strip_beside_coarse_nodes();

/// Moves every node that is not on a face of the box (tolerance: 1e-12 * box diagonal) by a uniform
/// random offset in [-amplitude, amplitude] per coordinate, clamped to stay inside the box.
/// Deterministic: the same seed gives the same nodes on every platform (own generator, no std:: distributions).
[[nodiscard]] NodeSet jitter_interior(const NodeSet& nodes, const Box& box, double amplitude, std::uint64_t seed);

/// A deterministic, platform-independent generator (splitmix64) for tests: uniform doubles in [0, 1).
class SplitMix64 {
 public:
  explicit SplitMix64(std::uint64_t seed) : state_(seed) {}
  std::uint64_t next() noexcept {
    std::uint64_t z = (state_ += 0x9e3779b97f4a7c15ULL);
    z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ULL;
    z = (z ^ (z >> 27)) * 0x94d049bb133111ebULL;
    return z ^ (z >> 31);
  }
  double uniform() noexcept { return static_cast<double>(next() >> 11) * 0x1.0p-53; }

 private:
  std::uint64_t state_;
};

/// n uniformly random points in the box (deterministic for a given seed).
[[nodiscard]] NodeSet random_points(const Box& box, std::size_t n, std::uint64_t seed);

}  // namespace lmeform
