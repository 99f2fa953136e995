#include "lmeform/assembler.hpp"

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

double seconds_since(std::chrono::steady_clock::time_point start) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
}

const char* order_name(int order) {
  return order == 0 ? "values" : order == 1 ? "gradients" : "Hessians";
}

}  // namespace

Assembler::Assembler(const Discretization& discretization, const kernel::FormKernels& form)
    : disc_(&discretization), form_(&form) {
  if (form.contract_version != kernel::kContractVersion) {
    throw std::invalid_argument(describe() + ": generated for kernel contract version " +
                                std::to_string(form.contract_version) + ", this runtime speaks version " +
                                std::to_string(kernel::kContractVersion) + "; regenerate it with this lmeformc");
  }
  // The discretization's quadrature is the cells': a boundary kernel needs boundary points and
  // their normals, and a point output is not an integral.
  if (form.kind == kernel::FunctionalKind::Point)
    throw std::invalid_argument(describe() + ": a point output (values at the quadrature points) is not assembled");
  if (form.domain != kernel::IntegralDomain::Cells) {
    const std::string part = form.boundary_part != nullptr && *form.boundary_part != '\0' ? std::string(form.boundary_part) : "";
    throw std::invalid_argument(describe() + ": integrates over the boundary (" + (part.empty() ? "ds" : "ds(" + part + ")") +
                                "); the assembler integrates over the cells only");
  }
  if (form.dim != disc_->dim()) {
    throw std::invalid_argument(describe() + ": generated for dimension " + std::to_string(form.dim) +
                                " but the discretization is " + std::to_string(disc_->dim()) + "-dimensional");
  }
  const int needed = std::max(form.basis_order, form.coefficient_basis_order);
  const int tabulated = disc_->options().basis_order;
  if (needed > tabulated) {
    throw std::invalid_argument(describe() + ": needs basis " + order_name(needed) + " (derivative order " +
                                std::to_string(needed) + ") but the discretization tabulates only up to " +
                                order_name(tabulated) + " (order " + std::to_string(tabulated) +
                                "); build it with DiscretizationOptions::basis_order = " + std::to_string(needed));
  }
  if (form.dofs_per_node < 1) throw std::invalid_argument(describe() + ": has no unknowns (dofs_per_node = 0)");
  if (form.workspace_doubles == nullptr) throw std::invalid_argument(describe() + ": has no workspace_doubles function");

  constants_.assign(static_cast<std::size_t>(form.n_constants), std::numeric_limits<double>::quiet_NaN());

  const int bs = form.dofs_per_node;
  const auto ghosts = disc_->ghost_nodes();
  ghost_blocks_.assign(ghosts.begin(), ghosts.end());
  LMEFORM_PETSC_CHECK(VecCreateGhostBlock(disc_->comm(), bs, disc_->n_owned() * bs, PETSC_DECIDE,
                                          static_cast<PetscInt>(ghost_blocks_.size()), ghost_blocks_.data(),
                                          u_ghosted_.out()));

  const auto n_max = static_cast<std::size_t>(disc_->max_element_nodes());
  const auto nq_max = static_cast<std::size_t>(disc_->max_element_points());
  const auto jet = static_cast<std::size_t>(kernel::jet_size(disc_->dim(), needed));
  tabulation_.resize(nq_max * jet * n_max);
  element_u_.resize(n_max * static_cast<std::size_t>(bs));
  element_c_.resize(n_max * static_cast<std::size_t>(std::max(form.coefficient_components_per_node, 0)));
  workspace_.resize(form.workspace_doubles(static_cast<int>(n_max), static_cast<int>(nq_max)));
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

void Assembler::set_qdata(std::span<const double> values) {
  const std::size_t expected = disc_->quadrature().size() * static_cast<std::size_t>(form_->qdata_per_point);
  if (values.size() != expected) {
    throw std::invalid_argument(describe() + ": quadrature data needs " + std::to_string(form_->qdata_per_point) +
                                " values at each of " + std::to_string(disc_->quadrature().size()) +
                                " quadrature points (" + std::to_string(expected) + "), got " +
                                std::to_string(values.size()));
  }
  qdata_.assign(values.begin(), values.end());
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

PetscMatrix Assembler::create_matrix(MatrixInsertion insertion) {
  const auto start = std::chrono::steady_clock::now();
  const int bs = form_->dofs_per_node;
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
        for (int d = 0; d < bs; ++d) columns.push_back(static_cast<PetscInt>(b) * bs + d);
      }
      zeros.assign(columns.size(), 0.0);
      for (int c = 0; c < bs; ++c) {
        const PetscInt r = static_cast<PetscInt>(pattern.row_begin + i) * bs + c;
        LMEFORM_PETSC_CHECK(MatSetValues(A, 1, &r, static_cast<PetscInt>(columns.size()), columns.data(), zeros.data(),
                                         INSERT_VALUES));
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
  times_.create_matrix = seconds_since(start);
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
  if (form_->qdata_per_point > 0 && qdata_.empty()) {
    throw std::invalid_argument(describe() + ": its quadrature data were not set (set_qdata)");
  }
}

template <class PerElement>
void Assembler::element_loop(Vec u, bool owned_only, PerElement&& per_element) {
  element_loop(u, owned_only, std::max(form_->basis_order, form_->coefficient_basis_order),
               std::forward<PerElement>(per_element));
}

template <class PerElement>
void Assembler::element_loop(Vec u, bool owned_only, int order, PerElement&& per_element) {
  check_ready();
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
  const int dim = disc_->dim();
  const CellQuadrature& quadrature = disc_->quadrature();
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

  for (int e = 0; e < disc_->n_elements(); ++e) {
    if (owned_only && !disc_->element_owned(e)) continue;
    const auto local_nodes = disc_->element_local_nodes(e);
    const int n = static_cast<int>(local_nodes.size());
    const int first = disc_->element_first_point(e);
    in.n_nodes = n;
    in.n_points = disc_->element_point_count(e);
    in.weights = quadrature.weights.data() + first;
    in.points = quadrature.points.data() + static_cast<std::size_t>(first) * static_cast<std::size_t>(dim);
    in.qdata = qdata_.empty() ? nullptr
                              : qdata_.data() + static_cast<std::size_t>(first) * static_cast<std::size_t>(form_->qdata_per_point);
    disc_->tabulate(e, order, tabulation_, lme_ws_);
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

double Assembler::value(Vec u) {
  if (form_->value == nullptr) throw std::logic_error(describe() + ": has no value kernel (it is not an energy or constraint)");
  const auto start = std::chrono::steady_clock::now();
  double local_sum = 0.0;
  element_loop(u, /*owned_only=*/true, [&](int, const kernel::CellInputs& in) { local_sum += form_->value(in); });
  double total = 0.0;
  MPI_Allreduce(&local_sum, &total, 1, MPI_DOUBLE, MPI_SUM, disc_->comm());
  times_.value = seconds_since(start);
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
  const auto start = std::chrono::steady_clock::now();
  const bool zero_communication = disc_->options().off_process == OffProcessMode::ZeroCommunication;
  const int bs = form_->dofs_per_node;
  LMEFORM_PETSC_CHECK(VecSetOption(out, VEC_IGNORE_OFF_PROC_ENTRIES, zero_communication ? PETSC_TRUE : PETSC_FALSE));
  double local_sum = 0.0;
  // One tabulation per element for both kernels; the value counts owned elements only.
  element_loop(u, /*owned_only=*/!zero_communication, [&](int e, const kernel::CellInputs& in) {
    if (with_value && disc_->element_owned(e)) local_sum += form_->value(in);
    const auto nodes = disc_->element_nodes(e);
    const std::size_t m = nodes.size() * static_cast<std::size_t>(bs);
    std::fill_n(local_.begin(), m, 0.0);
    form_->vector(in, local_.data());
    if (scale != 1.0) {
      for (std::size_t i = 0; i < m; ++i) local_[i] *= scale;
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
  times_.vector = seconds_since(start);
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

void Assembler::add_matrix_terms(Vec u, std::span<const MatrixTerm> all_terms, Mat out) {
  // The terms that add something; each must be a form on this discretization and block size.
  std::vector<MatrixTerm> terms;
  int order = 0;
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
    if (f.matrix_structurally_zero || t.weight == 0.0) continue;  // linear in the unknowns: adds nothing
    terms.push_back(t);
    order = std::max({order, f.basis_order, f.coefficient_basis_order});
  }
  if (terms.empty()) return;
  if (terms.front().form != this) {
    // The loop runs on this Assembler's scratch and coefficients: put it first.
    const auto self = std::find_if(terms.begin(), terms.end(), [this](const MatrixTerm& t) { return t.form == this; });
    if (self != terms.end()) std::iter_swap(terms.begin(), self);
  }

  const auto start = std::chrono::steady_clock::now();
  const bool zero_communication = disc_->options().off_process == OffProcessMode::ZeroCommunication;
  const int bs = form_->dofs_per_node;
  double kernel_seconds = 0.0;
  // Matrices from create_matrix() carry a map of their structure: element blocks are added
  // straight into the AIJ arrays. Others (another type chosen by options) go through MatSetValues.
  detail::AijDirectAdd* direct =
      (zero_communication || disc_->ranks() == 1) ? detail::AijDirectAdd::find(out) : nullptr;
  std::optional<detail::AijDirectAdd::Fill> fill;
  if (direct != nullptr) fill.emplace(*direct, out);

  element_loop(u, /*owned_only=*/!zero_communication, order, [&](int e, const kernel::CellInputs& in) {
    const auto kernel_start = std::chrono::steady_clock::now();
    const auto nodes = disc_->element_nodes(e);
    const std::size_t m = nodes.size() * static_cast<std::size_t>(bs);
    std::fill_n(local_.begin(), m * m, 0.0);
    bool first = true;
    for (const MatrixTerm& t : terms) {
      Assembler& a = *t.form;
      if (first && &a == this) {
        form_->matrix(in, local_.data());
        if (t.weight != 1.0) {
          for (std::size_t i = 0; i < m * m; ++i) local_[i] *= t.weight;
        }
      } else {
        // Same element, same tabulation; the other form's constants, data and scratch.
        kernel::CellInputs other = in;
        other.constants = a.constants_.data();
        other.workspace = a.workspace_.data();
        other.coefficients = nullptr;
        other.qdata = a.qdata_.empty() ? nullptr
                                       : a.qdata_.data() + static_cast<std::size_t>(disc_->element_first_point(e)) *
                                                               static_cast<std::size_t>(a.form_->qdata_per_point);
        std::fill_n(a.local_.begin(), m * m, 0.0);
        a.form_->matrix(other, a.local_.data());
        for (std::size_t i = 0; i < m * m; ++i) local_[i] += t.weight * a.local_[i];
      }
      first = false;
    }
    kernel_seconds += seconds_since(kernel_start);
    if (fill) {
      for (std::size_t a = 0; a < nodes.size(); ++a) {
        const bool mine = !zero_communication || disc_->owns(nodes[a]);
        for (int c = 0; c < bs; ++c) {
          const PetscInt dof = static_cast<PetscInt>(nodes[a]) * bs + c;
          scalar_cols_[a * static_cast<std::size_t>(bs) + static_cast<std::size_t>(c)] = dof;
          scalar_rows_[a * static_cast<std::size_t>(bs) + static_cast<std::size_t>(c)] = mine ? dof : -1;
        }
      }
      fill->add({scalar_rows_.data(), m}, {scalar_cols_.data(), m}, local_.data(), 1.0);
    } else {
      for (std::size_t a = 0; a < nodes.size(); ++a) {
        cols_[a] = nodes[a];
        rows_[a] = (!zero_communication || disc_->owns(nodes[a])) ? nodes[a] : -1;
      }
      const auto count = static_cast<PetscInt>(nodes.size());
      LMEFORM_PETSC_CHECK(MatSetValuesBlocked(out, count, rows_.data(), count, cols_.data(), local_.data(), ADD_VALUES));
    }
  });
  if (fill) {
    fill->finish();
  } else {
    LMEFORM_PETSC_CHECK(MatAssemblyBegin(out, MAT_FINAL_ASSEMBLY));
    LMEFORM_PETSC_CHECK(MatAssemblyEnd(out, MAT_FINAL_ASSEMBLY));
  }
  times_.matrix = seconds_since(start);
  times_.matrix_kernel = kernel_seconds;
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
