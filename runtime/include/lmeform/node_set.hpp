// A set of nodes in 1, 2 or 3 dimensions: the discretization points of a meshfree method.
#pragma once

#include <cstddef>
#include <span>
#include <stdexcept>
#include <string>
#include <vector>

namespace lmeform {

/// Nodes stored point-major: coordinate i of node a is coords[a * dim + i].
struct NodeSet {
  int dim = 0;
  std::vector<double> coords;

  NodeSet() = default;
  NodeSet(int dimension, std::vector<double> coordinates) : dim(dimension), coords(std::move(coordinates)) {
    if (dim < 1 || dim > 3) {
      throw std::invalid_argument("NodeSet: dimension must be 1, 2 or 3, got " + std::to_string(dim));
    }
    if (coords.size() % static_cast<std::size_t>(dim) != 0) {
      throw std::invalid_argument("NodeSet: " + std::to_string(coords.size()) +
                                  " coordinates are not a multiple of dimension " + std::to_string(dim));
    }
  }

  [[nodiscard]] std::size_t size() const noexcept { return dim == 0 ? 0 : coords.size() / static_cast<std::size_t>(dim); }
  [[nodiscard]] std::span<const double> point(std::size_t a) const noexcept {
    return {coords.data() + a * static_cast<std::size_t>(dim), static_cast<std::size_t>(dim)};
  }
};

}  // namespace lmeform
