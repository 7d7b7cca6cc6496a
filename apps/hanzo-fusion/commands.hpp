#pragma once
// Subcommand registration: each adds its CLI11 subcommand and sets `run` when selected.

#include <functional>
#include <string>
#include <vector>

#include <CLI/CLI.hpp>

#include "hanzo/fusion/calib/calibration.hpp"
#include "hanzo/fusion/calib/camera_calibration.hpp"
#include "hanzo/fusion/core/result.hpp"
#include "hanzo/fusion/io/trajectory.hpp"
#include "hanzo/fusion/msgs/estimate_messages.hpp"
#include "output.hpp"

namespace hanzo::fusion::app {

using Command = std::function<int()>;

void add_config_command(CLI::App& app, const Output& output, Command& run);
void add_calib_command(CLI::App& app, const Output& output, Command& run);
/// `calib motion` (calib_motion_command.cpp) and `calib camera` (calib_camera_command.cpp),
/// added by add_calib_command.
void add_calib_motion_command(CLI::App& calib_app, const Output& output, Command& run);
void add_calib_camera_command(CLI::App& calib_app, const Output& output, Command& run);
void add_calib_stereo_command(CLI::App& calib_app, const Output& output, Command& run);
void add_calib_camera_lidar_command(CLI::App& calib_app, const Output& output, Command& run);
/// A checkerboard from --board COLUMNSxROWS (inner corners) and --square (m).
Result<calib::CheckerboardTarget> parse_board(const std::string& text, double square);
/// Changes the entry of `sensor` in the calibration YAML `path` (an entry at the body origin is
/// added when missing, the file created when missing); the other entries are kept.
Status update_calibration_entry(const std::string& path, const std::string& sensor,
                                const std::function<void(calib::SensorCalibration&)>& change);
void add_eval_command(CLI::App& app, const Output& output, Command& run);
/// reconstruct splats, render (HANZO_FUSION_AI builds).
void add_reconstruct_command(CLI::App& app, const Output& output, Command& run);
void add_log_command(CLI::App& app, const Output& output, Command& run);
void add_import_command(CLI::App& app, const Output& output, Command& run);
void add_drive_command(CLI::App& app, const Output& output, Command& run);
/// The session's poses as a trajectory (run_command.cpp): times increasing, a repeated time kept once.
io::Trajectory trajectory_of(const std::vector<msgs::PoseEstimate>& poses);
void add_send_command(CLI::App& app, const Output& output, Command& run);
void add_export_command(CLI::App& app, const Output& output, Command& run);
/// `export dataset` under the `export` command (export_dataset_command.cpp).
void add_export_dataset_command(CLI::App& export_app, const Output& output, Command& run);
void add_sim_command(CLI::App& app, const Output& output, Command& run);
void add_run_command(CLI::App& app, const Output& output, Command& run);
void add_graph_command(CLI::App& app, const Output& output, Command& run);
void add_cloud_commands(CLI::App& app, const Output& output, Command& run);
void add_map_command(CLI::App& app, const Output& output, Command& run);
/// `map localize` (map_localize_command.cpp), added by add_map_command.
void add_map_localize_command(CLI::App& map_app, const Output& output, Command& run);
/// map merge (map_merge_command.cpp).
void add_map_merge_command(CLI::App& map_app, const Output& output, Command& run);
void add_serve_command(CLI::App& app, const Output& output, Command& run);
void add_stream_command(CLI::App& app, const Output& output, Command& run);
void add_slam2d_command(CLI::App& app, const Output& output, Command& run);
void add_lidar_odometry_command(CLI::App& app, const Output& output, Command& run);
void add_privacy_command(CLI::App& app, const Output& output, Command& run);
void add_crypto_command(CLI::App& app, const Output& output, Command& run);
void add_features_command(CLI::App& app, const Output& output, Command& run);
void add_vision_command(CLI::App& app, const Output& output, Command& run);
/// vision vlad, vision place-recall (vision_place_command.cpp), under `vision`.
void add_vision_place_commands(CLI::App& vision_app, const Output& output, Command& run);
/// vision detect (vision_detect_command.cpp).
void add_vision_detect_command(CLI::App& vision_app, const Output& output, Command& run);

}  // namespace hanzo::fusion::app
