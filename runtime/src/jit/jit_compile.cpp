#include "jit_compile.hpp"

#include <dlfcn.h>
#include <fcntl.h>
#include <spawn.h>
#include <sys/file.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cstdint>
#include <cstdlib>
#include <fstream>
#include <mutex>
#include <random>
#include <sstream>

#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include "jit_config.hpp"
#include "lmeform/stopwatch.hpp"
#include "lmeform/output.hpp"

extern char** environ;

namespace lmeform::jit {

namespace fs = std::filesystem;

namespace {

std::string read_file(const fs::path& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) throw FormLoadError(fmt::format("cannot read {}", path.string()));
  std::ostringstream text;
  text << in.rdbuf();
  return std::move(text).str();
}

std::vector<std::string> split(std::string_view text, char separator) {
  std::vector<std::string> parts;
  std::size_t start = 0;
  while (start <= text.size()) {
    const std::size_t end = std::min(text.find(separator, start), text.size());
    if (end > start) parts.emplace_back(text.substr(start, end - start));
    start = end + 1;
  }
  return parts;
}

std::vector<std::string> compiler_flags() { return split(jit_config::flags, ' '); }

/// The C++ compiler of run-time compiles: $LMEFORM_CXX, else the one lmeform was built with.
std::string compiler() {
  if (const char* env = std::getenv("LMEFORM_CXX"); env != nullptr && *env != '\0') return env;
  return jit_config::cxx;
}

/// The last lines of a long message (a compiler's errors can run to pages).
std::string tail_lines(const std::string& text, std::size_t max_lines) {
  std::size_t pos = text.size(), lines = 0;
  while (pos > 0 && lines <= max_lines) {
    pos = text.rfind('\n', pos - 1);
    if (pos == std::string::npos) return text;
    ++lines;
  }
  return "...\n" + text.substr(pos + 1);
}

fs::path unique_sibling(const fs::path& dir, const std::string& stem) {
  std::random_device rd;
  return dir / fmt::format("{}.tmp.{}.{:x}", stem, ::getpid(), rd());
}

/// An exclusive advisory lock on a file, held for the object's lifetime.
class FileLock {
 public:
  explicit FileLock(const fs::path& path) : fd_(::open(path.c_str(), O_RDWR | O_CREAT | O_CLOEXEC, 0644)) {
    if (fd_ < 0) throw FormLoadError(fmt::format("cannot create the cache lock {}", path.string()));
    while (::flock(fd_, LOCK_EX) != 0) {
      if (errno != EINTR) throw FormLoadError(fmt::format("cannot lock {}", path.string()));
    }
  }
  ~FileLock() { ::close(fd_); }
  FileLock(const FileLock&) = delete;
  FileLock& operator=(const FileLock&) = delete;

 private:
  int fd_;
};

/// Size and modification time of an executable: a changed compiler or lmeformc changes the key.
std::string binary_stamp(const fs::path& program) {
  std::error_code ec;
  const fs::path resolved = fs::canonical(program, ec);
  if (ec) return "unresolved";
  const auto size = fs::file_size(resolved, ec);
  const auto time = fs::last_write_time(resolved, ec);
  if (ec) return "unreadable";
  return fmt::format("{} {} {}", resolved.string(), size, time.time_since_epoch().count());
}


}  // namespace

/// run_process with a program that cannot be started reported as a form that cannot be loaded.
ProcessResult run_tool(const std::vector<std::string>& argv) {
  try {
    return lmeform::run_process(argv);
  } catch (const std::runtime_error& e) {
    throw FormLoadError(e.what());
  }
}

fs::path find_lmeformc(const FormLoadOptions& options) {
  std::vector<fs::path> tried;
  auto usable = [&](const fs::path& p) {
    tried.push_back(p);
    return !p.empty() && ::access(p.c_str(), X_OK) == 0 && fs::is_regular_file(p);
  };
  if (!options.lmeformc.empty()) {
    if (usable(options.lmeformc)) return options.lmeformc;
    throw FormLoadError(fmt::format("lmeformc not found: {} is not an executable file", options.lmeformc.string()));
  }
  if (const char* env = std::getenv("LMEFORM_LMEFORMC"); env != nullptr && *env != '\0') {
    if (usable(env)) return env;
    throw FormLoadError(fmt::format("lmeformc not found: LMEFORM_LMEFORMC={} is not an executable file", env));
  }
  if (const fs::path dir = executable_directory(); !dir.empty() && usable(dir / "lmeformc")) return dir / "lmeformc";
  if (usable(jit_config::built_lmeformc)) return jit_config::built_lmeformc;
  std::string where;
  for (const auto& p : tried) where += "\n  " + p.string();
  throw FormLoadError("lmeformc not found (set LMEFORM_LMEFORMC to its path); looked at:" + where);
}

CacheEntry describe_entry(const fs::path& form, const fs::path& lmeformc, const FormLoadOptions& options) {
  CacheEntry e;
  e.module = form.stem().string();
  std::vector<std::string> argv{lmeformc.string(), form.string(), "--dependencies", "-I", jit_config::forms_dir};
  for (const auto& dir : options.include_dirs) {
    argv.emplace_back("-I");
    argv.push_back(dir.string());
  }
  const ProcessResult deps = run_tool(argv);
  if (deps.exit_code != 0) throw FormLoadError(deps.err.empty() ? "lmeformc --dependencies failed" : deps.err);
  const ProcessResult version = run_tool({lmeformc.string(), "--version"});
  std::ostringstream material;
  material << "contract " << kernel::kContractVersion << "\n"
           << "lmeformc " << (version.exit_code == 0 ? version.out : "unknown") << "lmeformc-binary "
           << binary_stamp(lmeformc) << "\n"
           << "cxx " << compiler() << " " << binary_stamp(compiler()) << "\nflags " << jit_config::flags << "\nincludes " << jit_config::include_dirs << "\n";
  std::uint64_t h = content_hash(material.str());
  for (const auto& line : split(deps.out, '\n')) {
    const fs::path dep(line);
    e.dependencies.push_back(dep);
    material << "file " << dep.string() << "\n";
    h = content_hash(dep.string(), h);
    h = content_hash(read_file(dep), h);
  }
  e.key = fmt::format("{:016x}", h);
  e.key_material = material.str();
  const fs::path dir = form_cache_dir(options);
  e.library = dir / fmt::format("{}-{}.so", e.module, e.key);
  e.manifest = dir / fmt::format("{}-{}.json", e.module, e.key);
  return e;
}

BuildTimes ensure_entry(const CacheEntry& entry, const fs::path& form, const fs::path& lmeformc,
                        const FormLoadOptions& options) {
  BuildTimes times;
  const fs::path dir = entry.library.parent_path();
  std::error_code ec;
  fs::create_directories(dir, ec);
  if (ec) throw FormLoadError(fmt::format("cannot create the form cache {}: {}", dir.string(), ec.message()));
  if (!options.rebuild && fs::exists(entry.library)) return times;
  // One compile per entry at a time; a process that waited finds the entry made by the other.
  const FileLock lock(dir / fmt::format("{}-{}.lock", entry.module, entry.key));
  if (!options.rebuild && fs::exists(entry.library)) return times;

  const fs::path work = unique_sibling(dir, entry.module);
  fs::create_directories(work);
  // Failures keep the generated code for the user to inspect; a success removes the directory.
  auto keep_failed = [&]() {
    const fs::path kept = dir / "failed" / fmt::format("{}-{}", entry.module, entry.key);
    std::error_code ignore;
    fs::remove_all(kept, ignore);
    fs::create_directories(kept.parent_path(), ignore);
    fs::rename(work, kept, ignore);
    return ignore ? work : kept;
  };

  Stopwatch clock;
  std::vector<std::string> gen{lmeformc.string(), form.string(), "-o", work.string(), "--no-json", "-I",
                               jit_config::forms_dir};
  for (const auto& inc : options.include_dirs) {
    gen.emplace_back("-I");
    gen.push_back(inc.string());
  }
  const ProcessResult generated = run_tool(gen);
  times.generate_seconds = clock.seconds();
  if (generated.exit_code != 0) {
    std::error_code ignore;
    fs::remove_all(work, ignore);
    // lmeformc's message already names file:line:col with the caret.
    throw FormLoadError(generated.err.empty() ? fmt::format("lmeformc failed on {}", form.string()) : generated.err);
  }
  const fs::path header = work / (entry.module + "_kernels.hpp");
  if (!fs::exists(header)) {
    const fs::path kept = keep_failed();
    throw FormLoadError(fmt::format("lmeformc did not write {} (the module name must equal the file name); output kept in {}",
                                    header.filename().string(), kept.string()));
  }
  const fs::path source = work / (entry.module + "_module.cpp");
  write_text_atomically(source, fmt::format("// The JIT entry point of module {}.\n#define LMEFORM_MODULE_ENTRY 1\n#include \"{}\"\n",
                                            entry.module, header.filename().string()));
  clock.restart();
  const fs::path built = work / "module.so";
  std::vector<std::string> cc{compiler()};
  for (auto& f : compiler_flags()) cc.push_back(std::move(f));
  for (const auto& inc : split(jit_config::include_dirs, '|')) cc.push_back("-I" + inc);
  cc.push_back(source.string());
  cc.emplace_back("-o");
  cc.push_back(built.string());
  const ProcessResult compiled = run_tool(cc);
  times.compile_seconds = clock.seconds();
  if (compiled.exit_code != 0) {
    const fs::path kept = keep_failed();
    std::string command;
    for (const auto& a : cc) command += (command.empty() ? "" : " ") + a;
    throw FormLoadError(fmt::format("the C++ compiler failed on the code generated from {} (kept in {}):\n{}\n{}",
                                    form.string(), kept.string(), command, tail_lines(compiled.err, 40)));
  }
  nlohmann::json manifest;
  manifest["module"] = entry.module;
  manifest["key"] = entry.key;
  manifest["source"] = fs::absolute(form).lexically_normal().string();
  manifest["contract_version"] = kernel::kContractVersion;
  manifest["key_material"] = entry.key_material;
  manifest["generate_seconds"] = times.generate_seconds;
  manifest["compile_seconds"] = times.compile_seconds;
  write_text_atomically(entry.manifest, manifest.dump(2) + "\n");
  // The rename publishes the library whole: a reader sees no entry or a complete one.
  fs::rename(built, entry.library);
  std::error_code ignore;
  fs::remove_all(work, ignore);
  times.compiled = true;
  return times;
}

const kernel::ModuleTable& open_entry(const CacheEntry& entry) {
  void* handle = ::dlopen(entry.library.c_str(), RTLD_NOW | RTLD_LOCAL);
  if (handle == nullptr) {
    const char* why = ::dlerror();
    throw FormLoadError(fmt::format("stale or foreign cache entry {}: it cannot be loaded ({})", entry.library.string(),
                                    why != nullptr ? why : "unknown reason"));
  }
  auto close = [&]() { ::dlclose(handle); };
  auto* entry_point = reinterpret_cast<kernel::ModuleEntry>(::dlsym(handle, kernel::kModuleEntrySymbol));
  if (entry_point == nullptr) {
    close();
    throw FormLoadError(fmt::format("stale or foreign cache entry {}: no symbol {}", entry.library.string(),
                                    kernel::kModuleEntrySymbol));
  }
  const kernel::ModuleTable* table = entry_point();
  if (table == nullptr || table->contract_version != kernel::kContractVersion) {
    const int version = table == nullptr ? -1 : table->contract_version;
    close();
    throw FormLoadError(fmt::format("stale or foreign cache entry {}: kernel contract version {}, this lmeform uses {}",
                                    entry.library.string(), version, kernel::kContractVersion));
  }
  if (entry.module != table->module) {
    const std::string found = table->module;
    close();
    throw FormLoadError(fmt::format("stale or foreign cache entry {}: it holds module '{}', expected '{}'",
                                    entry.library.string(), found, entry.module));
  }
  // The handle stays open for the life of the process: the kernels point into it.
  return *table;
}

}  // namespace lmeform::jit
