// lmeform kernel contract: the only runtime header that generated code includes.
//
// A generated form module (`lmeformc model.form -o dir/`) defines one or more
// `FormKernels` (an energy, each constraint, a residual, ...). The runtime calls them once per
// background cell with the cell's quadrature data and basis tabulation, and scatters the
// dense local result into PETSc objects. Nothing here depends on PETSc, MPI or the parser.
//
// One output may have several FormKernels per dimension, one per integration domain: the same
// `name`, `kind` (and constraint target), told apart by `domain` and `boundary_part`. An energy
// `0.5*inner(grad(u), grad(u))*dx - dot(t, u)*ds(top)` gives one kernel over the cells and one over
// the boundary part "top"; the output is the sum of its kernels over their domains. The kernels of
// one output share the dof layout (unknowns, coefficients, qdata, constants, basis orders), so
// that the runtime can gather one cell's inputs once for all of them.
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
// * Boundary kernels (domain Boundary) are called with the quadrature points of a boundary (part)
//   and `CellInputs::normals`, the outward unit normal at each point; their weights include the
//   boundary's measure element. Everything else is as for cells: the volume fields' full jets at
//   the points, the cell's neighbourhood. Cell kernels never read `normals`.
// * Point kernels (kind Point) write, for each quadrature point q, the output's n_values
//   components (row-major, of shape point_extents[0 .. point_rank-1]) to values[q * n_values + i],
//   overwriting; they read no weights and have no derivatives. A requirement's kernel may read
//   `CellInputs::spacing` (FormKernels::reads_spacing), the local node spacing at each point.
// * Kernels allocate nothing: the runtime passes `workspace` of at least
//   `workspace_doubles(n, nq)` doubles.
// * The dense contractions with the basis (gradient = Bsᵀ G, Hessian blocks Bsᵀ D Bs) are
//   ContractionRoutines the runtime passes in CellInputs, compiled once with a BLAS-like library;
//   this header includes no library, so that a form's translation unit compiles in about a second.
#pragma once

#include <cstddef>
#include <cstring>

namespace lmeform::kernel {

inline constexpr int kContractVersion = 7;

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
  Point = 5,       ///< a value (scalar to tensor3) at each quadrature point: point kernel only
};

/// Where a kernel integrates.
enum class IntegralDomain : int {
  Cells = 0,     ///< the background cells (`dx`)
  Boundary = 1,  ///< the boundary (`ds`) or a named part of it (`ds(top)`): see boundary_part
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

/// A structurally non-zero component block of the local matrix; `mirror` adds its transpose at
/// (col, row) too (symmetric Hessians compute only the upper blocks); `symmetric`: a diagonal block
/// of a symmetric Hessian (D_q^{rr} symmetric), of which only one triangle need be computed.
struct MatrixBlock {
  int row;
  int col;
  bool mirror;
  bool symmetric;
};

/// The dense products of the generated kernels (see contract_vector / contract_matrix below for
/// their meaning). The runtime supplies an optimized implementation (lmeform/contractions.hpp);
/// without one the plain loops of this header run (same results, slower for large cells).
struct ContractionRoutines {
  void (*vector)(int n, int nq, int n_slots, int R, const double* Bs, const double* G, double* local_vector);
  void (*matrix)(int n, int nq, int n_slots, int R, int C, const double* Bs, const double* D, const MatrixBlock* blocks,
                 int n_blocks, double* work, double* local_matrix);
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
  const ContractionRoutines* contractions = nullptr;  ///< null: the plain loops of this header
  const double* normals = nullptr;     ///< [nq * dim] outward unit normals (boundary kernels; else null)
  /// [nq] the local node spacing at each point, which is a node: its distance to the nearest other
  /// node (point kernels with FormKernels::reads_spacing, i.e. requirements; else null).
  const double* spacing = nullptr;
  /// [dofs_per_node] 1 for the components whose matrix blocks are wanted, or null (all): matrix
  /// kernels skip the component blocks (r, c) with r or c not wanted (the runtime holds those
  /// components fixed, so their entries would be discarded).
  const unsigned char* coupled_components = nullptr;
};

using ValueKernel = double (*)(const CellInputs&);
using VectorKernel = void (*)(const CellInputs&, double* local_vector);
using MatrixKernel = void (*)(const CellInputs&, double* local_matrix);
using PointKernel = void (*)(const CellInputs&, double* values);
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

  // New fields go at the end of the struct, so that positional initializers of the earlier ones
  // stay valid.
  int target_constant = -1;            ///< Constraint: index into constants of the target, -1 if numeric
  double target_value = 0.0;           ///< Constraint: numeric target when target_constant < 0

  double flops_value = 0.0;            ///< per cell, as functions of n and nq: a*n*nq + b*nq ...
  double flops_vector = 0.0;           ///< (estimates for n = 1, nq = 1 scaled by the runtime)
  double flops_matrix = 0.0;

  /// Flop model of each kernel: flops(n, nq) = nq * (per_point + n*per_node_point + n*n*per_node_pair_point).
  struct FlopModel {
    double per_point = 0.0;
    double per_node_point = 0.0;
    double per_node_pair_point = 0.0;
    constexpr double operator()(int n, int nq) const noexcept {
      return nq * (per_point + n * per_node_point + double(n) * n * per_node_pair_point);
    }
  };
  /// A point output's one kernel is modelled in flops_value and flop_model_value.
  FlopModel flop_model_value{}, flop_model_vector{}, flop_model_matrix{};
  const char* source = "";             ///< the .form file the kernels were generated from
  /// The matrix kernel adds nothing (a functional linear in its unknowns, e.g. a volume):
  /// the runtime skips its assembly.
  bool matrix_structurally_zero = false;
  /// [n_constants]: the form's default of each constant, NaN where it declares none (the runtime
  /// must then be given a value).
  const double* constant_defaults = nullptr;

  IntegralDomain domain = IntegralDomain::Cells;
  const char* boundary_part = "";      ///< Boundary: the part's name, "" for the whole boundary (`ds`)
  PointKernel point = nullptr;         ///< Point: values at the quadrature points (see above)
  int n_values = 0;                    ///< Point: values per quadrature point
  int point_rank = 0;                  ///< Point: 0 scalar, 1 vector, 2 matrix, 3 tensor3
  int point_extents[3] = {0, 0, 0};    ///< Point: extent of each of the point_rank indices
  /// Point: a requirement of the model (`require CONDITION, "MESSAGE"`) instead of a value: the
  /// kernel is 1 where CONDITION holds, 0 where it fails; the runtime refuses a start that fails it.
  const char* requirement = nullptr;        ///< MESSAGE (nullptr: an ordinary point output)
  const char* requirement_condition = "";   ///< CONDITION as written
  bool requirement_pointwise = false;       ///< it reads the coordinate, the unknowns or the spacing (else only constants)
  bool reads_spacing = false;               ///< Point: reads CellInputs::spacing (a requirement on the resolution)
  bool requirement_advisory = false;        ///< `recommend`: a failure is warned of, not refused
};

/// A compiled form module: every functional it defines (each output in each declared dimension).
/// Built-in modules are linked into the runtime; a module compiled at run time (JIT) exports it
/// through the C symbol kModuleEntrySymbol, a function of type ModuleEntry.
struct ModuleTable {
  int contract_version = kContractVersion;
  const char* module = "";                     ///< the form's module name
  const char* source = "";                     ///< the .form file it was generated from
  const FormKernels* const* kernels = nullptr;
  int n_kernels = 0;
};

inline constexpr const char* kModuleEntrySymbol = "lmeform_module_table";
using ModuleEntry = const ModuleTable* (*)();

// ---- Contraction helpers used by generated kernels ----------------------------------------------
// The generated code evaluates, per quadrature point, the derivatives of the integrand with respect
// to the jet slots it uses (a dense (R*S) x (C*S) block D_q, weight included), then these helpers
// contract with the basis: gradient = Bsᵀ G and, per non-zero component block (r, c),
// H_rc = Bsᵀ (blockdiag_q D_q^{rc}) Bs, i.e. one small product per point and one product per block
// with inner dimension nq*S.

/// Gathers the used jet slots of every point's tabulation: `out` is (nq*S x n), row (q*S + i) =
/// basis row `slots[i]` of point q.
inline void gather_slots(const CellInputs& in, int dim, int n_slots, const int* slots, double* out) noexcept {
  const int n = in.n_nodes;
  const int J = jet_size(dim, in.basis_order);
  for (int q = 0; q < in.n_points; ++q)
    for (int i = 0; i < n_slots; ++i)
      std::memcpy(out + (std::size_t(q) * n_slots + i) * n, in.basis + (std::size_t(q) * J + slots[i]) * n,
                  sizeof(double) * std::size_t(n));
}

/// Workspace of contract_matrix (beyond Bs and D): nq*S*n + n*n doubles.
constexpr std::size_t contract_matrix_workspace(int n, int nq, int n_slots) noexcept {
  return std::size_t(nq) * n_slots * n + std::size_t(n) * n;
}

/// local_vector (n x R, dof-interleaved) += Bsᵀ G with Bs (nq*S x n) and G (nq*S x R). Plain loops.
inline void plain_contract_vector(int n, int nq, int n_slots, int R, const double* Bs, const double* G,
                                  double* local_vector) noexcept {
  const int rows = nq * n_slots;
  for (int k = 0; k < rows; ++k)
    for (int r = 0; r < R; ++r) {
      const double g = G[std::size_t(k) * R + r];
      if (g == 0.0) continue;
      const double* b = Bs + std::size_t(k) * n;
      for (int a = 0; a < n; ++a) local_vector[std::size_t(a) * R + r] += b[a] * g;
    }
}

/// local_matrix ((n*R) x (n*C), dof-interleaved) += Σ_q Bs_qᵀ D_q^{rc} Bs_q for every block.
/// D holds per point a row-major (R*S) x (C*S) matrix (weights included). Plain loops.
inline void plain_contract_matrix(int n, int nq, int n_slots, int R, int C, const double* Bs, const double* D,
                                  const MatrixBlock* blocks, int n_blocks, double* work, double* local_matrix) noexcept {
  const int S = n_slots;
  const std::size_t ld = std::size_t(C) * S;
  double* stacked = work;                                // (nq*S x n): D_q^{rc} Bs_q stacked
  double* block = work + std::size_t(nq) * S * n;        // (n x n)
  const std::size_t row_stride = std::size_t(R) * n * C;
  for (int b = 0; b < n_blocks; ++b) {
    const int r = blocks[b].row, c = blocks[b].col;
    for (int q = 0; q < nq; ++q) {
      const double* Dq = D + std::size_t(q) * R * S * ld + std::size_t(r) * S * ld + std::size_t(c) * S;
      const double* Bq = Bs + std::size_t(q) * S * n;
      double* out = stacked + std::size_t(q) * S * n;
      for (int i = 0; i < S; ++i) {
        double* o = out + std::size_t(i) * n;
        for (int a = 0; a < n; ++a) o[a] = 0.0;
        for (int j = 0; j < S; ++j) {
          const double d = Dq[std::size_t(i) * ld + j];
          if (d == 0.0) continue;
          const double* bj = Bq + std::size_t(j) * n;
          for (int a = 0; a < n; ++a) o[a] += d * bj[a];
        }
      }
    }
    for (std::size_t e = 0; e < std::size_t(n) * n; ++e) block[e] = 0.0;
    const bool upper_only = blocks[b].symmetric;
    for (int k = 0; k < nq * S; ++k) {
      const double* bk = Bs + std::size_t(k) * n;
      const double* sk = stacked + std::size_t(k) * n;
      for (int a = 0; a < n; ++a) {
        const double ba = bk[a];
        if (ba == 0.0) continue;
        double* h = block + std::size_t(a) * n;
        for (int e = upper_only ? a : 0; e < n; ++e) h[e] += ba * sk[e];
      }
    }
    if (upper_only)
      for (int a = 0; a < n; ++a)
        for (int e = 0; e < a; ++e) block[std::size_t(a) * n + e] = block[std::size_t(e) * n + a];
    for (int a = 0; a < n; ++a)
      for (int e = 0; e < n; ++e) {
        const double h = block[std::size_t(a) * n + e];
        local_matrix[std::size_t(r) * n * C + c + std::size_t(a) * row_stride + std::size_t(e) * C] += h;
        if (blocks[b].mirror) local_matrix[std::size_t(c) * n * C + r + std::size_t(e) * row_stride + std::size_t(a) * C] += h;
      }
  }
}

/// local_vector (n x R, dof-interleaved) += Bsᵀ G: the runtime's routine, else plain loops.
inline void contract_vector(const CellInputs& in, int n, int nq, int n_slots, int R, const double* Bs, const double* G,
                            double* local_vector) {
  if (in.contractions != nullptr) in.contractions->vector(n, nq, n_slots, R, Bs, G, local_vector);
  else plain_contract_vector(n, nq, n_slots, R, Bs, G, local_vector);
}

/// local_matrix += Σ_q Bs_qᵀ D_q^{rc} Bs_q per block: the runtime's routine, else plain loops.
inline void contract_matrix(const CellInputs& in, int n, int nq, int n_slots, int R, int C, const double* Bs,
                            const double* D, const MatrixBlock* blocks, int n_blocks, double* work, double* local_matrix) {
  MatrixBlock wanted[64];
  if (in.coupled_components != nullptr && n_blocks <= 64) {
    int kept = 0;
    for (int b = 0; b < n_blocks; ++b)
      if (in.coupled_components[blocks[b].row] != 0 && in.coupled_components[blocks[b].col] != 0) wanted[kept++] = blocks[b];
    blocks = wanted;
    n_blocks = kept;
  }
  if (in.contractions != nullptr) in.contractions->matrix(n, nq, n_slots, R, C, Bs, D, blocks, n_blocks, work, local_matrix);
  else plain_contract_matrix(n, nq, n_slots, R, C, Bs, D, blocks, n_blocks, work, local_matrix);
}

}  // namespace lmeform::kernel
