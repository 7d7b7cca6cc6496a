#pragma once
// Summary statistics of an error array, defined as evo defines them: rmse = sqrt(sse / n),
// std is the population standard deviation (numpy's default ddof = 0), median of an even count
// is the mean of the two middle values.

#include <cstddef>
#include <vector>

namespace hanzo::fusion::eval {

struct ErrorStatistics {
  std::size_t count = 0;
  double rmse = 0.0;
  double mean = 0.0;
  double median = 0.0;
  double std = 0.0;
  double min = 0.0;
  double max = 0.0;
  double sse = 0.0;
};

/// All zero for an empty array.
ErrorStatistics compute_statistics(const std::vector<double>& errors);

}  // namespace hanzo::fusion::eval
