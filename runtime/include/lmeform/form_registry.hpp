// Form modules by name or by path: the built-in model library (compiled when lmeform was built)
// and `.form` files compiled at run time (JIT) into a cached shared object.
//
// A JIT load runs `lmeformc` as a program (the runtime never links the parser), compiles the
// generated kernels with the compiler and flags recorded when lmeform was built, and loads the
// result with dlopen through the module's C entry point (kernel::kModuleEntrySymbol). Shared
// objects are cached in $LMEFORM_CACHE_DIR (default ~/.cache/lmeform) under a key that covers the
// form text and every included file, the lmeformc version, the kernel contract version, the C++
// compiler and its flags. Entries appear atomically (compiled in a private directory, renamed into
// place under a lock), so a concurrent run never sees half a library; under MPI one rank compiles
// and the others wait for it.
#pragma once

#include <mpi.h>

#include <cstdint>
#include <filesystem>
#include <iosfwd>
#include <stdexcept>
#include <string>
#include <string_view>
#include <vector>

#include "lmeform/kernel.hpp"

namespace lmeform {

/// Why a form could not be found, compiled or loaded. The message names the cause: lmeformc not
/// found, a form error (lmeformc's file:line:col message with its caret), a C++ compiler error
/// (with the kept generated file), a stale or foreign cache entry, an unknown module name.
class FormLoadError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

/// The keyword of an output kind as written in a form ("energy", "point", ...).
[[nodiscard]] const char* to_string(kernel::FunctionalKind kind) noexcept;

/// A loaded module: its functionals, and how it was obtained.
struct FormModule {
  std::string name;                      ///< the module name (`form NAME`)
  std::filesystem::path source;          ///< the .form file (built-ins: the file in forms/)
  bool builtin = false;
  std::vector<const kernel::FormKernels*> kernels;

  // JIT provenance (zero / empty for built-ins).
  bool cache_hit = false;
  std::filesystem::path library;         ///< the cached shared object
  std::string cache_key;
  double generate_seconds = 0;           ///< lmeformc
  double compile_seconds = 0;            ///< the C++ compiler
  double load_seconds = 0;               ///< the whole load (a cache hit: key + dlopen)

  /// Output names in declaration order (each once) and the declared dimensions (ascending).
  [[nodiscard]] std::vector<std::string> outputs() const;
  [[nodiscard]] std::vector<int> dimensions() const;
  /// The kernels of `output` in dimension `dim`, or nullptr.
  [[nodiscard]] const kernel::FormKernels* find(std::string_view output, int dim) const noexcept;
  /// As find(), but throws FormLoadError naming the module's outputs and dimensions.
  [[nodiscard]] const kernel::FormKernels& at(std::string_view output, int dim) const;
  /// Constant names used by any of the module's kernels (declaration order, each once).
  [[nodiscard]] std::vector<std::string> constants() const;
};

struct FormLoadOptions {
  /// Cache directory; empty: $LMEFORM_CACHE_DIR, else ~/.cache/lmeform.
  std::filesystem::path cache_dir;
  /// lmeformc executable; empty: $LMEFORM_LMEFORMC, else next to the running executable, else the
  /// one built with the runtime.
  std::filesystem::path lmeformc;
  /// Extra include directories for the form (-I); the built-in forms/ directory is always searched.
  std::vector<std::filesystem::path> include_dirs;
  /// Recompile even when the cache holds the entry.
  bool rebuild = false;
  /// Progress ("compiled ... in 3.2 s", "cache hit ... in 2 ms"); nullptr: silent.
  std::ostream* log = nullptr;
  /// Ranks that load together: rank 0 compiles, the others wait and then load the entry.
  MPI_Comm comm = MPI_COMM_SELF;
};

/// The built-in modules (compiled when lmeform was built), by name.
[[nodiscard]] std::vector<std::string> builtin_form_names();

/// A module by built-in name (`helfrich_axisymmetric`) or by the path of a `.form` file
/// (anything containing '/' or ending in `.form`; relative to the working directory). Loaded
/// once per process; later calls with the same name or canonical path return the same module.
/// Collective over options.comm for a JIT load.
[[nodiscard]] const FormModule& load_form(std::string_view name_or_path, const FormLoadOptions& options = {});

/// Compiles `form` (a path) into the cache without the process-wide memo: every call does the
/// full key computation and either a cache hit or a compile. For tests and `lmeform check`.
[[nodiscard]] FormModule compile_form(const std::filesystem::path& form, const FormLoadOptions& options = {});

/// FNV-1a (64 bits) of `bytes`, continuing from `state`: the cache keys of forms and of the forms
/// generated from scene expressions. A cache key, not a security boundary.
[[nodiscard]] std::uint64_t content_hash(std::string_view bytes, std::uint64_t state = 0xcbf29ce484222325ull) noexcept;

/// The cache directory that options (or the environment) select.
[[nodiscard]] std::filesystem::path form_cache_dir(const FormLoadOptions& options = {});

}  // namespace lmeform
