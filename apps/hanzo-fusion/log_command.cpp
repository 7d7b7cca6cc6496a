// hanzo-fusion log info LOG [--verify] | log export LOG --topic T [--format csv|png] [--out FILE|FOLDER]

#include <algorithm>
#include <filesystem>
#include <memory>
#include <string>

#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include <fmt/format.h>

#include "commands.hpp"
#include "hanzo/fusion/core/yaml_value.hpp"
#include "hanzo/fusion/io/csv_export.hpp"
#include "hanzo/fusion/io/log_summary.hpp"
#include "hanzo/fusion/io/sensor_log.hpp"

namespace hanzo::fusion::app {
namespace {

std::string iso(uint64_t ns) { return Timestamp::from_nanoseconds(static_cast<int64_t>(ns)).to_iso8601(); }

std::string human_bytes(uint64_t bytes) {
  const char* units[] = {"B", "KiB", "MiB", "GiB", "TiB"};
  double value = static_cast<double>(bytes);
  int unit = 0;
  while (value >= 1024.0 && unit < 4) {
    value /= 1024.0;
    ++unit;
  }
  return fmt::format("{:.1f} {}", value, units[unit]);
}

int run_info(const Output& output, const std::string& path, bool verify) {
  nlohmann::json result = {{"file", path}};
  auto reader = io::mcap::McapReader::open(path);
  if (!reader) return report_failure(output, result, reader.error().message);
  auto summary = io::summarize_log(**reader);
  if (!summary) return report_failure(output, result, summary.error().message);
  const double duration_s = static_cast<double>(summary->end_time - summary->start_time) * 1e-9;
  result["ok"] = true;
  result["library"] = summary->library;
  result["file_size"] = summary->file_size;
  result["messages"] = summary->message_count;
  result["start_time_ns"] = summary->start_time;
  result["end_time_ns"] = summary->end_time;
  result["duration_s"] = duration_s;
  result["chunks"] = summary->chunk_count;
  result["compression"] = summary->compressions;
  result["compressed_bytes"] = summary->compressed_bytes;
  result["uncompressed_bytes"] = summary->uncompressed_bytes;
  result["warning"] = (*reader)->warning() ? nlohmann::json(*(*reader)->warning()) : nlohmann::json(nullptr);
  std::string text = fmt::format("path:        {}\nlibrary:     {}\nsize:        {}\n", path, summary->library,
                                 human_bytes(summary->file_size));
  if (summary->message_count > 0) {
    text += fmt::format("duration:    {:.3f} s\nstart:       {}\nend:         {}\n", duration_s, iso(summary->start_time),
                        iso(summary->end_time));
  }
  text += fmt::format("messages:    {}\nchunks:      {} ({}; {} compressed from {})\nchannels:\n", summary->message_count,
                      summary->chunk_count, fmt::join(summary->compressions, ", "), human_bytes(summary->compressed_bytes),
                      human_bytes(summary->uncompressed_bytes));
  nlohmann::json channels = nlohmann::json::array();
  std::size_t topic_width = 5;
  for (const auto& c : summary->channels) topic_width = std::max(topic_width, c.topic.size());
  for (const io::ChannelSummary& c : summary->channels) {
    channels.push_back({{"topic", c.topic},
                        {"schema", c.schema_name},
                        {"encoding", c.message_encoding},
                        {"messages", c.message_count},
                        {"first_time_ns", c.first_time},
                        {"last_time_ns", c.last_time},
                        {"rate_hz", c.rate_hz},
                        {"max_gap_s", static_cast<double>(c.max_gap_ns) * 1e-9},
                        {"max_gap_at_ns", c.max_gap_at}});
    text += fmt::format("  {:<{}}  {:>8} msgs  {:>9.2f} Hz  max gap {:>8.3f} s  {}\n", c.topic, topic_width, c.message_count,
                        c.rate_hz, static_cast<double>(c.max_gap_ns) * 1e-9, c.schema_name);
  }
  result["channels"] = channels;
  if ((*reader)->warning()) text += fmt::format("warning:     {}\n", *(*reader)->warning());
  if (verify) {
    auto report = (*reader)->verify();
    if (!report) return report_failure(output, result, report.error().message);
    result["verified"] = {{"records", report->records},
                          {"chunks", report->chunks},
                          {"messages", report->messages},
                          {"data_section_crc_checked", report->data_section_crc_checked},
                          {"summary_crc_checked", report->summary_crc_checked}};
    text += fmt::format("verified:    {} records, {} chunks, {} messages; CRCs: data section {}, summary {}\n",
                        report->records, report->chunks, report->messages,
                        report->data_section_crc_checked ? "ok" : "absent", report->summary_crc_checked ? "ok" : "absent");
  }
  return report_success(output, result, text);
}

// One image message as a PNG (8-bit grey or colour; depth images as 16-bit grey in their units).
Status write_png(const msgs::ImageMessage& image, const std::string& file) {
  const int rows = static_cast<int>(image.height), cols = static_cast<int>(image.width);
  cv::Mat pixels;
  switch (image.encoding) {
    case msgs::ImageEncoding::kMono8: pixels = cv::Mat(rows, cols, CV_8UC1, const_cast<uint8_t*>(image.data.data())); break;
    case msgs::ImageEncoding::kBgr8: pixels = cv::Mat(rows, cols, CV_8UC3, const_cast<uint8_t*>(image.data.data())); break;
    case msgs::ImageEncoding::kRgb8: cv::cvtColor(cv::Mat(rows, cols, CV_8UC3, const_cast<uint8_t*>(image.data.data())), pixels, cv::COLOR_RGB2BGR); break;
    case msgs::ImageEncoding::kDepth16: pixels = cv::Mat(rows, cols, CV_16UC1, const_cast<uint8_t*>(image.data.data())); break;
    case msgs::ImageEncoding::kDepth32f:
      cv::Mat(rows, cols, CV_32FC1, const_cast<uint8_t*>(image.data.data())).convertTo(pixels, CV_16UC1, 1000.0);  // millimetres
      break;
  }
  if (!cv::imwrite(file, pixels)) return Error(fmt::format("{}: cannot write", file));
  return ok_status();
}

int run_export(const Output& output, const std::string& path, const std::string& topic, const std::string& format,
               const std::string& out_path) {
  nlohmann::json result = {{"file", path}, {"topic", topic}, {"format", format}};
  if (format != "csv" && format != "png") return report_failure(output, result, fmt::format("unknown export format '{}' (expected csv or png)", format));
  if (format == "png" && out_path.empty()) return report_failure(output, result, "--format png needs --out FOLDER (one PNG per image)");
  if (output.json && out_path.empty()) {
    return report_failure(output, result, "--json needs --out FILE (stdout carries the JSON result)");
  }
  io::mcap::ReadOptions options;
  options.topics = {topic};
  auto reader = io::SensorLogReader::open(path, options);
  if (!reader) return report_failure(output, result, reader.error().message);
  if ((*reader)->mcap().channel_by_topic(topic) == nullptr) {
    std::vector<std::string> topics;
    for (const auto& [id, channel] : (*reader)->mcap().channels()) topics.push_back(channel.topic);
    std::sort(topics.begin(), topics.end());
    return report_failure(output, result, fmt::format("{}: no topic '{}' (topics: {})", path, topic, fmt::join(topics, ", ")));
  }
  std::string csv;
  uint64_t messages = 0;
  io::LogEntry entry;
  if (format == "png") {
    std::error_code error;
    std::filesystem::create_directories(out_path, error);
    if (error) return report_failure(output, result, fmt::format("{}: cannot create the folder ({})", out_path, error.message()));
  }
  while (true) {
    auto more = (*reader)->next(entry);
    if (!more) return report_failure(output, result, more.error().message);
    if (!*more) break;
    if (format == "png") {
      const auto* message = std::get_if<msgs::SensorMessage>(&entry.message);
      const auto* image = message != nullptr ? std::get_if<msgs::ImageMessage>(message) : nullptr;
      if (image == nullptr) return report_failure(output, result, fmt::format("{}: topic '{}' does not carry images (png exports camera topics)", path, topic));
      // Named by the image's time in nanoseconds: the files sort in time order.
      const std::string file = (std::filesystem::path(out_path) / fmt::format("{}.png", image->timestamp.nanoseconds())).string();
      if (Status written = write_png(*image, file); !written) return report_failure(output, result, written.error().message);
      ++messages;
      continue;
    }
    if (messages++ == 0) csv += io::csv_header(entry);
    io::append_csv_rows(entry, csv);
  }
  if (Status whole = (*reader)->complete(); !whole) return report_failure(output, result, whole.error().message);
  if (messages == 0 && (*reader)->skipped_messages() > 0) {
    return report_failure(output, result, fmt::format("{}: topic '{}' does not carry hanzo.fusion.v1 messages (a Foxglove mirror or "
                                                      "another tool's channel); export its source topic instead", path, topic));
  }
  result["ok"] = true;
  result["messages"] = messages;
  if (format == "png") {
    result["out"] = out_path;
    return report_success(output, result, fmt::format("{}: {} images of {} written to {}/\n", path, messages, topic, out_path));
  }
  if (out_path.empty()) {
    std::fwrite(csv.data(), 1, csv.size(), stdout);
    return 0;
  }
  if (Status written = yaml::write_file_atomically(out_path, csv); !written) {
    return report_failure(output, result, written.error().message);
  }
  result["out"] = out_path;
  return report_success(output, result, fmt::format("{}: {} messages of {} written to {}\n", path, messages, topic, out_path));
}

}  // namespace

void add_log_command(CLI::App& app, const Output& output, Command& run) {
  CLI::App* log_command = app.add_subcommand("log", "Sensor logs (MCAP): summary, verification, export");
  log_command->require_subcommand(1);

  CLI::App* info = log_command->add_subcommand("info", "Channels, message counts, rates, duration and time gaps");
  auto info_path = std::make_shared<std::string>();
  auto verify = std::make_shared<bool>(false);
  info->add_option("LOG", *info_path, "Sensor log (.mcap)")->required();
  info->add_flag("--verify", *verify, "Also read every record and check every CRC and index");
  info->callback([&output, &run, info_path, verify] {
    run = [&output, info_path, verify] { return run_info(output, *info_path, *verify); };
  });

  CLI::App* export_command = log_command->add_subcommand("export", "Write one topic's messages as CSV, or a camera topic's images as PNG files");
  struct ExportOptions {
    std::string path, topic, format = "csv", out;
  };
  auto options = std::make_shared<ExportOptions>();
  export_command->add_option("LOG", options->path, "Sensor log (.mcap)")->required();
  export_command->add_option("--topic", options->topic, "Topic to export, e.g. /imu")->required();
  export_command->add_option("--format", options->format, "Output format: csv, or png for a camera topic (one file per image)")->capture_default_str();
  export_command->add_option("--out", options->out, "Output file (default: stdout); with png the folder for the images");
  export_command->callback([&output, &run, options] {
    run = [&output, options] { return run_export(output, options->path, options->topic, options->format, options->out); };
  });
}

}  // namespace hanzo::fusion::app
