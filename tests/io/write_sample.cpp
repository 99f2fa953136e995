// Writes a small axisymmetric (r, z) vesicle field file: phi = tanh profile of an oblate ellipse on
// jittered nodes over [0, 1.5] x [0, 2], with the attributes a run writes. Used by the plot test.
#include <cmath>
#include <cstdio>
#include <exception>
#include <filesystem>

#include "lmeform/delaunay.hpp"
#include "lmeform/node_sets.hpp"
#include "lmeform/output.hpp"

int main(int argc, char** argv) {
  if (argc != 2) {
    std::fprintf(stderr, "usage: %s OUT.h5\n", argv[0]);
    return 2;
  }
  try {
    const std::filesystem::path out = argv[1];
    if (out.has_parent_path()) std::filesystem::create_directories(out.parent_path());
    const lmeform::Box box{2, {0.0, 0.0, 0.0}, {1.5, 2.0, 0.0}};
    const lmeform::NodeSet nodes = lmeform::jitter_interior(lmeform::uniform_grid(box, 0.04), box, 0.01, 11);
    const lmeform::BackgroundCells cells = lmeform::delaunay(nodes);
    const double a = 0.7, b = 0.45, zc = 1.0, eps = 0.05;
    std::vector<double> phi(nodes.size());
    for (std::size_t i = 0; i < nodes.size(); ++i) {
      const auto x = nodes.point(i);
      const double rho = std::hypot(x[0] / a, (x[1] - zc) / b);
      phi[i] = std::tanh((1.0 - rho) * b / (std::sqrt(2.0) * eps));
    }
    lmeform::write_field_hdf5(out, nodes, cells, {{"phi", {phi}}},
                              {{"eps", eps}, {"energy", 9.12657}, {"step", 0}, {"coordinates", "axisymmetric r-z"}});
    std::printf("wrote %s: %zu nodes, %zu cells\n", out.c_str(), nodes.size(), cells.size());
  } catch (const std::exception& e) {
    std::fprintf(stderr, "io_write_sample: %s\n", e.what());
    return 1;
  }
  return 0;
}
