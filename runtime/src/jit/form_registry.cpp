#include "lmeform/form_registry.hpp"

#include <algorithm>
#include <chrono>
#include <cstdlib>
#include <map>
#include <memory>
#include <mutex>
#include <ostream>

#include <fmt/format.h>

#include "builtin_forms.hpp"
#include "jit_compile.hpp"
#include "lmeform/stopwatch.hpp"

namespace lmeform {

const char* to_string(kernel::FunctionalKind kind) noexcept {
  using kernel::FunctionalKind;
  switch (kind) {
    case FunctionalKind::Energy: return "energy";
    case FunctionalKind::Constraint: return "constraint";
    case FunctionalKind::Residual: return "residual";
    case FunctionalKind::Bilinear: return "bilinear";
    case FunctionalKind::Linear: return "linear";
    case FunctionalKind::Point: return "point";
  }
  return "?";
}

namespace fs = std::filesystem;

std::vector<std::string> FormModule::outputs() const {
  std::vector<std::string> names;
  for (const auto* k : kernels)
    if (std::find(names.begin(), names.end(), k->name) == names.end()) names.emplace_back(k->name);
  return names;
}

std::vector<int> FormModule::dimensions() const {
  std::vector<int> dims;
  for (const auto* k : kernels)
    if (std::find(dims.begin(), dims.end(), k->dim) == dims.end()) dims.push_back(k->dim);
  std::sort(dims.begin(), dims.end());
  return dims;
}

const kernel::FormKernels* FormModule::find(std::string_view output, int dim) const noexcept {
  for (const auto* k : kernels)
    if (k->dim == dim && output == k->name) return k;
  return nullptr;
}

const kernel::FormKernels& FormModule::at(std::string_view output, int dim) const {
  if (const auto* k = find(output, dim)) return *k;
  std::string outs, dims;
  for (const auto& o : outputs()) outs += (outs.empty() ? "" : ", ") + o;
  for (const int d : dimensions()) dims += (dims.empty() ? "" : ", ") + std::to_string(d);
  throw FormLoadError(fmt::format("form module '{}' ({}) has no output '{}' in dimension {} (outputs: {}; dimensions: {})",
                                  name, source.string(), output, dim, outs, dims));
}

std::vector<std::string> FormModule::constants() const {
  std::vector<std::string> names;
  for (const auto* k : kernels)
    for (int i = 0; i < k->n_constants; ++i)
      if (std::find(names.begin(), names.end(), k->constants[i]) == names.end()) names.emplace_back(k->constants[i]);
  return names;
}

std::vector<std::string> builtin_form_names() {
  std::vector<std::string> names;
  for (const auto& m : builtin::modules()) names.emplace_back(m.name);
  return names;
}

std::uint64_t content_hash(std::string_view bytes, std::uint64_t state) noexcept {
  for (const unsigned char c : bytes) {
    state ^= c;
    state *= 0x100000001b3ull;
  }
  return state;
}

fs::path form_cache_dir(const FormLoadOptions& options) {
  if (!options.cache_dir.empty()) return options.cache_dir;
  if (const char* env = std::getenv("LMEFORM_CACHE_DIR"); env != nullptr && *env != '\0') return env;
  if (const char* xdg = std::getenv("XDG_CACHE_HOME"); xdg != nullptr && *xdg != '\0') return fs::path(xdg) / "lmeform";
  if (const char* home = std::getenv("HOME"); home != nullptr && *home != '\0') return fs::path(home) / ".cache" / "lmeform";
  return fs::temp_directory_path() / "lmeform-cache";
}

namespace {

FormModule from_table(const kernel::ModuleTable& table) {
  FormModule m;
  m.name = table.module;
  m.kernels.assign(table.kernels, table.kernels + table.n_kernels);
  return m;
}

bool names_a_file(std::string_view s) {
  return s.find('/') != std::string_view::npos || (s.size() > 5 && s.substr(s.size() - 5) == ".form");
}

/// Every rank learns whether rank 0 succeeded, and rank 0's message if not.
void share_outcome(MPI_Comm comm, std::string& failure) {
  int size = static_cast<int>(failure.size());
  MPI_Bcast(&size, 1, MPI_INT, 0, comm);
  failure.resize(static_cast<std::size_t>(size));
  if (size > 0) MPI_Bcast(failure.data(), size, MPI_CHAR, 0, comm);
}

FormModule load_jit(const fs::path& form, const FormLoadOptions& options) {
  const Stopwatch clock;
  if (!fs::exists(form)) throw FormLoadError(fmt::format("{}: no such form file", form.string()));
  if (!fs::is_regular_file(form)) throw FormLoadError(fmt::format("{}: not a regular file", form.string()));
  int rank = 0;
  MPI_Comm_rank(options.comm, &rank);
  const fs::path lmeformc = jit::find_lmeformc(options);
  jit::CacheEntry entry;
  jit::BuildTimes times;
  std::string failure;
  if (rank == 0) {
    try {
      entry = jit::describe_entry(form, lmeformc, options);
      times = jit::ensure_entry(entry, form, lmeformc, options);
    } catch (const std::exception& e) {
      failure = e.what();
    }
  }
  share_outcome(options.comm, failure);
  if (!failure.empty()) throw FormLoadError(failure);
  if (rank != 0) entry = jit::describe_entry(form, lmeformc, options);

  const kernel::ModuleTable* table = nullptr;
  try {
    table = &jit::open_entry(entry);
  } catch (const FormLoadError& stale) {
    // A stale or foreign entry (another contract, a damaged file) is replaced, and the user told.
    if (options.log != nullptr && rank == 0) *options.log << "lmeform: " << stale.what() << "; rebuilding it\n";
    FormLoadOptions rebuild = options;
    rebuild.rebuild = true;
    if (rank == 0) {
      try {
        times = jit::ensure_entry(entry, form, lmeformc, rebuild);
      } catch (const std::exception& e) {
        failure = e.what();
      }
    }
    share_outcome(options.comm, failure);
    if (!failure.empty()) throw FormLoadError(failure);
    table = &jit::open_entry(entry);
  }
  FormModule m = from_table(*table);
  m.source = form;
  m.cache_hit = !times.compiled;
  m.library = entry.library;
  m.cache_key = entry.key;
  m.generate_seconds = times.generate_seconds;
  m.compile_seconds = times.compile_seconds;
  m.load_seconds = clock.seconds();
  if (options.log != nullptr && rank == 0) {
    if (m.cache_hit) {
      *options.log << fmt::format("form {}: cache hit ({}) in {:.0f} ms\n", form.string(), entry.library.string(),
                                  1e3 * m.load_seconds);
    } else {
      *options.log << fmt::format("form {}: compiled in {:.2f} s (lmeformc {:.2f} s, C++ {:.2f} s) into {}\n",
                                  form.string(), m.load_seconds, m.generate_seconds, m.compile_seconds,
                                  entry.library.string());
    }
  }
  return m;
}

}  // namespace

FormModule compile_form(const fs::path& form, const FormLoadOptions& options) { return load_jit(form, options); }

const FormModule& load_form(std::string_view name_or_path, const FormLoadOptions& options) {
  static std::mutex mutex;
  static std::map<std::string, std::unique_ptr<FormModule>, std::less<>> loaded;
  const std::lock_guard guard(mutex);
  if (!names_a_file(name_or_path)) {
    if (const auto it = loaded.find(name_or_path); it != loaded.end()) return *it->second;
    for (const auto& b : builtin::modules()) {
      if (name_or_path == b.name) {
        auto m = std::make_unique<FormModule>(from_table(*b.table()));
        m->builtin = true;
        m->source = b.source;
        return *loaded.emplace(std::string(name_or_path), std::move(m)).first->second;
      }
    }
    std::string names;
    for (const auto& n : builtin_form_names()) names += (names.empty() ? "" : ", ") + n;
    throw FormLoadError(fmt::format("'{}' is neither a built-in form module nor a .form file (built-in: {}; a file "
                                    "is named by a path containing '/' or ending in .form)",
                                    name_or_path, names));
  }
  std::error_code ec;
  const fs::path path(name_or_path);
  const fs::path canonical = fs::weakly_canonical(path, ec);
  const std::string key = ec ? path.string() : canonical.string();
  if (const auto it = loaded.find(key); it != loaded.end()) return *it->second;
  auto m = std::make_unique<FormModule>(load_jit(path, options));
  return *loaded.emplace(key, std::move(m)).first->second;
}

}  // namespace lmeform
