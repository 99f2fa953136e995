// lmeformc as a program: --version, --dependencies, errors about the form file itself, and outputs
// that appear all together or not at all. Every test runs both the CLI11 build and the fallback
// argument parser (built from the same main.cpp without CLI11).
#include <gtest/gtest.h>

#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

namespace fs = std::filesystem;

namespace {

std::string slurp(const fs::path& p) {
  std::ifstream in(p, std::ios::binary);
  std::ostringstream s;
  s << in.rdbuf();
  return s.str();
}

std::string quoted(const std::string& s) {
  std::string q = "'";
  for (char c : s) q += c == '\'' ? std::string("'\\''") : std::string(1, c);
  return q + "'";
}

struct Outcome {
  int exit_code = -1;
  std::string out, err;
};

/// The files under dir, relative to it, sorted.
std::vector<std::string> listing(const fs::path& dir) {
  std::vector<std::string> names;
  for (const auto& e : fs::recursive_directory_iterator(dir)) names.push_back(fs::relative(e.path(), dir).string());
  std::sort(names.begin(), names.end());
  return names;
}

class Lmeformc : public testing::TestWithParam<const char*> {
 protected:
  void SetUp() override {
    work_ = fs::temp_directory_path() / ("lmeform_cli_" + std::to_string(::getpid()) + "_" + std::to_string(counter_++));
    fs::remove_all(work_);
    fs::create_directories(work_ / "cwd");
  }
  void TearDown() override { fs::remove_all(work_); }

  /// Runs the binary under test with args (already quoted where needed) in work_/cwd.
  Outcome run(const std::string& args) const {
    const fs::path out = work_ / "stdout.txt", err = work_ / "stderr.txt";
    const std::string command = "cd " + quoted((work_ / "cwd").string()) + " && " + quoted(GetParam()) + " " + args + " > " +
                                quoted(out.string()) + " 2> " + quoted(err.string());
    const int status = std::system(command.c_str());
    Outcome r;
    r.exit_code = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
    r.out = slurp(out);
    r.err = slurp(err);
    return r;
  }

  void write(const fs::path& p, const std::string& text) const {
    std::ofstream o(p, std::ios::binary);
    o << text;
  }

  fs::path work_;
  static inline int counter_ = 0;
};

const fs::path data = LMEFORM_TEST_DATA;

}  // namespace

TEST_P(Lmeformc, VersionIsTheProjectVersion) {
  const Outcome r = run("--version");
  EXPECT_EQ(r.exit_code, 0) << r.err;
  EXPECT_EQ(r.out, std::string("lmeformc ") + LMEFORM_VERSION + "\n");
}

TEST_P(Lmeformc, DependenciesListTheFormAndItsIncludes) {
  const Outcome r = run(quoted((data / "axisymmetric.form").string()) + " --dependencies -I " + quoted((data / "include").string()));
  EXPECT_EQ(r.exit_code, 0) << r.err;
  EXPECT_EQ(r.out, (data / "axisymmetric.form").lexically_normal().string() + "\n" +
                       (data / "include" / "axisymmetric_ops.inc").lexically_normal().string() + "\n");
  EXPECT_EQ(r.err, "");
  EXPECT_TRUE(listing(work_ / "cwd").empty()) << "--dependencies wrote files";
  // Relative paths are printed absolute and normalized.
  write(work_ / "cwd" / "relative.form", "include \"sub/../parts.inc\"\nunknown u\nenergy e = u^2*dx\n");
  fs::create_directories(work_ / "cwd" / "sub");
  write(work_ / "cwd" / "parts.inc", "constant k\n");
  const Outcome rel = run("./relative.form --dependencies");
  EXPECT_EQ(rel.exit_code, 0) << rel.err;
  EXPECT_EQ(rel.out, (work_ / "cwd" / "relative.form").string() + "\n" + (work_ / "cwd" / "parts.inc").string() + "\n");
}

TEST_P(Lmeformc, DependenciesReportFormErrors) {
  write(work_ / "cwd" / "broken.form", "unknown u\nenergy e = (u*dx\n");
  const Outcome r = run("broken.form --dependencies");
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_EQ(r.out, "");
  EXPECT_EQ(r.err, "broken.form:3:1: error: expected ')', found end of file\n\n^\n");
}

TEST_P(Lmeformc, ReportExplainsEachKernel) {
  write(work_ / "cwd" / "cost.form",
        "form cost\ndimension 2, 3\nunknown u\nconstant k = 1\nenergy bend = k*lap(u)^2*dx\nenergy mass = u^2*dx\n");
  const Outcome r = run("cost.form --report");
  EXPECT_EQ(r.exit_code, 0) << r.err;
  EXPECT_TRUE(listing(work_ / "cwd").size() == 1) << "--report without -o wrote files";
  for (const std::string& expected :
       {std::string("cost report of form cost"), std::string("energy bend, dimension 2 (cost.form:5:1)"),
        std::string("energy bend, dimension 3 (cost.form:5:1)"), std::string("| energy bend = k*lap(u)^2*dx"),
        std::string("jet components (m = 2): u d2/dx0dx0, u d2/dx1dx1"),
        std::string("jet components (m = 3): u d2/dx0dx0, u d2/dx1dx1, u d2/dx2dx2"),
        std::string("jet components (m = 1): u value"), std::string("H/v "), std::string("% in the contractions"),
        std::string(" generated lines")})
    EXPECT_NE(r.out.find(expected), std::string::npos) << "missing: " << expected << "\n" << r.out;
  // With -o the files are written too.
  const Outcome w = run("cost.form --report -o out");
  EXPECT_EQ(w.exit_code, 0) << w.err;
  EXPECT_TRUE(fs::exists(work_ / "cwd" / "out" / "cost_kernels.hpp"));
  EXPECT_NE(w.out.find("cost report of form cost"), std::string::npos);
}

TEST_P(Lmeformc, ReportAndJsonNameBoundaryAndPointKernels) {
  write(work_ / "cwd" / "walls.form",
        "dimension 2, 3\nunknown y : vector\ncoordinate x\n"
        "energy E = inner(grad(y), grad(y))*dx - dot(y, n)*x[0]*ds(top)\npoint F = grad(y)\n");
  const Outcome r = run("walls.form --report -o out");
  EXPECT_EQ(r.exit_code, 0) << r.err;
  for (const std::string& expected :
       {std::string("energy E [dx], dimension 2 (walls.form:4:1)"), std::string("energy E [ds(top)], dimension 3 (walls.form:4:1)"),
        std::string("point F, dimension 3 (walls.form:5:1)"), std::string("point values: 9 per point (matrix[3x3]); flops/point")})
    EXPECT_NE(r.out.find(expected), std::string::npos) << "missing: " << expected << "\n" << r.out;
  const std::string json = slurp(work_ / "cwd" / "out" / "walls.json");
  for (const std::string& expected :
       {std::string("\"boundary_parts\": [\"top\"]"),
        std::string("\"symbol\": \"walls_E_ds_top_2d\", \"output\": \"E\", \"kind\": \"energy\", \"dim\": 2, \"domain\": \"boundary\", "
                    "\"boundary_part\": \"top\", \"measure\": \"ds(top)\""),
        std::string("\"symbol\": \"walls_E_3d\", \"output\": \"E\", \"kind\": \"energy\", \"dim\": 3, \"domain\": \"cells\""),
        std::string("\"point\": {\"shape\": \"matrix[2x2]\", \"rank\": 2, \"extents\": [2, 2], \"n_values\": 4}")})
    EXPECT_NE(json.find(expected), std::string::npos) << "missing: " << expected << "\n" << json;
}

TEST_P(Lmeformc, ADirectoryIsNotAForm) {
  fs::create_directories(work_ / "cwd" / "forms");
  const Outcome r = run("forms -o out");
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_EQ(r.err, "forms: error: is a directory, not a form file\n");
  EXPECT_FALSE(fs::exists(work_ / "cwd" / "out" / "forms_kernels.hpp"));
}

TEST_P(Lmeformc, OutputsAreWrittenTogether) {
  write(work_ / "cwd" / "m.form", "unknown u\nenergy e = u^2*dx\n");
  const Outcome r = run("m.form -o out --depfile out/m.d");
  EXPECT_EQ(r.exit_code, 0) << r.err;
  EXPECT_EQ(listing(work_ / "cwd" / "out"), (std::vector<std::string>{"m.d", "m.json", "m_kernels.hpp"}));
  EXPECT_NE(slurp(work_ / "cwd" / "out" / "m.d").find("m_kernels.hpp: " + (work_ / "cwd" / "m.form").string()), std::string::npos);
}

TEST_P(Lmeformc, NoOutputWhenTheJsonCannotBeWritten) {
  write(work_ / "cwd" / "m.form", "unknown u\nenergy e = u^2*dx\n");
  fs::create_directories(work_ / "cwd" / "out" / "m.json");  // in the way of the JSON file
  const Outcome r = run("m.form -o out --depfile m.d");
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_EQ(r.err, "lmeformc: error: cannot write out/m.json: it is a directory\n");
  EXPECT_EQ(listing(work_ / "cwd"), (std::vector<std::string>{"m.form", "out", "out/m.json"}));
}

TEST_P(Lmeformc, NoOutputWhenTheDepfileCannotBeWritten) {
  write(work_ / "cwd" / "m.form", "unknown u\nenergy e = u^2*dx\n");
  fs::create_directories(work_ / "cwd" / "deps.d");
  const Outcome in_the_way = run("m.form -o out --depfile deps.d");
  EXPECT_EQ(in_the_way.exit_code, 1);
  EXPECT_EQ(in_the_way.err, "lmeformc: error: cannot write deps.d: it is a directory\n");
  EXPECT_EQ(listing(work_ / "cwd"), (std::vector<std::string>{"deps.d", "m.form", "out"}));
  // A depfile in a directory that does not exist: its temporary cannot even be created.
  const Outcome no_dir = run("m.form -o out --depfile missing/deps.d");
  EXPECT_EQ(no_dir.exit_code, 1);
  EXPECT_EQ(no_dir.err, "lmeformc: error: cannot write missing/deps.d: No such file or directory\n");
  EXPECT_EQ(listing(work_ / "cwd"), (std::vector<std::string>{"deps.d", "m.form", "out"}));
}

INSTANTIATE_TEST_SUITE_P(Cli, Lmeformc, testing::Values(LMEFORMC, LMEFORMC_WITHOUT_CLI11),
                         [](const testing::TestParamInfo<const char*>& param_info) {
                           return param_info.index == 0 ? std::string("WithCli11") : std::string("Fallback");
                         });
