#pragma once
// Plots of an evaluation as self-contained SVG files (no scripts, fonts or network needed;
// any browser or image viewer opens them).

#include <string>
#include <vector>

#include "hanzo/fusion/core/result.hpp"
#include "hanzo/fusion/eval/statistics.hpp"
#include "hanzo/fusion/io/trajectory.hpp"

namespace hanzo::fusion::eval {

struct PlotLabels {
  std::string title;         ///< e.g. "APE w.r.t. translation part (m), SE(3) aligned"
  std::string error_label;   ///< axis / colour-bar label, e.g. "APE (m)"
  std::string time_label = "time (s)";  ///< x axis of the error plot ("frame" for KITTI files without times)
};

/// Top view (equal axes) of the reference (grey) and the estimate, each estimate segment
/// coloured by `errors` (one per estimate pose; the colour bar spans min..max). The view is
/// onto the plane of the two coordinate axes along which the reference extends most: x-y for
/// ENU data, x-z for camera-frame data such as KITTI's. Returns the SVG text.
std::string trajectory_top_view_svg(const io::Trajectory& reference, const io::Trajectory& estimate,
                                    const std::vector<double>& errors, const PlotLabels& labels);

/// Error over time (s since `times_s[0]`) with the rmse, mean and median as horizontal lines.
std::string error_over_time_svg(const std::vector<double>& times_s, const std::vector<double>& errors,
                                const ErrorStatistics& statistics, const PlotLabels& labels);

/// Writes `svg` to `path` atomically.
Status write_svg(const std::string& path, const std::string& svg);

}  // namespace hanzo::fusion::eval
