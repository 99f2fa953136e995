// Mutated scenes are refused before any solve, or they run. Each source scene (a small vesicle with
// an adaptivity schedule, the Poisson demo with expressions and a JIT-compiled form, the Poiseuille
// Stokes demo, a [dynamics] scene) is mutated deterministically: every line deleted, every value and
// every element of an array or inline table replaced by -1, 0, 1e308, nan, inf, a string, an array
// and an empty table (and by 1e100 and 1e-300, the numbers just inside the reader's caps), every
// table header doubled, every expression made malformed or non-finite somewhere.
// Each mutation is read (parse_scene) and checked (problems::check_scene, the pre-solve checks of
// `lmeform run --check`). It must be accepted, or refused with a SceneError / FormLoadError whose
// message names the scene file and a key ("key '...'") or a line ("FILE:LINE"); any other
// exception, or a message that names neither, fails the test with the mutation printed.
//
// The accepted mutations of the vesicle and Poisson scenes are then run (nothing written) under a
// per-case time limit: a run that throws, crashes or exceeds the limit fails the test, naming the
// mutation. A run whose solver stops unconverged is allowed (an iteration limit is the user's
// choice) and listed.
#include <gtest/gtest.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <csignal>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <initializer_list>
#include <stdexcept>
#include <set>
#include <sstream>
#include <string>
#include <string_view>
#include <thread>
#include <typeinfo>
#include <unistd.h>
#include <vector>

#include "lmeform/form_registry.hpp"
#include "lmeform/petsc.hpp"
#include "lmeform/scene.hpp"
#include "problem_registry.hpp"
#include "problem_space.hpp"

namespace {

using namespace lmeform;
namespace fs = std::filesystem;
using Clock = std::chrono::steady_clock;

// ---------------------------------------------------------------------------------------------
// The mutation under way, for the crash handler and the watchdog (both report it and end the
// process: a crash or a hang in one mutation must name it, not only kill the test).

constexpr std::size_t kLabelSize = 4096;
char g_current[kLabelSize] = "(no mutation)";
std::atomic<long long> g_deadline_ms{0};  // steady-clock milliseconds; 0: no run under way
std::atomic<bool> g_watchdog_stop{false};

void set_current(const std::string& label) {
  const std::size_t n = std::min(label.size(), kLabelSize - 2);
  std::memcpy(g_current, label.data(), n);
  g_current[n] = '\n';
  g_current[n + 1] = '\0';
}

long long now_ms() {
  return std::chrono::duration_cast<std::chrono::milliseconds>(Clock::now().time_since_epoch()).count();
}

extern "C" void on_crash(int sig) {
  const char head[] = "\ntest_scene_mutations: CRASH (signal) during mutation:\n";
  (void)!write(2, head, sizeof(head) - 1);
  (void)!write(2, g_current, std::strlen(g_current));
  std::signal(sig, SIG_DFL);
  std::raise(sig);
}

void install_crash_handlers() {
  for (const int sig : {SIGSEGV, SIGBUS, SIGFPE, SIGILL, SIGABRT}) std::signal(sig, on_crash);
}

/// A run longer than its limit cannot be interrupted from inside: the watchdog names it and ends
/// the process with a failure.
void watchdog() {
  while (!g_watchdog_stop.load()) {
    const long long deadline = g_deadline_ms.load();
    if (deadline > 0 && now_ms() > deadline) {
      const char head[] = "\ntest_scene_mutations: FAILED: a run exceeded its time limit; mutation:\n";
      (void)!write(2, head, sizeof(head) - 1);
      (void)!write(2, g_current, std::strlen(g_current));
      std::_Exit(3);
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
  }
}

// ---------------------------------------------------------------------------------------------
// Source scenes.

std::string read_file(const fs::path& p) {
  std::ifstream in(p, std::ios::binary);
  std::ostringstream s;
  s << in.rdbuf();
  return s.str();
}

// The scene of tests/app/test_dynamics.cpp (make("t_end = 0.03\ndt = 1e-3\n")): an oblate vesicle
// moved by the variational integrator in the box [0, 1] x [0, 1.5].
const char* const kDynamicsScene = R"scene([scene]
name = "dynamics_test"
coordinates = "axisymmetric"
[domain]
lower = [0.0, 0.0]
upper = [1.0, 1.5]
[nodes]
spacing = 0.0625
gamma = 0.8
[model]
forms = ["helfrich_lagrangian_axisymmetric", "area_lagrangian_axisymmetric", "volume_lagrangian_axisymmetric",
         "dissipation_axisymmetric"]
energy = "bending"
[constants]
k = 1.0
eps = 0.125
C0 = 0.0
mu = 1.0
lambda = 0.0
[constraints]
area = "initial"
volume = "initial"
[coefficients]
phi = "tanh((1 - (x[0]/0.4732)^2 - ((x[1] - 0.75)/0.2573)^2) / (2*sqrt(x[0]^2/0.4732^4 + (x[1] - 0.75)^2/0.2573^4 + 1e-12)) / (sqrt(2)*eps))"
[qdata]
phi0 = { field = "phi", jet = "value" }
gphi0 = { field = "phi", jet = "gradient" }
hphi0 = { field = "phi", jet = "hessian" }
[initial]
y = "x[0]*e(0) + x[1]*e(1)"
[[dirichlet]]
boundary = ["r_max", "z_min", "z_max"]
unknown = "y"
value = "x[0]*e(0) + x[1]*e(1)"
[[dirichlet]]
boundary = ["axis"]
unknown = "y"
components = [0]
value = 0.0
[dynamics]
dissipation = "dissipation"
time_unit = 0.064
t_end = 0.03
dt = 1e-3
)scene";

struct Source {
  std::string label;     ///< short name in messages
  std::string file;      ///< the scene's name for parse_scene: messages name it, its folder resolves paths
  std::string text;
  bool run = false;      ///< also run the accepted mutations
};

Source tiny_vesicle() {
  // tests/app/tiny_scene.toml with the adaptivity stage of run_two_ranks.sh: a CVT relocation.
  const fs::path dir = fs::path(LMEFORM_SOURCE_DIR) / "tests" / "app";
  return {"tiny", (dir / "tiny_adaptive.toml").string(),
          read_file(dir / "tiny_scene.toml") + "[vesicle.adaptivity]\nstages = [ { eps = 0.12, f = 10.0 } ]\n", true};
}

Source poisson() {
  const fs::path p = fs::path(LMEFORM_SOURCE_DIR) / "demos" / "poisson" / "poisson_uniform.toml";
  return {"poisson", p.string(), read_file(p), true};
}

Source poiseuille() {
  const fs::path p = fs::path(LMEFORM_SOURCE_DIR) / "demos" / "poiseuille.toml";
  return {"poiseuille", p.string(), read_file(p), false};
}

Source dynamics() {
  return {"dynamics", (fs::path(LMEFORM_TEST_TMPDIR) / "dynamics_test.toml").string(), kDynamicsScene, false};
}

// ---------------------------------------------------------------------------------------------
// Mutations.

struct Mutation {
  std::string what;   ///< "line 12 deleted: ...", "value of 'nodes.spacing' (line 9) -> nan", ...
  std::string text;
};

std::vector<std::string> split_lines(const std::string& text) {
  std::vector<std::string> lines;
  std::string line;
  std::istringstream in(text);
  while (std::getline(in, line)) lines.push_back(line);
  return lines;
}

std::string join_lines(const std::vector<std::string>& lines) {
  std::string s;
  for (const auto& l : lines) s += l + "\n";
  return s;
}

std::string trim(std::string_view s) {
  const auto b = s.find_first_not_of(" \t");
  if (b == std::string_view::npos) return {};
  const auto e = s.find_last_not_of(" \t");
  return std::string(s.substr(b, e - b + 1));
}

/// The position of the first '#' outside a string (npos if none).
std::size_t comment_start(std::string_view s) {
  bool in_string = false;
  for (std::size_t i = 0; i < s.size(); ++i) {
    if (s[i] == '"' && (i == 0 || s[i - 1] != '\\')) in_string = !in_string;
    if (s[i] == '#' && !in_string) return i;
  }
  return std::string_view::npos;
}

/// Brackets opened and not closed on a line (outside strings): > 0 when a value continues.
int open_brackets(std::string_view s) {
  int depth = 0;
  bool in_string = false;
  for (std::size_t i = 0; i < s.size() && i < comment_start(s); ++i) {
    if (s[i] == '"' && (i == 0 || s[i - 1] != '\\')) in_string = !in_string;
    if (in_string) continue;
    if (s[i] == '[' || s[i] == '{') ++depth;
    if (s[i] == ']' || s[i] == '}') --depth;
  }
  return depth;
}

/// The spans [begin, end) of the scalar entries (numbers, strings, booleans) of an array or inline
/// table value, keys of inline tables excluded.
std::vector<std::pair<std::size_t, std::size_t>> scalar_entries(std::string_view v) {
  std::vector<std::pair<std::size_t, std::size_t>> out;
  std::size_t i = 0;
  while (i < v.size()) {
    const char c = v[i];
    if (c == '"') {
      const std::size_t end = v.find('"', i + 1);
      if (end == std::string_view::npos) break;
      out.emplace_back(i, end + 1);
      i = end + 1;
    } else if (c == '[' || c == ']' || c == '{' || c == '}' || c == ',' || c == ' ' || c == '\t' || c == '=' || c == '\n') {
      ++i;
    } else {
      std::size_t end = i;
      while (end < v.size() && std::string_view(",]} \t=\n").find(v[end]) == std::string_view::npos) ++end;
      std::size_t next = end;
      while (next < v.size() && (v[next] == ' ' || v[next] == '\t')) ++next;
      const bool is_key = next < v.size() && v[next] == '=';
      if (!is_key) out.emplace_back(i, end);
      i = end;
    }
  }
  return out;
}

/// Whether a string value is an expression of x (not a name, a path or a provider).
bool is_expression(std::string_view quoted) {
  return quoted.find("x[") != std::string_view::npos || quoted.find('(') != std::string_view::npos ||
         quoted.find('*') != std::string_view::npos;
}

bool is_vector_expression(std::string_view quoted) {
  return quoted.find("e(") != std::string_view::npos || (quoted.size() > 1 && quoted[1] == '[');
}

std::vector<Mutation> mutations_of(const std::string& text) {
  static const char* const kValues[] = {"-1", "0", "1e308", "nan", "inf", "\"x\"", "[1, 2]", "{}", "1e100", "1e-300"};
  static const char* const kScalars[] = {"-1", "0", "1e308", "nan", "inf", "\"x\""};
  const std::vector<std::string> lines = split_lines(text);
  std::vector<Mutation> out;
  std::string table;
  for (std::size_t i = 0; i < lines.size(); ++i) {
    const std::string body = trim(lines[i].substr(0, std::min(lines[i].size(), comment_start(lines[i]))));
    if (body.empty()) continue;
    const std::string where = "line " + std::to_string(i + 1);
    if (body.front() == '[' && body.find('=') == std::string::npos) {
      // A table header: deleted (its keys join the table before), or given twice.
      table = trim(body.substr(body.starts_with("[[") ? 2 : 1, body.find(']') - (body.starts_with("[[") ? 2 : 1)));
      std::vector<std::string> l = lines;
      l.erase(l.begin() + std::ptrdiff_t(i));
      out.push_back({where + " deleted: " + body, join_lines(l)});
      l = lines;
      l.insert(l.begin() + std::ptrdiff_t(i), body);
      out.push_back({where + " doubled: " + body, join_lines(l)});
      continue;
    }
    {
      std::vector<std::string> l = lines;
      l.erase(l.begin() + std::ptrdiff_t(i));
      out.push_back({where + " deleted: " + body, join_lines(l)});
    }
    const std::size_t eq = body.find('=');
    if (eq == std::string::npos) continue;  // the continuation of a multi-line value
    const std::string key = trim(body.substr(0, eq));
    // The value, with its continuation lines when brackets stay open.
    std::size_t last = i;
    std::string value = trim(lines[i].substr(lines[i].find('=') + 1, comment_start(lines[i]) == std::string::npos
                                                                        ? std::string::npos
                                                                        : comment_start(lines[i]) - lines[i].find('=') - 1));
    int depth = open_brackets(value);
    while (depth > 0 && last + 1 < lines.size()) {
      ++last;
      const std::string more = trim(lines[last].substr(0, std::min(lines[last].size(), comment_start(lines[last]))));
      value += "\n" + more;
      depth += open_brackets(more);
    }
    const std::string name = "'" + (table.empty() ? key : table + "." + key) + "' (" + where + ")";
    auto with_value = [&](const std::string& replacement) {
      std::vector<std::string> l(lines.begin(), lines.begin() + std::ptrdiff_t(i));
      l.push_back(key + " = " + replacement);
      l.insert(l.end(), lines.begin() + std::ptrdiff_t(last + 1), lines.end());
      return join_lines(l);
    };
    for (const char* v : kValues)
      if (value != v) out.push_back({"value of " + name + " -> " + v, with_value(v)});
    if (value.front() == '"' && is_expression(value)) {
      // A malformed expression (an unclosed parenthesis), and ones with no finite value.
      const std::string inner = value.substr(1, value.size() - 2);
      const bool vector = is_vector_expression(value);
      out.push_back({"value of " + name + " -> malformed", with_value("\"(" + inner + "\"")});
      out.push_back({"value of " + name + " -> 1/0", with_value(vector ? "\"(1/(x[0] - x[0]))*e(0)\"" : "\"1/(x[0] - x[0])\"")});
      out.push_back({"value of " + name + " -> log(x[0])", with_value(vector ? "\"log(x[0])*e(0)\"" : "\"log(x[0])\"")});
    }
    if (value.front() == '[' || value.front() == '{') {
      const auto entries = scalar_entries(value);
      for (std::size_t e = 0; e < entries.size(); ++e) {
        const auto [b, end] = entries[e];
        for (const char* v : kScalars) {
          if (value.substr(b, end - b) == v) continue;
          const std::string changed = value.substr(0, b) + v + value.substr(end);
          out.push_back({"entry " + std::to_string(e) + " of " + name + " -> " + v, with_value(changed)});
        }
      }
    }
  }
  return out;
}

// ---------------------------------------------------------------------------------------------
// Checking and running.

struct Tally {
  int mutations = 0, accepted = 0, refused = 0, runs = 0, converged = 0, unconverged = 0;
  double seconds = 0;
  std::vector<std::string> unconverged_runs;
};

Tally g_total;

/// Why a refusal's message is not acceptable ("" if it is): it must name the file, and a key or a line.
std::string bad_message(const std::string& message, const std::string& file) {
  if (message.find(file) == std::string::npos) return "the message does not name the scene file";
  const bool key = message.find("key '") != std::string::npos;
  bool line = false;
  for (std::size_t at = message.find(file + ":"); at != std::string::npos; at = message.find(file + ":", at + 1)) {
    const std::size_t d = at + file.size() + 1;
    if (d < message.size() && std::isdigit(static_cast<unsigned char>(message[d])) != 0) line = true;
  }
  if (!key && !line) return "the message names neither a key nor a line";
  return {};
}

/// Whether the accepted mutations of a source run: every survivor of the vesicle and Poisson
/// scenes (35 runs, about 20 s). LMEFORM_MUTATIONS_RUN_ALL=1 runs those of the Stokes and dynamics
/// scenes too (minutes: a dynamics run takes 4-50 s), for exploring.
bool runs(const Source& source) { return source.run || std::getenv("LMEFORM_MUTATIONS_RUN_ALL") != nullptr; }

/// The time limit of one run: LMEFORM_MUTATIONS_RUN_LIMIT seconds (0: check only), else 60 s: a
/// watchdog against hangs. The slowest accepted mutation (reduced volume 1e-300: 40 multiplier
/// updates, then a clear failure) takes 11 s alone and exceeded 20 s under a loaded make test -j2.
int run_limit_seconds() {
  static const char* const given = std::getenv("LMEFORM_MUTATIONS_RUN_LIMIT");
  static const int limit = given != nullptr ? std::atoi(given) : 60;
  return limit;
}

/// LMEFORM_MUTATIONS_VERBOSE=1 prints every mutation's outcome (for reviewing the messages).
bool verbose() {
  static const bool v = std::getenv("LMEFORM_MUTATIONS_VERBOSE") != nullptr;
  return v;
}

void mutate_and_check(const Source& source) {
  const auto start = Clock::now();
  Tally tally;
  // The source itself binds and, if its survivors run, converges.
  {
    set_current(source.label + ": the unmutated scene");
    const Scene s = parse_scene(source.text, source.file, problems::driver_tables());
    problems::check_scene(PETSC_COMM_WORLD, s, nullptr);
    if (source.run && run_limit_seconds() > 0) {
      problems::DriverContext ctx;
      ctx.scene = &s;
      const problems::RunReport report = problems::driver_for(s).run(ctx);
      EXPECT_TRUE(report.success) << source.label << ", unmutated: " << report.status;
    }
  }
  std::set<std::string> seen{source.text};
  std::vector<std::pair<const Mutation*, Scene>> accepted;
  const std::vector<Mutation> all = mutations_of(source.text);
  for (const Mutation& m : all) {
    if (!seen.insert(m.text).second) continue;
    ++tally.mutations;
    const std::string label = source.label + ": " + m.what;
    set_current(label);
    const std::string shown = "\n--- mutation " + label + " ---\n" + m.text;
    try {
      Scene s = parse_scene(m.text, source.file, problems::driver_tables());
      problems::check_scene(PETSC_COMM_WORLD, s, nullptr);
      ++tally.accepted;
      if (verbose()) std::printf("ACCEPTED %s\n", label.c_str());
      if (runs(source) && run_limit_seconds() > 0) accepted.emplace_back(&m, std::move(s));
    } catch (const SceneError& e) {
      ++tally.refused;
      if (verbose()) std::printf("REFUSED  %s\n    %s\n", label.c_str(), e.what());
      const std::string why = bad_message(e.what(), source.file);
      EXPECT_TRUE(why.empty()) << why << ": SceneError: " << e.what() << shown;
    } catch (const FormLoadError& e) {
      ++tally.refused;
      if (verbose()) std::printf("REFUSED  %s\n    %s\n", label.c_str(), e.what());
      const std::string why = bad_message(e.what(), source.file);
      EXPECT_TRUE(why.empty()) << why << ": FormLoadError: " << e.what() << shown;
    } catch (const std::exception& e) {
      ADD_FAILURE() << "refused with an exception that is no SceneError or FormLoadError (" << typeid(e).name() << "): " << e.what()
                    << shown;
    } catch (...) {
      ADD_FAILURE() << "refused with an exception of unknown type" << shown;
    }
  }
  const double check_s = std::chrono::duration<double>(Clock::now() - start).count();
  // Every survivor whose mutation touches the solve runs, under the watchdog's limit.
  for (auto& [m, scene] : accepted) {
    const std::string label = source.label + ": " + m->what;
    set_current(label);
    const std::string shown = "\n--- mutation " + label + " ---\n" + m->text;
    problems::DriverContext ctx;
    ctx.comm = PETSC_COMM_WORLD;
    ctx.scene = &scene;
    ctx.log = nullptr;
    ++tally.runs;
    const auto run_start = Clock::now();
    g_deadline_ms = now_ms() + 1000LL * run_limit_seconds();
    try {
      const problems::RunReport report = problems::driver_for(scene).run(ctx);
      // A solve that ran on values the check let through and returned NaN is a refusal missing.
      bool finite = report.status.find("nan") == std::string::npos;
      if (report.fields)
        for (const auto& f : report.fields->fields)
          for (const double v : f.values) finite = finite && std::isfinite(v);
      EXPECT_TRUE(finite) << "the check accepted the scene, but its run produced values that are not finite (status: " << report.status
                          << ")" << shown;
      if (verbose()) std::printf("RAN      %s: %s\n", label.c_str(), report.status.c_str());
      if (report.success) {
        ++tally.converged;
      } else {
        ++tally.unconverged;
        tally.unconverged_runs.push_back(label + ": " + report.status);
      }
    } catch (const std::exception& e) {
      ADD_FAILURE() << "the check accepted the scene, but its run threw (" << typeid(e).name() << "): " << e.what() << shown;
    } catch (...) {
      ADD_FAILURE() << "the check accepted the scene, but its run threw an exception of unknown type" << shown;
    }
    g_deadline_ms = 0;
    const double run_s = std::chrono::duration<double>(Clock::now() - run_start).count();
    if (run_s > 5) std::printf("  slow run (%.1f s): %s\n", run_s, label.c_str());
  }
  set_current("(between mutations)");
  tally.seconds = std::chrono::duration<double>(Clock::now() - start).count();
  std::printf("%s: %d mutations, %d accepted, %d refused (%.1f s); %d runs: %d converged, %d not (%.1f s)\n", source.label.c_str(),
              tally.mutations, tally.accepted, tally.refused, check_s, tally.runs, tally.converged, tally.unconverged,
              tally.seconds - check_s);
  for (const auto& u : tally.unconverged_runs) std::printf("  not converged: %s\n", u.c_str());
  std::fflush(stdout);
  g_total.mutations += tally.mutations;
  g_total.accepted += tally.accepted;
  g_total.refused += tally.refused;
  g_total.runs += tally.runs;
  g_total.converged += tally.converged;
  g_total.unconverged += tally.unconverged;
  g_total.seconds += tally.seconds;
}

TEST(SceneMutations, TinyVesicleWithAdaptivity) { mutate_and_check(tiny_vesicle()); }
TEST(SceneMutations, PoissonWithExpressions) { mutate_and_check(poisson()); }
TEST(SceneMutations, PoiseuilleStokes) { mutate_and_check(poiseuille()); }
TEST(SceneMutations, Dynamics) { mutate_and_check(dynamics()); }

// The generator itself: deletions, replacements, entries of arrays and inline tables, doubled
// headers, malformed expressions.
TEST(SceneMutations, GeneratorCoversLinesValuesEntriesAndHeaders) {
  const std::string text = "[a]\nk = 1.0  # c\nv = [1, \"s\"]\nt = { x = 2 }\ne = \"sin(x[0])\"\n";
  const auto m = mutations_of(text);
  auto has = [&](const std::string& what, const std::string& fragment) {
    return std::any_of(m.begin(), m.end(), [&](const Mutation& x) {
      return x.what.starts_with(what) && x.text.find(fragment) != std::string::npos;
    });
  };
  EXPECT_TRUE(has("line 1 deleted", "k = 1.0"));
  EXPECT_TRUE(has("line 1 doubled", "[a]\n[a]\n"));
  EXPECT_TRUE(has("value of 'a.k' (line 2) -> nan", "k = nan\n"));
  EXPECT_TRUE(has("entry 1 of 'a.v' (line 3) -> inf", "v = [1, inf]"));
  EXPECT_TRUE(has("entry 0 of 'a.t' (line 4) -> \"x\"", "t = { x = \"x\" }"));
  EXPECT_TRUE(has("value of 'a.e' (line 5) -> malformed", "e = \"(sin(x[0])\""));
  EXPECT_FALSE(has("entry 0 of 'a.t'", "t = { -1 = 2 }"));
}

// ---------------------------------------------------------------------------------------------
// The refusals the mutations called for, each with its key.

/// The message of the check's refusal of `text` ("" when it is accepted).
std::string refusal(const Source& source, const std::string& text) {
  try {
    const Scene s = parse_scene(text, source.file, problems::driver_tables());
    problems::check_scene(PETSC_COMM_WORLD, s, nullptr);
  } catch (const SceneError& e) {
    return e.what();
  }
  return {};
}

std::string replaced(const std::string& text, const std::string& from, const std::string& to) {
  const std::size_t at = text.find(from);
  if (at == std::string::npos) throw std::invalid_argument("no '" + from + "' in the scene");
  return text.substr(0, at) + to + text.substr(at + from.size());
}

void expect_refused(const Source& source, const std::string& text, std::initializer_list<std::string_view> fragments) {
  const std::string message = refusal(source, text);
  ASSERT_FALSE(message.empty()) << "accepted:\n" << text;
  for (const auto f : fragments) EXPECT_NE(message.find(f), std::string::npos) << "'" << f << "' not in: " << message;
}

TEST(SceneMutations, TheReaderRefusesGridsAndBasesThatCannotRun) {
  const Source p = poisson();
  // gamma above -ln(1e-6): the LME support is shorter than the spacing.
  expect_refused(p, replaced(p.text, "gamma = 0.8 ", "gamma = 20 "), {":18: key 'nodes.gamma' = 20", "give at most 13.8"});
  EXPECT_EQ(refusal(p, replaced(p.text, "gamma = 0.8 ", "gamma = 13.8 ")), "");
  // A compact support (the weight at its edge 1e-3) lowers the largest gamma to -ln(1e-3) = 6.9.
  expect_refused(p, replaced(p.text, "gamma = 0.8 ", "gamma = 8\nsupport_tolerance = 1e-3 "),
                 {"key 'nodes.gamma' = 8", "give at most 6.9"});
  EXPECT_EQ(refusal(p, replaced(p.text, "gamma = 0.8 ", "gamma = 6\nsupport_tolerance = 1e-3 ")), "");
  expect_refused(p, replaced(p.text, "gamma = 0.8 ", "gamma = 0.8\nsupport_tolerance = 0.1 "),
                 {"key 'nodes.support_tolerance' = 0.1 must lie in [1e-12, 1e-2]"});
  expect_refused(p, replaced(p.text, "spacing = 0.05 ", "spacing = 1e-8 "),
                 {"key 'nodes.spacing' = 1e-08 gives 100000000 intervals on axis x"});
  expect_refused(p, replaced(p.text, "spacing = 0.05 ", "counts = [60000, 60000] "),
                 {"key 'nodes.counts' gives a grid of 3600000000 nodes", "32-bit"});
  // Nested grids: a box's graded set; not a polygon, not another kind of node set.
  const std::string graded = "spacing = 0.05\nrefine = [{ path = [[0.0, 0.25], [0.5, 0.25]], spacing = 0.0125, width = 0.02 }]\n";
  EXPECT_EQ(refusal(p, replaced(p.text, "spacing = 0.05 ", graded + "sampling = \"grids\" ")), "");
  EXPECT_EQ(refusal(p, replaced(p.text, "spacing = 0.05 ", graded + "sampling = \"poisson\" ")), "");
  expect_refused(p, replaced(p.text, "spacing = 0.05 ", graded + "sampling = \"hexagons\" "), {"key 'nodes.sampling'", "grids"});
  expect_refused(p, replaced(p.text, "spacing = 0.05 ", "counts = [21, 21]\nsampling = \"grids\" "),
                 {"key 'nodes.sampling' chooses how the nodes for 'nodes.spacing' are generated"});
  expect_refused(p,
                 replaced(replaced(p.text, "lower = [0.0, 0.0]\nupper = [1.0, 1.0]", "polygon = [[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]]"),
                          "spacing = 0.05 ", graded + "sampling = \"grids\" "),
                 {"key 'nodes.sampling' = \"grids\" nests uniform grids in a box"});
  const Source v = tiny_vesicle();
  expect_refused(v, replaced(v.text, "augmented_tolerance = 1e-2", "augmented_tolerance = 1e-12"),
                 {"key 'solver.augmented_tolerance' = 1e-12", "give at least 1e-10"});
}

TEST(SceneNodes, GridsSamplingNestsUniformRowsAlongARefinedLine) {
  // The unit square at 0.05, refined to 0.0125 within 0.02 of y = 0.5: nested grids put a row of
  // nodes 0.0125 apart on that line, the Poisson-disk sample (the default) does not align with it.
  const Source p = poisson();
  const std::string graded = "spacing = 0.05\nrefine = [{ path = [[0.0, 0.5], [1.0, 0.5]], spacing = 0.0125, width = 0.02 }]\n";
  auto on_line = [](const NodeSet& nodes) {
    std::set<double> xs;
    for (std::size_t a = 0; a < nodes.size(); ++a)
      if (std::abs(nodes.point(a)[1] - 0.5) < 1e-12) xs.insert(nodes.point(a)[0]);
    return xs;
  };
  const Scene grids = parse_scene(replaced(p.text, "spacing = 0.05 ", graded + "sampling = \"grids\" "), p.file, problems::driver_tables());
  const NodeSet nested = problems::initial_nodes(grids, PETSC_COMM_WORLD);
  const std::set<double> row = on_line(nested);
  ASSERT_EQ(row.size(), 81u);  // x = 0, 0.0125, ..., 1
  double largest_gap = 0;
  for (auto a = row.begin(), b = std::next(row.begin()); b != row.end(); ++a, ++b) largest_gap = std::max(largest_gap, *b - *a);
  EXPECT_NEAR(largest_gap, 0.0125, 1e-12);
  // Far from the line the level-0 grid: the corner cell's nodes 0.05 apart.
  std::size_t corner = 0;
  for (std::size_t a = 0; a < nested.size(); ++a)
    if (nested.point(a)[0] < 0.06 && nested.point(a)[1] < 0.06) ++corner;
  EXPECT_EQ(corner, 4u);
  const Scene poisson_disk = parse_scene(replaced(p.text, "spacing = 0.05 ", graded), p.file, problems::driver_tables());
  EXPECT_LT(on_line(problems::initial_nodes(poisson_disk, PETSC_COMM_WORLD)).size(), 10u);
}

TEST(SceneMutations, BindingRefusesExpressionsWithoutAFiniteValueAtANode) {
  const Source p = poisson();
  expect_refused(p, replaced(p.text, "value = \"c*sin(pi*x[0])*sin(pi*x[1])\"", "value = \"log(x[0])\""),
                 {":32: key 'dirichlet[0].value': the expression \"log(x[0])\" is -inf at the node (0, 0) on 'hull'"});
  // Only the parts it is given on: log(x[0]) is finite on x_max.
  EXPECT_EQ(refusal(p, replaced(replaced(p.text, "value = \"c*sin(pi*x[0])*sin(pi*x[1])\"", "value = \"log(x[0])\""),
                                "boundary = [\"hull\"]", "boundary = [\"x_max\"]")),
            "");
  expect_refused(p, replaced(p.text, "value = \"c*sin(pi*x[0])*sin(pi*x[1])\"", "value = \"exp(300*x[0])\""),
                 {"is 1.700887764e+104 at the node (0.8, 0) on 'hull'", "at most 1e+100 in magnitude"});
  const Source d = dynamics();
  expect_refused(d, replaced(d.text, "y = \"x[0]*e(0) + x[1]*e(1)\"", "y = \"x[1]/x[0]*e(0) + x[1]*e(1)\""),
                 {"key 'initial.y': the expression", "(component 0) at the node (0, 0)"});
  // A node file too small to triangulate.
  const fs::path points = fs::path(LMEFORM_TEST_TMPDIR) / "two_points.txt";
  std::ofstream(points) << "0.1 0.1\n0.9 0.9\n";
  expect_refused(p, replaced(p.text, "spacing = 0.05 ", "file = \"" + points.string() + "\" "),
                 {"key 'nodes.file'", "holds 2 points; a triangulation of a 2D domain needs at least 3"});
}

TEST(SceneMutations, TheVesicleRefusesBoundaryValuesAndRadiiItCannotRepresent) {
  const Source v = tiny_vesicle();
  expect_refused(v, replaced(v.text, "value = -1.0", "value = 0"),
                 {":21: key 'dirichlet[0].value' = 0 prescribes the phase field 'phi'", "give value = -1"});
  expect_refused(v, replaced(v.text, "radius = 0.35\nreduced_volume", "radius = 0.1\nreduced_volume"),
                 {"key 'vesicle.radius' = 0.1 is below the interface width eps = 0.12 (the finest of the schedule)"});
}

TEST(SceneMutations, TheDynamicsRefusesMotionsThatFold) {
  const Source d = dynamics();
  expect_refused(d, replaced(d.text, "energy = \"bending\"\n", ""), {"missing key 'model.energy'", "the dissipation 'dissipation'"});
  expect_refused(d, replaced(d.text, "energy = \"bending\"", "energy = [\"bending\", \"dissipation\"]"),
                 {"key 'model.energy[1]' = 'dissipation' is the dissipation"});
  expect_refused(d, replaced(d.text, "y = \"x[0]*e(0) + x[1]*e(1)\"\n", ""), {"missing key 'initial.y'"});
  expect_refused(d, replaced(d.text, "y = \"x[0]*e(0) + x[1]*e(1)\"", "y = 0"), {"key 'initial.y' = 0 maps every node to one point"});
  expect_refused(d, replaced(d.text, "components = [0]\n", ""),
                 {"key 'dirichlet[1].value' = 0 gives every component of the deformation 'y' one number", "'axis'"});
  expect_refused(d, replaced(d.text, "components = [0]\nvalue = 0.0", "components = [0]\nvalue = -1"),
                 {"key 'dirichlet[1].value' = -1 moves the axis off itself"});
  // A number on one component of another side is a wall the nodes slide along.
  EXPECT_EQ(refusal(d, replaced(d.text, "boundary = [\"axis\"]", "boundary = [\"z_min\"]")), "");
}

class Summary : public ::testing::Environment {
 public:
  void TearDown() override {
    if (g_total.mutations == 0) return;
    std::printf("scene mutations: %d mutations, %d accepted, %d refused; %d runs (%d converged, %d not); %.1f s\n", g_total.mutations,
                g_total.accepted, g_total.refused, g_total.runs, g_total.converged, g_total.unconverged, g_total.seconds);
  }
};

}  // namespace

int main(int argc, char** argv) {
  ::testing::InitGoogleTest(&argc, argv);
  lmeform::PetscSession session(&argc, &argv);
  // After PETSc's own handlers: a crash names the mutation.
  install_crash_handlers();
  std::thread guard(watchdog);
  ::testing::AddGlobalTestEnvironment(new Summary);
  const int code = RUN_ALL_TESTS();
  g_watchdog_stop = true;
  guard.join();
  return code;
}
