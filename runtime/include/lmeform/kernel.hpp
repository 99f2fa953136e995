// lmeform kernel contract: the only runtime header that generated code includes.
//
// A generated form module (`lmeformc model.form -o dir/`) defines one or more
// `FormKernels` (an energy, each constraint, a residual, ...). The runtime calls them once per
// background cell with the cell's quadrature data and basis tabulation, and scatters the
// dense local result into PETSc objects. Nothing here depends on PETSc, MPI or the parser.
//
// Conventions (shared by the compiler's code generator and the runtime's assembly):
//
// * Jet layout. For spatial dimension d and basis order k, one quadrature point's tabulation is a
//   (jet_size(d, k) x n) row-major block B_q, rows = jet slots, columns = cell nodes:
//     slot 0                      : value p_a
//     slots 1 .. d                : gradient dp_a/dx_i
//     slots 1+d .. jet_size-1     : Hessian d2p_a/dx_i dx_j, i <= j, in the order of
//                                   hessian_slot(i, j, d) (row-wise upper triangle).
//   The blocks of the cell's quadrature points are stacked: `basis[(q * J + s) * n + a]`,
//   so the whole cell tabulation is one (nq*J x n) row-major matrix.
// * Degrees of freedom of a cell are interleaved per node: the local index of component c of
//   unknown field f at cell node a is `a * dofs_per_node + field_offset(f) + c`
//   (fields in declaration order). Coefficients (known nodal fields) use the same layout
//   with their own `coefficient_components_per_node`.
// * Quadrature-point data: `qdata[q * qdata_per_point + offset + i]` (data in declaration
//   order, each flattened row-major).
// * Outputs are accumulated (+=): the runtime zeroes them. The local Hessian/Jacobian is
//   (n*dofs_per_node) x (n*dofs_per_node), row-major.
// * Kernels allocate nothing: the runtime passes `workspace` of at least
//   `workspace_doubles(n, nq)` doubles.
#pragma once

#include <cstddef>

namespace lmeform::kernel {

inline constexpr int kContractVersion = 1;

/// Number of jet slots of a scalar field for dimension d and derivative order k (0, 1, 2).
constexpr int jet_size(int dim, int order) noexcept {
  return order <= 0 ? 1 : order == 1 ? 1 + dim : 1 + dim + dim * (dim + 1) / 2;
}

/// Slot of the (i, j) second derivative in a point's jet (symmetric: (i, j) and (j, i) share it).
constexpr int hessian_slot(int i, int j, int dim) noexcept {
  if (i > j) { const int t = i; i = j; j = t; }
  // Row-wise upper triangle: rows 0..i-1 hold dim, dim-1, ... entries.
  return 1 + dim + i * dim - i * (i - 1) / 2 + (j - i);
}

/// What a functional is: how the runtime treats its kernels.
enum class FunctionalKind : int {
  Energy = 0,      ///< scalar E(u); kernels: value, gradient dE/du, Hessian d2E/du2
  Constraint = 1,  ///< scalar C(u) with a target; kernels: value, gradient (Hessian if generated)
  Residual = 2,    ///< vector R(u; v) for all test functions; kernels: residual, Jacobian
  Bilinear = 3,    ///< a(w, v): matrix only
  Linear = 4,      ///< l(v): vector only
};

/// A field that lives at the nodes: an unknown or a coefficient.
struct FieldInfo {
  const char* name;
  int components;   ///< 1 for scalars, dim for vectors
};

/// A quadrature-point datum (e.g. the reference phi0, grad phi0, hess phi0 of a Lagrangian form).
struct QdataInfo {
  const char* name;
  int size;         ///< flattened size per quadrature point
};

/// Everything a kernel reads for one background cell.
struct CellInputs {
  int n_nodes = 0;                     ///< nodes of the cell neighbourhood
  int n_points = 0;                    ///< quadrature points in the cell
  int basis_order = 0;                 ///< derivative order present in `basis`
  const double* weights = nullptr;     ///< [nq] quadrature weights (including the cell measure)
  const double* points = nullptr;      ///< [nq * dim] quadrature point coordinates
  const double* basis = nullptr;       ///< [nq * jet_size(dim, basis_order) * n] (see above)
  const double* unknowns = nullptr;    ///< [n * dofs_per_node] nodal values of the unknowns
  const double* coefficients = nullptr;///< [n * coefficient_components_per_node]
  const double* qdata = nullptr;       ///< [nq * qdata_per_point]
  const double* constants = nullptr;   ///< [n_constants], in declaration order
  double* workspace = nullptr;         ///< scratch, at least workspace_doubles(n, nq)
};

using ValueKernel = double (*)(const CellInputs&);
using VectorKernel = void (*)(const CellInputs&, double* local_vector);
using MatrixKernel = void (*)(const CellInputs&, double* local_matrix);
using WorkspaceSize = std::size_t (*)(int n_nodes, int n_points);

/// One generated functional: metadata plus its kernels (null where not generated).
struct FormKernels {
  int contract_version = kContractVersion;
  const char* module = "";             ///< the .form file's module name
  const char* name = "";               ///< e.g. "energy", "area", "residual"
  FunctionalKind kind = FunctionalKind::Energy;
  int dim = 0;                         ///< spatial dimension the kernel was generated for
  int basis_order = 0;                 ///< highest basis derivative order the kernels read

  const FieldInfo* unknowns = nullptr;
  int n_unknowns = 0;
  int dofs_per_node = 0;               ///< sum of the unknowns' components

  const FieldInfo* coefficients = nullptr;
  int n_coefficients = 0;
  int coefficient_components_per_node = 0;
  int coefficient_basis_order = 0;     ///< derivative order of coefficients used

  const QdataInfo* qdata = nullptr;
  int n_qdata = 0;
  int qdata_per_point = 0;

  const char* const* constants = nullptr;  ///< names, in the order of CellInputs::constants
  int n_constants = 0;

  WorkspaceSize workspace_doubles = nullptr;
  ValueKernel value = nullptr;         ///< energy / constraint value (Energy, Constraint)
  VectorKernel vector = nullptr;       ///< gradient (Energy, Constraint), residual, linear form
  MatrixKernel matrix = nullptr;       ///< Hessian (Energy), Jacobian (Residual), bilinear form

  double flops_value = 0.0;            ///< per cell, as functions of n and nq: a*n*nq + b*nq ...
  double flops_vector = 0.0;           ///< (estimates for n = 1, nq = 1 scaled by the runtime)
  double flops_matrix = 0.0;
};

}  // namespace lmeform::kernel
