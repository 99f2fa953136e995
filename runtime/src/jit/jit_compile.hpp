// Run-time compilation of a .form file into a cached shared object (form_registry.hpp has the
// contract). Internal to lmeform_jit.
#pragma once

#include <filesystem>
#include <string>
#include <vector>

#include "lmeform/form_registry.hpp"
#include "lmeform/process.hpp"

namespace lmeform::jit {

/// The lmeformc this process uses (FormLoadOptions::lmeformc, $LMEFORM_LMEFORMC, next to the
/// running executable, the one of this build), or throws FormLoadError naming where it looked.
std::filesystem::path find_lmeformc(const FormLoadOptions& options);

/// What a cache entry is and where it lives.
struct CacheEntry {
  std::string module;                  ///< from the form's file name (the compiler enforces form NAME == file name)
  std::string key;                     ///< 16 hex digits
  std::filesystem::path library;       ///< <cache>/<module>-<key>.so
  std::filesystem::path manifest;      ///< <cache>/<module>-<key>.json
  std::string key_material;            ///< what the key was computed from (kept in the manifest)
  std::vector<std::filesystem::path> dependencies;  ///< the form and its includes
};

/// The cache key of `form`: its text and every included file (listed by `lmeformc --dependencies`),
/// the lmeformc version and binary, the kernel contract, the C++ compiler and its flags.
CacheEntry describe_entry(const std::filesystem::path& form, const std::filesystem::path& lmeformc,
                          const FormLoadOptions& options);

/// Makes sure the entry exists: compiles it (under a lock, in a private directory, renamed into
/// place) unless present. Returns true when it was compiled now, and the two stage times.
struct BuildTimes {
  bool compiled = false;
  double generate_seconds = 0, compile_seconds = 0;
};
BuildTimes ensure_entry(const CacheEntry& entry, const std::filesystem::path& form, const std::filesystem::path& lmeformc,
                        const FormLoadOptions& options);

/// dlopens the entry's library and returns its module table (checked: contract version, module
/// name). Throws FormLoadError for a stale or foreign entry.
const kernel::ModuleTable& open_entry(const CacheEntry& entry);

}  // namespace lmeform::jit
