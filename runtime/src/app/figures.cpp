#include "figures.hpp"

#include <fmt/format.h>

#include "lmeform/process.hpp"

namespace lmeform::app {

namespace fs = std::filesystem;

fs::path installed_script(const std::string& name) {
  const fs::path dir = executable_directory();
  if (dir.empty()) return {};
  for (const fs::path& candidate : {dir / "share/lmeform" / name, dir / "../share/lmeform" / name})
    if (fs::is_regular_file(candidate)) return candidate.lexically_normal();
  return {};
}

namespace {

/// Runs an installed plotting script with Debian's interpreter (a python3 first on the PATH may be
/// a pyenv one without matplotlib): status 3 means a missing module.
FigureResult run_plot_script(const std::string& name, std::vector<std::string> arguments) {
  const fs::path python = "/usr/bin/python3";
  const fs::path script = installed_script(name);
  if (script.empty()) return {false, "no figure: " + name + " is not installed next to the lmeform binary (share/lmeform/)"};
  if (!fs::exists(python)) return {false, "no figure: /usr/bin/python3 is missing (apt-get install python3-matplotlib python3-h5py)"};
  std::vector<std::string> argv{python.string(), script.string()};
  argv.insert(argv.end(), arguments.begin(), arguments.end());
  try {
    const ProcessResult r = run_process(argv);
    if (r.exit_code == 0) return {true, ""};
    const std::string why = r.err.empty() ? fmt::format("exit status {}", r.exit_code) : r.err.substr(0, r.err.find_last_not_of('\n') + 1);
    if (r.exit_code == 3) return {false, "no figure: " + why};
    return {false, fmt::format("no figure: {} failed: {}", name, why)};
  } catch (const std::exception& e) {
    return {false, fmt::format("no figure: {}", e.what())};
  }
}

}  // namespace

FigureResult plot_field(const fs::path& h5, const fs::path& png, const std::string& field, bool mirror) {
  std::vector<std::string> arguments{h5.string(), png.string(), "--field", field};
  if (mirror) arguments.emplace_back("--mirror");
  return run_plot_script("plot_field.py", std::move(arguments));
}

FigureResult plot_history(const fs::path& csv, const fs::path& png, const std::string& x, const std::vector<std::string>& ys) {
  std::vector<std::string> arguments{csv.string(), png.string(), "--x", x};
  for (const auto& y : ys) arguments.insert(arguments.end(), {"--y", y});
  return run_plot_script("plot_history.py", std::move(arguments));
}

}  // namespace lmeform::app
