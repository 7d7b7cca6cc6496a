#pragma once
// Chi-square distribution helpers for innovation gating and consistency (NEES/NIS) checks.

namespace hanzo::fusion::estimate {

/// P(X <= x) for X ~ chi-square with `degrees` degrees of freedom (regularized lower
/// incomplete gamma function; series / continued fraction, Numerical Recipes 6.2).
double chi_square_cdf(double x, int degrees);

/// The x with chi_square_cdf(x, degrees) == probability, probability in (0, 1), degrees >= 1.
/// E.g. chi_square_quantile(0.95, 3) = 7.8147. Bisection to 1e-12 relative.
double chi_square_quantile(double probability, int degrees);

}  // namespace hanzo::fusion::estimate
