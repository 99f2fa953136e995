// `lmeform run`: a scene read, the driver that claims it run, its report printed as the closing
// table and written as fields (HDF5 + XDMF, a figure where asked for) and JSON. Nothing here knows a
// driver: the report says what to print and write.
#pragma once

#include <string>
#include <vector>

namespace lmeform::app {

struct RunOptions {
  std::string scene;                  ///< the scene file
  std::string json;                   ///< --json: the run's figures ("": none)
  std::string output;                 ///< --output: overrides the scene's [output] directory
  std::vector<std::string> settings;  ///< --set NAME=VALUE, winning over [constants]
  bool restart = false;               ///< --restart: resume from the checkpoint
  bool check = false;                 ///< --check: bind and check the scene, no solve
};

/// Runs the command (collective over PETSC_COMM_WORLD); returns the exit status (0 success, 2 a
/// run that did not converge or stopped early). Throws SceneError / FormLoadError for what cannot run.
[[nodiscard]] int run_command(const RunOptions& options);

}  // namespace lmeform::app
