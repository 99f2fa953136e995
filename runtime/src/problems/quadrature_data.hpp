// The values of quadrature data at every point of a discretization, by source: given by the driver
// (a reset's pushed-forward jets), a number or expression of x, the support size ρ̄ of the basis,
// the jets of a nodal field, or zeros. Each datum is computed once per problem space.
#pragma once

#include <map>
#include <optional>
#include <tuple>
#include <string>
#include <vector>

#include "bound_scene.hpp"
#include "lmeform/discretization.hpp"
#include "problem_space.hpp"

namespace lmeform::problems {

class QuadratureData {
 public:
  QuadratureData(const BoundScene& b, const Discretization& disc, const ProblemInput& input);

  /// The datum at every point of the cells (source.size each).
  [[nodiscard]] const std::vector<double>& values(const BoundQdata& source);
  /// ... at every point of an integration domain (the cells, a boundary part).
  [[nodiscard]] const std::vector<double>& values(const BoundQdata& source, const ElementSet& domain);

  /// The data that describe fields (given by the driver, or jets of a nodal field), by name: what a
  /// moving reference configuration carries (ProblemSpace::qdata).
  [[nodiscard]] std::map<std::string, std::vector<double>, std::less<>> field_data() const;

 private:
  [[nodiscard]] std::vector<double> compute(const BoundQdata& source, const ElementSet& domain);
  [[nodiscard]] std::vector<double> field_jets(const BoundQdata& source, const ElementSet& domain);

  const BoundScene& bound_;
  const Discretization& disc_;
  const ProblemInput& input_;
  std::map<std::pair<const ElementSet*, std::string>, std::vector<double>> computed_;  ///< (domain, datum)
  std::vector<std::string> field_data_names_;  ///< of the cells
  std::map<const ElementSet*, std::vector<double>> support_size_;
  std::map<std::tuple<const ElementSet*, std::string, int>, std::vector<double>> field_jets_;  ///< (domain, field, derivative)
  /// Scalar fields of an axisymmetric scene are even in r: interpolated with the mirrored basis even
  /// when the unknowns' basis is not (a deformation's y_r is odd, so its basis has the axis as hull).
  std::optional<LmeBasis> field_basis_;
};

/// ρ̄ at every point of a domain: Σ_a p_a(x_q) h_a over the point's LME neighbours.
[[nodiscard]] std::vector<double> support_size_qdata(const Discretization& disc, const ElementSet& domain);

}  // namespace lmeform::problems
