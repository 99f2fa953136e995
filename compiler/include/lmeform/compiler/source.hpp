// Source files, locations and diagnostics of the form compiler.
#pragma once

#include <cstddef>
#include <filesystem>
#include <memory>
#include <stdexcept>
#include <string>
#include <vector>

namespace lmeform::compiler {

/// A position in one of the files of a compilation (index into SourceSet::files).
struct Loc {
  int file = -1;
  std::size_t offset = 0;
};

struct SourceFile {
  std::filesystem::path path;   ///< as given / resolved (used in messages)
  std::string text;
  std::vector<std::size_t> line_starts;  ///< offset of the first character of each line
};

/// All files of one compilation (the main form and its includes), so that a Loc can be printed.
class SourceSet {
 public:
  int add(std::filesystem::path path, std::string text);
  const SourceFile& file(int index) const { return files_.at(static_cast<std::size_t>(index)); }
  int size() const { return static_cast<int>(files_.size()); }
  /// 1-based line and column of a location (a binary search: the code generator asks once per node).
  std::pair<int, int> line_col(const Loc& loc) const;
  /// The text of the line holding loc (without newline).
  std::string line_text(const Loc& loc) const;
  /// "file:line:col"
  std::string where(const Loc& loc) const;

 private:
  std::vector<SourceFile> files_;
};

/// A compile error already formatted as `file:line:col: error: ...` + source line + caret.
class CompileError : public std::runtime_error {
 public:
  explicit CompileError(const std::string& formatted) : std::runtime_error(formatted) {}
};

/// Formats a diagnostic pointing at loc.
std::string format_diagnostic(const SourceSet& sources, const Loc& loc, const std::string& message);

/// Throws a CompileError pointing at loc.
[[noreturn]] void fail_at(const SourceSet& sources, const Loc& loc, const std::string& message);

/// Edit distance, used for did-you-mean suggestions.
std::size_t edit_distance(const std::string& a, const std::string& b);
/// The closest candidate to `name` (empty if none is close enough).
std::string closest_name(const std::string& name, const std::vector<std::string>& candidates);

}  // namespace lmeform::compiler
