// hanzo-fusion import FORMAT SRC... --out LOG.mcap: converts recordings into a sensor log.
// Formats so far: csv (IMU / GNSS / wheel odometry files, see docs/sensor-logs.md).

#include <algorithm>
#include <filesystem>
#include <memory>
#include <string>
#include <vector>

#include <fmt/format.h>

#include "commands.hpp"
#include "hanzo/fusion/io/csv_import.hpp"
#include "hanzo/fusion/io/sensor_log.hpp"

namespace hanzo::fusion::app {
namespace {

struct ImportOptions {
  std::string format;
  std::vector<std::string> sources;
  std::string out;
  std::string compression = "zstd";
  std::vector<std::string> topic_overrides;  // "STEM=/topic"
};

struct SourceMessages {
  std::string topic;
  std::string sensor;
  std::vector<msgs::SensorMessage> messages;
};

int run_import(const Output& output, const ImportOptions& options) {
  nlohmann::json result = {{"format", options.format}, {"sources", options.sources}, {"out", options.out}};
  if (options.format != "csv") {
    return report_failure(output, result, fmt::format("unknown import format '{}' (supported: csv)", options.format));
  }
  auto compression = io::mcap::compression_from_name(options.compression);
  if (!compression) return report_failure(output, result, compression.error().message);
  std::map<std::string, std::string> topic_of_stem;
  for (const std::string& entry : options.topic_overrides) {
    const auto equals = entry.find('=');
    if (equals == std::string::npos || equals == 0 || equals + 1 == entry.size()) {
      return report_failure(output, result, fmt::format("--topic '{}': expected FILE_STEM=/topic", entry));
    }
    topic_of_stem[entry.substr(0, equals)] = entry.substr(equals + 1);
  }

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

  io::mcap::McapWriterConfig config;
  config.compression = *compression;
  const std::string temporary = options.out + ".partial";
  auto writer = io::SensorLogWriter::open(temporary, config);
  if (!writer) return report_failure(output, result, writer.error().message);
  std::map<std::string, std::string> provenance = {{"importer", "csv"}};
  for (std::size_t s = 0; s < sources.size(); ++s) provenance[fmt::format("source_{}", s)] = options.sources[s];
  Status status = (*writer)->add_metadata({"import", provenance});
  for (std::size_t k = 0; status && k < order.size(); ++k) {
    const SourceMessages& source = sources[order[k].source];
    status = (*writer)->write(source.topic, source.messages[order[k].index], source.sensor);
  }
  if (status) status = (*writer)->close();
  if (!status) {
    std::filesystem::remove(temporary);
    return report_failure(output, result, status.error().message);
  }
  std::error_code ec;
  std::filesystem::rename(temporary, options.out, ec);  // the log appears only when complete
  if (ec) return report_failure(output, result, fmt::format("{}: cannot move into place ({})", options.out, ec.message()));

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
  command->add_option("FORMAT", options->format, "Input format: csv")->required();
  command->add_option("SRC", options->sources, "Input files")->required();
  command->add_option("--out", options->out, "Sensor log to write (.mcap)")->required();
  command->add_option("--compression", options->compression, "Chunk compression: zstd, lz4 or none")->capture_default_str();
  command->add_option("--topic", options->topic_overrides, "Topic for a file: FILE_STEM=/topic (default /FILE_STEM)");
  command->callback([&output, &run, options] { run = [&output, options] { return run_import(output, *options); }; });
}

}  // namespace hanzo::fusion::app
