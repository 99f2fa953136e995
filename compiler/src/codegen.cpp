// Variational differentiation and code generation.
//
// For each output and dimension: f = integrand (IR node). The rows/columns of the local vector and
// matrix are the jet slots J = (u, ∇u, ∇∇u) of the row/column fields; ∂f/∂J and ∂²f/∂J² are
// formed symbolically (∂f/∂J by one reverse pass over the DAG, each row of ∂²f/∂J² by a reverse pass
// over one first derivative: ir::gradient) and emitted once per quadrature point in topological
// order: each hash-consed node becomes one `const double tN = ...;` (CSE). The contraction with the
// basis goes through the kernel contract's ContractionRoutines (the runtime's dense products, or the
// contract's plain loops), so generated code includes no library.
#include <algorithm>
#include <cstdio>
#include <cmath>
#include <iomanip>
#include <map>
#include <set>
#include <sstream>
#include <unordered_map>

#include "lmeform/compiler/codegen.hpp"

namespace lmeform::compiler {
namespace {

using ir::NodeId;
using ir::Op;

ir::Role row_role_of(OutputKind k) {
  return (k == OutputKind::Energy || k == OutputKind::Constraint) ? ir::Role::Unknown : ir::Role::Test;
}

std::vector<int> field_offsets(const CompiledForm& form, ir::Role role, int dim, int* total) {
  std::vector<int> off;
  int t = 0;
  for (const auto* f : form.fields_of(role)) {
    off.push_back(t);
    t += f->components(dim);
  }
  if (total) *total = t;
  return off;
}

bool reaches_role(const ir::Graph& g, std::span<const NodeId> roots, ir::Role role, std::string* field_hint, const CompiledForm& form) {
  for (NodeId id : g.reachable(roots))
    if (g.node(id).op == Op::Jet && g.jet_var(id).role == role) {
      if (field_hint) *field_hint = form.field(role, g.jet_var(id).field).name;
      return true;
    }
  return false;
}

std::string literal(double v) {
  std::ostringstream s;
  if (std::isfinite(v) && v == std::floor(v) && std::abs(v) < 1e15) s << std::fixed << std::setprecision(1) << v;
  else s << std::setprecision(17) << v;
  std::string r = s.str();
  return v < 0 ? "(" + r + ")" : r;
}

}  // namespace

namespace {

/// A point output reads jets but has no derivatives: its plan is its components and basis orders.
KernelPlan plan_point(const CompiledForm& form, const OutputDecl& output, int dim) {
  const ir::Graph& g = *form.graphs.at(dim);
  KernelPlan plan;
  plan.output = &output;
  plan.dim = dim;
  plan.point = output.point.at(dim);
  field_offsets(form, ir::Role::Unknown, dim, &plan.row_dofs);
  plan.reads_qdata = false;
  for (NodeId id : g.reachable(plan.point.components)) {
    if (g.node(id).op == Op::Qdata) plan.reads_qdata = true;
    if (g.node(id).op == Op::Spacing) plan.reads_spacing = true;
    if (g.node(id).op != Op::Jet) continue;
    const auto v = g.jet_var(id);
    int& order = v.role == ir::Role::Coefficient ? plan.coefficient_order : plan.basis_order;
    order = std::max(order, ir::slot_order(v.slot, dim));
  }
  return plan;
}

}  // namespace

KernelPlan plan_kernel(const CompiledForm& form, const OutputDecl& output, int dim, int domain) {
  if (output.kind == OutputKind::Point) return plan_point(form, output, dim);
  ir::Graph& g = *form.graphs.at(dim);
  KernelPlan plan;
  plan.output = &output;
  plan.dim = dim;
  plan.domain = domain;
  plan.row_role = row_role_of(output.kind);
  plan.symmetric = output.kind == OutputKind::Energy || output.kind == OutputKind::Constraint;
  const bool has_cols = output.kind != OutputKind::Linear;
  plan.col_role = output.kind == OutputKind::Bilinear ? ir::Role::Trial : ir::Role::Unknown;
  const auto row_off = field_offsets(form, plan.row_role, dim, &plan.row_dofs);
  std::vector<int> col_off;
  if (has_cols) col_off = field_offsets(form, plan.col_role, dim, &plan.col_dofs);
  const NodeId f = output.integrand(dim, domain);
  if (plan.symmetric) plan.value = f;

  // The differentiation variables: jets of the row and column fields that occur in f.
  std::vector<NodeId> row_vars, col_vars;
  const NodeId froots[] = {f};
  for (NodeId id : g.reachable(froots)) {
    if (g.node(id).op != Op::Jet) continue;
    const auto v = g.jet_var(id);
    if (v.role == plan.row_role) row_vars.push_back(id);
    if (has_cols && v.role == plan.col_role) col_vars.push_back(id);
    const int order = ir::slot_order(v.slot, dim);
    if (v.role == ir::Role::Coefficient) plan.coefficient_order = std::max(plan.coefficient_order, order);
    else plan.basis_order = std::max(plan.basis_order, order);
  }
  auto by_var = [&](NodeId a, NodeId b) { return g.jet_var(a) < g.jet_var(b); };
  std::sort(row_vars.begin(), row_vars.end(), by_var);
  std::sort(col_vars.begin(), col_vars.end(), by_var);
  std::set<int> slot_set;
  for (NodeId v : row_vars) slot_set.insert(g.jet_var(v).slot);
  for (NodeId v : col_vars) slot_set.insert(g.jet_var(v).slot);
  plan.slots.assign(slot_set.begin(), slot_set.end());
  auto slot_index = [&](int slot) {
    return static_cast<int>(std::lower_bound(plan.slots.begin(), plan.slots.end(), slot) - plan.slots.begin());
  };
  auto row_of = [&](NodeId v, const std::vector<int>& off) { const auto j = g.jet_var(v); return off[static_cast<std::size_t>(j.field)] + j.component; };

  const Loc saved = g.current_origin();
  std::vector<NodeId> first(row_vars.size(), g.zero());
  for (const auto& [k, d] : ir::gradient(g, f, row_vars)) first[k] = d;
  for (std::size_t k = 0; k < row_vars.size(); ++k) {
    if (!g.is_const(first[k], 0.0))
      plan.vector.push_back({row_of(row_vars[k], row_off), slot_index(g.jet_var(row_vars[k]).slot), first[k]});
  }
  if (has_cols && plan.symmetric) {
    // Energies and constraints (rows == columns): the Hessian two ways, by edge pushing (one sweep
    // carrying second-order interactions) and by a reverse sweep over each first derivative; each
    // wins on some integrands (edge pushing on the 2D Lagrangian forms, row sweeps where long sums
    // of intermediates make the pushed interaction lists swell, the 3D Lagrangian Helfrich). Keep
    // the one whose entries need fewer operations.
    std::vector<KernelPlan::MatrixEntry> pushed, rows;
    for (const auto& e : ir::hessian(g, f, row_vars)) {
      const int r = row_of(row_vars[e.row], row_off), rs = slot_index(g.jet_var(row_vars[e.row]).slot);
      const int c = row_of(row_vars[e.col], row_off), cs = slot_index(g.jet_var(row_vars[e.col]).slot);
      pushed.push_back({r, rs, c, cs, e.node});
      if (e.row != e.col) pushed.push_back({c, cs, r, rs, e.node});
    }
    for (std::size_t k = 0; k < row_vars.size(); ++k) {
      if (g.is_const(first[k], 0.0)) continue;
      for (const auto& [l, h] : ir::gradient(g, first[k], row_vars)) {
        if (l < k || g.is_const(h, 0.0)) continue;
        const int r = row_of(row_vars[k], row_off), rs = slot_index(g.jet_var(row_vars[k]).slot);
        const int c = row_of(row_vars[l], row_off), cs = slot_index(g.jet_var(row_vars[l]).slot);
        rows.push_back({r, rs, c, cs, h});
        if (l != k) rows.push_back({c, cs, r, rs, h});
      }
    }
    auto operations = [&](const std::vector<KernelPlan::MatrixEntry>& entries) {
      std::vector<NodeId> roots;
      for (const auto& e : entries) roots.push_back(e.node);
      double count = 0;
      for (NodeId id : g.reachable(roots)) count += ir::is_terminal(g.node(id).op) ? 0 : ir::flop_cost(g.node(id).op);
      return count;
    };
    plan.matrix = operations(pushed) <= operations(rows) ? std::move(pushed) : std::move(rows);
  } else if (has_cols) {
    // Residuals and bilinear forms: each row of the Jacobian by a reverse sweep over its row.
    for (std::size_t k = 0; k < row_vars.size(); ++k) {
      if (g.is_const(first[k], 0.0)) continue;
      for (const auto& [l, h] : ir::gradient(g, first[k], col_vars)) {
        if (g.is_const(h, 0.0)) continue;
        const int r = row_of(row_vars[k], row_off), rs = slot_index(g.jet_var(row_vars[k]).slot);
        const int c = row_of(col_vars[l], col_off), cs = slot_index(g.jet_var(col_vars[l]).slot);
        plan.matrix.push_back({r, rs, c, cs, h});
      }
    }
  }
  g.set_origin(saved);

  // Linearity in test/trial functions: their jets must be gone after differentiation.
  std::vector<NodeId> vroots, mroots;
  for (const auto& e : plan.vector) vroots.push_back(e.node);
  for (const auto& e : plan.matrix) mroots.push_back(e.node);
  std::string field;
  const std::string what = std::string(to_string(output.kind)) + " '" + output.name + "'";
  if (output.kind == OutputKind::Residual || output.kind == OutputKind::Linear || output.kind == OutputKind::Bilinear) {
    if (reaches_role(g, vroots, ir::Role::Test, &field, form) || reaches_role(g, mroots, ir::Role::Test, &field, form))
      fail_at(form.sources, output.loc, what + " is not linear in the test function '" + field + "'");
  }
  if (output.kind == OutputKind::Bilinear && reaches_role(g, mroots, ir::Role::Trial, &field, form))
    fail_at(form.sources, output.loc, what + " is not linear in the trial function '" + field + "'");
  // For a bilinear form plan.vector holds ∂f/∂v (still linear in the trial function): the
  // intermediate of the matrix; no vector kernel is generated for it.
  return plan;
}

namespace {

/// Emits the body of one kernel: per-point evaluation of a set of roots, with assignments.
class KernelWriter {
 public:
  KernelWriter(const CompiledForm& form, const KernelPlan& plan) : form_(form), plan_(plan), g_(*form.graphs.at(plan.dim)) {}

  std::string ref(NodeId id) const {
    const ir::Node& n = g_.node(id);
    switch (n.op) {
      case Op::Const: return literal(n.value);
      case Op::Jet: {
        const auto v = g_.jet_var(id);
        return std::string(v.role == ir::Role::Coefficient ? "c" : v.role == ir::Role::Unknown ? "u" : "v") +
               std::to_string(v.field) + "_" + std::to_string(v.component) + "_s" + std::to_string(v.slot);
      }
      case Op::Coord: return "x_" + std::to_string(n.arg[0]);
      case Op::Param: return "k_" + std::to_string(n.arg[0]);
      case Op::Qdata: return "qd_" + std::to_string(n.arg[0]);
      case Op::Normal: return "nrm_" + std::to_string(n.arg[0]);
      case Op::Spacing: return "spc";
      default: {
        if (const auto it = inlined_.find(id); it != inlined_.end()) return "(" + it->second + ")";
        return "t" + std::to_string(id);
      }
    }
  }

  std::string expression(NodeId id) const {
    const ir::Node& n = g_.node(id);
    auto A = [&](int k) { return ref(n.arg[static_cast<std::size_t>(k)]); };
    switch (n.op) {
      case Op::Add: return A(0) + " + " + A(1);
      case Op::Mul: return A(0) + " * " + A(1);
      case Op::Neg: return "-" + A(0);
      case Op::Div: return A(0) + " / " + A(1);
      case Op::Pow: {
        const ir::Node& e = g_.node(n.arg[1]);
        if (e.op == Op::Const) {
          if (e.value == 2.0) return A(0) + " * " + A(0);
          if (e.value == 3.0) return A(0) + " * " + A(0) + " * " + A(0);
          if (e.value == 4.0) return "(" + A(0) + " * " + A(0) + ") * (" + A(0) + " * " + A(0) + ")";
          if (e.value == -1.0) return "1.0 / " + A(0);
          if (e.value == -2.0) return "1.0 / (" + A(0) + " * " + A(0) + ")";
        }
        return "std::pow(" + A(0) + ", " + A(1) + ")";
      }
      case Op::Sqrt: return "std::sqrt(" + A(0) + ")";
      case Op::Exp: return "std::exp(" + A(0) + ")";
      case Op::Log: return "std::log(" + A(0) + ")";
      case Op::Sin: return "std::sin(" + A(0) + ")";
      case Op::Cos: return "std::cos(" + A(0) + ")";
      case Op::Tanh: return "std::tanh(" + A(0) + ")";
      case Op::Abs: return "std::abs(" + A(0) + ")";
      case Op::Sign: return "(" + A(0) + " > 0.0 ? 1.0 : (" + A(0) + " < 0.0 ? -1.0 : 0.0))";
      case Op::Select: return "(" + A(0) + " != 0.0 ? " + A(1) + " : " + A(2) + ")";
      case Op::Lt: return "(" + A(0) + " < " + A(1) + " ? 1.0 : 0.0)";
      case Op::Le: return "(" + A(0) + " <= " + A(1) + " ? 1.0 : 0.0)";
      case Op::Gt: return "(" + A(0) + " > " + A(1) + " ? 1.0 : 0.0)";
      case Op::Ge: return "(" + A(0) + " >= " + A(1) + " ? 1.0 : 0.0)";
      case Op::Eq: return "(" + A(0) + " == " + A(1) + " ? 1.0 : 0.0)";
      case Op::Ne: return "(" + A(0) + " != " + A(1) + " ? 1.0 : 0.0)";
      case Op::And: return "((" + A(0) + " != 0.0 && " + A(1) + " != 0.0) ? 1.0 : 0.0)";
      case Op::Or: return "((" + A(0) + " != 0.0 || " + A(1) + " != 0.0) ? 1.0 : 0.0)";
      case Op::Not: return "(" + A(0) + " == 0.0 ? 1.0 : 0.0)";
      default: return ref(id);
    }
  }

  /// Writes the quadrature loop: terminals, nodes, then `sink(os)` for the outputs; `weighted`:
  /// the loop reads the weight w (point kernels do not, and may be given none).
  /// Returns the flop estimate per point and the number of nodal jets evaluated.
  std::pair<double, int> point_loop(std::ostream& os, const std::vector<NodeId>& roots, const std::string& sink,
                                    bool weighted = true) {
    const auto order = g_.reachable(roots);
    // A node used once, by another node, is written into its user's expression rather than as a
    // temporary of its own (up to kInlineDepth levels): fewer lines to parse, the same operations.
    constexpr int kInlineDepth = 4;
    inlined_.clear();
    std::unordered_map<NodeId, int> uses, depth;
    for (NodeId id : order) {
      const ir::Node& n = g_.node(id);
      if (ir::is_terminal(n.op)) continue;
      for (NodeId c : n.arg)
        if (c >= 0) ++uses[c];
    }
    for (NodeId r : roots) uses[r] += 2;  // the sink names every root
    std::set<int> params;
    std::vector<NodeId> jets;
    std::set<int> coords, qdata, normals;
    bool spacing = false;
    double flops = 0;
    for (NodeId id : order) {
      const ir::Node& n = g_.node(id);
      if (n.op == Op::Param) params.insert(n.arg[0]);
      if (n.op == Op::Coord) coords.insert(n.arg[0]);
      if (n.op == Op::Qdata) qdata.insert(n.arg[0]);
      if (n.op == Op::Normal) normals.insert(n.arg[0]);
      if (n.op == Op::Spacing) spacing = true;
      if (n.op == Op::Jet) jets.push_back(id);
      flops += ir::flop_cost(n.op);
    }
    for (int p : params) os << "  const double k_" << p << " = in.constants[" << p << "];\n";
    os << "  for (int q = 0; q < nq; ++q) {\n";
    if (weighted) os << "    [[maybe_unused]] const double w = in.weights[q];\n";
    os << "    [[maybe_unused]] const double* Bq = in.basis + std::size_t(q) * std::size_t(J) * std::size_t(n);\n";
    for (int c : coords) os << "    const double x_" << c << " = in.points[std::size_t(q) * " << plan_.dim << " + " << c << "];\n";
    for (int i : normals) os << "    const double nrm_" << i << " = in.normals[std::size_t(q) * " << plan_.dim << " + " << i << "];\n";
    if (spacing) os << "    const double spc = in.spacing[q];\n";
    const int qpp = form_.qdata_per_point(plan_.dim);
    for (int o : qdata) os << "    const double qd_" << o << " = in.qdata[std::size_t(q) * " << qpp << " + " << o << "];\n";
    if (!jets.empty()) {
      int udofs = 0, cdofs = 0;
      const auto uoff = field_offsets(form_, ir::Role::Unknown, plan_.dim, &udofs);
      const auto coff = field_offsets(form_, ir::Role::Coefficient, plan_.dim, &cdofs);
      os << "    // jets of the nodal fields at the point: J = B_q u (only the slots used)\n    double";
      for (std::size_t i = 0; i < jets.size(); ++i) os << (i ? ", " : " ") << ref(jets[i]) << " = 0.0";
      os << ";\n    for (int a = 0; a < n; ++a) {\n";
      bool need_u = false, need_c = false;
      for (NodeId j : jets) (g_.jet_var(j).role == ir::Role::Coefficient ? need_c : need_u) = true;
      if (need_u) os << "      const double* ua = in.unknowns + std::size_t(a) * " << udofs << ";\n";
      if (need_c) os << "      const double* ca = in.coefficients + std::size_t(a) * " << cdofs << ";\n";
      for (NodeId j : jets) {
        const auto v = g_.jet_var(j);
        const bool coef = v.role == ir::Role::Coefficient;
        const int dof = (coef ? coff : uoff)[static_cast<std::size_t>(v.field)] + v.component;
        os << "      " << ref(j) << " += Bq[" << v.slot << " * n + a] * " << (coef ? "ca" : "ua") << "[" << dof << "];\n";
      }
      os << "    }\n";
    }
    int last_line = -1, last_file = -2;
    for (NodeId id : order) {
      const ir::Node& n = g_.node(id);
      if (ir::is_terminal(n.op)) continue;
      const Loc& o = g_.origin(id);
      if (o.file >= 0) {
        const int line = form_.sources.line_col(o).first;
        if (line != last_line || o.file != last_file) {
          std::string text = form_.sources.line_text(o);
          text.erase(0, text.find_first_not_of(" \t"));
          if (text.size() > 90) text = text.substr(0, 87) + "...";
          os << "    // " << form_.sources.file(o.file).path.filename().string() << ":" << line << ": " << text << "\n";
          last_line = line;
          last_file = o.file;
        }
      }
      int d = 1;
      for (NodeId c : n.arg)
        if (c >= 0 && inlined_.contains(c)) d = std::max(d, depth[c] + 1);
      if (uses[id] == 1 && d <= kInlineDepth) {
        inlined_.emplace(id, expression(id));
        depth[id] = d;
        continue;
      }
      os << "    const double t" << id << " = " << expression(id) << ";\n";
    }
    os << sink << "  }\n";
    inlined_.clear();
    return {flops, static_cast<int>(jets.size())};
  }

 private:
  const CompiledForm& form_;
  const KernelPlan& plan_;
  const ir::Graph& g_;
  std::unordered_map<NodeId, std::string> inlined_;  ///< nodes written into their single user
};

std::string json_escape(const std::string& s) {
  std::string o;
  for (char c : s) {
    if (c == '"' || c == '\\') o += '\\';
    if (c == '\n') { o += "\\n"; continue; }
    o += c;
  }
  return o;
}

struct FlopModel {
  double per_point = 0, per_node_point = 0, per_node_pair_point = 0;
};

struct EmittedKernel {
  std::string symbol;
  KernelPlan plan;
  FlopModel value, vector, matrix, point;
  bool has_value = false, has_vector = false, has_matrix = false;
  int n_blocks = 0;
  int line = 0;
  long generated_lines = 0;  ///< lines of this kernel's functions in the header
};

long count_lines(const std::string& text, std::size_t from) {
  return static_cast<long>(std::count(text.begin() + static_cast<std::ptrdiff_t>(from), text.end(), '\n'));
}

/// "phi", "y[1]": the field and component of a row of the plan.
std::string row_name(const CompiledForm& form, const KernelPlan& p, int row) {
  int offset = 0;
  for (const auto* f : form.fields_of(p.row_role)) {
    const int c = f->components(p.dim);
    if (row < offset + c) return c == 1 ? f->name : f->name + "[" + std::to_string(row - offset) + "]";
    offset += c;
  }
  return "?";
}

/// "value", "d/dx0", "d2/dx0dx1": the derivative a jet slot holds.
std::string slot_name(int slot, int dim) {
  if (slot == 0) return "value";
  if (slot <= dim) return "d/dx" + std::to_string(slot - 1);
  for (int i = 0; i < dim; ++i)
    for (int j = i; j < dim; ++j)
      if (1 + dim + i * dim - i * (i - 1) / 2 + (j - i) == slot)  // the contract's hessian_slot(i, j, dim)
        return "d2/dx" + std::to_string(i) + "dx" + std::to_string(j);
  return "slot" + std::to_string(slot);
}

/// "energy E", or "energy E [ds(top)]" for a kernel of an output integrated over several domains.
std::string kernel_label(const CompiledForm& form, const KernelPlan& p) {
  std::string s = std::string(to_string(p.output->kind)) + " " + p.output->name;
  const auto terms = p.output->integrands.find(p.dim);
  if (p.domain != kCellDomain || (terms != p.output->integrands.end() && terms->second.size() > 1))
    s += " [" + form.domains[static_cast<std::size_t>(p.domain)].measure() + "]";
  return s;
}

/// "scalar", "vector[3]", "tensor3[2x2x2]": the shape of a point output.
std::string point_shape_name(const std::vector<int>& shape) {
  static const char* names[] = {"scalar", "vector", "matrix", "tensor3"};
  std::string s = names[shape.size()];
  for (std::size_t i = 0; i < shape.size(); ++i) {
    s += i == 0 ? '[' : 'x';
    s += std::to_string(shape[i]);
  }
  return shape.empty() ? s : s + "]";
}

std::size_t point_values(const KernelPlan& p) { return p.point.components.size(); }

/// The per-kernel cost report of `lmeformc --report`.
std::string cost_report(const CompiledForm& form, const std::vector<EmittedKernel>& kernels, long total_lines) {
  std::ostringstream r;
  r << "cost report of form " << form.module << " (" << total_lines << " generated lines)\n"
    << "  flops per quadrature point from the generated expression DAG (after CSE); H/v = Hessian / value,\n"
    << "  bound 16 m = m reverse passes of <= 4x the gradient (m jet components); contraction share: of the\n"
    << "  Hessian kernel's flops on a cell of n = 30 (2D) / 60 (3D) nodes and 6 / 14 points, the part in\n"
    << "  the basis contractions (B_q^T D_q B_q) rather than in the point-wise derivatives\n";
  for (const auto& k : kernels) {
    const KernelPlan& p = k.plan;
    r << "\n" << kernel_label(form, p) << ", dimension " << p.dim << " (" << form.sources.where(p.output->loc)
      << "): " << k.generated_lines << " generated lines\n";
    std::string src = form.sources.line_text(p.output->loc);
    if (src.size() > 100) src = src.substr(0, 97) + "...";
    r << "  | " << src << "\n";
    if (p.is_point()) {
      r << "  point values: " << point_values(p) << " per point (" << point_shape_name(p.point.shape)
        << "); flops/point " << static_cast<long>(k.point.per_point) << "\n";
      continue;
    }
    r << "  jet components (m = " << p.vector.size() << "):";
    for (std::size_t e = 0; e < p.vector.size(); ++e)
      r << (e ? ", " : " ") << row_name(form, p, p.vector[e].row) << " " << slot_name(p.slots[static_cast<std::size_t>(p.vector[e].slot_index)], p.dim);
    r << "\n";
    char line[256];
    std::snprintf(line, sizeof line, "  flops/point: value %s, gradient %s, Hessian %s",
                  k.has_value ? std::to_string(static_cast<long>(k.value.per_point)).c_str() : "-",
                  k.has_vector ? std::to_string(static_cast<long>(k.vector.per_point)).c_str() : "-",
                  k.has_matrix ? std::to_string(static_cast<long>(k.matrix.per_point)).c_str() : "-");
    r << line;
    if (k.has_value && k.value.per_point > 0) {
      if (k.has_vector && k.vector.per_point > 0) {
        std::snprintf(line, sizeof line, "; g/v %.2f (bound 4)", k.vector.per_point / k.value.per_point);
        r << line;
      }
      if (k.has_matrix && k.matrix.per_point > 0) {
        std::snprintf(line, sizeof line, "; H/v %.2f (bound %zu)", k.matrix.per_point / k.value.per_point, 16 * p.vector.size());
        r << line;
      }
    }
    r << "\n";
    if (k.has_matrix) {
      const double n = p.dim == 3 ? 60 : 30, nq = p.dim == 3 ? 14 : 6;
      const int S = static_cast<int>(p.slots.size());
      const double contraction = nq * (n * 2.0 * S * S * k.n_blocks + n * n * k.matrix.per_node_pair_point);
      const double total = nq * (k.matrix.per_point + n * k.matrix.per_node_point + n * n * k.matrix.per_node_pair_point);
      std::snprintf(line, sizeof line, "  Hessian on a cell: %.3g flops, %.0f %% in the contractions (%d slots, %d blocks)\n", total,
                    total > 0 ? 100.0 * contraction / total : 0.0, S, k.n_blocks);
      r << line;
    }
  }
  return r.str();
}

std::string flop_json(const FlopModel& f) {
  std::ostringstream s;
  s << "{\"per_point\": " << f.per_point << ", \"per_node_point\": " << f.per_node_point
    << ", \"per_node_pair_point\": " << f.per_node_pair_point << "}";
  return s.str();
}

std::string flop_cxx(const FlopModel& f) {
  std::ostringstream s;
  s << "{" << f.per_point << ", " << f.per_node_point << ", " << f.per_node_pair_point << "}";
  return s.str();
}

/// The C++ name of a kernel: `<output>_<D>d` over the cells, `<output>_ds[_<part>]_<D>d` on the boundary.
std::string kernel_symbol(const CompiledForm& form, const OutputDecl& output, int dim, int domain) {
  const Domain& d = form.domains[static_cast<std::size_t>(domain)];
  std::string s = output.name;
  if (d.boundary) s += d.part.empty() ? std::string("_ds") : "_ds_" + d.part;
  return s + "_" + std::to_string(dim) + "d";
}

/// Writes the header, IR dump and metadata of one module, kernel by kernel.
class ModuleWriter {
 public:
  ModuleWriter(const CompiledForm& form, const std::string& source_name)
      : form_(form), source_(source_name), m_(form.module) {}

  GeneratedModule run() {
    preamble();
    for (const auto& output : form_.outputs)
      for (int dim : form_.dims) {
        if (output.kind == OutputKind::Point) kernel(output, dim, kCellDomain);
        else
          for (const auto& [domain, f] : output.integrands.at(dim)) kernel(output, dim, domain);
      }
    h_ << "}  // namespace " << m_ << "_detail\n\n";
    require_distinct_symbols();
    for (const auto& k : kernels_) descriptor(k);
    module_table();
    GeneratedModule out;
    out.header = h_.str();
    out.ir = ir_.str();
    out.json = json();
    out.report = cost_report(form_, kernels_, static_cast<long>(std::count(out.header.begin(), out.header.end(), '\n')));
    return out;
  }

 private:
  const CompiledForm& form_;
  const std::string& source_;
  const std::string& m_;
  std::ostringstream h_, ir_;
  std::vector<EmittedKernel> kernels_;

  std::string fields_array(ir::Role role, int dim) const {
    std::ostringstream s;
    for (const auto* f : form_.fields_of(role)) s << "{\"" << f->name << "\", " << f->components(dim) << "}, ";
    return s.str();
  }

  void preamble() {
    h_ << "// Generated by lmeformc from " << source_ << " -- do not edit.\n"
       << "// Every kernel block below carries `// file:line: source` comments mapping it back to the form.\n"
       << "#pragma once\n\n#include <cmath>\n#include <cstddef>\n\n#include <lmeform/kernel.hpp>\n\n"
       << "namespace " << m_ << "_detail {\n\n";
    for (int dim : form_.dims) {
      static const std::pair<ir::Role, const char*> roles[] = {{ir::Role::Unknown, "unknowns"}, {ir::Role::Test, "tests"},
                                                               {ir::Role::Trial, "trials"}, {ir::Role::Coefficient, "coefficients"}};
      for (const auto& [role, nm] : roles)
        if (!form_.fields_of(role).empty())
          h_ << "inline constexpr lmeform::kernel::FieldInfo " << nm << "_" << dim << "d[] = {" << fields_array(role, dim) << "};\n";
      if (!form_.qdata.empty()) {
        h_ << "inline constexpr lmeform::kernel::QdataInfo qdata_" << dim << "d[] = {";
        for (const auto& q : form_.qdata) h_ << "{\"" << q.name << "\", " << q.size(dim) << "}, ";
        h_ << "};\n";
      }
    }
    if (!form_.constants.empty()) {
      h_ << "inline constexpr const char* constant_names[] = {";
      for (const auto& c : form_.constants) h_ << "\"" << c.name << "\", ";
      h_ << "};\n";
      h_ << "inline const double constant_defaults[] = {";
      for (const auto& c : form_.constants) {
        if (c.default_value) h_ << literal(*c.default_value) << ", ";
        else h_ << "__builtin_nan(\"\"), ";
      }
      h_ << "};\n";
    }
    h_ << "\n";
  }

  static std::string head(int dim) {
    return "  const int n = in.n_nodes;\n  const int nq = in.n_points;\n"
           "  [[maybe_unused]] const int J = lmeform::kernel::jet_size(" + std::to_string(dim) + ", in.basis_order);\n";
  }

  std::string slot_list(const KernelPlan& p) const {
    std::ostringstream slots;
    for (std::size_t i = 0; i < p.slots.size(); ++i) slots << (i ? ", " : "") << p.slots[i];
    return slots.str();
  }

  void dump(const KernelWriter& w, int dim, const std::vector<NodeId>& roots) {
    const ir::Graph& g = *form_.graphs.at(dim);
    auto terminal_name = [&](NodeId id) { return w.ref(id); };
    for (NodeId id : g.reachable(roots))
      if (!ir::is_terminal(g.node(id).op)) ir_ << "  " << ir::describe(g, id, terminal_name) << "\n";
  }

  /// The kernels of one output over one domain in one dimension.
  void kernel(const OutputDecl& output, int dim, int domain) {
    EmittedKernel k;
    const std::size_t kernel_start = h_.tellp() < 0 ? 0 : static_cast<std::size_t>(h_.tellp());
    k.plan = plan_kernel(form_, output, dim, domain);
    const KernelPlan& p = k.plan;
    k.symbol = kernel_symbol(form_, output, dim, domain);
    k.line = form_.sources.line_col(output.loc).first;
    KernelWriter w(form_, p);
    h_ << "// ---- " << kernel_label(form_, p) << ", dimension " << dim << " (" << form_.sources.where(output.loc) << ")\n";
    ir_ << "== " << kernel_label(form_, p) << " (dim " << dim << "): slots {" << slot_list(p) << "}\n";
    if (p.is_point()) {
      point_kernel(k, w);
    } else {
      if (p.has_value()) value_kernel(k, w);
      if (p.has_vector()) vector_kernel(k, w);
      if (p.has_matrix()) matrix_kernel(k, w);
    }
    workspace(k);
    k.generated_lines = count_lines(h_.str(), kernel_start);
    kernels_.push_back(std::move(k));
  }

  void value_kernel(EmittedKernel& k, KernelWriter& w) {
    const KernelPlan& p = k.plan;
    k.has_value = true;
    h_ << "inline double " << k.symbol << "_value(const lmeform::kernel::CellInputs& in) {\n" << head(p.dim)
       << "  double result = 0.0;\n";
    const auto [fl, nj] = w.point_loop(h_, {p.value}, "    result += w * " + w.ref(p.value) + ";\n");
    h_ << "  return result;\n}\n\n";
    k.value = {fl + 2, 2.0 * nj, 0};
    ir_ << " value:\n";
    dump(w, p.dim, {p.value});
    ir_ << "  f = " << w.ref(p.value) << "\n";
  }

  void vector_kernel(EmittedKernel& k, KernelWriter& w) {
    const KernelPlan& p = k.plan;
    const int S = static_cast<int>(p.slots.size()), R = p.row_dofs;
    k.has_vector = true;
    h_ << "inline void " << k.symbol << "_vector(const lmeform::kernel::CellInputs& in, double* local_vector) {\n";
    if (S == 0) {
      // The integrand reads no row field (a boundary term constant in the unknowns): nothing to add.
      h_ << "  (void)in;\n  (void)local_vector;\n}\n\n";
      return;
    }
    std::vector<NodeId> roots;
    std::ostringstream sink;
    sink << "    double* Gq = G + std::size_t(q) * " << S * R << ";\n";
    for (const auto& e : p.vector) {
      roots.push_back(e.node);
      sink << "    Gq[" << e.slot_index * R + e.row << "] = w * " << w.ref(e.node) << ";\n";
    }
    h_ << head(p.dim) << "  static constexpr int slots[] = {" << slot_list(p) << "};\n"
       << "  double* Bs = in.workspace;  // gathered basis rows (nq*S x n)\n"
       << "  double* G = Bs + std::size_t(nq) * " << S << " * std::size_t(n);  // w_q df/dJ (nq*S x R)\n"
       << "  for (std::size_t i = 0; i < std::size_t(nq) * " << S * R << "; ++i) G[i] = 0.0;\n";
    const auto [fl, nj] = w.point_loop(h_, roots, sink.str());
    h_ << "  lmeform::kernel::gather_slots(in, " << p.dim << ", " << S << ", slots, Bs);\n"
       << "  lmeform::kernel::contract_vector(in, n, nq, " << S << ", " << R << ", Bs, G, local_vector);\n}\n\n";
    k.vector = {fl + static_cast<double>(p.vector.size()), 2.0 * nj + 2.0 * S * R, 0};
    ir_ << " vector (df/dJ):\n";
    dump(w, p.dim, roots);
    for (const auto& e : p.vector)
      ir_ << "  df/dJ[row " << e.row << ", slot " << p.slots[static_cast<std::size_t>(e.slot_index)] << "] = " << w.ref(e.node) << "\n";
  }

  void matrix_kernel(EmittedKernel& k, KernelWriter& w) {
    const KernelPlan& p = k.plan;
    const int S = static_cast<int>(p.slots.size()), R = p.row_dofs, C = p.col_dofs;
    k.has_matrix = true;
    std::vector<NodeId> roots;
    std::ostringstream sink;
    const int ld = C * S;
    sink << "    double* Dq = D + std::size_t(q) * " << R * S * ld << ";\n";
    std::set<std::pair<int, int>> blocks;
    for (const auto& e : p.matrix) {
      roots.push_back(e.node);
      blocks.insert({e.row, e.col});
    }
    // Symmetric forms: emit only the upper blocks' entries and mirror them in the contraction.
    for (const auto& e : p.matrix) {
      if (p.symmetric && e.row > e.col) continue;
      sink << "    Dq[" << (e.row * S + e.row_slot) * ld + e.col * S + e.col_slot << "] = w * " << w.ref(e.node) << ";\n";
    }
    std::ostringstream bl;
    int nb = 0;
    for (const auto& [r, c] : blocks) {
      if (p.symmetric && r > c) continue;
      bl << "{" << r << ", " << c << ", " << (p.symmetric && r != c ? "true" : "false") << ", "
         << (p.symmetric && r == c ? "true" : "false") << "}, ";
      ++nb;
    }
    k.n_blocks = nb;
    double matrix_point_flops = 0;
    int matrix_jets = 0;
    const std::size_t dsize = static_cast<std::size_t>(R) * S * ld;
    h_ << "inline void " << k.symbol << "_matrix(const lmeform::kernel::CellInputs& in, double* local_matrix) {\n";
    if (nb == 0) {
      // Structurally zero (e.g. a functional linear in the unknowns): nothing to accumulate.
      h_ << "  (void)in;\n  (void)local_matrix;\n}\n\n";
    } else {
      h_ << head(p.dim) << "  static constexpr int slots[] = {" << slot_list(p) << "};\n"
         << "  static constexpr lmeform::kernel::MatrixBlock blocks[] = {" << bl.str() << "};\n"
         << "  double* Bs = in.workspace;  // gathered basis rows (nq*S x n)\n"
         << "  double* D = Bs + std::size_t(nq) * " << S << " * std::size_t(n);  // w_q d2f/dJ2 per point\n"
         << "  double* work = D + std::size_t(nq) * " << dsize << ";\n"
         << "  for (std::size_t i = 0; i < std::size_t(nq) * " << dsize << "; ++i) D[i] = 0.0;\n";
      const auto [fl, nj] = w.point_loop(h_, roots, sink.str());
      h_ << "  lmeform::kernel::gather_slots(in, " << p.dim << ", " << S << ", slots, Bs);\n"
         << "  lmeform::kernel::contract_matrix(in, n, nq, " << S << ", " << R << ", " << C
         << ", Bs, D, blocks, " << nb << ", work, local_matrix);\n}\n\n";
      matrix_point_flops = fl;
      matrix_jets = nj;
    }
    const double mirror_blocks = static_cast<double>(blocks.size());
    k.matrix = {matrix_point_flops + static_cast<double>(p.matrix.size()), 2.0 * matrix_jets + 2.0 * S * S * nb,
                2.0 * S * nb + (mirror_blocks - nb)};
    ir_ << " matrix (d2f/dJ2):\n";
    dump(w, p.dim, roots);
    for (const auto& e : p.matrix)
      ir_ << "  d2f/dJ2[row " << e.row << " slot " << p.slots[static_cast<std::size_t>(e.row_slot)] << ", col " << e.col << " slot "
          << p.slots[static_cast<std::size_t>(e.col_slot)] << "] = " << w.ref(e.node) << "\n";
  }

  /// values[q * n_values + i] = component i (row-major) at point q: overwritten, no weights.
  void point_kernel(EmittedKernel& k, KernelWriter& w) {
    const KernelPlan& p = k.plan;
    const std::size_t nv = point_values(p);
    std::ostringstream sink;
    sink << "    double* vq = values + std::size_t(q) * " << nv << ";\n";
    for (std::size_t i = 0; i < nv; ++i) sink << "    vq[" << i << "] = " << w.ref(p.point.components[i]) << ";\n";
    h_ << "inline void " << k.symbol << "_point(const lmeform::kernel::CellInputs& in, double* values) {\n" << head(p.dim);
    const auto [fl, nj] = w.point_loop(h_, p.point.components, sink.str(), false);
    h_ << "}\n\n";
    k.point = {fl, 2.0 * nj, 0};
    ir_ << " point values:\n";
    dump(w, p.dim, p.point.components);
    for (std::size_t i = 0; i < nv; ++i) ir_ << "  value[" << i << "] = " << w.ref(p.point.components[i]) << "\n";
  }

  /// Workspace: the larger of the vector and matrix kernels' needs (point kernels need none).
  void workspace(const EmittedKernel& k) {
    const KernelPlan& p = k.plan;
    if (p.is_point()) {
      h_ << "inline std::size_t " << k.symbol << "_workspace(int, int) { return 0; }\n\n";
      return;
    }
    const int S = static_cast<int>(p.slots.size()), R = p.row_dofs, C = p.col_dofs;
    const std::size_t dsize = static_cast<std::size_t>(R) * S * C * S;
    h_ << "inline std::size_t " << k.symbol << "_workspace(int n, int nq) {\n"
       << "  const std::size_t N = std::size_t(n), Q = std::size_t(nq);\n"
       << "  const std::size_t vec = Q * " << S << " * N + Q * " << S * R << ";\n"
       << "  const std::size_t mat = " << (p.has_matrix() ? "Q * " + std::to_string(S) + " * N + Q * " + std::to_string(dsize) +
                                                                 " + lmeform::kernel::contract_matrix_workspace(n, nq, " + std::to_string(S) + ")"
                                                           : std::string("0"))
       << ";\n  return vec > mat ? vec : mat;\n}\n\n";
  }

  /// Output names are free, so `E` over ds and an output named `E_ds` could collide: refuse it.
  void require_distinct_symbols() const {
    std::map<std::string, const OutputDecl*> seen;
    for (const auto& k : kernels_) {
      const auto [it, fresh] = seen.emplace(k.symbol, k.plan.output);
      if (!fresh)
        fail_at(form_.sources, k.plan.output->loc,
                "the kernels of " + kernel_label(form_, k.plan) + " and of " + to_string(it->second->kind) + " '" +
                    it->second->name + "' would both be named '" + m_ + "_" + k.symbol + "'; rename one of the outputs");
    }
  }

  /// The basis orders of an output's kernels in one dimension: the largest over its domains, so
  /// that every kernel of the output reads one tabulation and dof layout.
  std::pair<int, int> output_orders(const KernelPlan& p) const {
    std::pair<int, int> orders{0, 0};
    for (const auto& k : kernels_)
      if (k.plan.output == p.output && k.plan.dim == p.dim) {
        orders.first = std::max(orders.first, k.plan.basis_order);
        orders.second = std::max(orders.second, k.plan.coefficient_order);
      }
    return orders;
  }

  void descriptor(const EmittedKernel& k);
  void module_table();
  std::string json() const;
  std::string kernel_json(const EmittedKernel& k) const;
};

void ModuleWriter::descriptor(const EmittedKernel& k) {
  const KernelPlan& p = k.plan;
  const int dim = p.dim;
  const ir::Role urole = p.output->kind == OutputKind::Bilinear ? ir::Role::Trial
                       : p.output->kind == OutputKind::Linear   ? ir::Role::Test : ir::Role::Unknown;
  const char* unm = urole == ir::Role::Trial ? "trials" : urole == ir::Role::Test ? "tests" : "unknowns";
  int udofs = 0, cdofs = 0;
  field_offsets(form_, urole, dim, &udofs);
  field_offsets(form_, ir::Role::Coefficient, dim, &cdofs);
  static const char* kinds[] = {"Energy", "Constraint", "Residual", "Bilinear", "Linear", "Point"};
  const auto [basis_order, coefficient_order] = output_orders(p);
  const Domain& domain = form_.domains[static_cast<std::size_t>(p.domain)];
  const std::string d = m_ + "_detail::";
  h_ << "inline const lmeform::kernel::FormKernels " << m_ << "_" << k.symbol << " = [] {\n"
     << "  lmeform::kernel::FormKernels k;\n"
     << "  k.module = \"" << m_ << "\";\n  k.name = \"" << p.output->name << "\";\n"
     << "  k.kind = lmeform::kernel::FunctionalKind::" << kinds[static_cast<int>(p.output->kind)] << ";\n"
     << "  k.dim = " << dim << ";\n  k.basis_order = " << basis_order << ";\n";
  if (!form_.fields_of(urole).empty())
    h_ << "  k.unknowns = " << d << unm << "_" << dim << "d;\n  k.n_unknowns = " << form_.fields_of(urole).size() << ";\n";
  h_ << "  k.dofs_per_node = " << udofs << ";\n";
  if (!form_.fields_of(ir::Role::Coefficient).empty())
    h_ << "  k.coefficients = " << d << "coefficients_" << dim << "d;\n  k.n_coefficients = "
       << form_.fields_of(ir::Role::Coefficient).size() << ";\n";
  h_ << "  k.coefficient_components_per_node = " << cdofs << ";\n  k.coefficient_basis_order = " << coefficient_order << ";\n";
  if (!form_.qdata.empty() && p.reads_qdata)
    h_ << "  k.qdata = " << d << "qdata_" << dim << "d;\n  k.n_qdata = " << form_.qdata.size() << ";\n";
  h_ << "  k.qdata_per_point = " << (p.reads_qdata ? form_.qdata_per_point(dim) : 0) << ";\n";
  if (!form_.constants.empty())
    h_ << "  k.constants = " << d << "constant_names;\n  k.n_constants = " << form_.constants.size() << ";\n"
       << "  k.constant_defaults = " << d << "constant_defaults;\n";
  h_ << "  k.workspace_doubles = &" << d << k.symbol << "_workspace;\n";
  if (k.has_value) h_ << "  k.value = &" << d << k.symbol << "_value;\n";
  if (k.has_vector) h_ << "  k.vector = &" << d << k.symbol << "_vector;\n";
  if (k.has_matrix) h_ << "  k.matrix = &" << d << k.symbol << "_matrix;\n";
  if (k.has_matrix && k.n_blocks == 0) h_ << "  k.matrix_structurally_zero = true;\n";
  if (p.output->kind == OutputKind::Constraint)
    h_ << "  k.target_constant = " << p.output->target_constant << ";\n  k.target_value = " << literal(p.output->target_value) << ";\n";
  if (domain.boundary)
    h_ << "  k.domain = lmeform::kernel::IntegralDomain::Boundary;\n  k.boundary_part = \"" << domain.part << "\";\n";
  if (p.is_point()) {
    h_ << "  k.point = &" << d << k.symbol << "_point;\n  k.n_values = " << point_values(p) << ";\n  k.point_rank = "
       << p.point.shape.size() << ";\n";
    for (std::size_t i = 0; i < p.point.shape.size(); ++i) h_ << "  k.point_extents[" << i << "] = " << p.point.shape[i] << ";\n";
    if (!p.output->requirement.empty())
      h_ << "  k.requirement = \"" << json_escape(p.output->requirement) << "\";\n  k.requirement_condition = \""
         << json_escape(p.output->requirement_condition) << "\";\n  k.requirement_pointwise = " << (p.output->requirement_pointwise ? "true" : "false")
         << ";\n";
    if (p.reads_spacing) h_ << "  k.reads_spacing = true;\n";
    if (p.output->requirement_advisory) h_ << "  k.requirement_advisory = true;\n";
  }
  // A point kernel's cost is reported as the value's: it is the one kernel of a point output.
  const FlopModel& value = p.is_point() ? k.point : k.value;
  auto total = [](const FlopModel& f) { return f.per_point + f.per_node_point + f.per_node_pair_point; };
  h_ << "  k.flops_value = " << total(value) << ";\n  k.flops_vector = " << total(k.vector) << ";\n  k.flops_matrix = " << total(k.matrix) << ";\n"
     << "  k.flop_model_value = " << flop_cxx(value) << ";\n  k.flop_model_vector = " << flop_cxx(k.vector)
     << ";\n  k.flop_model_matrix = " << flop_cxx(k.matrix) << ";\n"
     << "  k.source = \"" << json_escape(source_) << "\";\n  return k;\n}();\n\n";
}

void ModuleWriter::module_table() {
  h_ << "/// Every functional of the module, for registration by name.\n"
     << "inline const lmeform::kernel::FormKernels* const " << m_ << "_all_kernels[] = {";
  for (const auto& k : kernels_) h_ << "&" << m_ << "_" << k.symbol << ", ";
  h_ << "};\ninline constexpr int " << m_ << "_n_kernels = " << kernels_.size() << ";\n"
     << "inline const lmeform::kernel::ModuleTable " << m_ << "_module{lmeform::kernel::kContractVersion, \"" << m_ << "\", \""
     << json_escape(source_) << "\", " << m_ << "_all_kernels, " << m_ << "_n_kernels};\n\n"
     << "// A module compiled into a shared object (JIT) exports its table through one C symbol.\n"
     << "#ifdef LMEFORM_MODULE_ENTRY\n"
     << "extern \"C\" __attribute__((visibility(\"default\"))) const lmeform::kernel::ModuleTable* lmeform_module_table() {\n"
     << "  return &" << m_ << "_module;\n}\n#endif\n";
}

std::string ModuleWriter::kernel_json(const EmittedKernel& k) const {
  const auto& p = k.plan;
  const Domain& domain = form_.domains[static_cast<std::size_t>(p.domain)];
  const auto [basis_order, coefficient_order] = output_orders(p);
  std::ostringstream j;
  j << "    {\"symbol\": \"" << m_ << "_" << k.symbol << "\", \"output\": \"" << p.output->name << "\", \"kind\": \""
    << to_string(p.output->kind) << "\", \"dim\": " << p.dim << ", \"domain\": \"" << (domain.boundary ? "boundary" : "cells")
    << "\", \"boundary_part\": \"" << domain.part << "\", \"measure\": \"" << (p.is_point() ? "" : domain.measure())
    << "\", \"line\": " << k.line << ", \"basis_order\": " << basis_order << ", \"coefficient_basis_order\": " << coefficient_order
    << ", \"jet_slots\": [";
  for (std::size_t s = 0; s < p.slots.size(); ++s) j << (s ? ", " : "") << p.slots[s];
  // Jet components used per row component (structurally non-zero gradient entries).
  j << "], \"jet_components\": [";
  for (std::size_t e = 0; e < p.vector.size(); ++e)
    j << (e ? ", " : "") << "{\"component\": " << p.vector[e].row << ", \"slot\": " << p.slots[static_cast<std::size_t>(p.vector[e].slot_index)] << "}";
  j << "], \"hessian_entries\": " << p.matrix.size() << ", \"matrix_blocks\": " << k.n_blocks;
  if (p.output->kind == OutputKind::Constraint) {
    j << ", \"target\": ";
    if (p.output->target_constant >= 0) j << "\"" << form_.constants[static_cast<std::size_t>(p.output->target_constant)].name << "\"";
    else j << p.output->target_value;
  }
  if (p.is_point()) {
    j << ", \"point\": {\"shape\": \"" << point_shape_name(p.point.shape) << "\", \"rank\": " << p.point.shape.size() << ", \"extents\": [";
    for (std::size_t i = 0; i < p.point.shape.size(); ++i) j << (i ? ", " : "") << p.point.shape[i];
    j << "], \"n_values\": " << point_values(p) << "}";
    if (!p.output->requirement.empty())
      j << ", \"requirement\": \"" << json_escape(p.output->requirement) << "\", \"condition\": \"" << json_escape(p.output->requirement_condition) << "\"";
  }
  j << ",\n     \"flops\": {";
  bool first = true;
  auto add = [&](bool have, const char* nm, const FlopModel& f) {
    if (!have) return;
    j << (first ? "" : ", ") << "\"" << nm << "\": " << flop_json(f);
    first = false;
  };
  add(k.has_value, "value", k.value);
  add(k.has_vector, "vector", k.vector);
  add(k.has_matrix, "matrix", k.matrix);
  add(p.is_point(), "point", k.point);
  j << "}}";
  return j.str();
}

std::string ModuleWriter::json() const {
  std::ostringstream j;
  auto fields_json = [&](ir::Role role) {
    std::string s = "[";
    for (const auto* f : form_.fields_of(role))
      s += std::string(s.size() > 1 ? ", " : "") + "{\"name\": \"" + f->name + "\", \"shape\": \"" + (f->is_vector ? "vector" : "scalar") + "\"}";
    return s + "]";
  };
  j << "{\n  \"module\": \"" << m_ << "\",\n  \"source\": \"" << json_escape(source_) << "\",\n  \"dimensions\": [";
  for (std::size_t i = 0; i < form_.dims.size(); ++i) j << (i ? ", " : "") << form_.dims[i];
  j << "],\n  \"unknowns\": " << fields_json(ir::Role::Unknown) << ",\n  \"tests\": " << fields_json(ir::Role::Test)
    << ",\n  \"trials\": " << fields_json(ir::Role::Trial) << ",\n  \"coefficients\": " << fields_json(ir::Role::Coefficient)
    << ",\n  \"constants\": [";
  for (std::size_t i = 0; i < form_.constants.size(); ++i) {
    const auto& c = form_.constants[i];
    j << (i ? ", " : "") << "{\"name\": \"" << c.name << "\"";
    if (c.default_value) j << ", \"default\": " << std::setprecision(17) << *c.default_value;
    j << "}";
  }
  static const char* qshapes[] = {"scalar", "vector", "matrix", "tensor3"};
  j << "],\n  \"qdata\": [";
  for (std::size_t i = 0; i < form_.qdata.size(); ++i)
    j << (i ? ", " : "") << "{\"name\": \"" << form_.qdata[i].name << "\", \"shape\": \"" << qshapes[form_.qdata[i].rank] << "\"}";
  // The named boundary parts that kernels integrate over: what a scene must provide.
  j << "],\n  \"coordinate\": \"" << form_.coordinate << "\",\n  \"boundary_parts\": [";
  std::set<int> parts;
  for (const auto& k : kernels_)
    if (!form_.domains[static_cast<std::size_t>(k.plan.domain)].part.empty()) parts.insert(k.plan.domain);
  for (const int d : parts) j << (d == *parts.begin() ? "" : ", ") << "\"" << form_.domains[static_cast<std::size_t>(d)].part << "\"";
  j << "],\n  \"kernels\": [\n";
  for (std::size_t i = 0; i < kernels_.size(); ++i) j << kernel_json(kernels_[i]) << (i + 1 < kernels_.size() ? "," : "") << "\n";
  j << "  ]\n}\n";
  return j.str();
}

}  // namespace

GeneratedModule generate(const CompiledForm& form, const std::string& source_name) {
  return ModuleWriter(form, source_name).run();
}

}  // namespace lmeform::compiler
