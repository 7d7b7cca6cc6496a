#include "hanzo/fusion/estimate/chi_square.hpp"

#include <cassert>
#include <cmath>

namespace hanzo::fusion::estimate {
namespace {

// Regularized lower incomplete gamma P(a, x).
double regularized_gamma_p(double a, double x) {
  if (x <= 0.0) return 0.0;
  const double log_prefactor = a * std::log(x) - x - std::lgamma(a);
  if (x < a + 1.0) {
    // Series: P = e^-x x^a / Gamma(a+1) * sum x^n / ((a+1)...(a+n)).
    double term = 1.0 / a;
    double sum = term;
    for (int n = 1; n < 1000; ++n) {
      term *= x / (a + n);
      sum += term;
      if (std::abs(term) < std::abs(sum) * 1e-16) break;
    }
    return sum * std::exp(log_prefactor);
  }
  // Continued fraction for Q = 1 - P (modified Lentz).
  constexpr double kTiny = 1e-300;
  double b = x + 1.0 - a;
  double c = 1.0 / kTiny;
  double d = 1.0 / b;
  double h = d;
  for (int i = 1; i < 1000; ++i) {
    const double an = -i * (i - a);
    b += 2.0;
    d = an * d + b;
    if (std::abs(d) < kTiny) d = kTiny;
    c = b + an / c;
    if (std::abs(c) < kTiny) c = kTiny;
    d = 1.0 / d;
    const double delta = d * c;
    h *= delta;
    if (std::abs(delta - 1.0) < 1e-16) break;
  }
  return 1.0 - std::exp(log_prefactor) * h;
}

}  // namespace

double chi_square_cdf(double x, int degrees) {
  assert(degrees >= 1);
  return regularized_gamma_p(0.5 * degrees, 0.5 * x);
}

double chi_square_quantile(double probability, int degrees) {
  assert(probability > 0.0 && probability < 1.0 && degrees >= 1);
  double low = 0.0;
  double high = degrees + 10.0 * std::sqrt(2.0 * degrees) + 50.0;
  while (chi_square_cdf(high, degrees) < probability) high *= 2.0;
  for (int i = 0; i < 200 && high - low > 1e-12 * high; ++i) {
    const double middle = 0.5 * (low + high);
    (chi_square_cdf(middle, degrees) < probability ? low : high) = middle;
  }
  return 0.5 * (low + high);
}

}  // namespace hanzo::fusion::estimate
