// Assembly of generated kernels into distributed PETSc objects.
//
// One Assembler binds one functional (a FormKernels from a generated module) to a
// Discretization. It owns the per-element scratch (tabulation, gathered nodal values, the
// kernel's workspace, the dense local result), so an assembly allocates nothing per element,
// and it adds each element's dense block with one MatSetValuesBlocked / VecSetValuesBlocked.
//
//   Discretization disc(PETSC_COMM_WORLD, nodes, options);
//   Assembler poisson(disc, poisson_energy_2d);        // from poisson_kernels.hpp
//   poisson.set_constants({1.0});
//   PetscMatrix K = poisson.create_matrix();            // exact preallocation from the pattern
//   PetscVector u = poisson.create_vector(), g = poisson.create_vector();
//   double E = poisson.value(u);  poisson.vector(u, g);  poisson.matrix(u, K);
#pragma once

#include <span>
#include <string>
#include <string_view>
#include <vector>

#include "lmeform/discretization.hpp"
#include "lmeform/kernel.hpp"
#include "lmeform/petsc.hpp"

namespace lmeform {

/// Seconds of the last calls, this rank.
struct AssemblyTimes {
  double create_matrix = 0;  ///< matrix creation + exact preallocation
  double value = 0;
  double vector = 0;
  double matrix = 0;         ///< element loop + MatAssemblyBegin/End
  double matrix_kernel = 0;  ///< of which: the kernel calls alone (no tabulation, no PETSc insertion)
};

class Assembler {
 public:
  /// One form output: its kernels, one per integration domain (the cells, a boundary part), all
  /// generated from one form (same unknowns, coefficients, constants and quadrature data), summed
  /// by every assembly. The first kernel's metadata describes the output.
  Assembler(const Discretization& discretization, std::span<const kernel::FormKernels* const> integrals);
  Assembler(const Discretization& discretization, const kernel::FormKernels& form);

  [[nodiscard]] const kernel::FormKernels& form() const noexcept { return *form_; }
  /// The integrals: each kernel with the domain it integrates over.
  struct Integral {
    const kernel::FormKernels* kernel = nullptr;
    const ElementSet* domain = nullptr;
    std::vector<double> qdata;   ///< at every point of the domain, qdata_per_point each
  };
  [[nodiscard]] std::span<const Integral> integrals() const noexcept { return integrals_; }
  [[nodiscard]] const Discretization& discretization() const noexcept { return *disc_; }
  [[nodiscard]] int block_size() const noexcept { return form_->dofs_per_node; }
  /// "module/name (dim D)" for messages.
  [[nodiscard]] std::string describe() const;

  /// Constants in the declaration order of the form (FormKernels::constants).
  void set_constants(std::span<const double> values);
  void set_constant(std::string_view name, double value);
  /// Known nodal fields, a vector with coefficient_components_per_node entries per node, in the
  /// renumbered node order (create it with create_coefficient_vector()).
  void set_coefficients(Vec coefficients);
  /// Quadrature-point data for every point of the cells, qdata_per_point values each.
  void set_qdata(std::span<const double> values);
  /// ... for every point of an integration domain (the cells or a boundary part).
  void set_qdata(const ElementSet& domain, std::span<const double> values);

  [[nodiscard]] PetscVector create_vector() const;
  [[nodiscard]] PetscVector create_coefficient_vector() const;
  /// A matrix whose nonzero structure is the discretization's pattern, set once (explicit zeros);
  /// inserting outside it is an error. With MatrixInsertion::Direct (the default), assemblies add
  /// element blocks straight into the AIJ value arrays (one binary search and a merge walk per
  /// element row) instead of MatSetValues — about 10x faster to fill, same values; it applies to
  /// MATSEQAIJ / MATMPIAIJ (other types chosen with -mat_type use MatSetValues) and to owned rows
  /// (zero-communication mode, or one rank).
  ///
  /// `coupled_components` (per node, 0 … dofs_per_node − 1; empty: all) restricts the structure:
  /// the listed components couple as the pattern says, every other one keeps only its diagonal
  /// entry, and assemblies into the matrix skip the blocks of the others (their kernels' component
  /// blocks are not contracted, their entries not inserted). For Newton matrices whose other
  /// components are held fixed wholesale (one group of a staggered solve: MatZeroRowsColumns
  /// turns their rows and columns into the identity anyway), the factorization then costs what
  /// the coupled components' system costs. See coupled_components().
  enum class MatrixInsertion { Direct, SetValues };
  [[nodiscard]] PetscMatrix create_matrix(MatrixInsertion insertion = MatrixInsertion::Direct,
                                          std::span<const int> coupled_components = {});

  /// Energy or constraint value (summed over ranks).
  [[nodiscard]] double value(Vec u);
  /// Gradient / residual / linear form, overwriting `out`.
  void vector(Vec u, Vec out);
  /// value(u) and vector(u, out) in one pass over the elements (one basis tabulation).
  [[nodiscard]] double value_and_vector(Vec u, Vec out);
  /// Hessian / Jacobian / bilinear form, overwriting `out` (which must come from create_matrix()).
  void matrix(Vec u, Mat out);

  /// out += scale * (this form's vector / matrix): combinations such as ∇²E − Σ σ_i ∇²C_i are
  /// accumulated into one matrix (any matrix from an Assembler of the same discretization and
  /// block size) without temporaries.
  void add_vector(Vec u, Vec out, double scale);
  /// out += scale * vector, returning the value (unscaled): one pass, as value_and_vector.
  [[nodiscard]] double add_value_and_vector(Vec u, Vec out, double scale);
  void add_matrix(Vec u, Mat out, double scale);

  /// One weighted form of a sum (see matrix_sum).
  struct MatrixTerm {
    Assembler* form;
    double weight;
  };
  /// out = Σ weight_i · (matrix of form i), e.g. the Lagrangian Hessian ∇²E − Σ σ_i ∇²C_i, in one
  /// pass over the elements: each element is tabulated once (at the highest order the terms need)
  /// and its summed block inserted once. The forms share this discretization and block size;
  /// only this Assembler's form may have coefficients. Terms whose matrix is structurally zero
  /// cost nothing.
  void matrix_sum(Vec u, std::span<const MatrixTerm> terms, Mat out);

  [[nodiscard]] const AssemblyTimes& times() const noexcept { return times_; }  ///< of the last call of each kind
  [[nodiscard]] const AssemblyTimes& totals() const noexcept { return totals_; }  ///< summed over every call

 private:
  void check_ready() const;  // constants, coefficients and data set
  /// Runs per_element(e, inputs) over the elements of `domain`, with the element's unknowns,
  /// coefficients, points, weights, normals and basis tabulation to `order` set in the inputs.
  template <class PerElement>
  void element_loop(const ElementSet& domain, Vec u, bool owned_only, int order, PerElement&& per_element);
  /// The same over every integral of this form, with its kernel and data.
  template <class PerElement>
  void integral_loop(Vec u, bool owned_only, PerElement&& per_element);
  void add_matrix_terms(Vec u, std::span<const MatrixTerm> terms, Mat out);
  /// The terms' element blocks over one domain, each summed and handed to insert(nodes, block).
  template <class Insert>
  void add_domain_matrix(const ElementSet& domain, Vec u, std::span<const MatrixTerm> terms, const std::vector<unsigned char>* coupled,
                         Insert&& insert, double& kernel_seconds);
  // out += scale * vector; with_value: also the value (summed over ranks), else 0.
  double vector_pass(Vec u, Vec out, double scale, bool with_value);
  void gather_ghosted(Vec source, Vec ghosted);

  const Discretization* disc_;
  const kernel::FormKernels* form_;
  std::vector<Integral> integrals_;
  std::vector<double> constants_;
  std::vector<PetscInt> ghost_blocks_;
  PetscVector u_ghosted_;
  PetscVector c_ghosted_;
  bool have_coefficients_ = false;

  // Per-element scratch, sized for the largest element.
  std::vector<double> tabulation_;
  std::vector<double> element_u_;
  std::vector<double> element_c_;
  std::vector<double> element_qdata_;
  std::vector<double> workspace_;
  std::vector<double> local_;
  std::vector<PetscInt> rows_;
  std::vector<PetscInt> cols_;
  std::vector<PetscInt> scalar_rows_;  // element dofs (node * block size + component)
  std::vector<PetscInt> scalar_cols_;
  std::vector<std::size_t> coupled_local_;  // element-local dofs of the coupled components
  std::vector<double> coupled_block_;       // the element block restricted to them
  LmeWorkspace lme_ws_;
  AssemblyTimes times_;
  AssemblyTimes totals_;
};

/// Dirichlet conditions on node values, applied symmetrically: rows and columns of the
/// constrained dofs are zeroed with 1 on the diagonal, and b is corrected with the columns'
/// contribution (MatZeroRowsColumns). `dofs` are global (renumbered) dof indices owned by this
/// rank; `x` holds the prescribed values at those dofs (other entries are ignored).
void apply_dirichlet(Mat A, Vec b, Vec x, std::span<const PetscInt> dofs);

/// The components (per node, of block_size) that have at least one dof outside `fixed` (owned,
/// global dofs) on some rank, for create_matrix; empty when every component has (no restriction).
/// Collective.
[[nodiscard]] std::vector<int> coupled_components(const Discretization& disc, int block_size, std::span<const PetscInt> fixed);

/// Owned dofs (renumbered, global) of the given original node indices, all components.
[[nodiscard]] std::vector<PetscInt> owned_dofs_of_nodes(const Discretization& disc, std::span<const int> original_nodes,
                                                        int block_size);

/// Sets the owned entries of v (renumbered layout, block_size per node) from an array in the
/// original node order that every rank holds.
void set_from_original(const Discretization& disc, std::span<const double> original_values, int block_size, Vec v);

/// Gathers v into the original node order on every rank.
[[nodiscard]] std::vector<double> to_original(const Discretization& disc, Vec v, int block_size);

/// The rows of v this rank owns, in the original node order: their original node indices and
/// their values (block_size per row, row-major). What a collective writer needs, without a gather.
struct OwnedRows {
  std::vector<int> rows;
  std::vector<double> values;
};
[[nodiscard]] OwnedRows owned_original(const Discretization& disc, Vec v, int block_size);

}  // namespace lmeform
