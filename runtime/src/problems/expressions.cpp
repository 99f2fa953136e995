#include "expressions.hpp"

#include <cstdint>
#include <sstream>

#include <fmt/format.h>

#include "lmeform/contractions.hpp"
#include "lmeform/output.hpp"
#include "lmeform/scene.hpp"

namespace lmeform::problems {

namespace fs = std::filesystem;

namespace {

/// Writes a generated form into the cache's expression folder (named by its text, so an unchanged
/// scene reuses the compiled module) and loads it. The module name must equal the file name.
const FormModule& load_generated(const std::string& prefix, const std::string& body, MPI_Comm comm, std::ostream* log) {
  const std::string module = fmt::format("{}_{:016x}", prefix, content_hash(body));
  const fs::path dir = form_cache_dir() / "expressions";
  const fs::path path = dir / (module + ".form");
  int rank = 0;
  MPI_Comm_rank(comm, &rank);
  std::string failure;
  if (rank == 0 && !fs::exists(path)) {
    try {
      fs::create_directories(dir);
      write_text_atomically(path, "form " + module + "\n" + body);
    } catch (const std::exception& e) {
      failure = e.what();
    }
  }
  int failed = failure.empty() ? 0 : 1;
  MPI_Bcast(&failed, 1, MPI_INT, 0, comm);
  if (failed != 0) throw FormLoadError(rank == 0 ? failure : "cannot write a generated form in " + dir.string());
  FormLoadOptions options;
  options.comm = comm;
  options.log = log;
  return load_form(path.string(), options);
}

std::string constant_declarations(const std::map<std::string, double, std::less<>>& constants) {
  if (constants.empty()) return {};
  std::string s = "constant ";
  bool first = true;
  for (const auto& [name, value] : constants) {
    (void)value;
    s += (first ? "" : ", ") + name;
    first = false;
  }
  return s + "\n";
}

}  // namespace

PointExpressions::PointExpressions(int dim, std::map<std::string, double, std::less<>> constants)
    : dim_(dim), constants_(std::move(constants)) {}

int PointExpressions::add(const std::string& expression, int components, std::string where, bool scalar_allowed) {
  items_.push_back({expression, components, std::move(where), scalar_allowed});
  return static_cast<int>(items_.size()) - 1;
}

namespace {

std::string expression_header(int dim, const std::map<std::string, double, std::less<>>& constants) {
  return "dimension " + std::to_string(dim) + "\ncoordinate x\n" + constant_declarations(constants);
}

}  // namespace

void PointExpressions::compile(MPI_Comm comm, std::ostream* log) {
  if (items_.empty()) return;
  std::string body = expression_header(dim_, constants_);
  for (std::size_t i = 0; i < items_.size(); ++i) body += "point value" + std::to_string(i) + " = " + items_[i].expression + "\n";
  try {
    module_ = &load_generated("scene_expressions", body, comm, log);
  } catch (const FormLoadError& e) {
    // Compile the expressions one by one to name the one at fault.
    for (const Item& it : items_) {
      try {
        (void)load_generated("scene_expression", expression_header(dim_, constants_) + "point value = " + it.expression + "\n", comm,
                             nullptr);
      } catch (const FormLoadError& single) {
        throw SceneError(fmt::format("{}: the expression \"{}\" does not compile:\n{}", it.where, it.expression, single.what()));
      }
    }
    throw;
  }
  for (std::size_t i = 0; i < items_.size(); ++i) {
    const Item& it = items_[i];
    const auto& k = module_->at("value" + std::to_string(i), dim_);
    if (k.n_values != it.components && !(k.n_values == 1 && it.scalar_allowed))
      throw SceneError(fmt::format("{}: the expression \"{}\" is {}; {} expected{}", it.where, it.expression,
                                   k.n_values == 1 ? std::string("a scalar") : fmt::format("{} values", k.n_values),
                                   it.components == 1 ? std::string("a scalar") : fmt::format("a vector of {} components", it.components),
                                   it.components == 1 ? std::string() : std::string(" (write vectors with e(i): \"x[1]*e(0) - x[0]*e(1)\")")));
  }
  const auto& k0 = module_->at("value0", dim_);
  constant_values_.clear();
  for (int i = 0; i < k0.n_constants; ++i) constant_values_.push_back(constants_.at(k0.constants[i]));
}

void PointExpressions::set_constant(const std::string& name, double value) {
  if (!constants_.contains(name)) throw std::invalid_argument("PointExpressions: no constant '" + name + "'");
  constants_[name] = value;
  if (module_ == nullptr) return;
  const auto& k0 = module_->at("value0", dim_);
  for (int i = 0; i < k0.n_constants; ++i)
    if (name == k0.constants[i]) constant_values_[static_cast<std::size_t>(i)] = value;
}

void PointExpressions::evaluate(int handle, std::span<const double> x, std::span<double> out) const {
  if (out.size() < static_cast<std::size_t>(items_.at(static_cast<std::size_t>(handle)).components))
    throw std::invalid_argument("PointExpressions::evaluate: the output holds fewer values than the expression has");
  const auto& k = module_->at("value" + std::to_string(handle), dim_);
  std::vector<double> workspace(k.workspace_doubles != nullptr ? k.workspace_doubles(0, 1) + 1 : 1);
  const double weight = 1.0;
  kernel::CellInputs in;
  in.contractions = &dense_contractions();
  in.n_nodes = 0;
  in.n_points = 1;
  in.basis_order = 0;
  in.weights = &weight;
  in.points = x.data();
  in.constants = constant_values_.empty() ? nullptr : constant_values_.data();
  in.workspace = workspace.data();
  k.point(in, out.data());
  // A scalar where allowed for several components: the same value for each, as a number.
  if (k.n_values == 1)
    for (int c = 1; c < items_[static_cast<std::size_t>(handle)].components; ++c) out[static_cast<std::size_t>(c)] = out[0];
}

const FormModule& compile_error_form(int dim, const std::string& unknown, int components, const std::string& exact,
                                     const std::map<std::string, double, std::less<>>& constants, const std::string& where,
                                     MPI_Comm comm, std::ostream* log) {
  std::ostringstream body;
  body << "dimension " << dim << "\ncoordinate x\n" << constant_declarations(constants) << "unknown " << unknown
       << (components > 1 ? " : vector" : "") << "\n"
       << "let error_value = " << unknown << " - (" << exact << ")\n"
       << "let error_gradient = grad(" << unknown << ") - grad(" << exact << ")\n"
       << "energy l2 = inner(error_value, error_value) * dx\n"
       << "let error_hessian = hess(" << unknown << ") - hess(" << exact << ")\n"
       << "energy h1 = inner(error_gradient, error_gradient) * dx\n"
       << "energy h2 = inner(error_hessian, error_hessian) * dx\n";
  try {
    return load_generated("scene_errors", body.str(), comm, log);
  } catch (const FormLoadError& e) {
    throw SceneError(fmt::format("{}: the exact solution \"{}\" does not compile:\n{}", where, exact, e.what()));
  }
}

const FormModule& compile_quantity_form(int dim, const std::vector<std::pair<std::string, int>>& unknowns,
                                        const std::map<std::string, double, std::less<>>& constants,
                                        const std::vector<QuantityIntegral>& integrals, const std::vector<std::string>& where,
                                        MPI_Comm comm, std::ostream* log) {
  auto header = [&] {
    std::ostringstream h;
    h << "dimension " << dim << "\ncoordinate x\n" << constant_declarations(constants);
    for (const auto& [name, components] : unknowns) h << "unknown " << name << (components > 1 ? " : vector" : "") << "\n";
    return h.str();
  };
  auto output = [](std::size_t i, const QuantityIntegral& q) {
    const std::string measure = !q.boundary ? "dx" : q.part.empty() ? "ds" : "ds(" + q.part + ")";
    return "energy q" + std::to_string(i) + " = (" + q.expression + ") * " + measure + "\n";
  };
  std::string body = header();
  for (std::size_t i = 0; i < integrals.size(); ++i) body += output(i, integrals[i]);
  try {
    return load_generated("scene_quantities", body, comm, log);
  } catch (const FormLoadError&) {
    for (std::size_t i = 0; i < integrals.size(); ++i) {
      try {
        (void)load_generated("scene_quantity", header() + output(0, integrals[i]), comm, nullptr);
      } catch (const FormLoadError& single) {
        throw SceneError(fmt::format("{}: the integral \"{}\" does not compile:\n{}", where.at(i), integrals[i].expression, single.what()));
      }
    }
    throw;
  }
}

const FormModule& compile_kinematics_form(int dim, const std::string& deformation, MPI_Comm comm, std::ostream* log) {
  std::ostringstream body;
  body << "dimension " << dim << "\nunknown " << deformation << " : vector\n"
       << "point position = " << deformation << "\npoint F = grad(" << deformation << ")\npoint H = hess(" << deformation << ")\n";
  return load_generated("scene_kinematics", body.str(), comm, log);
}

const FormModule& compile_integral_form(int dim, MPI_Comm comm, std::ostream* log) {
  std::ostringstream body;
  body << "dimension " << dim << "\nunknown u\nenergy integral = u * dx\n";
  return load_generated("scene_integral", body.str(), comm, log);
}

}  // namespace lmeform::problems
