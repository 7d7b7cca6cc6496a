#include "hanzo/fusion/privacy/log_redaction.hpp"

#include <algorithm>
#include <filesystem>

#include <fmt/format.h>

#include "hanzo/fusion/core/files.hpp"

namespace hanzo::fusion::privacy {
void count_regions(const std::vector<RedactedRegion>& regions, TopicRedactionCounts& counts) {
  ++counts.images;
  if (!regions.empty()) ++counts.redacted_images;
  for (const RedactedRegion& region : regions) ++(region.kind == "face" ? counts.faces : counts.licence_plates);
}

namespace {

Result<LogRedactionSummary> copy_redacted(PrivacyFilter& filter, io::SensorLogReader& reader, io::SensorLogWriter& writer,
                                          const std::string& input_path) {
  for (const io::mcap::Metadata& metadata : reader.mcap().metadata()) {
    if (metadata.name == "hanzo-fusion") continue;  // the writer writes its own format record
    HANZO_RETURN_IF_ERROR(writer.add_metadata(metadata));
  }
  std::map<std::string, std::string> sensor_by_topic;
  for (const auto& [id, channel] : reader.mcap().channels()) {
    if (const auto sensor = channel.metadata.find("sensor"); sensor != channel.metadata.end()) sensor_by_topic[channel.topic] = sensor->second;
  }
  LogRedactionSummary summary;
  summary.input_warning = reader.mcap().warning();
  io::LogEntry entry;
  while (true) {
    Result<bool> more = reader.next(entry);
    if (!more) return Error(fmt::format("{}: {}", input_path, more.error().message));
    if (!*more) break;
    ++summary.messages;
    if (auto* pose = std::get_if<msgs::PoseEstimate>(&entry.message)) {
      HANZO_RETURN_IF_ERROR(writer.write(entry.topic, *pose));
      continue;
    }
    auto& message = std::get<msgs::SensorMessage>(entry.message);
    if (auto* image = std::get_if<msgs::ImageMessage>(&message)) {
      Result<std::vector<RedactedRegion>> regions = filter.apply(*image);
      if (!regions) return Error(fmt::format("{} at {} ns: {}", entry.topic, entry.log_time.nanoseconds(), regions.error().message));
      count_regions(*regions, summary.by_topic[entry.topic]);
      count_regions(*regions, summary.total);
    }
    const auto sensor = sensor_by_topic.find(entry.topic);
    HANZO_RETURN_IF_ERROR(writer.write(entry.topic, message, sensor == sensor_by_topic.end() ? std::string() : sensor->second));
  }
  HANZO_RETURN_IF_ERROR(writer.close());
  return summary;
}

}  // namespace

Result<LogRedactionSummary> redact_log(PrivacyFilter& filter, const std::string& input_path, const std::string& output_path,
                                       const io::SensorLogWriterConfig& writer_config) {
  if (std::filesystem::weakly_canonical(input_path) == std::filesystem::weakly_canonical(output_path)) {
    return Error(fmt::format("{}: the output must not be the input", output_path));
  }
  std::unique_ptr<io::SensorLogReader> reader;
  HANZO_ASSIGN_OR_RETURN(reader, io::SensorLogReader::open(input_path));
  const std::string partial = output_path + ".partial";
  io::SensorLogWriterConfig config = writer_config;
  const auto& channels = reader->mcap().channels();
  config.foxglove_channels = std::any_of(channels.begin(), channels.end(), [](const auto& channel) { return channel.second.metadata.count("mirror_of") > 0; });
  std::unique_ptr<io::SensorLogWriter> writer;
  HANZO_ASSIGN_OR_RETURN(writer, io::SensorLogWriter::open(partial, config));
  Result<LogRedactionSummary> summary = copy_redacted(filter, *reader, *writer, input_path);
  writer.reset();
  HANZO_RETURN_IF_ERROR(commit_partial_file(partial, output_path, summary ? ok_status() : Status(summary.error())));
  return summary;
}

}  // namespace hanzo::fusion::privacy
