// Small helpers shared by the benchmarks: command line (--quick, --out DIR), a wall clock and a
// JSON writer for flat records (arrays of objects with number / string values).
#pragma once

#include <chrono>
#include <ctime>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <stdexcept>
#include <string>
#include <string_view>
#include <utility>
#include <variant>
#include <vector>

namespace lmeform::bench {

/// The benchmark command line: `--quick` and `--out DIR` (default "."). Both are removed from
/// argv, so what remains can go to PETSc (e.g. -ksp_type preonly -pc_type lu).
struct BenchOptions {
  bool quick = false;
  std::filesystem::path out = ".";
  std::vector<std::string> unknown;  ///< other "--" arguments, reported by the caller
};

inline BenchOptions parse_bench_options(int& argc, char** argv) {
  BenchOptions o;
  int kept = 1;
  for (int i = 1; i < argc; ++i) {
    const std::string_view arg = argv[i];
    if (arg == "--quick") {
      o.quick = true;
    } else if (arg == "--out" && i + 1 < argc) {
      o.out = argv[++i];
    } else if (arg.starts_with("--out=")) {
      o.out = std::string(arg.substr(6));
    } else {
      if (arg.starts_with("--")) o.unknown.emplace_back(arg);
      argv[kept++] = argv[i];
    }
  }
  argc = kept;
  argv[argc] = nullptr;
  return o;
}

/// Seconds since construction (steady clock).
class Stopwatch {
 public:
  Stopwatch() : start_(std::chrono::steady_clock::now()) {}
  void restart() { start_ = std::chrono::steady_clock::now(); }
  [[nodiscard]] double seconds() const {
    return std::chrono::duration<double>(std::chrono::steady_clock::now() - start_).count();
  }

 private:
  std::chrono::steady_clock::time_point start_;
};

/// CPU seconds of the calling thread since construction: robust against other processes sharing
/// the cores, where wall-clock times stretch with the load.
class CpuStopwatch {
 public:
  CpuStopwatch() : start_(now()) {}
  void restart() { start_ = now(); }
  [[nodiscard]] double seconds() const { return now() - start_; }

 private:
  static double now() {
    timespec ts{};
    clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
    return static_cast<double>(ts.tv_sec) + 1e-9 * static_cast<double>(ts.tv_nsec);
  }
  double start_;
};

/// One flat JSON object; keys keep their insertion order.
class JsonRecord {
 public:
  using Value = std::variant<double, long long, bool, std::string>;

  JsonRecord& set(std::string key, double v) { return put(std::move(key), v); }
  JsonRecord& set(std::string key, int v) { return put(std::move(key), static_cast<long long>(v)); }
  JsonRecord& set(std::string key, long long v) { return put(std::move(key), v); }
  JsonRecord& set(std::string key, std::size_t v) { return put(std::move(key), static_cast<long long>(v)); }
  JsonRecord& set(std::string key, bool v) { return put(std::move(key), v); }
  JsonRecord& set(std::string key, const char* v) { return put(std::move(key), std::string(v)); }
  JsonRecord& set(std::string key, std::string v) { return put(std::move(key), std::move(v)); }

  [[nodiscard]] std::string str(int indent = 2) const {
    std::ostringstream os;
    const std::string pad(static_cast<std::size_t>(indent), ' ');
    os << "{";
    for (std::size_t i = 0; i < fields_.size(); ++i) {
      os << (i ? ",\n" : "\n") << pad << "  " << quote(fields_[i].first) << ": " << format(fields_[i].second);
    }
    os << "\n" << pad << "}";
    return os.str();
  }

  static std::string quote(std::string_view s) {
    std::string q = "\"";
    for (const char c : s) {
      switch (c) {
        case '"': q += "\\\""; break;
        case '\\': q += "\\\\"; break;
        case '\n': q += "\\n"; break;
        case '\t': q += "\\t"; break;
        default:
          if (static_cast<unsigned char>(c) < 0x20) {
            char buf[8];
            std::snprintf(buf, sizeof buf, "\\u%04x", static_cast<unsigned>(c));
            q += buf;
          } else {
            q += c;
          }
      }
    }
    return q + "\"";
  }

 private:
  JsonRecord& put(std::string key, Value v) {
    fields_.emplace_back(std::move(key), std::move(v));
    return *this;
  }
  static std::string format(const Value& v) {
    if (const auto* d = std::get_if<double>(&v)) {
      if (!std::isfinite(*d)) return "null";
      char buf[32];
      std::snprintf(buf, sizeof buf, "%.6g", *d);
      return buf;
    }
    if (const auto* i = std::get_if<long long>(&v)) return std::to_string(*i);
    if (const auto* b = std::get_if<bool>(&v)) return *b ? "true" : "false";
    return quote(std::get<std::string>(v));
  }

  std::vector<std::pair<std::string, Value>> fields_;
};

/// Writes {"benchmark": name, "quick": ..., <meta fields>, "records": [...]} to path.
inline void write_json(const std::filesystem::path& path, std::string_view name, bool quick, const JsonRecord& meta,
                       const std::vector<JsonRecord>& records) {
  if (path.has_parent_path()) std::filesystem::create_directories(path.parent_path());
  std::ofstream out(path);
  if (!out) throw std::runtime_error("cannot write " + path.string());
  out << "{\n  \"benchmark\": " << JsonRecord::quote(name) << ",\n  \"quick\": " << (quick ? "true" : "false")
      << ",\n  \"meta\": " << meta.str(2) << ",\n  \"records\": [";
  for (std::size_t i = 0; i < records.size(); ++i) out << (i ? ",\n    " : "\n    ") << records[i].str(4);
  out << "\n  ]\n}\n";
  if (!out) throw std::runtime_error("error writing " + path.string());
}

/// Writes one flat object (a single-figure benchmark such as a roofline).
inline void write_json_object(const std::filesystem::path& path, const JsonRecord& record) {
  if (path.has_parent_path()) std::filesystem::create_directories(path.parent_path());
  std::ofstream out(path);
  if (!out) throw std::runtime_error("cannot write " + path.string());
  out << record.str(0) << "\n";
  if (!out) throw std::runtime_error("error writing " + path.string());
}

}  // namespace lmeform::bench
