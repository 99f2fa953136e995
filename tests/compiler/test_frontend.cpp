// Parser and checker: valid forms compile; each broken form under data/errors gives exactly the
// diagnostic in golden/<name>.txt (file:line:col, message, source line, caret).
#include <gtest/gtest.h>

#include <unistd.h>

#include <chrono>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <functional>
#include <map>
#include <numbers>
#include <sstream>

#include "lmeform/compiler/codegen.hpp"
#include "lmeform/compiler/compile.hpp"
#include "lmeform/compiler/ir.hpp"

namespace fs = std::filesystem;
using namespace lmeform::compiler;

namespace {

std::string slurp(const fs::path& p) {
  std::ifstream in(p);
  std::ostringstream s;
  s << in.rdbuf();
  return s.str();
}

std::string replace_all(std::string s, const std::string& from, const std::string& to) {
  for (std::size_t at = s.find(from); at != std::string::npos; at = s.find(from, at + to.size())) s.replace(at, from.size(), to);
  return s;
}

/// The message of the CompileError that compiling `text` (as `path`) throws; empty if none.
std::string compile_error(const std::string& text, const fs::path& path = "t.form") {
  try {
    compile_source(text, path);
  } catch (const CompileError& e) {
    return e.what();
  }
  return {};
}

/// The message of the CompileError that compiling and generating `text` throws; empty if none.
std::string compile_error_generating(const std::string& text, const fs::path& path = "t.form") {
  try {
    generate(compile_source(text, path), path.string());
  } catch (const CompileError& e) {
    return e.what();
  }
  return {};
}

/// A fresh directory for one test's files.
fs::path scratch_dir(const std::string& name) {
  const fs::path dir = fs::temp_directory_path() / ("lmeform_frontend_" + name + "_" + std::to_string(::getpid()));
  fs::remove_all(dir);
  fs::create_directories(dir);
  return dir;
}

void write_text(const fs::path& p, const std::string& text) {
  std::ofstream out(p, std::ios::binary);
  out << text;
}

/// The integrand of output 0 at dimension dim, evaluated with every jet slot-0 component c of
/// field f equal to jet(f, c) and the coordinate x.
double evaluate_integrand(const CompiledForm& form, int dim, const std::vector<double>& x,
                          const std::function<double(int field, int component)>& jet) {
  const ir::Graph& g = *form.graphs.at(dim);
  const ir::NodeId roots[] = {form.outputs.at(0).integrand(dim)};
  return ir::Interpreter(g).evaluate(roots, [&](const ir::Node& n) {
    if (n.op == ir::Op::Coord) return x.at(static_cast<std::size_t>(n.arg[0]));
    if (n.op == ir::Op::Jet && n.arg[3] == 0) return jet(n.arg[1], n.arg[2]);
    ADD_FAILURE() << "unexpected terminal";
    return 0.0;
  })[0];
}

}  // namespace

TEST(CompilerFrontend, ValidFormsCompileAndGenerate) {
  const fs::path data = LMEFORM_TEST_DATA;
  CompileOptions opt;
  opt.include_dirs.push_back(data / "include");
  int count = 0;
  for (const auto& e : fs::directory_iterator(data)) {
    if (e.path().extension() != ".form") continue;
    SCOPED_TRACE(e.path().string());
    CompiledForm form;
    ASSERT_NO_THROW(form = compile_file(e.path(), opt));
    EXPECT_EQ(form.module, e.path().stem().string());
    const auto gen = generate(form, e.path().filename().string());
    EXPECT_NE(gen.header.find("_all_kernels[]"), std::string::npos);
    EXPECT_NE(gen.json.find("\"module\": \"" + form.module + "\""), std::string::npos);
    ++count;
  }
  EXPECT_GE(count, 5);
}

TEST(CompilerFrontend, BrokenFormsGiveTheGoldenDiagnostics) {
  const fs::path errors = fs::path(LMEFORM_TEST_DATA) / "errors";
  const fs::path golden = LMEFORM_TEST_GOLDEN;
  int count = 0;
  for (const auto& e : fs::directory_iterator(errors)) {
    if (e.path().extension() != ".form") continue;
    SCOPED_TRACE(e.path().filename().string());
    const fs::path expected_file = golden / (e.path().stem().string() + ".txt");
    ASSERT_TRUE(fs::exists(expected_file)) << "missing golden file " << expected_file;
    std::string message;
    try {
      // Some errors (linearity in test functions) are found while differentiating.
      generate(compile_file(e.path()), e.path().filename().string());
    } catch (const CompileError& err) {
      message = err.what();
    }
    // Goldens are produced with lmeformc run inside data/errors: paths relative to it.
    message = replace_all(message, errors.string() + "/", "");
    message = replace_all(message, errors.string(), ".");
    EXPECT_EQ(message, slurp(expected_file));
    ++count;
  }
  EXPECT_GE(count, 32);
}

TEST(CompilerFrontend, ErrorFormatHasLocationLineAndCaret) {
  try {
    compile_source("form t\nunknown phi\nenergy e = phi*dx + grad(phi)*dx\n", "t.form");
    FAIL() << "expected an error";
  } catch (const CompileError& e) {
    EXPECT_STREQ(e.what(),
                 "t.form:3:30: error: a measure can only multiply a scalar integrand; found vector[2]\n"
                 "energy e = phi*dx + grad(phi)*dx\n"
                 "                             ^\n") << e.what();
  }
}

TEST(CompilerFrontend, DeclarationsAndMetadata) {
  const auto form = compile_source(
      "form m\ndimension 2, 3\nunknown y : vector, p\ncoefficient c\nqdata a, b : vector, h : matrix\n"
      "constant k = 2*pi, eps\nenergy e = (k*p^2 + dot(y, b)*a + tr(h)*c)*dx\n",
      "m.form");
  EXPECT_EQ(form.dims, (std::vector<int>{2, 3}));
  ASSERT_EQ(form.constants.size(), 2u);
  EXPECT_NEAR(*form.constants[0].default_value, 2 * std::numbers::pi, 1e-15);
  EXPECT_FALSE(form.constants[1].default_value.has_value());
  EXPECT_EQ(form.qdata_per_point(3), 1 + 3 + 9);
  EXPECT_EQ(form.qdata_offset(2, 2), 3);
  const auto plan = plan_kernel(form, form.outputs[0], 3);
  EXPECT_EQ(plan.row_dofs, 4);   // y (3) + p
  EXPECT_EQ(plan.basis_order, 0);
  EXPECT_EQ(plan.slots, (std::vector<int>{0}));
}

// ---- module name ------------------------------------------------------------------------------

TEST(CompilerFrontend, ModuleNameMustEqualTheFileName) {
  EXPECT_EQ(compile_error("form other_name\nunknown u\nenergy e = u^2*dx\n", "dir/badname.form"),
            "dir/badname.form:1:6: error: module name 'other_name' must equal the file name 'badname'; "
            "write 'form badname' or omit the form line\n"
            "form other_name\n"
            "     ^\n");
  EXPECT_EQ(compile_source("form badname\nunknown u\nenergy e = u^2*dx\n", "dir/badname.form").module, "badname");
  EXPECT_EQ(compile_source("unknown u\nenergy e = u^2*dx\n", "dir/badname.form").module, "badname");
  // The file name made a C++ identifier, as CMake's MAKE_C_IDENTIFIER (lmeform_add_forms) does.
  EXPECT_EQ(compile_source("form my_form\nunknown u\nenergy e = u^2*dx\n", "my-form.form").module, "my_form");
  EXPECT_EQ(compile_source("unknown u\nenergy e = u^2*dx\n", "2d.form").module, "_2d");
  EXPECT_NE(compile_error("form my-form\nunknown u\nenergy e = u^2*dx\n", "my-form.form"), "");
  EXPECT_NE(compile_error("form other\nunknown u\nenergy e = u^2*dx\n", "my-form.form")
                .find("must equal the file name 'my_form' (made a C++ identifier from 'my-form.form')"),
            std::string::npos);
}

TEST(CompilerFrontend, TextWithoutAFileNameTakesTheFormLine) {
  EXPECT_EQ(compile_source("form anything\nunknown u\nenergy e = u^2*dx\n", "").module, "anything");
  EXPECT_NE(compile_error("unknown u\nenergy e = u^2*dx\n", "").find("needs a module name: add 'form NAME'"), std::string::npos);
}

// ---- linearity in test and trial functions --------------------------------------------------

TEST(CompilerFrontend, NonLinearTermIsPointedAt) {
  EXPECT_EQ(compile_error("unknown u\ntest v\nresidual R = (u*v + v*v) * dx\n"),
            "t.form:3:21: error: residual 'R' is not linear in the test function 'v'\n"
            "residual R = (u*v + v*v) * dx\n"
            "                    ^\n");
  EXPECT_EQ(compile_error("unknown u\ntest v\nresidual R = (u*v + u*sin(v)) * dx\n"),
            "t.form:3:23: error: residual 'R' is not linear in the test function 'v'\n"
            "residual R = (u*v + u*sin(v)) * dx\n"
            "                      ^\n");
  // A comparison of the test function is not linear either (the derivative check missed it).
  EXPECT_NE(compile_error("unknown u\ntest v\nresidual R = (u*v + (if v > 0 then u else 0)) * dx\n")
                .find("t.form:3:25: error: residual 'R' is not linear in the test function 'v'"),
            std::string::npos);
  // Inside a def the term is the call.
  EXPECT_EQ(compile_error("unknown u\ntest v\ndef sq(a) = a*a\nresidual R = (u*v + sq(v)) * dx\n"),
            "t.form:4:21: error: residual 'R' is not linear in the test function 'v'\n"
            "residual R = (u*v + sq(v)) * dx\n"
            "                    ^\n");
  EXPECT_EQ(compile_error("test v\ntrial w\nbilinear a = w*(v + 1)*v*dx\n"),
            "t.form:3:14: error: bilinear 'a' is not linear in the test function 'v'\n"
            "bilinear a = w*(v + 1)*v*dx\n"
            "             ^\n");
  // Linear forms of the same kinds still compile: affine in v, v in a denominator's numerator,
  // a test function under a condition that does not involve it.
  EXPECT_EQ(compile_error("unknown u\ntest v\ncoordinate x\n"
                          "residual R = (u^2*v/(1 + u^2) + (if x[0] > 0 then v else -v) + dot(grad(u), grad(v))) * dx\n"),
            "");
}

// ---- def scope ------------------------------------------------------------------------------

TEST(CompilerFrontend, DefBodySeesOnlyEarlierNames) {
  EXPECT_EQ(compile_error("unknown u\nconstant k = 2\ndef f(a) = k*a\nenergy e = f(u)^2*dx\n"), "");
  EXPECT_EQ(compile_error("unknown u\ndef f(a) = k*a\nconstant k = 2\nenergy e = f(u)^2*dx\n"),
            "t.form:2:12: error: 'k' is declared at t.form:3:10, after def 'f' (t.form:2:5): a def body may use only "
            "its parameters and names declared before the def\n"
            "def f(a) = k*a\n"
            "           ^\n");
  // Later defs and lets as well; parameters hide globals.
  EXPECT_NE(compile_error("unknown u\ndef f(a) = g(a)\ndef g(a) = a\nenergy e = f(u)^2*dx\n")
                .find("t.form:2:12: error: 'g' is declared at t.form:3:5, after def 'f'"),
            std::string::npos);
  EXPECT_EQ(compile_error("unknown u\ndef f(u) = 2*u\nenergy e = f(u)^2*dx\n"), "");
  EXPECT_NE(compile_error("unknown u\ndef f(a) = f(a)\nenergy e = f(u)*dx\n")
                .find("t.form:2:12: error: def 'f' cannot call itself: a def body may use only its parameters"),
            std::string::npos);
}

// ---- unit vectors and the dimension -----------------------------------------------------------

TEST(CompilerFrontend, UnitVectorsWorkInEveryDimension) {
  const auto form = compile_source(
      "dimension 2, 3\nunknown y : vector\ncoordinate x\n"
      "let b = sin(x[0])*e(0) + cos(x[1])*e(1) + (if dim == 3 then x[2]*e(dim - 1) else [0, 0])\n"
      "energy E = (dot(y, b) + dim) * dx\n",
      "t.form");
  for (int dim : {2, 3}) {
    SCOPED_TRACE(dim);
    const std::vector<double> x = {0.3, 0.7, 1.1};
    const std::vector<double> y = {2.0, -1.5, 0.25};
    const double expected = y[0] * std::sin(x[0]) + y[1] * std::cos(x[1]) + (dim == 3 ? y[2] * x[2] : 0.0) + dim;
    EXPECT_NEAR(evaluate_integrand(form, dim, x, [&](int, int c) { return y.at(static_cast<std::size_t>(c)); }), expected, 1e-14);
  }
  EXPECT_NO_THROW(generate(form, "t.form"));
}

TEST(CompilerFrontend, UnitVectorErrorsAndPredefinedNames) {
  EXPECT_NE(compile_error("dimension 3\nunknown y : vector\nenergy E = dot(y, e(3))*dx\n")
                .find("t.form:3:21: error: unit vector e(3) does not exist in dimension 3 (e(0) to e(2))"),
            std::string::npos);
  EXPECT_NE(compile_error("unknown y : vector\nenergy E = dot(y, e(0.5))*dx\n")
                .find("error: the argument of e() must be an integer constant expression"),
            std::string::npos);
  EXPECT_NE(compile_error("unknown y : vector\nenergy E = dot(y, e(0, 1))*dx\n").find("error: function 'e' takes 1 argument, got 2"),
            std::string::npos);
  // `e` and `dim` are not reserved: a declaration hides them (forms use `e` for strains).
  EXPECT_EQ(compile_error("unknown y : vector\nlet e = sym(grad(y))\nconstant dim = 4\nenergy E = (inner(e, e) + dim)*dx\n"), "");
  // ... but a def body, which only sees earlier names, keeps the builtin meaning of a later one.
  EXPECT_EQ(compile_error("unknown y : vector\ndef first(v) = dot(v, e(0))\nlet e = 2\nenergy E = e*first(y)^2*dx\n"), "");
}

// ---- boundary measures, the normal, point outputs ---------------------------------------------

namespace {

/// Evaluates root with every terminal given: jets by (field, component, slot), the coordinate x,
/// the normal nrm, constants 1.
double evaluate(const CompiledForm& form, int dim, ir::NodeId root, const std::vector<double>& x, const std::vector<double>& nrm,
                const std::function<double(int field, int component, int slot)>& jet) {
  const ir::NodeId roots[] = {root};
  return ir::Interpreter(*form.graphs.at(dim)).evaluate(roots, [&](const ir::Node& n) {
    switch (n.op) {
      case ir::Op::Coord: return x.at(static_cast<std::size_t>(n.arg[0]));
      case ir::Op::Normal: return nrm.at(static_cast<std::size_t>(n.arg[0]));
      case ir::Op::Jet: return jet(n.arg[1], n.arg[2], n.arg[3]);
      case ir::Op::Param: return 1.0;
      default: ADD_FAILURE() << "unexpected terminal"; return 0.0;
    }
  })[0];
}

/// A smooth jet: value 1 + field + component/10 + slot/7.
double some_jet(int field, int component, int slot) { return 1.0 + field + component / 10.0 + slot / 7.0; }

}  // namespace

TEST(CompilerFrontend, BoundaryMeasuresSplitAnOutputByDomain) {
  const auto form = compile_source(
      "dimension 2, 3\nunknown u\ncoordinate x\nmeasure dS = 2*pi*x[0]*ds\n"
      "energy E = 0.5*inner(grad(u), grad(u))*dx - u*x[1]*ds(top) + 2*u*ds(top) + u^2*dS + 0*ds(bottom)\n",
      "t.form");
  ASSERT_EQ(form.domains.size(), 4u);  // cells, ds, ds(top), ds(bottom): in order of first use
  EXPECT_FALSE(form.domains[0].boundary);
  EXPECT_EQ(form.domains[1].measure(), "ds");
  EXPECT_EQ(form.domains[2].measure(), "ds(top)");
  EXPECT_EQ(form.domains[3].measure(), "ds(bottom)");
  const OutputDecl& E = form.outputs.at(0);
  const std::vector<double> x = {0.3, 0.7, 1.1}, nrm = {0.6, 0.8, 0.0};
  for (int dim : {2, 3}) {
    SCOPED_TRACE(dim);
    // Two terms over ds(top) are one integrand; the vanishing ds(bottom) term generates nothing.
    ASSERT_EQ(E.integrands.at(dim).size(), 3u);
    EXPECT_FALSE(E.integrands.at(dim).contains(3));
    const double u = some_jet(0, 0, 0);
    double gg = 0;
    for (int i = 0; i < dim; ++i) gg += some_jet(0, 0, 1 + i) * some_jet(0, 0, 1 + i);
    EXPECT_NEAR(evaluate(form, dim, E.integrand(dim), x, nrm, some_jet), 0.5 * gg, 1e-14);
    EXPECT_NEAR(evaluate(form, dim, E.integrand(dim, 1), x, nrm, some_jet), 2 * std::numbers::pi * x[0] * u * u, 1e-14);
    EXPECT_NEAR(evaluate(form, dim, E.integrand(dim, 2), x, nrm, some_jet), -u * x[1] + 2 * u, 1e-14);
    // One kernel per domain, all named E.
    const auto plan = plan_kernel(form, E, dim, 2);
    EXPECT_EQ(plan.domain, 2);
    EXPECT_EQ(plan.slots, (std::vector<int>{0}));
    EXPECT_TRUE(plan.matrix.empty()) << "linear in u over ds(top)";
  }
  const auto gen = generate(form, "t.form");
  for (const char* text : {"inline const lmeform::kernel::FormKernels t_E_2d = ", "inline const lmeform::kernel::FormKernels t_E_ds_2d = ",
                           "inline const lmeform::kernel::FormKernels t_E_ds_top_3d = ", "k.boundary_part = \"top\";",
                           "k.domain = lmeform::kernel::IntegralDomain::Boundary;", "k.matrix_structurally_zero = true;"})
    EXPECT_NE(gen.header.find(text), std::string::npos) << text;
  EXPECT_EQ(gen.header.find("bottom"), std::string::npos);
  EXPECT_NE(gen.json.find("\"boundary_parts\": [\"top\"]"), std::string::npos) << gen.json;
  EXPECT_NE(gen.json.find("\"domain\": \"boundary\", \"boundary_part\": \"top\", \"measure\": \"ds(top)\""), std::string::npos);
  EXPECT_NE(gen.report.find("energy E [ds(top)], dimension 3"), std::string::npos) << gen.report;
  EXPECT_NE(gen.report.find("energy E [dx], dimension 2"), std::string::npos) << gen.report;
}

TEST(CompilerFrontend, TheNormalAtBoundaryPoints) {
  // Volume fields keep their jets at boundary points: normal derivatives of first and second order.
  const auto form = compile_source(
      "dimension 2, 3\nunknown u, w\ntest v, z\ncoordinate x\n"
      "energy E = (dot(grad(u), n) + dot(dot(hess(w), n), n) + inner(grad(n), grad(n)))*ds\n"
      "residual R = (dot(grad(u), grad(v)) + w*z)*dx - dot(grad(u), n)*v*ds(left)\n",
      "t.form");
  const std::vector<double> x = {0.3, 0.7, 1.1}, nrm = {0.6, 0.0, 0.8};
  for (int dim : {2, 3}) {
    SCOPED_TRACE(dim);
    double expected = 0;
    for (int i = 0; i < dim; ++i) {
      expected += some_jet(0, 0, 1 + i) * nrm[static_cast<std::size_t>(i)];
      for (int j = 0; j < dim; ++j)
        expected += some_jet(1, 0, ir::hessian_slot(i, j, dim)) * nrm[static_cast<std::size_t>(i)] * nrm[static_cast<std::size_t>(j)];
    }
    const OutputDecl& E = form.outputs.at(0);
    ASSERT_EQ(E.integrands.at(dim).size(), 1u);
    EXPECT_NEAR(evaluate(form, dim, E.integrand(dim, 1), x, nrm, some_jet), expected, 1e-13) << "grad(n) = 0";
    EXPECT_EQ(plan_kernel(form, E, dim, 1).basis_order, 2);
    EXPECT_EQ(form.outputs.at(1).integrands.at(dim).size(), 2u);
  }
  // `n` is predefined, not reserved: a declaration hides it, and then dx terms may use it.
  EXPECT_EQ(compile_error("unknown u, n\nenergy E = u*n*dx\n"), "");
  EXPECT_EQ(compile_error("unknown u\nlet n = e(0)\nenergy E = dot(grad(u), n)*dx\n"), "");
}

TEST(CompilerFrontend, TheNormalOnCellsIsAnErrorAtTheTerm) {
  const std::string message = "error: the normal n exists only on the boundary: this term is integrated with dx";
  // Through a let, the term that integrates it is named.
  EXPECT_EQ(compile_error("unknown u\nlet flux = dot(grad(u), n)\nenergy E = u^2*ds + flux*u*dx\n"),
            "t.form:3:21: " + message + "\nenergy E = u^2*ds + flux*u*dx\n                    ^\n");
  // In a measure over the cells, a condition of a conditional measure, a divisor.
  EXPECT_NE(compile_error("unknown u\nmeasure dA = n[0]*dx\nenergy E = u*dA\n").find("t.form:2:14: " + message), std::string::npos);
  EXPECT_NE(compile_error("unknown u\nenergy E = (if n[0] > 0 then u*dx else 2*u*dx)\n").find(message), std::string::npos);
  EXPECT_NE(compile_error("unknown u\nenergy E = u*dx/n[0]\n").find(message), std::string::npos);
  EXPECT_NE(compile_error("unknown u\nenergy E = n[0]*(u*ds + u*dx)\n").find(message), std::string::npos);
  // The same integrand over the boundary is fine.
  EXPECT_EQ(compile_error("unknown u\nenergy E = n[0]*(u*ds + u*ds(top))\n"), "");
  EXPECT_NE(compile_error("unknown u\nenergy E = u*n(0)*ds\n").find("'n' is the outward normal, a vector, not a function"),
            std::string::npos);
}

TEST(CompilerFrontend, BoundaryMeasureErrors) {
  EXPECT_EQ(compile_error("unknown u\nenergy E = u*ds(1)\n"),
            "t.form:2:17: error: the argument of ds must be the name of a boundary part (an identifier such as top); found a number\n"
            "energy E = u*ds(1)\n                ^\n");
  EXPECT_NE(compile_error("unknown u\nenergy E = u*ds(x[0])\n").find("found an expression"), std::string::npos);
  EXPECT_NE(compile_error("unknown u\nenergy E = u*ds()\n").find("t.form:2:14: error: ds() needs the name of a boundary part"),
            std::string::npos);
  EXPECT_NE(compile_error("unknown u\nenergy E = u*ds(top, bottom)\n").find("ds takes one boundary part name, got 2 arguments"),
            std::string::npos);
  EXPECT_NE(compile_error("unknown u\nenergy E = u*dx(top)\n").find("dx takes no argument"), std::string::npos);
  // ds is reserved like dx: no declaration, let or parameter may take the name.
  for (const char* text : {"unknown ds\nenergy E = ds*dx\n", "unknown u\nlet ds = 2*u\nenergy E = ds*dx\n",
                                  "unknown u\nconstant ds\nenergy E = u*dx\n", "unknown u\nmeasure ds = 2*dx\nenergy E = u*dx\n"})
    EXPECT_NE(compile_error(text).find("error: 'ds' is a builtin name and cannot be redeclared"), std::string::npos) << text;
  EXPECT_NE(compile_error("unknown u\ndef f(ds) = ds*u\nenergy E = f(1)*dx\n").find("t.form:2:7: error: 'ds' is a builtin name and cannot be a parameter"),
            std::string::npos);
  // A measure alone is still required of an integral output, and ds counts as one.
  EXPECT_NE(compile_error("unknown u\nenergy E = u^2\n").find("must be an integral (a scalar times dx, ds or a declared measure)"),
            std::string::npos);
  EXPECT_EQ(compile_error("unknown u\ntest v\nlinear l = v*ds(right)\n"), "");
  // A vanishing term in one dimension leaves the domain out there.
  const auto form = compile_source("dimension 2, 3\nunknown u\nenergy E = u^2*dx + (if dim == 3 then u*ds else 0*ds)\n", "t.form");
  EXPECT_EQ(form.outputs[0].integrands.at(2).size(), 1u);
  EXPECT_EQ(form.outputs[0].integrands.at(3).size(), 2u);
}

TEST(CompilerFrontend, PointOutputs) {
  const auto form = compile_source(
      "dimension 2, 3\nunknown y : vector\ncoefficient c\nqdata g0 : vector\ncoordinate x\nconstant k = 2\n"
      "let F = grad(y)\n"
      "point Y = y\npoint FF = F\npoint J = k*det(F)\npoint H = hess(y)\npoint K = dot(g0, hess(y))\n"
      "point G = transpose(inv(F))*g0\npoint X = x + c*e(0)\n",
      "t.form");
  const std::map<std::string, std::vector<int>> shapes2 = {{"Y", {2}}, {"FF", {2, 2}}, {"J", {}}, {"H", {2, 2, 2}},
                                                           {"K", {2, 2}}, {"G", {2}}, {"X", {2}}};
  for (const auto& o : form.outputs) {
    SCOPED_TRACE(o.name);
    EXPECT_EQ(o.kind, OutputKind::Point);
    EXPECT_TRUE(o.integrands.empty());
    EXPECT_EQ(o.point.at(2).shape, shapes2.at(o.name));
    std::size_t n3 = 1;
    for (const int e : o.point.at(3).shape) n3 *= static_cast<std::size_t>(e);
    EXPECT_EQ(o.point.at(3).components.size(), n3);
  }
  EXPECT_EQ(plan_kernel(form, form.outputs[3], 3).basis_order, 2);  // hess(y)
  EXPECT_EQ(plan_kernel(form, form.outputs[1], 3).basis_order, 1);
  EXPECT_EQ(plan_kernel(form, form.outputs[6], 2).coefficient_order, 0);
  const auto gen = generate(form, "t.form");
  for (const char* text : {"inline void H_3d_point(const lmeform::kernel::CellInputs& in, double* values) {",
                           "k.kind = lmeform::kernel::FunctionalKind::Point;", "k.n_values = 27;", "k.point_rank = 3;",
                           "k.point_extents[2] = 3;", "double* vq = values + std::size_t(q) * 4;"})
    EXPECT_NE(gen.header.find(text), std::string::npos) << text;
  EXPECT_EQ(gen.header.find("in.weights"), std::string::npos) << "point kernels read no weights";
  EXPECT_NE(gen.json.find("\"point\": {\"shape\": \"tensor3[3x3x3]\", \"rank\": 3, \"extents\": [3, 3, 3], \"n_values\": 27}"),
            std::string::npos);
  EXPECT_NE(gen.report.find("point values: 8 per point (tensor3[2x2x2])"), std::string::npos) << gen.report;
  // Errors: a measure (at the measure), a condition, rank 4, test functions, the normal.
  EXPECT_EQ(compile_error("unknown y : vector\npoint J = det(grad(y))*dx\n"),
            "t.form:2:24: error: point output 'J' must not contain a measure: it is a value at each quadrature point (remove dx or ds)\n"
            "point J = det(grad(y))*dx\n                       ^\n");
  EXPECT_NE(compile_error("unknown u\npoint c = u > 0\n").find("point output 'c' must be a value, not a condition"), std::string::npos);
  EXPECT_NE(compile_error("unknown y : vector\npoint Q = outer(grad(y), grad(y))\n")
                .find("point output 'Q' must be a scalar, vector, matrix or tensor3; found tensor4[2x2x2x2]"),
            std::string::npos);
  EXPECT_NE(compile_error("unknown u\ntest v\npoint P = u*v\n").find("point output 'P' must not use test or trial functions"),
            std::string::npos);
  EXPECT_EQ(compile_error("unknown u\npoint P = u + n[0]\n"),
            "t.form:2:15: error: the normal n exists only on the boundary: point output 'P' is evaluated at the cells' "
            "quadrature points\npoint P = u + n[0]\n              ^\n");
  // `point` is a keyword now.
  EXPECT_NE(compile_error("unknown point\nenergy E = point*dx\n"), "");
}

TEST(CompilerFrontend, Requirements) {
  const auto form = compile_source(
      "dimension 1, 2\nunknown u : vector, v\nconstant Gc = 1, l\ncoordinate x\n"
      "require Gc > 0 and l > 0, \"Gc and l must be positive\"\n"
      "require v >= 0 or x[0] < 0, \"v starts non-negative\"\n"
      "energy E = Gc*v^2*dx\n",
      "t.form");
  ASSERT_EQ(form.outputs.size(), 3U);
  const OutputDecl& constants_only = form.outputs[0];
  EXPECT_EQ(constants_only.kind, OutputKind::Point);
  EXPECT_EQ(constants_only.requirement, "Gc and l must be positive");
  EXPECT_EQ(constants_only.requirement_condition, "Gc > 0 and l > 0");
  EXPECT_FALSE(constants_only.requirement_pointwise);
  EXPECT_TRUE(form.outputs[1].requirement_pointwise) << "it reads v and x";
  EXPECT_EQ(form.outputs[1].point.at(2).components.size(), 1U);
  const auto gen = generate(form, "t.form");
  EXPECT_NE(gen.header.find("k.requirement = \"Gc and l must be positive\";"), std::string::npos);
  EXPECT_NE(gen.header.find("k.requirement_pointwise = true;"), std::string::npos);
  EXPECT_NE(gen.json.find("\"requirement\": \"v starts non-negative\", \"condition\": \"v >= 0 or x[0] < 0\""), std::string::npos);
  EXPECT_NE(compile_error("constant a = 1\nunknown v\nrequire a + 1, \"x\"\nenergy E = v*dx\n")
                .find("the requirement \"x\" must be a condition (a comparison such as Gc > 0, combined with and, or, not); found scalar"),
            std::string::npos);
  EXPECT_NE(compile_error("constant a = 1\nunknown v\nrequire a > 1 \"x\"\nenergy E = v*dx\n").find("expected ',' and the requirement's message"),
            std::string::npos);
  EXPECT_NE(compile_error("unknown v\nqdata q\nrequire q > 0, \"q\"\nenergy E = v*dx\n").find("must not read quadrature-point data"),
            std::string::npos);
  EXPECT_NE(compile_error("unknown v\ncoefficient c\nrequire c > 0, \"c\"\nenergy E = v*dx\n").find("not test, trial or coefficient fields"),
            std::string::npos);
}

TEST(CompilerFrontend, RecommendationsAndTheNodeSpacing) {
  const auto form = compile_source(
      "dimension 2\nunknown v\nconstant l\n"
      "recommend v > 0.5 or l >= 2*spacing, \"resolve the band\"\n"
      "require l > 0, \"l positive\"\n"
      "energy E = l*v^2*dx\n",
      "t.form");
  ASSERT_EQ(form.outputs.size(), 3U);
  EXPECT_TRUE(form.outputs[0].requirement_advisory);
  EXPECT_TRUE(form.outputs[0].requirement_pointwise) << "it reads v and the spacing";
  EXPECT_FALSE(form.outputs[1].requirement_advisory);
  const auto gen = generate(form, "t.form");
  EXPECT_NE(gen.header.find("k.reads_spacing = true;"), std::string::npos);
  EXPECT_NE(gen.header.find("k.requirement_advisory = true;"), std::string::npos);
  EXPECT_NE(gen.header.find("in.spacing[q]"), std::string::npos);
  // A requirement on the constants alone reads no spacing; only one kernel is advisory.
  EXPECT_EQ(gen.header.find("k.reads_spacing = true;"), gen.header.rfind("k.reads_spacing = true;"));
  EXPECT_EQ(gen.header.find("k.requirement_advisory = true;"), gen.header.rfind("k.requirement_advisory = true;"));
  // The spacing is a property of the nodes, known where requirements are checked only.
  EXPECT_EQ(compile_error("unknown v\nenergy E = spacing*v^2*dx\n"),
            "t.form:2:12: error: 'spacing' (the local node spacing) is known in require lines only, where the runtime checks the "
            "model's resolution rules (require l >= 2*spacing, ...)\nenergy E = spacing*v^2*dx\n           ^\n");
  EXPECT_NE(compile_error("unknown v\npoint P = v/spacing\n").find("is known in require lines only"), std::string::npos);
  // A form may name its own 'spacing'.
  EXPECT_NO_THROW(compile_source("unknown v\nconstant spacing = 2\nenergy E = spacing*v^2*dx\n", "t.form"));
  EXPECT_NE(compile_error("unknown v\nrecommend v > 0\nenergy E = v*dx\n").find("expected ',' and the requirement's message"), std::string::npos);
}

TEST(CompilerFrontend, KernelNamesOfDomainsMustNotCollide) {
  EXPECT_NE(compile_error_generating("unknown u\nenergy E_ds = u^2*dx\nenergy E = u^2*dx + u*ds\n")
                .find("t.form:3:1: error: the kernels of energy E [ds] and of energy 'E_ds' would both be named 't_E_ds_2d'"),
            std::string::npos);
}

// ---- hostile inputs -----------------------------------------------------------------------------

TEST(CompilerFrontend, LongSumsCompile) {
  std::string sum = "u";
  for (int i = 1; i < 5000; ++i) sum += i % 2 ? " + u" : " - 2*u";
  const auto form = compile_source("unknown u\ncoordinate x\nenergy e = (" + sum + " + x[0])^2*dx\n", "t.form");
  const auto gen = generate(form, "t.form");
  EXPECT_NE(gen.header.find("_all_kernels[]"), std::string::npos);
  // 20,000 distinct terms, lowered, differentiated and emitted.
  std::string terms = "u";
  for (int i = 1; i < 20000; ++i) terms += " + " + std::to_string(i) + "*u^2";
  EXPECT_NO_THROW(generate(compile_source("unknown u\nenergy e = (" + terms + ")*dx\n", "t.form"), "t.form"));
}

TEST(CompilerFrontend, DeepNestingIsAFormError) {
  const std::string deep = std::string(10000, '(') + "u" + std::string(10000, ')');
  const std::string message = compile_error("unknown u\nenergy e = " + deep + "^2*dx\n");
  EXPECT_EQ(message.substr(0, message.find('\n')),
            "t.form:2:141: error: expression nested too deeply: more than 128 levels of parentheses, brackets, calls, "
            "conditionals or prefix operators");
  // The source line is shown as a window around the caret.
  EXPECT_LT(message.size(), 600u);
  for (const std::string& prefix : {std::string(10000, '-'), std::string(5000, '(') + "sin"}) {
    SCOPED_TRACE(prefix.substr(0, 5));
    EXPECT_NE(compile_error("unknown u\nenergy e = " + prefix + "u^2*dx\n").find("expression nested too deeply"), std::string::npos);
  }
  // Def calls inline their bodies: a chain of defs nests as deep as their bodies together.
  std::string chain = "unknown u\ndef f0(a) = a\n";
  for (int k = 1; k < 64; ++k)
    chain += "def f" + std::to_string(k) + "(a) = " + std::string(100, '-') + "f" + std::to_string(k - 1) + "(a)\n";
  EXPECT_NE(compile_error(chain + "energy e = f63(u)^2*dx\n").find("error: expression nested too deeply once def calls are inlined: more than 512 levels"),
            std::string::npos);
  // 128 levels are fine, 129 are not.
  EXPECT_EQ(compile_error("unknown u\nenergy e = " + std::string(128, '(') + "u" + std::string(128, ')') + "^2*dx\n"), "");
  EXPECT_NE(compile_error("unknown u\nenergy e = " + std::string(129, '(') + "u" + std::string(129, ')') + "^2*dx\n"), "");
}

// Each def calls the previous one twice: inlined naively, 40 levels are 2^40 body lowerings. The IR
// is hash-consed, so repeated calls with the same arguments are reused and this takes milliseconds.
TEST(CompilerFrontend, DoublingDefChainsCompileInLinearTime) {
  std::string chain = "unknown u\ndef f0(a) = a*a + 1\n";
  for (int k = 1; k <= 40; ++k)
    chain += "def f" + std::to_string(k) + "(a) = f" + std::to_string(k - 1) + "(a) + f" + std::to_string(k - 1) + "(a)\n";
  const auto t0 = std::chrono::steady_clock::now();
  const auto gen = generate(compile_source(chain + "energy e = f40(u)*dx\n", "t.form"), "t.form");
  const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  EXPECT_NE(gen.header.find("_all_kernels[]"), std::string::npos);
  EXPECT_LT(seconds, 5.0);  // measured 7 ms; the naive expansion would not finish
}

TEST(CompilerFrontend, NonAsciiOutsideCommentsIsNamed) {
  EXPECT_EQ(compile_error("unknown u  # φ is fine here\nenergy e = u^2*dx  # and é here\n"), "");
  EXPECT_EQ(compile_error("unknown u\nenergy e = u^2*dx + u*λ*dx\n"),
            "t.form:2:23: error: non-ASCII character U+03BB (λ) is not allowed outside comments\n"
            "energy e = u^2*dx + u*λ*dx\n"
            "                      ^\n");
  EXPECT_NE(compile_error("unknown u\xff\nenergy e = u^2*dx\n")
                .find("t.form:1:10: error: non-ASCII character byte 0xFF (not valid UTF-8) is not allowed outside comments"),
            std::string::npos);
}

TEST(CompilerFrontend, TheFormFileMustBeARegularFile) {
  const fs::path dir = scratch_dir("regular");
  try {
    compile_file(dir);
    FAIL() << "a directory compiled";
  } catch (const CompileError& e) {
    EXPECT_EQ(std::string(e.what()), dir.string() + ": error: is a directory, not a form file\n");
  }
  try {
    compile_file("/dev/zero");
    FAIL() << "/dev/zero compiled";
  } catch (const CompileError& e) {
    EXPECT_EQ(std::string(e.what()), "/dev/zero: error: is not a regular file\n");
  }
  fs::remove_all(dir);
}

// ---- dependencies -------------------------------------------------------------------------------

TEST(CompilerFrontend, DependenciesOnlyParseAndResolveIncludes) {
  const fs::path dir = scratch_dir("dependencies");
  fs::create_directories(dir / "lib");
  fs::create_directories(dir / "forms");
  write_text(dir / "forms" / "main.form", "include \"local.inc\"\ninclude \"shared.inc\"\nunknown u\n"
                                         "energy e = undeclared_name*u*dx\n");  // an error only lowering sees
  write_text(dir / "forms" / "local.inc", "constant k\n");
  write_text(dir / "lib" / "shared.inc", "include \"nested.inc\"\n");
  write_text(dir / "lib" / "nested.inc", "constant m\n");
  CompileOptions options;
  options.include_dirs.push_back(dir / "forms" / ".." / "lib");
  const auto t0 = std::chrono::steady_clock::now();
  const auto files = form_dependencies(dir / "forms" / ".." / "forms" / "main.form", options);
  const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  const std::vector<fs::path> expected = {dir / "forms" / "main.form", dir / "forms" / "local.inc",
                                          dir / "lib" / "shared.inc", dir / "lib" / "nested.inc"};
  EXPECT_EQ(files, expected);
  EXPECT_LT(seconds, 0.5);
  // Relative paths come back absolute.
  const fs::path cwd = fs::current_path();
  fs::current_path(dir / "forms");
  EXPECT_EQ(form_dependencies("main.form", options).front(), dir / "forms" / "main.form");
  fs::current_path(cwd);
  // Syntax and include errors are reported.
  write_text(dir / "forms" / "broken.form", "include \"missing.inc\"\n");
  EXPECT_THROW(form_dependencies(dir / "forms" / "broken.form"), CompileError);
  fs::remove_all(dir);
}
