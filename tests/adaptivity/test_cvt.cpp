// CVT node relocation, phase-field density, nodal spacing and the eps >= 2 h_min check.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <span>
#include <stdexcept>
#include <string>
#include <vector>

#include "lmeform/cvt.hpp"
#include "lmeform/delaunay.hpp"
#include "lmeform/lme_basis.hpp"
#include "lmeform/neighbour_search.hpp"
#include "lmeform/node_sets.hpp"
#include "lmeform/quadrature.hpp"

namespace lmeform {
namespace {

constexpr double kR = 0.3;
constexpr double kW = 0.03;

double ring_distance(std::span<const double> x) {
  return std::hypot(x[0] - 0.5, x[1] - 0.5) - kR;
}

// |grad phi| of phi = tanh(d / (sqrt(2) w)) up to a constant: 1 / cosh^2.
double grad_norm(std::span<const double> x) {
  const double c = std::cosh(ring_distance(x) / kW);
  return 1.0 / (c * c);
}

std::size_t band_count(const NodeSet& nodes, double half_width) {
  std::size_t k = 0;
  for (std::size_t a = 0; a < nodes.size(); ++a) {
    if (std::abs(ring_distance(nodes.point(a))) < half_width) ++k;
  }
  return k;
}

double min_distance(const NodeSet& nodes) {
  const KdTree tree(nodes);
  std::vector<int> idx;
  std::vector<double> dist;
  double m = std::numeric_limits<double>::infinity();
  for (std::size_t a = 0; a < nodes.size(); ++a) {
    tree.knn(nodes.point(a), 2, idx, &dist);
    for (std::size_t j = 0; j < idx.size(); ++j) {
      if (idx[j] != static_cast<int>(a)) m = std::min(m, dist[j]);
    }
  }
  return m;
}

bool on_boundary(std::span<const double> x, const Box& box, std::size_t i) {
  return x[i] == box.lo[i] || x[i] == box.hi[i];
}

CvtOptions test_options() {
  CvtOptions o;
  o.iterations = 40;
  o.samples_per_node = 32;
  o.tolerance = 1e-4;
  o.seed = 7;
  return o;
}

TEST(Cvt, UniformDensityKeepsUniformGrid) {
  const Box box = Box::unit(2);
  const NodeSet grid = uniform_grid(box, {21, 21, 1});
  CvtReport report;
  const NodeSet out = cvt_relocate(grid, box, [](std::span<const double>) { return 1.0; }, test_options(), &report);
  ASSERT_EQ(out.size(), grid.size());
  double max_move = 0.0, mean_move = 0.0;
  for (std::size_t a = 0; a < grid.size(); ++a) {
    const double m = std::hypot(out.point(a)[0] - grid.point(a)[0], out.point(a)[1] - grid.point(a)[1]);
    max_move = std::max(max_move, m);
    mean_move += m / static_cast<double>(grid.size());
  }
  const double h = 1.0 / 20.0;
  const SpacingSummary su = spacing_summary(out);
  std::printf("uniform: iterations %zu, mean move %.3g h, max move %.3g h, samples %zu, h_min %.4g h_max %.4g\n",
              report.iterations.size(), mean_move / h, max_move / h, report.samples, su.h_min, su.h_max);
  // A square grid is a CVT of the uniform density; the sampled cells perturb it only slightly.
  EXPECT_LT(mean_move, 0.1 * h);
  EXPECT_LT(max_move, 0.35 * h);
  EXPECT_GT(min_distance(out), 0.6 * h);
  ASSERT_FALSE(report.iterations.empty());
  EXPECT_EQ(report.iterations.front().empty_cells, 0u);
  EXPECT_NEAR(su.h_min, h, 0.1 * h);
}

TEST(Cvt, CircleDensityConcentratesNodes) {
  const Box box = Box::unit(2);
  const NodeSet grid = uniform_grid(box, {30, 30, 1});
  const SpacingSummary s0 = spacing_summary(grid);
  const std::size_t band0 = band_count(grid, 0.05);
  double prev_hmin = s0.h_min, prev_ratio = s0.h_max / s0.h_min;
  std::size_t prev_band = band0;
  std::printf("f = 0: band %zu, h_min %.4g, h_max/h_min %.3g, eps_min %.4g\n", band0, s0.h_min, s0.h_max / s0.h_min,
              s0.eps_min);
  for (double f : {10.0, 100.0}) {
    CvtReport report;
    const NodeSet out = cvt_relocate(grid, box, phase_field_density(f, grad_norm), test_options(), &report);
    ASSERT_EQ(out.size(), grid.size());
    const SpacingSummary s = spacing_summary(out);
    const std::size_t band = band_count(out, 0.05);
    const double ratio = s.h_max / s.h_min;
    std::printf("f = %g: band %zu, h_min %.4g, h_max/h_min %.3g, eps_min %.4g, iterations %zu, last mean/max move "
                "%.3g/%.3g\n",
                f, band, s.h_min, ratio, s.eps_min, report.iterations.size(), report.iterations.back().mean_displacement,
                report.iterations.back().max_displacement);
    EXPECT_GT(band, prev_band);
    EXPECT_LT(s.h_min, prev_hmin);
    EXPECT_GT(ratio, prev_ratio);
    EXPECT_GT(min_distance(out), 0.0);
    // Lloyd decreases the displacement overall.
    EXPECT_LT(report.iterations.back().mean_displacement, report.iterations.front().mean_displacement);
    prev_band = band;
    prev_hmin = s.h_min;
    prev_ratio = ratio;
  }
}

TEST(Cvt, BoundaryNodesStayOnTheirFaces) {
  const Box box{2, {0.0, 0.0, 0.0}, {1.5, 2.0, 0.0}};
  const NodeSet grid = uniform_grid(box, {16, 21, 1});
  const NodeSet out = cvt_relocate(grid, box, phase_field_density(100.0, [](std::span<const double> x) {
                                     const double c = std::cosh((std::hypot(x[0], x[1] - 1.0) - 0.6) / 0.05);
                                     return 1.0 / (c * c);
                                   }),
                                   test_options());
  ASSERT_EQ(out.size(), grid.size());
  std::size_t moved_on_edge = 0;
  for (std::size_t a = 0; a < grid.size(); ++a) {
    const auto p = grid.point(a);
    const auto q = out.point(a);
    int faces = 0;
    for (std::size_t i = 0; i < 2; ++i) {
      EXPECT_GE(q[i], box.lo[i]);
      EXPECT_LE(q[i], box.hi[i]);
      if (on_boundary(p, box, i)) {
        ++faces;
        EXPECT_EQ(q[i], p[i]) << "node " << a << " left its face";
      } else {
        EXPECT_FALSE(on_boundary(q, box, i)) << "interior node " << a << " reached the boundary";
      }
    }
    if (faces == 2) {
      EXPECT_EQ(q[0], p[0]);
      EXPECT_EQ(q[1], p[1]);
    }
    if (faces == 1 && (q[0] != p[0] || q[1] != p[1])) ++moved_on_edge;
  }
  EXPECT_GT(moved_on_edge, 0u);  // edge nodes slide (the circle meets the side x = 0)
  EXPECT_GT(min_distance(out), 0.0);
}

TEST(Cvt, UniformCvtHasTheCountAndIsNearlyHexagonal) {
  // The seed's uniform grid O1: 6124 nodes on [0, 1.5] x [0, 2], mean spacing 0.024.
  Box box;
  box.dim = 2;
  box.lo = {0.0, 0.0, 0.0};
  box.hi = {1.5, 2.0, 0.0};
  CvtOptions o;
  o.iterations = 100;
  CvtReport report;
  const NodeSet nodes = uniform_cvt(box, 6124, o, &report);
  ASSERT_EQ(nodes.size(), 6124u);
  const BackgroundCells cells = delaunay(nodes);
  std::vector<std::vector<int>> neighbours(nodes.size());
  for (std::size_t c = 0; c < cells.size(); ++c) {
    const auto v = cells.cell(c);
    for (int i = 0; i < 3; ++i) {
      for (int j = 0; j < 3; ++j) {
        if (i != j) neighbours[static_cast<std::size_t>(v[i])].push_back(v[j]);
      }
    }
  }
  std::size_t interior = 0, six = 0;
  for (std::size_t a = 0; a < nodes.size(); ++a) {
    const auto x = nodes.point(a);
    if (x[0] < 0.1 || x[0] > 1.4 || x[1] < 0.1 || x[1] > 1.9) continue;
    auto& l = neighbours[a];
    std::sort(l.begin(), l.end());
    l.erase(std::unique(l.begin(), l.end()), l.end());
    ++interior;
    six += l.size() == 6 ? 1 : 0;
  }
  const SpacingSummary sp = spacing_summary(nodes);
  std::printf("uniform CVT: %zu iterations, %.1f %% of %zu interior nodes 6-valent, h_mean %.4f, h_min %.4f\n",
              report.iterations.size(), 100.0 * static_cast<double>(six) / static_cast<double>(interior), interior,
              sp.h_mean, sp.h_min);
  EXPECT_GT(static_cast<double>(six), 0.97 * static_cast<double>(interior));  // a random start gives ~78 %
  EXPECT_NEAR(sp.h_mean, 0.024, 0.001);
  EXPECT_GT(sp.h_min, 0.85 * sp.h_mean);
  for (std::size_t a = 0; a < nodes.size(); ++a) {
    for (int i = 0; i < 2; ++i) {
      EXPECT_GE(nodes.point(a)[static_cast<std::size_t>(i)], box.lo[static_cast<std::size_t>(i)]);
      EXPECT_LE(nodes.point(a)[static_cast<std::size_t>(i)], box.hi[static_cast<std::size_t>(i)]);
    }
  }
  EXPECT_THROW((void)uniform_cvt(Box::unit(3), 1000), std::invalid_argument);
  EXPECT_THROW((void)uniform_cvt(Box::unit(2), 5), std::invalid_argument);
}

TEST(Cvt, VoronoiCentroidsOfAUniformDensityFixASquareGrid) {
  // Every Voronoi cell of a square grid is a square (half/quarter at the edges) centred on its
  // node: exact centroids leave the grid in place to round-off.
  const Box box = Box::unit(2);
  const NodeSet grid = uniform_grid(box, {11, 11, 1});
  CvtOptions o;
  o.iterations = 3;
  o.tolerance = 0;
  CvtReport report;
  const NodeSet out = cvt_relocate(grid, box, [](std::span<const double>) { return 1.0; }, o, &report);
  double move = 0;
  for (std::size_t k = 0; k < grid.coords.size(); ++k) move = std::max(move, std::abs(out.coords[k] - grid.coords[k]));
  EXPECT_LT(move, 1e-12);
  EXPECT_EQ(report.iterations.size(), 3u);
}

TEST(Cvt, DeterministicForASeed) {
  const Box box = Box::unit(2);
  const NodeSet grid = uniform_grid(box, {20, 20, 1});
  CvtOptions o = test_options();
  o.iterations = 10;
  const auto rho = phase_field_density(50.0, grad_norm);
  for (const auto centroids : {CvtCentroids::voronoi, CvtCentroids::sampled}) {
    o.centroids = centroids;
    o.seed = 1;
    const NodeSet a = cvt_relocate(grid, box, rho, o);
    const NodeSet b = cvt_relocate(grid, box, rho, o);
    EXPECT_EQ(a.coords, b.coords);
    o.seed = 8;
    const NodeSet c = cvt_relocate(grid, box, rho, o);
    // Only the sampled centroids depend on the seed; the exact Voronoi ones do not.
    if (centroids == CvtCentroids::sampled) EXPECT_NE(a.coords, c.coords);
    else EXPECT_EQ(a.coords, c.coords);
  }
}

TEST(Cvt, ThreeDimensions) {
  const Box box = Box::unit(3);
  const NodeSet grid = uniform_grid(box, {8, 8, 8});
  CvtOptions o = test_options();
  o.iterations = 15;
  o.samples_per_node = 16;
  const auto rho = phase_field_density(20.0, [](std::span<const double> x) {
    const double c = std::cosh((std::hypot(x[0] - 0.5, x[1] - 0.5, x[2] - 0.5) - 0.3) / 0.05);
    return 1.0 / (c * c);
  });
  const NodeSet out = cvt_relocate(grid, box, rho, o);
  ASSERT_EQ(out.size(), grid.size());
  EXPECT_GT(min_distance(out), 0.0);
  EXPECT_LT(spacing_summary(out).h_min, spacing_summary(grid).h_min);
}

TEST(Cvt, RefusesBadInput) {
  const Box box = Box::unit(2);
  const NodeSet grid = uniform_grid(box, {5, 5, 1});
  EXPECT_THROW((void)cvt_relocate(grid, box, [](std::span<const double>) { return 0.0; }), std::invalid_argument);
  NodeSet dup = grid;
  dup.coords.insert(dup.coords.end(), {0.5, 0.5});
  EXPECT_THROW((void)cvt_relocate(dup, box, [](std::span<const double>) { return 1.0; }), std::invalid_argument);
  NodeSet outside = grid;
  outside.coords.insert(outside.coords.end(), {1.5, 0.5});
  EXPECT_THROW((void)cvt_relocate(outside, box, [](std::span<const double>) { return 1.0; }), std::invalid_argument);
  EXPECT_THROW((void)phase_field_density(-1.0, grad_norm), std::invalid_argument);
}

TEST(Spacing, VoronoiRingOfAUniformGridIsTheGridStep) {
  const NodeSet grid = uniform_grid(Box::unit(2), {11, 11, 1});
  for (double h : voronoi_ring_spacing(grid)) EXPECT_NEAR(h, 0.1, 1e-12);
  const NodeSet cube = uniform_grid(Box::unit(3), {5, 5, 5});
  for (double h : voronoi_ring_spacing(cube)) EXPECT_NEAR(h, 0.25, 1e-12);
  SpacingOptions nearest;
  nearest.measure = SpacingMeasure::nearest;
  EXPECT_NEAR(spacing_summary(grid, nearest).h_min, 0.1, 1e-12);
  EXPECT_NEAR(min_admissible_eps(grid), 0.2, 1e-12);
}

TEST(Spacing, CheckResolutionMessage) {
  const NodeSet grid = uniform_grid(Box::unit(2), {41, 41, 1});  // h = 0.025, eps_min = 0.05
  EXPECT_NO_THROW(check_resolution(0.05, grid));
  EXPECT_NO_THROW(check_resolution(0.08, grid));
  try {
    check_resolution(0.03, grid);
    FAIL() << "eps = 0.03 should be refused";
  } catch (const std::invalid_argument& e) {
    const std::string msg = e.what();
    std::printf("message: %s\n", msg.c_str());
    EXPECT_NE(msg.find("h_min = 0.025"), std::string::npos) << msg;
    EXPECT_NE(msg.find("admissible eps is 2 h_min = 0.05"), std::string::npos) << msg;
    EXPECT_NE(msg.find("eps = 0.03"), std::string::npos) << msg;
  }
  EXPECT_THROW(check_resolution(-1.0, grid), std::invalid_argument);
}

TEST(Spacing, CheckResolutionWithAFactor) {
  EXPECT_NO_THROW(check_resolution(0.05, 0.024));
  EXPECT_NO_THROW(check_resolution(0.048, 0.024));
  EXPECT_NO_THROW(check_resolution(0.04, 0.024, 1.6));
  try {
    check_resolution(0.01, 0.012, 2.0, "adaptivity stage 2");
    FAIL() << "eps = 0.01 should be refused";
  } catch (const std::invalid_argument& e) {
    EXPECT_STREQ(e.what(),
                 "adaptivity stage 2: eps = 0.01 is under-resolved: h_min = 0.012, the smallest admissible eps is 2 "
                 "h_min = 0.024 (criterion eps >= 2 h_min, seed Appendix B); refine or adapt the nodes, or raise eps");
  }
  EXPECT_THROW(check_resolution(0.05, 0.0), std::invalid_argument);
  EXPECT_THROW(check_resolution(0.05, 0.024, -1.0), std::invalid_argument);
}

// ---------------------------------------------------------------------------------------------
// Node sets for a spacing field: count_nodes_for_spacing and cvt_for_spacing.

Box box_2d(double lx, double ly) {
  Box box;
  box.dim = 2;
  box.lo = {0.0, 0.0, 0.0};
  box.hi = {lx, ly, 0.0};
  return box;
}

SpacingFunction constant_spacing(double h) {
  return {[h](std::span<const double>) { return h; }, h};
}

// h = h0 on the line x = c, growing by `slope` per unit distance from it, up to 8 h0.
SpacingFunction graded_spacing(double h0, double c, double slope) {
  return {[=](std::span<const double> x) { return std::min(8.0 * h0, h0 + slope * std::abs(x[0] - c)); }, h0};
}

std::size_t corner_count(const NodeSet& nodes, const Box& box) {
  std::size_t k = 0;
  for (std::size_t a = 0; a < nodes.size(); ++a) {
    if (on_boundary(nodes.point(a), box, 0) && on_boundary(nodes.point(a), box, 1)) ++k;
  }
  return k;
}

void expect_inside(const NodeSet& nodes, const Box& box) {
  for (std::size_t a = 0; a < nodes.size(); ++a) {
    for (std::size_t i = 0; i < 2; ++i) {
      EXPECT_GE(nodes.point(a)[i], box.lo[i]) << "node " << a;
      EXPECT_LE(nodes.point(a)[i], box.hi[i]) << "node " << a;
    }
  }
}

// Mean Voronoi-ring spacing of the nodes whose distance |x - c| lies in [lo, hi).
double mean_spacing_in(const NodeSet& nodes, const std::vector<double>& h, double c, double lo, double hi,
                       std::size_t* count = nullptr) {
  double sum = 0.0;
  std::size_t k = 0;
  for (std::size_t a = 0; a < nodes.size(); ++a) {
    const double d = std::abs(nodes.point(a)[0] - c);
    if (d >= lo && d < hi) {
      sum += h[a];
      ++k;
    }
  }
  if (count != nullptr) *count = k;
  return k == 0 ? std::numeric_limits<double>::quiet_NaN() : sum / static_cast<double>(k);
}

TEST(CvtForSpacing, UniformSpacingCountsAndGrid) {
  const Box box = box_2d(1.5, 2.0);
  const double h = 0.05;
  const SpacingFunction field = constant_spacing(h);
  const SpacingNodeCount count = count_nodes_for_spacing(box, field);
  const double area_nodes = 1.5 * 2.0 * 2.0 / (std::sqrt(3.0) * h * h);  // 1385.6
  std::size_t on_edges = 4;
  for (const std::size_t e : count.edges) on_edges += e;
  std::printf("uniform spacing: total %zu, interior %zu, edges %zu %zu %zu %zu, area formula %.1f\n", count.total,
              count.interior, count.edges[0], count.edges[1], count.edges[2], count.edges[3], area_nodes);
  // Edges without the corners: length / h - 1 (bottom, right, top, left).
  EXPECT_EQ(count.edges[0], 29u);
  EXPECT_EQ(count.edges[1], 39u);
  EXPECT_EQ(count.edges[2], 29u);
  EXPECT_EQ(count.edges[3], 39u);
  EXPECT_EQ(count.total, count.interior + on_edges);
  // The area integral counts a boundary node about half: total = area formula + on_edges / 2.
  EXPECT_NEAR(static_cast<double>(count.total), area_nodes + 0.5 * static_cast<double>(on_edges), 1.0);
  EXPECT_NEAR(static_cast<double>(count.total) / area_nodes, 1.0, 0.06);

  CvtReport report;
  const NodeSet nodes = cvt_for_spacing(box, field, count.total, {}, &report);
  ASSERT_EQ(nodes.size(), count.total);
  expect_inside(nodes, box);
  EXPECT_EQ(corner_count(nodes, box), 4u);
  EXPECT_GT(min_distance(nodes), 0.5 * h);
  const SpacingSummary s = spacing_summary(nodes);
  std::printf("uniform spacing CVT: %zu iterations, replaced %zu, h_mean %.4g, h_min %.4g, h_max %.4g\n",
              report.iterations.size(), report.replaced, s.h_mean, s.h_min, s.h_max);
  EXPECT_EQ(report.replaced, count.total - 4);  // CvtStart::density is implied: all but the corners re-placed
  EXPECT_NEAR(s.h_mean, h, 0.1 * h);
}

TEST(CvtForSpacing, GradedSpacingFollowsTheField) {
  const Box box = box_2d(2.0, 1.0);
  const double h0 = 0.02, c = 0.6, slope = 0.2;
  const SpacingFunction field = graded_spacing(h0, c, slope);
  const SpacingNodeCount count = count_nodes_for_spacing(box, field);
  const NodeSet nodes = cvt_for_spacing(box, field, count.total);
  ASSERT_EQ(nodes.size(), count.total);
  expect_inside(nodes, box);
  EXPECT_EQ(corner_count(nodes, box), 4u);
  const std::vector<double> h = voronoi_ring_spacing(nodes);
  // The same node count uniformly: what the spacing would be if the grading were ignored.
  const NodeSet uniform = uniform_cvt(box, count.total);
  const std::vector<double> hu = voronoi_ring_spacing(uniform);
  std::size_t near_count = 0, far_count = 0;
  const double near = mean_spacing_in(nodes, h, c, 0.0, 0.02, &near_count);
  const double far = mean_spacing_in(nodes, h, c, 0.8, 10.0, &far_count);
  const double near_u = mean_spacing_in(uniform, hu, c, 0.0, 0.02);
  std::printf("graded: %zu nodes; near %.4g (%zu nodes), far %.4g (%zu nodes); uniform CVT of the same count: near %.4g\n",
              nodes.size(), near, near_count, far, far_count, near_u);
  // Near the line the spacing is h0 (the ring averages neighbours a little farther out, up to
  // h0 + 0.2 h0); a uniform CVT of the same count is 3x coarser there.
  EXPECT_GE(near_count, 40u);
  EXPECT_NEAR(near, h0, 0.25 * h0);
  EXPECT_GT(near_u, 1.25 * h0);
  // Far from the line (|x - c| >= 0.8 > 0.7, where h reaches 8 h0): the coarse spacing.
  EXPECT_GE(far_count, 10u);
  EXPECT_NEAR(far, 8.0 * h0, 0.15 * 8.0 * h0);
  EXPECT_GT(far, 5.0 * near);
  // In between, the spacing follows the linear grading (measured ratios 0.92 to 0.99).
  for (int k = 0; k < 7; ++k) {
    const double lo = 0.1 * k;
    std::size_t n = 0;
    const double m = mean_spacing_in(nodes, h, c, lo, lo + 0.1, &n);
    const double target = std::min(8.0 * h0, h0 + slope * (lo + 0.05));
    std::printf("  |x - c| in [%.1f, %.1f): %zu nodes, mean h %.4g, target %.4g, ratio %.3f\n", lo, lo + 0.1, n, m,
                target, m / target);
    EXPECT_GE(n, 5u);
    EXPECT_NEAR(m / target, 1.0, 0.2) << "|x - c| in [" << lo << ", " << lo + 0.1 << ")";
  }
}

TEST(CvtForSpacing, RefusesBadInput) {
  const Box box = box_2d(1.5, 2.0);
  const SpacingFunction field = constant_spacing(0.05);
  const std::size_t budget = count_nodes_for_spacing(box, field).total;  // 1456
  EXPECT_NO_THROW((void)count_nodes_for_spacing(box, field));
  try {
    (void)cvt_for_spacing(box, field, budget - 1);
    ADD_FAILURE() << "a limit below the budget should be refused";
  } catch (const std::invalid_argument& e) {
    const std::string msg = e.what();
    EXPECT_NE(msg.find("needs " + std::to_string(budget) + " nodes"), std::string::npos) << msg;
    EXPECT_NE(msg.find("limit of " + std::to_string(budget - 1)), std::string::npos) << msg;
  }
  // A spacing that is not positive and finite somewhere.
  const SpacingFunction zero{[](std::span<const double> x) { return x[0] > 0.75 ? 0.0 : 0.05; }, 0.05};
  const SpacingFunction nan{[](std::span<const double> x) { return x[1] > 1.0 ? std::nan("") : 0.05; }, 0.05};
  const SpacingFunction negative{[](std::span<const double>) { return -0.05; }, 0.05};
  for (const SpacingFunction* bad : {&zero, &nan, &negative}) {
    EXPECT_THROW((void)count_nodes_for_spacing(box, *bad), std::invalid_argument);
    EXPECT_THROW((void)cvt_for_spacing(box, *bad, 100000), std::invalid_argument);
  }
  try {
    (void)cvt_for_spacing(box, zero, 100000);
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("the spacing must be positive and finite, got 0"), std::string::npos) << e.what();
  }
  // No spacing function, a bad h_min, a 3D box.
  EXPECT_THROW((void)count_nodes_for_spacing(box, SpacingFunction{}), std::invalid_argument);
  EXPECT_THROW((void)count_nodes_for_spacing(box, SpacingFunction{field.h, 0.0}), std::invalid_argument);
  EXPECT_THROW((void)count_nodes_for_spacing(Box::unit(3), constant_spacing(0.2)), std::invalid_argument);
  EXPECT_THROW((void)cvt_for_spacing(Box::unit(3), constant_spacing(0.2), 100000), std::invalid_argument);
}

TEST(Density, NodalValuesInterpolateLinearly) {
  const NodeSet grid = uniform_grid(Box::unit(2), {6, 6, 1});
  std::vector<double> g(grid.size());
  for (std::size_t a = 0; a < grid.size(); ++a) g[a] = 2.0 * grid.point(a)[0] + grid.point(a)[1];
  const Density rho = phase_field_density(3.0, grid, g);
  const double x[2] = {0.37, 0.61};
  EXPECT_NEAR(rho(x), 1.0 + 3.0 * (2.0 * 0.37 + 0.61), 1e-12);
}

// The second-order basis on the vesicles' interface grids: a CVT graded from a circle (h0 there,
// 8 h0 far away) has coarse, ragged rows along the box, and a face node's nearest neighbour often
// lies inside, nearer than the next node along the face. Evaluated at every Gauss point of the
// Delaunay cells (without the axisymmetric mirror, so that r = 0 is a face too): every point
// evaluates (the face gaps are widened where the face's own nodes need it) and meets the second
// moment condition.
TEST(CvtForSpacing, SecondOrderBasisEvaluatesOnAGradedCvtOfTheVesicleBox) {
  const Box box = box_2d(1.5, 2.0);
  const double h0 = 0.0125, band = 0.075, grading = 0.2, radius = 0.4;
  const SpacingFunction field{[=](std::span<const double> x) {
                                const double distance = std::abs(std::hypot(x[0], x[1] - 1.0) - radius);
                                return std::min(8.0 * h0, h0 + grading * std::max(0.0, distance - band));
                              },
                              h0};
  const NodeSet nodes = cvt_for_spacing(box, field, count_nodes_for_spacing(box, field).total);
  LmeOptions options;
  options.consistency = LmeConsistency::second;
  const LmeBasis basis(nodes, std::vector<double>{0.5}, options);
  const CellQuadrature q = map_to_cells(delaunay(nodes), nodes, triangle_rule(6));
  std::size_t failed = 0;
  double worst = 0.0;
  for (std::size_t p = 0; p < q.size(); ++p) {
    const auto x = q.point(p);
    const auto nbrs = basis.neighbours(x);
    try {
      const std::vector<double> jet = basis.evaluate(x, nbrs, 0);
      // sum p_a ((x_a - x)(x_a - x)^T - G_a) = 0: the r-r entry.
      double m = 0.0;
      for (std::size_t i = 0; i < nbrs.size(); ++i) {
        const auto a = static_cast<std::size_t>(nbrs[i]);
        const double dr = nodes.point(a)[0] - x[0];
        m += jet[i] * (dr * dr - basis.gaps()[a * 3]);
      }
      worst = std::max(worst, std::abs(m));
    } catch (const std::exception&) {
      ++failed;
    }
  }
  std::printf("graded vesicle-box CVT: %zu nodes, %zu points, %zu failed, worst second moment %.1e\n", nodes.size(), q.size(),
              failed, worst);
  EXPECT_EQ(failed, 0u);
  EXPECT_LE(worst, 1e-12);
}

}  // namespace
}  // namespace lmeform
