// hanzo-fusion calib camera: intrinsic calibration of a camera from a sensor log's images of a
// checkerboard (calib/camera_calibration.hpp). Prints the intrinsics, the distortion and the
// reprojection error; with --out writes them into the camera's entry of a calibration YAML
// (its mount and time offset kept; an entry at the body origin when the file has none).

#include <algorithm>
#include <cctype>
#include <charconv>
#include <memory>
#include <string>
#include <string_view>
#include <vector>

#include <fmt/format.h>
#include <fmt/ranges.h>

#include "commands.hpp"
#include "hanzo/fusion/calib/camera_calibration.hpp"
#include "hanzo/fusion/calib/calibration_json.hpp"
#include "log_messages.hpp"

namespace hanzo::fusion::app {
namespace {

struct CameraOptions {
  std::string log;
  std::string topic;
  std::string camera = "camera";
  std::string board = "9x6";
  double square = 0.05;
  std::string model = "radtan";
  bool k3 = false;
  std::size_t max_views = calib::CameraCalibrationConfig{}.max_views;
  std::string out;
};

Result<calib::CheckerboardTarget> parse_board(const std::string& text, double square) {
  // COLUMNSxROWS, each all digits and within an int.
  const auto whole = [](std::string_view digits, int& value) {
    return !digits.empty() && std::all_of(digits.begin(), digits.end(), [](unsigned char c) { return std::isdigit(c); }) &&
           std::from_chars(digits.data(), digits.data() + digits.size(), value).ec == std::errc();
  };
  const std::size_t x = text.find('x');
  int columns = 0, rows = 0;
  if (x == std::string::npos || !whole(std::string_view(text).substr(0, x), columns) || !whole(std::string_view(text).substr(x + 1), rows)) {
    return Error(fmt::format("--board '{}': expected the inner corners as COLUMNSxROWS, e.g. 9x6", text));
  }
  return calib::CheckerboardTarget{columns, rows, square};
}

std::string to_text(const std::string& camera, const calib::CameraCalibrationResult& result, const std::string& out) {
  const msgs::CameraIntrinsics& k = result.intrinsics;
  std::string text = fmt::format("{} intrinsics from {} views ({} images, board found in {})\n", camera, result.views_used, result.views_total,
                                 result.views_found);
  text += fmt::format("  fx {:.3f}  fy {:.3f}  cx {:.3f}  cy {:.3f}  ({} x {} px)\n", k.fx, k.fy, k.cx, k.cy, k.width, k.height);
  if (result.intrinsics_std) text += fmt::format("  one sigma: [{:.3f}] px\n", fmt::join(*result.intrinsics_std, ", "));
  text += fmt::format("  {} [{:.6f}]\n", msgs::to_string(result.distortion.type), fmt::join(result.distortion.coefficients, ", "));
  text += fmt::format("  reprojection error {:.3f} px rms\n", result.rms_px);
  if (!out.empty()) text += fmt::format("wrote {}_to_body intrinsics into {}\n", camera, out);
  return text;
}

}  // namespace

void add_calib_camera_command(CLI::App& calib_app, const Output& output, Command& run) {
  CLI::App* command = calib_app.add_subcommand("camera", "Camera intrinsics and distortion from a log's images of a checkerboard");
  auto options = std::make_shared<CameraOptions>();
  command->add_option("LOG", options->log, "Sensor log (.mcap) with the camera's images")->required();
  command->add_option("--topic", options->topic, "Image topic (default: the first)");
  command->add_option("--camera", options->camera, "The camera's name in the calibration file (camera -> camera_to_body)")->capture_default_str();
  command->add_option("--board", options->board, "Inner corners of the board, COLUMNSxROWS")->capture_default_str();
  command->add_option("--square", options->square, "Edge of a square, m")->capture_default_str();
  command->add_option("--model", options->model, "Distortion model: radtan or equidistant")->capture_default_str();
  command->add_flag("--k3", options->k3, "radtan: also estimate k3 (wide lenses)");
  command->add_option("--max-views", options->max_views, "Views used at most, spread over the log")->capture_default_str();
  command->add_option("--out", options->out, "Write the intrinsics into this calibration YAML (other entries and the mount kept)");
  command->callback([&output, &run, options] {
    run = [&output, options] {
      nlohmann::json result = {{"kind", "camera_calibration"}, {"camera", options->camera}};
      calib::CameraCalibrationConfig config;
      auto target = parse_board(options->board, options->square);
      if (!target) return report_failure(output, result, target.error().message);
      config.target = *target;
      const std::optional<msgs::DistortionType> model = msgs::distortion_type_from_string(options->model);
      if (!model) return report_failure(output, result, fmt::format("--model '{}': use radtan or equidistant", options->model));
      config.model = *model;
      config.estimate_k3 = options->k3;
      config.max_views = options->max_views;
      auto images = read_log_messages<msgs::ImageMessage>(options->log, options->topic, "images");
      if (!images) return report_failure(output, result, images.error().message);
      auto calibrated = calib::calibrate_camera(*images, config);
      if (!calibrated) return report_failure(output, result, calibrated.error().message);
      if (!options->out.empty()) {
        const Status written = update_calibration_entry(options->out, options->camera, [&](calib::SensorCalibration& entry) {
          entry.camera = calib::CameraCalibration{calibrated->intrinsics, calibrated->distortion};
        });
        if (!written) return report_failure(output, result, written.error().message);
        result["out"] = options->out;
      }
      result.update(calib::camera_calibration_to_json(*calibrated));
      result["ok"] = true;
      return report_success(output, result, to_text(options->camera, *calibrated, options->out));
    };
  });
}

}  // namespace hanzo::fusion::app
