// The form compiler's fuzz entry point: the input bytes are the text of a .form file, compiled as
// lmeformc compiles one (parse, includes, declarations, checks, lowering per dimension, then
// differentiation and code generation by generate()), without writing anything.
//
// A CompileError is the compiler's answer to a bad form and ends the input. Anything else is a
// finding: another exception escapes (std::terminate names its type), a crash, a sanitizer
// report, a failed assertion, a timeout. Built twice: as fuzz_lmeformc with libFuzzer
// (-DLMEFORM_FUZZ=ON, clang) and into fuzz_replay, which runs the seed corpus and the crashers of
// regressions/ through the same function in every build (docs/fuzzing.md).
#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <string>

#include "lmeform/compiler/codegen.hpp"
#include "lmeform/compiler/compile.hpp"

#ifndef LMEFORM_SOURCE_DIR
#error "LMEFORM_SOURCE_DIR (the project's source directory) must be defined by the build"
#endif

namespace {

using namespace lmeform::compiler;

/// Whether a double-quoted run (an include path, up to its closing quote or the end of the line)
/// holds a '/' or '\': such inputs are skipped, so that the fuzzer reads only files of the include
/// directories below and never wanders the file system (/proc/kcore, ../../..). Include paths
/// with directories are covered by tests/compiler.
bool names_a_directory(const std::string& text) {
  bool in_string = false;
  for (const char c : text) {
    if (c == '\n' || c == '\r') in_string = false;
    else if (c == '"') in_string = !in_string;
    else if (in_string && (c == '/' || c == '\\')) return true;
  }
  return false;
}

const CompileOptions& options() {
  static const CompileOptions o = [] {
    const std::filesystem::path root = LMEFORM_SOURCE_DIR;
    CompileOptions opt;
    opt.include_dirs = {root / "forms", root / "tests" / "compiler" / "data" / "include"};
    return opt;
  }();
  return o;
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const std::string text(reinterpret_cast<const char*>(data), size);
  if (names_a_directory(text)) return 0;
  try {
    // No file name: the module is named by the text's `form NAME` line (the seeds have one), and
    // includes are looked up in the include directories (after the working directory).
    const CompiledForm form = compile_source(text, {}, options());
    const GeneratedModule generated = generate(form, "fuzz.form");
    if (generated.header.empty() || generated.json.empty()) __builtin_trap();
  } catch (const CompileError&) {
  }
  return 0;
}
