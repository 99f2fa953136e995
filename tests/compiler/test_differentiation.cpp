// Every differentiation rule checked numerically at random inputs, through the real front end:
//  * spatial layer: grad/hess/div/lap of compound expressions (each operator) against central
//    differences in x of the expression, with polynomial fields whose jets are exact;
//  * variational layer: ∂f/∂J and ∂²f/∂J² of integrands against central differences in the jet.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <map>
#include <random>
#include <set>

#include "lmeform/compiler/codegen.hpp"
#include "lmeform/compiler/compile.hpp"

using namespace lmeform::compiler;
using ir::NodeId;

namespace {

/// A quadratic polynomial field per component: u(x) = a0 + a·x + ½ xᵀAx.
struct Quadratic {
  double a0 = 0;
  std::vector<double> a;
  std::vector<double> A;  // dim x dim symmetric
  int dim = 0;
  double jet(int slot, const std::vector<double>& x) const {
    if (slot == 0) {
      double v = a0;
      for (int i = 0; i < dim; ++i) {
        v += a[i] * x[i];
        for (int j = 0; j < dim; ++j) v += 0.5 * x[i] * A[i * dim + j] * x[j];
      }
      return v;
    }
    if (slot <= dim) {
      const int i = slot - 1;
      double g = a[i];
      for (int j = 0; j < dim; ++j) g += A[i * dim + j] * x[j];
      return g;
    }
    for (int i = 0; i < dim; ++i)
      for (int j = i; j < dim; ++j)
        if (ir::hessian_slot(i, j, dim) == slot) return A[i * dim + j];
    return NAN;
  }
};

struct Fields {
  // fields[f][c]
  std::vector<std::vector<Quadratic>> f;
};

Fields random_fields(const CompiledForm& form, int dim, std::mt19937& rng) {
  std::uniform_real_distribution<double> U(-0.5, 0.5);
  Fields F;
  for (const auto* fd : form.fields_of(ir::Role::Unknown)) {
    std::vector<Quadratic> comps;
    for (int c = 0; c < fd->components(dim); ++c) {
      Quadratic q;
      q.dim = dim;
      q.a0 = U(rng);
      for (int i = 0; i < dim; ++i) q.a.push_back(U(rng) + (fd->is_vector && i == c ? 1.0 : 0.0));  // y ≈ x
      q.A.assign(dim * dim, 0.0);
      for (int i = 0; i < dim; ++i)
        for (int j = i; j < dim; ++j) q.A[i * dim + j] = q.A[j * dim + i] = U(rng);
      comps.push_back(q);
    }
    F.f.push_back(comps);
  }
  return F;
}

double eval_at(const CompiledForm& form, int dim, NodeId root, const Fields& F, const std::vector<double>& x) {
  ir::Interpreter interp(*form.graphs.at(dim));
  const NodeId roots[] = {root};
  return interp.evaluate(roots, [&](const ir::Node& n) -> double {
    switch (n.op) {
      case ir::Op::Jet: return F.f.at(n.arg[1]).at(n.arg[2]).jet(n.arg[3], x);
      case ir::Op::Coord: return x.at(n.arg[0]);
      case ir::Op::Param: return 0.7 + 0.1 * n.arg[0];
      case ir::Op::Qdata: return 0.3 + 0.05 * n.arg[0];
      default: return NAN;
    }
  })[0];
}

/// Every test output is written `(expression + u) * dx` so that it depends on the unknown.
double eval_minus_u(const CompiledForm& form, int dim, NodeId root, const Fields& F, const std::vector<double>& x) {
  return eval_at(form, dim, root, F, x) - F.f.at(0).at(0).jet(0, x);
}

NodeId output(const CompiledForm& form, const std::string& name, int dim) {
  for (const auto& o : form.outputs)
    if (o.name == name) return o.integrand(dim);
  throw std::runtime_error("no output " + name);
}

/// Checks grad(E) and (optionally) hess(E), lap(E) against central differences of E in x.
void check_spatial(const std::string& expr, bool second) {
  for (int dim : {2, 3}) {
    SCOPED_TRACE(expr + " (dim " + std::to_string(dim) + ")");
    std::string src = "form t\ndimension " + std::to_string(dim) + "\nunknown u, y : vector\ncoordinate x\nqdata d\nconstant k\n"
                      "let E = " + expr + "\nenergy e = (E + u)*dx\n";
    for (int i = 0; i < dim; ++i) {
      src += "energy g" + std::to_string(i) + " = (grad(E)[" + std::to_string(i) + "] + u)*dx\n";
      if (second)
        for (int j = 0; j < dim; ++j)
          src += "energy h" + std::to_string(i) + std::to_string(j) + " = (hess(E)[" + std::to_string(i) + "," + std::to_string(j) + "] + u)*dx\n";
    }
    if (second) src += "energy L = (lap(E) - div(grad(E)) + u)*dx\n";
    CompiledForm form;
    try {
      form = compile_source(src, "t.form");
    } catch (const CompileError& e) {
      FAIL() << e.what();
    }
    std::mt19937 rng(42 + dim);
    for (int trial = 0; trial < 3; ++trial) {
      const Fields F = random_fields(form, dim, rng);
      std::uniform_real_distribution<double> U(0.3, 0.9);
      std::vector<double> x(dim);
      for (auto& v : x) v = U(rng);
      const double h = 1e-5;
      for (int i = 0; i < dim; ++i) {
        auto xp = x, xm = x;
        xp[i] += h;
        xm[i] -= h;
        const double fd = (eval_minus_u(form, dim, output(form, "e", dim), F, xp) - eval_minus_u(form, dim, output(form, "e", dim), F, xm)) / (2 * h);
        const double g = eval_minus_u(form, dim, output(form, "g" + std::to_string(i), dim), F, x);
        EXPECT_NEAR(g, fd, 1e-6 * (1 + std::abs(fd))) << "d/dx" << i;
        if (!second) continue;
        for (int j = 0; j < dim; ++j) {
          const std::string gj = "g" + std::to_string(j);
          const double fd2 = (eval_minus_u(form, dim, output(form, gj, dim), F, xp) - eval_minus_u(form, dim, output(form, gj, dim), F, xm)) / (2 * h);
          const double hij = eval_minus_u(form, dim, output(form, "h" + std::to_string(j) + std::to_string(i), dim), F, x);
          EXPECT_NEAR(hij, fd2, 1e-6 * (1 + std::abs(fd2))) << "d2/dx" << j << "dx" << i;
        }
      }
      if (second) {
        EXPECT_NEAR(eval_minus_u(form, dim, output(form, "L", dim), F, x), 0.0, 1e-10);
      }
    }
  }
}

}  // namespace

// One line per rule of the spatial layer.
TEST(SpatialChainRule, Arithmetic) { check_spatial("u^3 - 2*u*x[0] + u/(1 + x[1]^2) - (-u)", true); }
TEST(SpatialChainRule, PowerWithVariableExponent) { check_spatial("pow(1.5 + u^2, 0.5 + x[0])", true); }
TEST(SpatialChainRule, ElementaryFunctions) {
  check_spatial("exp(u) + sqrt(2 + u) + log(2 + u^2) + sin(u) + cos(u*x[1]) + tanh(u)", true);
}
TEST(SpatialChainRule, AbsSignAndConditionals) {
  check_spatial("abs(u - 0.05) + (if u > 0.1 and x[0] < 2 then u^2 else -u) + cond(not (u <= 0), u, 2*u) + min(u, x[1]) + max(u^2, 0.3)", true);
}
TEST(SpatialChainRule, GradientsOfFields) { check_spatial("dot(grad(u), grad(u)) + dot(grad(u), y) + grad(u)[1]*y[0]", false); }
TEST(SpatialChainRule, HessiansOfFieldsViaGradOfGradients) { check_spatial("grad(u)[0]*y[1] + div(y)*u + tr(grad(y))", false); }
TEST(SpatialChainRule, CoordinateAndConstants) { check_spatial("k*dot(x, x) + tr(grad(x))*u + norm(x)", true); }
TEST(SpatialChainRule, DeterminantAndInverse) {
  check_spatial("det(grad(y)) + inv(grad(y))[0,1] + tr(inv(grad(y))*transpose(grad(y)))", false);
}
TEST(SpatialChainRule, MatrixAlgebra) {
  check_spatial("inner(sym(grad(y)), dev(grad(y))) + inner(skew(grad(y)), grad(y)*grad(y)) + det(outer(y, grad(u)) + I)", false);
}
TEST(SpatialChainRule, VectorOperators) {
  check_spatial("norm(y)*div(y) + dot(y, grad(y)*y) + dot(y, transpose(grad(y))*y)", false);
}
TEST(SpatialChainRule, LiteralsAndIndexing) {
  check_spatial("dot([u, y[0]], [x[1], 2]) + inner([[u, 1], [y[1], u^2]], [[1, 2], [3, 4]]) + [[u, 2], [3, y[0]]][1][1]", true);
}

// Second-derivative operators on fields agree with each other and with the polynomial jets.
TEST(SpatialChainRule, LaplacianDivergenceAndHessianIdentities) {
  const auto form = compile_source(
      "form t\ndimension 3\nunknown u, y : vector\n"
      "energy a = (lap(u) - tr(hess(u)) + u)*dx\n"
      "energy b = (dot(lap(y) - div(grad(y)), [1, 2, 3]) + u)*dx\n"
      "energy c = (dot(y, hess(y))[0, 1] + u)*dx\n"
      "energy h = (hess(u)[1, 2] + u)*dx\n",
      "t.form");
  std::mt19937 rng(3);
  const Fields F = random_fields(form, 3, rng);
  const std::vector<double> x{0.2, 0.5, 0.7};
  EXPECT_NEAR(eval_minus_u(form, 3, output(form, "a", 3), F, x), 0.0, 1e-13);
  EXPECT_NEAR(eval_minus_u(form, 3, output(form, "b", 3), F, x), 0.0, 1e-13);
  // dot(y, hess(y))[j, k] = Σ_i y_i ∂²y_i/∂x_j∂x_k (contraction of the component index).
  double expect_c = 0;
  for (int i = 0; i < 3; ++i) expect_c += F.f[1][i].jet(0, x) * F.f[1][i].A[0 * 3 + 1];
  EXPECT_NEAR(eval_minus_u(form, 3, output(form, "c", 3), F, x), expect_c, 1e-13);
  EXPECT_NEAR(eval_minus_u(form, 3, output(form, "h", 3), F, x), F.f[0][0].A[1 * 3 + 2], 1e-13);
}

TEST(SpatialChainRule, GradOfCoordinateIsIdentity) {
  const auto form = compile_source("form t\nunknown u\ncoordinate x\nenergy e = (u + grad(x)[0,0] + 10*grad(x)[0,1])*dx\n", "t.form");
  Fields F = random_fields(form, 2, *std::make_unique<std::mt19937>(1));
  const NodeId e = form.outputs[0].integrand(2);
  EXPECT_NEAR(eval_at(form, 2, e, F, {0.3, 0.4}) - F.f[0][0].jet(0, {0.3, 0.4}), 1.0, 1e-14);
}

namespace {

/// Variational layer: the plan's ∂f/∂J and ∂²f/∂J² against central differences in the jet values.
void check_variational(const std::string& src, int dim) {
  SCOPED_TRACE(src);
  CompiledForm form;
  try {
    form = compile_source(src, "t.form");
  } catch (const CompileError& e) {
    FAIL() << e.what();
  }
  for (const auto& out : form.outputs) {
    SCOPED_TRACE(out.name);
    const KernelPlan plan = plan_kernel(form, out, dim);
    const ir::Graph& g = *form.graphs.at(dim);
    // Random independent jet values; vector-field gradients near the identity (det F ≈ 1).
    std::mt19937 rng(7);
    std::uniform_real_distribution<double> U(-0.3, 0.3);
    std::map<std::vector<int>, double> jets;
    auto jet_value = [&](const ir::Node& n) {
      const std::vector<int> key{n.arg[0], n.arg[1], n.arg[2], n.arg[3]};
      auto it = jets.find(key);
      if (it != jets.end()) return it->second;
      const double v = U(rng) + (n.arg[3] == 1 + n.arg[2] ? 1.0 : 0.5);
      jets[key] = v;
      return v;
    };
    ir::Interpreter interp(g);
    auto eval = [&](NodeId root) {
      const NodeId roots[] = {root};
      return interp.evaluate(roots, [&](const ir::Node& n) -> double {
        switch (n.op) {
          case ir::Op::Jet: return jet_value(n);
          case ir::Op::Coord: return 0.6 + 0.1 * n.arg[0];
          case ir::Op::Param: return 0.8;
          case ir::Op::Qdata: return 0.2 + 0.1 * n.arg[0];
          default: return NAN;
        }
      })[0];
    };
    const NodeId f = out.integrand(dim);
    eval(f);  // fixes the jet values
    // Map a (row dof component, slot) to the jet key of its field.
    auto key_of = [&](ir::Role role, int comp, int slot) {
      int field = 0, off = 0;
      for (const auto* fd : form.fields_of(role)) {
        if (comp < off + fd->components(dim)) break;
        off += fd->components(dim);
        ++field;
      }
      return std::vector<int>{static_cast<int>(role), field, comp - off, slot};
    };
    const double h = 1e-5;
    auto fd_of = [&](NodeId root, const std::vector<int>& key) {
      const double saved = jets.count(key) ? jets[key] : 0.0;
      jets[key] = saved + h;
      const double p = eval(root);
      jets[key] = saved - h;
      const double m = eval(root);
      jets[key] = saved;
      return (p - m) / (2 * h);
    };
    // Gradient: every (row, slot), zeros included.
    std::map<std::pair<int, int>, NodeId> vec;
    for (const auto& e : plan.vector) vec[{e.row, e.slot_index}] = e.node;
    for (int r = 0; r < plan.row_dofs; ++r)
      for (std::size_t s = 0; s < plan.slots.size(); ++s) {
        const auto key = key_of(plan.row_role, r, plan.slots[s]);
        if (plan.row_role != ir::Role::Unknown) jets[key] = 0.37;  // test functions: any value (linear)
        const double fd = fd_of(f, key);
        auto it = vec.find({r, static_cast<int>(s)});
        const double sym = it == vec.end() ? 0.0 : eval(it->second);
        EXPECT_NEAR(sym, fd, 1e-6 * (1 + std::abs(fd))) << "df/dJ row " << r << " slot " << plan.slots[s];
      }
    if (!plan.has_matrix()) continue;
    std::map<std::vector<int>, NodeId> mat;
    for (const auto& e : plan.matrix) mat[{e.row, e.row_slot, e.col, e.col_slot}] = e.node;
    for (const auto& e : plan.vector) {
      for (int c = 0; c < plan.col_dofs; ++c)
        for (std::size_t t = 0; t < plan.slots.size(); ++t) {
          const double fd = fd_of(e.node, key_of(plan.col_role, c, plan.slots[t]));
          auto it = mat.find({e.row, e.slot_index, c, static_cast<int>(t)});
          const double sym = it == mat.end() ? 0.0 : eval(it->second);
          EXPECT_NEAR(sym, fd, 1e-6 * (1 + std::abs(fd))) << "d2f/dJ2 row " << e.row << " col " << c;
        }
    }
  }
}

}  // namespace

TEST(VariationalDerivatives, ScalarEnergyWithLaplacian) {
  for (int dim : {2, 3})
    check_variational("form t\ndimension 2, 3\nunknown u\ncoefficient c\nconstant eps\n"
                      "energy e = (eps*lap(u) + u - u^3)^2*dx + exp(u*c)*dot(grad(u), grad(u))*dx + sqrt(1 + hess(u)[0,1]^2)*dx\n",
                      dim);
}

TEST(VariationalDerivatives, VectorUnknownWithInverseDeterminantAndHessian) {
  for (int dim : {2, 3})
    check_variational("form t\ndimension 2, 3\nunknown y : vector\nqdata p, gp : vector, hp : matrix\n"
                      "let F = grad(y)\nlet Fi = inv(F)\nlet gphi = transpose(Fi)*gp\n"
                      "let lap_phi = inner(hp, Fi*transpose(Fi)) + tr(dot(gp, grad(Fi))*Fi)\n"
                      "energy e = (lap_phi + p)^2*det(F)*dx + log(det(F))^2*dx + dot(gphi, dot(gphi, hess(y))*gphi)*dx\n",
                      dim);
}

TEST(VariationalDerivatives, MixedFieldsResidualAndBilinear) {
  check_variational("form t\ndimension 2\nunknown u : vector, p\ntest v : vector, q\n"
                    "residual R = (inner(grad(u), grad(v)) - p*div(v) + q*div(u) + dot(grad(u)*u, v) + p^2*q*abs(u[0]) "
                    "+ 0.1*dot(lap(u) + grad(p), grad(q)))*dx\n",
                    2);
  check_variational("form t\ndimension 3\ntest v\ntrial w\ncoordinate x\n"
                    "bilinear a = (dot(grad(w), grad(v)) + x[0]*w*v + lap(w)*lap(v))*dx\nlinear l = sin(x[1])*v*dx\n",
                    3);
}

TEST(VariationalDerivatives, ConditionalAndFunctions) {
  check_variational("form t\ndimension 2\nunknown u\nconstant d\n"
                    "energy e = (if u < d then (u - d)^2 + tanh(u) else cos(u)*sin(u))*dx + pow(2 + u^2, 1.3)*abs(grad(u)[1])*dx\n",
                    2);
}

TEST(VariationalDerivatives, StructuralZerosAreSkipped) {
  const auto form = compile_source("form t\nunknown u\nenergy e = (dot(grad(u), grad(u)) + u)*dx\n", "t.form");
  const auto plan = plan_kernel(form, form.outputs[0], 2);
  EXPECT_EQ(plan.slots, (std::vector<int>{0, 1, 2}));
  EXPECT_EQ(plan.basis_order, 1);
  EXPECT_EQ(plan.matrix.size(), 2u);  // only d2f/dgrad_i^2: the value slot has no second derivative
  EXPECT_EQ(plan.vector.size(), 3u);
}

namespace {

/// Reverse mode (ir::gradient) against forward mode (one Differentiator per jet), numerically at
/// random jet values: first derivatives of every output's integrand, and second derivatives as
/// the gradient of each first derivative.
void check_reverse_mode(const std::string& src, int dim) {
  SCOPED_TRACE(src);
  CompiledForm form = compile_source(src, "t.form");
  ir::Graph& g = *form.graphs.at(dim);
  std::mt19937 rng(11);
  std::uniform_real_distribution<double> U(0.2, 0.9);
  std::map<std::vector<int>, double> values;
  ir::Interpreter interp(g);
  auto eval = [&](NodeId root) {
    const NodeId roots[] = {root};
    return interp.evaluate(roots, [&](const ir::Node& n) {
      auto [it, fresh] = values.try_emplace({static_cast<int>(n.op), n.arg[0], n.arg[1], n.arg[2], n.arg[3]}, 0.0);
      // Positive values, and vector-field gradients near the identity (det F > 0).
      const bool diagonal_gradient = n.op == ir::Op::Jet && n.arg[3] == 1 + n.arg[2];
      if (fresh) it->second = diagonal_gradient ? 1.0 + 0.2 * U(rng) : 0.2 * U(rng);
      return it->second;
    })[0];
  };
  for (const auto& out : form.outputs) {
    SCOPED_TRACE(out.name);
    const NodeId f = out.integrand(dim);
    std::vector<NodeId> jets;
    const NodeId roots[] = {f};
    for (NodeId id : g.reachable(roots))
      if (g.node(id).op == ir::Op::Jet) jets.push_back(id);
    auto forward = [&](NodeId root, NodeId var) {
      return ir::Differentiator(g, [var](ir::Graph& gr, NodeId t) { return t == var ? gr.one() : gr.zero(); }).derivative(root);
    };
    std::vector<NodeId> first(jets.size(), g.zero());
    for (const auto& [k, d] : ir::gradient(g, f, jets)) first[k] = d;
    for (std::size_t k = 0; k < jets.size(); ++k) {
      EXPECT_NEAR(eval(first[k]), eval(forward(f, jets[k])), 1e-12) << "df/dJ " << k;
      std::vector<NodeId> second(jets.size(), g.zero());
      for (const auto& [l, d] : ir::gradient(g, first[k], jets)) second[l] = d;
      for (std::size_t l = 0; l < jets.size(); ++l)
        EXPECT_NEAR(eval(second[l]), eval(forward(forward(f, jets[k]), jets[l])), 1e-10) << "d2f/dJ " << k << "," << l;
    }
  }
}

}  // namespace

TEST(ReverseModeGradient, AgreesWithForwardMode) {
  check_reverse_mode("unknown u\ncoefficient c\nconstant eps\n"
                     "energy e = (eps*lap(u) + u - u^3)^2*dx + exp(u*c)*dot(grad(u), grad(u))*dx + sqrt(1 + hess(u)[0,1]^2)*dx\n",
                     2);
  check_reverse_mode("dimension 3\nunknown y : vector\nqdata p, gp : vector\n"
                     "let F = grad(y)\nlet gphi = transpose(inv(F))*gp\n"
                     "energy e = (dot(gphi, gphi) + p)*det(F)*dx + log(det(F))^2*dx + tanh(y[0])/cos(y[1])*dx\n",
                     3);
  check_reverse_mode("unknown u\nconstant d\n"
                     "energy e = (if u < d then (u - d)^2 + tanh(u) else cos(u)*sin(u))*dx + pow(2 + u^2, 1.3 + u)*abs(grad(u)[1])*dx\n",
                     2);
}

TEST(ReverseModeGradient, SkipsTerminalsTheFunctionDoesNotDependOn) {
  CompiledForm form = compile_source("unknown u, w\nenergy e = u^2*dx\n", "t.form");
  ir::Graph& g = *form.graphs.at(2);
  const NodeId u = g.jet({ir::Role::Unknown, 0, 0, 0}), w = g.jet({ir::Role::Unknown, 1, 0, 0});
  const NodeId wrt[] = {w, u};
  const auto grad = ir::gradient(g, form.outputs[0].integrand(2), wrt);
  ASSERT_EQ(grad.size(), 1u);
  EXPECT_EQ(grad[0].first, 1u);
}

// The two Hessian strategies of plan_kernel (edge pushing; a reverse sweep over each first
// derivative) agree to 1e-12 on every energy and constraint of the model library, in every
// dimension, at random jet values (vector-field gradients near the identity).
TEST(HessianStrategies, EdgePushingAgreesWithRowSweepsOnEveryForm) {
  namespace fs = std::filesystem;
  int checked = 0;
  for (const auto& entry : fs::directory_iterator(LMEFORM_FORMS_DIR)) {
    if (entry.path().extension() != ".form") continue;
    SCOPED_TRACE(entry.path().filename().string());
    CompileOptions options;
    options.include_dirs.push_back(LMEFORM_FORMS_DIR);
    const CompiledForm form = compile_file(entry.path(), options);
    for (const auto& out : form.outputs) {
      if (out.kind != OutputKind::Energy && out.kind != OutputKind::Constraint) continue;
      for (const auto& [dim, by_domain] : out.integrands) {
        for (const auto& [domain, f] : by_domain) {
          SCOPED_TRACE(out.name + " " + std::to_string(dim) + "D, domain " + std::to_string(domain));
          ir::Graph& g = *form.graphs.at(dim);
          const NodeId root[] = {f};
          std::vector<NodeId> vars;
          for (const NodeId id : g.reachable(root))
            if (g.node(id).op == ir::Op::Jet && g.jet_var(id).role == ir::Role::Unknown) vars.push_back(id);
          std::map<std::pair<std::size_t, std::size_t>, NodeId> pushed, rows;
          for (const auto& e : ir::hessian(g, f, vars)) pushed[{e.row, e.col}] = e.node;
          std::vector<NodeId> first(vars.size(), g.zero());
          for (const auto& [k, d] : ir::gradient(g, f, vars)) first[k] = d;
          for (std::size_t k = 0; k < vars.size(); ++k)
            for (const auto& [l, h] : ir::gradient(g, first[k], vars))
              if (l >= k) rows[{k, l}] = h;
          std::mt19937 rng(11);
          std::uniform_real_distribution<double> U(-0.2, 0.2);
          std::map<std::vector<int>, double> jets;
          const ir::Interpreter interp(g);
          auto value = [&](NodeId id) {
            const NodeId r[] = {id};
            return interp.evaluate(r, [&](const ir::Node& n) -> double {
              switch (n.op) {
                case ir::Op::Jet: {
                  const std::vector<int> key{n.arg[0], n.arg[1], n.arg[2], n.arg[3]};
                  if (const auto it = jets.find(key); it != jets.end()) return it->second;
                  return jets[key] = U(rng) + (n.arg[3] == 1 + n.arg[2] ? 1.0 : 0.3);
                }
                case ir::Op::Coord: return 0.6 + 0.1 * n.arg[0];
                case ir::Op::Param: return 0.7 + 0.05 * n.arg[0];
                case ir::Op::Qdata: return 0.3 + 0.07 * n.arg[0];
                case ir::Op::Normal: return n.arg[0] == 0 ? 0.6 : 0.8;
                default: return NAN;
              }
            })[0];
          };
          std::set<std::pair<std::size_t, std::size_t>> keys;
          for (const auto& [k, v] : pushed) keys.insert(k);
          for (const auto& [k, v] : rows) keys.insert(k);
          std::map<std::pair<std::size_t, std::size_t>, std::pair<double, double>> values;
          double scale = 0;
          for (const auto& key : keys) {
            const double a = pushed.contains(key) ? value(pushed[key]) : 0.0;
            const double b = rows.contains(key) ? value(rows[key]) : 0.0;
            values[key] = {a, b};
            scale = std::max({scale, std::abs(a), std::abs(b)});
          }
          for (const auto& [key, ab] : values)
            EXPECT_LE(std::abs(ab.first - ab.second), 1e-12 * std::max(1.0, scale))
                << "entry (" << key.first << ", " << key.second << "): edge pushing " << ab.first << ", rows " << ab.second;
          ++checked;
        }
      }
    }
  }
  EXPECT_GE(checked, 20);  // every energy and constraint of forms/ in each of its dimensions
}

