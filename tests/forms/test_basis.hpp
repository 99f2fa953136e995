// The basis the form tests tabulate: the real LME basis where lmeform_basis is built, else a
// synthetic smooth tabulation (Gaussian bumps with exact derivatives).
#pragma once

#include "cell_fixture.hpp"

namespace lmeform::formcheck {

/// The basis used by the tests (LME with gamma = 0.8 when LMEFORM_FORMS_HAVE_LME is defined).
BasisChoice test_basis();

/// True when test_basis() is the real LME basis.
bool test_basis_is_lme();

}  // namespace lmeform::formcheck
