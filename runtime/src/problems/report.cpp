#include "report.hpp"

#include <cmath>

namespace lmeform::problems {

nlohmann::json json_number(double v) { return std::isfinite(v) ? nlohmann::json(v) : nlohmann::json(nullptr); }

}  // namespace lmeform::problems
