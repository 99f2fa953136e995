// lmeformc: the form compiler's command line.
#include <unistd.h>

#include <cerrno>
#include <chrono>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <string>
#include <vector>

#include "lmeform/compiler/codegen.hpp"
#include "lmeform/compiler/compile.hpp"

#ifdef LMEFORM_HAVE_CLI11
#include <CLI/CLI.hpp>
#endif

namespace fs = std::filesystem;
using namespace lmeform::compiler;

namespace {

struct Options {
  std::string form;
  std::string out_dir = ".";
  bool json = true;
  bool print_ir = false;
  std::vector<std::string> include_dirs;
  std::string depfile;
  bool dependencies = false;
  bool report = false;
  bool out_dir_given = false;
};

#ifndef LMEFORM_VERSION
#error "LMEFORM_VERSION (the project version) must be defined by the build"
#endif
constexpr const char* kVersionLine = "lmeformc " LMEFORM_VERSION;

const char* kUsage =
    "lmeformc FILE.form -o DIR [--no-json] [--print-ir] [-I DIR]... [--depfile FILE]\n"
    "lmeformc FILE.form --dependencies [-I DIR]...\n"
    "lmeformc FILE.form --report [-o DIR] [-I DIR]...\n"
    "  Compiles a lmeform form file into DIR/<module>_kernels.hpp (C++ kernels: value, gradient,\n"
    "  Hessian / residual, Jacobian) and DIR/<module>.json (metadata).\n"
    "  -o, --output DIR   output directory (created if missing; default .)\n"
    "  --json             write the JSON description (the default)\n"
    "  --no-json          write only the header\n"
    "  --print-ir         print the IR after differentiation to stdout (for debugging a form)\n"
    "  -I DIR             add an include search directory (after the including file's own directory)\n"
    "  --depfile FILE     write a Makefile dependency file (the form and every included file)\n"
    "  --dependencies     only parse the form and its includes, and print the absolute path of the\n"
    "                     form and of every included file, one per line; write nothing\n"
    "  --report           print the cost of every kernel (flops per point of value, gradient and\n"
    "                     Hessian, jet components, generated lines, the .form line of each output,\n"
    "                     the share of the basis contractions); writes files only with -o\n"
    "  --version          print the version (lmeformc X.Y.Z)\n"
    "  -h, --help         this text\n";

void remove_quietly(const std::vector<fs::path>& paths) {
  for (const auto& p : paths) {
    std::error_code ignored;
    fs::remove(p, ignored);
  }
}

/// Writes every output or none: each goes to a temporary next to it, and the temporaries are
/// renamed into place only once all of them are complete. On failure the temporaries, and any
/// output already renamed, are removed, so that a build never sees a header without its JSON or
/// depfile.
void write_all_or_nothing(const std::vector<std::pair<fs::path, std::string>>& files) {
  std::vector<fs::path> temporaries;
  try {
    for (const auto& [path, text] : files) {
      if (fs::is_directory(path)) throw std::runtime_error("cannot write " + path.string() + ": it is a directory");
      // The process id keeps concurrent runs writing the same outputs from sharing a temporary.
      temporaries.push_back(path.string() + "." + std::to_string(::getpid()) + ".tmp");
      std::ofstream out(temporaries.back(), std::ios::binary);
      if (!out) throw std::runtime_error("cannot write " + path.string() + ": " + std::strerror(errno));
      out << text;
      out.close();
      if (!out) throw std::runtime_error("cannot write " + path.string() + ": " + std::strerror(errno));
    }
  } catch (...) {
    remove_quietly(temporaries);
    throw;
  }
  std::vector<fs::path> renamed;
  for (std::size_t i = 0; i < files.size(); ++i) {
    std::error_code ec;
    fs::rename(temporaries[i], files[i].first, ec);
    if (ec) {
      remove_quietly(renamed);
      remove_quietly(std::vector<fs::path>(temporaries.begin() + static_cast<std::ptrdiff_t>(i), temporaries.end()));
      throw std::runtime_error("cannot write " + files[i].first.string() + ": " + ec.message());
    }
    renamed.push_back(files[i].first);
  }
}

std::string make_escape(const std::string& s) {
  std::string o;
  for (char c : s) {
    if (c == ' ' || c == '#') o += '\\';
    if (c == '$') o += '$';
    o += c;
  }
  return o;
}

int run(const Options& opt) {
  CompileOptions copt;
  for (const auto& d : opt.include_dirs) copt.include_dirs.emplace_back(d);
  try {
    if (opt.dependencies) {
      for (const auto& file : form_dependencies(opt.form, copt)) std::cout << file.string() << '\n';
      return 0;
    }
    const auto t0 = std::chrono::steady_clock::now();
    const CompiledForm form = compile_file(opt.form, copt);
    const GeneratedModule gen = generate(form, fs::path(opt.form).filename().string());
    if (opt.print_ir) std::cout << gen.ir;
    if (opt.report) {
      std::cout << gen.report;
      if (!opt.out_dir_given) return 0;
    }
    fs::create_directories(opt.out_dir);
    // Everything is generated before anything is written: an error above leaves no files.
    const fs::path header = fs::path(opt.out_dir) / (form.module + "_kernels.hpp");
    std::vector<std::pair<fs::path, std::string>> files{{header, gen.header}};
    if (opt.json) files.emplace_back(fs::path(opt.out_dir) / (form.module + ".json"), gen.json);
    if (!opt.depfile.empty()) {
      std::string dep = make_escape(header.string()) + ":";
      for (const auto& d : form.dependencies) {
        dep += ' ';  // appended separately: `" " + string` trips GCC 12's -Wrestrict false positive
        dep += make_escape(fs::absolute(d).lexically_normal().string());
      }
      files.emplace_back(opt.depfile, dep + "\n");
    }
    write_all_or_nothing(files);
    const double s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    if (!opt.print_ir)
      std::cerr << "lmeformc: " << opt.form << " -> " << header.string() << " (" << form.outputs.size() << " outputs, "
                << form.dims.size() << " dimension(s), " << s << " s)\n";
    return 0;
  } catch (const CompileError& e) {
    std::cerr << e.what();
    return 1;
  } catch (const std::exception& e) {
    std::cerr << "lmeformc: error: " << e.what() << "\n";
    return 1;
  }
}

}  // namespace

int main(int argc, char** argv) {
  Options opt;
#ifdef LMEFORM_HAVE_CLI11
  CLI::App app{"lmeformc: compiles a .form file into C++ kernels for the lmeform runtime"};
  app.add_option("form", opt.form, "the .form file")->required();
  app.add_option("-o,--output", opt.out_dir, "output directory");
  bool json_flag = false, no_json = false;
  app.add_flag("--json", json_flag, "write <module>.json (the default)");
  app.add_flag("--no-json", no_json, "write only the header");
  app.add_flag("--print-ir", opt.print_ir, "print the IR after differentiation");
  app.add_option("-I", opt.include_dirs, "include search directory")->allow_extra_args(false);
  app.add_option("--depfile", opt.depfile, "write a Makefile dependency file");
  app.add_flag("--dependencies", opt.dependencies, "print the form's file and its includes (absolute paths), write nothing");
  app.add_flag("--report", opt.report, "print the cost of every kernel; writes files only with -o");
  app.set_version_flag("--version", kVersionLine);
  app.footer(kUsage);
  CLI11_PARSE(app, argc, argv);
  opt.json = !no_json;
  opt.out_dir_given = app.count("-o") > 0;
#else
  std::vector<std::string> args(argv + 1, argv + argc);
  for (std::size_t i = 0; i < args.size(); ++i) {
    const std::string& a = args[i];
    auto value = [&]() -> std::string {
      if (i + 1 >= args.size()) { std::cerr << "lmeformc: error: " << a << " needs a value\n" << kUsage; std::exit(1); }
      return args[++i];
    };
    if (a == "-h" || a == "--help") { std::cout << kUsage; return 0; }
    else if (a == "--version") { std::cout << kVersionLine << "\n"; return 0; }
    else if (a == "--dependencies") opt.dependencies = true;
    else if (a == "-o" || a == "--output") opt.out_dir = value(), opt.out_dir_given = true;
    else if (a == "--report") opt.report = true;
    else if (a == "--json") opt.json = true;
    else if (a == "--no-json") opt.json = false;
    else if (a == "--print-ir") opt.print_ir = true;
    else if (a == "-I") opt.include_dirs.push_back(value());
    else if (a.rfind("-I", 0) == 0) opt.include_dirs.push_back(a.substr(2));
    else if (a == "--depfile") opt.depfile = value();
    else if (!a.empty() && a[0] == '-') { std::cerr << "lmeformc: error: unknown option " << a << "\n" << kUsage; return 1; }
    else if (opt.form.empty()) opt.form = a;
    else { std::cerr << "lmeformc: error: more than one form file given\n" << kUsage; return 1; }
  }
  if (opt.form.empty()) { std::cerr << "lmeformc: error: no form file given\n" << kUsage; return 1; }
#endif
  return run(opt);
}
