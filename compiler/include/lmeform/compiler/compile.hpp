// Front end of lmeformc: parse a .form file (and its includes), check names and shapes, and lower
// every output to a scalar integrand in the IR, once per requested spatial dimension.
#pragma once

#include <filesystem>
#include <map>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "lmeform/compiler/ir.hpp"
#include "lmeform/compiler/source.hpp"

namespace lmeform::compiler {

struct FieldDecl {
  std::string name;
  ir::Role role;
  bool is_vector = false;
  Loc loc;
  int components(int dim) const { return is_vector ? dim : 1; }
};

struct ConstantDecl {
  std::string name;
  std::optional<double> default_value;
  Loc loc;
};

struct QdataDecl {
  std::string name;
  int rank = 0;  ///< 0 scalar, 1 vector, 2 matrix, 3 tensor3
  Loc loc;
  int size(int dim) const { int s = 1; for (int i = 0; i < rank; ++i) s *= dim; return s; }
};

enum class OutputKind { Energy, Constraint, Residual, Bilinear, Linear, Point };
const char* to_string(OutputKind k);

/// Where an integral is taken: the cells (`dx`), the whole boundary (`ds`) or a named part of it
/// (`ds(top)`; the runtime resolves the name).
struct Domain {
  bool boundary = false;
  std::string part;  ///< boundary part; empty for the whole boundary (and for the cells)
  /// "dx", "ds" or "ds(top)": the measure as the form writes it.
  std::string measure() const { return !boundary ? "dx" : part.empty() ? "ds" : "ds(" + part + ")"; }
  friend bool operator==(const Domain&, const Domain&) = default;
};
/// CompiledForm::domains[kCellDomain] is always the cells.
inline constexpr int kCellDomain = 0;

/// A point output's value at one dimension: its shape and components (row-major).
struct PointValue {
  std::vector<int> shape;
  std::vector<ir::NodeId> components;
};

struct OutputDecl {
  OutputKind kind = OutputKind::Energy;
  std::string name;
  Loc loc;
  int target_constant = -1;      ///< Constraint: index of the target constant, or -1
  double target_value = 0.0;     ///< Constraint: numeric target when target_constant < 0
  /// Integral outputs, per dimension and per domain (index into CompiledForm::domains): f such that
  /// the output's part over that domain is Σ_q w_q f. A domain whose terms vanish in a dimension
  /// (`if dim == 3 then ... else 0*ds`) is left out there.
  std::map<int, std::map<int, ir::NodeId>> integrands;
  /// Point outputs, per dimension.
  std::map<int, PointValue> point;
  /// A requirement (`require CONDITION, "MESSAGE"`): a point output that is 1 where the condition
  /// holds and 0 where it fails; the runtime checks it at every node of the start state.
  std::string requirement;
  std::string requirement_condition;   ///< the condition as written
  bool requirement_pointwise = false;  ///< it reads the coordinate, an unknown or the spacing (else constants only)
  /// `recommend CONDITION, "MESSAGE"`: a failure is a warning, not a refusal (a resolution rule
  /// that a convergence study breaks on purpose).
  bool requirement_advisory = false;
  /// The integrand over one domain (by default the cells) at dimension dim.
  ir::NodeId integrand(int dim, int domain = kCellDomain) const { return integrands.at(dim).at(domain); }
};

struct CompileOptions {
  std::vector<std::filesystem::path> include_dirs;
};

struct CompiledForm {
  std::string module;
  std::vector<int> dims;
  std::vector<FieldDecl> fields;       ///< all nodal fields, declaration order
  std::vector<ConstantDecl> constants;
  std::vector<QdataDecl> qdata;
  std::string coordinate;              ///< name of the coordinate, empty if none
  std::vector<Domain> domains{Domain{}};  ///< the cells, then boundary measures in order of first use
  std::vector<OutputDecl> outputs;
  SourceSet sources;
  std::vector<std::filesystem::path> dependencies;  ///< the form and every included file
  std::map<int, std::shared_ptr<ir::Graph>> graphs;  ///< one IR per dimension

  /// Fields of one role in declaration order (the order of their dofs).
  std::vector<const FieldDecl*> fields_of(ir::Role role) const;
  /// Index of a field within its role.
  const FieldDecl& field(ir::Role role, int index) const { return *fields_of(role).at(static_cast<std::size_t>(index)); }
  int qdata_offset(int index, int dim) const;
  int qdata_per_point(int dim) const;
};

/// Compiles a .form file. Throws CompileError (already formatted) on any error.
CompiledForm compile_file(const std::filesystem::path& path, const CompileOptions& options = {});
/// Same for text held in memory (tests); `path` is used in messages and to resolve includes, and
/// names the module as a file would. An empty path names none: the text must then say `form NAME`.
CompiledForm compile_source(const std::string& text, const std::filesystem::path& path,
                            const CompileOptions& options = {});

/// The form file and every file it includes, depth first, each once, as absolute normalized paths:
/// what its generated code depends on. Only parses and resolves includes (milliseconds, for cache
/// keys and build systems); throws CompileError on syntax and include errors, and leaves every
/// other check to compile_file.
std::vector<std::filesystem::path> form_dependencies(const std::filesystem::path& path, const CompileOptions& options = {});

}  // namespace lmeform::compiler
