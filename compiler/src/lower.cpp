// Checking and lowering: names, shapes, includes; every expression becomes a tensor of IR nodes
// (one Graph per dimension). Spatial operators are applied here by forward differentiation of the
// component nodes, which pushes grad/hess/div/lap through any expression down to the jets of
// nodal fields (the first differentiation layer of ARCHITECTURE §3).
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <numbers>
#include <fstream>
#include <limits>
#include <set>
#include <map>
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
    case OutputKind::Point: return "point";
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

/// A tensor-valued expression: components (row-major) of IR nodes. A measure is a sum of
/// integrals over domains: then `c` holds one integrand per domain of `domains` (ascending).
struct Value {
  std::vector<int> shape;
  std::vector<NodeId> c;
  bool measure = false;
  bool condition = false;
  std::vector<int> domains;  ///< measures: index into CompiledForm::domains of each integrand
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
  for (int i = 0; i < v.rank(); ++i) {
    if (i > 0) s += 'x';  // appended separately: `"x" + string` trips GCC 12's -Wrestrict false positive
    s += std::to_string(v.shape[static_cast<std::size_t>(i)]);
  }
  return s + "]";
}

/// A constant index as a message shows it: an integer as one (`2`), anything else as %g (`0.5`,
/// `1e+300`, `inf`, `nan`), since casting such a double to an integer type is undefined behaviour.
std::string index_text(double d) {
  if (d == std::floor(d) && std::abs(d) < 1e15) return std::to_string(static_cast<long long>(d));
  if (std::isnan(d)) return "nan";  // %g may print "-nan"
  char text[32];
  std::snprintf(text, sizeof text, "%g", d);
  return text;
}

struct QdataGradient { int offset; };
struct ThirdDerivative { ir::JetVar var; };

enum class SymKind { Field, Constant, Qdata, Coordinate, Let, Def, Measure };
struct Symbol {
  SymKind kind;
  Loc loc;
  Value value;              // Field/Constant/Qdata/Coordinate/Let/Measure
  const Stmt* def = nullptr;  // Def
  int order = 0;            ///< declaration sequence number: a def body sees only smaller ones
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
bool is_builtin_value(const std::string& n) { return n == "pi" || n == "identity" || n == "I" || n == "dx" || n == "ds"; }
/// Builtins that a declaration may hide: short names that forms already use for their own things
/// (`let e = sym(grad(u))`, `unknown n`), so reserving them would break such forms.
bool is_predefined(const std::string& n) { return n == "e" || n == "dim" || n == "n" || n == "spacing"; }

constexpr const char* kNormalOnCells = "the normal n exists only on the boundary: this term is integrated with dx";

constexpr const char* kDefScopeRule = "a def body may use only its parameters and names declared before the def";

class Lowering {
 public:
  Lowering(CompiledForm& form, int dim, const std::vector<const Stmt*>& statements)
      : form_(form), dim_(dim), stmts_(statements) {
    form_.graphs[dim] = std::make_shared<ir::Graph>();
    g_ = form_.graphs[dim].get();
    // Declarations are looked up by name once per declared item: maps keep that linear in the
    // number of declarations (forms with thousands of unknowns exist).
    std::map<ir::Role, int> count_of_role;
    for (const FieldDecl& f : form_.fields) field_of_name_.emplace(f.name, FieldRef{&f, count_of_role[f.role]++});
    for (std::size_t i = 0; i < form_.constants.size(); ++i) constant_index_.emplace(form_.constants[i].name, static_cast<int>(i));
    int offset = 0;
    for (std::size_t i = 0; i < form_.qdata.size(); ++i) {
      qdata_index_.emplace(form_.qdata[i].name, static_cast<int>(i));
      qdata_offset_.push_back(offset);
      offset += form_.qdata[i].size(dim_);
    }
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
  int declared_ = 0;  ///< number of globals declared so far (the next Symbol::order)
  /// The def bodies being lowered, innermost last: their parameters, and the def itself (whose
  /// declaration order bounds the globals its body may see).
  struct DefScope {
    std::map<std::string, Value> params;
    const Symbol* def = nullptr;
  };
  std::vector<DefScope> scopes_;
  std::map<std::string, Value> def_calls_;  ///< lowered def calls by (def, argument nodes)
  std::vector<std::unique_ptr<ir::Differentiator>> spatial_;
  int def_depth_ = 0;
  int expr_depth_ = 0;  ///< current recursion depth of expr()
  struct FieldRef {
    const FieldDecl* decl;
    int index_in_role;
  };
  std::map<std::string, FieldRef> field_of_name_;  ///< first declaration of each name
  std::map<std::string, int> constant_index_;
  std::map<std::string, int> qdata_index_;
  std::vector<int> qdata_offset_;  ///< per qdata, at this dimension
  /// Where the current statement first names the normal and a measure (file -1: not yet), for
  /// diagnostics about a whole output.
  Loc normal_use_{-1, 0}, measure_use_{-1, 0};
  /// Lowering the condition of a `require` or `recommend` line (the only place `spacing` is known).
  bool in_requirement_ = false;

  [[noreturn]] void fail(const Loc& loc, const std::string& msg) const { fail_at(form_.sources, loc, msg); }

  Value scalar(NodeId n) const {
    Value v;
    v.c = {n};
    return v;
  }

  // ---- measures -----------------------------------------------------------------------------
  int domain_index(const Domain& d) {
    const auto it = std::find(form_.domains.begin(), form_.domains.end(), d);
    if (it != form_.domains.end()) return static_cast<int>(it - form_.domains.begin());
    form_.domains.push_back(d);
    return static_cast<int>(form_.domains.size()) - 1;
  }

  /// The measure of one domain with integrand 1 (`dx`, `ds`, `ds(top)`).
  Value unit_measure(const Domain& d, const Loc& use) {
    if (measure_use_.file < 0) measure_use_ = use;
    Value v = scalar(g_->one());
    v.measure = true;
    v.domains = {domain_index(d)};
    return v;
  }

  /// Two measures combined domain by domain (a domain that one of them lacks counts as zero there).
  template <class Combine>
  Value merge_measures(const Value& a, const Value& b, Combine combine) {
    Value r = a;
    r.c.clear();
    r.domains.clear();
    constexpr int kNone = std::numeric_limits<int>::max();
    std::size_t i = 0, j = 0;
    while (i < a.domains.size() || j < b.domains.size()) {
      const bool take_a = i < a.domains.size(), take_b = j < b.domains.size();
      const int da = take_a ? a.domains[i] : kNone, db = take_b ? b.domains[j] : kNone;
      const int d = std::min(da, db);
      r.domains.push_back(d);
      r.c.push_back(combine(da == d ? a.c[i++] : g_->zero(), db == d ? b.c[j++] : g_->zero()));
    }
    return r;
  }

  /// The normal exists at boundary points only: a cell integrand must not read it.
  void require_no_normal_on_cells(const Value& m, const Loc& term) const {
    for (std::size_t i = 0; i < m.domains.size(); ++i)
      if (!form_.domains[static_cast<std::size_t>(m.domains[i])].boundary && g_->reads_normal(m.c[i])) fail(term, kNormalOnCells);
  }

  // ---- declarations -------------------------------------------------------------------------
  void declare(const std::string& name, const Loc& loc, Symbol sym) {
    if (is_builtin_value(name) || builtin_arity(name) >= 0)
      fail(loc, "'" + name + "' is a builtin name and cannot be redeclared");
    if (auto it = globals_.find(name); it != globals_.end())
      fail(loc, "'" + name + "' is already declared at " + form_.sources.where(it->second.loc));
    sym.loc = loc;
    sym.order = declared_++;
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
    normal_use_ = measure_use_ = Loc{-1, 0};
    switch (s.kind) {
      case StmtKind::Form: case StmtKind::Dimension: case StmtKind::Include: break;
      case StmtKind::Field: {
        for (const auto& item : s.items) {
          Symbol sym{SymKind::Field, item.loc, {}, nullptr};
          if (s.keyword == "qdata") {
            const int idx = qdata_index_.at(item.name);
            const auto& q = form_.qdata[static_cast<std::size_t>(idx)];
            sym.kind = SymKind::Qdata;
            const int off = qdata_offset_[static_cast<std::size_t>(idx)];
            for (int r = 0; r < q.rank; ++r) sym.value.shape.push_back(dim_);
            for (int i = 0; i < q.size(dim_); ++i) sym.value.c.push_back(g_->qdata(off + i));
          } else {
            const FieldRef& f = field_of_name_.at(item.name);
            sym.value = field_value(f.decl->role, f.index_in_role, f.decl->is_vector);
          }
          declare(item.name, item.loc, std::move(sym));
        }
        break;
      }
      case StmtKind::Constant: {
        for (const auto& item : s.items) {
          const int idx = constant_index_.at(item.name);
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
          fail(s.body->loc, "measure '" + s.name + "' must be a weighted measure such as 2*pi*x[0]*dx or 2*pi*x[0]*ds; found " +
                                shape_name(v));
        declare(s.name, s.name_loc, Symbol{SymKind::Measure, s.name_loc, std::move(v), nullptr});
        break;
      }
      case StmtKind::Def: {
        std::set<std::string> seen;
        for (std::size_t i = 0; i < s.params.size(); ++i) {
          if (is_builtin_value(s.params[i]) || builtin_arity(s.params[i]) >= 0)
            fail(s.param_locs[i], "'" + s.params[i] + "' is a builtin name and cannot be a parameter");
          if (!seen.insert(s.params[i]).second) fail(s.param_locs[i], "duplicate parameter '" + s.params[i] + "'");
        }
        declare(s.name, s.name_loc, Symbol{SymKind::Def, s.name_loc, {}, &s});
        break;
      }
      case StmtKind::Output: output(s); break;
    }
  }

  void output(const Stmt& s) {
    auto it = std::find_if(form_.outputs.begin(), form_.outputs.end(), [&](const OutputDecl& o) { return o.name == s.name; });
    OutputDecl& out = *it;
    in_requirement_ = s.keyword == "require" || s.keyword == "recommend";
    const Value v = expr(*s.body);
    if (in_requirement_) {
      in_requirement_ = false;
      return requirement(s, out, v);
    }
    if (out.kind == OutputKind::Point) return point_output(s, out, v);
    if (!v.measure)
      fail(s.body->loc, std::string("the right-hand side of ") + to_string(out.kind) + " '" + s.name +
                            "' must be an integral (a scalar times dx, ds or a declared measure); found " + shape_name(v));
    // Terms that vanish (`0*ds`, a branch not taken in this dimension) generate no kernel; if every
    // one does, the first stays, and the checks below say what the output lacks.
    std::map<int, NodeId>& terms = out.integrands[dim_];
    for (std::size_t i = 0; i < v.c.size(); ++i)
      if (!g_->is_const(v.c[i], 0.0)) terms[v.domains[i]] = v.c[i];
    if (terms.empty()) terms[v.domains[0]] = v.c[0];
    std::vector<NodeId> roots;
    for (const auto& [domain, f] : terms) roots.push_back(f);
    const auto vars = used_roles(roots);
    const bool has_u = vars.count(ir::Role::Unknown), has_v = vars.count(ir::Role::Test),
               has_w = vars.count(ir::Role::Trial);
    const std::string what = std::string(to_string(out.kind)) + " '" + s.name + "'";
    switch (out.kind) {
      case OutputKind::Energy: case OutputKind::Constraint:
        if (has_v || has_w) fail(s.body->loc, what + " must not use test or trial functions (use residual/bilinear)");
        // An energy of the coordinates and constants alone is a measured quantity (a length, an
        // area: zero gradient); a constraint must move with the unknowns to constrain them.
        if (!has_u && out.kind == OutputKind::Constraint) fail(s.body->loc, what + " does not depend on any unknown");
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
      case OutputKind::Point: break;
    }
    for (const NodeId f : roots) {
      if (out.kind == OutputKind::Residual || out.kind == OutputKind::Linear || out.kind == OutputKind::Bilinear)
        require_linear(f, ir::Role::Test, what, "test");
      if (out.kind == OutputKind::Bilinear) require_linear(f, ir::Role::Trial, what, "trial");
    }
  }

  /// `point NAME = EXPR`: a value at each quadrature point of the cells, of any shape up to tensor3.
  /// `require CONDITION, "MESSAGE"`: a scalar condition of the constants, the coordinate and the
  /// unknowns, kept as the point value 1 (holds) or 0 (fails).
  void requirement(const Stmt& s, OutputDecl& out, const Value& v) {
    const std::string what = "the requirement \"" + s.message + "\"";
    if (!v.condition || v.rank() != 0)
      fail(s.body->loc, what + " must be a condition (a comparison such as Gc > 0, combined with and, or, not); found " + shape_name(v));
    if (s.message.empty()) fail(s.loc, "a requirement needs a message that says what the model requires");
    const auto roles = used_roles(v.c);
    if (roles.count(ir::Role::Test) || roles.count(ir::Role::Trial) || roles.count(ir::Role::Coefficient))
      fail(s.body->loc, what + " may read the constants, the coordinate and the unknowns (at the start), not test, trial or coefficient fields");
    bool pointwise = roles.count(ir::Role::Unknown) > 0;
    const NodeId roots[] = {v.c[0]};
    for (NodeId id : g_->reachable(roots)) {
      const Op op = g_->node(id).op;
      if (op == Op::Qdata) fail(s.body->loc, what + " must not read quadrature-point data: it is checked at the nodes");
      if (op == Op::Normal) fail(s.body->loc, what + " must not read the normal n: it is checked at the nodes");
      pointwise = pointwise || op == Op::Coord || op == Op::Spacing;
    }
    const std::string& text = form_.sources.file(s.body->begin.file).text;
    const std::size_t from = s.body->begin.offset, to = text.find_last_of(',', text.find('"', from));
    out.requirement_condition = text.substr(from, to == std::string::npos ? std::string::npos : to - from);
    while (!out.requirement_condition.empty() && std::isspace(static_cast<unsigned char>(out.requirement_condition.back())))
      out.requirement_condition.pop_back();
    out.requirement_pointwise = out.requirement_pointwise || pointwise;
    out.point[dim_] = PointValue{{}, {g_->select(v.c[0], g_->constant(1.0), g_->constant(0.0))}};
  }

  void point_output(const Stmt& s, OutputDecl& out, const Value& v) {
    const std::string what = "point output '" + s.name + "'";
    if (v.measure)
      fail(measure_use_.file >= 0 ? measure_use_ : s.body->loc,
           what + " must not contain a measure: it is a value at each quadrature point (remove dx or ds)");
    if (v.condition) fail(s.body->loc, what + " must be a value, not a condition (write if ... then 1 else 0)");
    if (v.rank() > 3) fail(s.body->loc, what + " must be a scalar, vector, matrix or tensor3; found " + shape_name(v));
    const auto roles = used_roles(v.c);
    if (roles.count(ir::Role::Test) || roles.count(ir::Role::Trial))
      fail(s.body->loc, what + " must not use test or trial functions (it has no derivatives)");
    for (const NodeId c : v.c)
      if (g_->reads_normal(c))
        fail(normal_use_.file >= 0 ? normal_use_ : s.body->begin,
             "the normal n exists only on the boundary: " + what + " is evaluated at the cells' quadrature points");
    out.point[dim_] = PointValue{v.shape, v.c};
  }

  /// Fails, pointing at the offending term, unless the integrand f is linear in the fields of
  /// `role`: checked here, where the nodes still know the source they came from.
  void require_linear(NodeId f, ir::Role role, const std::string& what, const std::string& role_word) const {
    const NodeId term = first_nonlinear_node(f, role);
    if (term < 0) return;
    std::string field;
    const NodeId roots[] = {term};
    for (NodeId id : g_->reachable(roots))
      if (g_->node(id).op == Op::Jet && g_->jet_var(id).role == role) {
        field = form_.field(role, g_->jet_var(id).field).name;
        break;
      }
    fail(term_start(g_->origin(term)), what + " is not linear in the " + role_word + " function '" + field + "'");
  }

  /// The innermost node of f that is non-linear in the fields of `role` although its operands are
  /// at most linear in them (v*v, sin(v), 1/v, a comparison of v, ...), or -1 if f is linear.
  /// A polynomial degree per node, capped at 2 (= not linear), in increasing (topological) order.
  NodeId first_nonlinear_node(NodeId f, ir::Role role) const {
    constexpr unsigned char kConstant = 0, kLinear = 1, kNonlinear = 2;
    std::vector<unsigned char> degree(g_->size(), kConstant);
    const NodeId roots[] = {f};
    for (NodeId id : g_->reachable(roots)) {
      const ir::Node& n = g_->node(id);
      const auto deg = [&](int k) { return degree[static_cast<std::size_t>(n.arg[static_cast<std::size_t>(k)])]; };
      unsigned char d = kConstant;
      unsigned char operands = kConstant;  // the highest degree among the operands
      switch (n.op) {
        case Op::Const: case Op::Coord: case Op::Param: case Op::Qdata: break;
        case Op::Jet: d = g_->jet_var(id).role == role ? kLinear : kConstant; break;
        case Op::Add: operands = std::max(deg(0), deg(1)); d = operands; break;
        case Op::Neg: operands = deg(0); d = operands; break;
        case Op::Mul:
          operands = std::max(deg(0), deg(1));
          d = static_cast<unsigned char>(std::min<int>(kNonlinear, deg(0) + deg(1)));
          break;
        case Op::Div: operands = std::max(deg(0), deg(1)); d = deg(1) == kConstant ? deg(0) : kNonlinear; break;
        case Op::Select:
          operands = std::max({deg(0), deg(1), deg(2)});
          d = deg(0) == kConstant ? std::max(deg(1), deg(2)) : kNonlinear;
          break;
        default: {  // functions, powers, comparisons, logic: non-linear in anything they depend on
          for (int k = 0; k < 4 && n.arg[static_cast<std::size_t>(k)] >= 0; ++k) operands = std::max(operands, deg(k));
          d = operands == kConstant ? kConstant : kNonlinear;
        }
      }
      degree[static_cast<std::size_t>(id)] = d;
      if (d == kNonlinear && operands < kNonlinear) return id;
    }
    return -1;
  }

  /// Where the sub-expression that created a node starts. Nodes record the location of their
  /// operator or name (Expr::loc); a diagnostic about a whole term points at its beginning.
  Loc term_start(const Loc& origin) const {
    std::vector<const Expr*> pending;
    for (const Stmt* s : stmts_) {
      if (s->body) pending.push_back(s->body.get());
      for (const auto& item : s->items)
        if (item.value) pending.push_back(item.value.get());
    }
    while (!pending.empty()) {
      const Expr* e = pending.back();
      pending.pop_back();
      if (e->loc.file == origin.file && e->loc.offset == origin.offset) return e->begin;
      for (const auto& a : e->args) pending.push_back(a.get());
    }
    return origin;
  }

  std::set<ir::Role> used_roles(std::span<const NodeId> roots) const {
    std::set<ir::Role> roles;
    for (NodeId id : g_->reachable(roots))
      if (g_->node(id).op == Op::Jet) roles.insert(g_->jet_var(id).role);
    return roles;
  }

  // ---- expressions --------------------------------------------------------------------------
  std::vector<std::string> visible_names() const {
    std::vector<std::string> names;
    for (const auto& [n, s] : globals_)
      if (scopes_.empty() || s.order < scopes_.back().def->order) names.push_back(n);
    if (!scopes_.empty())
      for (const auto& [n, v] : scopes_.back().params) names.push_back(n);
    for (const auto& [n, a] : builtin_functions()) names.push_back(n);
    for (const char* n : {"pi", "identity", "I", "dx", "ds", "e", "dim", "n", "spacing"}) names.push_back(n);
    return names;
  }

  /// The global `name` as seen from where it is used (nullptr: not declared, or a predefined name
  /// whose builtin meaning applies). Inside a def body only names declared before the def count;
  /// using a later one is an error rather than silently binding whatever the caller sees.
  const Symbol* global(const std::string& name, const Loc& use) const {
    const auto it = globals_.find(name);
    if (it == globals_.end()) return nullptr;
    if (scopes_.empty() || it->second.order < scopes_.back().def->order) return &it->second;
    if (is_predefined(name)) return nullptr;
    const Symbol& def = *scopes_.back().def;
    if (&it->second == &def) fail(use, "def '" + name + "' cannot call itself: " + kDefScopeRule);
    fail(use, "'" + name + "' is declared at " + form_.sources.where(it->second.loc) + ", after def '" + def.def->name +
                  "' (" + form_.sources.where(def.loc) + "): " + kDefScopeRule);
  }

  [[noreturn]] void unknown_name(const Loc& loc, const std::string& name) const {
    std::string msg = "unknown identifier '" + name + "'";
    const std::string best = closest_name(name, visible_names());
    if (!best.empty()) msg += "; did you mean '" + best + "'?";
    fail(loc, msg);
  }

  Value expr(const Expr& e) {
    // Lowering recurses once per level of the expression tree, def bodies included: the parser
    // bounds the nesting of one expression, this bounds what def calls stack on top of it.
    constexpr int kMaxDepth = 512;
    if (expr_depth_ >= kMaxDepth)
      fail(e.begin, "expression nested too deeply once def calls are inlined: more than " + std::to_string(kMaxDepth) + " levels");
    ++expr_depth_;
    const Loc saved = g_->current_origin();
    if (def_depth_ == 0) g_->set_origin(e.loc);
    Value v = expr_impl(e);
    g_->set_origin(saved);
    --expr_depth_;
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
      case ExprKind::If: return conditional(*e.args[0], *e.args[1], *e.args[2], e.loc, "the condition of 'if'");
    }
    fail(e.loc, "internal: unhandled expression");
  }

  Value cond_value(NodeId n) const {
    Value v = scalar(n);
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

  /// `if c then a else b` and cond(c, a, b). A condition known at compile time (`dim == 3`) picks
  /// its branch before the other is lowered, so that the other may be invalid in this dimension.
  Value conditional(const Expr& cond, const Expr& a, const Expr& b, const Loc& loc, const std::string& what) {
    const Value c = expr(cond);
    if (!c.condition) fail(cond.loc, what + " must be a comparison; found " + shape_name(c));
    if (g_->is_const(c.c[0])) return expr(g_->node(c.c[0]).value != 0.0 ? a : b);
    return select(c, expr(a), expr(b), loc);
  }

  Value select(const Value& c, const Value& a, const Value& b, const Loc& loc) {
    if (a.shape != b.shape || a.measure != b.measure || a.condition || b.condition)
      fail(loc, "the branches of a conditional must have the same shape; found " + shape_name(a) + " and " + shape_name(b));
    if (a.measure) {
      const Value r = merge_measures(a, b, [&](NodeId x, NodeId y) { return g_->select(c.c[0], x, y); });
      require_no_normal_on_cells(r, loc);
      return r;
    }
    Value r = a;
    for (std::size_t i = 0; i < r.c.size(); ++i) r.c[i] = g_->select(c.c[0], a.c[i], b.c[i]);
    return r;
  }

  Value name(const Expr& e) {
    if (!scopes_.empty()) {
      const auto& params = scopes_.back().params;
      if (auto it = params.find(e.name); it != params.end()) return it->second;
    }
    if (const Symbol* sym = global(e.name, e.loc)) {
      if (sym->kind == SymKind::Def)
        fail(e.loc, "'" + e.name + "' is a function; call it with arguments: " + e.name + "(...)");
      if (sym->value.measure && measure_use_.file < 0) measure_use_ = e.loc;
      return sym->value;
    }
    if (e.name == "pi") return scalar(g_->constant(std::numbers::pi));
    if (e.name == "dim") return scalar(g_->constant(dim_));
    if (e.name == "identity" || e.name == "I") return identity();
    if (e.name == "dx") return unit_measure(Domain{}, e.loc);
    if (e.name == "ds") return unit_measure(Domain{true, ""}, e.loc);
    if (e.name == "spacing") {
      // The node spacing is a property of the node set, not of the model's fields: an integrand
      // that read it would change with the discretization.
      if (!in_requirement_)
        fail(e.loc, "'spacing' (the local node spacing) is known in require lines only, where the runtime checks the model's "
                    "resolution rules (require l >= 2*spacing, ...)");
      return scalar(g_->spacing());
    }
    if (e.name == "n") {
      if (normal_use_.file < 0) normal_use_ = e.loc;
      Value v;
      v.shape = {dim_};
      for (int i = 0; i < dim_; ++i) v.c.push_back(g_->normal(i));
      return v;
    }
    if (builtin_arity(e.name) >= 0 || e.name == "e")
      fail(e.loc, "'" + e.name + "' is a function; call it with arguments: " + e.name + "(...)");
    unknown_name(e.loc, e.name);
  }

  /// ds(part): the measure of a named part of the boundary. The part is a name the runtime resolves
  /// (a scene's boundary), not an expression: it is not looked up.
  Value boundary_measure(const Expr& e) {
    if (e.args.size() != 1)
      fail(e.loc, e.args.empty() ? "ds() needs the name of a boundary part: write ds for the whole boundary, ds(top) for a part"
                                 : "ds takes one boundary part name, got " + std::to_string(e.args.size()) + " arguments");
    const Expr& arg = *e.args[0];
    if (arg.kind != ExprKind::Name)
      fail(arg.begin, std::string("the argument of ds must be the name of a boundary part (an identifier such as top); found ") +
                          (arg.kind == ExprKind::Number ? "a number" : "an expression"));
    return unit_measure(Domain{true, arg.name}, e.loc);
  }

  /// e(i): the i-th Cartesian unit vector of the current dimension.
  Value unit_vector(const Expr& e) {
    if (e.args.size() != 1) fail(e.loc, "function 'e' takes 1 argument, got " + std::to_string(e.args.size()));
    const Expr& arg = *e.args[0];
    const Value iv = expr(arg);
    if (!iv.scalar() || iv.measure || iv.condition || !g_->is_const(iv.c[0]) ||
        g_->node(iv.c[0]).value != std::floor(g_->node(iv.c[0]).value))
      fail(arg.begin, "the argument of e() must be an integer constant expression (such as 0, 1 or dim - 1)");
    const double i = g_->node(iv.c[0]).value;
    if (i < 0 || i >= dim_)
      fail(arg.begin, "unit vector e(" + index_text(i) + ") does not exist in dimension " +
                          std::to_string(dim_) + " (e(0) to e(" + std::to_string(dim_ - 1) + "))");
    Value v;
    v.shape = {dim_};
    for (int k = 0; k < dim_; ++k) v.c.push_back(k == static_cast<int>(i) ? g_->one() : g_->zero());
    return v;
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
    r.shape.push_back(static_cast<int>(items.size()));
    r.shape.insert(r.shape.end(), items[0].shape.begin(), items[0].shape.end());
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
        fail(il, "index " + index_text(d) + " is out of range 0.." + std::to_string(extent - 1) +
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
    // a + b - c + ... is a left spine of Binary nodes as long as the chain: walk it with a loop,
    // so that a sum of thousands of terms does not recurse once per term.
    std::vector<const Expr*> spine;
    for (const Expr* p = &e; p->kind == ExprKind::Binary; p = p->args[0].get()) spine.push_back(p);
    Value acc = expr(*spine.back()->args[0]);
    const Loc saved = g_->current_origin();
    for (auto it = spine.rbegin(); it != spine.rend(); ++it) {
      const Expr& op = **it;
      Value rhs = expr(*op.args[1]);
      if (def_depth_ == 0) g_->set_origin(op.loc);
      acc = combine(op, std::move(acc), std::move(rhs));
    }
    g_->set_origin(saved);
    return acc;
  }

  /// One binary operator applied to its lowered operands.
  Value combine(const Expr& e, Value a, Value b) {
    const std::string& op = e.name;
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
      if (a.measure)
        return merge_measures(a, b, [&](NodeId x, NodeId y) { return op == "+" ? g_->add(x, y) : g_->sub(x, y); });
      for (std::size_t i = 0; i < a.c.size(); ++i) a.c[i] = op == "+" ? g_->add(a.c[i], b.c[i]) : g_->sub(a.c[i], b.c[i]);
      return a;
    }
    if (op == "*") return multiply(a, b, e);
    if (op == "/") {
      if (!b.scalar() || b.measure)
        fail(e.loc, "division needs a scalar divisor; found " + shape_name(a) + " / " + shape_name(b));
      for (auto& c : a.c) c = g_->div(c, b.c[0]);
      if (a.measure) require_no_normal_on_cells(a, e.begin);
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

  /// a * b; `e` is the product, whose extent is the term a diagnostic about the integrand names.
  Value multiply(const Value& a, const Value& b, const Expr& e) {
    const Loc& loc = e.loc;
    if (a.measure && b.measure) fail(loc, "cannot multiply two measures");
    if (a.measure || b.measure) {
      const Value& factor = a.measure ? b : a;
      if (!factor.scalar()) fail(loc, "a measure can only multiply a scalar integrand; found " + shape_name(factor));
      Value r = scale(a.measure ? a : b, factor.c[0]);
      require_no_normal_on_cells(r, e.begin);
      return r;
    }
    if (a.scalar() || b.scalar()) return a.scalar() ? scale(b, a.c[0]) : scale(a, b.c[0]);
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
    if (const Symbol* sym = global(e.name, e.loc)) {
      if (sym->kind != SymKind::Def)
        fail(e.loc, "'" + e.name + "' is not a function (declared at " + form_.sources.where(sym->loc) + ")");
      return call_def(e, *sym);
    }
    if (e.name == "e") return unit_vector(e);
    if (e.name == "ds") return boundary_measure(e);
    if (e.name == "dx") fail(e.loc, "dx takes no argument: it is the measure of the cells (ds(part) is that of a boundary part)");
    if (e.name == "n") fail(e.loc, "'n' is the outward normal, a vector, not a function: write n[0] for a component");
    const int arity = builtin_arity(e.name);
    if (arity < 0) {
      std::vector<std::string> fns;
      for (const auto& [n, s] : globals_)
        if (s.kind == SymKind::Def && (scopes_.empty() || s.order < scopes_.back().def->order)) fns.push_back(n);
      for (const auto& [n, a] : builtin_functions()) fns.push_back(n);
      fns.push_back("e");
      std::string msg = "unknown function '" + e.name + "'";
      const std::string best = closest_name(e.name, fns);
      if (!best.empty()) msg += "; did you mean '" + best + "'?";
      fail(e.loc, msg);
    }
    if (static_cast<int>(e.args.size()) != arity)
      fail(e.loc, "function '" + e.name + "' takes " + std::to_string(arity) + " argument" + (arity == 1 ? "" : "s") +
                      ", got " + std::to_string(e.args.size()));
    const std::string& f = e.name;
    if (f == "cond") return conditional(*e.args[0], *e.args[1], *e.args[2], e.loc, "the first argument of cond()");
    std::vector<Value> a;
    for (const auto& x : e.args) a.push_back(expr(*x));
    const Loc& l0 = e.args[0]->loc;
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

  Value call_def(const Expr& e, const Symbol& sym) {
    const Stmt& def = *sym.def;
    if (e.args.size() != def.params.size())
      fail(e.loc, "function '" + def.name + "' (defined at " + form_.sources.where(def.name_loc) + ") takes " +
                      std::to_string(def.params.size()) + " argument" + (def.params.size() == 1 ? "" : "s") + ", got " +
                      std::to_string(e.args.size()));
    // A def can only call earlier defs, so calls nest at most as deep as there are defs; the bound
    // keeps the lowering recursion (a few frames per level) far from the stack limit.
    constexpr int kMaxDefNesting = 64;
    if (def_depth_ >= kMaxDefNesting)
      fail(e.loc, "def calls nested more than " + std::to_string(kMaxDefNesting) + " deep (calling '" + def.name + "')");
    DefScope scope;
    scope.def = &sym;
    for (std::size_t i = 0; i < e.args.size(); ++i) scope.params[def.params[i]] = expr(*e.args[i]);
    // The IR is hash-consed, so a def called again with the same argument nodes yields the same
    // nodes: reuse them. Without this a chain of defs each calling the previous one twice costs
    // 2^depth body lowerings (40 such lines would run for days).
    std::ostringstream key;
    key << static_cast<const void*>(&def);
    for (const auto& p : def.params) {
      const Value& v = scope.params.at(p);
      key << '|' << v.measure << v.condition << ':';
      for (const int d : v.domains) key << d << ';';
      for (const int d : v.shape) key << d << 'x';
      key << ':';
      for (const NodeId id : v.c) key << id << ',';
    }
    if (const auto hit = def_calls_.find(key.str()); hit != def_calls_.end()) return hit->second;
    scopes_.push_back(std::move(scope));
    ++def_depth_;
    Value r = expr(*def.body);
    --def_depth_;
    scopes_.pop_back();
    def_calls_.emplace(key.str(), r);
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
    std::size_t not_regular = candidates.size();  // the first candidate that exists but is no regular file
    for (std::size_t i = 0; i < candidates.size() && found.empty(); ++i) {
      std::error_code ec;
      const auto status = std::filesystem::status(candidates[i], ec);
      if (std::filesystem::is_regular_file(status)) found = candidates[i];
      else if (std::filesystem::exists(status) && not_regular == candidates.size()) not_regular = i;
    }
    if (found.empty() && not_regular < candidates.size()) {
      const auto& path = candidates[not_regular];
      // Beside the including file is where one looks first; found through -I, say where.
      const std::string where = not_regular == 0 ? "" : " (found as " + path.string() + ")";
      fail_at(form.sources, s.loc, "include file '" + s.path + "'" + where + " is " +
                                       (std::filesystem::is_directory(path) ? "a directory, not a regular file" : "not a regular file"));
    }
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
      case StmtKind::Form: {
        // lmeform_add_forms and the runtime name the generated files after the form file, so
        // another name here would break them; a form compiled from text without a file name has
        // no file name to match and takes this one.
        const std::filesystem::path& file = form.sources.file(0).path;
        if (file.stem().empty()) form.module = s->name;
        else if (s->name != form.module)
          fail_at(form.sources, s->name_loc,
                  "module name '" + s->name + "' must equal the file name '" + form.module + "'" +
                      (file.stem().string() == form.module ? "" : " (made a C++ identifier from '" + file.filename().string() + "')") +
                      "; write 'form " + form.module + "' or omit the form line");
        break;
      }
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
               : s->keyword == "linear"   ? OutputKind::Linear : OutputKind::Point;
        if (s->keyword == "require" || s->keyword == "recommend") o.requirement = s->message;
        o.requirement_advisory = s->keyword == "recommend";
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
  if (form.module.empty())
    fail_at(form.sources, Loc{0, 0}, "a form compiled without a file name needs a module name: add 'form NAME'");
  if (form.dims.empty()) form.dims.push_back(2);
  if (form.outputs.empty())
    fail_at(form.sources, Loc{0, 0}, "the form defines no output (energy, constraint, residual, bilinear, linear or point)");
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

/// The module name a form file implies: its stem made a C identifier the way CMake's
/// string(MAKE_C_IDENTIFIER) does it (lmeform_add_forms names the generated header so).
std::string module_name_of(const std::filesystem::path& path) {
  std::string name = path.stem().string();
  for (char& ch : name)
    if (!std::isalnum(static_cast<unsigned char>(ch)) && ch != '_') ch = '_';
  if (!name.empty() && std::isdigit(static_cast<unsigned char>(name[0]))) name.insert(name.begin(), '_');
  return name;
}

/// The form's text with its includes spliced in: the statements in order (owned by `storage`).
std::vector<const Stmt*> load_statements(CompiledForm& form, int main_file, const CompileOptions& options,
                                         std::vector<std::unique_ptr<std::vector<Stmt>>>& storage) {
  std::vector<std::filesystem::path> stack{std::filesystem::weakly_canonical(form.sources.file(main_file).path)};
  std::vector<const Stmt*> stmts;
  expand(form, main_file, options, stack, storage, stmts);
  return stmts;
}

CompiledForm compile_main(CompiledForm form, int main_file, const CompileOptions& options) {
  std::vector<std::unique_ptr<std::vector<Stmt>>> storage;
  const std::vector<const Stmt*> stmts = load_statements(form, main_file, options, storage);
  form.module = module_name_of(form.sources.file(main_file).path);
  collect_declarations(form, stmts);
  for (int d : form.dims) Lowering(form, d, stmts).run();
  return form;
}

CompiledForm form_with_source(const std::string& text, const std::filesystem::path& path) {
  CompiledForm form;
  form.sources.add(path, text);
  if (!path.empty()) form.dependencies.push_back(path);
  return form;
}

/// Reads the main form file; refuses what is not a regular file (a directory would read as an
/// empty form, a device such as /dev/zero would never end).
std::string read_form_file(const std::filesystem::path& path) {
  std::error_code ec;
  const auto status = std::filesystem::status(path, ec);
  if (std::filesystem::is_directory(status)) throw CompileError(path.string() + ": error: is a directory, not a form file\n");
  if (std::filesystem::exists(status) && !std::filesystem::is_regular_file(status))
    throw CompileError(path.string() + ": error: is not a regular file\n");
  bool ok = false;
  std::string text = read_file(path, ok);
  if (!ok) throw CompileError(path.string() + ": error: cannot open the form file\n");
  return text;
}

}  // namespace

CompiledForm compile_source(const std::string& text, const std::filesystem::path& path, const CompileOptions& options) {
  return compile_main(form_with_source(text, path), 0, options);
}

CompiledForm compile_file(const std::filesystem::path& path, const CompileOptions& options) {
  return compile_source(read_form_file(path), path, options);
}

std::vector<std::filesystem::path> form_dependencies(const std::filesystem::path& path, const CompileOptions& options) {
  CompiledForm form = form_with_source(read_form_file(path), path);
  std::vector<std::unique_ptr<std::vector<Stmt>>> storage;
  load_statements(form, 0, options, storage);
  std::vector<std::filesystem::path> files;
  for (const auto& d : form.dependencies) {
    const auto normal = std::filesystem::absolute(d).lexically_normal();
    if (std::find(files.begin(), files.end(), normal) == files.end()) files.push_back(normal);
  }
  return files;
}

}  // namespace lmeform::compiler
