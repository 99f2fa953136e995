#include "lmeform/assembler.hpp"

#include <array>
#include "lmeform/stopwatch.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>
#include <optional>
#include <stdexcept>
#include <string>

#include "aij_direct_add.hpp"
#include "lmeform/contractions.hpp"

namespace lmeform {

namespace {


const char* order_name(int order) {
  return order == 0 ? "values" : order == 1 ? "gradients" : "Hessians";
}

// Which components a matrix from create_matrix couples (1) or keeps diagonal (0), attached to
// the Mat so that every Assembler adding into it skips the others' blocks.
constexpr const char* kCoupledKey = "lmeform_coupled_components";

PetscErrorCode destroy_coupled(void* pointer) {
  delete static_cast<std::vector<unsigned char>*>(pointer);
  return 0;
}

void attach_coupled(Mat A, std::vector<unsigned char> mask) {
  PetscContainer container = nullptr;
  LMEFORM_PETSC_CHECK(PetscContainerCreate(PetscObjectComm(reinterpret_cast<PetscObject>(A)), &container));
  LMEFORM_PETSC_CHECK(PetscContainerSetPointer(container, new std::vector<unsigned char>(std::move(mask))));
  LMEFORM_PETSC_CHECK(PetscContainerSetUserDestroy(container, destroy_coupled));
  LMEFORM_PETSC_CHECK(PetscObjectCompose(reinterpret_cast<PetscObject>(A), kCoupledKey, reinterpret_cast<PetscObject>(container)));
  LMEFORM_PETSC_CHECK(PetscContainerDestroy(&container));  // A holds the reference now
}

/// The mask of a matrix whose structure couples only some components, or null (all coupled).
const std::vector<unsigned char>* coupled_mask(Mat A) {
  PetscObject object = nullptr;
  LMEFORM_PETSC_CHECK(PetscObjectQuery(reinterpret_cast<PetscObject>(A), kCoupledKey, &object));
  if (object == nullptr) return nullptr;
  void* pointer = nullptr;
  LMEFORM_PETSC_CHECK(PetscContainerGetPointer(reinterpret_cast<PetscContainer>(object), &pointer));
  return static_cast<const std::vector<unsigned char>*>(pointer);
}

}  // namespace

namespace {

/// The integration domain of a kernel in a discretization.
const ElementSet& domain_of(const Discretization& disc, const kernel::FormKernels& k) {
  if (k.domain != kernel::IntegralDomain::Boundary) return disc.cells_domain();
  try {
    return disc.boundary_domain(k.boundary_part);
  } catch (const std::out_of_range&) {
    throw std::invalid_argument(std::string("form '") + k.module + "/" + k.name + "' integrates over the boundary part '" +
                                k.boundary_part + "', which the discretization has no quadrature for (DiscretizationOptions::boundary)");
  }
}

}  // namespace

Assembler::Assembler(const Discretization& discretization, const kernel::FormKernels& form)
    : Assembler(discretization, std::span<const kernel::FormKernels* const>(std::array<const kernel::FormKernels*, 1>{&form})) {}

Assembler::Assembler(const Discretization& discretization, std::span<const kernel::FormKernels* const> integrals)
    : disc_(&discretization), form_(integrals.empty() ? nullptr : integrals.front()) {
  if (form_ == nullptr) throw std::invalid_argument("Assembler: no kernel to assemble");
  const kernel::FormKernels& form = *form_;
  int needed = 0;
  std::size_t workspace = 0;
  for (const kernel::FormKernels* k : integrals) {
    if (k->contract_version != kernel::kContractVersion) {
      throw std::invalid_argument(describe() + ": generated for kernel contract version " + std::to_string(k->contract_version) +
                                  ", this runtime speaks version " + std::to_string(kernel::kContractVersion) +
                                  "; regenerate it with this lmeformc");
    }
    if (k->dim != disc_->dim()) {
      throw std::invalid_argument(describe() + ": generated for dimension " + std::to_string(k->dim) + " but the discretization is " +
                                  std::to_string(disc_->dim()) + "-dimensional");
    }
    if (k->dofs_per_node != form.dofs_per_node || k->n_constants != form.n_constants ||
        k->coefficient_components_per_node != form.coefficient_components_per_node || k->qdata_per_point != form.qdata_per_point)
      throw std::invalid_argument(describe() + ": its integrals over several domains do not share one layout of unknowns, "
                                  "coefficients, constants and data");
    if (k->kind == kernel::FunctionalKind::Point)
      throw std::invalid_argument(describe() + ": a point output (values at the quadrature points) is not an integral; evaluate it "
                                  "with a PointEvaluator");
    if (k->workspace_doubles == nullptr) throw std::invalid_argument(describe() + ": has no workspace_doubles function");
    needed = std::max({needed, k->basis_order, k->coefficient_basis_order});
    integrals_.push_back({k, &domain_of(discretization, *k), {}});
  }
  const int tabulated = disc_->options().basis_order;
  if (needed > tabulated) {
    throw std::invalid_argument(describe() + ": needs basis " + order_name(needed) + " (derivative order " + std::to_string(needed) +
                                ") but the discretization tabulates only up to " + order_name(tabulated) + " (order " +
                                std::to_string(tabulated) + "); build it with DiscretizationOptions::basis_order = " +
                                std::to_string(needed));
  }
  if (form.dofs_per_node < 1) throw std::invalid_argument(describe() + ": has no unknowns (dofs_per_node = 0)");

  constants_.assign(static_cast<std::size_t>(form.n_constants), std::numeric_limits<double>::quiet_NaN());

  const int bs = form.dofs_per_node;
  const auto ghosts = disc_->ghost_nodes();
  ghost_blocks_.assign(ghosts.begin(), ghosts.end());
  LMEFORM_PETSC_CHECK(VecCreateGhostBlock(disc_->comm(), bs, disc_->n_owned() * bs, PETSC_DECIDE,
                                          static_cast<PetscInt>(ghost_blocks_.size()), ghost_blocks_.data(), u_ghosted_.out()));

  const auto n_max = static_cast<std::size_t>(disc_->max_element_nodes());
  const auto nq_max = static_cast<std::size_t>(disc_->max_element_points());
  const auto jet = static_cast<std::size_t>(kernel::jet_size(disc_->dim(), needed));
  for (const Integral& i : integrals_) workspace = std::max(workspace, i.kernel->workspace_doubles(static_cast<int>(n_max), static_cast<int>(nq_max)));
  tabulation_.resize(nq_max * jet * n_max);
  element_u_.resize(n_max * static_cast<std::size_t>(bs));
  element_c_.resize(n_max * static_cast<std::size_t>(std::max(form.coefficient_components_per_node, 0)));
  workspace_.resize(workspace);
  local_.resize(n_max * n_max * static_cast<std::size_t>(bs * bs));
  rows_.resize(n_max);
  cols_.resize(n_max);
  scalar_rows_.resize(n_max * static_cast<std::size_t>(bs));
  scalar_cols_.resize(n_max * static_cast<std::size_t>(bs));
}

std::string Assembler::describe() const {
  return std::string("form '") + form_->module + "/" + form_->name + "' (dim " + std::to_string(form_->dim) + ")";
}

void Assembler::set_constants(std::span<const double> values) {
  if (values.size() != constants_.size()) {
    std::string names;
    for (int i = 0; i < form_->n_constants; ++i) names += std::string(i ? ", " : "") + form_->constants[i];
    throw std::invalid_argument(describe() + ": expects " + std::to_string(constants_.size()) + " constants (" +
                                names + "), got " + std::to_string(values.size()));
  }
  std::copy(values.begin(), values.end(), constants_.begin());
}

void Assembler::set_constant(std::string_view name, double value) {
  for (int i = 0; i < form_->n_constants; ++i) {
    if (name == form_->constants[i]) {
      constants_[static_cast<std::size_t>(i)] = value;
      return;
    }
  }
  std::string names;
  for (int i = 0; i < form_->n_constants; ++i) names += std::string(i ? ", " : "") + form_->constants[i];
  throw std::invalid_argument(describe() + ": has no constant '" + std::string(name) + "' (it has: " +
                              (names.empty() ? "none" : names) + ")");
}

void Assembler::set_coefficients(Vec coefficients) {
  const int cs = form_->coefficient_components_per_node;
  if (cs <= 0) throw std::invalid_argument(describe() + ": has no coefficients to set");
  if (!c_ghosted_) {
    LMEFORM_PETSC_CHECK(VecCreateGhostBlock(disc_->comm(), cs, disc_->n_owned() * cs, PETSC_DECIDE,
                                            static_cast<PetscInt>(ghost_blocks_.size()), ghost_blocks_.data(),
                                            c_ghosted_.out()));
  }
  gather_ghosted(coefficients, c_ghosted_);
  have_coefficients_ = true;
}

void Assembler::set_qdata(std::span<const double> values) { set_qdata(disc_->cells_domain(), values); }

void Assembler::set_qdata(const ElementSet& domain, std::span<const double> values) {
  const std::size_t expected = domain.n_points() * static_cast<std::size_t>(form_->qdata_per_point);
  if (values.size() != expected) {
    throw std::invalid_argument(describe() + ": quadrature data needs " + std::to_string(form_->qdata_per_point) + " values at each of " +
                                std::to_string(domain.n_points()) + " points of " + domain.name() + " (" + std::to_string(expected) +
                                "), got " + std::to_string(values.size()));
  }
  bool used = false;
  for (Integral& i : integrals_)
    if (i.domain == &domain) {
      i.qdata.assign(values.begin(), values.end());
      used = true;
    }
  if (!used) throw std::invalid_argument(describe() + ": has no integral over " + domain.name());
}

PetscVector Assembler::create_vector() const {
  PetscVector v;
  const int bs = form_->dofs_per_node;
  LMEFORM_PETSC_CHECK(VecCreate(disc_->comm(), v.out()));
  LMEFORM_PETSC_CHECK(VecSetSizes(v, disc_->n_owned() * bs, disc_->n_nodes() * bs));
  LMEFORM_PETSC_CHECK(VecSetBlockSize(v, bs));
  LMEFORM_PETSC_CHECK(VecSetType(v, VECSTANDARD));
  LMEFORM_PETSC_CHECK(VecZeroEntries(v));
  return v;
}

PetscVector Assembler::create_coefficient_vector() const {
  PetscVector v;
  const int cs = form_->coefficient_components_per_node;
  if (cs <= 0) throw std::invalid_argument(describe() + ": has no coefficients");
  LMEFORM_PETSC_CHECK(VecCreate(disc_->comm(), v.out()));
  LMEFORM_PETSC_CHECK(VecSetSizes(v, disc_->n_owned() * cs, disc_->n_nodes() * cs));
  LMEFORM_PETSC_CHECK(VecSetBlockSize(v, cs));
  LMEFORM_PETSC_CHECK(VecSetType(v, VECSTANDARD));
  LMEFORM_PETSC_CHECK(VecZeroEntries(v));
  return v;
}

PetscMatrix Assembler::create_matrix(MatrixInsertion insertion, std::span<const int> coupled_components) {
  const Stopwatch clock;
  const int bs = form_->dofs_per_node;
  std::vector<unsigned char> coupled;  // empty: every component couples
  if (!coupled_components.empty()) {
    coupled.assign(static_cast<std::size_t>(bs), 0);
    for (const int c : coupled_components) {
      if (c < 0 || c >= bs)
        throw std::invalid_argument(describe() + ": create_matrix: coupled component " + std::to_string(c) + " outside 0 … " +
                                    std::to_string(bs - 1));
      coupled[static_cast<std::size_t>(c)] = 1;
    }
    if (std::all_of(coupled.begin(), coupled.end(), [](unsigned char on) { return on != 0; })) coupled.clear();
  }
  const SparsityPattern& pattern = disc_->pattern();
  PetscMatrix A;
  LMEFORM_PETSC_CHECK(MatCreate(disc_->comm(), A.out()));
  LMEFORM_PETSC_CHECK(MatSetSizes(A, disc_->n_owned() * bs, disc_->n_owned() * bs, disc_->n_nodes() * bs,
                                  disc_->n_nodes() * bs));
  LMEFORM_PETSC_CHECK(MatSetBlockSize(A, bs));
  LMEFORM_PETSC_CHECK(MatSetType(A, MATAIJ));
  LMEFORM_PETSC_CHECK(MatSetFromOptions(A));
  std::vector<PetscInt> d_nnz(pattern.diagonal_counts.begin(), pattern.diagonal_counts.end());
  std::vector<PetscInt> o_nnz(pattern.off_diagonal_counts.begin(), pattern.off_diagonal_counts.end());
  LMEFORM_PETSC_CHECK(MatXAIJSetPreallocation(A, bs, d_nnz.data(), o_nnz.data(), nullptr, nullptr));
  LMEFORM_PETSC_CHECK(MatSetOption(A, MAT_NEW_NONZERO_ALLOCATION_ERR, PETSC_TRUE));
  const bool zero_communication = disc_->options().off_process == OffProcessMode::ZeroCommunication;
  if (zero_communication) LMEFORM_PETSC_CHECK(MatSetOption(A, MAT_NO_OFF_PROC_ENTRIES, PETSC_TRUE));
  // The structure is the pattern, inserted once as explicit zeros: every later assembly only
  // adds values, and (AIJ, owned rows only) can add them straight into PETSc's arrays.
  {
    std::vector<PetscInt> columns;
    std::vector<PetscScalar> zeros;
    for (int i = 0; i < pattern.n_rows(); ++i) {
      const auto row = pattern.row(i);
      columns.clear();
      for (const int b : row) {
        for (int d = 0; d < bs; ++d)
          if (coupled.empty() || coupled[static_cast<std::size_t>(d)] != 0) columns.push_back(static_cast<PetscInt>(b) * bs + d);
      }
      zeros.assign(std::max<std::size_t>(columns.size(), 1), 0.0);
      for (int c = 0; c < bs; ++c) {
        const PetscInt r = static_cast<PetscInt>(pattern.row_begin + i) * bs + c;
        if (coupled.empty() || coupled[static_cast<std::size_t>(c)] != 0) {
          LMEFORM_PETSC_CHECK(MatSetValues(A, 1, &r, static_cast<PetscInt>(columns.size()), columns.data(), zeros.data(),
                                           INSERT_VALUES));
        } else {
          LMEFORM_PETSC_CHECK(MatSetValues(A, 1, &r, 1, &r, zeros.data(), INSERT_VALUES));  // the diagonal alone
        }
      }
    }
  }
  LMEFORM_PETSC_CHECK(MatAssemblyBegin(A, MAT_FINAL_ASSEMBLY));
  LMEFORM_PETSC_CHECK(MatAssemblyEnd(A, MAT_FINAL_ASSEMBLY));
  LMEFORM_PETSC_CHECK(MatSetOption(A, MAT_NEW_NONZERO_LOCATION_ERR, PETSC_TRUE));
  LMEFORM_PETSC_CHECK(MatSetOption(A, MAT_KEEP_NONZERO_PATTERN, PETSC_TRUE));
  if (insertion == MatrixInsertion::Direct && (zero_communication || disc_->ranks() == 1)) {
    (void)detail::AijDirectAdd::attach(A);
  }
  if (!coupled.empty()) attach_coupled(A, std::move(coupled));
  times_.create_matrix = clock.seconds();
  totals_.create_matrix += times_.create_matrix;
  return A;
}

void Assembler::gather_ghosted(Vec source, Vec ghosted) {
  LMEFORM_PETSC_CHECK(VecCopy(source, ghosted));
  LMEFORM_PETSC_CHECK(VecGhostUpdateBegin(ghosted, INSERT_VALUES, SCATTER_FORWARD));
  LMEFORM_PETSC_CHECK(VecGhostUpdateEnd(ghosted, INSERT_VALUES, SCATTER_FORWARD));
}

void Assembler::check_ready() const {
  for (int i = 0; i < form_->n_constants; ++i) {
    if (std::isnan(constants_[static_cast<std::size_t>(i)])) {
      throw std::invalid_argument(describe() + ": constant '" + form_->constants[i] +
                                  "' was not set (set_constants / set_constant)");
    }
  }
  if (form_->coefficient_components_per_node > 0 && !have_coefficients_) {
    throw std::invalid_argument(describe() + ": its coefficients were not set (set_coefficients)");
  }
  for (const Integral& i : integrals_)
    if (form_->qdata_per_point > 0 && i.qdata.empty())
      throw std::invalid_argument(describe() + ": its quadrature data on " + i.domain->name() + " were not set (set_qdata)");
}

template <class PerElement>
void Assembler::element_loop(const ElementSet& domain, Vec u, bool owned_only, int order, PerElement&& per_element) {
  gather_ghosted(u, u_ghosted_);
  Vec u_local = nullptr;
  Vec c_local = nullptr;
  const PetscScalar* u_array = nullptr;
  const PetscScalar* c_array = nullptr;
  LMEFORM_PETSC_CHECK(VecGhostGetLocalForm(u_ghosted_, &u_local));
  LMEFORM_PETSC_CHECK(VecGetArrayRead(u_local, &u_array));
  if (have_coefficients_) {
    LMEFORM_PETSC_CHECK(VecGhostGetLocalForm(c_ghosted_, &c_local));
    LMEFORM_PETSC_CHECK(VecGetArrayRead(c_local, &c_array));
  }

  const int bs = form_->dofs_per_node;
  const int cs = form_->coefficient_components_per_node;
  const auto dim = static_cast<std::size_t>(disc_->dim());
  kernel::CellInputs in;
  in.contractions = &dense_contractions();
  in.basis_order = order;
  const std::size_t tabulation_size = static_cast<std::size_t>(disc_->max_element_points()) *
                                      static_cast<std::size_t>(kernel::jet_size(disc_->dim(), order)) *
                                      static_cast<std::size_t>(disc_->max_element_nodes());
  if (tabulation_.size() < tabulation_size) tabulation_.resize(tabulation_size);
  in.constants = constants_.data();
  in.workspace = workspace_.data();
  in.basis = tabulation_.data();
  in.unknowns = element_u_.data();
  in.coefficients = have_coefficients_ ? element_c_.data() : nullptr;
  const auto points = domain.points(), weights = domain.weights(), normals = domain.normals();

  for (int e = 0; e < domain.n_elements(); ++e) {
    if (owned_only && !domain.element_owned(e)) continue;
    const auto local_nodes = domain.element_local_nodes(e);
    const int n = static_cast<int>(local_nodes.size());
    const auto first = static_cast<std::size_t>(domain.element_first_point(e));
    in.n_nodes = n;
    in.n_points = domain.element_point_count(e);
    in.weights = weights.data() + first;
    in.points = points.data() + first * dim;
    in.normals = normals.empty() ? nullptr : normals.data() + first * dim;
    domain.tabulate(e, order, tabulation_, lme_ws_);
    for (int a = 0; a < n; ++a) {
      const auto src = static_cast<std::size_t>(local_nodes[static_cast<std::size_t>(a)]);
      for (int c = 0; c < bs; ++c) {
        element_u_[static_cast<std::size_t>(a * bs + c)] = u_array[src * static_cast<std::size_t>(bs) + static_cast<std::size_t>(c)];
      }
      for (int c = 0; c < cs; ++c) {
        element_c_[static_cast<std::size_t>(a * cs + c)] = c_array[src * static_cast<std::size_t>(cs) + static_cast<std::size_t>(c)];
      }
    }
    per_element(e, in);
  }

  LMEFORM_PETSC_CHECK(VecRestoreArrayRead(u_local, &u_array));
  LMEFORM_PETSC_CHECK(VecGhostRestoreLocalForm(u_ghosted_, &u_local));
  if (have_coefficients_) {
    LMEFORM_PETSC_CHECK(VecRestoreArrayRead(c_local, &c_array));
    LMEFORM_PETSC_CHECK(VecGhostRestoreLocalForm(c_ghosted_, &c_local));
  }
}

template <class PerElement>
void Assembler::integral_loop(Vec u, bool owned_only, PerElement&& per_element) {
  check_ready();
  for (const Integral& i : integrals_) {
    const kernel::FormKernels& k = *i.kernel;
    const auto per_point = static_cast<std::size_t>(k.qdata_per_point);
    element_loop(*i.domain, u, owned_only, std::max(k.basis_order, k.coefficient_basis_order), [&](int e, kernel::CellInputs& in) {
      in.qdata = i.qdata.empty() ? nullptr : i.qdata.data() + static_cast<std::size_t>(i.domain->element_first_point(e)) * per_point;
      per_element(i, e, in);
    });
  }
}

double Assembler::value(Vec u) {
  if (form_->value == nullptr) throw std::logic_error(describe() + ": has no value kernel (it is not an energy or constraint)");
  const Stopwatch clock;
  double local_sum = 0.0;
  integral_loop(u, /*owned_only=*/true, [&](const Integral& i, int, const kernel::CellInputs& in) { local_sum += i.kernel->value(in); });
  double total = 0.0;
  MPI_Allreduce(&local_sum, &total, 1, MPI_DOUBLE, MPI_SUM, disc_->comm());
  times_.value = clock.seconds();
  totals_.value += times_.value;
  return total;
}

double Assembler::value_and_vector(Vec u, Vec out) {
  if (form_->value == nullptr) throw std::logic_error(describe() + ": value_and_vector needs a value kernel");
  LMEFORM_PETSC_CHECK(VecZeroEntries(out));
  return vector_pass(u, out, 1.0, /*with_value=*/true);
}

void Assembler::vector(Vec u, Vec out) {
  LMEFORM_PETSC_CHECK(VecZeroEntries(out));
  add_vector(u, out, 1.0);
}

void Assembler::add_vector(Vec u, Vec out, double scale) { (void)vector_pass(u, out, scale, /*with_value=*/false); }

double Assembler::add_value_and_vector(Vec u, Vec out, double scale) {
  if (form_->value == nullptr) throw std::logic_error(describe() + ": add_value_and_vector needs a value kernel");
  return vector_pass(u, out, scale, /*with_value=*/true);
}

double Assembler::vector_pass(Vec u, Vec out, double scale, bool with_value) {
  if (form_->vector == nullptr) throw std::logic_error(describe() + ": has no vector kernel");
  const Stopwatch clock;
  const bool zero_communication = disc_->options().off_process == OffProcessMode::ZeroCommunication;
  const int bs = form_->dofs_per_node;
  LMEFORM_PETSC_CHECK(VecSetOption(out, VEC_IGNORE_OFF_PROC_ENTRIES, zero_communication ? PETSC_TRUE : PETSC_FALSE));
  double local_sum = 0.0;
  // One tabulation per element for both kernels; the value counts owned elements only.
  integral_loop(u, /*owned_only=*/!zero_communication, [&](const Integral& i, int e, const kernel::CellInputs& in) {
    if (with_value && i.domain->element_owned(e)) local_sum += i.kernel->value(in);
    const auto nodes = i.domain->element_nodes(e);
    const std::size_t m = nodes.size() * static_cast<std::size_t>(bs);
    std::fill_n(local_.begin(), m, 0.0);
    i.kernel->vector(in, local_.data());
    if (scale != 1.0) {
      for (std::size_t k = 0; k < m; ++k) local_[k] *= scale;
    }
    for (std::size_t a = 0; a < nodes.size(); ++a) {
      // Negative indices are skipped by PETSc: a rank keeps only its own rows.
      rows_[a] = (!zero_communication || disc_->owns(nodes[a])) ? nodes[a] : -1;
    }
    LMEFORM_PETSC_CHECK(VecSetValuesBlocked(out, static_cast<PetscInt>(nodes.size()), rows_.data(), local_.data(), ADD_VALUES));
  });
  LMEFORM_PETSC_CHECK(VecAssemblyBegin(out));
  LMEFORM_PETSC_CHECK(VecAssemblyEnd(out));
  double total = 0.0;
  if (with_value) MPI_Allreduce(&local_sum, &total, 1, MPI_DOUBLE, MPI_SUM, disc_->comm());
  times_.vector = clock.seconds();
  totals_.vector += times_.vector;
  return total;
}

void Assembler::matrix(Vec u, Mat out) {
  LMEFORM_PETSC_CHECK(MatZeroEntries(out));
  add_matrix(u, out, 1.0);
}

void Assembler::add_matrix(Vec u, Mat out, double scale) {
  const MatrixTerm self{this, scale};
  add_matrix_terms(u, {&self, 1}, out);
}

void Assembler::matrix_sum(Vec u, std::span<const MatrixTerm> terms, Mat out) {
  LMEFORM_PETSC_CHECK(MatZeroEntries(out));
  add_matrix_terms(u, terms, out);
}

template <class Insert>
void Assembler::add_domain_matrix(const ElementSet& domain, Vec u, std::span<const MatrixTerm> terms,
                                  const std::vector<unsigned char>* coupled, Insert&& insert, double& kernel_seconds) {
  const bool zero_communication = disc_->options().off_process == OffProcessMode::ZeroCommunication;
  const int bs = form_->dofs_per_node;
  // The terms' integrals over this domain, and the tabulation order they need.
  std::vector<std::pair<const MatrixTerm*, const Integral*>> parts;
  int order = 0;
  for (const MatrixTerm& t : terms)
    for (const Integral& i : t.form->integrals_)
      if (i.domain == &domain && !i.kernel->matrix_structurally_zero) {
        parts.emplace_back(&t, &i);
        order = std::max({order, i.kernel->basis_order, i.kernel->coefficient_basis_order});
      }
  element_loop(domain, u, /*owned_only=*/!zero_communication, order, [&](int e, kernel::CellInputs& in) {
    const Stopwatch kernel_clock;
    in.coupled_components = coupled != nullptr ? coupled->data() : nullptr;
    const auto nodes = domain.element_nodes(e);
    const std::size_t m = nodes.size() * static_cast<std::size_t>(bs);
    std::fill_n(local_.begin(), m * m, 0.0);
    bool first = true;
    for (const auto& [t, integral] : parts) {
      Assembler& a = *t->form;
      const auto qdata_at = [&](const Integral& i) {
        return i.qdata.empty() ? nullptr
                               : i.qdata.data() + static_cast<std::size_t>(domain.element_first_point(e)) *
                                                      static_cast<std::size_t>(i.kernel->qdata_per_point);
      };
      if (first && &a == this) {
        in.qdata = qdata_at(*integral);
        integral->kernel->matrix(in, local_.data());
        if (t->weight != 1.0) {
          for (std::size_t i = 0; i < m * m; ++i) local_[i] *= t->weight;
        }
      } else {
        // Same element, same tabulation; the other form's constants, data and scratch.
        kernel::CellInputs other = in;
        other.constants = a.constants_.data();
        other.workspace = a.workspace_.data();
        other.coefficients = &a == this ? in.coefficients : nullptr;
        other.qdata = qdata_at(*integral);
        std::fill_n(a.local_.begin(), m * m, 0.0);
        integral->kernel->matrix(other, a.local_.data());
        for (std::size_t i = 0; i < m * m; ++i) local_[i] += t->weight * a.local_[i];
      }
      first = false;
    }
    kernel_seconds += kernel_clock.seconds();
    insert(nodes, local_.data());
  });
}

void Assembler::add_matrix_terms(Vec u, std::span<const MatrixTerm> all_terms, Mat out) {
  // The terms that add something; each must be a form on this discretization and block size.
  std::vector<MatrixTerm> terms;
  for (const MatrixTerm& t : all_terms) {
    if (t.form == nullptr) throw std::invalid_argument(describe() + ": a matrix term has no form");
    const kernel::FormKernels& f = t.form->form();
    if (f.matrix == nullptr) throw std::logic_error(t.form->describe() + ": has no matrix kernel");
    if (&t.form->discretization() != disc_ || f.dofs_per_node != form_->dofs_per_node) {
      throw std::invalid_argument(t.form->describe() + ": a matrix term must share the discretization and the " +
                                  std::to_string(form_->dofs_per_node) + " dofs per node of " + describe());
    }
    if (t.form != this && f.coefficient_components_per_node > 0) {
      throw std::invalid_argument(t.form->describe() + ": forms with coefficients can only be summed as the first term");
    }
    t.form->check_ready();
    if (t.weight == 0.0) continue;
    if (std::all_of(t.form->integrals_.begin(), t.form->integrals_.end(), [](const Integral& i) { return i.kernel->matrix_structurally_zero; }))
      continue;  // linear in the unknowns: adds nothing
    terms.push_back(t);
  }
  if (terms.empty()) return;
  if (terms.front().form != this) {
    // The loop runs on this Assembler's scratch and coefficients: put it first.
    const auto self = std::find_if(terms.begin(), terms.end(), [this](const MatrixTerm& t) { return t.form == this; });
    if (self != terms.end()) std::iter_swap(terms.begin(), self);
  }
  // Each domain once: every term's integral over it adds to the same element block.
  std::vector<const ElementSet*> domains;
  for (const ElementSet& d : disc_->domains())
    for (const MatrixTerm& t : terms)
      for (const Integral& i : t.form->integrals_)
        if (i.domain == &d && !i.kernel->matrix_structurally_zero && std::find(domains.begin(), domains.end(), &d) == domains.end())
          domains.push_back(&d);

  const Stopwatch clock;
  const bool zero_communication = disc_->options().off_process == OffProcessMode::ZeroCommunication;
  double kernel_seconds = 0.0;
  // Matrices from create_matrix() carry a map of their structure: element blocks are added
  // straight into the AIJ arrays. Others (another type chosen by options) go through MatSetValues.
  detail::AijDirectAdd* direct = (zero_communication || disc_->ranks() == 1) ? detail::AijDirectAdd::find(out) : nullptr;
  std::optional<detail::AijDirectAdd::Fill> fill;
  if (direct != nullptr) fill.emplace(*direct, out);
  const int bs = form_->dofs_per_node;
  const std::vector<unsigned char>* coupled = coupled_mask(out);
  auto insert = [&](std::span<const int> nodes, const double* block) {
    const std::size_t m = nodes.size() * static_cast<std::size_t>(bs);
    if (coupled != nullptr) {
      // Only the coupled components' rows and columns exist: the block restricted to them.
      coupled_local_.clear();
      for (std::size_t a = 0; a < nodes.size(); ++a) {
        const bool mine = !zero_communication || disc_->owns(nodes[a]);
        for (int c = 0; c < bs; ++c) {
          if ((*coupled)[static_cast<std::size_t>(c)] == 0) continue;
          const PetscInt dof = static_cast<PetscInt>(nodes[a]) * bs + c;
          scalar_cols_[coupled_local_.size()] = dof;
          scalar_rows_[coupled_local_.size()] = mine ? dof : -1;
          coupled_local_.push_back(a * static_cast<std::size_t>(bs) + static_cast<std::size_t>(c));
        }
      }
      const std::size_t k = coupled_local_.size();
      coupled_block_.resize(k * k);
      for (std::size_t i = 0; i < k; ++i)
        for (std::size_t j = 0; j < k; ++j) coupled_block_[i * k + j] = block[coupled_local_[i] * m + coupled_local_[j]];
      if (fill) {
        fill->add({scalar_rows_.data(), k}, {scalar_cols_.data(), k}, coupled_block_.data(), 1.0);
      } else {
        LMEFORM_PETSC_CHECK(MatSetValues(out, static_cast<PetscInt>(k), scalar_rows_.data(), static_cast<PetscInt>(k), scalar_cols_.data(),
                                         coupled_block_.data(), ADD_VALUES));
      }
      return;
    }
    if (fill) {
      for (std::size_t a = 0; a < nodes.size(); ++a) {
        const bool mine = !zero_communication || disc_->owns(nodes[a]);
        for (int c = 0; c < bs; ++c) {
          const PetscInt dof = static_cast<PetscInt>(nodes[a]) * bs + c;
          scalar_cols_[a * static_cast<std::size_t>(bs) + static_cast<std::size_t>(c)] = dof;
          scalar_rows_[a * static_cast<std::size_t>(bs) + static_cast<std::size_t>(c)] = mine ? dof : -1;
        }
      }
      fill->add({scalar_rows_.data(), m}, {scalar_cols_.data(), m}, block, 1.0);
      return;
    }
    for (std::size_t a = 0; a < nodes.size(); ++a) {
      cols_[a] = nodes[a];
      rows_[a] = (!zero_communication || disc_->owns(nodes[a])) ? nodes[a] : -1;
    }
    const auto count = static_cast<PetscInt>(nodes.size());
    LMEFORM_PETSC_CHECK(MatSetValuesBlocked(out, count, rows_.data(), count, cols_.data(), block, ADD_VALUES));
  };
  for (const ElementSet* domain : domains) add_domain_matrix(*domain, u, terms, coupled, insert, kernel_seconds);
  if (fill) {
    fill->finish();
  } else {
    LMEFORM_PETSC_CHECK(MatAssemblyBegin(out, MAT_FINAL_ASSEMBLY));
    LMEFORM_PETSC_CHECK(MatAssemblyEnd(out, MAT_FINAL_ASSEMBLY));
  }
  times_.matrix = clock.seconds();
  times_.matrix_kernel = kernel_seconds;
  totals_.matrix += times_.matrix;
  totals_.matrix_kernel += kernel_seconds;
}

void apply_dirichlet(Mat A, Vec b, Vec x, std::span<const PetscInt> dofs) {
  LMEFORM_PETSC_CHECK(MatZeroRowsColumns(A, static_cast<PetscInt>(dofs.size()), dofs.data(), 1.0, x, b));
}

std::vector<PetscInt> owned_dofs_of_nodes(const Discretization& disc, std::span<const int> original_nodes,
                                          int block_size) {
  std::vector<PetscInt> dofs;
  for (const int o : original_nodes) {
    if (o < 0 || o >= disc.n_nodes()) {
      throw std::invalid_argument("owned_dofs_of_nodes: node " + std::to_string(o) + " outside [0, " +
                                  std::to_string(disc.n_nodes()) + ")");
    }
    const int b = disc.renumbered_index()[static_cast<std::size_t>(o)];
    if (!disc.owns(b)) continue;
    for (int c = 0; c < block_size; ++c) dofs.push_back(static_cast<PetscInt>(b * block_size + c));
  }
  std::sort(dofs.begin(), dofs.end());
  return dofs;
}

void set_from_original(const Discretization& disc, std::span<const double> original_values, int block_size, Vec v) {
  const std::size_t expected = static_cast<std::size_t>(disc.n_nodes()) * static_cast<std::size_t>(block_size);
  if (original_values.size() != expected) {
    throw std::invalid_argument("set_from_original: " + std::to_string(original_values.size()) + " values for " +
                                std::to_string(disc.n_nodes()) + " nodes x " + std::to_string(block_size) +
                                " components");
  }
  VecWriteView out(v);
  if (out.size() != disc.n_owned() * block_size) {
    throw std::invalid_argument("set_from_original: vector has local size " + std::to_string(out.size()) + ", expected " +
                                std::to_string(disc.n_owned() * block_size));
  }
  for (int b = disc.owned_begin(); b < disc.owned_end(); ++b) {
    const auto old = static_cast<std::size_t>(disc.original_index()[static_cast<std::size_t>(b)]);
    for (int c = 0; c < block_size; ++c) {
      out[(b - disc.owned_begin()) * block_size + c] = original_values[old * static_cast<std::size_t>(block_size) + static_cast<std::size_t>(c)];
    }
  }
}

std::vector<int> coupled_components(const Discretization& disc, int block_size, std::span<const PetscInt> fixed) {
  // Fixed dofs per component on this rank, against the owned nodes: a component is free where
  // its count falls short on any rank.
  const PetscInt first = static_cast<PetscInt>(disc.owned_begin()) * block_size;
  const auto n_owned = static_cast<std::size_t>(disc.n_owned()) * static_cast<std::size_t>(block_size);
  std::vector<unsigned char> held(n_owned, 0);
  for (const PetscInt dof : fixed)
    if (dof >= first && static_cast<std::size_t>(dof - first) < n_owned) held[static_cast<std::size_t>(dof - first)] = 1;
  std::vector<int> free(static_cast<std::size_t>(block_size), 0);
  for (std::size_t i = 0; i < n_owned; ++i)
    if (held[i] == 0) free[i % static_cast<std::size_t>(block_size)] = 1;
  MPI_Allreduce(MPI_IN_PLACE, free.data(), block_size, MPI_INT, MPI_MAX, disc.comm());
  std::vector<int> coupled;
  for (int c = 0; c < block_size; ++c)
    if (free[static_cast<std::size_t>(c)] != 0) coupled.push_back(c);
  if (static_cast<int>(coupled.size()) == block_size) coupled.clear();
  return coupled;
}

OwnedRows owned_original(const Discretization& disc, Vec v, int block_size) {
  OwnedRows out;
  const VecReadView in(v);
  out.values.assign(in.data(), in.data() + in.size());
  out.rows.reserve(static_cast<std::size_t>(disc.n_owned()));
  for (int b = disc.owned_begin(); b < disc.owned_end(); ++b) out.rows.push_back(disc.original_index()[static_cast<std::size_t>(b)]);
  if (out.values.size() != out.rows.size() * static_cast<std::size_t>(block_size))
    throw std::invalid_argument("owned_original: vector has local size " + std::to_string(out.values.size()) + ", expected " +
                                std::to_string(out.rows.size() * static_cast<std::size_t>(block_size)));
  return out;
}

std::vector<double> to_original(const Discretization& disc, Vec v, int block_size) {
  const int n = disc.n_nodes();
  std::vector<int> counts(static_cast<std::size_t>(disc.ranks()));
  std::vector<int> displs(static_cast<std::size_t>(disc.ranks()));
  for (int r = 0; r < disc.ranks(); ++r) {
    counts[static_cast<std::size_t>(r)] =
        (disc.partition().offsets[static_cast<std::size_t>(r) + 1] - disc.partition().offsets[static_cast<std::size_t>(r)]) * block_size;
    displs[static_cast<std::size_t>(r)] = disc.partition().offsets[static_cast<std::size_t>(r)] * block_size;
  }
  std::vector<double> renumbered(static_cast<std::size_t>(n) * static_cast<std::size_t>(block_size));
  {
    VecReadView in(v);
    MPI_Allgatherv(in.data(), static_cast<int>(in.size()), MPI_DOUBLE, renumbered.data(), counts.data(), displs.data(),
                   MPI_DOUBLE, disc.comm());
  }
  std::vector<double> original(renumbered.size());
  for (int b = 0; b < n; ++b) {
    const auto old = static_cast<std::size_t>(disc.original_index()[static_cast<std::size_t>(b)]);
    for (int c = 0; c < block_size; ++c) {
      original[old * static_cast<std::size_t>(block_size) + static_cast<std::size_t>(c)] =
          renumbered[static_cast<std::size_t>(b) * static_cast<std::size_t>(block_size) + static_cast<std::size_t>(c)];
    }
  }
  return original;
}

}  // namespace lmeform
