// Variational differentiation (second layer of ARCHITECTURE §3) and C++/JSON emission.
#pragma once

#include <string>
#include <vector>

#include "lmeform/compiler/compile.hpp"

namespace lmeform::compiler {

/// What one output needs at one dimension over one domain: derivatives of the integrand with respect
/// to the jet slots of its row fields (unknowns or tests) and column fields (unknowns or trials);
/// for a point output, its components.
struct KernelPlan {
  const OutputDecl* output = nullptr;
  int dim = 0;
  int domain = kCellDomain;         ///< index into CompiledForm::domains
  ir::Role row_role = ir::Role::Unknown;
  ir::Role col_role = ir::Role::Unknown;
  int row_dofs = 0;                 ///< dofs per node of the rows
  int col_dofs = 0;                 ///< dofs per node of the columns (0: no matrix)
  std::vector<int> slots;           ///< union of used jet slots (the gathered basis rows), sorted
  int basis_order = 0;              ///< highest slot order of any nodal-field jet read or contracted
  int coefficient_order = 0;
  bool symmetric = false;           ///< energy/constraint Hessians
  /// Whether the kernel reads quadrature-point data. A point output that reads none can be
  /// evaluated anywhere (at a node, a probe), though its form declares data for its integrals.
  bool reads_qdata = true;
  /// A point kernel reads the local node spacing (`spacing`, requirements only).
  bool reads_spacing = false;

  ir::NodeId value = -1;            ///< energy/constraint integrand
  struct VectorEntry { int row; int slot_index; ir::NodeId node; };
  struct MatrixEntry { int row; int row_slot; int col; int col_slot; ir::NodeId node; };
  std::vector<VectorEntry> vector;  ///< non-zero ∂f/∂J_row
  std::vector<MatrixEntry> matrix;  ///< non-zero ∂²f/∂J_row∂J_col (both triangles when symmetric)
  PointValue point;                 ///< point outputs: shape and components
  bool is_point() const { return output->kind == OutputKind::Point; }
  bool has_value() const { return value >= 0; }
  bool has_vector() const { return output->kind != OutputKind::Bilinear && !is_point(); }
  bool has_matrix() const { return col_dofs > 0; }
};

/// Differentiates one output at one dimension over one of its domains (a point output: collects
/// its components). Throws CompileError (e.g. a residual not linear in v).
KernelPlan plan_kernel(const CompiledForm& form, const OutputDecl& output, int dim, int domain = kCellDomain);

struct GeneratedModule {
  std::string header;  ///< <module>_kernels.hpp
  std::string json;    ///< <module>.json
  std::string ir;      ///< --print-ir text
  std::string report;  ///< --report text: per kernel flops, jet components, lines, source line
};

GeneratedModule generate(const CompiledForm& form, const std::string& source_name);

}  // namespace lmeform::compiler
