#include "lmeform/compiler/source.hpp"

#include <algorithm>

namespace lmeform::compiler {

int SourceSet::add(std::filesystem::path path, std::string text) {
  files_.push_back(SourceFile{std::move(path), std::move(text)});
  return static_cast<int>(files_.size()) - 1;
}

std::pair<int, int> SourceSet::line_col(const Loc& loc) const {
  if (loc.file < 0) return {0, 0};
  const std::string& t = file(loc.file).text;
  const std::size_t end = std::min(loc.offset, t.size());
  int line = 1;
  std::size_t line_start = 0;
  for (std::size_t i = 0; i < end; ++i) {
    if (t[i] == '\n') { ++line; line_start = i + 1; }
  }
  return {line, static_cast<int>(end - line_start) + 1};
}

std::string SourceSet::line_text(const Loc& loc) const {
  if (loc.file < 0) return {};
  const std::string& t = file(loc.file).text;
  const std::size_t at = std::min(loc.offset, t.size());
  std::size_t b = at;
  while (b > 0 && t[b - 1] != '\n') --b;
  std::size_t e = t.find('\n', at);
  if (e == std::string::npos) e = t.size();
  return t.substr(b, e - b);
}

std::string SourceSet::where(const Loc& loc) const {
  if (loc.file < 0) return "<builtin>";
  auto [line, col] = line_col(loc);
  return file(loc.file).path.string() + ":" + std::to_string(line) + ":" + std::to_string(col);
}

std::string format_diagnostic(const SourceSet& sources, const Loc& loc, const std::string& message) {
  std::string out = sources.where(loc) + ": error: " + message + "\n";
  if (loc.file >= 0) {
    const std::string line = sources.line_text(loc);
    out += line + "\n";
    const int col = sources.line_col(loc).second;
    std::string pad;
    for (int i = 0; i + 1 < col && i < static_cast<int>(line.size()); ++i) pad += (line[static_cast<std::size_t>(i)] == '\t' ? '\t' : ' ');
    out += pad + "^\n";
  }
  return out;
}

void fail_at(const SourceSet& sources, const Loc& loc, const std::string& message) {
  throw CompileError(format_diagnostic(sources, loc, message));
}

std::size_t edit_distance(const std::string& a, const std::string& b) {
  std::vector<std::size_t> prev(b.size() + 1), cur(b.size() + 1);
  for (std::size_t j = 0; j <= b.size(); ++j) prev[j] = j;
  for (std::size_t i = 1; i <= a.size(); ++i) {
    cur[0] = i;
    for (std::size_t j = 1; j <= b.size(); ++j) {
      cur[j] = std::min({prev[j] + 1, cur[j - 1] + 1, prev[j - 1] + (a[i - 1] == b[j - 1] ? 0u : 1u)});
    }
    std::swap(prev, cur);
  }
  return prev[b.size()];
}

std::string closest_name(const std::string& name, const std::vector<std::string>& candidates) {
  std::string best;
  std::size_t best_d = std::max<std::size_t>(1, name.size() / 3) + 1;
  for (const auto& c : candidates) {
    const std::size_t d = edit_distance(name, c);
    if (d < best_d) { best_d = d; best = c; }
  }
  return best;
}

}  // namespace lmeform::compiler
