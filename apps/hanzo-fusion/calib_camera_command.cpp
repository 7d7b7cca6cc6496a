// hanzo-fusion calib camera: intrinsic calibration of a camera from a sensor log's images of a
// checkerboard (calib/camera_calibration.hpp). Prints the intrinsics, the distortion and the
// reprojection error; with --out writes them into the camera's entry of a calibration YAML
// (its mount and time offset kept; an entry at the body origin when the file has none).
// hanzo-fusion calib stereo: a stereo pair from image files of a checkerboard
// (calib/stereo_calibration.hpp): both cameras' intrinsics and the right camera's pose in the
// left's, with --out written into the YAML (the left's mount kept, the right's set from it).

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
#include "hanzo/fusion/calib/stereo_calibration.hpp"
#include "image_input.hpp"

#include <opencv2/imgcodecs.hpp>
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

struct StereoOptions {
  std::vector<std::string> left, right;
  std::string left_camera = "left", right_camera = "right";
  std::string board = "9x6";
  double square = 0.05;
  bool k3 = false;
  std::string out;
};

Result<std::vector<msgs::ImageMessage>> grey_images(const std::vector<std::string>& paths) {
  std::vector<msgs::ImageMessage> images;
  for (const std::string& path : paths) {
    cv::Mat grey;
    HANZO_ASSIGN_OR_RETURN(grey, read_image_input(path, cv::IMREAD_GRAYSCALE));
    msgs::ImageMessage& image = images.emplace_back();
    image.timestamp = Timestamp::from_seconds(static_cast<double>(images.size()));
    image.width = static_cast<uint32_t>(grey.cols);
    image.height = static_cast<uint32_t>(grey.rows);
    image.encoding = msgs::ImageEncoding::kMono8;
    image.data.assign(grey.datastart, grey.dataend);
  }
  return images;
}

int run_stereo(const Output& output, const StereoOptions& options) {
  nlohmann::json result = {{"kind", "stereo_calibration"}, {"left_camera", options.left_camera}, {"right_camera", options.right_camera}};
  calib::CameraCalibrationConfig config;
  auto target = parse_board(options.board, options.square);
  if (!target) return report_failure(output, result, target.error().message);
  config.target = *target;
  config.estimate_k3 = options.k3;
  auto left = grey_images(options.left);
  if (!left) return report_failure(output, result, left.error().message);
  auto right = grey_images(options.right);
  if (!right) return report_failure(output, result, right.error().message);
  auto stereo = calib::calibrate_stereo(*left, *right, config);
  if (!stereo) return report_failure(output, result, stereo.error().message);
  const Eigen::Vector3d t = stereo->T_left_right.translation();
  const Eigen::Matrix<double, 6, 1> sigma = stereo->covariance.diagonal().cwiseSqrt();
  result["left"] = calib::camera_calibration_to_json(stereo->left);
  result["right"] = calib::camera_calibration_to_json(stereo->right);
  result["T_left_right"] = {{"position", {t.x(), t.y(), t.z()}},
                            {"rotation_vector", {stereo->T_left_right.rotation().log().x(), stereo->T_left_right.rotation().log().y(),
                                                 stereo->T_left_right.rotation().log().z()}}};
  result["baseline"] = t.norm();
  result["sigma"] = {{"position", {sigma(0), sigma(1), sigma(2)}}, {"rotation", {sigma(3), sigma(4), sigma(5)}}};
  result["rms_px"] = stereo->rms_px;
  result["pair_rms_px"] = stereo->pair_rms_px;
  result["epipolar_error_px"] = stereo->epipolar_error_px;
  result["pairs"] = stereo->pairs_total;
  result["pairs_used"] = stereo->pairs_used;
  if (!options.out.empty()) {
    SE3 T_body_left;
    Status written = update_calibration_entry(options.out, options.left_camera, [&](calib::SensorCalibration& entry) {
      entry.camera = calib::CameraCalibration{stereo->left.intrinsics, stereo->left.distortion};
      T_body_left = entry.T_body_sensor();
    });
    if (written) {
      written = update_calibration_entry(options.out, options.right_camera, [&](calib::SensorCalibration& entry) {
        const calib::SensorCalibration mounted = calib::SensorCalibration::from_transform(options.right_camera, T_body_left * stereo->T_left_right,
                                                                                           entry.time_offset);
        entry.rotation_wxyz = mounted.rotation_wxyz;
        entry.translation = mounted.translation;
        entry.camera = calib::CameraCalibration{stereo->right.intrinsics, stereo->right.distortion};
      });
    }
    if (!written) return report_failure(output, result, written.error().message);
    result["out"] = options.out;
  }
  result["ok"] = true;
  std::string text = to_text(options.left_camera, stereo->left, "") + to_text(options.right_camera, stereo->right, "");
  text += fmt::format("{} in {}: position [{:.4f}, {:.4f}, {:.4f}] m (baseline {:.4f}, one sigma [{:.4f}, {:.4f}, {:.4f}]), rotation one sigma "
                      "[{:.4f}, {:.4f}, {:.4f}] rad\n",
                      options.right_camera, options.left_camera, t.x(), t.y(), t.z(), t.norm(), sigma(0), sigma(1), sigma(2), sigma(3), sigma(4), sigma(5));
  text += fmt::format("  {} of {} pairs: stereo reprojection error {:.3f} px rms, epipolar error {:.3f} px\n", stereo->pairs_used, stereo->pairs_total,
                      stereo->rms_px, stereo->epipolar_error_px);
  if (!options.out.empty()) text += fmt::format("wrote {} and {} into {}\n", options.left_camera, options.right_camera, options.out);
  return report_success(output, result, text);
}

}  // namespace

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

void add_calib_stereo_command(CLI::App& calib_app, const Output& output, Command& run) {
  CLI::App* command = calib_app.add_subcommand("stereo", "A stereo pair's intrinsics and extrinsics from image pairs of a checkerboard");
  auto options = std::make_shared<StereoOptions>();
  command->add_option("--left", options->left, "The left camera's images (in pair order)")->required();
  command->add_option("--right", options->right, "The right camera's images (as many, in the same order)")->required();
  command->add_option("--left-camera", options->left_camera, "The left camera's name in the calibration file")->capture_default_str();
  command->add_option("--right-camera", options->right_camera, "The right camera's name in the calibration file")->capture_default_str();
  command->add_option("--board", options->board, "Inner corners of the board, COLUMNSxROWS")->capture_default_str();
  command->add_option("--square", options->square, "Edge of a square, m")->capture_default_str();
  command->add_flag("--k3", options->k3, "Also estimate k3 (wide lenses)");
  command->add_option("--out", options->out, "Write both cameras into this calibration YAML (the left's mount kept, the right's set from it)");
  command->callback([&output, &run, options] { run = [&output, options] { return run_stereo(output, *options); }; });
}

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
