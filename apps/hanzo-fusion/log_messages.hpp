#pragma once
// Reading one topic of a sensor log into messages (calib motion: the IMU; calib camera: images).

#include <string>
#include <string_view>
#include <variant>
#include <vector>

#include <fmt/format.h>

#include "hanzo/fusion/io/sensor_log.hpp"

namespace hanzo::fusion::app {

/// Every `Message` on `topic` of the log at `path`, in log order (the first topic carrying a
/// `Message` when `topic` is empty). Fails when the log cannot be read or has none (`what`
/// names them in the message: "IMU messages", "images").
template <typename Message>
Result<std::vector<Message>> read_log_messages(const std::string& path, std::string topic, std::string_view what) {
  auto reader = io::SensorLogReader::open(path);
  if (!reader) return reader.error();
  std::vector<Message> messages;
  io::LogEntry entry;
  while (true) {
    Result<bool> more = (*reader)->next(entry);
    if (!more) return more.error();
    if (!*more) break;
    const auto* sensor_message = std::get_if<msgs::SensorMessage>(&entry.message);
    const auto* message = sensor_message ? std::get_if<Message>(sensor_message) : nullptr;
    if (message == nullptr) continue;
    if (topic.empty()) topic = entry.topic;
    if (entry.topic == topic) messages.push_back(*message);
  }
  if (messages.empty()) return Error(fmt::format("{}: no {}{}", path, what, topic.empty() ? "" : " on " + topic));
  return messages;
}

}  // namespace hanzo::fusion::app
