#include "hanzo/fusion/eval/plots.hpp"

#include <algorithm>
#include <array>
#include <cmath>

#include <fmt/format.h>

#include "hanzo/fusion/core/yaml_value.hpp"

namespace hanzo::fusion::eval {
namespace {

constexpr double kWidth = 800.0;
constexpr double kHeight = 600.0;
constexpr double kMarginLeft = 80.0;
constexpr double kMarginRight = 110.0;  // room for the colour bar / legend
constexpr double kMarginTop = 50.0;
constexpr double kMarginBottom = 60.0;

// Linear map of a data interval onto a pixel interval.
struct Axis {
  double data_min;
  double data_max;
  double pixel_min;
  double pixel_max;
  double operator()(double v) const {
    const double span = data_max - data_min;
    return pixel_min + (span > 0 ? (v - data_min) / span : 0.5) * (pixel_max - pixel_min);
  }
};

std::string escape(const std::string& text) {
  std::string out;
  for (char c : text) {
    switch (c) {
      case '&': out += "&amp;"; break;
      case '<': out += "&lt;"; break;
      case '>': out += "&gt;"; break;
      case '"': out += "&quot;"; break;
      default: out += c;
    }
  }
  return out;
}

// Viridis, sampled at 5 stops and interpolated linearly: dark blue (low) to yellow (high).
std::string error_colour(double fraction) {
  static constexpr std::array<std::array<double, 3>, 5> kStops = {
      {{68, 1, 84}, {59, 82, 139}, {33, 145, 140}, {94, 201, 98}, {253, 231, 37}}};
  const double x = std::clamp(std::isfinite(fraction) ? fraction : 0.0, 0.0, 1.0) * (kStops.size() - 1);
  const auto i = std::min(static_cast<std::size_t>(x), kStops.size() - 2);
  const double t = x - static_cast<double>(i);
  std::array<int, 3> rgb{};
  for (std::size_t c = 0; c < 3; ++c) rgb[c] = static_cast<int>(std::lround(kStops[i][c] * (1 - t) + kStops[i + 1][c] * t));
  return fmt::format("#{:02x}{:02x}{:02x}", rgb[0], rgb[1], rgb[2]);
}

// "Nice" tick step (1, 2 or 5 x 10^k) giving about `count` ticks over span.
double tick_step(double span, int count) {
  if (!(span > 0)) return 1.0;
  const double raw = span / count;
  const double magnitude = std::pow(10.0, std::floor(std::log10(raw)));
  for (double m : {1.0, 2.0, 5.0}) {
    if (m * magnitude >= raw) return m * magnitude;
  }
  return 10.0 * magnitude;
}

std::string header(const std::string& title) {
  return fmt::format(
      "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"{0}\" height=\"{1}\" viewBox=\"0 0 {0} {1}\" "
      "font-family=\"sans-serif\" font-size=\"12\">\n<rect width=\"100%\" height=\"100%\" fill=\"white\"/>\n"
      "<text x=\"{2}\" y=\"28\" text-anchor=\"middle\" font-size=\"15\">{3}</text>\n",
      kWidth, kHeight, kWidth / 2, escape(title));
}

// Frame, grid and tick labels for both axes.
std::string axes(const Axis& x, const Axis& y, const std::string& x_label, const std::string& y_label) {
  std::string svg = fmt::format("<rect x=\"{}\" y=\"{}\" width=\"{}\" height=\"{}\" fill=\"none\" stroke=\"#444\"/>\n",
                                x.pixel_min, y.pixel_max, x.pixel_max - x.pixel_min, y.pixel_min - y.pixel_max);
  const double x_step = tick_step(x.data_max - x.data_min, 8);
  for (double v = std::ceil(x.data_min / x_step) * x_step; v <= x.data_max + 1e-9 * x_step; v += x_step) {
    svg += fmt::format("<line x1=\"{0:.1f}\" y1=\"{1}\" x2=\"{0:.1f}\" y2=\"{2}\" stroke=\"#ddd\"/>"
                       "<text x=\"{0:.1f}\" y=\"{3}\" text-anchor=\"middle\">{4:g}</text>\n",
                       x(v), y.pixel_min, y.pixel_max, y.pixel_min + 16, std::abs(v) < 1e-12 ? 0.0 : v);
  }
  const double y_step = tick_step(y.data_max - y.data_min, 6);
  for (double v = std::ceil(y.data_min / y_step) * y_step; v <= y.data_max + 1e-9 * y_step; v += y_step) {
    svg += fmt::format("<line x1=\"{0}\" y1=\"{1:.1f}\" x2=\"{2}\" y2=\"{1:.1f}\" stroke=\"#ddd\"/>"
                       "<text x=\"{3}\" y=\"{4:.1f}\" text-anchor=\"end\">{5:g}</text>\n",
                       x.pixel_min, y(v), x.pixel_max, x.pixel_min - 6, y(v) + 4, std::abs(v) < 1e-12 ? 0.0 : v);
  }
  svg += fmt::format("<text x=\"{}\" y=\"{}\" text-anchor=\"middle\">{}</text>\n", (x.pixel_min + x.pixel_max) / 2,
                     kHeight - 15, escape(x_label));
  svg += fmt::format("<text transform=\"translate(20 {}) rotate(-90)\" text-anchor=\"middle\">{}</text>\n",
                     (y.pixel_min + y.pixel_max) / 2, escape(y_label));
  return svg;
}

}  // namespace

std::string trajectory_top_view_svg(const io::Trajectory& reference, const io::Trajectory& estimate,
                                    const std::vector<double>& errors, const PlotLabels& labels) {
  // The two axes along which the trajectories extend most form the view plane.
  Eigen::Vector3d low = Eigen::Vector3d::Constant(INFINITY);
  Eigen::Vector3d high = Eigen::Vector3d::Constant(-INFINITY);
  for (const io::Trajectory* trajectory : {&reference, &estimate}) {
    for (std::size_t i = 0; i < trajectory->size(); ++i) {
      low = low.cwiseMin(trajectory->position(i));
      high = high.cwiseMax(trajectory->position(i));
    }
  }
  if (!std::isfinite(low.x())) low = high = Eigen::Vector3d::Zero();
  const Eigen::Vector3d extent = high - low;
  int h = 0, v = 1;  // horizontal and vertical axis index
  if (extent.z() > std::min(extent.x(), extent.y())) (extent.x() >= extent.y() ? v : h) = 2;
  if (h > v) std::swap(h, v);
  const double min_x = low[h], max_x = high[h], min_y = low[v], max_y = high[v];
  // Equal scale on both axes: widen the narrower data range to the plot's aspect ratio.
  const double plot_width = kWidth - kMarginLeft - kMarginRight;
  const double plot_height = kHeight - kMarginTop - kMarginBottom;
  const double metres_per_pixel = std::max({(max_x - min_x) / plot_width, (max_y - min_y) / plot_height, 1e-6}) * 1.05;
  const double centre_x = (min_x + max_x) / 2;
  const double centre_y = (min_y + max_y) / 2;
  const Axis x{centre_x - metres_per_pixel * plot_width / 2, centre_x + metres_per_pixel * plot_width / 2, kMarginLeft,
               kMarginLeft + plot_width};
  const Axis y{centre_y - metres_per_pixel * plot_height / 2, centre_y + metres_per_pixel * plot_height / 2,
               kMarginTop + plot_height, kMarginTop};

  const char* kAxisNames[] = {"x (m)", "y (m)", "z (m)"};
  std::string svg = header(labels.title) + axes(x, y, kAxisNames[h], kAxisNames[v]);
  std::string reference_points;
  for (std::size_t i = 0; i < reference.size(); ++i) {
    reference_points += fmt::format("{:.1f},{:.1f} ", x(reference.position(i)[h]), y(reference.position(i)[v]));
  }
  svg += fmt::format("<polyline points=\"{}\" fill=\"none\" stroke=\"#888\" stroke-width=\"1.5\" "
                     "stroke-dasharray=\"6 3\"/>\n", reference_points);
  const auto [min_it, max_it] = std::minmax_element(errors.begin(), errors.end());
  const double error_min = errors.empty() ? 0.0 : *min_it;
  const double error_max = errors.empty() ? 1.0 : *max_it;
  for (std::size_t i = 1; i < estimate.size(); ++i) {
    const double error = i < errors.size() ? errors[i] : error_min;
    svg += fmt::format("<line x1=\"{:.1f}\" y1=\"{:.1f}\" x2=\"{:.1f}\" y2=\"{:.1f}\" stroke=\"{}\" stroke-width=\"2\"/>\n",
                       x(estimate.position(i - 1)[h]), y(estimate.position(i - 1)[v]), x(estimate.position(i)[h]),
                       y(estimate.position(i)[v]), error_colour((error - error_min) / (error_max - error_min)));
  }
  // Colour bar.
  const double bar_x = kWidth - kMarginRight + 25;
  constexpr int kBarSteps = 50;
  for (int k = 0; k < kBarSteps; ++k) {
    const double step_height = plot_height / kBarSteps;
    svg += fmt::format("<rect x=\"{}\" y=\"{:.1f}\" width=\"18\" height=\"{:.1f}\" fill=\"{}\"/>\n", bar_x,
                       kMarginTop + plot_height - (k + 1) * step_height, step_height + 0.5, error_colour((k + 0.5) / kBarSteps));
  }
  svg += fmt::format("<text x=\"{0}\" y=\"{1}\">{2:.4g}</text><text x=\"{0}\" y=\"{3}\">{4:.4g}</text>\n", bar_x + 22,
                     kMarginTop + 10, error_max, kMarginTop + plot_height, error_min);
  svg += fmt::format("<text transform=\"translate({} {}) rotate(-90)\" text-anchor=\"middle\">{}</text>\n", bar_x + 80,
                     kMarginTop + plot_height / 2, escape(labels.error_label));
  svg += fmt::format("<text x=\"{}\" y=\"{}\" fill=\"#666\">dashed: reference; coloured: estimate</text>\n", kMarginLeft,
                     kMarginTop - 8);
  return svg + "</svg>\n";
}

std::string error_over_time_svg(const std::vector<double>& times_s, const std::vector<double>& errors,
                                const ErrorStatistics& statistics, const PlotLabels& labels) {
  const double t0 = times_s.empty() ? 0.0 : times_s.front();
  const double t1 = times_s.empty() ? 1.0 : times_s.back();
  const double error_max = errors.empty() ? 1.0 : *std::max_element(errors.begin(), errors.end());
  const Axis x{0.0, std::max(t1 - t0, 1e-9), kMarginLeft, kWidth - kMarginRight};
  const Axis y{0.0, std::max(error_max * 1.05, 1e-12), kHeight - kMarginBottom, kMarginTop};
  std::string svg = header(labels.title) + axes(x, y, labels.time_label, labels.error_label);
  std::string points;
  for (std::size_t i = 0; i < std::min(times_s.size(), errors.size()); ++i) {
    points += fmt::format("{:.1f},{:.1f} ", x(times_s[i] - t0), y(errors[i]));
  }
  svg += fmt::format("<polyline points=\"{}\" fill=\"none\" stroke=\"#1f77b4\" stroke-width=\"1.2\"/>\n", points);
  const std::array<std::pair<const char*, double>, 3> lines = {
      {{"rmse", statistics.rmse}, {"mean", statistics.mean}, {"median", statistics.median}}};
  const std::array<const char*, 3> colours = {"#d62728", "#2ca02c", "#9467bd"};
  for (std::size_t k = 0; k < lines.size(); ++k) {
    svg += fmt::format("<line x1=\"{0}\" y1=\"{1:.1f}\" x2=\"{2}\" y2=\"{1:.1f}\" stroke=\"{3}\" stroke-dasharray=\"5 3\"/>"
                       "<text x=\"{4}\" y=\"{5:.1f}\" fill=\"{3}\">{6} {7:.4g}</text>\n",
                       x.pixel_min, y(lines[k].second), x.pixel_max, colours[k], x.pixel_max + 6,
                       y(lines[k].second) + 4 + 13.0 * (static_cast<double>(k) - 1.0), lines[k].first, lines[k].second);
  }
  return svg + "</svg>\n";
}

Status write_svg(const std::string& path, const std::string& svg) { return yaml::write_file_atomically(path, svg); }

}  // namespace hanzo::fusion::eval
