// Forms compiled at run time: a miss then a hit (milliseconds), two processes compiling the same
// form at once (both succeed, one entry), and the message of every failure (lmeformc not found, a
// form error with its caret, a C++ compiler error with the generated code kept, a stale entry).
#include <gtest/gtest.h>

#include <mpi.h>
#include <spawn.h>
#include <sys/wait.h>

#include <chrono>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>

#include "lmeform/form_registry.hpp"

extern char** environ;

namespace fs = std::filesystem;
using namespace lmeform;

namespace {

std::string self_path;  // argv[0], for the child processes

fs::path fresh_dir(const std::string& name) {
  const fs::path dir = fs::temp_directory_path() / ("lmeform-test-jit-" + std::to_string(::getpid())) / name;
  fs::remove_all(dir);
  fs::create_directories(dir);
  return dir;
}

fs::path write(const fs::path& path, const std::string& text) {
  std::ofstream(path) << text;
  return path;
}

const std::string kHeat =
    "form heat\n"
    "dimension 2\n"
    "unknown T\n"
    "constant kappa = 1\n"
    "energy heat = kappa/2*dot(grad(T), grad(T))*dx\n";

std::size_t count_files(const fs::path& dir, const std::string& extension) {
  std::size_t n = 0;
  for (const auto& e : fs::directory_iterator(dir))
    if (e.path().extension() == extension) ++n;
  return n;
}

TEST(Jit, SecondLoadIsACacheHitInMilliseconds) {
  const fs::path dir = fresh_dir("hit");
  const fs::path form = write(dir / "heat.form", kHeat);
  FormLoadOptions options;
  options.cache_dir = dir / "cache";
  const FormModule first = compile_form(form, options);
  EXPECT_FALSE(first.cache_hit);
  EXPECT_GT(first.compile_seconds, 0.0);
  ASSERT_NE(first.find("heat", 2), nullptr);
  EXPECT_EQ(first.find("heat", 2)->kind, kernel::FunctionalKind::Energy);
  EXPECT_EQ(first.constants(), std::vector<std::string>{"kappa"});
  const FormModule second = compile_form(form, options);
  EXPECT_TRUE(second.cache_hit);
  EXPECT_EQ(second.library, first.library);
  std::printf("compile %.2f s (lmeformc %.3f s, C++ %.2f s); cache hit %.1f ms\n", first.load_seconds,
              first.generate_seconds, first.compile_seconds, 1e3 * second.load_seconds);
  EXPECT_LT(second.load_seconds, 0.5);
  // An edit of an included file changes the key.
  write(dir / "coefficient.inc", "let c = 2\n");
  const fs::path with_include =
      write(dir / "heat2.form", "dimension 2\nunknown T\ninclude \"coefficient.inc\"\nenergy heat = c*dot(grad(T), grad(T))*dx\n");
  const FormModule before = compile_form(with_include, options);
  write(dir / "coefficient.inc", "let c = 3\n");
  const FormModule after = compile_form(with_include, options);
  EXPECT_FALSE(after.cache_hit);
  EXPECT_NE(before.cache_key, after.cache_key);
}

TEST(Jit, BuiltinAndFileFormsComeFromOneRegistry) {
  const FormModule& builtin = load_form("poisson");
  EXPECT_TRUE(builtin.builtin);
  EXPECT_NE(builtin.find("heat", 3), nullptr);
  EXPECT_EQ(&load_form("poisson"), &builtin);
  try {
    (void)load_form("poison");
    FAIL() << "an unknown module name loaded";
  } catch (const FormLoadError& e) {
    EXPECT_NE(std::string(e.what()).find("'poison' is neither a built-in form module"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("poisson"), std::string::npos) << e.what();
  }
  const fs::path dir = fresh_dir("registry");
  const fs::path form = write(dir / "heat.form", kHeat);
  FormLoadOptions options;
  options.cache_dir = dir / "cache";
  const FormModule& jit = load_form(form.string(), options);
  EXPECT_FALSE(jit.builtin);
  EXPECT_EQ(&load_form(form.string(), options), &jit);
}

TEST(Jit, TwoProcessesCompilingAtOnceBothSucceedAndLeaveOneEntry) {
  const fs::path dir = fresh_dir("concurrent");
  const fs::path form = write(dir / "heat.form", kHeat);
  const fs::path cache = dir / "cache";
  pid_t pids[2];
  for (pid_t& pid : pids) {
    std::vector<std::string> args{self_path, "--compile-only", form.string(), cache.string()};
    std::vector<char*> argv;
    for (auto& a : args) argv.push_back(a.data());
    argv.push_back(nullptr);
    ASSERT_EQ(posix_spawn(&pid, self_path.c_str(), nullptr, nullptr, argv.data(), environ), 0);
  }
  for (const pid_t pid : pids) {
    int status = 0;
    ASSERT_EQ(waitpid(pid, &status, 0), pid);
    EXPECT_TRUE(WIFEXITED(status) && WEXITSTATUS(status) == 0) << "a compiling process failed";
  }
  EXPECT_EQ(count_files(cache, ".so"), 1u);
  EXPECT_EQ(count_files(cache, ".json"), 1u);
  for (const auto& e : fs::directory_iterator(cache))
    EXPECT_EQ(e.path().string().find(".tmp."), std::string::npos) << "a temporary was left: " << e.path();
}

TEST(Jit, AFormErrorNamesFileLineAndColumn) {
  const fs::path dir = fresh_dir("form-error");
  const fs::path form = write(dir / "broken.form", "dimension 2\nunknown T\nenergy e = dot(grad(T), grad(S))*dx\n");
  FormLoadOptions options;
  options.cache_dir = dir / "cache";
  try {
    (void)compile_form(form, options);
    FAIL() << "a broken form compiled";
  } catch (const FormLoadError& e) {
    const std::string m = e.what();
    EXPECT_NE(m.find("broken.form:3:"), std::string::npos) << m;
    EXPECT_NE(m.find("^"), std::string::npos) << m;
  }
}

TEST(Jit, ACompilerErrorKeepsTheGeneratedCodeAndSaysWhere) {
  const fs::path dir = fresh_dir("cxx-error");
  const fs::path form = write(dir / "heat.form", kHeat);
  const fs::path fake = write(dir / "fake-cxx.sh", "#!/bin/sh\necho 'fake-cxx: error: no such intrinsic' >&2\nexit 1\n");
  fs::permissions(fake, fs::perms::owner_all);
  ::setenv("LMEFORM_CXX", fake.c_str(), 1);
  FormLoadOptions options;
  options.cache_dir = dir / "cache";
  try {
    (void)compile_form(form, options);
    ::unsetenv("LMEFORM_CXX");
    FAIL() << "a failing compiler produced a module";
  } catch (const FormLoadError& e) {
    ::unsetenv("LMEFORM_CXX");
    const std::string m = e.what();
    EXPECT_NE(m.find("the C++ compiler failed"), std::string::npos) << m;
    EXPECT_NE(m.find("no such intrinsic"), std::string::npos) << m;
    const auto kept = m.find("(kept in ");
    ASSERT_NE(kept, std::string::npos) << m;
    const std::string path = m.substr(kept + 9, m.find(')', kept) - kept - 9);
    EXPECT_TRUE(fs::exists(fs::path(path) / "heat_kernels.hpp")) << path;
  }
  EXPECT_EQ(count_files(dir / "cache", ".so"), 0u);
}

TEST(Jit, MissingLmeformcIsNamed) {
  const fs::path dir = fresh_dir("no-lmeformc");
  const fs::path form = write(dir / "heat.form", kHeat);
  ::setenv("LMEFORM_LMEFORMC", (dir / "nowhere" / "lmeformc").c_str(), 1);
  FormLoadOptions options;
  options.cache_dir = dir / "cache";
  try {
    (void)compile_form(form, options);
    ::unsetenv("LMEFORM_LMEFORMC");
    FAIL() << "compiled without lmeformc";
  } catch (const FormLoadError& e) {
    ::unsetenv("LMEFORM_LMEFORMC");
    EXPECT_NE(std::string(e.what()).find("lmeformc not found"), std::string::npos) << e.what();
  }
}

TEST(Jit, AStaleEntryIsReplacedAndReported) {
  const fs::path dir = fresh_dir("stale");
  const fs::path form = write(dir / "heat.form", kHeat);
  FormLoadOptions options;
  options.cache_dir = dir / "cache";
  // The entry is made by another process: this one must not have the library mapped when it is
  // damaged (the cache itself never rewrites a library in place; it renames whole files).
  pid_t pid = 0;
  std::vector<std::string> args{self_path, "--compile-only", form.string(), options.cache_dir.string()};
  std::vector<char*> argv;
  for (auto& a : args) argv.push_back(a.data());
  argv.push_back(nullptr);
  ASSERT_EQ(posix_spawn(&pid, self_path.c_str(), nullptr, nullptr, argv.data(), environ), 0);
  int status = 0;
  ASSERT_EQ(waitpid(pid, &status, 0), pid);
  ASSERT_TRUE(WIFEXITED(status) && WEXITSTATUS(status) == 0);
  ASSERT_EQ(count_files(options.cache_dir, ".so"), 1u);
  for (const auto& e : fs::directory_iterator(options.cache_dir))
    if (e.path().extension() == ".so") std::ofstream(e.path(), std::ios::trunc) << "not a shared object";
  std::ostringstream log;
  options.log = &log;
  const FormModule again = compile_form(form, options);
  EXPECT_FALSE(again.cache_hit);
  EXPECT_NE(again.find("heat", 2), nullptr);
  EXPECT_NE(log.str().find("stale or foreign cache entry"), std::string::npos) << log.str();
}

}  // namespace

int main(int argc, char** argv) {
  self_path = fs::canonical("/proc/self/exe").string();
  MPI_Init(&argc, &argv);
  int code = 0;
  if (argc == 4 && std::string(argv[1]) == "--compile-only") {
    // A child of TwoProcessesCompilingAtOnce...: compile one form into a cache, exit 0 on success.
    try {
      FormLoadOptions options;
      options.cache_dir = argv[3];
      const FormModule m = compile_form(argv[2], options);
      code = m.find("heat", 2) != nullptr ? 0 : 1;
    } catch (const std::exception& e) {
      std::fprintf(stderr, "%s\n", e.what());
      code = 1;
    }
  } else {
    ::testing::InitGoogleTest(&argc, argv);
    code = RUN_ALL_TESTS();
  }
  MPI_Finalize();
  return code;
}
