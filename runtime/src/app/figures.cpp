#include "figures.hpp"

#include <fmt/format.h>

#include "lmeform/process.hpp"

namespace lmeform::app {

namespace fs = std::filesystem;

fs::path plot_script() {
  const fs::path dir = executable_directory();
  if (dir.empty()) return {};
  for (const fs::path& candidate : {dir / "share/lmeform/plot_field.py", dir / "../share/lmeform/plot_field.py"})
    if (fs::is_regular_file(candidate)) return candidate.lexically_normal();
  return {};
}

FigureResult plot_field(const fs::path& h5, const fs::path& png, const std::string& field, bool mirror) {
  // Debian's interpreter: a python3 first on the PATH may be a pyenv one without matplotlib.
  const fs::path python = "/usr/bin/python3";
  const fs::path script = plot_script();
  if (script.empty()) return {false, "no figure: plot_field.py is not installed next to the lmeform binary (share/lmeform/)"};
  if (!fs::exists(python)) return {false, "no figure: /usr/bin/python3 is missing (apt-get install python3-matplotlib python3-h5py)"};
  std::vector<std::string> argv{python.string(), script.string(), h5.string(), png.string(), "--field", field};
  if (mirror) argv.emplace_back("--mirror");
  try {
    const ProcessResult r = run_process(argv);
    if (r.exit_code == 0) return {true, ""};
    const std::string why = r.err.empty() ? fmt::format("exit status {}", r.exit_code) : r.err.substr(0, r.err.find_last_not_of('\n') + 1);
    if (r.exit_code == 3) return {false, "no figure: " + why};
    return {false, fmt::format("no figure: {} failed: {}", script.filename().string(), why)};
  } catch (const std::exception& e) {
    return {false, fmt::format("no figure: {}", e.what())};
  }
}

}  // namespace lmeform::app
