#include "saddle_point.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <map>
#include <memory>
#include <set>

#include <Eigen/Dense>
#include <fmt/format.h>
#include <fmt/ranges.h>

#include "expressions.hpp"
#include "linear_system.hpp"
#include "lmeform/stopwatch.hpp"
#include "lmeform/symmetric_factorization.hpp"
#include "minimization.hpp"
#include "problem_registry.hpp"
#include "stationary.hpp"

namespace lmeform::problems {

void bind_saddle_point(const Scene& scene, BoundScene& b) {
  for (const SceneName& m : scene.model.maximize) {
    if (!b.layout.has(m.name)) {
      std::vector<std::string> names;
      for (const auto& u : b.layout.fields) names.push_back(u.name);
      throw SceneError(fmt::format("{}: '{}' is no unknown of the problem{} (unknowns: {})", m.where, m.name, did_you_mean(m.name, names),
                                   fmt::join(names, ", ")));
    }
    if (std::find(b.maximize.begin(), b.maximize.end(), m.name) != b.maximize.end())
      throw SceneError(fmt::format("{}: '{}' is listed twice", m.where, m.name));
    b.maximize.push_back(m.name);
  }
  if (!b.maximize.empty() && b.maximize.size() == b.layout.fields.size())
    throw SceneError(fmt::format("{}: every unknown is maximized: that is the minimization of minus the energy, not a saddle point "
                                 "(list the unknowns the energy is maximized over, not all)",
                                 scene.model.maximize.front().where));
  if (!b.maximize.empty() && !scene.constraints.empty())
    throw SceneError(fmt::format("{}: [constraints] and model.maximize together are not supported (the saddle-point driver has no "
                                 "multipliers of global constraints)",
                                 scene.constraints.front().where));
  if (!b.maximize.empty() && !b.bounds.empty())
    throw SceneError(fmt::format("{}: [bounds] and model.maximize together are not supported", b.bounds.front().where));
  for (const SceneEquipotential& e : scene.equipotentials) {
    if (b.maximize.empty())
      throw SceneError(fmt::format("{}: [[equipotential]] parts are solved by saddle-point problems (model.maximize, e.g. an electric "
                                   "enthalpy) only; this scene is a {} problem",
                                   e.where, b.solver != nullptr ? std::string(b.solver->name()) : std::string("different")));
    if (!b.layout.has(e.unknown)) {
      std::vector<std::string> names;
      for (const auto& u : b.layout.fields) names.push_back(u.name);
      throw SceneError(fmt::format("{}: key 'unknown': '{}' is no unknown of the problem{} (unknowns: {})", e.where, e.unknown,
                                   did_you_mean(e.unknown, names), fmt::join(names, ", ")));
    }
    const UnknownField& field = b.unknown(e.unknown);
    if (field.components != 1)
      throw SceneError(fmt::format("{}: key 'unknown': '{}' has {} components; an equipotential part holds a scalar unknown", e.where,
                                   e.unknown, field.components));
    for (const BoundDirichlet& d : b.dirichlet) {
      if (d.field.name != e.unknown) continue;
      for (const auto& part : e.boundary)
        if (std::find(d.parts.begin(), d.parts.end(), part) != d.parts.end())
          throw SceneError(fmt::format("{}: part '{}' is also held by {} of '{}': an equipotential part's value is unknown, a Dirichlet "
                                       "part's is given (give one of them)",
                                       e.where, part, d.where, e.unknown));
    }
    b.equipotentials.push_back({e.boundary, field, e.charge, e.name, e.where});
  }
}

std::vector<EquipotentialGroup> equipotential_groups(const BoundScene& b, const ProblemSpace& space) {
  std::vector<EquipotentialGroup> groups;
  const Discretization& disc = *space.disc;
  const auto renumbered = disc.renumbered_index();
  const int bs = b.layout.dofs_per_node;
  std::map<std::pair<int, int>, std::string> taken;  // (node, dof) -> the entry holding it
  for (const auto& [node, dof] : space.fixed_pairs) taken[{node, dof}] = "a [[dirichlet]] entry";
  for (const BoundEquipotential& e : b.equipotentials) {
    EquipotentialGroup g;
    g.entry = &e;
    std::set<int> nodes;
    for (const auto& part : e.parts)
      for (const int n : boundary_nodes(b.geometry, space.nodes, part)) nodes.insert(n);
    if (nodes.empty()) throw SceneError(fmt::format("{}: no node lies on its parts ({})", e.where, fmt::join(e.parts, ", ")));
    g.nodes.assign(nodes.begin(), nodes.end());
    for (const int n : g.nodes) {
      const auto [it, fresh] = taken.emplace(std::pair{n, e.field.offset}, e.where);
      if (!fresh)
        throw SceneError(fmt::format("{}: the node ({}) on its parts is also held by {}: a node can follow one equipotential part or "
                                     "take a prescribed value, not both (leave the shared corner to one of the entries)",
                                     e.where, fmt::join(space.nodes.point(std::size_t(n)), ", "), it->second));
    }
    PetscInt master = std::numeric_limits<PetscInt>::max();
    for (const int n : g.nodes) {
      const PetscInt dof = static_cast<PetscInt>(renumbered[std::size_t(n)]) * bs + e.field.offset;
      g.dofs.push_back(dof);
      master = std::min(master, dof);
    }
    g.master_dof = master;
    groups.push_back(std::move(g));
  }
  return groups;
}

void add_equipotential_quantities(const BoundScene& b, ProblemSpace& space, Vec u, Vec residual, QuantityValues& out) {
  if (b.equipotentials.empty()) return;
  const Discretization& disc = *space.disc;
  const int bs = b.layout.dofs_per_node;
  const PetscInt first = static_cast<PetscInt>(disc.owned_begin()) * bs, end = static_cast<PetscInt>(disc.owned_end()) * bs;
  const VecReadView state(u), r(residual);
  for (const EquipotentialGroup& g : equipotential_groups(b, space)) {
    double sums[2] = {0, 0};  // the master's value, Σ residual
    for (const PetscInt dof : g.dofs) {
      if (dof < first || dof >= end) continue;
      sums[1] += r[dof - first];
      if (dof == g.master_dof) sums[0] = state[dof - first];
    }
    MPI_Allreduce(MPI_IN_PLACE, sums, 2, MPI_DOUBLE, MPI_SUM, disc.comm());
    out.emplace_back(g.entry->name + "_potential", sums[0]);
    out.emplace_back(g.entry->name + "_charge", 0.0 - sums[1]);
  }
}

namespace {

/// The dof each dof follows: its group's master, else itself.
std::map<PetscInt, PetscInt> followed_dofs(const std::vector<EquipotentialGroup>& groups) {
  std::map<PetscInt, PetscInt> follows;
  for (const auto& g : groups)
    for (const PetscInt dof : g.dofs)
      if (dof != g.master_dof) follows[dof] = g.master_dof;
  return follows;
}

/// Pᵀ H P for the elimination matrix P below, summed entry by entry: row and column i of H go to
/// the dof i follows (PETSc's general MatPtAP spent 3.9 s of a 6.7 s solve in its symbolic phase
/// on 6000 unknowns for this near-identity P). Every row is summed here and inserted once, sorted
/// and exactly preallocated; a follower's row whose master another rank owns goes through PETSc's
/// stash. The followers' rows and columns stay empty but for a unit diagonal.
PetscMatrix reduced_matrix(MPI_Comm comm, Mat H, const std::map<PetscInt, PetscInt>& follows) {
  PetscInt begin = 0, end = 0, n = 0;
  LMEFORM_PETSC_CHECK(MatGetOwnershipRange(H, &begin, &end));
  LMEFORM_PETSC_CHECK(MatGetSize(H, &n, nullptr));
  const PetscInt local = end - begin;
  auto target = [&](PetscInt i) {
    const auto it = follows.find(i);
    return it == follows.end() ? i : it->second;
  };
  std::vector<std::map<PetscInt, PetscScalar>> rows(static_cast<std::size_t>(local));
  std::vector<std::pair<PetscInt, std::map<PetscInt, PetscScalar>>> remote;  // rows of masters other ranks own
  PetscInt largest_remote = 0;
  for (PetscInt row = begin; row < end; ++row) {
    PetscInt ncols = 0;
    const PetscInt* cols = nullptr;
    const PetscScalar* values = nullptr;
    LMEFORM_PETSC_CHECK(MatGetRow(H, row, &ncols, &cols, &values));
    const PetscInt to = target(row);
    std::map<PetscInt, PetscScalar>* sum = nullptr;
    if (to >= begin && to < end) {
      sum = &rows[static_cast<std::size_t>(to - begin)];
    } else {
      remote.emplace_back(to, std::map<PetscInt, PetscScalar>{});
      sum = &remote.back().second;
    }
    for (PetscInt j = 0; j < ncols; ++j) (*sum)[target(cols[j])] += values[j];
    LMEFORM_PETSC_CHECK(MatRestoreRow(H, row, &ncols, &cols, &values));
    if (sum != nullptr && !(to >= begin && to < end)) largest_remote = std::max(largest_remote, static_cast<PetscInt>(sum->size()));
  }
  // Rows that receive remote contributions may grow by their size: bound them by the largest.
  PetscInt remote_rows = static_cast<PetscInt>(remote.size());
  MPI_Allreduce(MPI_IN_PLACE, &largest_remote, 1, MPIU_INT, MPI_MAX, comm);
  MPI_Allreduce(MPI_IN_PLACE, &remote_rows, 1, MPIU_INT, MPI_SUM, comm);
  std::set<PetscInt> masters;
  for (const auto& [follower, master] : follows) masters.insert(master);
  std::vector<PetscInt> d_nnz(rows.size()), o_nnz(rows.size());
  for (std::size_t i = 0; i < rows.size(); ++i) {
    PetscInt d = 0, o = 0;
    for (const auto& [c, v] : rows[i]) (c >= begin && c < end ? d : o) += 1;
    const bool followed = masters.contains(begin + static_cast<PetscInt>(i));
    const PetscInt extra = followed && remote_rows > 0 ? largest_remote : 0;
    d_nnz[i] = std::min(std::max<PetscInt>(d, 1) + extra, local);
    o_nnz[i] = std::min(o + extra, n - local);
  }
  PetscMatrix A;
  LMEFORM_PETSC_CHECK(MatCreateAIJ(comm, local, local, n, n, 0, d_nnz.data(), 0, o_nnz.data(), A.out()));
  LMEFORM_PETSC_CHECK(MatSetOption(A, MAT_NEW_NONZERO_ALLOCATION_ERR, PETSC_FALSE));
  std::vector<PetscInt> cols;
  std::vector<PetscScalar> values;
  auto insert = [&](PetscInt row, const std::map<PetscInt, PetscScalar>& sum) {
    cols.clear();
    values.clear();
    for (const auto& [c, v] : sum) {
      cols.push_back(c);
      values.push_back(v);
    }
    if (!cols.empty())
      LMEFORM_PETSC_CHECK(MatSetValues(A, 1, &row, static_cast<PetscInt>(cols.size()), cols.data(), values.data(), ADD_VALUES));
  };
  for (std::size_t i = 0; i < rows.size(); ++i) {
    const PetscInt row = begin + static_cast<PetscInt>(i);
    if (rows[i].empty()) rows[i][row] = 0.0;  // a follower's row: its diagonal, set to 1 with the Dirichlet rows
    insert(row, rows[i]);
  }
  for (const auto& [row, sum] : remote) insert(row, sum);
  LMEFORM_PETSC_CHECK(MatAssemblyBegin(A, MAT_FINAL_ASSEMBLY));
  LMEFORM_PETSC_CHECK(MatAssemblyEnd(A, MAT_FINAL_ASSEMBLY));
  return A;
}

/// P with u = P û: the identity, except that the dof of every node of an equipotential group
/// follows the group's master (P[i, master] = 1, column i empty).
PetscMatrix elimination_matrix(MPI_Comm comm, Mat like, const std::vector<EquipotentialGroup>& groups) {
  PetscInt begin = 0, end = 0, n = 0;
  LMEFORM_PETSC_CHECK(MatGetOwnershipRange(like, &begin, &end));
  LMEFORM_PETSC_CHECK(MatGetSize(like, &n, nullptr));
  std::map<PetscInt, PetscInt> follows;
  for (const auto& g : groups)
    for (const PetscInt dof : g.dofs) follows[dof] = g.master_dof;
  PetscMatrix P;
  LMEFORM_PETSC_CHECK(MatCreateAIJ(comm, end - begin, end - begin, n, n, 1, nullptr, 1, nullptr, P.out()));
  for (PetscInt row = begin; row < end; ++row) {
    const auto it = follows.find(row);
    LMEFORM_PETSC_CHECK(MatSetValue(P, row, it == follows.end() ? row : it->second, 1.0, INSERT_VALUES));
  }
  LMEFORM_PETSC_CHECK(MatAssemblyBegin(P, MAT_FINAL_ASSEMBLY));
  LMEFORM_PETSC_CHECK(MatAssemblyEnd(P, MAT_FINAL_ASSEMBLY));
  return P;
}

/// One candidate null mode of the Hessian: a field's constant, or a rigid motion of a vector
/// field with one component per dimension.
struct CandidateMode {
  std::string description;
  std::string field;
  bool vector = false;
  PetscVector values;
};

std::vector<CandidateMode> candidate_modes(const BoundScene& b, const ProblemSpace& space, Vec like) {
  const Discretization& disc = *space.disc;
  const int bs = b.layout.dofs_per_node, dim = b.dim;
  // Rotations about the centroid, scaled to 1 at the farthest node: entries of order one.
  std::array<double, 3> centre{0, 0, 0};
  for (std::size_t a = 0; a < space.nodes.size(); ++a)
    for (int i = 0; i < dim; ++i) centre[std::size_t(i)] += space.nodes.point(a)[std::size_t(i)] / static_cast<double>(space.nodes.size());
  double radius = 0;
  for (std::size_t a = 0; a < space.nodes.size(); ++a) {
    double r2 = 0;
    for (int i = 0; i < dim; ++i) r2 += std::pow(space.nodes.point(a)[std::size_t(i)] - centre[std::size_t(i)], 2);
    radius = std::max(radius, std::sqrt(r2));
  }
  static const char* const axis[] = {"x", "y", "z"};
  std::vector<CandidateMode> modes;
  auto add = [&](std::string description, const UnknownField& f, bool vector, auto&& value /* (node, component) */) {
    CandidateMode m{std::move(description), f.name, vector, {}};
    LMEFORM_PETSC_CHECK(VecDuplicate(like, m.values.out()));
    LMEFORM_PETSC_CHECK(VecSet(m.values, 0.0));
    {
      VecWriteView v(m.values);
      for (int r = disc.owned_begin(); r < disc.owned_end(); ++r)
        for (int c = 0; c < f.components; ++c) v[(r - disc.owned_begin()) * bs + f.offset + c] = value(r, c);
    }
    modes.push_back(std::move(m));
  };
  for (const UnknownField& f : b.layout.fields) {
    if (f.components == 1) {
      add(fmt::format("a constant added to {}", f.name), f, false, [](int, int) { return 1.0; });
      continue;
    }
    if (f.components != dim || b.axisymmetric) continue;
    for (int i = 0; i < dim; ++i)
      add(fmt::format("a rigid translation of {} along {}", f.name, axis[i]), f, true, [i](int, int c) { return c == i ? 1.0 : 0.0; });
    // Rotations ω × (x − centre) with ω along each axis (2D: the out-of-plane one).
    for (int w = dim == 2 ? 2 : 0; w < 3; ++w) {
      add(fmt::format("a rigid rotation of {}{}", f.name, dim == 3 ? fmt::format(" about {}", axis[w]) : std::string()), f, true,
          [&, w](int r, int c) {
            const auto x = disc.nodes().point(std::size_t(r));
            std::array<double, 3> d{0, 0, 0};
            for (int i = 0; i < dim; ++i) d[std::size_t(i)] = (x[std::size_t(i)] - centre[std::size_t(i)]) / radius;
            std::array<double, 3> omega{0, 0, 0};
            omega[std::size_t(w)] = 1;
            const std::array<double, 3> v{omega[1] * d[2] - omega[2] * d[1], omega[2] * d[0] - omega[0] * d[2], omega[0] * d[1] - omega[1] * d[0]};
            return v[std::size_t(c)];
          });
    }
  }
  return modes;
}

/// Refuses, before any factorization, a Hessian whose null modes no Dirichlet value, zero-mean
/// condition or equipotential charge holds: the constant of a potential with no grounded part and
/// no zero mean, a rigid motion of a displacement that no support prevents. Each candidate mode
/// m is null when |H m| is round-off against the diagonal of its field; the null modes' span is
/// held when its values at the fixed dofs (and its means) have full rank.
void refuse_unheld_null_modes(const BoundScene& b, const ProblemSpace& space, Mat H, std::span<const Vec> mean_functionals) {
  PetscVector like;
  LMEFORM_PETSC_CHECK(MatCreateVecs(H, like.out(), nullptr));
  std::vector<CandidateMode> modes = candidate_modes(b, space, like);
  const auto k = static_cast<Eigen::Index>(modes.size());
  if (k == 0) return;
  const Discretization& disc = *space.disc;
  const int bs = b.layout.dofs_per_node;
  // The scale of each field: the largest diagonal entry of its rows.
  PetscVector diagonal;
  LMEFORM_PETSC_CHECK(VecDuplicate(like, diagonal.out()));
  LMEFORM_PETSC_CHECK(MatGetDiagonal(H, diagonal));
  std::map<std::string, double> scale;
  {
    const VecReadView d(diagonal);
    for (const UnknownField& f : b.layout.fields) {
      double s = 0;
      for (PetscInt r = 0; r < disc.n_owned(); ++r)
        for (int c = 0; c < f.components; ++c) s = std::max(s, std::abs(d[r * bs + f.offset + c]));
      MPI_Allreduce(MPI_IN_PLACE, &s, 1, MPI_DOUBLE, MPI_MAX, disc.comm());
      scale[f.name] = s > 0 ? s : 1.0;
    }
  }
  std::vector<PetscVector> hm(modes.size());
  for (std::size_t j = 0; j < modes.size(); ++j) {
    LMEFORM_PETSC_CHECK(VecDuplicate(like, hm[j].out()));
    LMEFORM_PETSC_CHECK(MatMult(H, modes[j].values, hm[j]));
    LMEFORM_PETSC_CHECK(VecScale(hm[j], 1.0 / scale[modes[j].field]));
  }
  // Each mode's own size (its 2-norm): |H m| / |m| against the field's diagonal.
  Eigen::MatrixXd gram(k, k);
  for (Eigen::Index i = 0; i < k; ++i) {
    PetscReal ni = 0;
    LMEFORM_PETSC_CHECK(VecNorm(modes[std::size_t(i)].values, NORM_2, &ni));
    for (Eigen::Index j = 0; j <= i; ++j) {
      PetscReal nj = 0;
      LMEFORM_PETSC_CHECK(VecNorm(modes[std::size_t(j)].values, NORM_2, &nj));
      PetscScalar d = 0;
      LMEFORM_PETSC_CHECK(VecDot(hm[std::size_t(i)], hm[std::size_t(j)], &d));
      gram(i, j) = gram(j, i) = d / (ni * nj);
    }
  }
  // Null combinations: |H m| below 1e-9 of the diagonal (round-off is 1e-14 or less; the weakest
  // support measured, a foundation a millionth as stiff as the body, is 1e-7 or more).
  const Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> null_space(gram);
  std::vector<Eigen::VectorXd> null;
  for (Eigen::Index i = 0; i < k; ++i)
    if (null_space.eigenvalues()(i) < 1e-18) null.push_back(null_space.eigenvectors().col(i));
  if (null.empty()) return;
  // Their values at the fixed dofs and their means: what holds them.
  const auto z = static_cast<Eigen::Index>(null.size());
  Eigen::MatrixXd held = Eigen::MatrixXd::Zero(z, z);
  std::vector<std::vector<double>> at_fixed(null.size());
  {
    std::vector<std::unique_ptr<VecReadView>> views;
    for (const auto& m : modes) views.push_back(std::make_unique<VecReadView>(m.values));
    const PetscInt first = static_cast<PetscInt>(disc.owned_begin()) * bs;
    for (const PetscInt dof : space.fixed) {
      Eigen::VectorXd v(z);
      for (Eigen::Index a = 0; a < z; ++a) {
        double s = 0;
        for (Eigen::Index j = 0; j < k; ++j) s += null[std::size_t(a)](j) * (*views[std::size_t(j)])[dof - first];
        v(a) = s;
      }
      held += v * v.transpose();
    }
  }
  MPI_Allreduce(MPI_IN_PLACE, held.data(), static_cast<int>(held.size()), MPI_DOUBLE, MPI_SUM, disc.comm());
  for (const Vec c : mean_functionals) {
    PetscScalar total = 0;
    PetscVector one;
    LMEFORM_PETSC_CHECK(VecDuplicate(c, one.out()));
    LMEFORM_PETSC_CHECK(VecSet(one, 1.0));
    LMEFORM_PETSC_CHECK(VecDot(c, one, &total));
    Eigen::VectorXd v(z);
    for (Eigen::Index a = 0; a < z; ++a) {
      double s = 0;
      for (Eigen::Index j = 0; j < k; ++j) {
        PetscScalar d = 0;
        LMEFORM_PETSC_CHECK(VecDot(c, modes[std::size_t(j)].values, &d));
        s += null[std::size_t(a)](j) * d;
      }
      v(a) = s / std::abs(total);
    }
    held += v * v.transpose();
  }
  const Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> free_modes(held);
  std::vector<std::string> unheld, fixes;
  for (Eigen::Index a = 0; a < z; ++a) {
    if (free_modes.eigenvalues()(a) > 1e-12) continue;
    Eigen::VectorXd combination = Eigen::VectorXd::Zero(k);
    for (Eigen::Index i = 0; i < z; ++i) combination += free_modes.eigenvectors()(i, a) * null[std::size_t(i)];
    const double largest = combination.cwiseAbs().maxCoeff();
    std::vector<std::string> parts;
    for (Eigen::Index j = 0; j < k; ++j) {
      if (std::abs(combination(j)) < 0.2 * largest) continue;
      const CandidateMode& m = modes[std::size_t(j)];
      parts.push_back(m.description);
      const std::string fix =
          m.vector ? fmt::format("hold {} against rigid motion: [[dirichlet]] entries on enough components (a clamped part, or the normal "
                                 "components on two parts that are not parallel), or a support energy",
                                 m.field)
                   : fmt::format("hold {} on a part (a [[dirichlet]] entry: a grounded electrode) or fix its level with model.zero_mean = "
                                 "[\"{}\"]",
                                 m.field, m.field);
      if (std::find(fixes.begin(), fixes.end(), fix) == fixes.end()) fixes.push_back(fix);
    }
    unheld.push_back(fmt::format("{}", fmt::join(parts, " with ")));
  }
  if (unheld.empty()) return;
  throw SceneError(fmt::format("{}: the saddle-point system is singular: the energy does not change under {}, and nothing holds {}; {}",
                               b.source, fmt::join(unheld, "; under "), unheld.size() == 1 ? "it" : "them", fmt::join(fixes, "; ")));
}

/// c_a = ∫ N_a dx at the dofs of a zero-mean field (0 elsewhere).
PetscVector mean_functional(MPI_Comm comm, const BoundScene& b, const ProblemSpace& space, const UnknownField& f, std::ostream* log) {
  const Discretization& disc = *space.disc;
  const int bs = b.layout.dofs_per_node;
  const FormModule& integral = compile_integral_form(b.dim, comm, log);
  Assembler integral_form(disc, integral.at("integral", b.dim));
  PetscVector one = integral_form.create_vector(), weights = integral_form.create_vector();
  LMEFORM_PETSC_CHECK(VecSet(one, 1.0));
  integral_form.vector(one, weights);
  PetscVector c = space.primary->create_vector();
  LMEFORM_PETSC_CHECK(VecSet(c, 0.0));
  {
    const VecReadView w(weights);
    VecWriteView cv(c);
    for (PetscInt i = 0; i < w.size(); ++i) cv[i * bs + f.offset] = w[i];
  }
  return c;
}

class SaddlePointDriver final : public StationaryDriver {
 public:
  [[nodiscard]] std::string_view name() const override { return "saddle point"; }
  [[nodiscard]] bool claims(const Scene& scene) const override { return !scene.model.maximize.empty(); }
  [[nodiscard]] OutputRoles roles(const Scene& scene) const override {
    OutputRoles r;
    r.energies = scene.model.energy;
    r.all_energies = scene.model.energy.empty();
    return r;
  }

  void solve(MPI_Comm comm, const BoundScene& b, ProblemSpace& space, const ProblemInput& input, Vec u, ProblemResult& result) const override {
    const SceneSolver& settings = b.scene->solver;
    const std::vector<EquipotentialGroup> groups = equipotential_groups(b, space);

    PetscMatrix H = space.primary->create_matrix();
    PetscMatrix P;
    if (!groups.empty()) P = elimination_matrix(comm, H, groups);
    const std::map<PetscInt, PetscInt> follows = followed_dofs(groups);
    // Rows whose step is zero: the Dirichlet dofs and the followers of a master.
    std::vector<PetscInt> eliminated(space.fixed.begin(), space.fixed.end());
    {
      PetscInt begin = 0, end = 0;
      LMEFORM_PETSC_CHECK(MatGetOwnershipRange(H, &begin, &end));
      for (const auto& g : groups)
        for (const PetscInt dof : g.dofs)
          if (dof != g.master_dof && dof >= begin && dof < end) eliminated.push_back(dof);
      std::sort(eliminated.begin(), eliminated.end());
    }
    auto reduce = [&](Vec full, Vec reduced) {  // reduced = Pᵀ full, 0 at the eliminated rows
      if (P) LMEFORM_PETSC_CHECK(MatMultTranspose(P, full, reduced));
      else LMEFORM_PETSC_CHECK(VecCopy(full, reduced));
      LMEFORM_PETSC_CHECK(VecSetValues(reduced, static_cast<PetscInt>(eliminated.size()), eliminated.data(),
                                       std::vector<PetscScalar>(eliminated.size(), 0.0).data(), INSERT_VALUES));
      LMEFORM_PETSC_CHECK(VecAssemblyBegin(reduced));
      LMEFORM_PETSC_CHECK(VecAssemblyEnd(reduced));
    };
    auto expand = [&](Vec reduced, Vec full) {  // full = P reduced
      if (P) LMEFORM_PETSC_CHECK(MatMult(P, reduced, full));
      else LMEFORM_PETSC_CHECK(VecCopy(reduced, full));
    };
    PetscVector g = space.primary->create_vector(), gr = space.primary->create_vector(), step = space.primary->create_vector();
    // The groups start at their master's value.
    if (P) {
      LMEFORM_PETSC_CHECK(VecCopy(u, gr));
      std::vector<PetscInt> followers;
      for (const PetscInt dof : eliminated)
        if (!std::binary_search(space.fixed.begin(), space.fixed.end(), dof)) followers.push_back(dof);
      LMEFORM_PETSC_CHECK(VecSetValues(gr, static_cast<PetscInt>(followers.size()), followers.data(),
                                       std::vector<PetscScalar>(followers.size(), 0.0).data(), INSERT_VALUES));
      LMEFORM_PETSC_CHECK(VecAssemblyBegin(gr));
      LMEFORM_PETSC_CHECK(VecAssemblyEnd(gr));
      expand(gr, u);
    }
    std::vector<PetscVector> means, reduced_means;
    for (const auto& name : b.zero_mean) {
      means.push_back(mean_functional(comm, b, space, b.unknown(name), input.log));
      reduced_means.push_back(space.primary->create_vector());
      reduce(means.back(), reduced_means.back());
    }
    std::vector<Vec> mean_columns;
    for (const auto& c : reduced_means) mean_columns.push_back(c);
    const auto k = static_cast<PetscInt>(means.size());

    // The gradient: Σ ∇E plus, at each group's master, its charge (the energy gains Q × its value).
    auto gradient = [&](Vec x, Vec out) {
      LMEFORM_PETSC_CHECK(VecZeroEntries(out));
      for (Assembler* term : space.energy_terms) term->add_vector(x, out, 1.0);
      PetscInt begin = 0, end = 0;
      LMEFORM_PETSC_CHECK(VecGetOwnershipRange(out, &begin, &end));
      for (const auto& grp : groups)
        if (grp.entry->charge != 0 && grp.master_dof >= begin && grp.master_dof < end)
          LMEFORM_PETSC_CHECK(VecSetValue(out, grp.master_dof, grp.entry->charge, ADD_VALUES));
      LMEFORM_PETSC_CHECK(VecAssemblyBegin(out));
      LMEFORM_PETSC_CHECK(VecAssemblyEnd(out));
    };

    result.expected_negative_eigenvalues = expected_negative(b, space, groups);
    SymmetricFactorization factorization(comm, "saddle_");
    factorization.set_log(input.log);
    double first_norm = -1, norm = 0, previous_norm = 0;
    bool round_off_floor = false;
    std::vector<double> multipliers(std::size_t(k), 0.0);
    int steps = 0;
    const int max_steps = std::max(1, settings.max_newton_iterations);
    bool converged = false;
    std::string failure;
    double assembly_s = 0, factorization_s = 0;
    PetscMatrix A, K;  // the reduced Hessian and, with zero-mean conditions, its bordered system
    bool refine = false;
    for (;;) {
      const Stopwatch gradient_clock;
      gradient(u, g);
      assembly_s += gradient_clock.seconds();
      reduce(g, gr);
      // The Lagrangian's gradient: the zero-mean conditions' multipliers times their functionals.
      PetscVector lagrangian_gradient;
      LMEFORM_PETSC_CHECK(VecDuplicate(gr, lagrangian_gradient.out()));
      LMEFORM_PETSC_CHECK(VecCopy(gr, lagrangian_gradient));
      for (PetscInt j = 0; j < k; ++j) LMEFORM_PETSC_CHECK(VecAXPY(lagrangian_gradient, multipliers[std::size_t(j)], mean_columns[std::size_t(j)]));
      PetscReal n2 = 0;
      LMEFORM_PETSC_CHECK(VecNorm(lagrangian_gradient, NORM_2, &n2));
      double mean_residual = 0;
      for (PetscInt j = 0; j < k; ++j) {
        PetscScalar d = 0;
        LMEFORM_PETSC_CHECK(VecDot(means[std::size_t(j)], u, &d));
        mean_residual = std::max(mean_residual, std::abs(d));
      }
      norm = static_cast<double>(n2);
      if (first_norm < 0) first_norm = norm;
      if (input.log != nullptr && PetscSession::rank(comm) == 0)
        *input.log << fmt::format("  saddle   step {:2d}  |grad| {:.3e}{}\n", steps, norm,
                                  k > 0 ? fmt::format("  |mean| {:.1e}", mean_residual) : std::string());
      if (norm <= settings.newton_tolerance * first_norm || norm == 0) {
        converged = steps > 0 || norm == 0 || first_norm == 0;
        if (converged) break;
      }
      // A quadratic energy is solved by the first step; the next ones refine it until rounding
      // decides. On an ill-conditioned system (a beam with a flexoelectric length a quarter of its
      // thickness: 4e-9 of the start's after 25 steps) that floor lies above newton_tolerance:
      // a step that no longer halves |grad| below 1e-6 of the start's (the linear driver's
      // acceptance) ends the solve there.
      if (steps > 0 && norm > 0.5 * previous_norm && norm <= 1e-6 * first_norm) {
        converged = true;
        round_off_floor = true;
        break;
      }
      // After a step that removed all but a millionth of |grad|, what is left is rounding (or a
      // nonlinearity that small): this and later steps refine with the factorization at hand.
      refine = refine || (steps > 0 && norm <= 1e-6 * previous_norm);
      previous_norm = norm;
      if (steps >= max_steps) {
        failure = fmt::format("|grad| {:.3e} after {} Newton steps, {:.1e} of the start's (newton_tolerance {:.0e})", norm, steps,
                              norm / first_norm, settings.newton_tolerance);
        break;
      }
      if (!refine) {
        // The reduced Hessian Pᵀ H P, the eliminated rows and columns the identity.
        const Stopwatch hessian_clock;
        std::vector<Assembler::MatrixTerm> terms;
        for (Assembler* term : space.energy_terms) terms.push_back({term, 1.0});
        space.primary->matrix_sum(u, terms, H);
        assembly_s += hessian_clock.seconds();
        if (steps == 0) {
          std::vector<Vec> full_means;
          for (const auto& c : means) full_means.push_back(c);
          refuse_unheld_null_modes(b, space, H, full_means);
        }
        if (P) A = reduced_matrix(comm, H, follows);
        else LMEFORM_PETSC_CHECK(MatDuplicate(H, MAT_COPY_VALUES, A.out()));
        LMEFORM_PETSC_CHECK(MatZeroRowsColumns(A, static_cast<PetscInt>(eliminated.size()), eliminated.data(), 1.0, nullptr, nullptr));
        LMEFORM_PETSC_CHECK(MatSetOption(A, MAT_SYMMETRIC, PETSC_TRUE));
        if (k > 0) {
          K = bordered_matrix(comm, A, mean_columns);
          LMEFORM_PETSC_CHECK(MatSetOption(K, MAT_SYMMETRIC, PETSC_TRUE));
        }
        const Stopwatch factor_clock;
        const bool factored = factorization.factor(k > 0 ? Mat(K) : Mat(A));
        factorization_s += factor_clock.seconds();
        if (!factored) {
          failure = "the factorization of the saddle-point Hessian failed (" + factorization.failure() + ")";
          break;
        }
        result.negative_eigenvalues = static_cast<long>(factorization.negative_eigenvalues());
      }
      PetscVector rhs, x;
      LMEFORM_PETSC_CHECK(VecScale(gr, -1.0));
      if (k > 0) {
        rhs = bordered_vector(comm, gr, k);
        // The conditions' rows: c·(u + step) = 0.
        int rank = 0, size = 1;
        MPI_Comm_rank(comm, &rank);
        MPI_Comm_size(comm, &size);
        PetscInt n = 0;
        LMEFORM_PETSC_CHECK(VecGetSize(gr, &n));
        for (PetscInt j = 0; j < k; ++j) {
          PetscScalar d = 0;
          LMEFORM_PETSC_CHECK(VecDot(means[std::size_t(j)], u, &d));
          if (rank == size - 1) LMEFORM_PETSC_CHECK(VecSetValue(rhs, n + j, -d, INSERT_VALUES));
        }
        LMEFORM_PETSC_CHECK(VecAssemblyBegin(rhs));
        LMEFORM_PETSC_CHECK(VecAssemblyEnd(rhs));
        LMEFORM_PETSC_CHECK(VecDuplicate(rhs, x.out()));
      } else {
        LMEFORM_PETSC_CHECK(VecDuplicate(gr, x.out()));
      }
      try {
        const Stopwatch solve_clock;
        factorization.solve(k > 0 ? Vec(rhs) : Vec(gr), x);
        factorization_s += solve_clock.seconds();
      } catch (const std::runtime_error& e) {
        failure = e.what();
        break;
      }
      if (k > 0) {
        // The first part is the step, the border the multipliers.
        PetscVector reduced_step;
        LMEFORM_PETSC_CHECK(VecDuplicate(gr, reduced_step.out()));
        const VecReadView from(x);
        {
          VecWriteView to(reduced_step);
          for (PetscInt i = 0; i < to.size(); ++i) to[i] = from[i];
        }
        std::vector<double> border(std::size_t(k), 0.0);
        int rank = 0, size = 1;
        MPI_Comm_rank(comm, &rank);
        MPI_Comm_size(comm, &size);
        if (rank == size - 1)
          for (PetscInt j = 0; j < k; ++j) border[std::size_t(j)] = from[from.size() - k + j];
        MPI_Allreduce(MPI_IN_PLACE, border.data(), static_cast<int>(k), MPI_DOUBLE, MPI_SUM, comm);
        multipliers = border;
        expand(reduced_step, step);
      } else {
        expand(x, step);
      }
      LMEFORM_PETSC_CHECK(VecAXPY(u, 1.0, step));
      ++steps;
    }
    result.seconds_assembly = assembly_s;
    result.seconds_factorization = factorization_s;
    result.converged = converged;
    result.iterations = steps;
    result.residual_norm = norm;
    const std::string inertia =
        result.negative_eigenvalues < 0
            ? std::string()
            : fmt::format(", inertia {} negative of {} expected{}", result.negative_eigenvalues, result.expected_negative_eigenvalues,
                          result.negative_eigenvalues == result.expected_negative_eigenvalues ? " (min-max saddle)"
                                                                                               : " (NOT the declared min-max saddle)");
    result.message = converged ? fmt::format("Newton on the saddle point: {} step{}, |grad| {:.2e} ({:.1e} of the start's{}), MUMPS LDL^T{}",
                                             steps, steps == 1 ? "" : "s", norm, first_norm > 0 ? norm / first_norm : 0.0,
                                             round_off_floor ? ", its round-off floor" : "", inertia)
                               : failure + inertia;
    result.energy = space.energy(u);
    result.minimization.energy = result.energy;
    result.minimization.converged = converged;
    result.minimization.newton_iterations = steps;
  }

  void residual(const BoundScene&, ProblemSpace& space, Vec u, const ProblemResult&, Vec out) const override {
    LMEFORM_PETSC_CHECK(VecZeroEntries(out));
    for (Assembler* term : space.energy_terms) term->add_vector(u, out, 1.0);
  }

  void describe(const BoundScene& b, const ProblemResult& r, RunReport& report) const override {
    report.row("energy", fmt::format("{:.10g} (at the saddle point: min over {}, max over {})", r.energy, minimized(b), fmt::join(b.maximize, ", ")));
    report.row("solver", r.message);
    report.json["energy"] = json_number(r.energy);
    report.json["iterations"] = r.iterations;
    report.json["newton_iterations"] = r.iterations;
    report.json["residual_norm"] = json_number(r.residual_norm);
    report.json["negative_eigenvalues"] = r.negative_eigenvalues;
    report.json["expected_negative_eigenvalues"] = r.expected_negative_eigenvalues;
    report.json["assembly_s"] = json_number(r.seconds_assembly);
    report.json["factorization_s"] = json_number(r.seconds_factorization);
    if (report.fields) report.fields->attributes.emplace("energy", r.energy);
  }

 private:
  static std::string minimized(const BoundScene& b) {
    std::vector<std::string> names;
    for (const auto& f : b.layout.fields)
      if (std::find(b.maximize.begin(), b.maximize.end(), f.name) == b.maximize.end()) names.push_back(f.name);
    return fmt::format("{}", fmt::join(names, ", "));
  }

  /// The free dofs of the maximized unknowns in the reduced system: a min-max saddle's Hessian has
  /// that many negative eigenvalues (a zero-mean border adds one of each sign where the level was free).
  static long expected_negative(const BoundScene& b, const ProblemSpace& space, const std::vector<EquipotentialGroup>& groups) {
    long count = 0;
    for (const auto& name : b.maximize) {
      const UnknownField& f = b.unknown(name);
      count += static_cast<long>(space.nodes.size()) * f.components;
      for (const auto& [node, dof] : space.fixed_pairs)
        if (dof >= f.offset && dof < f.offset + f.components) --count;
      for (const auto& g : groups)
        if (g.entry->field.name == name) count -= static_cast<long>(g.nodes.size()) - 1;
    }
    return count;
  }
};

}  // namespace

const StationaryDriver& saddle_point_driver() {
  static const SaddlePointDriver driver;
  return driver;
}

}  // namespace lmeform::problems
