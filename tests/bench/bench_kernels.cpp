// bench_kernels: per form of the model library, the cost of generating and compiling its kernels
// and their size; per kernel (form, output, dimension) the flops per quadrature point of the value,
// gradient and Hessian, the ratios gradient/value and Hessian/value next to the bounds of the
// differentiation method, and the Hessian kernel's time on a check cell with the runtime's dense
// contractions (the n x n product by BLAS), with Eigen's products alone (eigen_contractions.hpp, the
// runtime's way before) and with the contract's plain loops (the way without routines); for
// helfrich_axisymmetric and helfrich_lagrangian also the generated Hessian against a naive
// thesis-style one (tests/bench/naive_kernels.hpp) on the same cell (they must agree to 1e-10).
//
//   bench_kernels [--quick] [--out DIR]      writes DIR/kernels.json and prints tables
//
// Baked in at build time: LMEFORMC (path of lmeformc), LMEFORM_CXX + LMEFORM_CXX_FLAGS (the
// compiler and flags of this build), LMEFORM_KERNEL_INCLUDES (runtime/include and Eigen),
// LMEFORM_FORMS_DIR and LMEFORM_FORM_LIST (the .form files, '|'-separated).
#include "eigen_contractions.hpp"
#include "naive_kernels.hpp"
#include "test_cells.hpp"

#include <lmeform/contractions.hpp>
#include <lmeform/form_check.hpp>
#include <lmeform/form_check_setup.hpp>
#include <lmeform/form_registry.hpp>
#include <lmeform/module_check.hpp>

#include <nlohmann/json.hpp>

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

struct Record {
  std::string form;
  double lmeformc_s = 0, cxx_compile_s = 0;
  long generated_lines = 0;
  nlohmann::json module_json;
  bool timed = false;
  double gen_s = 0, naive_s = 0, max_diff = 0;
  int n = 0, nq = 0;
};

/// Bounds of the differentiation method (compiler/src/codegen.cpp, plan_kernel): the gradient is
/// one reverse pass over the integrand's DAG, at most 4 times its operations (the cheap-gradient
/// principle, Griewank & Walther, Evaluating Derivatives, ch. 4); the Hessian is one reverse pass
/// over each of the m first derivatives, each at most 4 times the gradient: 16 m times the value.
/// CSE across the passes only lowers the cost.
constexpr double kGradientBound = 4.0;
double hessian_bound(int jet_components) { return 16.0 * jet_components; }

/// Median time of one Hessian call on the cell (the output is zeroed before each call).
double time_hessian(const FormKernels& f, const fc::Cell& cell, const fc::State& s, int reps,
                    std::vector<double>& H, const lmeform::kernel::ContractionRoutines* contractions = &lmeform::dense_contractions()) {
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
  in.coefficients = s.coefficients.empty() ? nullptr : s.coefficients.data();
  in.contractions = contractions;
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
    r.module_json = nlohmann::json::parse(read_file(dir / (r.form + ".json")));
    records.push_back(r);
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
    if (!(r.max_diff <= 1e-10)) {
      std::fprintf(stderr, "bench_kernels: %s generated and naive Hessians differ by %.3e (relative)\n",
                   r.form.c_str(), r.max_diff);
      agree = false;
    }
  }

  // Per kernel: flops per point from the module JSON, method bounds, and the Hessian's time per
  // cell with the runtime's dense contractions, with the Eigen-only ones and with the plain loops.
  nlohmann::json kernels_json = nlohmann::json::array();
  std::printf("\n%-34s %-12s %3s %3s %10s %10s %10s %7s %7s %8s %12s %12s %7s %12s %7s\n", "form", "output", "dim", "m",
              "flops_v/pt", "flops_g/pt", "flops_H/pt", "g/v", "H/v", "H bound", "H_dense_s", "H_plain_s", "plain/d", "H_eigen_s",
              "eigen/d");
  for (const Record& r : records) {
    const lmeform::FormModule& module = lmeform::load_form(r.form);
    std::string reason;
    const fc::Coordinates coords = fc::default_coordinates(r.form, module.source, {fs::path(module.source).parent_path()}, &reason);
    const auto constants = fc::resolve_constants(module.kernels, {}, 5);
    for (const FormKernels* k : module.kernels) {
      const std::string symbol = r.form + "_" + k->name + "_" + std::to_string(k->dim) + "d";
      nlohmann::json kj;
      for (const auto& e : r.module_json["kernels"])
        if (e["symbol"] == symbol) kj = e;
      if (kj.is_null()) continue;
      const int m = static_cast<int>(kj["jet_components"].size());
      auto per_point = [&](const char* kernel) {
        return kj["flops"].contains(kernel) ? kj["flops"][kernel]["per_point"].get<double>() : 0.0;
      };
      const double fv = per_point("value"), fg = per_point("vector"), fh = per_point("matrix");
      nlohmann::json rec{{"form", r.form},
                         {"output", k->name},
                         {"dim", k->dim},
                         {"jet_components", m},
                         {"flops_value_per_point", fv},
                         {"flops_gradient_per_point", fg},
                         {"flops_hessian_per_point", fh},
                         {"generated_lines", r.generated_lines},
                         {"cxx_compile_s", r.cxx_compile_s}};
      if (fv > 0 && fg > 0) rec["ratio_gradient_value"] = fg / fv, rec["bound_gradient_value"] = kGradientBound;
      if (fv > 0 && fh > 0) rec["ratio_hessian_value"] = fh / fv, rec["bound_hessian_value"] = hessian_bound(m);
      double dense_s = 0, plain_s = 0, eigen_s = 0;
      if (k->matrix != nullptr && fh > 0) {
        fc::GeometryOptions go;
        go.dim = k->dim;
        go.coordinates = coords;
        const fc::CheckGeometry geometry(go);
        bool vector_fields = false;
        for (int i = 0; i < k->n_unknowns; ++i) vector_fields = vector_fields || (k->dim > 1 && k->unknowns[i].components == k->dim);
        for (int i = 0; i < k->n_coefficients; ++i)
          vector_fields = vector_fields || (k->dim > 1 && k->coefficients[i].components == k->dim);
        const fc::Cell cell = geometry.check_cells(2, vector_fields).front();
        std::vector<double> values;
        for (int i = 0; i < k->n_constants; ++i)
          for (const auto& c : constants)
            if (c.name == k->constants[i]) values.push_back(c.value);
        std::mt19937_64 case_rng(17);
        const fc::CheckCase cc = fc::generic_case(*k, cell, geometry, values, fc::StateOptions{}, case_rng);
        std::vector<double> Hd, Hp, He;
        // Interleaved, so that a change of the machine's speed during the run hits all three.
        std::vector<double> dense_t, plain_t, eigen_t;
        for (int round = 0; round < 3; ++round) {
          dense_t.push_back(time_hessian(*k, cell, cc.state, reps, Hd));
          plain_t.push_back(time_hessian(*k, cell, cc.state, reps, Hp, nullptr));
          eigen_t.push_back(time_hessian(*k, cell, cc.state, reps, He, &lmeform::bench::eigen_contractions()));
        }
        dense_s = *std::min_element(dense_t.begin(), dense_t.end());
        plain_s = *std::min_element(plain_t.begin(), plain_t.end());
        eigen_s = *std::min_element(eigen_t.begin(), eigen_t.end());
        double big = 0, diff = 0;
        for (std::size_t i = 0; i < Hd.size(); ++i) {
          big = std::max(big, std::abs(Hd[i]));
          diff = std::max({diff, std::abs(Hd[i] - Hp[i]), std::abs(Hd[i] - He[i])});
        }
        const double rel = big > 0 ? diff / big : diff;
        rec["hessian_cell_s_dense"] = dense_s;
        rec["hessian_cell_s_plain"] = plain_s;
        rec["plain_over_dense"] = plain_s / dense_s;
        rec["hessian_cell_s_eigen"] = eigen_s;
        rec["eigen_over_dense"] = eigen_s / dense_s;
        rec["dense_plain_max_rel_diff"] = rel;
        rec["cell_nodes"] = cell.n;
        rec["cell_points"] = cell.nq;
        if (!(rel <= 1e-12)) {
          std::fprintf(stderr, "bench_kernels: %s: dense, Eigen and plain contractions differ by %.3e (relative)\n", symbol.c_str(), rel);
          agree = false;
        }
      }
      std::printf("%-34s %-12s %3d %3d %10.0f %10.0f %10.0f %7.2f %7.2f %8.0f", r.form.c_str(), k->name, k->dim, m, fv, fg,
                  fh, fv > 0 ? fg / fv : 0.0, fv > 0 ? fh / fv : 0.0, hessian_bound(m));
      if (dense_s > 0) std::printf(" %12.3e %12.3e %7.2f %12.3e %7.2f", dense_s, plain_s, plain_s / dense_s, eigen_s, eigen_s / dense_s);
      std::printf("\n");
      kernels_json.push_back(rec);
    }
  }

  nlohmann::json forms_json = nlohmann::json::array();
  for (const Record& r : records) {
    nlohmann::json f{{"form", r.form},
                     {"lmeformc_s", r.lmeformc_s},
                     {"cxx_compile_s", r.cxx_compile_s},
                     {"generated_lines", r.generated_lines}};
    if (r.timed) {
      f["hessian_cell_s_generated"] = r.gen_s;
      f["hessian_cell_s_naive"] = r.naive_s;
      f["speedup_vs_naive"] = r.naive_s / r.gen_s;
      f["hessian_max_rel_diff"] = r.max_diff;
      f["cell_nodes"] = r.n;
      f["cell_points"] = r.nq;
    }
    forms_json.push_back(f);
  }
  const nlohmann::json js{{"compiler", LMEFORM_CXX},
                          {"flags", LMEFORM_CXX_FLAGS},
                          {"forms", forms_json},
                          {"kernels", kernels_json}};
  {
    std::ofstream f(out / "kernels.json.tmp");
    f << js.dump(2) << "\n";
  }
  fs::rename(out / "kernels.json.tmp", out / "kernels.json");

  std::printf("\n%-34s %10s %10s %9s %12s %12s %8s\n", "form", "lmeformc_s", "cxx_s", "lines", "H_gen_s", "H_naive_s",
              "speedup");
  for (const Record& r : records) {
    std::printf("%-34s %10.3f %10.2f %9ld", r.form.c_str(), r.lmeformc_s, r.cxx_compile_s, r.generated_lines);
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
