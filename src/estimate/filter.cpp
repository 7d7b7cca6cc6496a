#include "hanzo/fusion/estimate/filter.hpp"

#include <limits>

#include "hanzo/fusion/estimate/chi_square.hpp"

namespace hanzo::fusion::estimate {

std::string_view to_string(UpdateStatus status) {
  switch (status) {
    case UpdateStatus::kApplied: return "applied";
    case UpdateStatus::kRejectedByGate: return "gated";
    case UpdateStatus::kNumericalFailure: return "numerical_failure";
  }
  return "unknown";
}

ChiSquareGate::ChiSquareGate(double probability) {
  for (int dimension = 1; dimension <= kMaxMeasurementDimension; ++dimension) {
    thresholds_[static_cast<size_t>(dimension)] =
        probability >= 1.0 ? std::numeric_limits<double>::infinity() : chi_square_quantile(probability, dimension);
  }
}

}  // namespace hanzo::fusion::estimate
