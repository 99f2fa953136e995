// Alternate (staggered) minimization: a scene with a [staggered] table splits its unknowns into
// groups solved in turn, each with the others held, until the state stops changing — the
// phase-field fracture algorithm (u, then the damage), generic for any problem whose [model]
// outputs a minimization or a residual:
//
//   [staggered]
//   groups = [["u"], ["v"]]    # solved in this order
//   tolerance = 1e-6           # stop when no group's fields change by more than this (relative)
//   max_iterations = 200
//   relaxation = 1.0           # the largest over-relaxation of the updates (1: none; < 2)
//   anderson = 0               # Anderson acceleration over this many past rounds (0: none)
//   extrapolation = 0          # the largest stretch of a round whose change keeps growing (0: none)
//
// With `anderson`, the over-relaxation stretches the combined round instead of each group's update.
// With `extrapolation`, once the change has grown several rounds in a row (the state leaving a
// saddle, e.g. a crack that starts to run), each growing round is stretched by 2, 4, ... up to
// this factor while the energy, the first group solved again, falls.
// Each group's Newton solves read PETSc options under its unknowns' names joined by "_" as
// prefix ("v_" for ["v"]): `-v_ksp_type cg -v_pc_type hypre` sets one group's linear solver.
// Each group's solve is the problem's own stationary solve (with its bounds), the other groups'
// dofs fixed. Load steps ([steps]) take it as their stationary solve.
#include <algorithm>
#include <chrono>
#include <cmath>
#include <deque>
#include <optional>

#include <Eigen/Dense>

#include <fmt/format.h>
#include <fmt/ranges.h>

#include "lmeform/scene_table.hpp"
#include "problem_registry.hpp"
#include "stationary.hpp"

namespace lmeform::problems {

const StationaryDriver& basic_stationary_driver_for(const Scene& scene);

namespace {

inline constexpr std::string_view kStaggeredTable = "staggered";
/// The rounds in a row whose change grew before rounds are stretched ([staggered] extrapolation).
inline constexpr int kGrowingRounds = 5;

struct StaggeredSettings {
  std::vector<std::vector<std::string>> groups;
  double tolerance = 1e-6;
  int max_iterations = 200;
  double relaxation = 1.0;
  int anderson = 0;
  int extrapolation = 0;
  std::string where;
};

StaggeredSettings read_staggered(const Scene& scene) {
  const auto t = extension_table(scene, kStaggeredTable, {"groups", "tolerance", "max_iterations", "relaxation", "anderson", "extrapolation"});
  StaggeredSettings s;
  s.where = t->where("groups");
  const toml::node& n = t->require("groups");
  const auto* a = n.as_array();
  if (a == nullptr || a->size() < 2) t->fail_key("groups", "must list at least two groups of unknowns, e.g. [[\"u\"], [\"v\"]]");
  for (std::size_t i = 0; i < a->size(); ++i) {
    const auto* g = (*a)[i].as_array();
    if (g == nullptr || g->empty()) t->fail_key("groups", "entry " + std::to_string(i) + " must be a non-empty array of unknown names");
    std::vector<std::string> names;
    for (std::size_t k = 0; k < g->size(); ++k) names.push_back(t->string_of("groups[" + std::to_string(i) + "][" + std::to_string(k) + "]", (*g)[k]));
    s.groups.push_back(std::move(names));
  }
  s.tolerance = t->relative_tolerance("tolerance", t->number("tolerance", s.tolerance));
  s.max_iterations = t->at_least("max_iterations", t->integer("max_iterations", s.max_iterations), 1);
  s.relaxation = t->number("relaxation", s.relaxation);
  if (!(s.relaxation >= 1 && s.relaxation < 2)) t->fail_key("relaxation", "must lie in [1, 2): the largest factor of the updates (1: none)");
  s.anderson = t->integer("anderson", s.anderson);
  if (s.anderson < 0 || s.anderson > 20) t->fail_key("anderson", "must lie in [0, 20]: the number of past rounds the acceleration combines (0: none)");
  s.extrapolation = t->integer("extrapolation", s.extrapolation);
  if (s.extrapolation < 0 || s.extrapolation > 1024)
    t->fail_key("extrapolation", "must lie in [0, 1024]: the largest factor a growing round is stretched by (0: none)");
  if (s.extrapolation > 0 && s.extrapolation < 2)
    t->fail_key("extrapolation", "must be 0 (none) or at least 2: the largest factor a growing round is stretched by");
  if (s.extrapolation > 0 && scene.model.residual)
    t->fail_key("extrapolation", "stretches a round while the energy falls: the forms must define an energy");
  return s;
}

/// The owned dofs of a group's unknowns.
std::vector<PetscInt> group_dofs(const BoundScene& b, const ProblemSpace& space, const std::vector<std::string>& group) {
  std::vector<PetscInt> dofs;
  const int bs = b.layout.dofs_per_node;
  for (int node = space.disc->owned_begin(); node < space.disc->owned_end(); ++node)
    for (const std::string& name : group) {
      const UnknownField& f = b.unknown(name);
      for (int c = 0; c < f.components; ++c) dofs.push_back(static_cast<PetscInt>(node) * bs + f.offset + c);
    }
  std::sort(dofs.begin(), dofs.end());
  return dofs;
}

/// The largest change of a group's dofs from `before`, relative to max(1, |u|∞).
double relative_change(MPI_Comm comm, Vec u, Vec before, const std::vector<PetscInt>& dofs, PetscInt first) {
  const VecReadView now(u), old(before);
  double change = 0, size = 1;
  for (const PetscInt d : dofs) {
    change = std::max(change, std::abs(now[d - first] - old[d - first]));
    size = std::max(size, std::abs(now[d - first]));
  }
  double both[2] = {change, size};
  MPI_Allreduce(MPI_IN_PLACE, both, 2, MPI_DOUBLE, MPI_MAX, comm);
  return both[0] / both[1];
}

/// Writes `values` into u's `dofs` (global numbers, `first` the first owned one), each put within
/// [lower, max(lower, upper)] when `lower` is given.
void write_within_bounds(Vec u, Vec lower, Vec upper, const std::vector<PetscInt>& dofs, PetscInt first, const std::vector<double>& values) {
  const VecWriteView w(u);
  std::optional<VecReadView> lo, hi;
  if (lower != nullptr) lo.emplace(lower), hi.emplace(upper);
  for (std::size_t i = 0; i < dofs.size(); ++i) {
    const PetscInt d = dofs[i] - first;
    w[d] = lo ? std::clamp(values[i], (*lo)[d], std::max((*lo)[d], (*hi)[d])) : values[i];
  }
}

/// Anderson acceleration of the alternation. One round (every group solved once) maps the state of
/// the groups after the first, x, to G(x); the first group's values are a function of the others and
/// are solved again at the start of each round. From the last m rounds' x_j and f_j = G(x_j) - x_j,
/// the next start is x_k - ΔX γ + β (f_k - ΔF γ), γ minimizing |f_k - ΔF γ|, put back within the
/// bounds. The history restarts when a round's change grew: measured on the coarse SENT, keeping it
/// through growth (or through growth up to 2x) stalled the step where the crack starts for minutes;
/// restarting did not stall.
class AndersonMixer {
 public:
  AndersonMixer(MPI_Comm comm, int depth, std::vector<PetscInt> dofs, PetscInt first)
      : comm_(comm), depth_(depth), dofs_(std::move(dofs)), first_(first) {}

  /// The state's accelerated dofs at the start of a round.
  void start_round(Vec u) { x_ = values(u); }

  /// After the round: writes the next start into u, x_k - ΔX γ + β (f_k - ΔF γ) (β = 1: the
  /// combination of the rounds' results; with no history, x_k + β f_k, the over-relaxed round).
  void mix(Vec u, Vec lower, Vec upper, double beta) {
    std::vector<double> g = values(u), f(g.size());
    for (std::size_t i = 0; i < g.size(); ++i) f[i] = g[i] - x_[i];
    const double norm = std::sqrt(dot(f, f));
    if (!f_.empty() && norm > last_norm_) {
      xs_.clear();
      f_.clear();
      ++restarts_;
    }
    last_norm_ = norm;
    xs_.push_back(x_);
    f_.push_back(f);
    if (static_cast<int>(xs_.size()) > depth_ + 1) {
      xs_.pop_front();
      f_.pop_front();
    }
    const int m = static_cast<int>(xs_.size()) - 1;
    Eigen::VectorXd gamma = Eigen::VectorXd::Zero(m);
    if (m > 0) {
      // The Gram matrix of the residuals' differences and its right side, summed over ranks.
      std::vector<double> sums(static_cast<std::size_t>(m * m + m), 0.0);
      for (int a = 0; a < m; ++a) {
        for (int c = a; c < m; ++c) sums[a * m + c] = local_dot_of_differences(a, c);
        double r = 0;
        for (std::size_t i = 0; i < f.size(); ++i) r += (f_[a + 1][i] - f_[a][i]) * f[i];
        sums[m * m + a] = r;
      }
      MPI_Allreduce(MPI_IN_PLACE, sums.data(), static_cast<int>(sums.size()), MPI_DOUBLE, MPI_SUM, comm_);
      double trace = 0;
      for (int a = 0; a < m; ++a) trace += sums[a * m + a];
      // A small shift keeps the nearly dependent differences of a converging run solvable.
      const double shift = 1e-10 * std::max(trace, 1e-300);
      Eigen::MatrixXd gram(m, m);
      Eigen::VectorXd rhs(m);
      for (int a = 0; a < m; ++a) {
        for (int c = a; c < m; ++c) gram(a, c) = gram(c, a) = sums[a * m + c];
        gram(a, a) += shift;
        rhs(a) = sums[m * m + a];
      }
      gamma = gram.ldlt().solve(rhs);
      if (!gamma.allFinite()) gamma.setZero();
    }
    std::vector<double> next(g.size());
    for (std::size_t i = 0; i < g.size(); ++i) {
      double x = x_[i], r = f[i];
      for (int j = 0; j < m; ++j) {
        x -= gamma(j) * (xs_[j + 1][i] - xs_[j][i]);
        r -= gamma(j) * (f_[j + 1][i] - f_[j][i]);
      }
      next[i] = x + beta * r;
    }
    write_within_bounds(u, lower, upper, dofs_, first_, next);
    if (m > 0) ++accelerated_;
  }

  /// Drops the history: the next round starts it again.
  void forget() {
    xs_.clear();
    f_.clear();
    last_norm_ = 0;
  }

  [[nodiscard]] int restarts() const { return restarts_; }
  [[nodiscard]] int accelerated() const { return accelerated_; }

 private:
  std::vector<double> values(Vec u) const {
    const VecReadView r(u);
    std::vector<double> out(dofs_.size());
    for (std::size_t i = 0; i < dofs_.size(); ++i) out[i] = r[dofs_[i] - first_];
    return out;
  }
  double local_dot_of_differences(int a, int c) const {
    double s = 0;
    for (std::size_t i = 0; i < x_.size(); ++i) s += (f_[a + 1][i] - f_[a][i]) * (f_[c + 1][i] - f_[c][i]);
    return s;
  }
  static double local_dot(const std::vector<double>& a, const std::vector<double>& b) {
    double s = 0;
    for (std::size_t i = 0; i < a.size(); ++i) s += a[i] * b[i];
    return s;
  }
  double dot(const std::vector<double>& a, const std::vector<double>& b) const {
    double s = local_dot(a, b);
    MPI_Allreduce(MPI_IN_PLACE, &s, 1, MPI_DOUBLE, MPI_SUM, comm_);
    return s;
  }

  MPI_Comm comm_;
  int depth_;
  std::vector<PetscInt> dofs_;
  PetscInt first_;
  std::vector<double> x_;
  std::deque<std::vector<double>> xs_, f_;
  double last_norm_ = 0;
  int restarts_ = 0, accelerated_ = 0;
};

/// Stretches a round that moved the state from `start` to u: the later groups' dofs set to
/// start + f (u − start) within the bounds, the first group solved again on each (`resolve`, false
/// when its solve fails), f a power of 2 up to `largest`. The reference is u with the first group
/// solved again (f = 1). f is doubled from 2 while the energy falls, each stretch's solve starting
/// from the last one's state: starting from the last round's factor instead took 45 % more Newton
/// steps of the first group at the step where SENT on grids breaks (the solves from far states).
/// Writes the best into u and returns its f.
template <class Resolve>
int stretch_round(const ProblemSpace& space, Vec u, Vec start, const std::vector<PetscInt>& later, PetscInt first, int largest,
                  Resolve&& resolve) {
  PetscVector best = space.primary->create_vector(), trial = space.primary->create_vector();
  LMEFORM_PETSC_CHECK(VecCopy(u, best));
  if (!resolve(static_cast<Vec>(best))) return 1;
  double best_energy = space.energy(best);
  std::vector<double> from(later.size()), move(later.size());
  {
    const VecReadView now(u), was(start);
    for (std::size_t i = 0; i < later.size(); ++i) {
      from[i] = was[later[i] - first];
      move[i] = now[later[i] - first] - from[i];
    }
  }
  // The energy after the stretch by f (the first group solved on the best state so far), or
  // nothing when its solve fails.
  auto energy_after = [&](int f) -> std::optional<double> {
    LMEFORM_PETSC_CHECK(VecCopy(best, trial));
    std::vector<double> stretched(later.size());
    for (std::size_t i = 0; i < later.size(); ++i) stretched[i] = from[i] + f * move[i];
    write_within_bounds(trial, space.bounded() ? static_cast<Vec>(space.lower_bound) : nullptr,
                        space.bounded() ? static_cast<Vec>(space.upper_bound) : nullptr, later, first, stretched);
    if (!resolve(static_cast<Vec>(trial))) return std::nullopt;
    return space.energy(trial);
  };
  int kept = 1;
  auto improves = [&](int f) {
    const std::optional<double> e = energy_after(f);
    if (!e || !(*e < best_energy)) return false;
    best_energy = *e;
    kept = f;
    std::swap(best, trial);
    return true;
  };
  for (int f = 2; f <= largest && improves(f);) f *= 2;
  LMEFORM_PETSC_CHECK(VecCopy(best, u));
  return kept;
}

class StaggeredDriver final : public StationaryDriver {
 public:
  [[nodiscard]] std::string_view name() const override { return "staggered"; }
  [[nodiscard]] std::string_view table() const override { return kStaggeredTable; }
  [[nodiscard]] bool claims(const Scene& scene) const override { return scene.has_extension(kStaggeredTable); }
  [[nodiscard]] OutputRoles roles(const Scene& scene) const override {
    if (scene.model.bilinear) throw SceneError(fmt::format("{}: [staggered] alternates the solves of a minimization or a residual; this scene's "
                                                           "problem is linear",
                                                           scene.source));
    return basic_stationary_driver_for(scene).roles(scene);
  }
  void solve(MPI_Comm comm, const BoundScene& b, ProblemSpace& space, const ProblemInput& input, Vec u, ProblemResult& result) const override;
  void residual(const BoundScene& b, ProblemSpace& space, Vec u, const ProblemResult& r, Vec out) const override {
    basic_stationary_driver_for(*b.scene).residual(b, space, u, r, out);
  }
  void describe(const BoundScene& b, const ProblemResult& r, RunReport& report) const override {
    basic_stationary_driver_for(*b.scene).describe(b, r, report);
    report.row("staggered", r.message);
    for (const auto& [name, value] : r.solver_figures) report.json["staggered"][name] = json_number(value);
  }
  void check(const DriverContext& ctx) const override {
    const StaggeredSettings s = read_staggered(*ctx.scene);
    const BoundScene b = bind_scene(*ctx.scene, ctx.comm, ctx.log, *this);
    check_groups(s, b);
  }

 private:
  static void check_groups(const StaggeredSettings& s, const BoundScene& b) {
    std::vector<std::string> seen;
    for (const auto& group : s.groups)
      for (const std::string& name : group) {
        if (!b.layout.has(name)) throw SceneError(fmt::format("{}: '{}' is no unknown of the problem", s.where, name));
        if (std::find(seen.begin(), seen.end(), name) != seen.end()) throw SceneError(fmt::format("{}: '{}' is in two groups", s.where, name));
        seen.push_back(name);
      }
    for (const auto& f : b.layout.fields)
      if (std::find(seen.begin(), seen.end(), f.name) == seen.end())
        throw SceneError(fmt::format("{}: the unknown '{}' is in no group: list every unknown once", s.where, f.name));
  }
};

void StaggeredDriver::solve(MPI_Comm comm, const BoundScene& b, ProblemSpace& space, const ProblemInput& input, Vec u,
                            ProblemResult& result) const {
  const StaggeredSettings s = read_staggered(*b.scene);
  check_groups(s, b);
  const StationaryDriver& inner = basic_stationary_driver_for(*b.scene);
  const std::vector<PetscInt> prescribed = space.fixed;
  std::vector<std::vector<PetscInt>> dofs;
  for (const auto& g : s.groups) dofs.push_back(group_dofs(b, space, g));
  const PetscInt first = static_cast<PetscInt>(space.disc->owned_begin()) * b.layout.dofs_per_node;
  PetscVector before = space.primary->create_vector();
  int iterations = 0, inner_iterations = 0;
  // Per group: Newton steps, assembly seconds (every assembler's clocks) and wall seconds.
  std::vector<int> group_newton(s.groups.size(), 0);
  std::vector<double> group_assembly(s.groups.size(), 0.0), group_wall(s.groups.size(), 0.0);
  auto assembly_seconds = [&space] {
    double t = 0;
    for (const auto& [label, a] : space.assemblers) t += a->totals().create_matrix + a->totals().value + a->totals().vector + a->totals().matrix;
    return t;
  };
  double change = 0, last_change = -1, omega = 1.0;
  bool converged = false;
  std::string failure;
  // The dofs of every group after the first: the state the first group's solve is a function of.
  std::vector<PetscInt> later;
  for (std::size_t g = 1; g < dofs.size(); ++g) later.insert(later.end(), dofs[g].begin(), dofs[g].end());
  std::sort(later.begin(), later.end());
  std::optional<AndersonMixer> anderson;
  if (s.anderson > 0) anderson.emplace(comm, s.anderson, later, first);
  // The prefix is the space's for this solve only: cleared on the way out, a throw included.
  std::vector<std::string> prefixes;
  for (const auto& g : s.groups) prefixes.push_back(fmt::format("{}_", fmt::join(g, "_")));
  struct PrefixReset {
    ProblemSpace& space;
    ~PrefixReset() { space.solver_options_prefix.clear(); }
  } prefix_reset{space};
  // One group's stationary solve on x, the other groups' dofs held with the prescribed ones.
  auto solve_group = [&](std::size_t g, Vec x) {
    space.fixed = prescribed;
    for (std::size_t h = 0; h < s.groups.size(); ++h)
      if (h != g) space.fixed.insert(space.fixed.end(), dofs[h].begin(), dofs[h].end());
    std::sort(space.fixed.begin(), space.fixed.end());
    space.fixed.erase(std::unique(space.fixed.begin(), space.fixed.end()), space.fixed.end());
    ProblemResult part;
    const double assembly_before = assembly_seconds();
    const auto started = std::chrono::steady_clock::now();
    space.solver_options_prefix = prefixes[g];
    inner.solve(comm, b, space, input, x, part);
    group_wall[g] += std::chrono::duration<double>(std::chrono::steady_clock::now() - started).count();
    group_assembly[g] += assembly_seconds() - assembly_before;
    group_newton[g] += part.iterations;
    inner_iterations += part.iterations;
    return part;
  };
  PetscVector round_start = space.primary->create_vector();
  int extrapolated = 0, growing = 0;
  bool escaping = false;
  for (; iterations < s.max_iterations && !converged && failure.empty(); ++iterations) {
    change = 0;
    if (anderson) anderson->start_round(u);
    if (s.extrapolation > 0) LMEFORM_PETSC_CHECK(VecCopy(u, round_start));
    for (std::size_t g = 0; g < s.groups.size() && failure.empty(); ++g) {
      LMEFORM_PETSC_CHECK(VecCopy(u, before));
      const ProblemResult part = solve_group(g, u);
      if (!part.converged) failure = fmt::format("the solve of group {} ({}) did not converge: {}", g, fmt::join(s.groups[g], ", "), part.message);
      // Over-relaxation: the update stretched by ω, then put back within the bounds (the other
      // groups' and the prescribed dofs did not move, so they stay).
      if (omega != 1.0 && !anderson && failure.empty()) {
        LMEFORM_PETSC_CHECK(VecAXPBY(u, 1.0 - omega, omega, before));
        if (space.bounded()) {
          LMEFORM_PETSC_CHECK(VecPointwiseMax(u, u, space.lower_bound));
          LMEFORM_PETSC_CHECK(VecPointwiseMin(u, u, space.upper_bound));
        }
      }
      change = std::max(change, relative_change(comm, u, before, dofs[g], first));
      result.minimization = part.minimization;
      result.active_lower = part.active_lower;
      result.active_upper = part.active_upper;
    }
    converged = failure.empty() && change <= s.tolerance;
    const bool grew = last_change > 0 && change > last_change;
    growing = grew ? growing + 1 : 0;
    escaping = escaping || growing >= kGrowingRounds;
    // The alternation is a fixed-point iteration whose changes fall by ρ per round; stretched by
    // ω = 1/(1 − ρ) its slow mode would vanish in one. Measured on the coarse SENT: a fixed ω = 1.5
    // cut the alternations of the steps where the crack runs 2.6-fold but raised those of the
    // quiet steps (ρ ≈ 0) from 2 to 12, so ω follows ρ, within [1, relaxation].
    if (s.relaxation != 1.0 && last_change > 0) {
      const double rho = std::clamp(change / last_change, 0.0, 0.95);
      omega = std::clamp(1.0 / (1.0 - rho), 1.0, s.relaxation);
    }
    last_change = change;
    // Rounds whose change keeps growing leave a fixed point that is not a minimum (a crack that
    // starts to run): Anderson's combination would lead back to it, and plain rounds leave it by a
    // small factor per round (the step where SENT on grids breaks: 962 rounds, two in three of the
    // first 318 growing, by 0.09 % in the median). The round's move of the later groups is
    // stretched instead, the first group solved again for each stretch, while the energy falls.
    // Shorter runs of growth are left to Anderson, which restarts there: in the steps before the
    // break (30-60 rounds each) they are at most 4 long, and stretching from the second growing
    // round on made those steps 28 % slower; the crawl grows for hundreds of rounds in a row. Once
    // a run has reached kGrowingRounds, every growing round of the solve is stretched: a stretch
    // ends the run it follows, and waiting for the next run of that length took the break 1.7
    // times the rounds.
    int stretch = 1;
    const bool stretching = s.extrapolation > 0 && escaping && grew && failure.empty() && !converged;
    if (stretching) {
      stretch = stretch_round(space, u, round_start, later, first, s.extrapolation, [&](Vec x) { return solve_group(0, x).converged; });
      if (stretch > 1) ++extrapolated;
    }
    if (anderson && failure.empty() && !converged) {
      if (stretch > 1)
        anderson->forget();
      else  // With Anderson acceleration the stretch ω applies to the combined round instead.
        anderson->mix(u, space.bounded() ? static_cast<Vec>(space.lower_bound) : nullptr,
                      space.bounded() ? static_cast<Vec>(space.upper_bound) : nullptr, omega);
    }
    if (b.scene->solver.monitor && input.log != nullptr)
      *input.log << fmt::format("    round {}: change {:.3e}, omega {:.3f}{}{}\n", iterations + 1, change, omega,
                                anderson ? fmt::format(", anderson steps {}", anderson->accelerated()) : "",
                                stretching ? fmt::format(", stretched x{}", stretch) : "");
  }
  space.fixed = prescribed;
  result.solver_figures.emplace_back("alternations", double(iterations));
  if (s.extrapolation > 0) result.solver_figures.emplace_back("extrapolations", double(extrapolated));
  if (anderson) {
    result.solver_figures.emplace_back("anderson_steps", double(anderson->accelerated()));
    result.solver_figures.emplace_back("anderson_restarts", double(anderson->restarts()));
  }
  for (std::size_t g = 0; g < s.groups.size(); ++g) {
    const std::string name = fmt::format("{}", fmt::join(s.groups[g], "+"));
    result.solver_figures.emplace_back(name + "_newton", double(group_newton[g]));
    result.solver_figures.emplace_back(name + "_assembly_s", group_assembly[g]);
    result.solver_figures.emplace_back(name + "_solve_s", group_wall[g] - group_assembly[g]);
  }
  result.converged = converged;
  result.iterations = inner_iterations;
  result.energy = space.energy_terms.empty() ? std::nan("") : space.energy(u);
  result.message = !failure.empty() ? failure
                   : converged      ? fmt::format("converged in {} iterations of the groups (last change {:.2e}, {} Newton steps)", iterations, change,
                                                  inner_iterations)
                                    : fmt::format("{} iterations of the groups without the change falling below {:.1e} (last {:.2e})", iterations,
                                                  s.tolerance, change);
}

}  // namespace

const StationaryDriver& staggered_driver() {
  static const StaggeredDriver driver;
  return driver;
}

}  // namespace lmeform::problems
