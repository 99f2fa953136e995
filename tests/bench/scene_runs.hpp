// Benchmarks that sweep a demo scene: the scene's text with keys replaced, written next to the
// results and run through the same driver as `lmeform run`.
#pragma once

#include <filesystem>
#include <fstream>
#include <regex>
#include <sstream>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

#include <nlohmann/json.hpp>

#include "bench_common.hpp"
#include "lmeform/output.hpp"
#include "lmeform/petsc.hpp"
#include "lmeform/scene.hpp"
#include "problem_registry.hpp"

namespace lmeform::bench {

inline std::string read_text(const std::filesystem::path& p) {
  std::ifstream in(p);
  if (!in) throw std::runtime_error("cannot read " + p.string());
  std::stringstream s;
  s << in.rdbuf();
  return s.str();
}

/// `text` with the line `key = ...` of table [table] set to `key = value`, added when absent.
inline std::string with_key(std::string text, const std::string& table, const std::string& key, const std::string& value) {
  const std::regex existing("(\\n\\[" + table + "\\]\\n(?:[^\\[\\n][^\\n]*\\n|\\n)*?)" + key + " = [^\\n]*");
  if (std::regex_search(text, existing)) return std::regex_replace(text, existing, "$1" + key + " = " + value, std::regex_constants::format_first_only);
  return std::regex_replace(text, std::regex("\\n\\[" + table + "\\]\\n"), "\n[" + table + "]\n" + key + " = " + value + "\n",
                            std::regex_constants::format_first_only);
}

/// `text` without the line `key = ...` of table [table].
inline std::string without_key(std::string text, const std::string& table, const std::string& key) {
  const std::regex existing("(\\n\\[" + table + "\\]\\n(?:[^\\[\\n][^\\n]*\\n|\\n)*?)" + key + " = [^\\n]*\\n");
  return std::regex_replace(text, existing, "$1", std::regex_constants::format_first_only);
}

/// Runs the scene `text` saved as `path`; returns the report's JSON and the wall time. Throws when
/// the run fails.
inline nlohmann::json run_scene_text(const std::string& text, const std::filesystem::path& path, double& wall_s) {
  std::filesystem::create_directories(path.parent_path());
  write_text_atomically(path, text);
  const Scene scene = load_scene(path, problems::driver_tables());
  problems::DriverContext ctx;
  ctx.comm = PETSC_COMM_WORLD;
  ctx.scene = &scene;
  const Stopwatch clock;
  const problems::RunReport report = problems::driver_for(scene).run(ctx);
  wall_s = clock.seconds();
  if (!report.success) throw std::runtime_error(path.string() + ": " + report.status);
  return report.json;
}

}  // namespace lmeform::bench
