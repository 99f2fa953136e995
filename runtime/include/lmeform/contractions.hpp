// The dense contractions of generated kernels (kernel::ContractionRoutines), compiled once here
// with Eigen's matrix products so that generated code does not include Eigen. Every caller that
// fills a kernel::CellInputs sets `in.contractions = &lmeform::dense_contractions();`.
#pragma once

#include "lmeform/kernel.hpp"

namespace lmeform {

[[nodiscard]] const kernel::ContractionRoutines& dense_contractions() noexcept;

}  // namespace lmeform
