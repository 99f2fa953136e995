#include "lmeform/compiler/ir.hpp"

#include <algorithm>
#include <array>
#include <bit>
#include <cmath>
#include <functional>
#include <sstream>
#include <unordered_map>
#include <unordered_set>

namespace lmeform::compiler::ir {

bool is_terminal(Op op) { return op <= Op::Spacing; }

int flop_cost(Op op) {
  switch (op) {
    case Op::Const: case Op::Jet: case Op::Coord: case Op::Param: case Op::Qdata: case Op::Normal: case Op::Spacing: return 0;
    case Op::Sqrt: case Op::Div: return 4;
    case Op::Exp: case Op::Log: case Op::Sin: case Op::Cos: case Op::Tanh: case Op::Pow: return 20;
    default: return 1;
  }
}

std::size_t Graph::KeyHash::operator()(const Node& n) const noexcept {
  std::size_t h = static_cast<std::size_t>(n.op) * 0x9E3779B97F4A7C15ull;
  h ^= std::bit_cast<std::uint64_t>(n.value) + 0x9E3779B97F4A7C15ull + (h << 6) + (h >> 2);
  for (int a : n.arg) h ^= static_cast<std::size_t>(a) + 0x9E3779B97F4A7C15ull + (h << 6) + (h >> 2);
  return h;
}
bool Graph::KeyEq::operator()(const Node& a, const Node& b) const noexcept {
  return a.op == b.op && std::bit_cast<std::uint64_t>(a.value) == std::bit_cast<std::uint64_t>(b.value) && a.arg == b.arg;
}

Graph::Graph() {
  zero_ = constant(0.0);
  one_ = constant(1.0);
}

NodeId Graph::intern(const Node& n) {
  auto it = table_.find(n);
  if (it != table_.end()) return it->second;
  const auto id = static_cast<NodeId>(nodes_.size());
  nodes_.push_back(n);
  origins_.push_back(current_origin_);
  bool normal = n.op == Op::Normal;
  if (!is_terminal(n.op))
    for (int a : n.arg) normal = normal || (a >= 0 && reads_normal_[static_cast<std::size_t>(a)] != 0);
  reads_normal_.push_back(normal ? 1 : 0);
  table_.emplace(n, id);
  return id;
}

NodeId Graph::constant(double v) {
  Node n;
  n.op = Op::Const;
  n.value = (v == 0.0) ? 0.0 : v;  // one zero (no -0.0)
  return intern(n);
}
NodeId Graph::jet(JetVar v) {
  Node n;
  n.op = Op::Jet;
  n.arg = {static_cast<int>(v.role), v.field, v.component, v.slot};
  return intern(n);
}
JetVar Graph::jet_var(NodeId id) const {
  const Node& n = node(id);
  return JetVar{static_cast<Role>(n.arg[0]), n.arg[1], n.arg[2], n.arg[3]};
}
static Node leaf(Op op, int i) {
  Node n;
  n.op = op;
  n.arg[0] = i;
  return n;
}
NodeId Graph::coord(int i) { return intern(leaf(Op::Coord, i)); }
NodeId Graph::param(int i) { return intern(leaf(Op::Param, i)); }
NodeId Graph::qdata(int i) { return intern(leaf(Op::Qdata, i)); }
NodeId Graph::normal(int i) { return intern(leaf(Op::Normal, i)); }
NodeId Graph::spacing() { return intern(leaf(Op::Spacing, 0)); }

static Node op2(Op op, NodeId a, NodeId b) {
  Node n;
  n.op = op;
  n.arg[0] = a;
  n.arg[1] = b;
  return n;
}

NodeId Graph::add(NodeId a, NodeId b) {
  if (is_const(a) && is_const(b)) return constant(node(a).value + node(b).value);
  if (is_const(a, 0.0)) return b;
  if (is_const(b, 0.0)) return a;
  if (node(a).op == Op::Neg && node(a).arg[0] == b) return zero_;
  if (node(b).op == Op::Neg && node(b).arg[0] == a) return zero_;
  if (a > b) std::swap(a, b);  // commutative: canonical order shares a+b and b+a
  return intern(op2(Op::Add, a, b));
}

NodeId Graph::mul(NodeId a, NodeId b) {
  if (is_const(a) && is_const(b)) return constant(node(a).value * node(b).value);
  if (is_const(a, 0.0) || is_const(b, 0.0)) return zero_;
  if (is_const(a, 1.0)) return b;
  if (is_const(b, 1.0)) return a;
  if (is_const(a, -1.0)) return neg(b);
  if (is_const(b, -1.0)) return neg(a);
  // Pull negations out so that -a*b and a*-b are one node.
  if (node(a).op == Op::Neg) return neg(mul(node(a).arg[0], b));
  if (node(b).op == Op::Neg) return neg(mul(a, node(b).arg[0]));
  if (is_const(b)) std::swap(a, b);  // constant first
  if (is_const(a) && node(b).op == Op::Mul && is_const(node(b).arg[0]))
    return mul(constant(node(a).value * node(node(b).arg[0]).value), node(b).arg[1]);
  if (!is_const(a) && a > b) std::swap(a, b);
  return intern(op2(Op::Mul, a, b));
}

NodeId Graph::neg(NodeId a) {
  if (is_const(a)) return constant(-node(a).value);
  if (node(a).op == Op::Neg) return node(a).arg[0];
  Node n;
  n.op = Op::Neg;
  n.arg[0] = a;
  return intern(n);
}

NodeId Graph::div(NodeId a, NodeId b) {
  if (is_const(a, 0.0)) return zero_;
  if (is_const(b, 1.0)) return a;
  if (is_const(b)) return mul(constant(1.0 / node(b).value), a);
  if (a == b) return one_;
  if (node(a).op == Op::Neg) return neg(div(node(a).arg[0], b));
  return intern(op2(Op::Div, a, b));
}

NodeId Graph::pow(NodeId a, NodeId b) {
  if (is_const(b, 0.0)) return one_;
  if (is_const(b, 1.0)) return a;
  if (is_const(a) && is_const(b)) return constant(std::pow(node(a).value, node(b).value));
  if (is_const(a, 0.0) && is_const(b) && node(b).value > 0) return zero_;
  if (is_const(a, 1.0)) return one_;
  if (is_const(b, 0.5)) return unary(Op::Sqrt, a);
  return intern(op2(Op::Pow, a, b));
}

NodeId Graph::unary(Op op, NodeId a) {
  if (is_const(a)) {
    const double v = node(a).value;
    switch (op) {
      case Op::Sqrt: return constant(std::sqrt(v));
      case Op::Exp: return constant(std::exp(v));
      case Op::Log: return constant(std::log(v));
      case Op::Sin: return constant(std::sin(v));
      case Op::Cos: return constant(std::cos(v));
      case Op::Tanh: return constant(std::tanh(v));
      case Op::Abs: return constant(std::abs(v));
      case Op::Sign: return constant(v > 0 ? 1.0 : v < 0 ? -1.0 : 0.0);
      case Op::Neg: return constant(-v);
      default: break;
    }
  }
  if (op == Op::Neg) return neg(a);
  Node n;
  n.op = op;
  n.arg[0] = a;
  return intern(n);
}

NodeId Graph::compare(Op op, NodeId a, NodeId b) {
  if (is_const(a) && is_const(b)) {
    const double x = node(a).value, y = node(b).value;
    bool r = false;
    switch (op) {
      case Op::Lt: r = x < y; break;
      case Op::Le: r = x <= y; break;
      case Op::Gt: r = x > y; break;
      case Op::Ge: r = x >= y; break;
      case Op::Eq: r = x == y; break;
      case Op::Ne: r = x != y; break;
      default: break;
    }
    return r ? one_ : zero_;
  }
  return intern(op2(op, a, b));
}

NodeId Graph::logic(Op op, NodeId a, NodeId b) {
  if (op == Op::Not) {
    if (is_const(a)) return node(a).value != 0.0 ? zero_ : one_;
    Node n;
    n.op = Op::Not;
    n.arg[0] = a;
    return intern(n);
  }
  if (is_const(a) && is_const(b)) {
    const bool x = node(a).value != 0.0, y = node(b).value != 0.0;
    return (op == Op::And ? (x && y) : (x || y)) ? one_ : zero_;
  }
  return intern(op2(op, a, b));
}

NodeId Graph::select(NodeId c, NodeId a, NodeId b) {
  if (a == b) return a;
  if (is_const(c)) return node(c).value != 0.0 ? a : b;
  Node n;
  n.op = Op::Select;
  n.arg = {c, a, b, -1};
  return intern(n);
}

std::vector<NodeId> Graph::reachable(std::span<const NodeId> roots) const {
  std::vector<char> seen(nodes_.size(), 0);
  std::vector<NodeId> stack(roots.begin(), roots.end());
  while (!stack.empty()) {
    const NodeId id = stack.back();
    stack.pop_back();
    if (id < 0 || seen[static_cast<std::size_t>(id)]) continue;
    seen[static_cast<std::size_t>(id)] = 1;
    const Node& n = node(id);
    if (is_terminal(n.op)) continue;
    for (int a : n.arg)
      if (a >= 0) stack.push_back(a);
  }
  std::vector<NodeId> out;
  for (std::size_t i = 0; i < seen.size(); ++i)
    if (seen[i]) out.push_back(static_cast<NodeId>(i));
  return out;
}

namespace {

/// The children whose derivatives the rule of node n needs (Sign, comparisons and logic are
/// piecewise constant, a Select's condition is not differentiated, a constant exponent neither).
int differentiated_children(const Graph& g, const Node& n, NodeId (&out)[2]) {
  switch (n.op) {
    case Op::Add: case Op::Mul: case Op::Div: out[0] = n.arg[0]; out[1] = n.arg[1]; return 2;
    case Op::Pow:
      out[0] = n.arg[0];
      if (g.is_const(n.arg[1])) return 1;
      out[1] = n.arg[1];
      return 2;
    case Op::Neg: case Op::Sqrt: case Op::Exp: case Op::Log: case Op::Sin: case Op::Cos: case Op::Tanh:
    case Op::Abs: out[0] = n.arg[0]; return 1;
    case Op::Select: out[0] = n.arg[1]; out[1] = n.arg[2]; return 2;
    default: return 0;
  }
}

}  // namespace

// Post-order over an explicit stack rather than recursion: a sum of thousands of terms is a chain
// that deep, and every node's derivative needs its children's first.
NodeId Differentiator::derivative(NodeId root) {
  if (auto it = memo_.find(root); it != memo_.end()) return it->second;
  std::vector<NodeId> stack{root};
  while (!stack.empty()) {
    const NodeId id = stack.back();
    if (memo_.count(id)) {
      stack.pop_back();
      continue;
    }
    const Node n = g_.node(id);  // copy: the graph grows below
    NodeId children[2] = {-1, -1};
    const int n_children = differentiated_children(g_, n, children);
    bool ready = true;
    for (int k = n_children - 1; k >= 0; --k)  // pushed last-first: the first child is done first
      if (!memo_.count(children[k])) {
        stack.push_back(children[k]);
        ready = false;
      }
    if (!ready) continue;
    stack.pop_back();
    memo_.emplace(id, apply_rule(id, n));
  }
  return memo_.at(root);
}

NodeId Differentiator::apply_rule(NodeId id, const Node& n) {
  const auto D = [&](NodeId child) { return memo_.at(child); };
  const Loc saved = g_.current_origin();
  g_.set_origin(g_.origin(id));
  NodeId d = g_.zero();
  const NodeId a = n.arg[0], b = n.arg[1];
  switch (n.op) {
    case Op::Const: d = g_.zero(); break;
    case Op::Jet: case Op::Coord: case Op::Param: case Op::Qdata: case Op::Normal: d = rule_(g_, id); break;
    case Op::Spacing: d = g_.zero(); break;
    case Op::Add: d = g_.add(D(a), D(b)); break;
    case Op::Mul: d = g_.add(g_.mul(D(a), b), g_.mul(a, D(b))); break;
    case Op::Neg: d = g_.neg(D(a)); break;
    case Op::Div: d = g_.div(g_.sub(D(a), g_.mul(id, D(b))), b); break;  // (a/b)' = (a' - (a/b) b') / b
    case Op::Pow:
      if (g_.is_const(b)) {
        const double p = g_.node(b).value;
        d = g_.mul(g_.mul(b, g_.pow(a, g_.constant(p - 1.0))), D(a));
      } else {  // (a^b)' = a^b (b' log a + b a'/a)
        d = g_.mul(id, g_.add(g_.mul(D(b), g_.unary(Op::Log, a)), g_.div(g_.mul(b, D(a)), a)));
      }
      break;
    case Op::Sqrt: d = g_.div(D(a), g_.mul(g_.constant(2.0), id)); break;
    case Op::Exp: d = g_.mul(id, D(a)); break;
    case Op::Log: d = g_.div(D(a), a); break;
    case Op::Sin: d = g_.mul(g_.unary(Op::Cos, a), D(a)); break;
    case Op::Cos: d = g_.neg(g_.mul(g_.unary(Op::Sin, a), D(a))); break;
    case Op::Tanh: d = g_.mul(g_.sub(g_.one(), g_.mul(id, id)), D(a)); break;
    case Op::Abs: d = g_.mul(g_.unary(Op::Sign, a), D(a)); break;
    case Op::Select: d = g_.select(a, D(b), D(n.arg[2])); break;
    default: d = g_.zero(); break;  // Sign, comparisons and logic are piecewise constant
  }
  g_.set_origin(saved);
  return d;
}

std::vector<std::pair<std::size_t, NodeId>> gradient(Graph& g, NodeId f, std::span<const NodeId> wrt) {
  // The nodes f depends on, by a walk that touches only them (f may be a small part of a large
  // graph: one row of a Hessian), then visited from f down, in decreasing (reverse topological) id.
  std::unordered_set<NodeId> cone{f};
  std::vector<NodeId> pending{f};
  while (!pending.empty()) {
    const Node& n = g.node(pending.back());
    pending.pop_back();
    if (is_terminal(n.op)) continue;
    for (NodeId child : n.arg)
      if (child >= 0 && cone.insert(child).second) pending.push_back(child);
  }
  std::vector<NodeId> order(cone.begin(), cone.end());
  std::sort(order.begin(), order.end(), std::greater<>());

  std::unordered_map<NodeId, NodeId> adjoint{{f, g.one()}};  // ∂f/∂node, accumulated over its uses
  const auto accumulate = [&](NodeId node, NodeId contribution) {
    if (g.is_const(contribution, 0.0)) return;
    auto [it, fresh] = adjoint.try_emplace(node, contribution);
    if (!fresh) it->second = g.add(it->second, contribution);
  };
  const Loc saved = g.current_origin();
  for (NodeId id : order) {
    const auto found = adjoint.find(id);
    if (found == adjoint.end()) continue;
    const NodeId bar = found->second;
    const Node n = g.node(id);  // copy: the graph grows below
    const NodeId a = n.arg[0], b = n.arg[1];
    g.set_origin(g.origin(id));
    switch (n.op) {
      case Op::Add: accumulate(a, bar); accumulate(b, bar); break;
      case Op::Mul: accumulate(a, g.mul(bar, b)); accumulate(b, g.mul(bar, a)); break;
      case Op::Neg: accumulate(a, g.neg(bar)); break;
      case Op::Div:  // d(a/b) = da/b - (a/b) db/b
        accumulate(a, g.div(bar, b));
        accumulate(b, g.neg(g.div(g.mul(bar, id), b)));
        break;
      case Op::Pow:
        if (g.is_const(b)) {
          accumulate(a, g.mul(bar, g.mul(b, g.pow(a, g.constant(g.node(b).value - 1.0)))));
        } else {  // d(a^b) = a^b (b/a da + log a db)
          accumulate(a, g.mul(bar, g.div(g.mul(b, id), a)));
          accumulate(b, g.mul(bar, g.mul(id, g.unary(Op::Log, a))));
        }
        break;
      case Op::Sqrt: accumulate(a, g.div(bar, g.mul(g.constant(2.0), id))); break;
      case Op::Exp: accumulate(a, g.mul(bar, id)); break;
      case Op::Log: accumulate(a, g.div(bar, a)); break;
      case Op::Sin: accumulate(a, g.mul(bar, g.unary(Op::Cos, a))); break;
      case Op::Cos: accumulate(a, g.neg(g.mul(bar, g.unary(Op::Sin, a)))); break;
      case Op::Tanh: accumulate(a, g.mul(bar, g.sub(g.one(), g.mul(id, id)))); break;
      case Op::Abs: accumulate(a, g.mul(bar, g.unary(Op::Sign, a))); break;
      case Op::Select:
        accumulate(n.arg[1], g.select(a, bar, g.zero()));
        accumulate(n.arg[2], g.select(a, g.zero(), bar));
        break;
      default: break;  // terminals; Sign, comparisons and logic are piecewise constant
    }
  }
  g.set_origin(saved);
  std::vector<std::pair<std::size_t, NodeId>> result;
  for (std::size_t i = 0; i < wrt.size(); ++i)
    if (const auto it = adjoint.find(wrt[i]); it != adjoint.end()) result.emplace_back(i, it->second);
  return result;
}

namespace {

/// First and second partial derivatives of one node with respect to its argument positions.
struct LocalPartials {
  std::array<NodeId, 3> child{-1, -1, -1};
  std::array<NodeId, 3> first{-1, -1, -1};   ///< ∂v/∂child (zero node when none)
  std::array<std::array<NodeId, 3>, 3> second{};  ///< ∂²v/∂child_p∂child_q, symmetric (-1: zero)
  int count = 0;
};

LocalPartials local_partials(Graph& g, NodeId id) {
  const Node n = g.node(id);
  LocalPartials L;
  for (auto& row : L.second) row.fill(-1);
  const NodeId a = n.arg[0], b = n.arg[1];
  auto set1 = [&](int k, NodeId c, NodeId d) {
    L.child[static_cast<std::size_t>(k)] = c;
    L.first[static_cast<std::size_t>(k)] = d;
    L.count = std::max(L.count, k + 1);
  };
  auto set2 = [&](int p, int q, NodeId s) {
    L.second[static_cast<std::size_t>(p)][static_cast<std::size_t>(q)] = s;
    L.second[static_cast<std::size_t>(q)][static_cast<std::size_t>(p)] = s;
  };
  switch (n.op) {
    case Op::Add: set1(0, a, g.one()); set1(1, b, g.one()); break;
    case Op::Mul: set1(0, a, b); set1(1, b, a); set2(0, 1, g.one()); break;
    case Op::Neg: set1(0, a, g.constant(-1.0)); break;
    case Op::Div: {  // v = a/b: v_a = 1/b, v_b = -v/b, v_ab = -1/b², v_bb = 2v/b²
      const NodeId inv = g.div(g.one(), b);
      set1(0, a, inv);
      set1(1, b, g.neg(g.div(id, b)));
      set2(0, 1, g.neg(g.mul(inv, inv)));
      set2(1, 1, g.div(g.mul(g.constant(2.0), id), g.mul(b, b)));
      break;
    }
    case Op::Pow:
      if (g.is_const(b)) {
        const double c = g.node(b).value;
        set1(0, a, g.mul(b, g.pow(a, g.constant(c - 1.0))));
        set2(0, 0, g.mul(g.constant(c * (c - 1.0)), g.pow(a, g.constant(c - 2.0))));
      } else {  // v = a^b
        const NodeId log_a = g.unary(Op::Log, a);
        set1(0, a, g.div(g.mul(b, id), a));
        set1(1, b, g.mul(id, log_a));
        set2(0, 0, g.div(g.mul(g.mul(b, g.sub(b, g.one())), id), g.mul(a, a)));
        set2(0, 1, g.div(g.mul(id, g.add(g.one(), g.mul(b, log_a))), a));
        set2(1, 1, g.mul(id, g.mul(log_a, log_a)));
      }
      break;
    case Op::Sqrt:  // v' = 1/(2v), v'' = -1/(4 v³)
      set1(0, a, g.div(g.one(), g.mul(g.constant(2.0), id)));
      set2(0, 0, g.neg(g.div(g.one(), g.mul(g.constant(4.0), g.mul(id, g.mul(id, id))))));
      break;
    case Op::Exp: set1(0, a, id); set2(0, 0, id); break;
    case Op::Log: {
      const NodeId inv = g.div(g.one(), a);
      set1(0, a, inv);
      set2(0, 0, g.neg(g.mul(inv, inv)));
      break;
    }
    case Op::Sin: set1(0, a, g.unary(Op::Cos, a)); set2(0, 0, g.neg(id)); break;
    case Op::Cos: set1(0, a, g.neg(g.unary(Op::Sin, a))); set2(0, 0, g.neg(id)); break;
    case Op::Tanh: {
      const NodeId d = g.sub(g.one(), g.mul(id, id));
      set1(0, a, d);
      set2(0, 0, g.mul(g.constant(-2.0), g.mul(id, d)));
      break;
    }
    case Op::Abs: set1(0, a, g.unary(Op::Sign, a)); break;
    case Op::Select:
      set1(0, n.arg[1], g.select(a, g.one(), g.zero()));
      set1(1, n.arg[2], g.select(a, g.zero(), g.one()));
      break;
    default: break;  // terminals; Sign, comparisons and logic are piecewise constant
  }
  return L;
}

}  // namespace

std::vector<HessianEntry> hessian(Graph& g, NodeId f, std::span<const NodeId> wrt) {
  // Active nodes: those depending on a variable of wrt (only they carry derivatives).
  const std::vector<NodeId> order_up = g.reachable(std::span<const NodeId>(&f, 1));
  std::unordered_map<NodeId, std::size_t> var_index;
  for (std::size_t i = 0; i < wrt.size(); ++i) var_index.emplace(wrt[i], i);
  std::unordered_set<NodeId> active;
  for (NodeId id : order_up) {
    const Node& n = g.node(id);
    if (is_terminal(n.op)) {
      if (var_index.contains(id)) active.insert(id);
      continue;
    }
    for (NodeId child : n.arg)
      if (child >= 0 && active.contains(child)) {
        active.insert(id);
        break;
      }
  }
  if (!active.contains(f)) return {};

  // Edge pushing (Gower & Mello 2012) over the DAG, symbolically: a reverse sweep carrying the
  // adjoints and the symmetric matrix W of second-order interactions between live nodes. At node v
  // the entries W(v, ·) are pushed to v's arguments through the chain rule, v's own curvature is
  // created with its adjoint, and v leaves W; at the end W holds the Hessian on the variables.
  std::unordered_map<NodeId, NodeId> adjoint{{f, g.one()}};
  std::unordered_map<NodeId, std::unordered_map<NodeId, NodeId>> off;  // W(u, p), u != p, stored both ways
  std::unordered_map<NodeId, NodeId> diag;                               // W(u, u)
  auto add_to = [&](NodeId& slot, NodeId x) { slot = slot < 0 ? x : g.add(slot, x); };
  auto add_pair = [&](NodeId u, NodeId p, NodeId x) {
    if (g.is_const(x, 0.0)) return;
    if (u == p) {
      auto [it, fresh] = diag.try_emplace(u, x);
      if (!fresh) it->second = g.add(it->second, x);
      return;
    }
    NodeId& a = off[u].try_emplace(p, -1).first->second;
    add_to(a, x);
    off[p][u] = a;
  };
  const Loc saved = g.current_origin();
  for (auto it = order_up.rbegin(); it != order_up.rend(); ++it) {
    const NodeId v = *it;
    if (!active.contains(v) || is_terminal(g.node(v).op)) continue;
    g.set_origin(g.origin(v));
    const LocalPartials L = local_partials(g, v);
    // Unique active children with merged partials: d[c] and S[c][c'] (symmetric).
    std::vector<NodeId> kids;
    std::vector<int> pos_to_kid(static_cast<std::size_t>(L.count), -1);
    for (int p = 0; p < L.count; ++p) {
      const NodeId c = L.child[static_cast<std::size_t>(p)];
      if (c < 0 || !active.contains(c)) continue;
      const auto found = std::find(kids.begin(), kids.end(), c);
      pos_to_kid[static_cast<std::size_t>(p)] = static_cast<int>(found - kids.begin());
      if (found == kids.end()) kids.push_back(c);
    }
    if (kids.empty()) continue;
    const std::size_t K = kids.size();
    std::vector<NodeId> d(K, g.zero());
    std::vector<std::vector<NodeId>> S(K, std::vector<NodeId>(K, g.zero()));
    for (int p = 0; p < L.count; ++p) {
      const int i = pos_to_kid[static_cast<std::size_t>(p)];
      if (i < 0) continue;
      d[static_cast<std::size_t>(i)] = g.add(d[static_cast<std::size_t>(i)], L.first[static_cast<std::size_t>(p)]);
      for (int q = 0; q < L.count; ++q) {
        const int j = pos_to_kid[static_cast<std::size_t>(q)];
        const NodeId s = L.second[static_cast<std::size_t>(p)][static_cast<std::size_t>(q)];
        if (j < 0 || s < 0) continue;
        S[static_cast<std::size_t>(i)][static_cast<std::size_t>(j)] = g.add(S[static_cast<std::size_t>(i)][static_cast<std::size_t>(j)], s);
      }
    }
    // Pushing: W(v, p) and W(v, v) to the children.
    if (const auto row = off.find(v); row != off.end()) {
      const auto partners = std::move(row->second);
      off.erase(row);
      for (const auto& [p, w] : partners) {
        if (auto back = off.find(p); back != off.end()) back->second.erase(v);
        for (std::size_t i = 0; i < K; ++i) {
          const NodeId x = g.mul(d[i], w);
          add_pair(kids[i], p, kids[i] == p ? g.mul(g.constant(2.0), x) : x);
        }
      }
    }
    if (const auto dv = diag.find(v); dv != diag.end()) {
      const NodeId w = dv->second;
      diag.erase(dv);
      for (std::size_t i = 0; i < K; ++i)
        for (std::size_t j = i; j < K; ++j) add_pair(kids[i], kids[j], g.mul(g.mul(d[i], d[j]), w));
    }
    // Creating (v's own curvature) and the adjoints.
    const auto found = adjoint.find(v);
    if (found == adjoint.end()) continue;
    const NodeId bar = found->second;
    for (std::size_t i = 0; i < K; ++i)
      for (std::size_t j = i; j < K; ++j)
        if (!g.is_const(S[i][j], 0.0)) add_pair(kids[i], kids[j], g.mul(bar, S[i][j]));
    for (std::size_t i = 0; i < K; ++i) {
      const NodeId contribution = g.mul(bar, d[i]);
      if (g.is_const(contribution, 0.0)) continue;
      auto [a, fresh] = adjoint.try_emplace(kids[i], contribution);
      if (!fresh) a->second = g.add(a->second, contribution);
    }
  }
  g.set_origin(saved);
  std::vector<HessianEntry> result;
  for (std::size_t k = 0; k < wrt.size(); ++k) {
    if (const auto dk = diag.find(wrt[k]); dk != diag.end() && !g.is_const(dk->second, 0.0)) result.push_back({k, k, dk->second});
    if (const auto row = off.find(wrt[k]); row != off.end())
      for (const auto& [p, w] : row->second)
        if (const auto l = var_index.find(p); l != var_index.end() && l->second > k && !g.is_const(w, 0.0))
          result.push_back({k, l->second, w});
  }
  std::sort(result.begin(), result.end(), [](const HessianEntry& x, const HessianEntry& y) {
    return std::pair(x.row, x.col) < std::pair(y.row, y.col);
  });
  return result;
}

std::vector<double> Interpreter::evaluate(std::span<const NodeId> roots,
                                          const std::function<double(const Node&)>& terminal) const {
  const auto order = g_.reachable(roots);
  std::unordered_map<NodeId, double> v;
  for (NodeId id : order) {
    const Node& n = g_.node(id);
    auto A = [&](int k) { return v.at(n.arg[static_cast<std::size_t>(k)]); };
    double r = 0;
    switch (n.op) {
      case Op::Const: r = n.value; break;
      case Op::Jet: case Op::Coord: case Op::Param: case Op::Qdata: case Op::Normal: case Op::Spacing: r = terminal(n); break;
      case Op::Add: r = A(0) + A(1); break;
      case Op::Mul: r = A(0) * A(1); break;
      case Op::Neg: r = -A(0); break;
      case Op::Div: r = A(0) / A(1); break;
      case Op::Pow: r = std::pow(A(0), A(1)); break;
      case Op::Sqrt: r = std::sqrt(A(0)); break;
      case Op::Exp: r = std::exp(A(0)); break;
      case Op::Log: r = std::log(A(0)); break;
      case Op::Sin: r = std::sin(A(0)); break;
      case Op::Cos: r = std::cos(A(0)); break;
      case Op::Tanh: r = std::tanh(A(0)); break;
      case Op::Abs: r = std::abs(A(0)); break;
      case Op::Sign: r = A(0) > 0 ? 1.0 : A(0) < 0 ? -1.0 : 0.0; break;
      case Op::Select: r = A(0) != 0.0 ? A(1) : A(2); break;
      case Op::Lt: r = A(0) < A(1); break;
      case Op::Le: r = A(0) <= A(1); break;
      case Op::Gt: r = A(0) > A(1); break;
      case Op::Ge: r = A(0) >= A(1); break;
      case Op::Eq: r = A(0) == A(1); break;
      case Op::Ne: r = A(0) != A(1); break;
      case Op::And: r = (A(0) != 0.0) && (A(1) != 0.0); break;
      case Op::Or: r = (A(0) != 0.0) || (A(1) != 0.0); break;
      case Op::Not: r = A(0) == 0.0; break;
    }
    v[id] = r;
  }
  std::vector<double> out;
  for (NodeId r : roots) out.push_back(v.at(r));
  return out;
}

static const char* op_name(Op op) {
  switch (op) {
    case Op::Sqrt: return "sqrt"; case Op::Exp: return "exp"; case Op::Log: return "log";
    case Op::Sin: return "sin"; case Op::Cos: return "cos"; case Op::Tanh: return "tanh";
    case Op::Abs: return "abs"; case Op::Sign: return "sign"; case Op::Not: return "!";
    case Op::Add: return "+"; case Op::Mul: return "*"; case Op::Div: return "/"; case Op::Pow: return "^";
    case Op::Lt: return "<"; case Op::Le: return "<="; case Op::Gt: return ">"; case Op::Ge: return ">=";
    case Op::Eq: return "=="; case Op::Ne: return "!="; case Op::And: return "&&"; case Op::Or: return "||";
    default: return "?";
  }
}

std::string describe(const Graph& g, NodeId id, const std::function<std::string(NodeId)>& name) {
  const Node& n = g.node(id);
  auto ref = [&](int c) {
    const Node& m = g.node(c);
    if (m.op == Op::Const) { std::ostringstream s; s.precision(17); s << m.value; return s.str(); }
    if (is_terminal(m.op)) return name(c);
    std::string r = "t";  // appended separately: `"t" + string` trips GCC 12's -Wrestrict false positive
    r += std::to_string(c);
    return r;
  };
  std::ostringstream s;
  s << "t" << id << " = ";
  switch (n.op) {
    case Op::Neg: s << "-" << ref(n.arg[0]); break;
    case Op::Select: s << ref(n.arg[0]) << " ? " << ref(n.arg[1]) << " : " << ref(n.arg[2]); break;
    case Op::Add: case Op::Mul: case Op::Div: case Op::Pow: case Op::Lt: case Op::Le: case Op::Gt:
    case Op::Ge: case Op::Eq: case Op::Ne: case Op::And: case Op::Or:
      s << ref(n.arg[0]) << " " << op_name(n.op) << " " << ref(n.arg[1]); break;
    default:
      if (is_terminal(n.op)) s << ref(id);
      else s << op_name(n.op) << "(" << ref(n.arg[0]) << ")";
  }
  return s.str();
}

}  // namespace lmeform::compiler::ir
