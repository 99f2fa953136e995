// bench_kernels: per form of the model library, the cost of generating and compiling its kernels,
// their size and Hessian flop model, and for helfrich_axisymmetric and helfrich_lagrangian the
// generated Hessian kernel against a naive thesis-style one (tests/bench/naive_kernels.hpp) on the
// same LME cell with the same inputs (they must agree to 1e-10).
//
//   bench_kernels [--quick] [--out DIR]      writes DIR/kernels.json and prints a table
//
// Baked in at build time: LMEFORMC (path of lmeformc), LMEFORM_CXX + LMEFORM_CXX_FLAGS (the
// compiler and flags of this build), LMEFORM_KERNEL_INCLUDES (runtime/include and Eigen),
// LMEFORM_FORMS_DIR and LMEFORM_FORM_LIST (the .form files, '|'-separated).
#include "naive_kernels.hpp"
#include "test_cells.hpp"

#include <lmeform/form_check.hpp>
#include <lmeform/form_check_setup.hpp>

#include <helfrich_axisymmetric_kernels.hpp>
#include <helfrich_lagrangian_kernels.hpp>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <map>
#include <random>
#include <sstream>
#include <string>
#include <vector>

#include <unistd.h>

namespace fs = std::filesystem;
namespace fc = lmeform::formcheck;
using lmeform::kernel::FormKernels;

namespace {

double now() {
  return std::chrono::duration<double>(std::chrono::steady_clock::now().time_since_epoch()).count();
}

std::vector<std::string> split(const std::string& s, char sep) {
  std::vector<std::string> out;
  std::stringstream ss(s);
  std::string item;
  while (std::getline(ss, item, sep))
    if (!item.empty()) out.push_back(item);
  return out;
}

std::string read_file(const fs::path& p) {
  std::ifstream f(p);
  std::stringstream ss;
  ss << f.rdbuf();
  return ss.str();
}

int run(const std::string& cmd) { return std::system(cmd.c_str()); }

/// Sum over the JSON's dim-2 kernels of the per-point (n-independent) matrix flops and the model at (n, nq).
std::pair<double, double> hessian_flops(const std::string& json, int n, int nq) {
  double per_point = 0.0, cell = 0.0;
  std::size_t pos = 0;
  while ((pos = json.find("\"symbol\"", pos)) != std::string::npos) {
    const std::size_t end = json.find("\"symbol\"", pos + 1);
    const std::string k = json.substr(pos, end == std::string::npos ? std::string::npos : end - pos);
    pos += 8;
    if (k.find("\"dim\": 2") == std::string::npos) continue;
    const std::size_t m = k.find("\"matrix\": {");
    if (m == std::string::npos) continue;
    auto num = [&](const char* key) {
      const std::size_t p = k.find(key, m);
      return p == std::string::npos ? 0.0 : std::atof(k.c_str() + p + std::string(key).size());
    };
    const double a = num("\"per_point\": "), b = num("\"per_node_point\": "), c = num("\"per_node_pair_point\": ");
    per_point += a;
    cell += nq * (a + n * b + double(n) * n * c);
  }
  return {per_point, cell};
}

struct Record {
  std::string form;
  double lmeformc_s = 0, cxx_compile_s = 0;
  long generated_lines = 0;
  double flops_hessian = 0, flops_hessian_cell = 0;
  bool timed = false;
  double gen_s = 0, naive_s = 0, max_diff = 0;
  int n = 0, nq = 0;
};

/// Median time of one Hessian call on the cell (the output is zeroed before each call).
double time_hessian(const FormKernels& f, const fc::Cell& cell, const fc::State& s, int reps,
                    std::vector<double>& H) {
  std::vector<double> ws(f.workspace_doubles ? f.workspace_doubles(cell.n, cell.nq) + 1 : 1);
  lmeform::kernel::CellInputs in;
  in.n_nodes = cell.n;
  in.n_points = cell.nq;
  in.basis_order = cell.basis_order;
  in.weights = cell.weights.data();
  in.points = cell.points.data();
  in.basis = cell.basis.data();
  in.unknowns = s.unknowns.data();
  in.qdata = s.qdata.empty() ? nullptr : s.qdata.data();
  in.constants = s.constants.data();
  in.workspace = ws.data();
  const std::size_t N = static_cast<std::size_t>(cell.n) * f.dofs_per_node;
  H.assign(N * N, 0.0);
  std::vector<double> t;
  for (int r = 0; r < reps; ++r) {
    std::fill(H.begin(), H.end(), 0.0);
    const double t0 = now();
    f.matrix(in, H.data());
    t.push_back(now() - t0);
  }
  std::sort(t.begin(), t.end());
  return t[t.size() / 2];
}

}  // namespace

int main(int argc, char** argv) {
  bool quick = false;
  fs::path out = ".";
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    if (a == "--quick") quick = true;
    else if (a == "--out" && i + 1 < argc) out = argv[++i];
    else if (a.rfind("--out=", 0) == 0) out = a.substr(6);
    else { std::fprintf(stderr, "bench_kernels: unknown argument '%s' (use --quick, --out DIR)\n", a.c_str()); return 2; }
  }
  fs::create_directories(out);
  const fs::path work = fs::temp_directory_path() / ("lmeform_bench_kernels_" + std::to_string(::getpid()));
  fs::create_directories(work);

  std::vector<Record> records;
  const std::string includes = LMEFORM_KERNEL_INCLUDES;
  std::string inc_flags;
  for (const auto& d : split(includes, '|')) inc_flags += " -I\"" + d + "\"";
  for (const std::string& form : split(LMEFORM_FORM_LIST, '|')) {
    Record r;
    r.form = fs::path(form).stem().string();
    const fs::path dir = work / r.form;
    fs::create_directories(dir);
    double t0 = now();
    if (run(std::string("\"") + LMEFORMC + "\" \"" + form + "\" -o \"" + dir.string() + "\" --json > \"" +
            (dir / "lmeformc.log").string() + "\" 2>&1") != 0) {
      std::fprintf(stderr, "bench_kernels: lmeformc failed on %s:\n%s\n", form.c_str(),
                   read_file(dir / "lmeformc.log").c_str());
      return 1;
    }
    r.lmeformc_s = now() - t0;
    const fs::path header = dir / (r.form + "_kernels.hpp");
    {
      std::ifstream h(header);
      std::string line;
      while (std::getline(h, line)) ++r.generated_lines;
    }
    const fs::path tu = dir / "tu.cpp";
    // The TU must odr-use every kernel (through <module>_all_kernels), else the inline kernels are
    // only parsed and never compiled.
    std::ofstream(tu) << "#include \"" << header.string()
                      << "\"\nconst lmeform::kernel::FormKernels* const* lmeform_bench_tu() { return " << r.form
                      << "_all_kernels; }\n";
    t0 = now();
    const std::string cxx = std::string("\"") + LMEFORM_CXX + "\" " + LMEFORM_CXX_FLAGS + inc_flags + " -c \"" +
                            tu.string() + "\" -o \"" + (dir / "tu.o").string() + "\" > \"" +
                            (dir / "cxx.log").string() + "\" 2>&1";
    if (run(cxx) != 0) {
      std::fprintf(stderr, "bench_kernels: compiling the generated header of %s failed:\n%s\n", r.form.c_str(),
                   read_file(dir / "cxx.log").c_str());
      return 1;
    }
    r.cxx_compile_s = now() - t0;
    const std::string json = read_file(dir / (r.form + ".json"));
    records.push_back(r);
    records.back().flops_hessian = hessian_flops(json, 0, 1).first;
  }

  // Hessian cell timings on a real LME cell (graded node set, 6 Gauss points, interface cell).
  std::mt19937_64 rng(3);
  const int reps = quick ? 20 : 200;
  bool agree = true;
  for (Record& r : records) {
    const bool axi = r.form == "helfrich_axisymmetric";
    if (!axi && r.form != "helfrich_lagrangian") continue;
    const double cx = axi ? 0.0 : 0.45;
    const fc::CheckGeometry& st = fc::testing::test_geometry(cx, 0.45, 0.3);
    const fc::Cell cell = fc::testing::cell_at(st, cx + 0.24, 0.63, 2);
    fc::State s;
    s.constants = {1.0, 0.08, 0.6};
    const FormKernels& gen = axi ? helfrich_axisymmetric_bending_2d : helfrich_lagrangian_bending_2d;
    FormKernels naive = gen;
    naive.matrix = axi ? &lmeform::naive::helfrich_axisymmetric_hessian : &lmeform::naive::helfrich_lagrangian_hessian;
    const std::vector<double> phi = fc::testing::phase_field(cell, cx, 0.45, 0.3, 0.08, 0.05, rng);
    if (axi) {
      s.unknowns = phi;
    } else {
      s.unknowns = fc::testing::deformation(cell, rng);
      s.qdata = fc::reference_qdata(cell, phi);
    }
    std::vector<double> Hg, Hn;
    r.gen_s = time_hessian(gen, cell, s, reps, Hg);
    r.naive_s = time_hessian(naive, cell, s, std::max(5, reps / 10), Hn);
    double m = 0;
    for (std::size_t i = 0; i < Hg.size(); ++i) {
      m = std::max(m, std::abs(Hg[i]));
      r.max_diff = std::max(r.max_diff, std::abs(Hg[i] - Hn[i]));
    }
    r.max_diff /= m;
    r.n = cell.n;
    r.nq = cell.nq;
    r.timed = true;
    r.flops_hessian_cell = 0;
    if (!(r.max_diff <= 1e-10)) {
      std::fprintf(stderr, "bench_kernels: %s generated and naive Hessians differ by %.3e (relative)\n",
                   r.form.c_str(), r.max_diff);
      agree = false;
    }
  }

  std::ofstream js(out / "kernels.json");
  js << "[\n";
  for (std::size_t i = 0; i < records.size(); ++i) {
    const Record& r = records[i];
    char b[1024];
    std::snprintf(b, sizeof b,
                  "  {\"form\": \"%s\", \"lmeformc_s\": %.6f, \"cxx_compile_s\": %.6f, \"generated_lines\": %ld, "
                  "\"flops_hessian\": %.0f",
                  r.form.c_str(), r.lmeformc_s, r.cxx_compile_s, r.generated_lines, r.flops_hessian);
    js << b;
    if (r.timed) {
      std::snprintf(b, sizeof b,
                    ", \"hessian_cell_s_generated\": %.9e, \"hessian_cell_s_naive\": %.9e, \"speedup_vs_naive\": %.3f, "
                    "\"hessian_max_rel_diff\": %.3e, \"cell_nodes\": %d, \"cell_points\": %d",
                    r.gen_s, r.naive_s, r.naive_s / r.gen_s, r.max_diff, r.n, r.nq);
      js << b;
    }
    js << "}" << (i + 1 < records.size() ? "," : "") << "\n";
  }
  js << "]\n";
  js.close();

  std::printf("%-34s %10s %10s %9s %12s %12s %12s %8s\n", "form", "lmeformc_s", "cxx_s", "lines", "flops_H/pt",
              "H_gen_s", "H_naive_s", "speedup");
  for (const Record& r : records) {
    std::printf("%-34s %10.3f %10.2f %9ld %12.0f", r.form.c_str(), r.lmeformc_s, r.cxx_compile_s, r.generated_lines,
                r.flops_hessian);
    if (r.timed)
      std::printf(" %12.3e %12.3e %8.1f   (n=%d, nq=%d, rel diff %.1e)", r.gen_s, r.naive_s, r.naive_s / r.gen_s, r.n,
                  r.nq, r.max_diff);
    std::printf("\n");
  }
  std::printf("wrote %s\n", (out / "kernels.json").string().c_str());
  std::error_code ec;
  fs::remove_all(work, ec);
  return agree ? 0 : 1;
}
