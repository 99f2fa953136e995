// `lmeform check` and its library (runtime/src/check): every built-in module passes in every
// declared dimension (2D and 3D, Cartesian and axisymmetric) with generic states; corrupted kernels
// fail with the offending output named (and exit code 1 from the command); residual, bilinear and
// linear outputs are checked for what applies to them; non-smooth forms report kinks, not failures;
// boundary kernels are checked like cell kernels and named with their domain, point outputs evaluated.
#include "check_command.hpp"

#include <lmeform/form_check_setup.hpp>
#include <lmeform/form_registry.hpp>
#include <lmeform/module_check.hpp>

#include <check_boundary_kernels.hpp>
#include <check_elastic_kernels.hpp>
#include <check_kinks_kernels.hpp>
#include <check_weak_kernels.hpp>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <functional>
#include <sstream>
#include <string>
#include <vector>

namespace fc = lmeform::formcheck;
namespace fs = std::filesystem;
using lmeform::kernel::CellInputs;
using lmeform::kernel::FormKernels;
using lmeform::kernel::ModuleTable;

namespace {

std::span<const FormKernels* const> kernels_of(const ModuleTable& t) {
  return {t.kernels, static_cast<std::size_t>(t.n_kernels)};
}

const fc::CheckRecord* find_record(const fc::ModuleCheck& check, const std::string& output, int dim,
                                  const std::string& measure = "") {
  for (const auto& r : check.records)
    if (r.output == output && r.dim == dim && (measure.empty() || r.measure == measure)) return &r;
  return nullptr;
}

// ---- Corrupted kernels ----------------------------------------------------------------------------
// Kernel pointers are plain functions: the wrapped original lives in a global for the wrapper.

const FormKernels* g_original = nullptr;

int ndofs(const CellInputs& in) { return in.n_nodes * g_original->dofs_per_node; }

/// Adds 1e-3 max|H| to one off-diagonal entry (kernels accumulate: compute, then add).
void matrix_with_one_wrong_entry(const CellInputs& in, double* m) {
  const int N = ndofs(in);
  std::vector<double> H(static_cast<std::size_t>(N) * N, 0.0);
  g_original->matrix(in, H.data());
  double largest = 0.0;
  for (const double h : H) largest = std::max(largest, std::abs(h));
  H[static_cast<std::size_t>(1) * N + 2] += 1e-3 * largest;
  for (std::size_t i = 0; i < H.size(); ++i) m[i] += H[i];
}

void vector_scaled(const CellInputs& in, double* g) {
  std::vector<double> v(static_cast<std::size_t>(ndofs(in)), 0.0);
  g_original->vector(in, v.data());
  for (std::size_t i = 0; i < v.size(); ++i) g[i] += 1.001 * v[i];
}

/// A "linear" form that squares its entries: not linear in the test function.
void vector_squared(const CellInputs& in, double* g) {
  std::vector<double> v(static_cast<std::size_t>(ndofs(in)), 0.0);
  g_original->vector(in, v.data());
  for (std::size_t i = 0; i < v.size(); ++i) g[i] += v[i] + 10.0 * v[i] * v[i];
}

/// A "bilinear" form that reads the unknowns.
void matrix_reading_unknowns(const CellInputs& in, double* m) {
  const int N = ndofs(in);
  std::vector<double> A(static_cast<std::size_t>(N) * N, 0.0);
  g_original->matrix(in, A.data());
  for (std::size_t i = 0; i < A.size(); ++i) m[i] += A[i] * (1.0 + 1e-3 * in.unknowns[0]);
}

/// A module table with `replaced` standing in for the kernel of the same output, dimension and domain.
struct PatchedModule {
  std::vector<const FormKernels*> kernels;
  ModuleTable table;
  PatchedModule(const ModuleTable& original, const FormKernels& replaced) : table(original) {
    for (int i = 0; i < original.n_kernels; ++i) {
      const FormKernels* k = original.kernels[i];
      const bool same = std::string(k->name) == replaced.name && k->dim == replaced.dim && k->domain == replaced.domain &&
                        std::strcmp(k->boundary_part, replaced.boundary_part) == 0;
      kernels.push_back(same ? &replaced : k);
    }
    table.kernels = kernels.data();
  }
};

}  // namespace

// ---- Built-in modules ------------------------------------------------------------------------------

class BuiltinModule : public ::testing::TestWithParam<std::string> {};

TEST_P(BuiltinModule, PassesInEveryDeclaredDimension) {
  const lmeform::FormModule& module = lmeform::load_form(GetParam());
  const fc::ModuleCheck check = fc::check_module(module.name, module.source, module.kernels, {});
  std::printf("%s\n", fc::format_table(check).c_str());
  EXPECT_EQ(check.records.size(), module.kernels.size()) << "every output in every declared dimension";
  for (const fc::CheckRecord& r : check.records) {
    EXPECT_TRUE(r.passed) << r.output << " " << r.dim << "d";
    EXPECT_EQ(r.status, "pass") << r.output << " " << r.dim << "d: a smooth form reports no kink";
    EXPECT_EQ(r.cells, 2);
  }
  const bool axisymmetric = GetParam().find("_axisymmetric") != std::string::npos;
  EXPECT_EQ(check.coordinates, axisymmetric ? fc::Coordinates::axisymmetric : fc::Coordinates::cartesian);
}

// Fourth-order scenes run on the second-order max-ent basis (nodes.basis = "second"): every form's
// derivatives must hold on its check cells too (a gap-corrected span, other neighbour weights).
TEST_P(BuiltinModule, PassesWithTheSecondOrderBasis) {
  const lmeform::FormModule& module = lmeform::load_form(GetParam());
  fc::ModuleCheckOptions options;
  options.basis = lmeform::LmeConsistency::second;
  const fc::ModuleCheck check = fc::check_module(module.name, module.source, module.kernels, options);
  EXPECT_EQ(check.basis, lmeform::LmeConsistency::second);
  EXPECT_NE(fc::format_table(check).find("basis: second order"), std::string::npos);
  EXPECT_EQ(check.records.size(), module.kernels.size());
  for (const fc::CheckRecord& r : check.records) {
    EXPECT_TRUE(r.passed) << r.output << " " << r.dim << "d";
    EXPECT_EQ(r.status, "pass") << r.output << " " << r.dim << "d";
  }
}

INSTANTIATE_TEST_SUITE_P(All, BuiltinModule, ::testing::ValuesIn(lmeform::builtin_form_names()),
                         [](const ::testing::TestParamInfo<std::string>& p) { return p.param; });

/// Checks a form by name: every output passes; every energy's gradient and Hessian agree with
/// differences (1e-5) and its Taylor remainders have their orders (2 for the gradient, 3 with the
/// Hessian term, 2 for the Hessian; "exact" where the energy is a polynomial along the direction);
/// an energy is checked in every dimension of `dims`. Returns the check for further assertions.
fc::ModuleCheck expect_form_passes(const std::string& name, const std::vector<int>& dims, const fc::ModuleCheckOptions& options,
                                   const std::string& label) {
  auto slope_ok = [](const fc::SlopeResult& s, double expected) {
    return s.kind == fc::SlopeResult::Kind::exact || (s.kind == fc::SlopeResult::Kind::fitted && std::abs(s.value - expected) < 0.3);
  };
  const lmeform::FormModule& module = lmeform::load_form(name);
  fc::ModuleCheck check = fc::check_module(module.name, module.source, module.kernels, options);
  std::vector<int> energy_dims;
  for (const fc::CheckRecord& r : check.records) {
    const std::string what = name + "." + r.output + " " + std::to_string(r.dim) + "d (" + label + ", " + lmeform::to_string(options.basis) + " order)";
    EXPECT_TRUE(r.passed) << what;
    if (r.kind != "energy") continue;
    energy_dims.push_back(r.dim);
    EXPECT_LT(r.gradient_rel_error, 1e-5) << what;
    EXPECT_LT(r.hessian_rel_error, 1e-5) << what;
    EXPECT_TRUE(slope_ok(r.taylor_slope_gradient, 2.0)) << what << ": gradient remainder slope " << r.taylor_slope_gradient.text();
    EXPECT_TRUE(slope_ok(r.taylor_slope_second_order, 3.0)) << what << ": second-order remainder slope " << r.taylor_slope_second_order.text();
    EXPECT_TRUE(slope_ok(r.taylor_slope_hessian, 2.0)) << what << ": Hessian remainder slope " << r.taylor_slope_hessian.text();
  }
  for (const int d : dims)
    EXPECT_NE(std::find(energy_dims.begin(), energy_dims.end(), d), energy_dims.end()) << name << ": no energy checked in " << d << "d";
  return check;
}

// The solids forms (docs/solids.md), by name, in every dimension each declares, on the graded check
// cells, with both bases. The axisymmetric forms are checked in r-z coordinates with the mirrored basis.
TEST(ModuleCheck, SolidsFormsByName) {
  const std::map<std::string, std::vector<int>> forms = {
      {"elasticity", {2, 3}},       {"neo_hookean", {2, 3}},   {"elasticity_axisymmetric", {2}}, {"pressure_axisymmetric", {2}},
      {"traction", {2, 3}},         {"kirchhoff_plate", {2}},  {"kirchhoff_clamped", {2}}};
  for (const auto basis : {lmeform::LmeConsistency::first, lmeform::LmeConsistency::second}) {
    for (const auto& [name, dims] : forms) {
      fc::ModuleCheckOptions options;
      options.basis = basis;
      const fc::ModuleCheck check = expect_form_passes(name, dims, options, "defaults");
      const bool axisymmetric = name.find("_axisymmetric") != std::string::npos;
      EXPECT_EQ(check.coordinates, axisymmetric ? fc::Coordinates::axisymmetric : fc::Coordinates::cartesian) << name;
    }
  }
}

// Every fracture form in every dimension it declares, both bases, with and without the
// volumetric-deviatoric split (max/min of tr eps: the branch taken is differentiated), the split
// smoothed over a width of the order of the check's strains (its curvature in play) and, for the
// anisotropic surface energy, a rotated cubic tensor and an orthotropic gradient metric.
TEST(ModuleCheck, FractureFormsByName) {
  const std::map<std::string, std::vector<int>> forms = {
      {"fracture_at1", {1, 2, 3}}, {"fracture_at2", {1, 2, 3}}, {"fracture_fourth", {1, 2, 3}}, {"fracture_anisotropic", {2, 3}}};
  const std::vector<std::pair<std::string, double>> anisotropy = {{"theta0", 0.4}, {"a2", 1.6}, {"g1111", 1.2}, {"g1122", 0.3}, {"g1212", 0.7}};
  for (const auto basis : {lmeform::LmeConsistency::first, lmeform::LmeConsistency::second}) {
    for (const auto& [name, dims] : forms) {
      for (const auto& [split, width] : std::vector<std::pair<double, double>>{{0.0, 0.0}, {1.0, 0.0}, {1.0, 0.3}}) {
        fc::ModuleCheckOptions options;
        options.basis = basis;
        options.constants = {{"split", split}, {"split_width", width}};
        if (name == "fracture_anisotropic") options.constants.insert(options.constants.end(), anisotropy.begin(), anisotropy.end());
        (void)expect_form_passes(name, dims, options, "split " + std::to_string(int(split)) + " width " + std::to_string(width));
      }
    }
  }
}

// The flexoelectric enthalpies (seed Eqs. 5.15 and 5.16) with every coupling switched on: a poled
// piezoelectric tensor, a cubic flexoelectric tensor with a shear constant, rotated crystal axes.
// The Hessian's check covers its mixed displacement-potential block, which these constants fill.
TEST(ModuleCheck, FlexoelectricFormsWithEveryCoupling) {
  const std::map<std::string, std::vector<std::pair<std::string, double>>> forms = {
      {"flexoelectric", {{"e31", -4.4}, {"e33", 18.6}, {"e15", 11.6}, {"theta", 0.3}, {"mu_L", 1.3}, {"mu_T", 0.7}, {"mu_S", 0.4}}},
      {"flexoelectric_fd",
       {{"e31", -4.4}, {"e33", 18.6}, {"e15", 11.6}, {"theta", 0.3}, {"f_L", -0.5}, {"f_T", 0.2}, {"f_S", 0.3}, {"d_L", 0.8}, {"d_T", 0.9}, {"d_S", 0.1}}},
      {"flexoelectric_loads", {{"k_support", 2.0}}}};
  for (const auto basis : {lmeform::LmeConsistency::first, lmeform::LmeConsistency::second}) {
    for (const auto& [name, constants] : forms) {
      const lmeform::FormModule& module = lmeform::load_form(name);
      fc::ModuleCheckOptions options;
      options.basis = basis;
      options.constants = constants;
      const fc::ModuleCheck check = fc::check_module(module.name, module.source, module.kernels, options);
      std::vector<int> dims;
      for (const fc::CheckRecord& r : check.records) {
        const std::string what = name + "." + r.output + " " + std::to_string(r.dim) + "d (" + lmeform::to_string(basis) + " order)";
        EXPECT_TRUE(r.passed) << what;
        if (r.kind != "energy") continue;
        dims.push_back(r.dim);
        EXPECT_LT(r.gradient_rel_error, 1e-5) << what;
        if (!std::isnan(r.hessian_rel_error)) {
          EXPECT_LT(r.hessian_rel_error, 1e-5) << what;
        }
        EXPECT_LT(r.symmetry_error, 1e-12) << what;
      }
      for (const int d : {2, 3}) EXPECT_NE(std::find(dims.begin(), dims.end(), d), dims.end()) << name << ": no energy checked in " << d << "d";
    }
  }
}

// The Norton-Hoff flow forms (docs/forming.md): the residual's Jacobian against differences of the
// residual, in every dimension each declares, both bases, from the Newtonian m = 1 to a nearly
// rigid-plastic m = 0.05 with the rate floor active (a rate_floor comparable to the check's rates).
TEST(ModuleCheck, ViscoplasticFormsByName) {
  const std::map<std::string, std::vector<int>> forms = {{"viscoplastic", {2, 3}}, {"viscoplastic_axisymmetric", {2}}};
  for (const auto basis : {lmeform::LmeConsistency::first, lmeform::LmeConsistency::second}) {
    for (const auto& [name, dims] : forms) {
      for (const auto& [m, floor] : std::vector<std::pair<double, double>>{{1.0, 1e-4}, {0.2, 1e-4}, {0.05, 1.0}}) {
        fc::ModuleCheckOptions options;
        options.basis = basis;
        options.constants = {{"m", m}, {"rate_floor", floor}, {"K", 2.5}, {"C", 0.3}};
        const std::string label = "m " + std::to_string(m) + ", rate_floor " + std::to_string(floor);
        const fc::ModuleCheck check = expect_form_passes(name, {}, options, label);  // a residual: no energy
        std::vector<int> residual_dims;
        for (const fc::CheckRecord& r : check.records) {
          if (r.kind != "residual") continue;
          residual_dims.push_back(r.dim);
          const std::string what = name + "." + r.output + " " + std::to_string(r.dim) + "d (" + label + ")";
          EXPECT_LT(r.hessian_rel_error, 1e-5) << what;
          EXPECT_TRUE(r.taylor_slope_hessian.kind == fc::SlopeResult::Kind::exact ||
                      (r.taylor_slope_hessian.kind == fc::SlopeResult::Kind::fitted && std::abs(r.taylor_slope_hessian.value - 2.0) < 0.3))
              << what << ": Jacobian remainder slope " << r.taylor_slope_hessian.text();
        }
        for (const int d : dims) EXPECT_NE(std::find(residual_dims.begin(), residual_dims.end(), d), residual_dims.end()) << name << " " << d << "d";
      }
    }
  }
}

TEST(ModuleCheck, BuiltinsCoverBothDimensionsAndKinds) {
  // The built-in library must exercise 3D and the axisymmetric geometry, or the test above proves little.
  bool three_d = false, axisymmetric = false, constraint = false;
  for (const auto& name : lmeform::builtin_form_names()) {
    const auto& m = lmeform::load_form(name);
    for (const auto* k : m.kernels) {
      three_d = three_d || k->dim == 3;
      constraint = constraint || k->kind == lmeform::kernel::FunctionalKind::Constraint;
    }
    axisymmetric = axisymmetric || name.find("_axisymmetric") != std::string::npos;
  }
  EXPECT_TRUE(three_d && axisymmetric && constraint);
}

// ---- Corrupted kernels fail, naming the output -------------------------------------------------------

TEST(ModuleCheck, WrongHessianEntryFails) {
  const auto& helfrich = lmeform::load_form("helfrich");
  FormKernels bad = helfrich.at("bending", 2);
  g_original = &helfrich.at("bending", 2);
  bad.matrix = &matrix_with_one_wrong_entry;
  const fc::CheckRecord r = fc::check_kernels(bad, fc::resolve_constants(helfrich.kernels, {}, 1),
                                              fc::Coordinates::cartesian, {});
  EXPECT_FALSE(r.passed);
  EXPECT_EQ(r.status, "fail");
  EXPECT_GT(r.hessian_rel_error, 1e-6);
  EXPECT_GT(r.symmetry_error, 1e-12);
  EXPECT_LT(r.gradient_rel_error, 1e-6) << "the gradient is untouched";
  for (const auto& f : r.failures) std::printf("  %s\n", f.c_str());
}

TEST(ModuleCheck, ScaledGradientOfA3dLagrangianFormFails) {
  const auto& lagrangian = lmeform::load_form("helfrich_lagrangian");
  FormKernels bad = lagrangian.at("bending", 3);
  g_original = &lagrangian.at("bending", 3);
  bad.vector = &vector_scaled;
  const fc::CheckRecord r = fc::check_kernels(bad, fc::resolve_constants(lagrangian.kernels, {}, 1),
                                              fc::Coordinates::cartesian, {});
  EXPECT_FALSE(r.passed);
  EXPECT_GT(r.gradient_rel_error, 1e-4);
  ASSERT_FALSE(r.failures.empty());
  EXPECT_NE(r.failures.front().find("gradient"), std::string::npos) << r.failures.front();
}

TEST(CheckCommand, CorruptedKernelExitsOneNamingTheOutput) {
  FormKernels bad = check_weak_nonlinear_2d;
  g_original = &check_weak_nonlinear_2d;
  bad.matrix = &matrix_with_one_wrong_entry;
  const PatchedModule patched(check_weak_module, bad);
  lmeform::CheckCommandOptions options;
  options.module = &patched.table;
  std::ostringstream out, err;
  options.out = &out;
  options.err = &err;
  EXPECT_EQ(lmeform::run_check_command(options), 1);
  std::printf("%s%s", out.str().c_str(), err.str().c_str());
  EXPECT_NE(out.str().find("FAIL nonlinear 2d"), std::string::npos);
  EXPECT_NE(err.str().find("nonlinear (2d)"), std::string::npos);
  EXPECT_EQ(err.str().find("affine"), std::string::npos) << "only the corrupted output fails";
  EXPECT_EQ(err.str().find("nonlinear (3d)"), std::string::npos);
}

TEST(ModuleCheck, LinearFormThatIsNotLinearFails) {
  FormKernels bad = check_weak_load_2d;
  g_original = &check_weak_load_2d;
  bad.vector = &vector_squared;
  const fc::CheckRecord r = fc::check_kernels(bad, fc::resolve_constants(kernels_of(check_weak_module), {}, 1),
                                              fc::Coordinates::cartesian, {});
  EXPECT_FALSE(r.passed);
  EXPECT_GT(r.linearity_error, 1e-6);
}

TEST(ModuleCheck, BilinearFormReadingTheUnknownsFails) {
  FormKernels bad = check_weak_stiffness_3d;
  g_original = &check_weak_stiffness_3d;
  bad.matrix = &matrix_reading_unknowns;
  const fc::CheckRecord r = fc::check_kernels(bad, fc::resolve_constants(kernels_of(check_weak_module), {}, 1),
                                              fc::Coordinates::cartesian, {});
  EXPECT_FALSE(r.passed);
  EXPECT_GT(r.state_dependence_error, 1e-6);
}

// ---- Residual, bilinear and linear outputs ---------------------------------------------------------

TEST(ModuleCheck, ResidualBilinearAndLinearOutputs) {
  const fc::ModuleCheck check = fc::check_module("check_weak", "", kernels_of(check_weak_module), {});
  std::printf("%s\n", fc::format_table(check).c_str());
  EXPECT_TRUE(check.passed());
  for (const int dim : {2, 3}) {
    const auto* nonlinear = find_record(check, "nonlinear", dim);
    const auto* affine = find_record(check, "affine", dim);
    const auto* stiffness = find_record(check, "stiffness", dim);
    const auto* load = find_record(check, "load", dim);
    ASSERT_TRUE(nonlinear && affine && stiffness && load);
    // A residual: Jacobian against FD of R, its Taylor remainder, linearity in the test function;
    // no value, so no gradient check and no value remainders.
    EXPECT_TRUE(std::isnan(nonlinear->gradient_rel_error));
    EXPECT_LT(nonlinear->hessian_rel_error, 1e-6);
    EXPECT_LT(nonlinear->linearity_error, 1e-10);
    EXPECT_EQ(nonlinear->taylor_slope_gradient.kind, fc::SlopeResult::Kind::not_applicable);
    EXPECT_EQ(nonlinear->taylor_slope_hessian.kind, fc::SlopeResult::Kind::fitted);
    EXPECT_NEAR(nonlinear->taylor_slope_hessian.value, 2.0, 0.2);
    EXPECT_EQ(affine->taylor_slope_hessian.kind, fc::SlopeResult::Kind::exact) << "R affine in T";
    // Bilinear and linear forms: linearity and independence of the unknowns, nothing else.
    for (const auto* r : {stiffness, load}) {
      EXPECT_LT(r->linearity_error, 1e-10);
      EXPECT_EQ(r->state_dependence_error, 0.0);
      EXPECT_TRUE(std::isnan(r->gradient_rel_error) && std::isnan(r->hessian_rel_error));
      EXPECT_EQ(r->taylor_slope_hessian.kind, fc::SlopeResult::Kind::not_applicable);
    }
  }
}

TEST(ModuleCheck, ResidualOfAVectorUnknown) {
  const fc::ModuleCheck check = fc::check_module("check_elastic", "", kernels_of(check_elastic_module), {});
  std::printf("%s\n", fc::format_table(check).c_str());
  EXPECT_TRUE(check.passed());
  for (const auto& r : check.records) EXPECT_GT(r.min_det, 0.5) << r.dim << "d";
}

// ---- Boundary kernels and point outputs --------------------------------------------------------------

TEST(ModuleCheck, BoundaryKernelsAreCheckedWithTheirDomain) {
  const fc::ModuleCheck check = fc::check_module("check_boundary", "", kernels_of(check_boundary_module), {});
  const std::string table = fc::format_table(check);
  std::printf("%s\n", table.c_str());
  EXPECT_TRUE(check.passed());
  EXPECT_EQ(check.records.size(), static_cast<std::size_t>(check_boundary_module.n_kernels));
  for (const int dim : {2, 3}) {
    SCOPED_TRACE(dim);
    const auto* cells = find_record(check, "E", dim, "dx");
    const auto* top = find_record(check, "E", dim, "ds(top)");
    const auto* weighted = find_record(check, "E", dim, "ds");
    const auto* flux = find_record(check, "R", dim, "ds(left)");
    const auto* fourth = find_record(check, "W", dim, "ds");
    const auto* point = find_record(check, "P", dim);
    ASSERT_TRUE(cells && top && weighted && flux && fourth && point);
    EXPECT_EQ(cells->domain, "cells");
    EXPECT_EQ(top->domain, "boundary");
    EXPECT_EQ(top->boundary_part, "top");
    EXPECT_EQ(fc::kernel_label(*top), "E [ds(top)]");
    EXPECT_EQ(weighted->boundary_part, "");
    // The boundary kernels get every check of their kind: gradients, Hessians, Jacobians, slopes.
    for (const auto* r : {top, weighted, fourth}) {
      EXPECT_LT(r->gradient_rel_error, 1e-6) << fc::kernel_label(*r);
      EXPECT_NE(r->taylor_slope_gradient.kind, fc::SlopeResult::Kind::not_applicable);
    }
    EXPECT_EQ(top->taylor_slope_gradient.kind, fc::SlopeResult::Kind::exact) << "linear in u";
    EXPECT_LT(weighted->hessian_rel_error, 1e-6);
    EXPECT_EQ(weighted->taylor_slope_hessian.kind, fc::SlopeResult::Kind::exact) << "quadratic in u";
    EXPECT_LT(fourth->hessian_rel_error, 1e-6);
    EXPECT_NEAR(fourth->taylor_slope_second_order.value, 3.0, 0.2);
    EXPECT_LT(flux->hessian_rel_error, 1e-6);
    EXPECT_LT(flux->linearity_error, 1e-10);
    EXPECT_EQ(point->kind, "point");
    EXPECT_EQ(point->status, "pass");
    EXPECT_NE(std::find(point->notes.begin(), point->notes.end(), "point output, evaluated (finite)"), point->notes.end());
  }
  EXPECT_NE(table.find("E [ds(top)]"), std::string::npos);
  EXPECT_NE(table.find("R [ds(left)]"), std::string::npos);
  EXPECT_NE(table.find("[ds...]: a boundary kernel"), std::string::npos);
}

TEST(CheckCommand, JsonNamesTheDomainOfEachKernel) {
  const fs::path json = fs::temp_directory_path() / "lmeform_check_boundary.json";
  lmeform::CheckCommandOptions o;
  o.module = &check_boundary_module;
  o.json = json.string();
  std::ostringstream out, err;
  o.out = &out;
  o.err = &err;
  EXPECT_EQ(lmeform::run_check_command(o), 0) << out.str() << err.str();
  const auto records = nlohmann::json::parse(std::ifstream(json));
  ASSERT_EQ(records.size(), static_cast<std::size_t>(check_boundary_module.n_kernels));
  std::vector<std::string> labels;
  for (const auto& r : records) {
    for (const char* key : {"domain", "boundary_part", "measure", "label"}) EXPECT_TRUE(r.contains(key)) << key;
    labels.push_back(r["label"].get<std::string>() + " " + std::to_string(r["dim"].get<int>()) + "d");
    if (r["domain"] == "boundary") {
      EXPECT_EQ(r["measure"].get<std::string>().substr(0, 2), "ds");
    }
  }
  for (const char* label : {"energy E 2d", "energy E [ds(top)] 2d", "energy E [ds] 3d", "residual R [ds(left)] 3d",
                            "energy W [ds] 2d", "point P 3d"})
    EXPECT_NE(std::find(labels.begin(), labels.end(), label), labels.end()) << label;
}

TEST(CheckCommand, BoundaryFormByPathIsCompiledAndChecked) {
  const fs::path cache = fs::temp_directory_path() / "lmeform_check_test_cache";
  ::setenv("LMEFORM_CACHE_DIR", cache.c_str(), 1);
  const fs::path json = fs::temp_directory_path() / "lmeform_check_boundary_jit.json";
  lmeform::CheckCommandOptions o;
  o.form = std::string(LMEFORM_CHECK_TEST_FORMS) + "/check_boundary.form";
  o.json = json.string();
  std::ostringstream out, err;
  o.out = &out;
  o.err = &err;
  const int code = lmeform::run_check_command(o);
  std::printf("%s%s", out.str().c_str(), err.str().c_str());
  EXPECT_EQ(code, 0);
  const auto records = nlohmann::json::parse(std::ifstream(json));
  int boundary_2d = 0, boundary_3d = 0;
  for (const auto& r : records)
    if (r["domain"] == "boundary") (r["dim"] == 2 ? boundary_2d : boundary_3d) += 1;
  EXPECT_EQ(boundary_2d, 4);  // E [ds(top)], E [ds], R [ds(left)], W [ds]
  EXPECT_EQ(boundary_3d, 4);
}

TEST(CheckCommand, CorruptedBoundaryKernelFailsNamingItsDomain) {
  FormKernels bad = check_boundary_R_ds_left_2d;
  g_original = &check_boundary_R_ds_left_2d;
  bad.matrix = &matrix_with_one_wrong_entry;
  const PatchedModule patched(check_boundary_module, bad);
  lmeform::CheckCommandOptions options;
  options.module = &patched.table;
  std::ostringstream out, err;
  options.out = &out;
  options.err = &err;
  EXPECT_EQ(lmeform::run_check_command(options), 1);
  std::printf("%s%s", out.str().c_str(), err.str().c_str());
  EXPECT_NE(out.str().find("FAIL R [ds(left)] 2d"), std::string::npos);
  EXPECT_NE(err.str().find("R [ds(left)] (2d)"), std::string::npos);
  EXPECT_EQ(err.str().find("R (2d)"), std::string::npos) << "the cells' kernel of R is untouched";
}

TEST(FormCheck, PointKernelMustWriteFiniteValues) {
  const fc::CheckGeometry geometry(fc::GeometryOptions{});
  const fc::Cell cell = geometry.check_cells(2).front();
  fc::State state;
  state.unknowns.assign(static_cast<std::size_t>(cell.n), 0.5);
  state.constants = {1.5};
  FormKernels silent = check_boundary_P_2d;
  silent.point = [](const CellInputs&, double*) {};  // writes nothing
  const fc::Report rep = fc::check_form(silent, cell, state, {}, fc::Options{});
  ASSERT_FALSE(rep.ok());
  EXPECT_NE(rep.failures.front().find("not written, or not finite"), std::string::npos) << rep.failures.front();
  FormKernels greedy = check_boundary_P_2d;
  greedy.n_values = 1;  // the kernel writes two per point
  EXPECT_THROW((void)fc::check_form(greedy, cell, state, {}, fc::Options{}), std::runtime_error);
  EXPECT_TRUE(fc::check_form(check_boundary_P_2d, cell, state, {}, fc::Options{}).ok());
}

// ---- Non-smooth forms ----------------------------------------------------------------------------

TEST(ModuleCheck, NonSmoothFormReportsKinksNotFailures) {
  const fc::ModuleCheck check = fc::check_module("check_kinks", "", kernels_of(check_kinks_module), {});
  std::printf("%s\n", fc::format_table(check).c_str());
  EXPECT_TRUE(check.passed());
  int kinked = 0;
  for (const auto& r : check.records) kinked += r.status == "kink" ? 1 : 0;
  EXPECT_GT(kinked, 0) << "the random perturbations cross kinks of abs(sin(20 phi)) and max(phi, 0.2)";
  const auto* absolute = find_record(check, "absolute", 2);
  ASSERT_TRUE(absolute);
  EXPECT_EQ(absolute->status, "kink");
  ASSERT_FALSE(absolute->kinks.empty());
  EXPECT_NE(absolute->kinks.front().find("Taylor direction"), std::string::npos) << absolute->kinks.front();
}

TEST(FormCheck, KinksAndJumpsAtTheStateAreReportedNotFailed) {
  // phi = threshold + 1e-9 (x - x_cell) / h at the nodes, so the quadrature points sit on both sides
  // of the kink of max(phi, 0.2) or the jump of `if phi > 0.3`, 1e-9 away: every finite difference
  // and the Taylor direction (increasing phi everywhere) cross it right at the state.
  const fc::CheckGeometry geometry(fc::GeometryOptions{});
  const fc::Cell cell = geometry.check_cells(2).front();
  struct Case { const FormKernels* form; double threshold; const char* label; };
  for (const Case& c : {Case{&check_kinks_clipped_2d, 0.2, "max(phi, 0.2)^2 at its kink"},
                        Case{&check_kinks_switched_2d, 0.3, "if phi > 0.3 at its jump"}}) {
    fc::State state;
    const double x_cell = cell.points[0];
    for (int a = 0; a < cell.n; ++a)
      state.unknowns.push_back(c.threshold + 1e-9 * (cell.nodes[static_cast<std::size_t>(a) * 2] - x_cell) / geometry.h_min());
    state.constants = std::vector<double>(static_cast<std::size_t>(c.form->n_constants), 0.2);
    const std::vector<double> direction(static_cast<std::size_t>(cell.n), 1.0);
    const fc::Report rep = fc::check_form(*c.form, cell, state, direction, fc::Options{});
    std::printf("%s\n", rep.summary(c.label).c_str());
    EXPECT_TRUE(rep.ok()) << c.label;
    const auto lines = fc::describe_kinks(rep.kinks);
    auto mentions = [&](const char* what) {
      return std::any_of(lines.begin(), lines.end(), [&](const std::string& l) { return l.find(what) != std::string::npos; });
    };
    EXPECT_TRUE(mentions("FD of the value")) << c.label;
    EXPECT_TRUE(mentions("Taylor direction")) << c.label;
    // Without kink detection the same check fails: the detection is what saves it.
    fc::Options blind;
    blind.detect_kinks = false;
    EXPECT_FALSE(fc::check_form(*c.form, cell, state, direction, blind).ok()) << c.label;
  }
}

// ---- Setup: cells and states ---------------------------------------------------------------------

TEST(CheckSetup, GradedCellsInEveryGeometry) {
  for (const int dim : {1, 2, 3})
    for (const auto coordinates : {fc::Coordinates::cartesian, fc::Coordinates::axisymmetric}) {
      if (dim == 1 && coordinates == fc::Coordinates::axisymmetric) continue;
      fc::GeometryOptions go;
      go.dim = dim;
      go.coordinates = coordinates;
      const fc::CheckGeometry g(go);
      const auto cells = g.check_cells(2);
      ASSERT_EQ(cells.size(), 2u);
      double h_lo = 1e300, h_hi = 0;
      for (const double h : g.basis().spacing()) { h_lo = std::min(h_lo, h); h_hi = std::max(h_hi, h); }
      std::printf("%dD %s: %zu nodes, %zu cells, spacing %.3f .. %.3f, check cells n = %d, %d (nq = %d)\n", dim,
                  fc::to_string(coordinates), g.nodes().size(), g.cells().size(), h_lo, h_hi, cells[0].n, cells[1].n,
                  cells[0].nq);
      EXPECT_GT(h_hi / h_lo, 2.0) << "strongly graded";
      if (coordinates == fc::Coordinates::axisymmetric && dim > 1) {
        const fc::Cell off_axis = g.check_cells(2, true).back();
        std::mt19937_64 rng(5);
        const auto y = fc::near_identity_field(off_axis, 0.1, 0.001, coordinates, rng);
        EXPECT_GT(fc::min_det_grad(off_axis, y, dim, 0), 0.5) << "the cell off the axis for vector fields";
      }
      for (const auto& cell : cells) {
        // A partition of unity that reproduces linear fields, at points inside the domain.
        for (int q = 0; q < cell.nq; ++q) {
          double sum = 0.0;
          for (int a = 0; a < cell.n; ++a) sum += cell.basis[static_cast<std::size_t>(q) * lmeform::kernel::jet_size(dim, 2) * cell.n + a];
          EXPECT_NEAR(sum, 1.0, 1e-10);
          if (coordinates == fc::Coordinates::axisymmetric) {
            EXPECT_GT(cell.points[static_cast<std::size_t>(q) * dim], 0.0);
          }
        }
        std::mt19937_64 rng(5);
        const auto y = fc::near_identity_field(cell, 0.1, 0.001, coordinates, rng);
        // Vector fields meet the axis cell only where it is off the axis (check_cells(order, true)).
        if (dim > 1 && (coordinates == fc::Coordinates::cartesian || &cell == &cells.front())) {
          EXPECT_GT(fc::min_det_grad(cell, y, dim, 0), 0.5);
        }
        const auto phi = fc::smooth_scalar_field(cell, g.feature(), 2 * g.h_min(), 0.05, rng);
        for (const double p : phi) EXPECT_LT(std::abs(p), 1.0);
      }
    }
}

TEST(CheckSetup, QdataFollowsTheDeclaredSizes) {
  const fc::CheckGeometry g(fc::GeometryOptions{});
  const fc::Cell cell = g.check_cells(2).front();
  std::mt19937_64 rng(1);
  const auto phi = fc::smooth_scalar_field(cell, g.feature(), 0.06, 0.05, rng);
  const auto qd = fc::reference_qdata(cell, phi);  // phi0, gphi0, hphi0
  ASSERT_EQ(qd.size(), static_cast<std::size_t>(cell.nq) * 7);
  EXPECT_DOUBLE_EQ(qd[0], cell.jet(0, 0, phi.data(), 1, 0));
  EXPECT_DOUBLE_EQ(qd[2], cell.jet(0, 2, phi.data(), 1, 0));
  EXPECT_DOUBLE_EQ(qd[4], qd[5]) << "the Hessian is symmetric";
}

// ---- Constants and coordinates ----------------------------------------------------------------

TEST(ModuleCheck, ConstantsFromSetDefaultsOrRandom) {
  const auto& helfrich = lmeform::load_form("helfrich");  // constant k = 1, eps, C0 = 0
  const auto c = fc::resolve_constants(helfrich.kernels, {{"eps", 0.02}}, 7);
  ASSERT_EQ(c.size(), 3u);
  EXPECT_EQ(c[0].name, "k");
  EXPECT_EQ(c[0].value, 1.0);
  EXPECT_EQ(c[0].origin, "default");
  EXPECT_EQ(c[1].value, 0.02);
  EXPECT_EQ(c[1].origin, "--set");
  const auto r = fc::resolve_constants(helfrich.kernels, {}, 7);
  EXPECT_EQ(r[1].origin, "random");
  EXPECT_NEAR(r[1].value, 1.0, 0.2);
  try {
    (void)fc::resolve_constants(helfrich.kernels, {{"kappa", 1.0}}, 7);
    FAIL() << "unknown constant accepted";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("k, eps, C0"), std::string::npos) << e.what();
  }
}

TEST(ModuleCheck, DefaultCoordinatesRule) {
  const auto& eulerian = lmeform::load_form("helfrich");
  const auto& axi = lmeform::load_form("area_axisymmetric");
  EXPECT_EQ(fc::default_coordinates(eulerian.name, eulerian.source, {}), fc::Coordinates::cartesian);
  EXPECT_EQ(fc::default_coordinates(axi.name, axi.source, {}), fc::Coordinates::axisymmetric);
  // By the include, whatever the name.
  const fs::path dir = fs::temp_directory_path() / "lmeform_check_coordinates";
  fs::create_directories(dir);
  std::ofstream(dir / "ring.form") << "form ring\ninclude \"axisymmetric.inc\"  # r, z\nunknown u\nenergy e = u^2*dA\n";
  std::ofstream(dir / "commented.form") << "form commented\n# include \"axisymmetric.inc\"\nunknown u\n";
  std::string why;
  EXPECT_EQ(fc::default_coordinates("ring", dir / "ring.form", {}, &why), fc::Coordinates::axisymmetric);
  EXPECT_EQ(why, "source includes axisymmetric.inc");
  EXPECT_EQ(fc::default_coordinates("commented", dir / "commented.form", {}), fc::Coordinates::cartesian);
}

// ---- The command ---------------------------------------------------------------------------------

TEST(CheckCommand, ParsesItsFlags) {
  CLI::App app;
  lmeform::CheckCommandOptions o;
  CLI::App* cmd = lmeform::add_check_subcommand(app, o);
  const char* argv[] = {"lmeform", "check", "--dim", "2", "--set", "eps=0.02", "--set", "k=2", "--output",
                        "bending", "--coordinates", "cartesian", "--seed", "9", "--json", "out.json", "-I",
                        "inc", "--perturbation", "0.05", "--interface-width", "0.1", "helfrich"};
  app.parse(static_cast<int>(std::size(argv)), argv);
  EXPECT_TRUE(cmd->parsed());
  EXPECT_EQ(o.form, "helfrich");
  EXPECT_EQ(o.dims, std::vector<int>{2});
  EXPECT_EQ(o.sets, (std::vector<std::string>{"eps=0.02", "k=2"}));
  EXPECT_EQ(o.outputs, std::vector<std::string>{"bending"});
  EXPECT_EQ(o.coordinates, "cartesian");
  EXPECT_EQ(o.seed, 9u);
  EXPECT_EQ(o.json, "out.json");
  EXPECT_EQ(o.include_dirs, std::vector<std::string>{"inc"});
  EXPECT_EQ(o.perturbation, 0.05);
  EXPECT_EQ(o.interface_width, 0.1);
}

TEST(CheckCommand, BuiltinByNameWritesJsonRecords) {
  const fs::path json = fs::temp_directory_path() / "lmeform_check_poisson.json";
  lmeform::CheckCommandOptions o;
  o.form = "poisson";
  o.json = json.string();
  std::ostringstream out, err;
  o.out = &out;
  o.err = &err;
  EXPECT_EQ(lmeform::run_check_command(o), 0) << out.str() << err.str();
  std::printf("%s", out.str().c_str());
  const auto records = nlohmann::json::parse(std::ifstream(json));
  ASSERT_TRUE(records.is_array());
  ASSERT_EQ(records.size(), 2u);  // heat in 2D and 3D
  for (const auto& r : records) {
    for (const char* key : {"form", "output", "kind", "dim", "gradient_rel_error", "hessian_rel_error",
                            "taylor_slope_gradient", "taylor_slope_hessian", "passed"})
      EXPECT_TRUE(r.contains(key)) << key;
    EXPECT_EQ(r["form"], "poisson");
    EXPECT_EQ(r["kind"], "energy");
    EXPECT_TRUE(r["passed"].get<bool>());
    EXPECT_EQ(r["taylor_slope_hessian"], "exact") << "a quadratic energy";
    EXPECT_NEAR(r["taylor_slope_gradient"].get<double>(), 2.0, 0.2);
  }
}

TEST(CheckCommand, UsageErrorsExitTwo) {
  std::ostringstream out, err;
  lmeform::CheckCommandOptions o;
  o.out = &out;
  o.err = &err;
  o.form = "helfrich";
  o.sets = {"kappa=1"};
  EXPECT_EQ(lmeform::run_check_command(o), 2);
  EXPECT_NE(err.str().find("k, eps, C0"), std::string::npos) << err.str();
  o.sets = {"eps=abc"};
  EXPECT_EQ(lmeform::run_check_command(o), 2);
  o.sets = {};
  o.outputs = {"energy"};
  EXPECT_EQ(lmeform::run_check_command(o), 2);
  EXPECT_NE(err.str().find("outputs: bending"), std::string::npos) << err.str();
  o.outputs = {};
  o.form = "no_such_module";
  EXPECT_EQ(lmeform::run_check_command(o), 2);
  // A scene given to check is named as one, not parsed as a form.
  o.form = "demos/my_scene.toml";
  EXPECT_EQ(lmeform::run_check_command(o), 2);
  EXPECT_NE(err.str().find("demos/my_scene.toml is a scene (TOML)"), std::string::npos) << err.str();
  EXPECT_NE(err.str().find("lmeform run demos/my_scene.toml"), std::string::npos) << err.str();
}

TEST(CheckCommand, FormByPathIsCompiledAndChecked) {
  const fs::path cache = fs::temp_directory_path() / "lmeform_check_test_cache";
  ::setenv("LMEFORM_CACHE_DIR", cache.c_str(), 1);
  lmeform::CheckCommandOptions o;
  o.form = std::string(LMEFORM_CHECK_TEST_FORMS) + "/check_weak.form";
  o.dims = {2};
  o.sets = {"c=0.5"};
  std::ostringstream out, err;
  o.out = &out;
  o.err = &err;
  const int code = lmeform::run_check_command(o);
  std::printf("%s%s", out.str().c_str(), err.str().c_str());
  EXPECT_EQ(code, 0);
  EXPECT_NE(out.str().find("c = 0.5 (--set)"), std::string::npos);
}
