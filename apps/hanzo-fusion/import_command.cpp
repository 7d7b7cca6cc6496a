// hanzo-fusion import FORMAT SRC... --out LOG.mcap: converts recordings into a sensor log.
// Formats so far: csv (IMU / GNSS / wheel odometry files), rosbag (ROS1 bag v2.0) and carmen
// (2D laser logs); see docs/sensor-logs.md.

#include <algorithm>
#include <filesystem>
#include <functional>
#include <memory>
#include <string>
#include <vector>

#include <fmt/format.h>

#include "commands.hpp"
#include "hanzo/fusion/io/carmen_import.hpp"
#include "hanzo/fusion/io/csv_import.hpp"
#include "hanzo/fusion/io/rosbag_import.hpp"
#include "hanzo/fusion/io/sensor_log.hpp"

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
  bool use_record_time = false;              // rosbag
  std::string ground_truth;                  // carmen: scan poses as TUM
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

// Opens LOG.partial, lets `fill` write it, and moves it into place only when complete.
int write_log(const Output& output, nlohmann::json& result, const ImportOptions& options,
              const std::function<Status(io::SensorLogWriter&)>& fill) {
  auto compression = io::mcap::compression_from_name(options.compression);
  if (!compression) return report_failure(output, result, compression.error().message);
  io::SensorLogWriterConfig config;
  config.mcap.compression = *compression;
  config.foxglove_channels = !options.no_foxglove;
  const std::string temporary = options.out + ".partial";
  auto writer = io::SensorLogWriter::open(temporary, config);
  if (!writer) return report_failure(output, result, writer.error().message);
  Status status = fill(**writer);
  if (status) status = (*writer)->close();
  if (!status) {
    (void)(*writer)->close();  // the partial file is removed anyway
    std::filesystem::remove(temporary);
    return report_failure(output, result, status.error().message);
  }
  std::error_code ec;
  std::filesystem::rename(temporary, options.out, ec);
  if (ec) return report_failure(output, result, fmt::format("{}: cannot move into place ({})", options.out, ec.message()));
  return 0;
}

int run_rosbag_import(const Output& output, const ImportOptions& options) {
  nlohmann::json result = {{"format", "rosbag"}, {"sources", options.sources}, {"out", options.out}};
  if (options.sources.size() != 1) return report_failure(output, result, "rosbag import takes one bag (SRC) at a time");
  io::RosbagImportConfig config;
  auto map = topic_map(options.topic_overrides, "/ros/topic=/log/topic");
  if (!map) return report_failure(output, result, map.error().message);
  config.topic_map = *map;
  if (options.wheel_separation > 0.0) config.wheel_separation = options.wheel_separation;
  config.use_record_time = options.use_record_time;
  io::RosbagImportReport report;
  const int code = write_log(output, result, options, [&](io::SensorLogWriter& writer) -> Status {
    HANZO_ASSIGN_OR_RETURN(report, io::import_rosbag(options.sources[0], writer, config));
    return writer.add_metadata({"import", {{"importer", "rosbag"}, {"source", options.sources[0]}}});
  });
  if (code != 0) return code;
  result["ok"] = true;
  result["bag"] = {{"chunks", report.bag.chunks}, {"messages", report.bag.messages}, {"complete", report.bag.complete},
                   {"compressions", report.bag.chunk_compressions}};
  nlohmann::json topics = nlohmann::json::array();
  uint64_t imported = 0;
  std::string text = fmt::format("{}: {} chunks, {} messages{}\n", options.sources[0], report.bag.chunks, report.bag.messages,
                                 report.bag.complete ? "" : " (cut off: read up to the last complete record)");
  for (const io::TopicImportReport& topic : report.topics) {
    imported += topic.imported;
    topics.push_back({{"ros_topic", topic.ros_topic}, {"ros_type", topic.ros_type}, {"topic", topic.topic},
                      {"imported", topic.imported}, {"rejected", topic.rejected}, {"first_rejection", topic.first_rejection}});
    text += fmt::format("  {} ({}) -> {}: {} messages", topic.ros_topic, topic.ros_type, topic.topic, topic.imported);
    text += topic.rejected == 0 ? "\n" : fmt::format(", {} rejected (first {})\n", topic.rejected, topic.first_rejection);
  }
  for (const auto& [ros_topic, type] : report.skipped_topics) text += fmt::format("  {} ({}) skipped\n", ros_topic, type);
  result["topics"] = topics;
  result["skipped_topics"] = report.skipped_topics;
  result["messages"] = imported;
  text += fmt::format("{}: {} messages\n", options.out, imported);
  return report_success(output, result, text);
}

int run_carmen_import(const Output& output, const ImportOptions& options) {
  nlohmann::json result = {{"format", "carmen"}, {"sources", options.sources}, {"out", options.out}};
  if (options.sources.size() != 1) return report_failure(output, result, "carmen import takes one log (SRC) at a time");
  io::CarmenImportConfig config;
  config.wheel_separation = options.wheel_separation;
  io::CarmenImportReport report;
  const int code = write_log(output, result, options, [&](io::SensorLogWriter& writer) -> Status {
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
  std::string text = fmt::format("{}: {} scans -> {}, {} odometry -> {}, {} other lines skipped\n", options.sources[0],
                                 report.scans, config.laser_topic, report.odometry,
                                 config.wheel_separation > 0 ? config.odometry_topic : "(left out: no --wheel-separation)",
                                 report.skipped_lines);
  if (report.rejected > 0) text += fmt::format("  {} rejected (first: {})\n", report.rejected, report.first_rejection);
  if (!options.ground_truth.empty()) text += fmt::format("  scan poses written to {}\n", options.ground_truth);
  return report_success(output, result, text);
}

int run_import(const Output& output, const ImportOptions& options) {
  if (options.format == "rosbag") return run_rosbag_import(output, options);
  if (options.format == "carmen") return run_carmen_import(output, options);
  nlohmann::json result = {{"format", options.format}, {"sources", options.sources}, {"out", options.out}};
  if (options.format != "csv") {
    return report_failure(output, result, fmt::format("unknown import format '{}' (supported: csv, rosbag, carmen)", options.format));
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

  const int code = write_log(output, result, options, [&](io::SensorLogWriter& writer) -> Status {
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
  command->add_option("FORMAT", options->format, "Input format: csv, rosbag or carmen")->required();
  command->add_option("SRC", options->sources, "Input files")->required();
  command->add_option("--out", options->out, "Sensor log to write (.mcap)")->required();
  command->add_option("--compression", options->compression, "Chunk compression: zstd, lz4 or none")->capture_default_str();
  command->add_flag("--no-foxglove", options->no_foxglove,
                    "Leave out the Foxglove mirror channels (<topic>/foxglove for poses, clouds, fixes, images)");
  command->add_option("--topic", options->topic_overrides,
                      "csv: FILE_STEM=/topic (default /FILE_STEM); rosbag: /ros/topic=/topic (only these are imported)");
  command->add_option("--wheel-separation", options->wheel_separation,
                      "rosbag, carmen: wheel separation (m) to import odometry as differential-drive wheel odometry");
  command->add_flag("--use-record-time", options->use_record_time, "rosbag: bag record time instead of header.stamp");
  command->add_option("--ground-truth", options->ground_truth, "carmen: write the scans' poses to this TUM file");
  command->callback([&output, &run, options] { run = [&output, options] { return run_import(output, *options); }; });
}

}  // namespace hanzo::fusion::app
