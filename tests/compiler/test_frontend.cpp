// Parser and checker: valid forms compile; each broken form under data/errors gives exactly the
// diagnostic in golden/<name>.txt (file:line:col, message, source line, caret).
#include <gtest/gtest.h>

#include <unistd.h>

#include <chrono>
#include <cmath>
#include <filesystem>
#include <fstream>
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
  const ir::NodeId roots[] = {form.outputs.at(0).integrand.at(dim)};
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
  EXPECT_GE(count, 26);
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
