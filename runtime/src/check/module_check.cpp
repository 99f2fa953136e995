#include "lmeform/module_check.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <fstream>
#include <functional>
#include <map>
#include <memory>
#include <mutex>
#include <regex>
#include <set>
#include <sstream>
#include <tuple>
#include <stdexcept>

#include <fmt/format.h>
#include <nlohmann/json.hpp>

namespace lmeform::formcheck {

namespace fs = std::filesystem;
using kernel::FormKernels;
using kernel::FunctionalKind;

std::string kernel_label(const CheckRecord& record) {
  return record.domain == "boundary" ? record.output + " [" + record.measure + "]" : record.output;
}

std::string SlopeResult::text() const {
  switch (kind) {
    case Kind::not_applicable: return "n/a";
    case Kind::exact: return "exact";
    case Kind::kink: return "kink";
    case Kind::fitted: return fmt::format("{:.2f}", value);
  }
  return "?";
}

bool ModuleCheck::passed() const {
  return std::all_of(records.begin(), records.end(), [](const CheckRecord& r) { return r.passed; });
}

// ---- Coordinates ---------------------------------------------------------------------------------

namespace {

/// Whether `file` includes axisymmetric.inc, directly or through the files it includes.
bool includes_axisymmetric(const fs::path& file, const std::vector<fs::path>& include_dirs, std::set<fs::path>& seen) {
  std::error_code ec;
  const fs::path canonical = fs::weakly_canonical(file, ec);
  if (!seen.insert(ec ? file : canonical).second) return false;
  std::ifstream in(file);
  if (!in) return false;
  static const std::regex include_statement(R"(\binclude\s+"([^"]+)\")");
  std::string line;
  while (std::getline(in, line)) {
    line = line.substr(0, line.find('#'));
    std::smatch m;
    if (!std::regex_search(line, m, include_statement)) continue;
    const fs::path name = m[1].str();
    if (name.filename() == "axisymmetric.inc") return true;
    std::vector<fs::path> candidates{file.parent_path() / name};
    for (const auto& dir : include_dirs) candidates.push_back(dir / name);
    for (const auto& c : candidates)
      if (fs::exists(c, ec)) {
        if (includes_axisymmetric(c, include_dirs, seen)) return true;
        break;
      }
  }
  return false;
}

}  // namespace

Coordinates default_coordinates(const std::string& module, const fs::path& source,
                                const std::vector<fs::path>& include_dirs, std::string* reason) {
  auto say = [&](const std::string& why) {
    if (reason) *reason = why;
  };
  const std::string suffix = "_axisymmetric";
  if (module.size() > suffix.size() && module.compare(module.size() - suffix.size(), suffix.size(), suffix) == 0) {
    say("module name ends in _axisymmetric");
    return Coordinates::axisymmetric;
  }
  std::set<fs::path> seen;
  if (!source.empty() && includes_axisymmetric(source, include_dirs, seen)) {
    say("source includes axisymmetric.inc");
    return Coordinates::axisymmetric;
  }
  say(source.empty() || !fs::exists(source) ? "default (source not readable)" : "default (no axisymmetric.inc)");
  return Coordinates::cartesian;
}

// ---- Constants -----------------------------------------------------------------------------------

namespace {

std::uint64_t text_hash(const std::string& s) {
  // FNV-1a: stable across runs and platforms (std::hash is not), so a seed gives the same values.
  std::uint64_t h = 1469598103934665603ULL;
  for (const unsigned char c : s) h = (h ^ c) * 1099511628211ULL;
  return h;
}

std::mt19937_64 seeded(std::uint64_t seed, const std::string& what) {
  std::seed_seq seq{static_cast<std::uint32_t>(seed), static_cast<std::uint32_t>(seed >> 32),
                    static_cast<std::uint32_t>(text_hash(what)), static_cast<std::uint32_t>(text_hash(what) >> 32)};
  return std::mt19937_64(seq);
}

}  // namespace

std::vector<ConstantChoice> resolve_constants(std::span<const FormKernels* const> kernels,
                                              const std::vector<std::pair<std::string, double>>& user,
                                              std::uint64_t seed) {
  std::vector<ConstantChoice> out;
  for (const FormKernels* k : kernels)
    for (int i = 0; i < k->n_constants; ++i) {
      const std::string name = k->constants[i];
      if (std::any_of(out.begin(), out.end(), [&](const ConstantChoice& c) { return c.name == name; })) continue;
      ConstantChoice c{name, 0.0, ""};
      const double fallback = k->constant_defaults ? k->constant_defaults[i] : std::nan("");
      if (!std::isnan(fallback)) {
        c.value = fallback;
        c.origin = "default";
      } else {
        std::mt19937_64 rng = seeded(seed, "constant " + name);
        c.value = 1.0 + 0.2 * std::uniform_real_distribution<double>(-1.0, 1.0)(rng);
        c.origin = "random";
      }
      out.push_back(c);
    }
  for (const auto& [name, value] : user) {
    auto it = std::find_if(out.begin(), out.end(), [&](const ConstantChoice& c) { return c.name == name; });
    if (it == out.end()) {
      std::string names;
      for (const auto& c : out) names += (names.empty() ? "" : ", ") + c.name;
      throw std::invalid_argument(fmt::format("--set {}: the form has no constant '{}' (its constants: {})", name, name,
                                              names.empty() ? "none" : names));
    }
    it->value = value;
    it->origin = "--set";
  }
  return out;
}

// ---- One output in one dimension -----------------------------------------------------------------

namespace {

/// The geometry and check cells of one dimension and coordinate system, built once per process.
struct CheckSite {
  std::unique_ptr<CheckGeometry> geometry;
  std::vector<Cell> cells;                // for forms of scalar fields only
  std::vector<Cell> vector_field_cells;   // for forms with a vector field (off the axis)
};

const CheckSite& check_site(int dim, Coordinates coordinates, LmeConsistency basis) {
  static std::mutex mutex;
  static std::map<std::tuple<int, Coordinates, LmeConsistency>, CheckSite> sites;
  const std::lock_guard<std::mutex> lock(mutex);
  auto& site = sites[{dim, coordinates, basis}];
  if (!site.geometry) {
    GeometryOptions go;
    go.dim = dim;
    go.coordinates = coordinates;
    go.basis = basis;
    site.geometry = std::make_unique<CheckGeometry>(go);
    site.cells = site.geometry->check_cells(2, false);
    site.vector_field_cells = site.geometry->check_cells(2, true);
  }
  return site;
}

/// Keeps the slope farthest from its expected value over the cells.
void merge_slope(SlopeResult& acc, const Remainder& r, double expected) {
  if (!r.computed()) return;
  SlopeResult s;
  int usable = 0;
  for (const double h : r.h) usable += h < r.h_limit ? 1 : 0;
  if (std::isfinite(r.h_limit) && usable < 3) s.kind = SlopeResult::Kind::kink;
  else if (r.exact) s.kind = SlopeResult::Kind::exact;
  else { s.kind = SlopeResult::Kind::fitted; s.value = r.slope; }
  using K = SlopeResult::Kind;
  // Worst first: an unfittable slope, then the farthest from expected, a kink, exact.
  auto rank = [&](const SlopeResult& x) {
    if (x.kind == K::fitted) return std::isnan(x.value) ? 1e300 : 2.0 + std::abs(x.value - expected);
    return x.kind == K::kink ? 1.0 : x.kind == K::exact ? 0.5 : 0.0;
  };
  if (rank(s) > rank(acc)) acc = s;
}

double worst(double acc, double x) {
  if (std::isnan(x)) return acc;
  if (std::isnan(acc)) return x;
  return std::max(acc, x);
}

double flops(const FormKernels::FlopModel& model, double per_cell_estimate, int n, int nq) {
  const double f = model(n, nq);
  return f > 0 ? f : per_cell_estimate * n * nq;
}

}  // namespace

CheckRecord check_kernels(const FormKernels& form, const std::vector<ConstantChoice>& constants, Coordinates coordinates,
                          const ModuleCheckOptions& options) {
  const auto t0 = std::chrono::steady_clock::now();
  CheckRecord rec;
  rec.form = form.module;
  rec.output = form.name;
  rec.kind = to_string(form.kind);
  const bool boundary = form.domain == kernel::IntegralDomain::Boundary;
  rec.domain = boundary ? "boundary" : "cells";
  rec.boundary_part = boundary && form.boundary_part != nullptr ? form.boundary_part : "";
  rec.measure = form.kind == FunctionalKind::Point ? "" : !boundary ? "dx" : rec.boundary_part.empty() ? "ds" : "ds(" + rec.boundary_part + ")";
  rec.dim = form.dim;
  rec.coordinates = to_string(coordinates);
  std::vector<double> values;
  for (int i = 0; i < form.n_constants; ++i) {
    const auto it = std::find_if(constants.begin(), constants.end(),
                                 [&](const ConstantChoice& c) { return c.name == form.constants[i]; });
    if (it == constants.end())
      throw std::invalid_argument(fmt::format("{}::{}: no value for constant '{}'", form.module, form.name, form.constants[i]));
    values.push_back(it->value);
  }
  try {
    const CheckSite& site = check_site(form.dim, coordinates, options.basis);
    bool vector_fields = false;
    for (int i = 0; i < form.n_unknowns; ++i) vector_fields = vector_fields || (form.dim > 1 && form.unknowns[i].components == form.dim);
    for (int i = 0; i < form.n_coefficients; ++i)
      vector_fields = vector_fields || (form.dim > 1 && form.coefficients[i].components == form.dim);
    if (vector_fields && coordinates == Coordinates::axisymmetric)
      rec.notes.push_back("vector fields: the near-axis cell is a row off the axis (the mirrored basis is even in r, "
                          "so det grad y -> 0 on the axis for any nodal values)");
    const std::vector<Cell>& cells = vector_fields ? site.vector_field_cells : site.cells;
    for (std::size_t k = 0; k < cells.size(); ++k) {
      Cell cell = cells[k];
      if (boundary) cell.normals = radial_normals(cell, site.geometry->feature());
      rec.cells += 1;
      rec.max_nodes = std::max(rec.max_nodes, cell.n);
      rec.points = cell.nq;
      std::mt19937_64 rng = seeded(options.seed, fmt::format("{}::{} {}d cell {}", form.module, form.name, form.dim, k));
      const CheckCase cc = generic_case(form, cell, *site.geometry, values, options.states, rng);
      if (!std::isnan(cc.min_det)) rec.min_det = std::isnan(rec.min_det) ? cc.min_det : std::min(rec.min_det, cc.min_det);
      Options opt = options.checks;
      opt.dof_scales = cc.dof_scales;
      const Report rep = check_form(form, cell, cc.state, cc.direction, opt);
      rec.gradient_rel_error = worst(rec.gradient_rel_error, rep.grad_err);
      rec.hessian_rel_error = worst(rec.hessian_rel_error, rep.hess_err);
      rec.symmetry_error = worst(rec.symmetry_error, rep.hess_asym);
      rec.linearity_error = worst(rec.linearity_error, rep.linearity_err);
      rec.state_dependence_error = worst(rec.state_dependence_error, rep.state_dependence);
      merge_slope(rec.taylor_slope_gradient, rep.r1, 2.0);
      merge_slope(rec.taylor_slope_second_order, rep.r2, 3.0);
      merge_slope(rec.taylor_slope_hessian, rep.r3, 2.0);
      for (const std::string& kink : describe_kinks(rep.kinks)) rec.kinks.push_back(fmt::format("cell {}: {}", k, kink));
      for (const std::string& note : rep.notes) rec.notes.push_back(fmt::format("cell {}: {}", k, note));
      for (const std::string& f : rep.failures) rec.failures.push_back(fmt::format("cell {} (n = {}): {}", k, cell.n, f));
    }
  } catch (const std::exception& e) {
    rec.failures.push_back(std::string("could not be checked: ") + e.what());
  }
  // A point output's kernel cost is given as the value's (kernel.hpp).
  if (form.value || form.point) rec.flops_value = flops(form.flop_model_value, form.flops_value, rec.max_nodes, rec.points);
  if (form.vector) rec.flops_vector = flops(form.flop_model_vector, form.flops_vector, rec.max_nodes, rec.points);
  if (form.matrix) rec.flops_matrix = flops(form.flop_model_matrix, form.flops_matrix, rec.max_nodes, rec.points);
  rec.passed = rec.failures.empty();
  if (form.kind == FunctionalKind::Point && rec.passed) rec.notes.push_back("point output, evaluated (finite)");
  rec.status = !rec.passed ? "fail" : rec.kinks.empty() ? "pass" : "kink";
  rec.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  return rec;
}

ModuleCheck check_module(const std::string& module, const fs::path& source, std::span<const FormKernels* const> kernels,
                         const ModuleCheckOptions& options, const std::vector<fs::path>& include_dirs) {
  const auto t0 = std::chrono::steady_clock::now();
  ModuleCheck mc;
  mc.module = module;
  mc.source = source;
  mc.basis = options.basis;
  if (options.coordinates) {
    mc.coordinates = *options.coordinates;
    mc.coordinates_reason = "--coordinates";
  } else {
    mc.coordinates = default_coordinates(module, source, include_dirs, &mc.coordinates_reason);
  }
  std::vector<std::string> outputs;
  std::vector<int> dims;
  for (const FormKernels* k : kernels) {
    if (std::find(outputs.begin(), outputs.end(), k->name) == outputs.end()) outputs.emplace_back(k->name);
    if (std::find(dims.begin(), dims.end(), k->dim) == dims.end()) dims.push_back(k->dim);
  }
  std::sort(dims.begin(), dims.end());
  auto list = [](const auto& xs) {
    std::string s;
    for (const auto& x : xs) s += (s.empty() ? "" : ", ") + fmt::format("{}", x);
    return s;
  };
  for (const auto& o : options.outputs)
    if (std::find(outputs.begin(), outputs.end(), o) == outputs.end())
      throw std::invalid_argument(fmt::format("--output {}: module '{}' has no such output (outputs: {})", o, module, list(outputs)));
  for (const int d : options.dims)
    if (std::find(dims.begin(), dims.end(), d) == dims.end())
      throw std::invalid_argument(fmt::format("--dim {}: module '{}' is not declared for it (dimensions: {})", d, module, list(dims)));
  mc.constants = resolve_constants(kernels, options.constants, options.seed);
  for (const FormKernels* k : kernels) {
    const bool output_selected = options.outputs.empty() ||
                                 std::find(options.outputs.begin(), options.outputs.end(), k->name) != options.outputs.end();
    const bool dim_selected = options.dims.empty() || std::find(options.dims.begin(), options.dims.end(), k->dim) != options.dims.end();
    if (output_selected && dim_selected) mc.records.push_back(check_kernels(*k, mc.constants, mc.coordinates, options));
  }
  if (mc.records.empty())
    throw std::invalid_argument(fmt::format("module '{}': nothing selected (outputs: {}; dimensions: {})", module,
                                            list(outputs), list(dims)));
  mc.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  return mc;
}

// ---- Output --------------------------------------------------------------------------------------

namespace {

std::string error_text(double x) { return std::isnan(x) ? "n/a" : fmt::format("{:.1e}", x); }
std::string flop_text(double x) { return std::isnan(x) ? "-" : fmt::format("{:.3g}", x); }

}  // namespace

std::string format_table(const ModuleCheck& mc) {
  std::ostringstream os;
  os << fmt::format("lmeform check {} ({})\n", mc.module, mc.source.empty() ? "source unknown" : mc.source.string());
  os << fmt::format("  coordinates: {} ({}); basis: {} order", to_string(mc.coordinates), mc.coordinates_reason, to_string(mc.basis));
  if (!mc.provenance.empty()) os << "; module: " << mc.provenance;
  os << "\n";
  if (!mc.constants.empty()) {
    os << "  constants:";
    for (std::size_t i = 0; i < mc.constants.size(); ++i)
      os << fmt::format("{} {} = {:.6g} ({})", i ? "," : "", mc.constants[i].name, mc.constants[i].value,
                        mc.constants[i].origin);
    os << "\n";
  }
  // Linearity column: in the test functions (residual, bilinear, linear), or independence of the
  // unknowns (bilinear, linear), whichever is worse.
  os << fmt::format("\n{:<16} {:<10} {:>3} {:>5} {:>5} {:>9} {:>9} {:>9} {:>9} {:>6} {:>6} {:>6}  {}\n", "output", "kind",
                    "dim", "cells", "nodes", "grad err", "hess err", "sym err", "lin err", "r1", "r2", "r3", "status");
  for (const CheckRecord& r : mc.records) {
    const double lin = std::isnan(r.linearity_error) ? r.state_dependence_error
                       : std::isnan(r.state_dependence_error) ? r.linearity_error
                                                              : std::max(r.linearity_error, r.state_dependence_error);
    os << fmt::format("{:<16} {:<10} {:>3} {:>5} {:>5} {:>9} {:>9} {:>9} {:>9} {:>6} {:>6} {:>6}  {}\n", kernel_label(r), r.kind,
                      r.dim, r.cells, r.max_nodes, error_text(r.gradient_rel_error), error_text(r.hessian_rel_error),
                      error_text(r.symmetry_error), error_text(lin), r.taylor_slope_gradient.text(),
                      r.taylor_slope_second_order.text(), r.taylor_slope_hessian.text(),
                      r.status == "fail" ? "FAIL" : r.status);
  }
  os << "  r1 = |E(u+hv)-E-h g.v| (slope 2), r2 = |r1 - h^2/2 vHv| (slope 3), r3 = |g(u+hv)-g-h Hv| "
        "(residual: R, J; slope 2)\n";
  if (std::any_of(mc.records.begin(), mc.records.end(), [](const CheckRecord& r) { return r.domain == "boundary"; }))
    os << "  [ds...]: a boundary kernel, checked at the cells' quadrature points with the outward normals of spheres "
          "about the feature's centre\n";
  for (const CheckRecord& r : mc.records) {
    for (const auto& n : r.notes) os << fmt::format("  note {} {}d: {}\n", kernel_label(r), r.dim, n);
    for (const auto& k : r.kinks) os << fmt::format("  kink {} {}d: {}\n", kernel_label(r), r.dim, k);
    for (const auto& f : r.failures) os << fmt::format("  FAIL {} {}d: {}\n", kernel_label(r), r.dim, f);
  }
  const std::string compile = mc.builtin         ? "built-in"
                              : mc.cache_hit     ? "cache hit"
                              : mc.compile_seconds > 0 ? fmt::format("{:.2f} s", mc.compile_seconds)
                                                       : "-";
  os << fmt::format("\n{:<16} {:>3} {:>5} {:>4} {:>10} {:>10} {:>10} {:>11} {:>9}\n", "kernel", "dim", "n", "nq",
                    "value", "vector", "matrix", "JIT compile", "check");
  for (const CheckRecord& r : mc.records)
    os << fmt::format("{:<16} {:>3} {:>5} {:>4} {:>10} {:>10} {:>10} {:>11} {:>8.2f}s\n", kernel_label(r), r.dim, r.max_nodes,
                      r.points, flop_text(r.flops_value), flop_text(r.flops_vector), flop_text(r.flops_matrix), compile,
                      r.seconds);
  os << "  flops per cell of the largest check cell (n nodes, nq points); JIT compile is per module\n";
  const std::size_t failed =
      static_cast<std::size_t>(std::count_if(mc.records.begin(), mc.records.end(), [](const CheckRecord& r) { return !r.passed; }));
  os << fmt::format("\n{}: {} of {} checks passed in {:.2f} s\n", mc.passed() ? "PASSED" : "FAILED",
                    mc.records.size() - failed, mc.records.size(), mc.seconds);
  return os.str();
}

std::string records_json(const std::vector<ModuleCheck>& checks) {
  // Ordered: records read form, output, kind, dim, ... as the specification lists them.
  using json = nlohmann::ordered_json;
  auto number = [](double x) { return std::isfinite(x) ? json(x) : json(nullptr); };
  auto slope = [](const SlopeResult& s) {
    switch (s.kind) {
      case SlopeResult::Kind::fitted: return std::isfinite(s.value) ? json(s.value) : json(nullptr);
      case SlopeResult::Kind::exact: return json("exact");
      case SlopeResult::Kind::kink: return json("kink");
      case SlopeResult::Kind::not_applicable: break;
    }
    return json(nullptr);
  };
  json list = json::array();
  for (const ModuleCheck& mc : checks) {
    json constants = json::object();
    for (const auto& c : mc.constants) constants[c.name] = {{"value", c.value}, {"origin", c.origin}};
    for (const CheckRecord& r : mc.records) {
      list.push_back({{"form", r.form},
                      {"source", mc.source.string()},
                      {"output", r.output},
                      {"kind", r.kind},
                      {"domain", r.domain},
                      {"boundary_part", r.boundary_part},
                      {"measure", r.measure},
                      {"label", r.kind + " " + kernel_label(r)},
                      {"dim", r.dim},
                      {"coordinates", r.coordinates},
                      {"basis", to_string(mc.basis)},
                      {"gradient_rel_error", number(r.gradient_rel_error)},
                      {"hessian_rel_error", number(r.hessian_rel_error)},
                      {"symmetry_error", number(r.symmetry_error)},
                      {"linearity_error", number(r.linearity_error)},
                      {"state_dependence_error", number(r.state_dependence_error)},
                      {"taylor_slope_gradient", slope(r.taylor_slope_gradient)},
                      {"taylor_slope_second_order", slope(r.taylor_slope_second_order)},
                      {"taylor_slope_hessian", slope(r.taylor_slope_hessian)},
                      {"passed", r.passed},
                      {"status", r.status},
                      {"kinks", r.kinks},
                      {"notes", r.notes},
                      {"failures", r.failures},
                      {"cells", r.cells},
                      {"max_nodes", r.max_nodes},
                      {"points", r.points},
                      {"min_det_grad", number(r.min_det)},
                      {"flops", {{"value", number(r.flops_value)}, {"vector", number(r.flops_vector)},
                                 {"matrix", number(r.flops_matrix)}}},
                      {"check_seconds", r.seconds},
                      {"builtin", mc.builtin},
                      {"cache_hit", mc.cache_hit},
                      {"compile_seconds", mc.compile_seconds},
                      {"constants", constants}});
    }
  }
  return list.dump(2) + "\n";
}

}  // namespace lmeform::formcheck
