// fuzz_replay: the fuzz target's entry point (fuzz_lmeformc.cpp) over its seed corpus (every .form
// and .inc of forms/ and tests/compiler/data/) and over regressions/ (inputs that once crashed the
// compiler), built with the normal compiler and run by `make test`. A CompileError is caught by the
// entry point; any other exception fails the test here, naming the input.
#include <gtest/gtest.h>

#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size);

namespace fs = std::filesystem;

namespace {

const fs::path kRoot = LMEFORM_SOURCE_DIR;

std::vector<fs::path> files_under(const fs::path& dir, const std::vector<std::string>& extensions) {
  std::vector<fs::path> files;
  for (const auto& e : fs::recursive_directory_iterator(dir)) {
    if (!e.is_regular_file()) continue;
    const std::string ext = e.path().extension().string();
    if (extensions.empty() ? e.path().filename() != "README.md"
                           : std::find(extensions.begin(), extensions.end(), ext) != extensions.end())
      files.push_back(e.path());
  }
  std::sort(files.begin(), files.end());
  return files;
}

void replay(const fs::path& file) {
  SCOPED_TRACE(file.string());
  std::ifstream in(file, std::ios::binary);
  ASSERT_TRUE(in) << "cannot read " << file;
  std::ostringstream read;
  read << in.rdbuf();
  const std::string bytes = std::move(read).str();
  try {
    EXPECT_EQ(LLVMFuzzerTestOneInput(reinterpret_cast<const std::uint8_t*>(bytes.data()), bytes.size()), 0);
  } catch (const std::exception& e) {
    ADD_FAILURE() << "an exception other than CompileError escaped: " << e.what();
  } catch (...) {
    ADD_FAILURE() << "an exception other than CompileError escaped (not a std::exception)";
  }
}

}  // namespace

TEST(FuzzReplay, SeedCorpus) {
  std::size_t count = 0;
  for (const char* dir : {"forms", "tests/compiler/data"})
    for (const auto& file : files_under(kRoot / dir, {".form", ".inc"})) {
      replay(file);
      ++count;
    }
  EXPECT_GE(count, 40u);
}

TEST(FuzzReplay, Regressions) {
  for (const auto& file : files_under(kRoot / "compiler" / "fuzz" / "regressions", {})) replay(file);
}
