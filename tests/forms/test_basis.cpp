#include "test_basis.hpp"

#include <cmath>
#include <memory>
#include <span>

#ifdef LMEFORM_FORMS_HAVE_LME
#include <lmeform/delaunay.hpp>
#include <lmeform/lme_basis.hpp>
#include <lmeform/node_sets.hpp>
#endif

namespace lmeform::formcheck {

#ifdef LMEFORM_FORMS_HAVE_LME

bool test_basis_is_lme() { return true; }

TestSetup test_setup(double cx, double cy, double R) {
  GradedGridOptions go;
  go.h_min = 0.03;
  go.h_max = 0.09;
  go.center = {cx, cy};
  go.radius = R;
  go.transition = 0.15;
  go.seed = 11;
  NodeSet nodes = graded_grid_2d(go);
  const BackgroundCells cells = delaunay(nodes);
  TestSetup s;
  s.cloud.dim = 2;
  s.cloud.x = nodes.coords;
  for (std::size_t c = 0; c < cells.size(); ++c) {
    const auto v = cells.cell(c);
    s.cloud.triangles.push_back({v[0], v[1], v[2]});
  }
  const double gamma = 0.8;
  auto lme = std::make_shared<LmeBasis>(nodes, std::span<const double>(&gamma, 1));
  s.cloud.h.assign(lme->spacing().begin(), lme->spacing().end());
  s.basis.name = "lme(gamma=0.8)";
  s.basis.radius = [lme](const NodeCloud&, int a) { return lme->support_radii()[static_cast<std::size_t>(a)]; };
  s.basis.tabulate = [lme](const NodeCloud&, const std::vector<int>& ids, const double* x, int order, double* out) {
    LmeWorkspace ws;
    const int n = static_cast<int>(ids.size());
    lme->tabulate_cell(std::span<const double>(x, 2), ids, order,
                       std::span<double>(out, static_cast<std::size_t>(kernel::jet_size(2, order)) * n), ws);
    return true;
  };
  return s;
}

#else

bool test_basis_is_lme() { return false; }

TestSetup test_setup(double, double, double) {
  TestSetup s;
  s.cloud = graded_cloud(12, 12, 0.0, 1.0, 0.0, 1.0, 3.0, 0.2, 7);
  s.basis = gaussian_basis(0.8);
  return s;
}

#endif

}  // namespace lmeform::formcheck
