// hanzo-fusion calib motion: hand-eye calibration of one sensor from motion (calib/motion_calibration.hpp).
// The sensor's own odometry (a trajectory file) against the body's trajectory or the IMU in a
// sensor log; prints T_body_sensor and the time offset, and with --out writes the sensor's entry
// into a calibration YAML (created, or the entry replaced, the others kept).

#include <algorithm>
#include <memory>
#include <numbers>
#include <optional>
#include <string>
#include <vector>

#include <fmt/format.h>

#include "commands.hpp"
#include "hanzo/fusion/calib/motion_calibration.hpp"
#include "hanzo/fusion/io/trajectory.hpp"
#include "hanzo/fusion/calib/calibration_json.hpp"
#include "log_messages.hpp"

namespace hanzo::fusion::app {
namespace {

struct MotionOptions {
  std::string sensor;
  std::string sensor_poses;
  std::string body_poses;
  std::string imu_log;
  std::string imu_topic;
  std::string format = "tum";
  double pair_interval = calib::MotionCalibrationConfig{}.pair_interval;
  double max_time_offset = calib::MotionCalibrationConfig{}.max_time_offset;
  bool no_time_offset = false;
  std::vector<double> prior_translation;
  std::string out;
};

Result<std::vector<calib::StampedPose>> read_poses(const std::string& path, const std::string& format_name) {
  Result<io::TrajectoryFormat> format = io::trajectory_format_from_name(format_name);
  if (!format) return format.error();
  Result<io::Trajectory> trajectory = io::read_trajectory(path, *format);
  if (!trajectory) return trajectory.error();
  std::vector<calib::StampedPose> poses;
  for (std::size_t i = 0; i < trajectory->size(); ++i) poses.push_back({trajectory->timestamps[i], trajectory->pose_se3(i)});
  return poses;
}

// The gyroscope of the log's IMU topic (the first IMU topic when none is named).
Result<std::vector<calib::GyroSample>> read_gyro(const std::string& path, const std::string& topic) {
  auto imu = read_log_messages<msgs::ImuMessage>(path, topic, "IMU messages");
  if (!imu) return imu.error();
  std::vector<calib::GyroSample> samples;
  for (const msgs::ImuMessage& message : *imu) samples.push_back({message.timestamp, message.angular_velocity});
  return samples;
}

std::string to_text(const calib::MotionCalibrationSummary& summary, const std::string& out) {
  const calib::SensorCalibration& result = summary.calibration;
  const SO3 rotation = result.T_body_sensor().rotation();
  std::string text = fmt::format(
      "{}_to_body from motion ({} relative motions, {} turning, {} outliers)\n"
      "  rotation wxyz [{:.6f}] ({:.3f} deg), residual {:.3f} deg rms, axis spread {:.3f}\n",
      result.sensor, summary.pairs, summary.rotation_pairs, summary.outlier_pairs, fmt::join(result.rotation_wxyz, ", "),
      rotation.angle() * 180.0 / std::numbers::pi, summary.rotation_residual_rms_deg, summary.rotation_axis_spread);
  if (summary.translation_estimated) {
    text += fmt::format("  translation [{:.4f}] m, residual {:.4f} m rms, observability {:.3f}\n", fmt::join(result.translation, ", "),
                        summary.translation_residual_rms_m, summary.translation_observability);
    if (summary.unobservable_translation_axis) {
      text += fmt::format("  not observable along [{:.3f}] (rotation about one axis): kept from the prior\n",
                          fmt::join(*summary.unobservable_translation_axis, ", "));
    }
  } else {
    text += fmt::format("  translation not estimated (gyroscope: rotation only); gyro bias [{:.5f}] rad/s\n", fmt::join(summary.gyro_bias, ", "));
  }
  text += fmt::format("  time offset {:.3f} ms (t_body = t_{} + offset)\n", static_cast<double>(result.time_offset.nanoseconds()) * 1e-6,
                      result.sensor);
  if (!out.empty()) text += fmt::format("wrote {}_to_body into {}\n", result.sensor, out);
  return text;
}

}  // namespace

void add_calib_motion_command(CLI::App& calib_app, const Output& output, Command& run) {
  CLI::App* command = calib_app.add_subcommand(
      "motion", "Hand-eye calibration of a sensor from motion: T_body_sensor and time offset from its odometry against the body's");
  auto options = std::make_shared<MotionOptions>();
  command->add_option("--sensor", options->sensor, "The sensor's name in the calibration file (lidar -> lidar_to_body)")->required();
  command->add_option("--sensor-poses", options->sensor_poses, "The sensor's own odometry, T_odom_sensor (trajectory file)")->required();
  auto* body = command->add_option("--body-poses", options->body_poses, "The body's trajectory T_world_body (rotation, translation, offset)");
  command->add_option("--imu-log", options->imu_log, "Sensor log with the body's IMU (rotation, offset, gyro bias)")->excludes(body);
  command->add_option("--imu-topic", options->imu_topic, "IMU topic in --imu-log (default: the first)");
  command->add_option("--format", options->format, "Trajectory file format: tum, euroc or kitti")->capture_default_str();
  command->add_option("--pair-interval", options->pair_interval, "Seconds between the poses of a relative motion")->capture_default_str();
  command->add_option("--max-time-offset", options->max_time_offset, "Offsets searched both ways, s")->capture_default_str();
  command->add_flag("--no-time-offset", options->no_time_offset, "Keep the clocks as they are (offset 0)");
  command->add_option("--prior-translation", options->prior_translation, "x,y,z m: kept along axes the motion does not observe")
      ->delimiter(',')
      ->expected(3);
  command->add_option("--out", options->out, "Write the entry into this calibration YAML (other entries kept)");
  command->callback([&output, &run, options] {
    run = [&output, options] {
      nlohmann::json result = {{"kind", "motion_calibration"}, {"sensor", options->sensor}};
      if (options->body_poses.empty() == options->imu_log.empty()) {
        return report_failure(output, result, "give the body's motion: --body-poses FILE or --imu-log LOG");
      }
      calib::MotionCalibrationInput input;
      input.sensor = options->sensor;
      auto sensor_poses = read_poses(options->sensor_poses, options->format);
      if (!sensor_poses) return report_failure(output, result, sensor_poses.error().message);
      input.sensor_poses = std::move(sensor_poses).value();
      if (!options->body_poses.empty()) {
        auto body_poses = read_poses(options->body_poses, options->format);
        if (!body_poses) return report_failure(output, result, body_poses.error().message);
        input.body_poses = std::move(body_poses).value();
      } else {
        auto gyro = read_gyro(options->imu_log, options->imu_topic);
        if (!gyro) return report_failure(output, result, gyro.error().message);
        input.body_gyro = std::move(gyro).value();
      }
      calib::MotionCalibrationConfig config;
      config.pair_interval = options->pair_interval;
      config.max_time_offset = options->max_time_offset;
      config.time_offset_step = std::min(config.time_offset_step, options->max_time_offset);
      config.estimate_time_offset = !options->no_time_offset;
      if (!options->prior_translation.empty()) {
        config.prior_translation = Eigen::Vector3d(options->prior_translation[0], options->prior_translation[1], options->prior_translation[2]);
      }
      auto summary = calib::calibrate_from_motion(input, config);
      if (!summary) return report_failure(output, result, summary.error().message);
      if (!options->out.empty()) {
        const calib::SensorCalibration& calibrated = summary->calibration;
        const Status written = update_calibration_entry(options->out, calibrated.sensor, [&](calib::SensorCalibration& entry) {
          std::optional<calib::CameraCalibration> camera = entry.camera;  // intrinsics are not this procedure's
          entry = calibrated;
          entry.camera = std::move(camera);
        });
        if (!written) {
          return report_failure(output, result, written.error().message);
        }
      }
      result.update(calib::motion_calibration_to_json(*summary));
      result["ok"] = true;
      if (!options->out.empty()) result["out"] = options->out;
      return report_success(output, result, to_text(*summary, options->out));
    };
  });
}

}  // namespace hanzo::fusion::app
