#include "lmeform/compiler/source.hpp"

#include <algorithm>

namespace lmeform::compiler {

int SourceSet::add(std::filesystem::path path, std::string text) {
  std::vector<std::size_t> line_starts{0};
  for (std::size_t i = 0; i < text.size(); ++i)
    if (text[i] == '\n') line_starts.push_back(i + 1);
  files_.push_back(SourceFile{std::move(path), std::move(text), std::move(line_starts)});
  return static_cast<int>(files_.size()) - 1;
}

std::pair<int, int> SourceSet::line_col(const Loc& loc) const {
  if (loc.file < 0) return {0, 0};
  const SourceFile& f = file(loc.file);
  const std::size_t at = std::min(loc.offset, f.text.size());
  // The last line starting at or before `at`.
  const auto next_line = std::upper_bound(f.line_starts.begin(), f.line_starts.end(), at);
  const std::size_t line_start = *(next_line - 1);
  return {static_cast<int>(next_line - f.line_starts.begin()), static_cast<int>(at - line_start) + 1};
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

namespace {

bool is_utf8_continuation(char c) { return (static_cast<unsigned char>(c) & 0xC0u) == 0x80u; }

}  // namespace

std::string format_diagnostic(const SourceSet& sources, const Loc& loc, const std::string& message) {
  std::string out = sources.where(loc) + ": error: " + message + "\n";
  if (loc.file >= 0) {
    std::string line = sources.line_text(loc);
    std::size_t caret = std::min(static_cast<std::size_t>(sources.line_col(loc).second - 1), line.size());
    // A very long line (a generated sum of thousands of terms) is shown as a window around the
    // caret, so that the message stays readable.
    constexpr std::size_t kWindow = 160;
    if (line.size() > kWindow) {
      // Each end moves over at most the 3 continuation bytes of one UTF-8 character, so as not to
      // cut it: a longer run (invalid UTF-8 in a comment) must not push the caret out of the window.
      std::size_t first = caret > kWindow / 2 ? caret - kWindow / 2 : 0;
      for (int k = 0; k < 3 && first > 0 && is_utf8_continuation(line[first]); ++k) --first;
      std::size_t last = std::min(line.size(), first + kWindow);
      for (int k = 0; k < 3 && last < line.size() && is_utf8_continuation(line[last]); ++k) ++last;
      const std::string head = first > 0 ? "..." : "", tail = last < line.size() ? "..." : "";
      line = head + line.substr(first, last - first) + tail;
      caret = caret - first + head.size();
    }
    out += line + "\n";
    // One pad character per displayed character: tabs are kept, UTF-8 continuation bytes (in a
    // comment or string before the caret) take no column of their own.
    std::string pad;
    for (std::size_t i = 0; i < caret; ++i) {
      if (is_utf8_continuation(line[i])) continue;
      pad += line[i] == '\t' ? '\t' : ' ';
    }
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
