// hanzo-fusion calib camera-lidar: the LiDAR's pose in a camera's frame from a sensor log in
// which both saw a checkerboard held still at several stations (calib/camera_lidar_calibration.hpp).
// Prints T_camera_lidar, its one-sigma bounds and the residuals; with --out writes the LiDAR's
// entry (lidar_to_body = camera_to_body * T_camera_lidar) into a calibration YAML, only when the
// result is certified.

#include <charconv>
#include <memory>
#include <string>
#include <system_error>

#include <fmt/format.h>

#include "commands.hpp"
#include "hanzo/fusion/calib/camera_lidar_calibration.hpp"
#include "log_messages.hpp"

namespace hanzo::fusion::app {
namespace {

struct CameraLidarOptions {
  std::string log;
  std::string camera = "camera", lidar = "lidar";
  std::string camera_topic, lidar_topic;
  std::string board = "8x6";
  double square = 0.10;
  std::string board_size;
  std::string calibration;
  bool initial_guess = false;
  double max_corner_motion = calib::CameraLidarCalibrationConfig{}.max_corner_motion_px;
  std::string out;
};

// "WIDTHxHEIGHT" in metres, both > 0.
Result<std::pair<double, double>> parse_board_size(const std::string& text) {
  const std::size_t x = text.find('x');
  double width = 0.0, height = 0.0;
  const auto number = [](std::string_view digits, double& value) {
    const auto [end, error] = std::from_chars(digits.data(), digits.data() + digits.size(), value);
    return error == std::errc() && end == digits.data() + digits.size() && value > 0.0;
  };
  if (x == std::string::npos || !number(std::string_view(text).substr(0, x), width) || !number(std::string_view(text).substr(x + 1), height)) {
    return Error(fmt::format("--board-size '{}': expected the board's width and height in metres as WIDTHxHEIGHT, e.g. 1.1x0.9", text));
  }
  return std::pair{width, height};
}

nlohmann::json pose_json(const SE3& T) {
  const Eigen::Vector3d t = T.translation();
  const Eigen::Vector4d q = T.rotation().wxyz();
  const Eigen::Vector3d phi = T.rotation().log();
  return {{"position", {t.x(), t.y(), t.z()}}, {"rotation_wxyz", {q(0), q(1), q(2), q(3)}}, {"rotation_vector", {phi.x(), phi.y(), phi.z()}}};
}

int run_camera_lidar(const Output& output, const CameraLidarOptions& options) {
  nlohmann::json result = {{"kind", "camera_lidar_calibration"}, {"camera", options.camera}, {"lidar", options.lidar}};
  calib::CameraLidarCalibrationConfig config;
  auto target = parse_board(options.board, options.square);
  if (!target) return report_failure(output, result, target.error().message);
  config.target = *target;
  if (!options.board_size.empty()) {
    auto size = parse_board_size(options.board_size);
    if (!size) return report_failure(output, result, size.error().message);
    config.board_width = size->first;
    config.board_height = size->second;
  }
  config.max_corner_motion_px = options.max_corner_motion;
  std::optional<calib::Calibration> calibration;
  if (!options.calibration.empty()) {
    auto loaded = calib::load_calibration(options.calibration);
    if (!loaded) return report_failure(output, result, loaded.error().message);
    calibration = std::move(*loaded);
  }
  const calib::SensorCalibration* camera_entry = calibration ? calibration->find(options.camera) : nullptr;
  if (options.initial_guess) {
    const calib::SensorCalibration* lidar_entry = calibration ? calibration->find(options.lidar) : nullptr;
    if (camera_entry == nullptr || lidar_entry == nullptr) {
      return report_failure(output, result, fmt::format("--initial-guess: --calibration needs both {0}_to_body and {1}_to_body", options.camera, options.lidar));
    }
    config.initial_T_camera_lidar = camera_entry->T_body_sensor().inverse() * lidar_entry->T_body_sensor();
  }
  auto images = read_log_messages<msgs::ImageMessage>(options.log, options.camera_topic, "images");
  if (!images) return report_failure(output, result, images.error().message);
  auto scans = read_log_messages<msgs::PointCloudMessage>(options.log, options.lidar_topic, "point clouds");
  if (!scans) return report_failure(output, result, scans.error().message);
  // Intrinsics: the calibration file's, else the images' own.
  msgs::CameraIntrinsics intrinsics;
  msgs::DistortionModel distortion;
  if (camera_entry != nullptr && camera_entry->camera) {
    intrinsics = camera_entry->camera->intrinsics;
    distortion = camera_entry->camera->distortion;
  } else if (images->front().intrinsics) {
    intrinsics = *images->front().intrinsics;
    distortion = images->front().distortion.value_or(msgs::DistortionModel{});
  } else {
    return report_failure(output, result, fmt::format("no intrinsics for {}: the images carry none; give --calibration with {}_to_body.intrinsics "
                                                      "(calib camera writes them)",
                                                      options.camera, options.camera));
  }
  auto calibrated = calib::calibrate_camera_lidar(*images, intrinsics, distortion, *scans, config);
  if (!calibrated) return report_failure(output, result, calibrated.error().message);

  const Eigen::Matrix3d R = calibrated->T_camera_lidar.rotation().matrix();
  const Eigen::Vector3d position_sigma = (R * calibrated->covariance.topLeftCorner<3, 3>() * R.transpose()).diagonal().cwiseSqrt();
  const Eigen::Vector3d rotation_sigma_deg =
      (R * calibrated->covariance.bottomRightCorner<3, 3>() * R.transpose()).diagonal().cwiseSqrt() * (180.0 / 3.14159265358979323846);
  result["T_camera_lidar"] = pose_json(calibrated->T_camera_lidar);
  result["sigma"] = {{"position", {position_sigma.x(), position_sigma.y(), position_sigma.z()}},
                     {"rotation_deg", {rotation_sigma_deg.x(), rotation_sigma_deg.y(), rotation_sigma_deg.z()}}};
  result["plane_rms_m"] = calibrated->plane_rms_m;
  result["edge_rms_m"] = calibrated->edge_rms_m;
  result["edge_bias_m"] = calibrated->edge_bias_m;
  result["normal_spread_deg"] = calibrated->normal_spread_deg;
  result["certified"] = calibrated->certified;
  result["weakest"] = calibrated->weakest;
  if (!calibrated->certified) result["not_certified_reason"] = calibrated->not_certified_reason;
  result["images"] = calibrated->images;
  result["images_with_board"] = calibrated->images_with_board;
  result["scans"] = calibrated->scans;
  result["scans_static"] = calibrated->scans_static;
  result["scans_used"] = calibrated->scans_used;
  result["scans_board_moving"] = calibrated->scans_board_moving;
  result["scans_board_not_in_lidar"] = calibrated->scans_board_not_in_lidar;
  result["stations"] = calibrated->stations;
  nlohmann::json views = nlohmann::json::array();
  for (const calib::CameraLidarView& view : calibrated->views) {
    views.push_back({{"scan_time", view.scan_time.seconds()}, {"station", view.station}, {"board_points", view.board_points},
                     {"edge_points", view.edge_points}, {"plane_rms_m", view.plane_rms_m}, {"edge_rms_m", view.edge_rms_m}});
  }
  result["views"] = std::move(views);
  const Eigen::Vector3d t = calibrated->T_camera_lidar.translation();
  std::string text = fmt::format("{} in {}'s optical frame from {} scans at {} stations ({} scans, {} static, board in {} of {} images)\n", options.lidar,
                                 options.camera, calibrated->scans_used, calibrated->stations, calibrated->scans, calibrated->scans_static,
                                 calibrated->images_with_board, calibrated->images);
  text += fmt::format("  position [{:.4f}, {:.4f}, {:.4f}] m, one sigma [{:.4f}, {:.4f}, {:.4f}] m\n", t.x(), t.y(), t.z(), position_sigma.x(),
                      position_sigma.y(), position_sigma.z());
  const Eigen::Vector4d q = calibrated->T_camera_lidar.rotation().wxyz();
  text += fmt::format("  rotation (w, x, y, z) [{:.6f}, {:.6f}, {:.6f}, {:.6f}], one sigma [{:.3f}, {:.3f}, {:.3f}] deg\n", q(0), q(1), q(2), q(3),
                      rotation_sigma_deg.x(), rotation_sigma_deg.y(), rotation_sigma_deg.z());
  text += fmt::format("  board plane {:.4f} m rms, edges {:.4f} m rms ({:+.4f} m outside on average), normals spread {:.1f} deg\n",
                      calibrated->plane_rms_m, calibrated->edge_rms_m, calibrated->edge_bias_m, calibrated->normal_spread_deg);
  if (!calibrated->certified) {
    return report_failure(output, result,
                          fmt::format("not certified: {}{}", calibrated->not_certified_reason,
                                      options.out.empty() ? "" : fmt::format("; {} not written", options.out)));
  }
  if (!options.out.empty()) {
    // The camera's mount: the output file's entry, else the --calibration file's.
    std::optional<SE3> T_body_camera;
    if (auto existing = calib::load_calibration(options.out); existing && existing->find(options.camera) != nullptr) {
      T_body_camera = existing->find(options.camera)->T_body_sensor();
    } else if (camera_entry != nullptr) {
      T_body_camera = camera_entry->T_body_sensor();
    }
    if (!T_body_camera) {
      return report_failure(output, result, fmt::format("--out {}: neither it nor --calibration has {}_to_body, the mount the LiDAR's is relative to",
                                                        options.out, options.camera));
    }
    const SE3 T_body_lidar = *T_body_camera * calibrated->T_camera_lidar;
    const Status written = update_calibration_entry(options.out, options.lidar, [&](calib::SensorCalibration& entry) {
      const calib::SensorCalibration mounted = calib::SensorCalibration::from_transform(options.lidar, T_body_lidar, entry.time_offset);
      entry.rotation_wxyz = mounted.rotation_wxyz;
      entry.translation = mounted.translation;
    });
    if (!written) return report_failure(output, result, written.error().message);
    result["out"] = options.out;
    result["lidar_to_body"] = pose_json(T_body_lidar);
    text += fmt::format("wrote {}_to_body into {}\n", options.lidar, options.out);
  }
  result["ok"] = true;
  return report_success(output, result, text);
}

}  // namespace

void add_calib_camera_lidar_command(CLI::App& calib_app, const Output& output, Command& run) {
  CLI::App* command = calib_app.add_subcommand("camera-lidar", "A LiDAR's pose in a camera's frame from a log of a checkerboard held still at several stations");
  auto options = std::make_shared<CameraLidarOptions>();
  command->add_option("LOG", options->log, "Sensor log (.mcap) with the camera's images and the LiDAR's scans")->required();
  command->add_option("--camera", options->camera, "The camera's name in the calibration file")->capture_default_str();
  command->add_option("--lidar", options->lidar, "The LiDAR's name in the calibration file")->capture_default_str();
  command->add_option("--camera-topic", options->camera_topic, "Image topic (default: the first)");
  command->add_option("--lidar-topic", options->lidar_topic, "Point cloud topic (default: the first)");
  command->add_option("--board", options->board, "Inner corners of the board, COLUMNSxROWS")->capture_default_str();
  command->add_option("--square", options->square, "Edge of a square, m")->capture_default_str();
  command->add_option("--board-size", options->board_size, "The physical board around the pattern, WIDTHxHEIGHT in m (default: the pattern's extent)");
  command->add_option("--calibration", options->calibration, "Calibration YAML with the camera's intrinsics (default: the images' own)");
  command->add_flag("--initial-guess", options->initial_guess, "Start from the mounts in --calibration instead of finding the board by its size");
  command->add_option("--max-corner-motion", options->max_corner_motion, "px: the board's corners may move this much (mean) across a scan used")
      ->capture_default_str();
  command->add_option("--out", options->out, "Write lidar_to_body into this calibration YAML (relative to the camera's mount in it or in --calibration)");
  command->callback([&output, &run, options] { run = [&output, options] { return run_camera_lidar(output, *options); }; });
}

}  // namespace hanzo::fusion::app
