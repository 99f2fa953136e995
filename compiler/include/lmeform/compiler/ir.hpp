// Scalar expression DAG. Tensors are expanded to components per spatial dimension (shapes are
// known once the dimension is fixed), so the IR is a hash-consed DAG of scalar nodes: equal
// subexpressions are one node (common-subexpression elimination for free), and the builders
// simplify as they go (constant folding, 0/1 propagation, x^1, --x, ...). Node ids grow
// monotonically and children are always older, so increasing id order is a topological order.
#pragma once

#include <array>
#include <cstdint>
#include <functional>
#include <span>
#include <string>
#include <unordered_map>
#include <utility>
#include <vector>

#include "lmeform/compiler/source.hpp"

namespace lmeform::compiler::ir {

using NodeId = std::int32_t;

// Jet layout of the kernel contract (runtime/include/lmeform/kernel.hpp), restated here because the
// compiler must not include runtime headers; tests/compiler checks that both agree.
constexpr int jet_size(int dim, int order) noexcept {
  return order <= 0 ? 1 : order == 1 ? 1 + dim : 1 + dim + dim * (dim + 1) / 2;
}
constexpr int hessian_slot(int i, int j, int dim) noexcept {
  if (i > j) { const int t = i; i = j; j = t; }
  return 1 + dim + i * dim - i * (i - 1) / 2 + (j - i);
}
/// Derivative order of a jet slot (0 value, 1 gradient, 2 Hessian).
constexpr int slot_order(int slot, int dim) noexcept { return slot == 0 ? 0 : slot <= dim ? 1 : 2; }

enum class Op : std::uint8_t {
  Const, Jet, Coord, Param, Qdata, Normal, Spacing,      // terminals
  Add, Mul, Neg, Div, Pow,                               // arithmetic
  Sqrt, Exp, Log, Sin, Cos, Tanh, Abs, Sign,             // functions
  Select, Lt, Le, Gt, Ge, Eq, Ne, And, Or, Not,          // conditionals (true = 1.0)
};

/// Role of a nodal field whose jet appears in the IR.
enum class Role : std::uint8_t { Unknown = 0, Test = 1, Trial = 2, Coefficient = 3 };

struct Node {
  Op op = Op::Const;
  double value = 0.0;             ///< Const
  std::array<int, 4> arg{-1, -1, -1, -1};  ///< children; Jet: role, field, component, slot; Coord/Param/Qdata/Normal: index
};

/// Identifies one jet entry of one component of a nodal field.
struct JetVar {
  Role role;
  int field;
  int component;
  int slot;
  friend bool operator==(const JetVar&, const JetVar&) = default;
  friend auto operator<=>(const JetVar&, const JetVar&) = default;
};

class Graph {
 public:
  Graph();
  const Node& node(NodeId id) const { return nodes_[static_cast<std::size_t>(id)]; }
  std::size_t size() const { return nodes_.size(); }
  const Loc& origin(NodeId id) const { return origins_[static_cast<std::size_t>(id)]; }
  /// Location recorded on nodes created from now on (provenance for the generated code).
  void set_origin(Loc loc) { current_origin_ = loc; }
  Loc current_origin() const { return current_origin_; }

  NodeId zero() const { return zero_; }
  NodeId one() const { return one_; }
  NodeId constant(double v);
  NodeId jet(JetVar v);
  NodeId coord(int i);
  NodeId param(int i);
  NodeId qdata(int offset);
  /// Component i of the outward unit normal at a boundary quadrature point.
  NodeId normal(int i);
  /// The local node spacing at the point (a node: the distance to its nearest other node): known
  /// where requirements are checked, a constant to differentiation.
  NodeId spacing();

  NodeId add(NodeId a, NodeId b);
  NodeId sub(NodeId a, NodeId b) { return add(a, neg(b)); }
  NodeId mul(NodeId a, NodeId b);
  NodeId neg(NodeId a);
  NodeId div(NodeId a, NodeId b);
  NodeId pow(NodeId a, NodeId b);
  NodeId unary(Op op, NodeId a);
  NodeId compare(Op op, NodeId a, NodeId b);
  NodeId logic(Op op, NodeId a, NodeId b = -1);
  NodeId select(NodeId c, NodeId a, NodeId b);

  bool is_const(NodeId id, double v) const { return node(id).op == Op::Const && node(id).value == v; }
  bool is_const(NodeId id) const { return node(id).op == Op::Const; }
  JetVar jet_var(NodeId id) const;
  /// Whether the node depends on the normal (kept per node as it is built: checking an integrand
  /// over a cell measure must not walk the whole DAG once per term).
  bool reads_normal(NodeId id) const { return reads_normal_[static_cast<std::size_t>(id)] != 0; }

  /// All nodes reachable from roots, in increasing id (= topological) order.
  std::vector<NodeId> reachable(std::span<const NodeId> roots) const;

 private:
  NodeId intern(const Node& n);
  struct KeyHash {
    std::size_t operator()(const Node& n) const noexcept;
  };
  struct KeyEq {
    bool operator()(const Node& a, const Node& b) const noexcept;
  };
  std::vector<Node> nodes_;
  std::vector<Loc> origins_;
  std::vector<unsigned char> reads_normal_;
  std::unordered_map<Node, NodeId, KeyHash, KeyEq> table_;
  Loc current_origin_;
  NodeId zero_ = -1, one_ = -1;
};

/// Maps a terminal to its derivative (a node id) in some direction; may throw.
using TerminalRule = std::function<NodeId(Graph&, NodeId terminal)>;

/// Forward-mode symbolic differentiation in one direction, memoized over the DAG.
class Differentiator {
 public:
  Differentiator(Graph& graph, TerminalRule terminal_rule) : g_(graph), rule_(std::move(terminal_rule)) {}
  NodeId derivative(NodeId id);

 private:
  /// The derivative of node id from its children's (already memoized) derivatives.
  NodeId apply_rule(NodeId id, const Node& n);

  Graph& g_;
  TerminalRule rule_;
  std::unordered_map<NodeId, NodeId> memo_;
};

/// Reverse-mode symbolic differentiation: the non-zero ∂f/∂t for the terminals t of `wrt`, as
/// (index into wrt, derivative) in increasing index, from one sweep over the nodes f depends on.
/// Forward mode (Differentiator) needs one sweep per terminal, which makes the gradient of a
/// functional of many unknowns quadratic in their number; this stays linear.
std::vector<std::pair<std::size_t, NodeId>> gradient(Graph& graph, NodeId f, std::span<const NodeId> wrt);

/// One entry of a symmetric Hessian: ∂²f/∂wrt[row]∂wrt[col] with row <= col.
struct HessianEntry {
  std::size_t row;
  std::size_t col;
  NodeId node;
};

/// Reverse-mode symbolic Hessian by edge pushing (Gower & Mello, 2012): the non-zero upper-triangle
/// entries of ∂²f/∂t∂t' for the terminals of `wrt`, from one reverse sweep that pushes second-order
/// interactions through the DAG; intermediates with few inputs (F⁻¹, det F, ∇φ) are then
/// differentiated once, not once per variable as by a reverse sweep over every first derivative.
std::vector<HessianEntry> hessian(Graph& graph, NodeId f, std::span<const NodeId> wrt);

/// Numerical evaluation of the DAG (tests, constant defaults): terminal values from a callback.
class Interpreter {
 public:
  explicit Interpreter(const Graph& g) : g_(g) {}
  std::vector<double> evaluate(std::span<const NodeId> roots, const std::function<double(const Node&)>& terminal) const;

 private:
  const Graph& g_;
};

/// Readable one-line form of a node (`t12 = t3 * t7`), for --print-ir.
std::string describe(const Graph& g, NodeId id, const std::function<std::string(NodeId)>& terminal_name);
bool is_terminal(Op op);
/// Operation count of evaluating a node once (for flop estimates).
int flop_cost(Op op);

}  // namespace lmeform::compiler::ir
