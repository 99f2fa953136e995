#include "test_basis.hpp"

namespace lmeform::formcheck {

BasisChoice test_basis() { return gaussian_basis(0.8); }
bool test_basis_is_lme() { return false; }

}  // namespace lmeform::formcheck
