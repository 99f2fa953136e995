// The .form grammar (Boost.Spirit X3). Kept in this single translation unit: X3 is heavy to
// compile, and nothing else needs it. Expressions are built bottom-up by semantic actions on rules
// whose attribute is an ast::ExprPtr; statements are appended to the parse state as their keyword
// is recognized (after a keyword, every part is an expectation point, so errors say what was
// expected where).
#include <boost/spirit/home/x3.hpp>

#include <boost/fusion/include/at_c.hpp>
#include <cstdio>
#include <optional>
#include <set>

#include "lmeform/compiler/ast.hpp"

namespace lmeform::compiler::ast {
namespace {

namespace x3 = boost::spirit::x3;
using Iter = std::string::const_iterator;

struct ParseState {
  Iter begin;
  int file = 0;
  int nesting = 0;  ///< open parentheses, brackets, calls, conditionals and prefix operators
  std::vector<Stmt> statements;
};

/// The grammar is recursive descent: every nesting level costs kilobytes of stack (tens of them in
/// a sanitizer build), so the depth is bounded (no sensible form comes close) instead of letting a
/// hostile input overflow it.
constexpr int kMaxNesting = 128;
struct NestingTooDeep {
  std::size_t offset;
};
struct state_tag;

template <class Ctx>
ParseState& state_of(const Ctx& ctx) { return x3::get<state_tag>(ctx).get(); }

const std::set<std::string>& keywords() {
  static const std::set<std::string> k = {
      "form", "dimension", "unknown", "test", "trial", "coefficient", "qdata", "constant",
      "coordinate", "let", "def", "measure", "include", "energy", "constraint", "residual",
      "bilinear", "linear", "point", "require", "recommend", "if", "then", "else", "and", "or", "not"};
  return k;
}

bool is_ident_char(char c) { return std::isalnum(static_cast<unsigned char>(c)) || c == '_'; }

/// A token with its position: operators, keywords, identifiers.
struct Tok {
  std::size_t pos = 0;
  std::string text;
};

/// Matches one of a set of fixed spellings (longest first) after skipping; keywords must not be
/// followed by an identifier character. The attribute records where the token starts.
struct token_parser : x3::parser<token_parser> {
  using attribute_type = Tok;
  static bool const has_attribute = true;
  std::vector<std::string> spellings;  // longest first
  bool word = false;
  std::string label;

  template <class It, class Ctx, class RCtx, class Attr>
  bool parse(It& first, const It& last, const Ctx& ctx, RCtx&, Attr& attr) const {
    x3::skip_over(first, last, ctx);
    for (const auto& s : spellings) {
      if (static_cast<std::size_t>(last - first) < s.size()) continue;
      if (!std::equal(s.begin(), s.end(), first)) continue;
      It after = first + static_cast<std::ptrdiff_t>(s.size());
      if (word && after != last && is_ident_char(*after)) continue;
      x3::traits::move_to(Tok{static_cast<std::size_t>(first - state_of(ctx).begin), s}, attr);
      first = after;
      return true;
    }
    return false;
  }
};

token_parser tok(std::vector<std::string> spellings, bool word = false) {
  token_parser p;
  std::sort(spellings.begin(), spellings.end(), [](const auto& a, const auto& b) { return a.size() > b.size(); });
  p.spellings = std::move(spellings);
  p.word = word;
  return p;
}
token_parser kw(const std::string& k) { return tok({k}, true); }

/// nested[p]: p one nesting level deeper; past kMaxNesting the parse stops with NestingTooDeep.
template <class Subject>
struct nesting_guard : x3::unary_parser<Subject, nesting_guard<Subject>> {
  using base_type = x3::unary_parser<Subject, nesting_guard<Subject>>;
  static bool const is_pass_through_unary = true;
  constexpr explicit nesting_guard(const Subject& wrapped) : base_type(wrapped) {}

  template <class It, class Ctx, class RCtx, class Attr>
  bool parse(It& first, const It& last, const Ctx& ctx, RCtx& rctx, Attr& attr) const {
    ParseState& st = state_of(ctx);
    if (st.nesting >= kMaxNesting) {
      x3::skip_over(first, last, ctx);
      throw NestingTooDeep{static_cast<std::size_t>(first - st.begin)};
    }
    ++st.nesting;
    const bool ok = this->subject.parse(first, last, ctx, rctx, attr);
    --st.nesting;  // an expectation failure unwinds past this, but it also ends the parse
    return ok;
  }
};

struct nesting_generator {
  template <class Subject>
  constexpr nesting_guard<typename x3::extension::as_parser<Subject>::value_type> operator[](const Subject& subject) const {
    return nesting_guard<typename x3::extension::as_parser<Subject>::value_type>(x3::as_parser(subject));
  }
};
constexpr nesting_generator nested{};

}  // namespace
}  // namespace lmeform::compiler::ast

namespace boost::spirit::x3 {
template <>
struct get_info<lmeform::compiler::ast::token_parser> {
  using result_type = std::string;
  std::string operator()(const lmeform::compiler::ast::token_parser& p) const {
    std::string s;
    for (const auto& t : p.spellings) s += (s.empty() ? "" : " or ") + ("'" + t + "'");
    return s;
  }
};
/// A nested expression is expected under the name of what it wraps.
template <class Subject>
struct get_info<lmeform::compiler::ast::nesting_guard<Subject>> {
  using result_type = std::string;
  std::string operator()(const lmeform::compiler::ast::nesting_guard<Subject>& p) const { return what(p.subject); }
};
}  // namespace boost::spirit::x3

namespace lmeform::compiler::ast {
namespace {

struct no_special_reals : x3::ureal_policies<double> {
  template <typename It, typename A>
  static bool parse_nan(It&, const It&, A&) { return false; }
  template <typename It, typename A>
  static bool parse_inf(It&, const It&, A&) { return false; }
};
const x3::real_parser<double, no_special_reals> unsigned_number{};

Loc loc_of(const ParseState& st, std::size_t pos) { return Loc{st.file, pos}; }

std::shared_ptr<Expr> make(ExprKind k, Loc loc, std::string name = {}) {
  auto e = std::make_shared<Expr>();
  e->kind = k;
  e->loc = loc;
  e->begin = loc;
  e->name = std::move(name);
  return e;
}

using x3::_attr;
using x3::_val;
using boost::fusion::at_c;

// ---- lexical pieces -------------------------------------------------------------------------
const x3::rule<class ident_raw_tag, std::string> ident_raw = "identifier";
const auto ident_raw_def = x3::lexeme[(x3::alpha | x3::char_('_')) >> *(x3::alnum | x3::char_('_'))];

struct pos_parser : x3::parser<pos_parser> {
  using attribute_type = std::size_t;
  static bool const has_attribute = true;
  template <class It, class Ctx, class RCtx, class Attr>
  bool parse(It& first, const It& last, const Ctx& ctx, RCtx&, Attr& attr) const {
    x3::skip_over(first, last, ctx);
    x3::traits::move_to(static_cast<std::size_t>(first - state_of(ctx).begin), attr);
    return true;
  }
};
const pos_parser pos{};

const x3::rule<class name_tag, Tok> name = "identifier";
const auto name_def = (pos >> ident_raw)[([](auto& ctx) {
  const std::string& s = at_c<1>(_attr(ctx));
  if (keywords().count(s)) { x3::_pass(ctx) = false; return; }
  _val(ctx) = Tok{at_c<0>(_attr(ctx)), s};
})];

const x3::rule<class string_tag, std::string> string_lit = "a string in double quotes";
const auto string_lit_def = x3::lexeme['"' > *(x3::char_ - '"' - x3::eol) > '"'];

// ---- expressions ----------------------------------------------------------------------------
const x3::rule<class expr_tag, ExprPtr> expr = "expression";
const x3::rule<class disj_tag, ExprPtr> disjunction = "expression";
const x3::rule<class conj_tag, ExprPtr> conjunction = "expression";
const x3::rule<class neg_tag, ExprPtr> negation = "expression";
const x3::rule<class cmp_tag, ExprPtr> comparison = "expression";
const x3::rule<class sum_tag, ExprPtr> sum = "expression";
const x3::rule<class prod_tag, ExprPtr> product = "expression";
const x3::rule<class unary_tag, ExprPtr> unary = "expression";
const x3::rule<class power_tag, ExprPtr> power = "expression";
const x3::rule<class postfix_tag, ExprPtr> postfix = "expression";
const x3::rule<class primary_tag, ExprPtr> primary = "an operand (number, name, call, '(' or '[')";
const x3::rule<class args_tag, std::vector<ExprPtr>> arguments = "arguments";
const x3::rule<class expr_list_tag, std::vector<ExprPtr>> expr_list = "expression";
const x3::rule<class then_tag> then_kw = "'then'";
const x3::rule<class else_tag> else_kw = "'else'";

const auto assign = [](auto& ctx) { _val(ctx) = _attr(ctx); };
const auto fold_binary = [](auto& ctx) {
  const Tok& op = at_c<0>(_attr(ctx));
  auto e = make(ExprKind::Binary, loc_of(state_of(ctx), op.pos), op.text);
  e->begin = _val(ctx)->begin;
  e->args = {_val(ctx), at_c<1>(_attr(ctx))};
  _val(ctx) = e;
};
const auto make_unary = [](auto& ctx) {
  const Tok& op = at_c<0>(_attr(ctx));
  auto e = make(ExprKind::Unary, loc_of(state_of(ctx), op.pos), op.text);
  e->args = {at_c<1>(_attr(ctx))};
  _val(ctx) = e;
};

const auto if_kw = kw("if");
const auto then_kw_def = kw("then");
const auto else_kw_def = kw("else");
const auto expr_def =
    (if_kw > nested[expr] > then_kw > nested[expr] > else_kw > nested[expr])[([](auto& ctx) {
      auto e = make(ExprKind::If, loc_of(state_of(ctx), at_c<0>(_attr(ctx)).pos), "if");
      e->args = {at_c<1>(_attr(ctx)), at_c<2>(_attr(ctx)), at_c<3>(_attr(ctx))};
      _val(ctx) = e;
    })] |
    disjunction[assign];
const auto disjunction_def = conjunction[assign] >> *((kw("or") > conjunction)[fold_binary]);
const auto conjunction_def = negation[assign] >> *((kw("and") > negation)[fold_binary]);
const auto negation_def = (kw("not") > nested[negation])[make_unary] | comparison[assign];
const auto comparison_def =
    sum[assign] >> -((tok({"<=", ">=", "==", "!=", "<", ">"}) > sum)[fold_binary]);
const auto sum_def = product[assign] >> *((tok({"+", "-"}) > product)[fold_binary]);
const auto product_def = unary[assign] >> *((tok({"*", "/"}) > unary)[fold_binary]);
const auto unary_def = (tok({"-"}) > nested[unary])[make_unary] | power[assign];
const auto power_def = postfix[assign] >> -((tok({"^"}) > nested[unary])[fold_binary]);
const auto postfix_def =
    primary[assign] >> *((pos >> '[' > nested[expr_list] > ']')[([](auto& ctx) {
      auto e = make(ExprKind::Index, loc_of(state_of(ctx), at_c<0>(_attr(ctx))), "[]");
      e->begin = _val(ctx)->begin;
      e->args.push_back(_val(ctx));
      for (const auto& i : at_c<1>(_attr(ctx))) e->args.push_back(i);
      _val(ctx) = e;
    })]);
const auto arguments_def = expr_list | x3::eps;
const auto expr_list_def = expr % ',';
const auto primary_def =
    (pos >> unsigned_number)[([](auto& ctx) {
      auto e = make(ExprKind::Number, loc_of(state_of(ctx), at_c<0>(_attr(ctx))));
      e->number = at_c<1>(_attr(ctx));
      _val(ctx) = e;
    })] |
    (name >> '(' > nested[arguments] > ')')[([](auto& ctx) {
      const Tok& n = at_c<0>(_attr(ctx));
      auto e = make(ExprKind::Call, loc_of(state_of(ctx), n.pos), n.text);
      e->args = at_c<1>(_attr(ctx));
      _val(ctx) = e;
    })] |
    name[([](auto& ctx) {
      _val(ctx) = make(ExprKind::Name, loc_of(state_of(ctx), _attr(ctx).pos), _attr(ctx).text);
    })] |
    (pos >> '(' > nested[expr] > ')')[([](auto& ctx) {
      // The parentheses belong to the sub-expression's extent (diagnostics point at them).
      auto e = std::make_shared<Expr>(*at_c<1>(_attr(ctx)));
      e->begin = loc_of(state_of(ctx), at_c<0>(_attr(ctx)));
      _val(ctx) = e;
    })] |
    (pos >> '[' > nested[expr_list] > ']')[([](auto& ctx) {
      auto e = make(ExprKind::List, loc_of(state_of(ctx), at_c<0>(_attr(ctx))), "[]");
      e->args = at_c<1>(_attr(ctx));
      _val(ctx) = e;
    })];

BOOST_SPIRIT_DEFINE(ident_raw, name, string_lit, expr, disjunction, conjunction, negation, comparison,
                    sum, product, unary, power, postfix, primary, arguments, expr_list, then_kw, else_kw)

// ---- statements -----------------------------------------------------------------------------
auto begin_stmt(StmtKind kind) {
  return [kind](auto& ctx) {
    auto& st = state_of(ctx);
    Stmt s;
    s.kind = kind;
    s.loc = loc_of(st, _attr(ctx).pos);
    s.keyword = _attr(ctx).text;
    st.statements.push_back(std::move(s));
  };
}
const auto set_name = [](auto& ctx) {
  auto& st = state_of(ctx);
  st.statements.back().name = _attr(ctx).text;
  st.statements.back().name_loc = loc_of(st, _attr(ctx).pos);
};
const auto add_item = [](auto& ctx) {
  auto& st = state_of(ctx);
  DeclItem d;
  d.name = _attr(ctx).text;
  d.loc = loc_of(st, _attr(ctx).pos);
  st.statements.back().items.push_back(std::move(d));
};
const auto set_item_shape = [](auto& ctx) {
  auto& st = state_of(ctx);
  st.statements.back().items.back().shape = _attr(ctx).text;
  st.statements.back().items.back().shape_loc = loc_of(st, _attr(ctx).pos);
};
const auto set_item_value = [](auto& ctx) { state_of(ctx).statements.back().items.back().value = _attr(ctx); };
const auto add_dim = [](auto& ctx) { state_of(ctx).statements.back().dims.push_back(_attr(ctx)); };
const auto add_param = [](auto& ctx) {
  auto& st = state_of(ctx);
  st.statements.back().params.push_back(_attr(ctx).text);
  st.statements.back().param_locs.push_back(loc_of(st, _attr(ctx).pos));
};
const auto set_body = [](auto& ctx) { state_of(ctx).statements.back().body = _attr(ctx); };
const auto set_target = [](auto& ctx) { state_of(ctx).statements.back().target = _attr(ctx); };
const auto set_path = [](auto& ctx) { state_of(ctx).statements.back().path = _attr(ctx); };
const auto set_message = [](auto& ctx) {
  Stmt& s = state_of(ctx).statements.back();
  s.message = _attr(ctx);
  // A requirement has no name of its own: its place in the sources makes one (a C++ identifier).
  s.name = s.keyword + "_" + std::to_string(s.loc.file) + "_" + std::to_string(s.loc.offset);
  s.name_loc = s.loc;
};

// Each action-carrying piece after an expectation point is its own named rule, so that an
// expectation failure can say what was expected in words.
const x3::rule<class stmt_name_tag> stmt_name = "a name";
const auto stmt_name_def = name[set_name];
const x3::rule<class shape_word_tag> shape_word = "a shape (scalar, vector, matrix or tensor3)";
const auto shape_word_def = name[set_item_shape];
const x3::rule<class item_default_tag> item_default = "an expression";
const auto item_default_def = expr[set_item_value];
const x3::rule<class field_item_tag> field_item = "a name to declare";
const auto field_item_def = name[add_item] >> -(':' > shape_word);
const x3::rule<class const_item_tag> const_item = "a constant name";
const auto const_item_def = name[add_item] >> -('=' > item_default);
const x3::rule<class target_tag> target = "a target (constant name or number)";
const auto target_def = primary[set_target];
const x3::rule<class dim_tag> dimension_value = "a dimension (1, 2 or 3)";
const auto dimension_value_def = x3::int_[add_dim];
const x3::rule<class param_tag> param = "a parameter name";
const auto param_def = name[add_param];
const x3::rule<class body_tag> body = "an expression";
const auto body_def = expr[set_body];
const x3::rule<class sum_body_tag> sum_body = "an expression";
const auto sum_body_def = sum[set_body];
const x3::rule<class path_tag> include_path = "a file name in double quotes";
const auto include_path_def = string_lit[set_path];
const x3::rule<class message_tag> require_message = "the requirement's message in double quotes";
const auto require_message_def = string_lit[set_message];
const x3::rule<class comma_tag> require_comma = "',' and the requirement's message";
const auto require_comma_def = x3::lit(',');
const x3::rule<class eqeq_tag> equals_target = "'==' and the constraint's target";
const auto equals_target_def = x3::omit[tok({"=="})];
const x3::rule<class field_list_tag> field_list = "a name to declare";
const auto field_list_def = field_item % ',';
const x3::rule<class const_list_tag> const_list = "a constant name";
const auto const_list_def = const_item % ',';
const x3::rule<class dim_list_tag> dimension_list = "a dimension (1, 2 or 3)";
const auto dimension_list_def = dimension_value % ',';
const x3::rule<class param_list_tag> param_list = "a parameter name";
const auto param_list_def = param % ',';
BOOST_SPIRIT_DEFINE(equals_target, stmt_name, shape_word, item_default, field_item, const_item, target, dimension_value, param,
                    body, sum_body, include_path, require_message, require_comma, field_list, const_list, dimension_list, param_list)

const auto statement =
    (kw("form")[begin_stmt(StmtKind::Form)] > stmt_name) |
    (kw("dimension")[begin_stmt(StmtKind::Dimension)] > dimension_list) |
    (tok({"unknown", "test", "trial", "coefficient", "qdata"}, true)[begin_stmt(StmtKind::Field)] > field_list) |
    (kw("constant")[begin_stmt(StmtKind::Constant)] > const_list) |
    (kw("coordinate")[begin_stmt(StmtKind::Coordinate)] > stmt_name) |
    (kw("let")[begin_stmt(StmtKind::Let)] > stmt_name > '=' > body) |
    (kw("measure")[begin_stmt(StmtKind::Measure)] > stmt_name > '=' > body) |
    (kw("def")[begin_stmt(StmtKind::Def)] > stmt_name > '(' > param_list > ')' > '=' > body) |
    (kw("include")[begin_stmt(StmtKind::Include)] > include_path) |
    (tok({"energy", "residual", "bilinear", "linear", "point"}, true)[begin_stmt(StmtKind::Output)] > stmt_name > '=' >
     body) |
    (kw("constraint")[begin_stmt(StmtKind::Output)] > stmt_name > '=' > sum_body > equals_target >
     target) |
    (kw("require")[begin_stmt(StmtKind::Output)] > body > require_comma > require_message) |
    (kw("recommend")[begin_stmt(StmtKind::Output)] > body > require_comma > require_message);

const auto skipper = x3::space | x3::lexeme['#' >> *(x3::char_ - x3::eol)];

/// "U+03C6 (φ)" for the UTF-8 sequence starting at text[at], or "byte 0xCF" if it is not valid UTF-8.
std::string describe_non_ascii(const std::string& text, std::size_t at) {
  const auto byte = [&](std::size_t i) { return static_cast<unsigned char>(text[i]); };
  const unsigned char lead = byte(at);
  const int length = lead >= 0xC2 && lead <= 0xDF ? 2 : lead >= 0xE0 && lead <= 0xEF ? 3 : lead >= 0xF0 && lead <= 0xF4 ? 4 : 0;
  char hex[16];
  bool valid = length > 0 && at + static_cast<std::size_t>(length) <= text.size();
  char32_t code = length == 4 ? lead & 0x07u : length == 3 ? lead & 0x0Fu : lead & 0x1Fu;
  for (int k = 1; valid && k < length; ++k) {
    const unsigned char c = byte(at + static_cast<std::size_t>(k));
    valid = (c & 0xC0u) == 0x80u;
    code = (code << 6) | (c & 0x3Fu);
  }
  valid = valid && code >= (length == 3 ? 0x800u : length == 4 ? 0x10000u : 0x80u) && code <= 0x10FFFFu &&
          !(code >= 0xD800u && code <= 0xDFFFu);
  if (!valid) {
    std::snprintf(hex, sizeof hex, "0x%02X", static_cast<unsigned>(lead));
    return std::string("byte ") + hex + " (not valid UTF-8)";
  }
  std::snprintf(hex, sizeof hex, "U+%04X", static_cast<unsigned>(code));
  return std::string(hex) + " (" + text.substr(at, static_cast<std::size_t>(length)) + ")";
}

/// Spirit's character classes are defined for ASCII only, so any other byte where the grammar
/// may look at it (anywhere but in comments and strings) is refused before parsing.
void reject_non_ascii(const SourceSet& sources, int file) {
  const std::string& text = sources.file(file).text;
  const auto skip_to_line_end = [&](std::size_t i, char also_stop_at) {
    while (i < text.size() && text[i] != '\n' && text[i] != '\r' && text[i] != also_stop_at) ++i;
    return i;
  };
  for (std::size_t i = 0; i < text.size(); ++i) {
    const char c = text[i];
    if (c == '#') i = skip_to_line_end(i + 1, '\n');
    else if (c == '"') i = skip_to_line_end(i + 1, '"');
    else if (static_cast<unsigned char>(c) >= 0x80)
      fail_at(sources, Loc{file, i}, "non-ASCII character " + describe_non_ascii(text, i) + " is not allowed outside comments");
  }
}

}  // namespace

Expr::~Expr() {
  std::vector<ExprPtr> pending = std::move(args);
  while (!pending.empty()) {
    ExprPtr e = std::move(pending.back());
    pending.pop_back();
    // The last owner takes the operands first, so that e's own destructor has nothing to recurse into.
    if (e.use_count() == 1) {
      auto& operands = const_cast<Expr&>(*e).args;  // every Expr is created non-const (make_shared<Expr>)
      for (auto& a : operands) pending.push_back(std::move(a));
      operands.clear();
    }
  }
}

std::vector<Stmt> parse_form(const SourceSet& sources, int file) {
  const std::string& text = sources.file(file).text;
  reject_non_ascii(sources, file);
  ParseState st;
  st.begin = text.begin();
  st.file = file;
  Iter first = text.begin();
  const Iter last = text.end();
  const auto parser = x3::with<state_tag>(std::ref(st))[*statement];
  try {
    x3::phrase_parse(first, last, parser, skipper);
  } catch (const NestingTooDeep& deep) {
    fail_at(sources, Loc{file, deep.offset},
            "expression nested too deeply: more than " + std::to_string(kMaxNesting) +
                " levels of parentheses, brackets, calls, conditionals or prefix operators");
  } catch (const x3::expectation_failure<Iter>& e) {
    Iter at = e.where();
    while (at != last && std::isspace(static_cast<unsigned char>(*at))) ++at;
    std::string found = at == last ? std::string("end of file") : "'" + std::string(1, *at) + "'";
    if (at != last && is_ident_char(*at)) {
      Iter w = at;
      while (w != last && is_ident_char(*w)) ++w;
      found = "'" + std::string(at, w) + "'";
    }
    fail_at(sources, Loc{file, static_cast<std::size_t>(at - text.begin())},
            "expected " + e.which() + ", found " + found);
  }
  // Skip trailing blanks and comments; anything left is not a statement.
  x3::phrase_parse(first, last, x3::eps, skipper);
  if (first != last) {
    Iter w = first;
    while (w != last && is_ident_char(*w)) ++w;
    const std::string found = w == first ? std::string(1, *first) : std::string(first, w);
    fail_at(sources, Loc{file, static_cast<std::size_t>(first - text.begin())},
            "expected a statement (form, dimension, unknown, test, trial, coefficient, qdata, constant, "
            "coordinate, let, def, measure, include, energy, constraint, residual, bilinear, linear, point, require, recommend), found '" +
                found + "'");
  }
  return std::move(st.statements);
}

}  // namespace lmeform::compiler::ast
