// Checking and lowering: names, shapes, includes; every expression becomes a tensor of IR nodes
// (one Graph per dimension). Spatial operators are applied here by forward differentiation of the
// component nodes, which pushes grad/hess/div/lap through any expression down to the jets of
// nodal fields (the first differentiation layer of ARCHITECTURE §3).
#include <algorithm>
#include <cmath>
#include <numbers>
#include <fstream>
#include <set>
#include <sstream>

#include "lmeform/compiler/ast.hpp"
#include "lmeform/compiler/compile.hpp"

namespace lmeform::compiler {

const char* to_string(OutputKind k) {
  switch (k) {
    case OutputKind::Energy: return "energy";
    case OutputKind::Constraint: return "constraint";
    case OutputKind::Residual: return "residual";
    case OutputKind::Bilinear: return "bilinear";
    case OutputKind::Linear: return "linear";
  }
  return "?";
}

std::vector<const FieldDecl*> CompiledForm::fields_of(ir::Role role) const {
  std::vector<const FieldDecl*> out;
  for (const auto& f : fields)
    if (f.role == role) out.push_back(&f);
  return out;
}
int CompiledForm::qdata_offset(int index, int dim) const {
  int off = 0;
  for (int i = 0; i < index; ++i) off += qdata[static_cast<std::size_t>(i)].size(dim);
  return off;
}
int CompiledForm::qdata_per_point(int dim) const { return qdata_offset(static_cast<int>(qdata.size()), dim); }

namespace {

using ast::Expr;
using ast::ExprKind;
using ast::Stmt;
using ast::StmtKind;
using ir::NodeId;
using ir::Op;

/// A tensor-valued expression: components (row-major) of IR nodes.
struct Value {
  std::vector<int> shape;
  std::vector<NodeId> c;
  bool measure = false;
  bool condition = false;
  int rank() const { return static_cast<int>(shape.size()); }
  bool scalar() const { return shape.empty(); }
};

std::string shape_name(const Value& v) {
  if (v.measure) return "measure";
  if (v.condition) return "condition";
  static const char* names[] = {"scalar", "vector", "matrix", "tensor3", "tensor4", "tensor5"};
  std::string s = v.rank() < 6 ? names[v.rank()] : "tensor";
  if (v.scalar()) return s;
  s += "[";
  for (int i = 0; i < v.rank(); ++i) s += (i ? "x" : "") + std::to_string(v.shape[static_cast<std::size_t>(i)]);
  return s + "]";
}

struct QdataGradient { int offset; };
struct ThirdDerivative { ir::JetVar var; };

enum class SymKind { Field, Constant, Qdata, Coordinate, Let, Def, Measure };
struct Symbol {
  SymKind kind;
  Loc loc;
  Value value;              // Field/Constant/Qdata/Coordinate/Let/Measure
  const Stmt* def = nullptr;  // Def
};

const std::vector<std::pair<std::string, int>>& builtin_functions() {
  static const std::vector<std::pair<std::string, int>> f = {
      {"grad", 1}, {"hess", 1}, {"div", 1}, {"lap", 1}, {"dot", 2}, {"inner", 2}, {"outer", 2},
      {"transpose", 1}, {"tr", 1}, {"det", 1}, {"inv", 1}, {"sym", 1}, {"skew", 1}, {"dev", 1},
      {"norm", 1}, {"sqrt", 1}, {"exp", 1}, {"log", 1}, {"sin", 1}, {"cos", 1}, {"tanh", 1},
      {"abs", 1}, {"sign", 1}, {"pow", 2}, {"min", 2}, {"max", 2}, {"cond", 3}};
  return f;
}
int builtin_arity(const std::string& name) {
  for (const auto& [n, a] : builtin_functions())
    if (n == name) return a;
  return -1;
}
bool is_builtin_value(const std::string& n) { return n == "pi" || n == "identity" || n == "I" || n == "dx"; }

class Lowering {
 public:
  Lowering(CompiledForm& form, int dim, const std::vector<const Stmt*>& statements)
      : form_(form), dim_(dim), stmts_(statements) {
    form_.graphs[dim] = std::make_shared<ir::Graph>();
    g_ = form_.graphs[dim].get();
  }

  void run() {
    for (const Stmt* s : stmts_) statement(*s);
  }

 private:
  CompiledForm& form_;
  int dim_;
  const std::vector<const Stmt*>& stmts_;
  ir::Graph* g_ = nullptr;
  std::map<std::string, Symbol> globals_;
  std::vector<std::map<std::string, Value>> locals_;  // def parameters, innermost last
  std::vector<std::unique_ptr<ir::Differentiator>> spatial_;
  int def_depth_ = 0;

  [[noreturn]] void fail(const Loc& loc, const std::string& msg) const { fail_at(form_.sources, loc, msg); }

  Value scalar(NodeId n) const { return Value{{}, {n}}; }

  // ---- declarations -------------------------------------------------------------------------
  void declare(const std::string& name, const Loc& loc, Symbol sym) {
    if (is_builtin_value(name) || builtin_arity(name) >= 0)
      fail(loc, "'" + name + "' is a builtin name and cannot be redeclared");
    if (auto it = globals_.find(name); it != globals_.end())
      fail(loc, "'" + name + "' is already declared at " + form_.sources.where(it->second.loc));
    sym.loc = loc;
    globals_.emplace(name, std::move(sym));
  }

  Value field_value(ir::Role role, int index, bool is_vector) {
    Value v;
    const int n = is_vector ? dim_ : 1;
    if (is_vector) v.shape = {dim_};
    for (int c = 0; c < n; ++c) v.c.push_back(g_->jet(ir::JetVar{role, index, c, 0}));
    return v;
  }

  void statement(const Stmt& s) {
    g_->set_origin(s.loc);
    switch (s.kind) {
      case StmtKind::Form: case StmtKind::Dimension: case StmtKind::Include: break;
      case StmtKind::Field: {
        for (const auto& item : s.items) {
          Symbol sym{SymKind::Field, item.loc, {}, nullptr};
          if (s.keyword == "qdata") {
            int idx = -1;
            for (std::size_t i = 0; i < form_.qdata.size(); ++i)
              if (form_.qdata[i].name == item.name && form_.qdata[i].loc.offset == item.loc.offset) idx = static_cast<int>(i);
            const auto& q = form_.qdata[static_cast<std::size_t>(idx)];
            sym.kind = SymKind::Qdata;
            const int off = form_.qdata_offset(idx, dim_);
            for (int r = 0; r < q.rank; ++r) sym.value.shape.push_back(dim_);
            for (int i = 0; i < q.size(dim_); ++i) sym.value.c.push_back(g_->qdata(off + i));
          } else {
            const FieldDecl* f = nullptr;
            int index = 0;
            for (const auto& fd : form_.fields) {
              if (fd.name == item.name) { f = &fd; break; }
            }
            for (const auto* fd : form_.fields_of(f->role)) {
              if (fd == f) break;
              ++index;
            }
            sym.value = field_value(f->role, index, f->is_vector);
          }
          declare(item.name, item.loc, std::move(sym));
        }
        break;
      }
      case StmtKind::Constant: {
        for (const auto& item : s.items) {
          int idx = 0;
          while (form_.constants[static_cast<std::size_t>(idx)].name != item.name) ++idx;
          if (item.value) {
            const Value v = expr(*item.value);
            if (!v.scalar() || v.measure || v.condition || !g_->is_const(v.c[0]))
              fail(item.value->loc, "the default of constant '" + item.name +
                                        "' must be a constant scalar expression (numbers, pi, operators)");
            form_.constants[static_cast<std::size_t>(idx)].default_value = g_->node(v.c[0]).value;
          }
          declare(item.name, item.loc, Symbol{SymKind::Constant, item.loc, scalar(g_->param(idx)), nullptr});
        }
        break;
      }
      case StmtKind::Coordinate: {
        Value v;
        v.shape = {dim_};
        for (int i = 0; i < dim_; ++i) v.c.push_back(g_->coord(i));
        declare(s.name, s.name_loc, Symbol{SymKind::Coordinate, s.name_loc, v, nullptr});
        break;
      }
      case StmtKind::Let: {
        Value v = expr(*s.body);
        declare(s.name, s.name_loc, Symbol{SymKind::Let, s.name_loc, std::move(v), nullptr});
        break;
      }
      case StmtKind::Measure: {
        Value v = expr(*s.body);
        if (!v.measure)
          fail(s.body->loc, "measure '" + s.name + "' must be a weighted measure such as 2*pi*x[0]*dx; found " +
                                shape_name(v));
        declare(s.name, s.name_loc, Symbol{SymKind::Measure, s.name_loc, std::move(v), nullptr});
        break;
      }
      case StmtKind::Def: {
        std::set<std::string> seen;
        for (std::size_t i = 0; i < s.params.size(); ++i)
          if (!seen.insert(s.params[i]).second) fail(s.param_locs[i], "duplicate parameter '" + s.params[i] + "'");
        declare(s.name, s.name_loc, Symbol{SymKind::Def, s.name_loc, {}, &s});
        break;
      }
      case StmtKind::Output: output(s); break;
    }
  }

  void output(const Stmt& s) {
    auto it = std::find_if(form_.outputs.begin(), form_.outputs.end(), [&](const OutputDecl& o) { return o.name == s.name; });
    OutputDecl& out = *it;
    const Value v = expr(*s.body);
    if (!v.measure)
      fail(s.body->loc, std::string("the right-hand side of ") + to_string(out.kind) + " '" + s.name +
                            "' must be an integral (a scalar times dx or a declared measure); found " + shape_name(v));
    out.integrand[dim_] = v.c[0];
    const auto vars = used_roles(v.c[0]);
    const bool has_u = vars.count(ir::Role::Unknown), has_v = vars.count(ir::Role::Test),
               has_w = vars.count(ir::Role::Trial);
    const std::string what = std::string(to_string(out.kind)) + " '" + s.name + "'";
    switch (out.kind) {
      case OutputKind::Energy: case OutputKind::Constraint:
        if (has_v || has_w) fail(s.body->loc, what + " must not use test or trial functions (use residual/bilinear)");
        if (!has_u) fail(s.body->loc, what + " does not depend on any unknown");
        break;
      case OutputKind::Residual:
        if (!has_v) fail(s.body->loc, what + " must be linear in a test function; none is used");
        if (has_w) fail(s.body->loc, what + " must not use trial functions (its Jacobian is derived)");
        if (!has_u) fail(s.body->loc, what + " does not depend on any unknown (use a linear form)");
        break;
      case OutputKind::Bilinear:
        if (!has_v || !has_w) fail(s.body->loc, what + " must use a test and a trial function");
        if (has_u) fail(s.body->loc, what + " must not depend on unknowns (use a residual)");
        break;
      case OutputKind::Linear:
        if (!has_v) fail(s.body->loc, what + " must use a test function");
        if (has_u || has_w) fail(s.body->loc, what + " must not depend on unknowns or trial functions");
        break;
    }
  }

  std::set<ir::Role> used_roles(NodeId root) const {
    std::set<ir::Role> roles;
    const NodeId roots[] = {root};
    for (NodeId id : g_->reachable(roots))
      if (g_->node(id).op == Op::Jet) roles.insert(g_->jet_var(id).role);
    return roles;
  }

  // ---- expressions --------------------------------------------------------------------------
  std::vector<std::string> visible_names() const {
    std::vector<std::string> names;
    for (const auto& [n, s] : globals_) names.push_back(n);
    if (!locals_.empty())
      for (const auto& [n, v] : locals_.back()) names.push_back(n);
    for (const auto& [n, a] : builtin_functions()) names.push_back(n);
    for (const char* n : {"pi", "identity", "I", "dx"}) names.push_back(n);
    return names;
  }

  [[noreturn]] void unknown_name(const Loc& loc, const std::string& name) const {
    std::string msg = "unknown identifier '" + name + "'";
    const std::string best = closest_name(name, visible_names());
    if (!best.empty()) msg += "; did you mean '" + best + "'?";
    fail(loc, msg);
  }

  Value expr(const Expr& e) {
    const Loc saved = g_->current_origin();
    if (def_depth_ == 0) g_->set_origin(e.loc);
    Value v = expr_impl(e);
    g_->set_origin(saved);
    return v;
  }

  Value expr_impl(const Expr& e) {
    switch (e.kind) {
      case ExprKind::Number: return scalar(g_->constant(e.number));
      case ExprKind::Name: return name(e);
      case ExprKind::Call: return call(e);
      case ExprKind::Index: return index(e);
      case ExprKind::List: return list(e);
      case ExprKind::Unary: {
        Value a = expr(*e.args[0]);
        if (e.name == "not") {
          if (!a.condition) fail(e.loc, "'not' expects a condition (a comparison); found " + shape_name(a));
          return cond_value(g_->logic(Op::Not, a.c[0]));
        }
        no_condition(a, e.args[0]->loc);
        for (auto& c : a.c) c = g_->neg(c);
        return a;
      }
      case ExprKind::Binary: return binary(e);
      case ExprKind::If: {
        const Value c = expr(*e.args[0]);
        if (!c.condition) fail(e.args[0]->loc, "the condition of 'if' must be a comparison; found " + shape_name(c));
        return select(c, expr(*e.args[1]), expr(*e.args[2]), e.loc);
      }
    }
    fail(e.loc, "internal: unhandled expression");
  }

  Value cond_value(NodeId n) const {
    Value v{{}, {n}};
    v.condition = true;
    return v;
  }

  void no_condition(const Value& v, const Loc& loc) const {
    if (v.condition) fail(loc, "a condition can only be used in 'if ... then ... else' or cond(); found it as an operand");
  }
  void plain(const Value& v, const Loc& loc, const std::string& what) const {
    no_condition(v, loc);
    if (v.measure) fail(loc, what + " cannot be applied to a measure");
  }

  Value select(const Value& c, const Value& a, const Value& b, const Loc& loc) {
    if (a.shape != b.shape || a.measure != b.measure || a.condition || b.condition)
      fail(loc, "the branches of a conditional must have the same shape; found " + shape_name(a) + " and " + shape_name(b));
    Value r = a;
    for (std::size_t i = 0; i < r.c.size(); ++i) r.c[i] = g_->select(c.c[0], a.c[i], b.c[i]);
    return r;
  }

  Value name(const Expr& e) {
    if (!locals_.empty()) {
      if (auto it = locals_.back().find(e.name); it != locals_.back().end()) return it->second;
    }
    if (auto it = globals_.find(e.name); it != globals_.end()) {
      if (it->second.kind == SymKind::Def)
        fail(e.loc, "'" + e.name + "' is a function; call it with arguments: " + e.name + "(...)");
      return it->second.value;
    }
    if (e.name == "pi") return scalar(g_->constant(std::numbers::pi));
    if (e.name == "identity" || e.name == "I") return identity();
    if (e.name == "dx") {
      Value v = scalar(g_->one());
      v.measure = true;
      return v;
    }
    if (builtin_arity(e.name) >= 0) fail(e.loc, "'" + e.name + "' is a function; call it with arguments: " + e.name + "(...)");
    unknown_name(e.loc, e.name);
  }

  Value identity() const {
    Value v;
    v.shape = {dim_, dim_};
    for (int i = 0; i < dim_; ++i)
      for (int j = 0; j < dim_; ++j) v.c.push_back(i == j ? g_->one() : g_->zero());
    return v;
  }

  Value list(const Expr& e) {
    std::vector<Value> items;
    for (const auto& a : e.args) items.push_back(expr(*a));
    Value r;
    r.shape = items[0].shape;
    r.shape.insert(r.shape.begin(), static_cast<int>(items.size()));
    for (std::size_t i = 0; i < items.size(); ++i) {
      plain(items[i], e.args[i]->loc, "a list literal");
      if (items[i].shape != items[0].shape)
        fail(e.args[i]->loc, "all entries of a literal must have the same shape; entry " + std::to_string(i) + " is " +
                                 shape_name(items[i]) + ", entry 0 is " + shape_name(items[0]));
      r.c.insert(r.c.end(), items[i].c.begin(), items[i].c.end());
    }
    if (r.rank() > 4) fail(e.loc, "tensors of rank above 4 are not supported");
    return r;
  }

  Value index(const Expr& e) {
    Value base = expr(*e.args[0]);
    plain(base, e.args[0]->loc, "indexing");
    const int k = static_cast<int>(e.args.size()) - 1;
    if (k > base.rank())
      fail(e.loc, "too many indices: " + std::to_string(k) + " given for " + shape_name(base));
    std::size_t offset = 0, stride = base.c.size();
    for (int i = 0; i < k; ++i) {
      const Value iv = expr(*e.args[static_cast<std::size_t>(i) + 1]);
      const Loc& il = e.args[static_cast<std::size_t>(i) + 1]->loc;
      if (!iv.scalar() || iv.measure || iv.condition || !g_->is_const(iv.c[0]))
        fail(il, "an index must be an integer constant expression");
      const double d = g_->node(iv.c[0]).value;
      const int extent = base.shape[static_cast<std::size_t>(i)];
      if (d != std::floor(d) || d < 0 || d >= extent)
        fail(il, "index " + std::to_string(static_cast<long long>(d)) + " is out of range 0.." + std::to_string(extent - 1) +
                     " for " + shape_name(base) + " (dimension " + std::to_string(dim_) + ")");
      stride /= static_cast<std::size_t>(extent);
      offset += static_cast<std::size_t>(d) * stride;
    }
    Value r;
    r.shape.assign(base.shape.begin() + k, base.shape.end());
    r.c.assign(base.c.begin() + static_cast<std::ptrdiff_t>(offset), base.c.begin() + static_cast<std::ptrdiff_t>(offset + stride));
    return r;
  }

  Value binary(const Expr& e) {
    const std::string& op = e.name;
    Value a = expr(*e.args[0]);
    Value b = expr(*e.args[1]);
    if (op == "and" || op == "or") {
      if (!a.condition || !b.condition)
        fail(e.loc, "'" + op + "' combines conditions (comparisons); found " + shape_name(a) + " and " + shape_name(b));
      return cond_value(g_->logic(op == "and" ? Op::And : Op::Or, a.c[0], b.c[0]));
    }
    no_condition(a, e.args[0]->loc);
    no_condition(b, e.args[1]->loc);
    static const std::map<std::string, Op> cmp = {{"<", Op::Lt}, {"<=", Op::Le}, {">", Op::Gt},
                                                  {">=", Op::Ge}, {"==", Op::Eq}, {"!=", Op::Ne}};
    if (auto it = cmp.find(op); it != cmp.end()) {
      if (!a.scalar() || !b.scalar() || a.measure || b.measure)
        fail(e.loc, "comparison '" + op + "' needs two scalars; found " + shape_name(a) + " and " + shape_name(b));
      return cond_value(g_->compare(it->second, a.c[0], b.c[0]));
    }
    if (op == "+" || op == "-") {
      if (a.shape != b.shape || a.measure != b.measure)
        fail(e.loc, std::string("cannot ") + (op == "+" ? "add " : "subtract ") + shape_name(b) + (op == "+" ? " to " : " from ") +
                        shape_name(a) + (a.measure != b.measure ? " (write every term as integrand * dx)" : ""));
      for (std::size_t i = 0; i < a.c.size(); ++i) a.c[i] = op == "+" ? g_->add(a.c[i], b.c[i]) : g_->sub(a.c[i], b.c[i]);
      return a;
    }
    if (op == "*") return multiply(a, b, e.loc);
    if (op == "/") {
      if (!b.scalar() || b.measure)
        fail(e.loc, "division needs a scalar divisor; found " + shape_name(a) + " / " + shape_name(b));
      for (auto& c : a.c) c = g_->div(c, b.c[0]);
      return a;
    }
    if (op == "^") {
      if (!a.scalar() || !b.scalar() || a.measure || b.measure)
        fail(e.loc, "'^' needs scalar operands; found " + shape_name(a) + " ^ " + shape_name(b) +
                        (a.rank() > 0 ? " (for a squared norm write dot(a, a) or inner(A, A))" : ""));
      return scalar(g_->pow(a.c[0], b.c[0]));
    }
    fail(e.loc, "internal: unknown operator '" + op + "'");
  }

  Value scale(Value t, NodeId s) {
    for (auto& c : t.c) c = g_->mul(s, c);
    return t;
  }

  Value multiply(const Value& a, const Value& b, const Loc& loc) {
    if (a.measure && b.measure) fail(loc, "cannot multiply two measures");
    if (a.scalar() || b.scalar()) {
      Value r = a.scalar() ? scale(b, a.c[0]) : scale(a, b.c[0]);
      r.measure = a.measure || b.measure;
      if (r.measure && !r.scalar()) fail(loc, "a measure can only multiply a scalar integrand; found " + shape_name(a.scalar() ? b : a));
      return r;
    }
    if (a.measure || b.measure) fail(loc, "a measure can only multiply a scalar integrand");
    if (a.rank() == 2 && (b.rank() == 1 || b.rank() == 2) && a.shape[1] == b.shape[0]) return contract(a, b);
    std::string hint;
    if (a.rank() == 1 && b.rank() == 1) hint = "; use dot(a, b) for the scalar product or outer(a, b) for the tensor product";
    else if (a.rank() == 1 && b.rank() == 2) hint = "; use dot(v, A) or transpose(A)*v";
    else if (a.rank() == 2 && b.rank() <= 2) hint = " (inner dimensions differ)";
    fail(loc, "cannot multiply " + shape_name(a) + " and " + shape_name(b) + hint);
  }

  /// Contraction of the last index of a with the first of b.
  Value contract(const Value& a, const Value& b) {
    const int n = a.shape.back();
    const std::size_t left = a.c.size() / static_cast<std::size_t>(n), right = b.c.size() / static_cast<std::size_t>(n);
    Value r;
    r.shape.assign(a.shape.begin(), a.shape.end() - 1);
    r.shape.insert(r.shape.end(), b.shape.begin() + 1, b.shape.end());
    for (std::size_t i = 0; i < left; ++i)
      for (std::size_t j = 0; j < right; ++j) {
        NodeId s = g_->zero();
        for (int k = 0; k < n; ++k)
          s = g_->add(s, g_->mul(a.c[i * static_cast<std::size_t>(n) + static_cast<std::size_t>(k)], b.c[static_cast<std::size_t>(k) * right + j]));
        r.c.push_back(s);
      }
    return r;
  }

  // ---- spatial differentiation --------------------------------------------------------------
  ir::Differentiator& spatial(int i) {
    if (spatial_.empty()) {
      for (int k = 0; k < dim_; ++k) {
        spatial_.push_back(std::make_unique<ir::Differentiator>(*g_, [k, d = dim_](ir::Graph& g, NodeId t) -> NodeId {
          const ir::Node& n = g.node(t);
          switch (n.op) {
            case Op::Coord: return n.arg[0] == k ? g.one() : g.zero();
            case Op::Param: return g.zero();
            case Op::Qdata: throw QdataGradient{n.arg[0]};
            case Op::Jet: {
              ir::JetVar v = g.jet_var(t);
              if (v.slot == 0) v.slot = 1 + k;
              else if (v.slot <= d) v.slot = ir::hessian_slot(v.slot - 1, k, d);
              else throw ThirdDerivative{v};
              return g.jet(v);
            }
            default: return g.zero();
          }
        }));
      }
    }
    return *spatial_[static_cast<std::size_t>(i)];
  }

  std::string qdata_name(int offset) const {
    for (std::size_t i = 0; i < form_.qdata.size(); ++i) {
      const int off = form_.qdata_offset(static_cast<int>(i), dim_);
      if (offset >= off && offset < off + form_.qdata[i].size(dim_)) return form_.qdata[i].name;
    }
    return "?";
  }

  Value gradient(const Value& v, const Loc& loc, const std::string& fn) {
    plain(v, loc, fn);
    if (v.rank() >= 4) fail(loc, fn + " of " + shape_name(v) + " would exceed rank 4");
    Value r;
    r.shape = v.shape;
    r.shape.push_back(dim_);
    try {
      for (NodeId c : v.c)
        for (int i = 0; i < dim_; ++i) r.c.push_back(spatial(i).derivative(c));
    } catch (const QdataGradient& q) {
      fail(loc, fn + " of an expression that depends on the quadrature-point datum '" + qdata_name(q.offset) +
                    "': qdata has no spatial derivatives (pass its derivatives as further qdata, or declare it a coefficient)");
    } catch (const ThirdDerivative& t) {
      fail(loc, fn + " needs third derivatives of '" + form_.field(t.var.role, t.var.field).name +
                    "', but the basis provides values, gradients and Hessians only");
    }
    return r;
  }

  // ---- calls --------------------------------------------------------------------------------
  Value call(const Expr& e) {
    if (auto it = globals_.find(e.name); it != globals_.end()) {
      if (it->second.kind != SymKind::Def)
        fail(e.loc, "'" + e.name + "' is not a function (declared at " + form_.sources.where(it->second.loc) + ")");
      return call_def(e, *it->second.def);
    }
    const int arity = builtin_arity(e.name);
    if (arity < 0) {
      std::vector<std::string> fns;
      for (const auto& [n, s] : globals_)
        if (s.kind == SymKind::Def) fns.push_back(n);
      for (const auto& [n, a] : builtin_functions()) fns.push_back(n);
      std::string msg = "unknown function '" + e.name + "'";
      const std::string best = closest_name(e.name, fns);
      if (!best.empty()) msg += "; did you mean '" + best + "'?";
      fail(e.loc, msg);
    }
    if (static_cast<int>(e.args.size()) != arity)
      fail(e.loc, "function '" + e.name + "' takes " + std::to_string(arity) + " argument" + (arity == 1 ? "" : "s") +
                      ", got " + std::to_string(e.args.size()));
    std::vector<Value> a;
    for (const auto& x : e.args) a.push_back(expr(*x));
    const std::string& f = e.name;
    const Loc& l0 = e.args[0]->loc;
    if (f == "cond") {
      if (!a[0].condition) fail(l0, "the first argument of cond() must be a comparison; found " + shape_name(a[0]));
      return select(a[0], a[1], a[2], e.loc);
    }
    for (std::size_t i = 0; i < a.size(); ++i) plain(a[i], e.args[i]->loc, "function '" + f + "'");
    if (f == "grad") return gradient(a[0], e.loc, "grad");
    if (f == "hess") return gradient(gradient(a[0], e.loc, "hess"), e.loc, "hess");
    if (f == "div" || f == "lap") {
      if (f == "div" && a[0].rank() < 1) fail(l0, "div expects a vector or matrix; found " + shape_name(a[0]));
      if (f == "div" && a[0].shape.back() != dim_)
        fail(l0, "div expects a last index of extent " + std::to_string(dim_) + "; found " + shape_name(a[0]));
      if (f == "lap" && a[0].rank() > 1) fail(l0, "lap expects a scalar or vector; found " + shape_name(a[0]));
      const Value src = f == "div" ? a[0] : gradient(a[0], e.loc, "lap");
      const Value g = gradient(src, e.loc, f);  // [..., d, d]: trace of the last two indices
      Value r;
      r.shape.assign(g.shape.begin(), g.shape.end() - 2);
      const std::size_t blocks = g.c.size() / static_cast<std::size_t>(dim_ * dim_);
      for (std::size_t b = 0; b < blocks; ++b) {
        NodeId s = g_->zero();
        for (int i = 0; i < dim_; ++i) s = g_->add(s, g.c[b * static_cast<std::size_t>(dim_ * dim_) + static_cast<std::size_t>(i * dim_ + i)]);
        r.c.push_back(s);
      }
      return r;
    }
    if (f == "dot") {
      if (a[0].scalar() || a[1].scalar() || a[0].shape.back() != a[1].shape.front())
        fail(e.loc, "dot contracts the last index of its first argument with the first index of its second; cannot contract " +
                        shape_name(a[0]) + " with " + shape_name(a[1]));
      if (a[0].rank() + a[1].rank() - 2 > 4) fail(e.loc, "dot would give a tensor of rank above 4");
      return contract(a[0], a[1]);
    }
    if (f == "inner") {
      if (a[0].shape != a[1].shape) fail(e.loc, "inner needs two tensors of the same shape; found " + shape_name(a[0]) + " and " + shape_name(a[1]));
      NodeId s = g_->zero();
      for (std::size_t i = 0; i < a[0].c.size(); ++i) s = g_->add(s, g_->mul(a[0].c[i], a[1].c[i]));
      return scalar(s);
    }
    if (f == "outer") {
      if (a[0].rank() + a[1].rank() > 4) fail(e.loc, "outer would give a tensor of rank above 4");
      Value r;
      r.shape = a[0].shape;
      r.shape.insert(r.shape.end(), a[1].shape.begin(), a[1].shape.end());
      for (NodeId x : a[0].c)
        for (NodeId y : a[1].c) r.c.push_back(g_->mul(x, y));
      return r;
    }
    if (f == "norm") {
      NodeId s = g_->zero();
      for (NodeId x : a[0].c) s = g_->add(s, g_->mul(x, x));
      return scalar(g_->unary(Op::Sqrt, s));
    }
    static const std::set<std::string> matrix_fns = {"transpose", "tr", "det", "inv", "sym", "skew", "dev"};
    if (matrix_fns.count(f)) {
      const Value& m = a[0];
      if (m.rank() != 2 || m.shape[0] != m.shape[1])
        fail(l0, f + " expects a square matrix; found " + shape_name(m));
      return matrix_function(f, m, e.loc);
    }
    // Scalar functions.
    for (std::size_t i = 0; i < a.size(); ++i)
      if (!a[i].scalar())
        fail(e.args[i]->loc, "function '" + f + "' expects scalar arguments; argument " + std::to_string(i + 1) + " is " + shape_name(a[i]));
    static const std::map<std::string, Op> unary_ops = {{"sqrt", Op::Sqrt}, {"exp", Op::Exp}, {"log", Op::Log},
                                                        {"sin", Op::Sin},   {"cos", Op::Cos}, {"tanh", Op::Tanh},
                                                        {"abs", Op::Abs},   {"sign", Op::Sign}};
    if (auto it = unary_ops.find(f); it != unary_ops.end()) return scalar(g_->unary(it->second, a[0].c[0]));
    if (f == "pow") return scalar(g_->pow(a[0].c[0], a[1].c[0]));
    if (f == "min") return scalar(g_->select(g_->compare(Op::Le, a[0].c[0], a[1].c[0]), a[0].c[0], a[1].c[0]));
    if (f == "max") return scalar(g_->select(g_->compare(Op::Ge, a[0].c[0], a[1].c[0]), a[0].c[0], a[1].c[0]));
    fail(e.loc, "internal: unhandled function '" + f + "'");
  }

  Value matrix_function(const std::string& f, const Value& m, const Loc& loc) {
    const int n = m.shape[0];
    auto at = [&](int i, int j) { return m.c[static_cast<std::size_t>(i * n + j)]; };
    Value r;
    r.shape = m.shape;
    if (f == "transpose" || f == "sym" || f == "skew" || f == "dev") {
      NodeId trace = g_->zero();
      for (int i = 0; i < n; ++i) trace = g_->add(trace, at(i, i));
      for (int i = 0; i < n; ++i)
        for (int j = 0; j < n; ++j) {
          NodeId x = at(j, i);
          if (f == "sym") x = g_->mul(g_->constant(0.5), g_->add(at(i, j), at(j, i)));
          if (f == "skew") x = g_->mul(g_->constant(0.5), g_->sub(at(i, j), at(j, i)));
          if (f == "dev") x = i == j ? g_->sub(at(i, j), g_->div(trace, g_->constant(n))) : at(i, j);
          r.c.push_back(x);
        }
      return r;
    }
    if (f == "tr") {
      NodeId s = g_->zero();
      for (int i = 0; i < n; ++i) s = g_->add(s, at(i, i));
      return scalar(s);
    }
    if (n > 3) fail(loc, f + " is implemented for matrices up to 3x3; found " + shape_name(m));
    // Cofactors C_ij; det = Σ_j a_0j C_0j; inv = C^T / det.
    std::vector<NodeId> cof(static_cast<std::size_t>(n * n));
    auto C = [&](int i, int j) -> NodeId& { return cof[static_cast<std::size_t>(i * n + j)]; };
    if (n == 1) C(0, 0) = g_->one();
    if (n == 2) {
      C(0, 0) = at(1, 1); C(0, 1) = g_->neg(at(1, 0));
      C(1, 0) = g_->neg(at(0, 1)); C(1, 1) = at(0, 0);
    }
    if (n == 3) {
      for (int i = 0; i < 3; ++i)
        for (int j = 0; j < 3; ++j) {
          const int i1 = (i + 1) % 3, i2 = (i + 2) % 3, j1 = (j + 1) % 3, j2 = (j + 2) % 3;
          C(i, j) = g_->sub(g_->mul(at(i1, j1), at(i2, j2)), g_->mul(at(i1, j2), at(i2, j1)));
        }
    }
    NodeId det = g_->zero();
    for (int j = 0; j < n; ++j) det = g_->add(det, g_->mul(at(0, j), C(0, j)));
    if (f == "det") return scalar(det);
    for (int i = 0; i < n; ++i)
      for (int j = 0; j < n; ++j) r.c.push_back(g_->div(C(j, i), det));
    return r;
  }

  Value call_def(const Expr& e, const Stmt& def) {
    if (e.args.size() != def.params.size())
      fail(e.loc, "function '" + def.name + "' (defined at " + form_.sources.where(def.name_loc) + ") takes " +
                      std::to_string(def.params.size()) + " argument" + (def.params.size() == 1 ? "" : "s") + ", got " +
                      std::to_string(e.args.size()));
    if (def_depth_ > 64) fail(e.loc, "function calls nested too deeply (recursive definition of '" + def.name + "'?)");
    std::map<std::string, Value> scope;
    for (std::size_t i = 0; i < e.args.size(); ++i) scope[def.params[i]] = expr(*e.args[i]);
    locals_.push_back(std::move(scope));
    ++def_depth_;
    Value r = expr(*def.body);
    --def_depth_;
    locals_.pop_back();
    return r;
  }
};

std::string read_file(const std::filesystem::path& p, bool& ok) {
  std::ifstream in(p, std::ios::binary);
  ok = static_cast<bool>(in);
  std::ostringstream s;
  s << in.rdbuf();
  return s.str();
}

/// Parses a file and splices in its includes (depth first), detecting cycles.
void expand(CompiledForm& form, int file, const CompileOptions& options, std::vector<std::filesystem::path>& stack,
            std::vector<std::unique_ptr<std::vector<Stmt>>>& storage, std::vector<const Stmt*>& out) {
  storage.push_back(std::make_unique<std::vector<Stmt>>(ast::parse_form(form.sources, file)));
  const auto& stmts = *storage.back();
  for (const Stmt& s : stmts) {
    if (s.kind != StmtKind::Include) {
      out.push_back(&s);
      continue;
    }
    std::vector<std::filesystem::path> candidates;
    candidates.push_back(form.sources.file(file).path.parent_path() / s.path);
    for (const auto& d : options.include_dirs) candidates.push_back(d / s.path);
    std::filesystem::path found;
    for (const auto& c : candidates)
      if (std::filesystem::is_regular_file(c)) { found = c; break; }
    if (found.empty()) {
      std::string searched;
      for (const auto& c : candidates) {
        const std::string dir = c.parent_path().string();
        searched += (searched.empty() ? "" : ", ") + (dir.empty() ? std::string(".") : dir);
      }
      fail_at(form.sources, s.loc, "cannot find include file '" + s.path + "' (searched: " + searched + ")");
    }
    const auto canonical = std::filesystem::weakly_canonical(found);
    if (std::find(stack.begin(), stack.end(), canonical) != stack.end())
      fail_at(form.sources, s.loc, "include cycle: '" + s.path + "' is already being included");
    bool ok = false;
    std::string text = read_file(found, ok);
    if (!ok) fail_at(form.sources, s.loc, "cannot read include file '" + found.string() + "'");
    form.dependencies.push_back(found);
    const int idx = form.sources.add(found.lexically_normal(), std::move(text));
    stack.push_back(canonical);
    expand(form, idx, options, stack, storage, out);
    stack.pop_back();
  }
}

/// Dimension-independent declarations: module name, dimensions, fields, constants, qdata, outputs.
void collect_declarations(CompiledForm& form, const std::vector<const Stmt*>& stmts) {
  std::map<std::string, Loc> outputs;
  bool have_dims = false;
  for (const Stmt* s : stmts) {
    switch (s->kind) {
      case StmtKind::Form: form.module = s->name; break;
      case StmtKind::Dimension:
        if (have_dims) fail_at(form.sources, s->loc, "the dimensions are already given");
        have_dims = true;
        for (int d : s->dims) {
          if (d < 1 || d > 3) fail_at(form.sources, s->loc, "dimension " + std::to_string(d) + " is not supported; expected 1, 2 or 3");
          if (std::find(form.dims.begin(), form.dims.end(), d) != form.dims.end())
            fail_at(form.sources, s->loc, "dimension " + std::to_string(d) + " is listed twice");
          form.dims.push_back(d);
        }
        break;
      case StmtKind::Field:
        for (const auto& item : s->items) {
          if (s->keyword == "qdata") {
            static const std::vector<std::string> shapes = {"scalar", "vector", "matrix", "tensor3"};
            auto it = std::find(shapes.begin(), shapes.end(), item.shape.empty() ? "scalar" : item.shape);
            if (it == shapes.end()) {
              const std::string best = closest_name(item.shape, shapes);
              fail_at(form.sources, item.shape_loc, "unknown shape '" + item.shape + "'; expected scalar, vector, matrix or tensor3" +
                                                         (best.empty() ? "" : " (did you mean '" + best + "'?)"));
            }
            form.qdata.push_back(QdataDecl{item.name, static_cast<int>(it - shapes.begin()), item.loc});
          } else {
            if (!item.shape.empty() && item.shape != "scalar" && item.shape != "vector")
              fail_at(form.sources, item.shape_loc, "unknown shape '" + item.shape + "' for " + s->keyword + " '" + item.name +
                                                         "'; expected scalar or vector (matrix and tensor3 are for qdata)");
            FieldDecl f;
            f.name = item.name;
            f.loc = item.loc;
            f.is_vector = item.shape == "vector";
            f.role = s->keyword == "unknown" ? ir::Role::Unknown : s->keyword == "test" ? ir::Role::Test
                   : s->keyword == "trial"   ? ir::Role::Trial : ir::Role::Coefficient;
            form.fields.push_back(f);
          }
        }
        break;
      case StmtKind::Constant:
        for (const auto& item : s->items) form.constants.push_back(ConstantDecl{item.name, std::nullopt, item.loc});
        break;
      case StmtKind::Coordinate:
        if (!form.coordinate.empty()) fail_at(form.sources, s->name_loc, "the coordinate is already named '" + form.coordinate + "'");
        form.coordinate = s->name;
        break;
      case StmtKind::Output: {
        if (auto it = outputs.find(s->name); it != outputs.end())
          fail_at(form.sources, s->name_loc, "output '" + s->name + "' is already defined at " + form.sources.where(it->second));
        outputs[s->name] = s->name_loc;
        OutputDecl o;
        o.name = s->name;
        o.loc = s->loc;
        o.kind = s->keyword == "energy" ? OutputKind::Energy : s->keyword == "constraint" ? OutputKind::Constraint
               : s->keyword == "residual" ? OutputKind::Residual : s->keyword == "bilinear" ? OutputKind::Bilinear
               : OutputKind::Linear;
        if (s->target) {
          if (s->target->kind == ExprKind::Number) {
            o.target_value = s->target->number;
          } else if (s->target->kind == ExprKind::Name) {
            auto it = std::find_if(form.constants.begin(), form.constants.end(), [&](const auto& c) { return c.name == s->target->name; });
            if (it == form.constants.end()) {
              std::vector<std::string> names;
              for (const auto& c : form.constants) names.push_back(c.name);
              const std::string best = closest_name(s->target->name, names);
              fail_at(form.sources, s->target->loc, "the target of constraint '" + s->name + "' must be a declared constant or a number; '" +
                                                         s->target->name + "' is not a constant" + (best.empty() ? "" : "; did you mean '" + best + "'?"));
            }
            o.target_constant = static_cast<int>(it - form.constants.begin());
          } else {
            fail_at(form.sources, s->target->loc, "the target of a constraint must be a constant name or a number");
          }
        }
        form.outputs.push_back(std::move(o));
        break;
      }
      default: break;
    }
  }
  if (form.dims.empty()) form.dims.push_back(2);
  if (form.outputs.empty()) fail_at(form.sources, Loc{0, 0}, "the form defines no output (energy, constraint, residual, bilinear or linear)");
  // Residuals and bilinear forms pair test functions with unknowns / trials, in order.
  auto tests = form.fields_of(ir::Role::Test);
  for (const auto& o : form.outputs) {
    if (o.kind != OutputKind::Residual && o.kind != OutputKind::Bilinear) continue;
    const auto cols = form.fields_of(o.kind == OutputKind::Residual ? ir::Role::Unknown : ir::Role::Trial);
    const char* what = o.kind == OutputKind::Residual ? "unknown" : "trial";
    if (tests.size() != cols.size())
      fail_at(form.sources, o.loc, std::string(to_string(o.kind)) + " '" + o.name + "' needs one test function per " + what + " (" +
                                       std::to_string(cols.size()) + " " + what + (cols.size() == 1 ? "" : "s") + ", " +
                                       std::to_string(tests.size()) + " test function" + (tests.size() == 1 ? "" : "s") + ")");
    for (std::size_t i = 0; i < tests.size(); ++i)
      if (tests[i]->is_vector != cols[i]->is_vector)
        fail_at(form.sources, tests[i]->loc, "test function '" + tests[i]->name + "' must have the shape of " + what + " '" +
                                                 cols[i]->name + "' (" + (cols[i]->is_vector ? "vector" : "scalar") + ")");
  }
}

CompiledForm compile_main(CompiledForm form, int main_file, const CompileOptions& options) {
  std::vector<std::filesystem::path> stack{std::filesystem::weakly_canonical(form.sources.file(main_file).path)};
  std::vector<std::unique_ptr<std::vector<Stmt>>> storage;
  std::vector<const Stmt*> stmts;
  expand(form, main_file, options, stack, storage, stmts);
  form.module = form.sources.file(main_file).path.stem().string();
  collect_declarations(form, stmts);
  for (char& ch : form.module)
    if (!std::isalnum(static_cast<unsigned char>(ch)) && ch != '_') ch = '_';
  for (int d : form.dims) Lowering(form, d, stmts).run();
  return form;
}

}  // namespace

CompiledForm compile_source(const std::string& text, const std::filesystem::path& path, const CompileOptions& options) {
  CompiledForm form;
  const int idx = form.sources.add(path, text);
  form.dependencies.push_back(path);
  return compile_main(std::move(form), idx, options);
}

CompiledForm compile_file(const std::filesystem::path& path, const CompileOptions& options) {
  bool ok = false;
  std::string text = read_file(path, ok);
  if (!ok) throw CompileError(path.string() + ": error: cannot open the form file\n");
  return compile_source(text, path, options);
}

}  // namespace lmeform::compiler
