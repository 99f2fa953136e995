// Private: one qhull computation (reentrant C API) with RAII cleanup and qhull's messages kept for errors.
#pragma once

#include <cstdio>
#include <string>
#include <vector>

extern "C" {
#include <libqhull_r/qhull_ra.h>
}

#include "lmeform/node_set.hpp"

namespace lmeform::detail {

/// Throws std::invalid_argument unless there are at least dim + 1 nodes spanning dim dimensions.
void require_full_dimensional(const NodeSet& nodes, const char* who);

class QhullRun {
 public:
  /// options without the leading "qhull", e.g. "d Qbb Qt Qz". Throws std::runtime_error with qhull's
  /// own message when qhull reports an error.
  QhullRun(const NodeSet& nodes, const char* options, const char* who);
  ~QhullRun();
  QhullRun(const QhullRun&) = delete;
  QhullRun& operator=(const QhullRun&) = delete;

  qhT* get() noexcept { return &qh_; }
  [[nodiscard]] int point_count() const noexcept { return npoints_; }

 private:
  void release() noexcept;
  qhT qh_{};
  std::vector<coordT> points_;  // qhull keeps a pointer into this array for the whole run
  int npoints_ = 0;
  char* errbuf_ = nullptr;
  std::size_t errlen_ = 0;
  FILE* err_ = nullptr;
  bool active_ = false;
};

}  // namespace lmeform::detail
