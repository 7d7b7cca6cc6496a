#pragma once
// Correlative scan matching for planar scans (Olson, "Real-time correlative scan matching",
// ICRA 2009): an exhaustive search of a window of SE2 poses around a guess for the one whose
// moved source points land on the most likely target cells. The target is rasterized into a
// likelihood grid, L(cell) = max over target points of exp(-d^2 / (2 sigma^2)) (Olson's
// eq. 5-6 with a Gaussian sensor model); a pose scores the mean of L over the source points.
// Rotations are searched in angular_step increments; for each rotation, translations in steps
// of one cell are integer index offsets, so a pose costs one grid lookup per point. A
// two-level branch and bound (Olson's sec. III-C) bounds blocks of translations with a grid of
// block maxima and scores only the blocks whose bound beats the best pose found.
//
// Use it where ICP's basin of convergence is too small: loop closures after drift, recovery
// when scan-to-map matching fails. Refine its result with point-to-line ICP (planar_icp.hpp):
// the search is only as fine as a cell and an angular step.
//
// Failure cases (an Error naming which): empty or non-finite clouds, an invalid config.

#include "hanzo/fusion/core/result.hpp"
#include "hanzo/fusion/core/se2.hpp"
#include "hanzo/fusion/lidar/planar_icp.hpp"

namespace hanzo::fusion::lidar {

struct CorrelativeScanMatcherConfig {
  double linear_window = 1.0;   ///< m, searched +- around the guess along x and y
  double angular_window = 0.35; ///< rad, searched +- around the guess's heading (20 deg)
  double resolution = 0.05;     ///< m, grid cell and translation step
  double angular_step = 0.0087; ///< rad (0.5 deg); Olson picks it so the farthest point moves about a cell
  double sigma = 0.1;           ///< m, standard deviation of the likelihood blur
  /// Branch and bound over blocks of 4 x 4 translations (the same result as the exhaustive
  /// search, in a fraction of the lookups); false: score every pose.
  bool branch_and_bound = true;

  Status validate() const;
};

struct CorrelativeScanMatch {
  SE2 T_target_source;
  /// Mean likelihood of the source points at the best pose, in [0, 1]: 1 when every point lies
  /// on a target point.
  double score = 0.0;
  size_t poses_evaluated = 0;  ///< bounds and poses scored
};

/// The best pose within the window around `T_target_source_guess`.
Result<CorrelativeScanMatch> correlative_scan_match(const PlanarPoints& source, const PlanarPoints& target,
                                                    const SE2& T_target_source_guess, const CorrelativeScanMatcherConfig& config = {});

}  // namespace hanzo::fusion::lidar
