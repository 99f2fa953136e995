// bench_lme: LME basis evaluation speed and full vs compressed storage (seed Table B.2), and the
// neighbour search on a strongly graded node set.
//   bench_lme [--quick] [--out DIR]   writes DIR/lme_basis.json, DIR/graded_lists.json and
//                                     DIR/point_lists.json (default DIR: .)
// One record per (dim, gamma): nodes on a jittered grid of [0,1]^d, evaluation points uniform in
// the inner half of the box (full supports), their primal lists from the Tol0 = 1e-6 cutoff.
// graded_lists: the nested grids of a 3D box graded to a sphere (spacings 1 : 8), the lists of
// points spread over the box from per-node supports, searched by radius classes (primal_lists)
// against one search with the largest radius, filtered (the same lists, checked). point_lists: the
// lists of points asked for one at a time against one call for all, on 10^4 and 10^5 nodes.
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <random>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "lmeform/domain.hpp"
#include "lmeform/kernel.hpp"
#include "lmeform/lme_basis.hpp"
#include "lmeform/lme_storage.hpp"
#include "lmeform/neighbour_search.hpp"

namespace {

using Clock = std::chrono::steady_clock;
double seconds_since(Clock::time_point t0) { return std::chrono::duration<double>(Clock::now() - t0).count(); }

lmeform::NodeSet jittered_grid(int dim, int per_side, unsigned seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> u(-0.1, 0.1);
  const double step = 1.0 / (per_side - 1);
  std::vector<double> c;
  int total = 1;
  for (int i = 0; i < dim; ++i) total *= per_side;
  for (int k = 0; k < total; ++k) {
    int rest = k;
    for (int i = 0; i < dim; ++i) {
      const int idx = rest % per_side;
      rest /= per_side;
      const bool edge = idx == 0 || idx == per_side - 1;
      c.push_back(idx * step + (edge ? 0.0 : u(rng) * step));
    }
  }
  return lmeform::NodeSet(dim, std::move(c));
}

/// The nodes b with |x - x_b| <= radii[b], from one search with the largest radius.
lmeform::CsrLists lists_by_one_search(const lmeform::KdTree& tree, std::span<const double> points, std::span<const double> radii) {
  const auto d = static_cast<std::size_t>(tree.dim());
  const double rmax = *std::max_element(radii.begin(), radii.end());
  lmeform::CsrLists lists;
  std::vector<int> cand;
  for (std::size_t q = 0; q < points.size() / d; ++q) {
    const auto x = points.subspan(q * d, d);
    tree.radius_search(x, rmax, cand);
    for (const int b : cand) {
      const auto xb = tree.nodes().point(static_cast<std::size_t>(b));
      double d2 = 0;
      for (std::size_t i = 0; i < d; ++i) d2 += (x[i] - xb[i]) * (x[i] - xb[i]);
      if (d2 <= radii[static_cast<std::size_t>(b)] * radii[static_cast<std::size_t>(b)]) lists.indices.push_back(b);
    }
    lists.offsets.push_back(static_cast<int>(lists.indices.size()));
  }
  return lists;
}

/// Graded 3D lists: nested grids of [0, 1.5]^3, h = 1/32 within 0.1 of the sphere |x| = 0.6,
/// growing by 0.2 per unit distance up to 1/4; supports of gamma 0.8 and Tol0 1e-6 on the smoothed
/// spacing (the basis' rule).
nlohmann::json graded_lists(bool quick) {
  const double fine = 1.0 / 32, coarse = 0.25;
  const lmeform::Box box{3, {0, 0, 0}, {1.5, 1.5, 1.5}};
  const lmeform::SpacingFunction spacing{[=](std::span<const double> x) {
                                           const double d = std::abs(std::sqrt(x[0] * x[0] + x[1] * x[1] + x[2] * x[2]) - 0.6);
                                           return std::min(coarse, fine + 0.2 * std::max(0.0, d - 0.1));
                                         },
                                         fine};
  const lmeform::NodeSet nodes = lmeform::nested_grids(box, spacing);
  const lmeform::KdTree tree(nodes);
  const std::vector<double> h = lmeform::smooth_spacing(tree, lmeform::nodal_spacing(tree), 5);
  std::vector<double> radii(h.size());
  for (std::size_t a = 0; a < h.size(); ++a) radii[a] = lmeform::support_radius(0.8 / (h[a] * h[a]), 1e-6);
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> u(0.0, 1.5);
  std::vector<double> pts(std::size_t(3) * (quick ? 2000 : 20000));
  for (double& v : pts) v = u(rng);
  auto t0 = Clock::now();
  const lmeform::CsrLists by_class = lmeform::primal_lists(tree, pts, radii);
  const double classes_s = seconds_since(t0);
  t0 = Clock::now();
  const lmeform::CsrLists by_one = lists_by_one_search(tree, pts, radii);
  const double one_s = seconds_since(t0);
  const bool equal = by_class.offsets == by_one.offsets && by_class.indices == by_one.indices;
  std::printf("graded 3D lists: %zu nodes (spacing %.4g to %.4g), %zu points, mean list %.1f: radius classes %.3f s, "
              "one search %.3f s (%.1fx), lists %s\n",
              nodes.size(), fine, coarse, by_class.size(), by_class.mean_size(), classes_s, one_s, one_s / classes_s,
              equal ? "equal" : "DIFFERENT");
  return {{"case", "graded_lists_3d"}, {"nodes", nodes.size()}, {"points", by_class.size()}, {"mean_list", by_class.mean_size()},
          {"classes_s", classes_s}, {"one_search_s", one_s}, {"speedup", one_s / classes_s}, {"equal", equal}, {"quick", quick}};
}

/// Lists asked for one point at a time (LmeBasis::neighbours, as field jets, transfers and point
/// values ask) against one call for all points, on jittered 2D grids of two sizes: the cost per
/// point must not grow with the nodes (it did while every call scanned every support radius).
nlohmann::json point_by_point_lists(bool quick) {
  nlohmann::json records = nlohmann::json::array();
  for (const int per_side : quick ? std::vector<int>{51, 161} : std::vector<int>{101, 317}) {
    const lmeform::NodeSet nodes = jittered_grid(2, per_side, 4);
    const lmeform::LmeBasis basis(nodes, std::vector<double>{0.8});
    std::mt19937 rng(5);
    std::uniform_real_distribution<double> u(0.0, 1.0);
    std::vector<double> pts(std::size_t(2) * (quick ? 2000 : 20000));
    for (double& v : pts) v = u(rng);
    auto t0 = Clock::now();
    const lmeform::CsrLists all = basis.neighbour_lists(pts);
    const double batched_s = seconds_since(t0);
    t0 = Clock::now();
    bool equal = true;
    for (std::size_t q = 0; q < all.size(); ++q) {
      const std::vector<int> one = basis.neighbours(std::span<const double>(pts).subspan(2 * q, 2));
      equal = equal && std::equal(one.begin(), one.end(), all[q].begin(), all[q].end());
    }
    const double one_by_one_s = seconds_since(t0);
    const double points = double(all.size());
    std::printf("lists point by point: %zu nodes, %zu points, mean list %.1f: %.2f us per point one by one, %.2f us batched "
                "(%.2fx), lists %s\n",
                nodes.size(), all.size(), all.mean_size(), 1e6 * one_by_one_s / points, 1e6 * batched_s / points,
                one_by_one_s / batched_s, equal ? "equal" : "DIFFERENT");
    records.push_back({{"case", "point_by_point_lists_2d"}, {"nodes", nodes.size()}, {"points", all.size()},
                       {"mean_list", all.mean_size()}, {"one_by_one_us_per_point", 1e6 * one_by_one_s / points},
                       {"batched_us_per_point", 1e6 * batched_s / points}, {"ratio", one_by_one_s / batched_s},
                       {"equal", equal}, {"quick", quick}});
  }
  return records;
}

struct Record {
  int dim;
  double gamma;
  std::size_t points;
  double mean_neighbours, full_doubles, compressed_doubles, memory_ratio, evals_values, evals_hessians,
      reconstruct_over_full, reconstruct_over_evaluate, seed_ratio;
};

}  // namespace

int main(int argc, char** argv) {
  bool quick = false;
  std::string out = ".";
  for (int i = 1; i < argc; ++i) {
    if (std::strcmp(argv[i], "--quick") == 0) {
      quick = true;
    } else if (std::strcmp(argv[i], "--out") == 0 && i + 1 < argc) {
      out = argv[++i];
    } else {
      std::fprintf(stderr, "usage: %s [--quick] [--out DIR]\n", argv[0]);
      return 2;
    }
  }
  std::vector<Record> records;
  double checksum = 0.0;
  for (const int dim : {2, 3}) {
    for (const double gamma : {0.8, 1.6, 4.0}) {
      const int per_side = dim == 2 ? (quick ? 41 : 101) : (quick ? 15 : 25);
      const int npts = dim == 2 ? (quick ? 3000 : 30000) : (quick ? 600 : 6000);
      const lmeform::NodeSet nodes = jittered_grid(dim, per_side, 1);
      const lmeform::LmeBasis basis(nodes, std::vector<double>{gamma});
      std::mt19937 rng(2);
      std::uniform_real_distribution<double> u(0.25, 0.75);
      std::vector<double> pts(static_cast<std::size_t>(npts * dim));
      for (double& v : pts) v = u(rng);
      const lmeform::CsrLists lists = basis.neighbour_lists(pts);
      const auto d = static_cast<std::size_t>(dim);
      std::size_t nmax = 0;
      for (std::size_t q = 0; q < lists.size(); ++q) nmax = std::max(nmax, lists[q].size());
      std::vector<double> jet(static_cast<std::size_t>(lmeform::kernel::jet_size(dim, 2)) * nmax);
      lmeform::LmeWorkspace ws;

      auto time_evals = [&](int order) {
        const auto t0 = Clock::now();
        for (std::size_t q = 0; q < lists.size(); ++q) {
          basis.evaluate(std::span<const double>(pts).subspan(q * d, d), lists[q], order, jet, ws);
          checksum += jet[0];
        }
        return static_cast<double>(lists.size()) / seconds_since(t0);
      };
      const double ev0 = time_evals(0);
      const double t_eval2 = static_cast<double>(lists.size()) / time_evals(2);

      const lmeform::LmeFullStorage full(basis, pts, lists, 2);
      const lmeform::LmeCompressedStorage comp(basis, pts, lists, 2);
      // Getting every point's (p, grad p, Hp) from each storage, repeated for a measurable time.
      const int reps = 5;
      auto t0 = Clock::now();
      for (int r = 0; r < reps; ++r)
        for (std::size_t q = 0; q < lists.size(); ++q) {
          full.point_jet(q, 2, jet);
          checksum += jet[lists[q].size() - 1];
        }
      const double t_full = seconds_since(t0) / reps;
      t0 = Clock::now();
      for (int r = 0; r < reps; ++r)
        for (std::size_t q = 0; q < lists.size(); ++q) {
          comp.point_jet(basis, q, 2, jet, ws);
          checksum += jet[lists[q].size() - 1];
        }
      const double t_comp = seconds_since(t0) / reps;

      Record rec{};
      rec.dim = dim;
      rec.gamma = gamma;
      rec.points = lists.size();
      rec.mean_neighbours = lists.mean_size();
      rec.full_doubles = static_cast<double>(full.doubles());
      rec.compressed_doubles = static_cast<double>(comp.doubles());
      rec.memory_ratio = rec.full_doubles / rec.compressed_doubles;
      rec.evals_values = ev0;
      rec.evals_hessians = static_cast<double>(lists.size()) / t_eval2;
      rec.reconstruct_over_full = t_comp / t_full;
      rec.reconstruct_over_evaluate = t_comp / t_eval2;
      rec.seed_ratio = rec.mean_neighbours / (2.0 + dim);
      records.push_back(rec);
    }
  }

  std::printf("LME basis benchmark (%s): Tol0 = 1e-6, order-2 storages\n", quick ? "quick" : "full");
  std::printf("%3s %5s %7s %8s %12s %12s %8s %8s %12s %12s %9s %9s\n", "dim", "gamma", "points", "nbar", "full_dbl",
              "compr_dbl", "mem_rat", "seed_est", "evals/s p", "evals/s Hp", "rec/full", "rec/eval");
  for (const auto& r : records) {
    std::printf("%3d %5.1f %7zu %8.1f %12.0f %12.0f %8.1f %8.1f %12.0f %12.0f %9.1f %9.3f\n", r.dim, r.gamma, r.points,
                r.mean_neighbours, r.full_doubles, r.compressed_doubles, r.memory_ratio, r.seed_ratio, r.evals_values,
                r.evals_hessians, r.reconstruct_over_full, r.reconstruct_over_evaluate);
  }
  std::printf("rec/full: time to get p, grad p, Hp of all points from compressed records over reading them from full\n"
              "storage; rec/eval: the same over a fresh evaluation (Newton + formulas). checksum %.3e\n",
              checksum);

  std::filesystem::create_directories(out);
  const auto path = std::filesystem::path(out) / "lme_basis.json";
  nlohmann::json basis_records = nlohmann::json::array();
  for (const auto& r : records)
    basis_records.push_back({{"dim", r.dim},
                             {"gamma", r.gamma},
                             {"points", r.points},
                             {"mean_neighbours", r.mean_neighbours},
                             {"full_storage_doubles", r.full_doubles},
                             {"compressed_storage_doubles", r.compressed_doubles},
                             {"memory_ratio", r.memory_ratio},
                             {"seed_memory_ratio_estimate", r.seed_ratio},
                             {"evals_per_s_values", r.evals_values},
                             {"evals_per_s_hessians", r.evals_hessians},
                             {"reconstruct_over_full_time_ratio", r.reconstruct_over_full},
                             {"reconstruct_over_evaluate_time_ratio", r.reconstruct_over_evaluate},
                             {"quick", quick}});
  std::ofstream js(path);
  js << basis_records.dump(2) << "\n";
  std::printf("wrote %s\n", path.string().c_str());
  const nlohmann::json graded = graded_lists(quick);
  const auto graded_path = std::filesystem::path(out) / "graded_lists.json";
  std::ofstream gs(graded_path);
  gs << graded.dump(2) << "\n";
  std::printf("wrote %s\n", graded_path.string().c_str());
  const nlohmann::json by_point = point_by_point_lists(quick);
  const auto by_point_path = std::filesystem::path(out) / "point_lists.json";
  std::ofstream ps(by_point_path);
  ps << by_point.dump(2) << "\n";
  std::printf("wrote %s\n", by_point_path.string().c_str());
  const bool lists_equal = std::all_of(by_point.begin(), by_point.end(), [](const nlohmann::json& r) { return r["equal"].get<bool>(); });
  return js && gs && ps && graded["equal"].get<bool>() && lists_equal ? 0 : 1;
}
