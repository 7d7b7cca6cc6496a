#include "hanzo/fusion/eval/statistics.hpp"

#include <algorithm>
#include <cmath>

namespace hanzo::fusion::eval {

ErrorStatistics compute_statistics(const std::vector<double>& errors) {
  ErrorStatistics stats;
  if (errors.empty()) return stats;
  const auto n = static_cast<double>(errors.size());
  stats.count = errors.size();
  double sum = 0.0;
  for (double e : errors) {
    sum += e;
    stats.sse += e * e;
  }
  stats.mean = sum / n;
  stats.rmse = std::sqrt(stats.sse / n);
  double squared_deviation = 0.0;
  for (double e : errors) squared_deviation += (e - stats.mean) * (e - stats.mean);
  stats.std = std::sqrt(squared_deviation / n);
  const auto [min_it, max_it] = std::minmax_element(errors.begin(), errors.end());
  stats.min = *min_it;
  stats.max = *max_it;
  std::vector<double> sorted = errors;
  std::sort(sorted.begin(), sorted.end());
  const std::size_t middle = sorted.size() / 2;
  stats.median = sorted.size() % 2 == 1 ? sorted[middle] : 0.5 * (sorted[middle - 1] + sorted[middle]);
  return stats;
}

}  // namespace hanzo::fusion::eval
