// The node cloud and basis the form tests use: the real LME basis (gamma = 0.8) on a graded node set
// with Delaunay background cells where lmeform_basis and lmeform_geometry are built
// (LMEFORM_FORMS_HAVE_LME), else a synthetic Shepard-Gaussian basis on a graded tensor grid.
#pragma once

#include "cell_fixture.hpp"

namespace lmeform::formcheck {

struct TestSetup {
  NodeCloud cloud;
  BasisChoice basis;
};

/// Graded 2D node set on [0,1]^2 whose spacing is finest (h_min) near the circle (cx, cy, R).
TestSetup test_setup(double cx = 0.45, double cy = 0.45, double R = 0.3);

/// True when test_setup() uses the real LME basis.
bool test_basis_is_lme();

}  // namespace lmeform::formcheck
