// Strict reading of scene tables, shared by the scene reader and the models that own extension
// tables (e.g. [vesicle]): every key known, typed and range-checked, and every message
// "FILE:LINE: key 'table.key' <what is wrong>", with a did-you-mean for unknown keys.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <initializer_list>
#include <limits>
#include <optional>
#include <sstream>
#include <string>
#include <string_view>
#include <vector>

#include <toml++/toml.h>

#include "lmeform/scene.hpp"

namespace lmeform {

/// The largest magnitude of a number in a scene: squares and products of larger values overflow
/// double precision in an assembly or a factorization (a Dirichlet value of 1e308 gave NaN pivots).
inline constexpr double kLargestSceneNumber = 1e100;
/// The smallest relative tolerance a scene may ask for: about 50 machine epsilons.
inline constexpr double kSmallestRelativeTolerance = 1e-14;
/// The most nodes a node set may have: node indices are 32-bit integers.
inline constexpr double kLargestNodeCount = 2147483647.0;
/// The most intervals per axis of a uniform grid from a spacing (uniform_grid refuses more).
inline constexpr double kLargestGridIntervals = 1e7;

namespace scene_detail {

inline std::string format_number(double v) {
  std::ostringstream s;
  s.precision(10);
  s << v;
  return s.str();
}

inline std::size_t edit_distance(std::string_view a, std::string_view b) {
  std::vector<std::size_t> row(b.size() + 1);
  for (std::size_t j = 0; j <= b.size(); ++j) row[j] = j;
  for (std::size_t i = 1; i <= a.size(); ++i) {
    std::size_t diag = row[0];
    row[0] = i;
    for (std::size_t j = 1; j <= b.size(); ++j) {
      const std::size_t up = row[j];
      row[j] = std::min({row[j] + 1, row[j - 1] + 1, diag + (a[i - 1] == b[j - 1] ? 0 : 1)});
      diag = up;
    }
  }
  return row[b.size()];
}

/// The closest candidate when it is close enough to be a likely typo; empty otherwise (closest_name).
inline std::string closest(std::string_view word, std::initializer_list<std::string_view> candidates) {
  const std::vector<std::string> names(candidates.begin(), candidates.end());
  return closest_name(word, names);
}

/// Candidates one of whose '_'-separated words is close to `word` ("tolerence": every *_tolerance).
inline std::vector<std::string_view> partial_matches(std::string_view word,
                                              std::initializer_list<std::string_view> candidates) {
  std::vector<std::string_view> out;
  for (auto c : candidates) {
    std::size_t start = 0;
    while (start <= c.size()) {
      const std::size_t end = std::min(c.find('_', start), c.size());
      const std::string_view part = c.substr(start, end - start);
      const std::size_t limit = std::max<std::size_t>(1, std::min(word.size(), part.size()) / 4);
      if (part.size() >= 3 && edit_distance(word, part) <= limit) {
        out.push_back(c);
        break;
      }
      start = end + 1;
    }
  }
  return out;
}

/// The entries of a table in the order of the file (toml++ keeps tables sorted by key; the order
/// of constraints and fields is the user's).
inline std::vector<std::pair<std::string, const toml::node*>> in_file_order(const toml::table& table) {
  std::vector<std::pair<std::string, const toml::node*>> out;
  for (const auto& [key, node] : table) out.emplace_back(std::string(key.str()), &node);
  std::stable_sort(out.begin(), out.end(), [](const auto& a, const auto& b) {
    const auto& sa = a.second->source().begin;
    const auto& sb = b.second->source().begin;
    return sa.line != sb.line ? sa.line < sb.line : sa.column < sb.column;
  });
  return out;
}

inline std::string join(std::initializer_list<std::string_view> items) {
  std::string s;
  for (auto it : items) {
    if (!s.empty()) s += ", ";
    s += "'";
    s += it;
    s += "'";
  }
  return s;
}

inline const char* type_name(toml::node_type t) {
  switch (t) {
    case toml::node_type::table: return "a table";
    case toml::node_type::array: return "an array";
    case toml::node_type::string: return "a string";
    case toml::node_type::integer: return "an integer";
    case toml::node_type::floating_point: return "a floating-point number";
    case toml::node_type::boolean: return "a boolean";
    case toml::node_type::date: return "a date";
    case toml::node_type::time: return "a time";
    case toml::node_type::date_time: return "a date-time";
    case toml::node_type::none: break;
  }
  return "nothing";
}

struct Context {
  std::string file;
};


}  // namespace scene_detail

/// The parsed scene file, kept for the models that read their extension tables.
struct SceneDocument {
  scene_detail::Context context;
  toml::table root;
};

namespace scene_detail {

[[noreturn]] inline void fail(const Context& ctx, const toml::node* at, const std::string& message) {
  std::string where = ctx.file;
  if (at != nullptr && at->source().begin.line > 0) where += ":" + std::to_string(at->source().begin.line);
  throw SceneError(where + ": " + message);
}

/// A table of the scene with its key path; construction refuses unknown keys.
class SceneTable {
 public:
  SceneTable(const Context& ctx, const toml::table& table, std::string path,
          std::initializer_list<std::string_view> allowed)
      : ctx_(ctx), table_(table), path_(std::move(path)) {
    for (const auto& [key, node] : table_) {
      const std::string_view k = key.str();
      if (std::find(allowed.begin(), allowed.end(), k) != allowed.end()) continue;
      std::string msg = "unknown key '" + key_path(k) + "'";
      if (path_.empty()) msg = "unknown table [" + std::string(k) + "]";
      const std::string guess = closest(k, allowed);
      const std::vector<std::string_view> partial = partial_matches(k, allowed);
      if (!guess.empty()) {
        msg += "; did you mean '" + guess + "'?";
      } else if (!partial.empty()) {
        msg += partial.size() == 1 ? "; did you mean " : "; did you mean one of ";
        for (std::size_t i = 0; i < partial.size(); ++i)
          msg += (i == 0 ? "'" : ", '") + std::string(partial[i]) + "'";
        msg += "?";
      } else
        msg += "; the keys of " + (path_.empty() ? std::string("a scene") : "[" + path_ + "]") + " are " +
               join(allowed);
      fail(ctx_, &node, msg);
    }
  }

  /// A table whose keys are names chosen by the user ([constants], [initial], ...): not checked here.
  struct AnyKeys {};
  SceneTable(const Context& ctx, const toml::table& table, std::string path, AnyKeys)
      : ctx_(ctx), table_(table), path_(std::move(path)) {}

  [[nodiscard]] const Context& context() const { return ctx_; }
  [[nodiscard]] const toml::table& entries() const { return table_; }
  /// "FILE:LINE: key 'path.key'", the prefix of a message about `key`.
  [[nodiscard]] std::string where(std::string_view key) const {
    std::string w = ctx_.file;
    const toml::node* n = at(key);
    if (n != nullptr && n->source().begin.line > 0) w += ":" + std::to_string(n->source().begin.line);
    return w + ": key '" + key_path(key) + "'";
  }
  /// A sub-table with user-chosen keys.
  [[nodiscard]] std::optional<SceneTable> optional_any_table(std::string_view key) const {
    const toml::node* n = node(key);
    if (n == nullptr) return std::nullopt;
    const auto* t = n->as_table();
    if (t == nullptr) {
      if (path_.empty())
        fail(ctx_, n, "'" + std::string(key) + "' must be a table ([" + std::string(key) + "]), found " + type_name(n->type()));
      wrong_type(key, *n, "a table");
    }
    return SceneTable(ctx_, *t, key_path(key), AnyKeys{});
  }
  [[nodiscard]] const std::string& path() const { return path_; }
  [[nodiscard]] std::string key_path(std::string_view key) const {
    return path_.empty() ? std::string(key) : path_ + "." + std::string(key);
  }
  [[nodiscard]] bool has(std::string_view key) const { return table_.get(key) != nullptr; }
  [[nodiscard]] const toml::node* node(std::string_view key) const { return table_.get(key); }
  /// The node to point at for a message about `key`: the key's value, else this table.
  [[nodiscard]] const toml::node* at(std::string_view key) const {
    const toml::node* n = table_.get(key);
    return n != nullptr ? n : &table_;
  }

  [[noreturn]] void fail_key(std::string_view key, const std::string& reason) const {
    fail(ctx_, at(key), "key '" + key_path(key) + "' " + reason);
  }

  const toml::node& require(std::string_view key) const {
    const toml::node* n = table_.get(key);
    if (n == nullptr) {
      if (path_.empty()) fail(ctx_, &table_, "missing table [" + std::string(key) + "]");
      fail(ctx_, &table_, "missing key '" + key_path(key) + "' in [" + path_ + "]");
    }
    return *n;
  }

  void wrong_type(std::string_view key, const toml::node& n, const char* expected) const {
    fail(ctx_, &n, "key '" + key_path(key) + "' must be " + expected + ", found " + type_name(n.type()));
  }

  double number_of(std::string_view key, const toml::node& n) const {
    double v = 0;
    if (const auto* f = n.as_floating_point()) {
      v = f->get();
    } else if (const auto* i = n.as_integer()) {
      v = static_cast<double>(i->get());
    } else {
      wrong_type(key, n, "a number");
    }
    if (!std::isfinite(v)) fail(ctx_, &n, "key '" + key_path(key) + "' must be finite, got " + format_number(v));
    if (std::abs(v) > kLargestSceneNumber)
      fail(ctx_, &n, "key '" + key_path(key) + "' = " + format_number(v) + " is too large: scene numbers are at most " +
                         format_number(kLargestSceneNumber) + " in magnitude (products and squares of larger ones overflow a solve)");
    return v;
  }

  [[nodiscard]] double number(std::string_view key) const { return number_of(key, require(key)); }
  [[nodiscard]] double number(std::string_view key, double fallback) const {
    const toml::node* n = node(key);
    return n != nullptr ? number_of(key, *n) : fallback;
  }
  [[nodiscard]] std::optional<double> optional_number(std::string_view key) const {
    const toml::node* n = node(key);
    if (n == nullptr) return std::nullopt;
    return number_of(key, *n);
  }

  [[nodiscard]] int integer_of(std::string_view key, const toml::node& n) const {
    const auto* i = n.as_integer();
    if (i == nullptr) wrong_type(key, n, "an integer");
    const std::int64_t v = i->get();
    if (v < std::numeric_limits<int>::min() || v > std::numeric_limits<int>::max())
      fail(ctx_, &n, "key '" + key_path(key) + "' is out of range: " + std::to_string(v));
    return static_cast<int>(v);
  }
  [[nodiscard]] int integer(std::string_view key, int fallback) const {
    const toml::node* n = node(key);
    return n != nullptr ? integer_of(key, *n) : fallback;
  }

  [[nodiscard]] bool boolean(std::string_view key, bool fallback) const {
    const toml::node* n = node(key);
    if (n == nullptr) return fallback;
    const auto* b = n->as_boolean();
    if (b == nullptr) wrong_type(key, *n, "a boolean (true or false)");
    return b->get();
  }

  [[nodiscard]] std::string string_of(std::string_view key, const toml::node& n) const {
    const auto* s = n.as_string();
    if (s == nullptr) wrong_type(key, n, "a string");
    if (s->get().empty()) fail(ctx_, &n, "key '" + key_path(key) + "' must not be empty");
    return s->get();
  }
  [[nodiscard]] std::string string(std::string_view key) const { return string_of(key, require(key)); }
  [[nodiscard]] std::optional<std::string> optional_string(std::string_view key) const {
    const toml::node* n = node(key);
    if (n == nullptr) return std::nullopt;
    return string_of(key, *n);
  }

  /// A string that must be one of `choices`.
  [[nodiscard]] std::string choice_of(std::string_view key, const std::string& value,
                                      std::initializer_list<std::string_view> choices) const {
    if (std::find(choices.begin(), choices.end(), value) != choices.end()) return value;
    std::string msg = "must be one of " + join(choices) + ", got '" + value + "'";
    const std::string guess = closest(value, choices);
    if (!guess.empty()) msg += "; did you mean '" + guess + "'?";
    fail_key(key, msg);
  }

  /// An array of `count` numbers (count = 0: 1, 2 or 3 numbers).
  [[nodiscard]] std::vector<double> numbers(std::string_view key, int count) const {
    const toml::node& n = require(key);
    const auto* a = n.as_array();
    const std::string expected = count > 0 ? "an array of " + std::to_string(count) + " numbers"
                                           : std::string("an array of 1, 2 or 3 numbers");
    if (a == nullptr) wrong_type(key, n, expected.c_str());
    const auto size = static_cast<int>(a->size());
    if ((count > 0 && size != count) || (count == 0 && (size < 1 || size > 3)))
      fail(ctx_, &n, "key '" + key_path(key) + "' must be " + expected + ", found " + std::to_string(size) +
                         (size == 1 ? " entry" : " entries"));
    std::vector<double> v;
    for (std::size_t i = 0; i < a->size(); ++i)
      v.push_back(number_of(std::string(key) + "[" + std::to_string(i) + "]", (*a)[i]));
    return v;
  }

  [[nodiscard]] std::vector<int> integers(std::string_view key, int count) const {
    const toml::node& n = require(key);
    const auto* a = n.as_array();
    const std::string expected = "an array of " + std::to_string(count) + " integers";
    if (a == nullptr) wrong_type(key, n, expected.c_str());
    if (static_cast<int>(a->size()) != count)
      fail(ctx_, &n, "key '" + key_path(key) + "' must be " + expected + ", found " + std::to_string(a->size()) +
                         (a->size() == 1 ? " entry" : " entries"));
    std::vector<int> v;
    for (std::size_t i = 0; i < a->size(); ++i)
      v.push_back(integer_of(std::string(key) + "[" + std::to_string(i) + "]", (*a)[i]));
    return v;
  }

  [[nodiscard]] SceneTable table_of(std::string_view key, const toml::node& n,
                                 std::initializer_list<std::string_view> allowed) const {
    const auto* t = n.as_table();
    if (t == nullptr) {
      if (path_.empty())
        fail(ctx_, &n, "'" + std::string(key) + "' must be a table ([" + std::string(key) + "]), found " +
                           type_name(n.type()));
      wrong_type(key, n, "a table");
    }
    return SceneTable(ctx_, *t, key_path(key), allowed);
  }
  [[nodiscard]] SceneTable table(std::string_view key, std::initializer_list<std::string_view> allowed) const {
    return table_of(key, require(key), allowed);
  }
  [[nodiscard]] std::optional<SceneTable> optional_table(std::string_view key,
                                                      std::initializer_list<std::string_view> allowed) const {
    const toml::node* n = node(key);
    if (n == nullptr) return std::nullopt;
    return table_of(key, *n, allowed);
  }

  // Range checks: the value is returned for chaining.
  double positive(std::string_view key, double v) const {
    if (!(v > 0)) fail_key(key, "must be positive, got " + format_number(v));
    return v;
  }
  /// A relative tolerance: positive, at least kSmallestRelativeTolerance (below it the rounding
  /// of the residual itself decides convergence, and a solve runs until its iteration limit).
  double relative_tolerance(std::string_view key, double v) const {
    positive(key, v);
    if (v < kSmallestRelativeTolerance)
      fail_key(key, "= " + format_number(v) + " is below what double precision can reach: give at least " +
                        format_number(kSmallestRelativeTolerance));
    return v;
  }
  double non_negative(std::string_view key, double v) const {
    if (!(v >= 0)) fail_key(key, "must be non-negative, got " + format_number(v));
    return v;
  }
  int at_least(std::string_view key, int v, int lo) const {
    if (v < lo) fail_key(key, "must be at least " + std::to_string(lo) + ", got " + std::to_string(v));
    return v;
  }

 private:
  const Context& ctx_;
  const toml::table& table_;
  std::string path_;
};

/// A number or an expression string (of x and the constants).
inline SceneValue value_of(const SceneTable& t, std::string_view key, const toml::node& n) {
  SceneValue v;
  v.where = t.where(key);
  if (n.is_string()) {
    v.value = t.string_of(key, n);
  } else if (n.is_number()) {
    v.value = t.number_of(key, n);
  } else {
    t.wrong_type(key, n, "a number or an expression string (e.g. \"sin(pi*x[0])\")");
  }
  return v;
}

}  // namespace scene_detail

using scene_detail::SceneTable;

/// The extension table `name` of a scene (nullopt when absent), read with the scene's strictness.
inline std::optional<SceneTable> extension_table(const Scene& scene, std::string_view name,
                                                 std::initializer_list<std::string_view> allowed) {
  if (!scene.document) return std::nullopt;
  const toml::node* n = scene.document->root.get(name);
  if (n == nullptr) return std::nullopt;
  const auto* t = n->as_table();
  if (t == nullptr)
    scene_detail::fail(scene.document->context, n,
                       "'" + std::string(name) + "' must be a table ([" + std::string(name) + "]), found " +
                           scene_detail::type_name(n->type()));
  return SceneTable(scene.document->context, *t, std::string(name), allowed);
}

}  // namespace lmeform
