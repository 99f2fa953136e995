// Parser and checker: valid forms compile; each broken form under data/errors gives exactly the
// diagnostic in golden/<name>.txt (file:line:col, message, source line, caret).
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <numbers>
#include <sstream>

#include "lmeform/compiler/codegen.hpp"
#include "lmeform/compiler/compile.hpp"

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
  EXPECT_GE(count, 15);
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
