// Abstract syntax tree of a .form file, with source locations. Produced by parse_form (the
// Spirit X3 grammar lives in parser.cpp only, to keep X3 out of every other translation unit).
#pragma once

#include <memory>
#include <string>
#include <vector>

#include "lmeform/compiler/source.hpp"

namespace lmeform::compiler::ast {

enum class ExprKind { Number, Name, Call, Index, List, Binary, Unary, If };

struct Expr;
using ExprPtr = std::shared_ptr<const Expr>;

struct Expr {
  ExprKind kind = ExprKind::Number;
  Loc loc;                    ///< operator / name / first token position
  Loc begin;                  ///< first character of the whole sub-expression (its '(' if parenthesized)
  std::string name;           ///< identifier, function name or operator spelling
  double number = 0.0;
  std::vector<ExprPtr> args;  ///< operands; Index: [base, i, j, ...]; If: [cond, then, else]

  Expr() = default;
  Expr(const Expr&) = default;
  Expr& operator=(const Expr&) = default;
  /// Releases the operands iteratively: a sum of thousands of terms is a left spine that deep,
  /// and the implicit destructor would recurse once per term.
  ~Expr();
};

enum class StmtKind { Form, Dimension, Field, Constant, Coordinate, Let, Def, Measure, Include, Output };

/// A declared name with an optional shape word (`phi`, `y : vector`) or a default (`k = 1`).
struct DeclItem {
  std::string name;
  Loc loc;
  std::string shape;   ///< empty = scalar
  Loc shape_loc;
  ExprPtr value;       ///< constant default (may be null)
};

struct Stmt {
  StmtKind kind = StmtKind::Form;
  Loc loc;                     ///< the keyword
  std::string keyword;         ///< "unknown", "energy", ...
  std::string name;
  Loc name_loc;
  std::vector<int> dims;       ///< Dimension
  std::vector<DeclItem> items; ///< Field / Constant
  std::vector<std::string> params;  ///< Def
  std::vector<Loc> param_locs;
  ExprPtr body;                ///< Let, Def, Measure, Output
  ExprPtr target;              ///< Output "constraint"
  std::string path;            ///< Include
  std::string message;         ///< Output "require": what the model requires, in words
};

/// Parses one file's text (index `file` in sources). Throws CompileError on syntax errors.
std::vector<Stmt> parse_form(const SourceSet& sources, int file);

}  // namespace lmeform::compiler::ast
