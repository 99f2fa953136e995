// Figures of field files, drawn by the plotting script installed next to the lmeform binary
// (share/lmeform/plot_field.py) with Debian's /usr/bin/python3. A figure is an extra: without
// Python or matplotlib, or on any failure of the script, the caller gets a warning, not an error.
#pragma once

#include <filesystem>
#include <string>
#include <vector>

namespace lmeform::app {

/// What drawing a figure gave: the PNG written, or why none was.
struct FigureResult {
  bool written = false;
  std::string warning;  ///< empty when written
};

/// Draws scalar field `field` of an HDF5 field file as a PNG (the zero contour over the nodes;
/// `mirror` reflects an axisymmetric field across the axis). Never throws.
[[nodiscard]] FigureResult plot_field(const std::filesystem::path& h5, const std::filesystem::path& png, const std::string& field,
                                      bool mirror);

/// Draws columns `ys` of a load-stepped run's history.csv against column `x` as a PNG. Never throws.
[[nodiscard]] FigureResult plot_history(const std::filesystem::path& csv, const std::filesystem::path& png, const std::string& x,
                                        const std::vector<std::string>& ys);

/// An installed plotting script (plot_field.py, plot_history.py), or empty when it cannot be found.
[[nodiscard]] std::filesystem::path installed_script(const std::string& name);

}  // namespace lmeform::app
