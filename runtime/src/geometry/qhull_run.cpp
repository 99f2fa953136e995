#include "qhull_run.hpp"

#include <array>
#include <cmath>
#include <cstdlib>
#include <limits>
#include <stdexcept>

namespace lmeform::detail {

void require_full_dimensional(const NodeSet& nodes, const char* who) {
  const auto d = nodes.dim;
  const auto n = static_cast<long>(nodes.size());
  if (nodes.dim < 1 || nodes.dim > 3) throw std::invalid_argument(std::string(who) + ": dimension must be 1, 2 or 3, got " + std::to_string(nodes.dim));
  if (n < d + 1) {
    throw std::invalid_argument(std::string(who) + ": " + std::to_string(n) + " nodes are too few in " + std::to_string(d) +
                                "D (need at least " + std::to_string(d + 1) + ")");
  }
  // Greedy affine-rank test, relative to the extent of the set so that it does not depend on length
  // units: the farthest node from node 0, then the farthest from that line, then from that plane.
  const auto dd = static_cast<std::size_t>(d);
  auto at = [&](std::size_t a, std::size_t i) { return nodes.coords[a * dd + i] - nodes.coords[i]; };
  const auto shape = [&](const char* word) {
    return std::invalid_argument(std::string(who) + ": all " + std::to_string(n) + " nodes are " + word +
                                 " (they span fewer than " + std::to_string(d) + " dimensions)");
  };
  double l2 = 0;
  std::size_t p1 = 0;
  for (std::size_t a = 0; a < nodes.size(); ++a) {
    double s = 0;
    for (std::size_t i = 0; i < dd; ++i) s += at(a, i) * at(a, i);
    if (s > l2) {
      l2 = s;
      p1 = a;
    }
  }
  const double extent = std::sqrt(l2);
  if (!(extent > 0)) throw shape("coincident");
  if (d == 1) return;
  std::array<double, 3> u{}, w{};
  for (std::size_t i = 0; i < dd; ++i) u[i] = at(p1, i) / extent;
  double far = 0;
  for (std::size_t a = 0; a < nodes.size(); ++a) {
    double along = 0;
    for (std::size_t i = 0; i < dd; ++i) along += at(a, i) * u[i];
    double s = 0;
    std::array<double, 3> r{};
    for (std::size_t i = 0; i < dd; ++i) {
      r[i] = at(a, i) - along * u[i];
      s += r[i] * r[i];
    }
    if (s > far) {
      far = s;
      w = r;
    }
  }
  if (!(std::sqrt(far) > 1e-12 * extent)) throw shape("collinear");
  if (d == 2) return;
  std::array<double, 3> nrm{u[1] * w[2] - u[2] * w[1], u[2] * w[0] - u[0] * w[2], u[0] * w[1] - u[1] * w[0]};
  const double nl = std::sqrt(nrm[0] * nrm[0] + nrm[1] * nrm[1] + nrm[2] * nrm[2]);
  double off = 0;
  for (std::size_t a = 0; a < nodes.size(); ++a)
    off = std::max(off, std::abs(at(a, 0) * nrm[0] + at(a, 1) * nrm[1] + at(a, 2) * nrm[2]) / nl);
  if (!(off > 1e-12 * extent)) throw shape("coplanar");
}

QhullRun::QhullRun(const NodeSet& nodes, const char* options, const char* who)
    : points_(nodes.coords.begin(), nodes.coords.end()), npoints_(static_cast<int>(nodes.size())) {
  if (nodes.size() > static_cast<std::size_t>(std::numeric_limits<int>::max())) {
    throw std::invalid_argument(std::string(who) + ": too many nodes for qhull (" + std::to_string(nodes.size()) + ")");
  }
  err_ = open_memstream(&errbuf_, &errlen_);
  if (err_ == nullptr) throw std::runtime_error(std::string(who) + ": cannot open a memory stream for qhull's messages");
  QHULL_LIB_CHECK
  qh_zero(&qh_, err_);
  active_ = true;
  std::string cmd = std::string("qhull ") + options;
  const int code = qh_new_qhull(&qh_, nodes.dim, npoints_, points_.data(), False, cmd.data(), nullptr, err_);
  if (code != 0) {
    std::fflush(err_);
    std::string msg(errbuf_ == nullptr ? "" : errbuf_, errlen_);
    release();
    throw std::runtime_error(std::string(who) + ": qhull (" + options + ") failed with exit code " + std::to_string(code) +
                             " on " + std::to_string(nodes.size()) + " nodes in " + std::to_string(nodes.dim) + "D:\n" + msg);
  }
}

QhullRun::~QhullRun() { release(); }

void QhullRun::release() noexcept {
  if (active_) {
    qh_freeqhull(&qh_, !qh_ALL);
    int curlong = 0, totlong = 0;
    qh_memfreeshort(&qh_, &curlong, &totlong);
    active_ = false;
  }
  if (err_ != nullptr) {
    std::fclose(err_);
    err_ = nullptr;
  }
  std::free(errbuf_);
  errbuf_ = nullptr;
}

}  // namespace lmeform::detail
