// hanzo-fusion import FORMAT SRC... --out LOG.mcap: converts recordings into a sensor log.
// Formats: csv (IMU / GNSS / wheel odometry files), rosbag (ROS 1 bag v2.0), ros2bag (rosbag2:
// MCAP or SQLite storage), carmen (2D laser logs), kitti (odometry sequences), euroc (ASL
// folders), tum-rgbd, nmea (GNSS receiver logs), xsens (IMU streams), pcap; see docs/sensor-logs.md.

#include <algorithm>
#include <filesystem>
#include <functional>
#include <map>
#include <memory>
#include <string>
#include <vector>

#include <fmt/format.h>

#include "commands.hpp"
#include "log_writing.hpp"
#include "hanzo/fusion/core/files.hpp"
#include "hanzo/fusion/drivers/hesai.hpp"
#include "hanzo/fusion/drivers/nmea.hpp"
#include "hanzo/fusion/drivers/xsens.hpp"
#include "hanzo/fusion/drivers/ouster.hpp"
#include "hanzo/fusion/drivers/pcap.hpp"
#include "hanzo/fusion/drivers/velodyne.hpp"
#include "hanzo/fusion/io/carmen_import.hpp"
#include "hanzo/fusion/io/csv_import.hpp"
#include "hanzo/fusion/io/euroc_import.hpp"
#include "hanzo/fusion/io/image_folder_import.hpp"
#include "hanzo/fusion/msgs/validate.hpp"
#include "hanzo/fusion/io/kitti_import.hpp"
#include "hanzo/fusion/io/rosbag_import.hpp"
#include "hanzo/fusion/io/sensor_log.hpp"
#include "hanzo/fusion/io/tum_rgbd_import.hpp"

namespace hanzo::fusion::app {
namespace {

struct ImportOptions {
  std::string format;
  std::vector<std::string> sources;
  std::string out;
  std::string compression = "zstd";
  bool no_foxglove = false;                  // leave out the Foxglove mirror channels
  std::vector<std::string> topic_overrides;  // "STEM=/topic" (csv) or "/ros/topic=/topic" (rosbag)
  double wheel_separation = 0.0;             // rosbag: nav_msgs/Odometry -> wheel odometry
  bool use_record_time = false;              // rosbag, ros2bag
  std::string body_frame;                    // rosbag, ros2bag: the calibration's body frame
  std::string ground_truth;                  // carmen, kitti, euroc, tum-rgbd: reference trajectory as TUM
  std::string calibration;                   // kitti, euroc, tum-rgbd, bags: the sensors' calibration YAML
  bool no_images = false;                    // kitti, euroc: leave the cameras out
  std::string poses;                         // kitti: poses file
  double time_origin = 1e9;                  // kitti, images: Unix time of relative times' zero
  std::string times;                         // images: times file
  double rate = 0.0;                         // images: frames per second
  std::vector<double> intrinsics;            // images: fx fy cx cy
  std::vector<double> distortion;            // images: radtan k1 k2 p1 p2 [k3]
  double baseline = 0.0;                     // images: stereo baseline (m)
  std::string privacy;                       // "blur" / "black": camera images redacted before writing
  std::shared_ptr<ImageRedaction> redaction; // made from `privacy` by run_import
  std::string date;                          // nmea: UTC date of fixes before the log's first RMC / ZDA
  std::string driver;                        // pcap: velodyne
  std::string model;                         // pcap, velodyne: VLP-16, VLP-32C, HDL-32E, HDL-64E, VLS-128
  int port = 0;                              // pcap: the LiDAR's data port (0: the driver's default)
  std::string metadata;                      // pcap, ouster: the sensor's metadata JSON
  std::string firetime;                      // pcap, hesai: the firetime correction CSV
};

struct SourceMessages {
  std::string topic;
  std::string sensor;
  std::vector<msgs::SensorMessage> messages;
};

Result<std::map<std::string, std::string>> topic_map(const std::vector<std::string>& entries, const char* form) {
  std::map<std::string, std::string> map;
  for (const std::string& entry : entries) {
    const auto equals = entry.find('=');
    if (equals == std::string::npos || equals == 0 || equals + 1 == entry.size() || entry[equals + 1] != '/') {
      return Error(fmt::format("--topic '{}': expected {}", entry, form));
    }
    map[entry.substr(0, equals)] = entry.substr(equals + 1);
  }
  return map;
}

LogWriteOptions log_options(const ImportOptions& options) {
  LogWriteOptions log;
  log.path = options.out;
  log.compression = options.compression;
  log.foxglove_channels = !options.no_foxglove;
  log.redaction = options.redaction;
  return log;
}

// rosbag (ROS 1) and ros2bag (ROS 2: a bag folder or its .mcap / .db3 file).
int run_rosbag_import(const Output& output, const ImportOptions& options) {
  nlohmann::json result = {{"format", options.format}, {"sources", options.sources}, {"out", options.out}};
  if (options.sources.size() != 1) return report_failure(output, result, fmt::format("{} import takes one bag (SRC) at a time", options.format));
  io::RosbagImportConfig config;
  auto map = topic_map(options.topic_overrides, "/ros/topic=/log/topic");
  if (!map) return report_failure(output, result, map.error().message);
  config.topic_map = *map;
  if (options.wheel_separation > 0.0) config.wheel_separation = options.wheel_separation;
  config.use_record_time = options.use_record_time;
  config.body_frame = options.body_frame;
  const bool ros2 = options.format == "ros2bag";
  io::RosbagImportReport report;
  const int code = write_log(output, result, log_options(options), [&](io::SensorLogWriter& writer) -> Status {
    HANZO_ASSIGN_OR_RETURN(report, ros2 ? io::import_rosbag2(options.sources[0], writer, config)
                                        : io::import_rosbag(options.sources[0], writer, config));
    return writer.add_metadata({"import", {{"importer", options.format}, {"source", options.sources[0]}}});
  });
  if (code != 0) return code;
  result["ok"] = true;
  result["bag"] = {{"storage", report.storage}, {"messages", report.messages}, {"warnings", report.warnings}};
  std::string text = fmt::format("{}: {} storage, {} messages\n", options.sources[0], report.storage, report.messages);
  if (!ros2) {
    result["bag"].update({{"chunks", report.bag.chunks}, {"complete", report.bag.complete}, {"compressions", report.bag.chunk_compressions}});
  }
  for (const std::string& warning : report.warnings) text += "  warning: " + warning + "\n";
  nlohmann::json topics = nlohmann::json::array();
  uint64_t imported = 0;
  for (const io::TopicImportReport& topic : report.topics) {
    imported += topic.imported;
    topics.push_back({{"ros_topic", topic.ros_topic}, {"ros_type", topic.ros_type}, {"topic", topic.topic}, {"frame_id", topic.frame_id},
                      {"imported", topic.imported}, {"rejected", topic.rejected}, {"first_rejection", topic.first_rejection}});
    text += fmt::format("  {} ({}) -> {}: {} messages", topic.ros_topic, topic.ros_type, topic.topic.empty() ? "(no camera)" : topic.topic,
                        topic.imported);
    text += topic.rejected == 0 ? "\n" : fmt::format(", {} rejected (first {})\n", topic.rejected, topic.first_rejection);
  }
  for (const auto& [ros_topic, count] : report.calibration_topics) text += fmt::format("  {}: {} messages read (calibration, class names)\n", ros_topic, count);
  for (const auto& [ros_topic, type] : report.skipped_topics) text += fmt::format("  {} ({}) skipped\n", ros_topic, type);
  result["topics"] = topics;
  result["skipped_topics"] = report.skipped_topics;
  result["calibration_topics"] = report.calibration_topics;
  result["messages"] = imported;
  result["body_frame"] = report.body_frame;
  result["calibration_sensors"] = report.calibration.sensors.size();
  result["calibration_notes"] = report.calibration_notes;
  for (const std::string& note : report.calibration_notes) text += "  calibration: " + note + "\n";
  if (!options.calibration.empty()) {
    if (report.calibration.sensors.empty()) {
      return report_failure(output, result, fmt::format("--calibration: the bag places no imported sensor (no /tf_static, no "
                                                        "CameraInfo connecting them){}", report.calibration_notes.empty() ? "" : ": " + report.calibration_notes.front()));
    }
    if (Status written = calib::save_calibration(report.calibration, options.calibration); !written) {
      return report_failure(output, result, written.error().message);
    }
    result["calibration"] = options.calibration;
    text += fmt::format("  calibration ({} sensor{}, body frame {}) written to {}\n", report.calibration.sensors.size(),
                        report.calibration.sensors.size() == 1 ? "" : "s",
                        report.body_frame, options.calibration);
  }
  text += fmt::format("{}: {} messages\n", options.out, imported);
  return report_success(output, result, text);
}

int run_carmen_import(const Output& output, const ImportOptions& options) {
  nlohmann::json result = {{"format", "carmen"}, {"sources", options.sources}, {"out", options.out}};
  if (options.sources.size() != 1) return report_failure(output, result, "carmen import takes one log (SRC) at a time");
  io::CarmenImportConfig config;
  config.wheel_separation = options.wheel_separation;
  io::CarmenImportReport report;
  const int code = write_log(output, result, log_options(options), [&](io::SensorLogWriter& writer) -> Status {
    HANZO_ASSIGN_OR_RETURN(report, io::import_carmen(options.sources[0], writer, config));
    return writer.add_metadata({"import", {{"importer", "carmen"}, {"source", options.sources[0]}}});
  });
  if (code != 0) return code;
  if (!options.ground_truth.empty()) {
    if (Status written = io::write_trajectory(options.ground_truth, report.scan_poses, io::TrajectoryFormat::kTum); !written) {
      return report_failure(output, result, written.error().message);
    }
    result["ground_truth"] = options.ground_truth;
  }
  result["ok"] = true;
  result["scans"] = report.scans;
  result["odometry"] = report.odometry;
  result["rejected"] = report.rejected;
  result["first_rejection"] = report.first_rejection;
  result["skipped_lines"] = report.skipped_lines;
  result["timestamps_reconstructed"] = report.timestamps_reconstructed;
  if (report.timestamps_reconstructed) result["warnings"] = {report.timestamp_warning};
  std::string text = fmt::format("{}: {} scans -> {}, {} odometry -> {}, {} other lines skipped\n", options.sources[0],
                                 report.scans, config.laser_topic, report.odometry,
                                 config.wheel_separation > 0 ? config.odometry_topic : "(left out: no --wheel-separation)",
                                 report.skipped_lines);
  if (report.rejected > 0) text += fmt::format("  {} rejected (first: {})\n", report.rejected, report.first_rejection);
  if (!options.ground_truth.empty()) text += fmt::format("  scan poses written to {}\n", options.ground_truth);
  return report_success(output, result, text);
}

// What a dataset importer (kitti, euroc, tum-rgbd) hands back besides the log.
struct DatasetOutputs {
  const io::Trajectory* ground_truth = nullptr;
  const calib::Calibration* calibration = nullptr;
};

// Writes --ground-truth and --calibration; adds them to result and text.
int write_dataset_outputs(const Output& output, nlohmann::json& result, std::string& text, const ImportOptions& options,
                          const DatasetOutputs& outputs) {
  if (!options.ground_truth.empty()) {
    if (outputs.ground_truth->empty()) return report_failure(output, result, "--ground-truth: the dataset has no ground truth");
    if (Status written = io::write_trajectory(options.ground_truth, *outputs.ground_truth, io::TrajectoryFormat::kTum); !written) {
      return report_failure(output, result, written.error().message);
    }
    result["ground_truth"] = options.ground_truth;
    text += fmt::format("  ground truth ({} poses) written to {}\n", outputs.ground_truth->size(), options.ground_truth);
  }
  if (!options.calibration.empty()) {
    if (Status written = calib::save_calibration(*outputs.calibration, options.calibration); !written) {
      return report_failure(output, result, written.error().message);
    }
    result["calibration"] = options.calibration;
    text += fmt::format("  calibration ({} sensor{}) written to {}\n", outputs.calibration->sensors.size(),
                        outputs.calibration->sensors.size() == 1 ? "" : "s", options.calibration);
  }
  result["ok"] = true;
  return report_success(output, result, text);
}

int run_kitti_import(const Output& output, const ImportOptions& options) {
  nlohmann::json result = {{"format", "kitti"}, {"sources", options.sources}, {"out", options.out}};
  if (options.sources.size() != 1) return report_failure(output, result, "kitti import takes one sequence folder (SRC) at a time");
  io::KittiImportConfig config;
  config.import_images = !options.no_images;
  config.poses_path = options.poses;
  config.time_origin = options.time_origin;
  io::KittiImportReport report;
  const int code = write_log(output, result, log_options(options), [&](io::SensorLogWriter& writer) -> Status {
    HANZO_ASSIGN_OR_RETURN(report, io::import_kitti(options.sources[0], writer, config));
    // KITTI's times are relative (unless `export dataset` kept the absolute ones): `run --gt`
    // takes the origin off to pair them with relative ground truth.
    std::map<std::string, std::string> values = {{"importer", "kitti"}, {"source", options.sources[0]}};
    if (!report.absolute_times) values["relative_time_origin_s"] = fmt::format("{}", options.time_origin);
    return writer.add_metadata({"import", values});
  });
  if (code != 0) return code;
  result["frames"] = report.frames;
  result["scans"] = report.scans;
  result["images"] = report.images;
  result["points"] = report.points;
  result["poses"] = report.poses_path;
  std::string text = fmt::format("{}: {} frames: {} scans ({} points) -> {}, {} images\n", options.sources[0], report.frames,
                                 report.scans, report.points, config.lidar_topic, report.images);
  if (!report.poses_path.empty()) text += fmt::format("  poses from {}\n", report.poses_path);
  return write_dataset_outputs(output, result, text, options, {&report.ground_truth, &report.calibration});
}

int run_euroc_import(const Output& output, const ImportOptions& options) {
  nlohmann::json result = {{"format", "euroc"}, {"sources", options.sources}, {"out", options.out}};
  if (options.sources.size() != 1) return report_failure(output, result, "euroc import takes one dataset folder (SRC) at a time");
  io::EurocImportConfig config;
  config.import_images = !options.no_images;
  io::EurocImportReport report;
  const int code = write_log(output, result, log_options(options), [&](io::SensorLogWriter& writer) -> Status {
    HANZO_ASSIGN_OR_RETURN(report, io::import_euroc(options.sources[0], writer, config));
    return writer.add_metadata({"import", {{"importer", "euroc"}, {"source", options.sources[0]}}});
  });
  if (code != 0) return code;
  std::string text = fmt::format("{}:\n", options.sources[0]);
  nlohmann::json streams = nlohmann::json::array();
  for (const io::EurocStreamReport& stream : report.streams) {
    streams.push_back({{"topic", stream.topic}, {"messages", stream.messages}, {"rejected", stream.rejected},
                       {"first_rejection", stream.first_rejection}});
    text += fmt::format("  {}: {} messages", stream.topic, stream.messages);
    text += stream.rejected == 0 ? "\n" : fmt::format(", {} rejected (first: {})\n", stream.rejected, stream.first_rejection);
  }
  result["topics"] = streams;
  result["ground_truth_source"] = report.ground_truth_path;
  return write_dataset_outputs(output, result, text, options, {&report.ground_truth, &report.calibration});
}

int run_tum_rgbd_import(const Output& output, const ImportOptions& options) {
  nlohmann::json result = {{"format", "tum-rgbd"}, {"sources", options.sources}, {"out", options.out}};
  if (options.sources.size() != 1) return report_failure(output, result, "tum-rgbd import takes one sequence folder (SRC) at a time");
  io::TumRgbdImportConfig config;
  io::TumRgbdImportReport report;
  const int code = write_log(output, result, log_options(options), [&](io::SensorLogWriter& writer) -> Status {
    HANZO_ASSIGN_OR_RETURN(report, io::import_tum_rgbd(options.sources[0], writer, config));
    return writer.add_metadata({"import", {{"importer", "tum-rgbd"}, {"source", options.sources[0]}}});
  });
  if (code != 0) return code;
  result["rgb_images"] = report.rgb_images;
  result["depth_images"] = report.depth_images;
  result["depth_unpaired"] = report.depth_unpaired;
  result["rejected"] = report.rejected;
  result["first_rejection"] = report.first_rejection;
  result["camera_model"] = report.camera_model;
  std::string text = fmt::format("{}: {} colour images -> {}, {} depth images -> {}; intrinsics: {}\n", options.sources[0],
                                 report.rgb_images, config.rgb_topic, report.depth_images, config.depth_topic,
                                 report.camera_model.empty() ? "none (folder name names no freiburg Kinect)" : report.camera_model);
  if (report.rejected > 0) text += fmt::format("  {} rejected (first: {})\n", report.rejected, report.first_rejection);
  if (report.depth_unpaired > 0) {
    text += fmt::format("  {} depth images without a colour image within {} s left out\n", report.depth_unpaired, config.max_depth_offset);
  }
  return write_dataset_outputs(output, result, text, options, {&report.ground_truth, &report.calibration});
}

int run_image_folder_import(const Output& output, const ImportOptions& options) {
  nlohmann::json result = {{"format", "images"}, {"sources", options.sources}, {"out", options.out}};
  io::ImageFolderImportConfig config;
  config.times_path = options.times;
  config.rate_hz = options.rate;
  config.time_origin = options.time_origin;
  config.baseline = options.baseline;
  if (!options.intrinsics.empty()) {
    if (options.intrinsics.size() != 4) return report_failure(output, result, fmt::format("--intrinsics: {} numbers (expected fx,fy,cx,cy)", options.intrinsics.size()));
    calib::CameraCalibration camera;
    camera.intrinsics = {options.intrinsics[0], options.intrinsics[1], options.intrinsics[2], options.intrinsics[3], 0, 0};
    if (!options.distortion.empty()) camera.distortion = {msgs::DistortionType::kRadtan, options.distortion};
    if (Status valid = msgs::validate(camera.intrinsics, "--intrinsics"); !valid) return report_failure(output, result, valid.error().message);
    if (Status valid = msgs::validate(camera.distortion, "--distortion"); !valid) return report_failure(output, result, valid.error().message);
    config.camera = camera;
  } else if (!options.distortion.empty()) {
    return report_failure(output, result, "--distortion: give --intrinsics too");
  }
  if (!options.calibration.empty() && !config.camera) return report_failure(output, result, "--calibration: give the camera's --intrinsics");
  io::ImageFolderImportReport report;
  const int code = write_log(output, result, log_options(options), [&](io::SensorLogWriter& writer) -> Status {
    HANZO_ASSIGN_OR_RETURN(report, io::import_image_folders(options.sources, writer, config));
    std::map<std::string, std::string> values = {{"importer", "images"}, {"source", fmt::format("{}", fmt::join(options.sources, " "))}};
    if (report.relative_times) values["relative_time_origin_s"] = fmt::format("{}", options.time_origin);
    return writer.add_metadata({"import", values});
  });
  if (code != 0) return code;
  result["images"] = report.images;
  result["rejected"] = report.rejected;
  result["first_rejection"] = report.first_rejection;
  result["time_source"] = report.time_source;
  result["width"] = report.width;
  result["height"] = report.height;
  std::string text = fmt::format("{}: {} images ({}x{}) -> {}; times from the {}\n", fmt::join(options.sources, ", "), report.images, report.width,
                                 report.height, fmt::join(config.topics.begin(), config.topics.begin() + static_cast<std::ptrdiff_t>(options.sources.size()), ", "),
                                 report.time_source);
  if (report.rejected > 0) text += fmt::format("  {} left out (first: {})\n", report.rejected, report.first_rejection);
  io::Trajectory no_ground_truth;
  return write_dataset_outputs(output, result, text, options, {&no_ground_truth, &report.calibration});
}

/// NMEA-0183 receiver logs (raw bytes, binary in between skipped) into GnssMessages on /gnss
/// (sensor "gnss", or --topic /gnss=/other).
int run_nmea_import(const Output& output, const ImportOptions& options) {
  nlohmann::json result = {{"format", "nmea"}, {"sources", options.sources}, {"out", options.out}};
  auto topics = topic_map(options.topic_overrides, "/gnss=/topic");
  if (!topics) return report_failure(output, result, topics.error().message);
  const auto renamed = topics->find("/gnss");
  const std::string topic = renamed == topics->end() ? "/gnss" : renamed->second;
  drivers::NmeaDecoderConfig config;
  config.date = options.date;
  Result<drivers::NmeaDecoder> decoder = drivers::NmeaDecoder::create(config);
  if (!decoder) return report_failure(output, result, "--date: " + decoder.error().message);
  std::vector<msgs::GnssMessage> fixes;
  for (const std::string& path : options.sources) {
    Result<std::string> bytes = read_file(path);
    if (!bytes) return report_failure(output, result, bytes.error().message);
    decoder->feed(*bytes, fixes);
  }
  decoder->flush(fixes);
  const drivers::NmeaStatistics& statistics = decoder->statistics();
  result["fixes"] = fixes.size();
  result["sentences"] = statistics.sentences;
  result["checksum_errors"] = statistics.checksum_errors;
  result["malformed"] = statistics.malformed;
  result["skipped_bytes"] = statistics.skipped_bytes;
  result["without_date"] = statistics.no_date;
  result["without_position"] = statistics.no_position;
  result["gst_covariances"] = statistics.gst;
  result["without_geoid_separation"] = statistics.no_geoid_separation;
  if (fixes.empty()) {
    std::string why = statistics.sentences == 0 ? "no NMEA sentence" : "no GGA sentence with a position";
    if (statistics.no_date > 0) why = fmt::format("{} GGA fixes but no date (no RMC or ZDA sentence): give --date YYYY-MM-DD", statistics.no_date);
    return report_failure(output, result, fmt::format("{}: {}", fmt::join(options.sources, ", "), why));
  }
  const int code = write_log(output, result, log_options(options), [&](io::SensorLogWriter& writer) -> Status {
    HANZO_RETURN_IF_ERROR(writer.add_metadata({"import", {{"importer", "nmea"}, {"source", fmt::format("{}", fmt::join(options.sources, " "))}}}));
    for (const msgs::GnssMessage& fix : fixes) HANZO_RETURN_IF_ERROR(writer.write(topic, fix, "gnss"));
    return ok_status();
  });
  if (code != 0) return code;
  result["ok"] = true;
  result["topic"] = topic;
  std::string text = fmt::format("{}: {} fixes on {} from {} sentences ({:.1f} s)\n", options.out, fixes.size(), topic, statistics.sentences,
                                 (fixes.back().timestamp - fixes.front().timestamp).seconds());
  if (statistics.checksum_errors + statistics.malformed + statistics.no_date > 0) {
    text += fmt::format("  left out: {} checksum errors, {} malformed sentences (first: {}), {} fixes before the first date; {} bytes between sentences skipped\n",
                        statistics.checksum_errors, statistics.malformed, statistics.first_error.empty() ? "none" : statistics.first_error,
                        statistics.no_date, statistics.skipped_bytes);
  }
  return report_success(output, result, text);
}

/// Xsens MTData2 streams (raw serial bytes) into ImuMessages on /imu (sensor "imu") and the
/// receiver's GNSS PVT fixes on /gnss (sensor "gnss"); --topic /imu=/other, /gnss=/other.
int run_xsens_import(const Output& output, const ImportOptions& options) {
  nlohmann::json result = {{"format", "xsens"}, {"sources", options.sources}, {"out", options.out}};
  auto topics = topic_map(options.topic_overrides, "/imu=/topic or /gnss=/topic");
  if (!topics) return report_failure(output, result, topics.error().message);
  const auto topic_of = [&](const std::string& standard) {
    const auto renamed = topics->find(standard);
    return renamed == topics->end() ? standard : renamed->second;
  };
  drivers::XsensDecoder decoder;
  std::vector<msgs::ImuMessage> imu;
  std::vector<msgs::GnssMessage> fixes;
  for (const std::string& path : options.sources) {
    Result<std::string> bytes = read_file(path);
    if (!bytes) return report_failure(output, result, bytes.error().message);
    decoder.feed(*bytes, imu, fixes);
  }
  const drivers::XsensStatistics& statistics = decoder.statistics();
  result["imu_messages"] = imu.size();
  result["gnss_fixes"] = fixes.size();
  result["frames"] = statistics.messages;
  result["mtdata2"] = statistics.mtdata2;
  result["checksum_errors"] = statistics.checksum_errors;
  result["malformed"] = statistics.malformed;
  result["skipped_bytes"] = statistics.skipped_bytes;
  result["cut_off_bytes"] = decoder.pending_bytes();
  result["without_inertial"] = statistics.without_inertial;
  result["gnss_without_fix"] = statistics.gnss_without_fix;
  result["device_clock"] = statistics.device_clock;
  if (imu.empty()) {
    const std::string why = statistics.messages == 0 ? "no Xsens frame (preamble 0xFA 0xFF with a valid checksum)"
                            : statistics.mtdata2 == 0 ? fmt::format("{} Xsens frames but no MTData2 message", statistics.messages)
                                                      : fmt::format("{} MTData2 messages but none with acceleration and rate of turn "
                                                                    "(or DeltaV and DeltaQ) and a time", statistics.mtdata2);
    return report_failure(output, result, fmt::format("{}: {}", fmt::join(options.sources, ", "), why));
  }
  const std::string imu_topic = topic_of("/imu"), gnss_topic = topic_of("/gnss");
  const int code = write_log(output, result, log_options(options), [&](io::SensorLogWriter& writer) -> Status {
    HANZO_RETURN_IF_ERROR(writer.add_metadata({"import", {{"importer", "xsens"}, {"source", fmt::format("{}", fmt::join(options.sources, " "))}}}));
    std::size_t next_fix = 0;
    for (const msgs::ImuMessage& sample : imu) {
      for (; next_fix < fixes.size() && fixes[next_fix].timestamp <= sample.timestamp; ++next_fix) {
        HANZO_RETURN_IF_ERROR(writer.write(gnss_topic, fixes[next_fix], "gnss"));
      }
      HANZO_RETURN_IF_ERROR(writer.write(imu_topic, sample, "imu"));
    }
    for (; next_fix < fixes.size(); ++next_fix) HANZO_RETURN_IF_ERROR(writer.write(gnss_topic, fixes[next_fix], "gnss"));
    return ok_status();
  });
  if (code != 0) return code;
  result["ok"] = true;
  result["topics"] = fixes.empty() ? nlohmann::json{imu_topic} : nlohmann::json{imu_topic, gnss_topic};
  std::string text = fmt::format("{}: {} IMU messages on {} ({:.1f} s){}\n", options.out, imu.size(), imu_topic,
                                 (imu.back().timestamp - imu.front().timestamp).seconds(),
                                 fixes.empty() ? "" : fmt::format(", {} GNSS fixes on {}", fixes.size(), gnss_topic));
  if (statistics.device_clock > 0) text += fmt::format("  {} messages timed by the device's clock (no valid UTC yet)\n", statistics.device_clock);
  if (statistics.checksum_errors + statistics.malformed + decoder.pending_bytes() > 0) {
    text += fmt::format("  left out: {} frames with a bad checksum, {} malformed (first: {}), {} bytes cut off at the end\n", statistics.checksum_errors,
                        statistics.malformed, statistics.first_error.empty() ? "none" : statistics.first_error, decoder.pending_bytes());
  }
  return report_success(output, result, text);
}

/// Every UDP datagram of the captures, in file order, to `visit`; fails on a capture that
/// cannot be read on, adding its counts to `capture`.
Status for_each_datagram(const std::vector<std::string>& paths, drivers::PcapStatistics& capture,
                         const std::function<void(const drivers::UdpDatagram&)>& visit) {
  for (const std::string& path : paths) {
    Result<drivers::PcapReader> reader = drivers::PcapReader::open(path);
    if (!reader) return reader.error();
    while (true) {
      Result<std::optional<drivers::UdpDatagram>> datagram = reader->next();
      if (!datagram) return datagram.error();
      if (!*datagram) break;
      visit(**datagram);
    }
    const drivers::PcapStatistics& read = reader->statistics();
    capture.records += read.records;
    capture.datagrams += read.datagrams;
    capture.other_packets += read.other_packets;
    capture.truncated += read.truncated;
  }
  return ok_status();
}

/// The report's line on packets a LiDAR import left out (none: empty).
std::string left_out_packets(uint64_t malformed, const std::string& first_error, uint64_t truncated) {
  if (malformed + truncated == 0) return {};
  return fmt::format("  left out: {} malformed packets (first: {}), {} truncated records\n", malformed, first_error.empty() ? "none" : first_error, truncated);
}

/// An Ouster capture with its metadata into one PointCloudMessage per frame on /lidar and the
/// IMU packets on /imu, in time order.
int run_ouster_pcap_import(const Output& output, const ImportOptions& options, nlohmann::json result) {
  if (options.metadata.empty()) return report_failure(output, result, "--metadata: give the Ouster's metadata JSON (ouster-cli or the sensor's HTTP API writes it)");
  Result<drivers::OusterMetadata> metadata = drivers::load_ouster_metadata(options.metadata);
  if (!metadata) return report_failure(output, result, metadata.error().message);
  Result<drivers::OusterDecoder> decoder = drivers::OusterDecoder::create(*metadata);
  if (!decoder) return report_failure(output, result, fmt::format("{}: {}", options.metadata, decoder.error().message));
  const uint16_t lidar_port = static_cast<uint16_t>(options.port > 0 ? options.port : 7502);
  constexpr uint16_t kImuPort = 7503;
  std::vector<drivers::OusterFrame> frames;
  std::vector<msgs::ImuMessage> imu;
  uint64_t other_ports = 0;
  drivers::PcapStatistics capture;
  const Status read = for_each_datagram(options.sources, capture, [&](const drivers::UdpDatagram& datagram) {
    if (datagram.destination_port != lidar_port && datagram.destination_port != kImuPort) {
      ++other_ports;
      return;
    }
    decoder->add_packet(datagram.payload, datagram.time, frames, imu);
  });
  if (!read) return report_failure(output, result, read.error().message);
  decoder->flush(frames);
  const drivers::OusterStatistics& statistics = decoder->statistics();
  result["frames"] = frames.size();
  result["incomplete_frames"] = statistics.incomplete_frames;
  result["imu_samples"] = imu.size();
  result["packets"] = statistics.lidar_packets;
  result["malformed_packets"] = statistics.malformed;
  result["invalid_columns"] = statistics.invalid_columns;
  result["invalid_imu_samples"] = statistics.invalid_imu_samples;
  result["zone_packets"] = statistics.zone_packets;
  result["other_packets"] = capture.other_packets + other_ports;
  result["truncated_records"] = capture.truncated;
  if (frames.empty()) {
    return report_failure(output, result,
                          fmt::format("{}: no Ouster frame decoded ({} datagrams to port {}, {} malformed{}{})", fmt::join(options.sources, ", "),
                                      statistics.lidar_packets + statistics.malformed, lidar_port, statistics.malformed,
                                      statistics.first_error.empty() ? "" : ": ", statistics.first_error));
  }
  const int code = write_log(output, result, log_options(options), [&](io::SensorLogWriter& writer) -> Status {
    HANZO_RETURN_IF_ERROR(writer.add_metadata({"import", {{"importer", "pcap ouster"}, {"metadata", options.metadata}, {"source", fmt::format("{}", fmt::join(options.sources, " "))}}}));
    std::size_t next_imu = 0;
    for (const drivers::OusterFrame& frame : frames) {
      for (; next_imu < imu.size() && imu[next_imu].timestamp <= frame.cloud.timestamp; ++next_imu) HANZO_RETURN_IF_ERROR(writer.write("/imu", imu[next_imu], "imu"));
      HANZO_RETURN_IF_ERROR(writer.write("/lidar", frame.cloud, "lidar"));
    }
    for (; next_imu < imu.size(); ++next_imu) HANZO_RETURN_IF_ERROR(writer.write("/imu", imu[next_imu], "imu"));
    return ok_status();
  });
  if (code != 0) return code;
  result["ok"] = true;
  std::string text = fmt::format("{}: {} frames ({} incomplete) on /lidar, {} IMU samples on /imu, from {} packets\n", options.out, frames.size(),
                                 statistics.incomplete_frames, imu.size(), statistics.lidar_packets);
  text += left_out_packets(statistics.malformed, statistics.first_error, capture.truncated);
  return report_success(output, result, text);
}

/// The other destination ports of a capture, most datagrams first ("2369 (200 datagrams)").
std::string busiest_ports(const std::map<uint16_t, uint64_t>& other_ports) {
  std::vector<std::pair<uint64_t, uint16_t>> by_count;
  for (const auto& [port, count] : other_ports) by_count.emplace_back(count, port);
  std::sort(by_count.rbegin(), by_count.rend());
  std::vector<std::string> listed;
  for (std::size_t i = 0; i < std::min<std::size_t>(by_count.size(), 3); ++i) listed.push_back(fmt::format("{} ({} datagrams)", by_count[i].second, by_count[i].first));
  return listed.empty() ? "none" : fmt::format("{}", fmt::join(listed, ", "));
}

/// A spinning LiDAR's capture (Velodyne, Hesai: `decoder`) into one PointCloudMessage per
/// rotation on /lidar (sensor "lidar"): the datagrams to `ports` (the first the data port) are
/// decoded; `describe` adds the driver's own counts to the JSON and notes to the text.
template <typename Decoder>
int import_rotations(const Output& output, const ImportOptions& options, nlohmann::json& result, Decoder& decoder, const std::string& name,
                     const std::vector<uint16_t>& ports, const std::function<void(nlohmann::json&, std::string&)>& describe) {
  auto topics = topic_map(options.topic_overrides, "/lidar=/topic");
  if (!topics) return report_failure(output, result, topics.error().message);
  const auto renamed = topics->find("/lidar");
  const std::string topic = renamed == topics->end() ? "/lidar" : renamed->second;
  std::vector<msgs::PointCloudMessage> frames;
  std::map<uint16_t, uint64_t> other_ports;
  uint64_t other_datagrams = 0;
  drivers::PcapStatistics capture;
  const Status read = for_each_datagram(options.sources, capture, [&](const drivers::UdpDatagram& datagram) {
    if (std::find(ports.begin(), ports.end(), datagram.destination_port) == ports.end()) {
      ++other_ports[datagram.destination_port];
      ++other_datagrams;
      return;
    }
    decoder.add_packet(datagram.payload, datagram.time, frames);
  });
  if (!read) return report_failure(output, result, read.error().message);
  decoder.flush(frames);
  const auto& statistics = decoder.statistics();
  result["frames"] = frames.size();
  result["points"] = statistics.points;
  result["packets"] = statistics.packets;
  result["malformed_packets"] = statistics.malformed;
  result["records"] = capture.records;
  result["other_packets"] = capture.other_packets + other_datagrams;
  result["truncated_records"] = capture.truncated;
  std::string notes;
  describe(result, notes);
  if (frames.empty()) {
    return report_failure(output, result,
                          fmt::format("{}: no {} rotation decoded ({} datagrams to port {}, {} malformed{}{}; other ports: {})", fmt::join(options.sources, ", "),
                                      name, statistics.packets + statistics.malformed, ports.front(), statistics.malformed,
                                      statistics.first_error.empty() ? "" : ": ", statistics.first_error, busiest_ports(other_ports)));
  }
  const int code = write_log(output, result, log_options(options), [&](io::SensorLogWriter& writer) -> Status {
    HANZO_RETURN_IF_ERROR(writer.add_metadata({"import", {{"importer", "pcap " + options.driver}, {"model", options.model}, {"source", fmt::format("{}", fmt::join(options.sources, " "))}}}));
    for (const msgs::PointCloudMessage& frame : frames) HANZO_RETURN_IF_ERROR(writer.write(topic, frame, "lidar"));
    return ok_status();
  });
  if (code != 0) return code;
  result["ok"] = true;
  result["topic"] = topic;
  std::string text = fmt::format("{}: {} rotations ({} points) on {} from {} packets ({:.2f} s)\n", options.out, frames.size(), statistics.points, topic,
                                 statistics.packets, (frames.back().timestamp - frames.front().timestamp).seconds());
  text += notes + left_out_packets(statistics.malformed, statistics.first_error, capture.truncated);
  return report_success(output, result, text);
}

/// A Hesai Pandar40P capture with the unit's angle (and firetime) corrections.
int run_hesai_pcap_import(const Output& output, const ImportOptions& options, nlohmann::json result) {
  if (options.calibration.empty()) return report_failure(output, result, "--calibration: give the Pandar40P's angle correction CSV (Channel,Elevation,Azimuth)");
  Result<drivers::HesaiCalibration> calibration = drivers::load_hesai_calibration(options.calibration, options.firetime);
  if (!calibration) return report_failure(output, result, calibration.error().message);
  drivers::HesaiDecoderConfig config;
  config.frame_id = "lidar";
  Result<drivers::HesaiDecoder> decoder = drivers::HesaiDecoder::create(*calibration, config);
  if (!decoder) return report_failure(output, result, decoder.error().message);
  return import_rotations(output, options, result, *decoder, "Hesai", {static_cast<uint16_t>(options.port > 0 ? options.port : 2368)},
                          [&](nlohmann::json& counts, std::string& notes) {
                            const drivers::HesaiStatistics& statistics = decoder->statistics();
                            counts["capture_clock_packets"] = statistics.capture_clock_packets;
                            counts["firetime"] = options.firetime.empty() ? "none" : options.firetime;
                            if (statistics.capture_clock_packets > 0) {
                              notes += fmt::format("  {} packets timed by the capture's clock (the sensor's own was more than 10 s off: not synchronized)\n",
                                                   statistics.capture_clock_packets);
                            }
                            if (options.firetime.empty()) notes += "  no --firetime file: every channel of a block at the block's time\n";
                          });
}

/// A LiDAR's packet capture into one PointCloudMessage per rotation on /lidar (sensor "lidar").
int run_pcap_import(const Output& output, const ImportOptions& options) {
  nlohmann::json result = {{"format", "pcap"}, {"sources", options.sources}, {"out", options.out}, {"driver", options.driver}};
  if (options.driver == "ouster") return run_ouster_pcap_import(output, options, result);
  if (options.driver == "hesai") return run_hesai_pcap_import(output, options, result);
  if (options.driver != "velodyne") {
    return report_failure(output, result, fmt::format("--driver '{}': the pcap import decodes velodyne, ouster and hesai captures", options.driver));
  }
  if (options.model.empty()) return report_failure(output, result, "--model: give the Velodyne's model (VLP-16, VLP-32C, HDL-32E, HDL-64E, VLS-128)");
  Result<drivers::VelodyneModel> model = drivers::parse_velodyne_model(options.model);
  if (!model) return report_failure(output, result, "--model: " + model.error().message);
  drivers::VelodyneCalibration calibration = drivers::nominal_velodyne_calibration(*model);
  if (!options.calibration.empty()) {
    Result<drivers::VelodyneCalibration> loaded = drivers::load_velodyne_calibration(options.calibration);
    if (!loaded) return report_failure(output, result, loaded.error().message);
    calibration = std::move(*loaded);
  }
  drivers::VelodyneDecoderConfig config;
  config.model = *model;
  config.frame_id = "lidar";
  Result<drivers::VelodyneDecoder> decoder = drivers::VelodyneDecoder::create(calibration, config);
  if (!decoder) return report_failure(output, result, decoder.error().message);
  constexpr uint16_t kPositionPort = 8308;
  return import_rotations(output, options, result, *decoder, "Velodyne", {static_cast<uint16_t>(options.port > 0 ? options.port : 2368), kPositionPort},
                          [&](nlohmann::json& counts, std::string& notes) {
                            counts["position_packets"] = decoder->statistics().position_packets;
                            counts["calibration"] = options.calibration.empty() ? "nominal" : options.calibration;
                            if (options.calibration.empty()) notes += "  nominal calibration: give --calibration for the unit's\n";
                          });
}

int run_import(const Output& output, ImportOptions options) {
  if (!(options.time_origin > 0.0)) {  // a zero time means "no time" in a sensor log
    return report_failure(output, {{"format", options.format}},
                          fmt::format("--time-origin {}: relative times need an origin after 0 (a time of 0 is no time in a sensor log); "
                                      "keep the default 1e9: `run --gt` and `eval` pair the log with a ground truth in relative times",
                                      options.time_origin));
  }
  if (!options.privacy.empty()) {
    privacy::PrivacyFilterConfig config;
    Result<privacy::Redaction> redaction = privacy::parse_redaction(options.privacy);
    if (!redaction) return report_failure(output, {{"format", options.format}}, "--privacy: " + redaction.error().message);
    config.redaction = *redaction;
    Result<std::unique_ptr<privacy::PrivacyFilter>> filter = privacy::PrivacyFilter::create(config);
    if (!filter) return report_failure(output, {{"format", options.format}}, filter.error().message);
    options.redaction = std::make_shared<ImageRedaction>();
    options.redaction->filter = std::move(filter).value();
  }
  if (options.format == "rosbag" || options.format == "ros2bag") return run_rosbag_import(output, options);
  if (options.format == "carmen") return run_carmen_import(output, options);
  if (options.format == "kitti") return run_kitti_import(output, options);
  if (options.format == "euroc") return run_euroc_import(output, options);
  if (options.format == "tum-rgbd") return run_tum_rgbd_import(output, options);
  if (options.format == "images") return run_image_folder_import(output, options);
  if (options.format == "nmea") return run_nmea_import(output, options);
  if (options.format == "xsens") return run_xsens_import(output, options);
  if (options.format == "pcap") return run_pcap_import(output, options);
  nlohmann::json result = {{"format", options.format}, {"sources", options.sources}, {"out", options.out}};
  if (options.format != "csv") {
    return report_failure(output, result, fmt::format("unknown import format '{}' (supported: csv, rosbag, ros2bag, carmen, kitti, euroc, tum-rgbd, images, nmea, xsens, pcap)", options.format));
  }
  auto stems = topic_map(options.topic_overrides, "FILE_STEM=/topic");
  if (!stems) return report_failure(output, result, stems.error().message);
  const std::map<std::string, std::string>& topic_of_stem = *stems;

  std::vector<SourceMessages> sources;
  for (const std::string& path : options.sources) {
    auto messages = io::read_sensor_csv(path);
    if (!messages) return report_failure(output, result, messages.error().message);
    const std::string stem = std::filesystem::path(path).stem().string();
    const auto topic = topic_of_stem.find(stem);
    sources.push_back({topic == topic_of_stem.end() ? "/" + stem : topic->second, stem, std::move(*messages)});
  }
  // Write in time order across all sources so chunks do not overlap in time (readers then hold
  // one chunk at a time).
  struct Item {
    Timestamp time;
    std::size_t source;
    std::size_t index;
  };
  std::vector<Item> order;
  for (std::size_t s = 0; s < sources.size(); ++s) {
    for (std::size_t i = 0; i < sources[s].messages.size(); ++i) order.push_back({msgs::timestamp_of(sources[s].messages[i]), s, i});
  }
  std::stable_sort(order.begin(), order.end(), [](const Item& a, const Item& b) { return a.time < b.time; });

  const int code = write_log(output, result, log_options(options), [&](io::SensorLogWriter& writer) -> Status {
    std::map<std::string, std::string> provenance = {{"importer", "csv"}};
    for (std::size_t s = 0; s < sources.size(); ++s) provenance[fmt::format("source_{}", s)] = options.sources[s];
    HANZO_RETURN_IF_ERROR(writer.add_metadata({"import", provenance}));
    for (const Item& item : order) {
      const SourceMessages& source = sources[item.source];
      HANZO_RETURN_IF_ERROR(writer.write(source.topic, source.messages[item.index], source.sensor));
    }
    return ok_status();
  });
  if (code != 0) return code;

  result["ok"] = true;
  result["messages"] = order.size();
  nlohmann::json topics = nlohmann::json::array();
  std::string text = fmt::format("{}: {} messages from {} file(s)\n", options.out, order.size(), sources.size());
  for (const SourceMessages& source : sources) {
    topics.push_back({{"topic", source.topic}, {"messages", source.messages.size()}});
    text += fmt::format("  {}  {} messages\n", source.topic, source.messages.size());
  }
  result["topics"] = topics;
  return report_success(output, result, text);
}

}  // namespace

void add_import_command(CLI::App& app, const Output& output, Command& run) {
  auto options = std::make_shared<ImportOptions>();
  CLI::App* command = app.add_subcommand("import", "Convert recordings into a sensor log (MCAP)");
  command->add_option("FORMAT", options->format, "Input format: csv, rosbag (ROS 1), ros2bag, carmen, kitti, euroc, tum-rgbd, images (a folder of image files), nmea (GNSS receiver logs), xsens (an Xsens IMU's MTData2 stream) or pcap (a LiDAR's packet capture)")->required();
  command->add_option("SRC", options->sources, "Input files (kitti, euroc, tum-rgbd: the sequence folder; ros2bag: the bag folder or its .mcap / .db3 file; images: one folder, or two for a stereo pair)")->required();
  command->add_option("--out", options->out, "Sensor log to write (.mcap)")->required();
  command->add_option("--compression", options->compression, "Chunk compression: zstd, lz4 or none")->capture_default_str();
  command->add_flag("--no-foxglove", options->no_foxglove,
                    "Leave out the Foxglove mirror channels (<topic>/foxglove for poses, clouds, fixes, images)");
  command->add_option("--topic", options->topic_overrides,
                      "csv: FILE_STEM=/topic (default /FILE_STEM); rosbag, ros2bag: /ros/topic=/topic (only these are imported); nmea: /gnss=/topic; xsens: /imu=/topic, /gnss=/topic");
  command->add_option("--wheel-separation", options->wheel_separation,
                      "rosbag, ros2bag, carmen: wheel separation (m) to import odometry / twists as differential-drive wheel odometry");
  command->add_flag("--use-record-time", options->use_record_time, "rosbag, ros2bag: bag record time instead of header.stamp");
  command->add_option("--ground-truth,--gt", options->ground_truth,
                      "carmen, kitti, euroc, tum-rgbd: write the reference trajectory (carmen: the scans' poses) as TUM");
  command->add_option("--calibration,--calib", options->calibration, "kitti, euroc, tum-rgbd, rosbag, ros2bag, images: write the sensors' calibration YAML (bags: from /tf_static and CameraInfo; images: needs --intrinsics); pcap: read the LiDAR's calibration (Velodyne db.xml or ROS YAML; Hesai angle correction CSV)");
  command->add_option("--body-frame", options->body_frame,
                      "rosbag, ros2bag: the calibration's body frame (default base_link, base_footprint, the IMU's frame)");
  command->add_flag("--no-images", options->no_images, "kitti, euroc: leave the camera images out");
  command->add_option("--poses", options->poses, "kitti: poses file (default SEQUENCE/../../poses/NN.txt when present)");
  command->add_option("--time-origin", options->time_origin, "kitti, images: Unix time (s) of relative times' zero")->capture_default_str();
  command->add_option("--times", options->times, "images: times file, a line per image: TIME (s) or TIME NAME (default: times in the file names)");
  command->add_option("--rate", options->rate, "images: frames per second, when neither a times file nor the names give times");
  command->add_option("--intrinsics", options->intrinsics, "images: the camera's fx,fy,cx,cy (pixels)")->delimiter(',');
  command->add_option("--distortion", options->distortion, "images: radtan coefficients k1,k2,p1,p2[,k3]")->delimiter(',');
  command->add_option("--baseline", options->baseline, "images, two folders: the stereo baseline (m; the right camera along the left one's x axis)");
  command->add_option("--driver", options->driver, "pcap: the sensor's driver (velodyne, ouster, hesai)");
  command->add_option("--firetime", options->firetime, "pcap, hesai: the Pandar40P's firetime correction CSV (Channel,fire time(us))");
  command->add_option("--metadata", options->metadata, "pcap, ouster: the sensor's metadata JSON");
  command->add_option("--model", options->model, "pcap, velodyne: VLP-16, VLP-32C, HDL-32E, HDL-64E or VLS-128");
  command->add_option("--port", options->port, "pcap: the LiDAR's UDP data port (default: velodyne 2368, ouster 7502, hesai 2368)")->check(CLI::Range(1, 65535));
  command->add_option("--date", options->date, "nmea: UTC date (YYYY-MM-DD) of fixes before the log's first RMC or ZDA sentence");
  command->add_option("--privacy", options->privacy, "Blur (blur) or black out (black) faces and licence plates in camera images before they are written")
      ->check(CLI::IsMember({"blur", "black"}));
  command->callback([&output, &run, options] { run = [&output, options] { return run_import(output, *options); }; });
}

}  // namespace hanzo::fusion::app
