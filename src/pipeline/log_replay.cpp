#include "hanzo/fusion/pipeline/log_replay.hpp"

#include <chrono>
#include <utility>

namespace hanzo::fusion::pipeline {

LogReplaySummary replay_log(Session& session, io::SensorLogReader& reader, const std::function<void(Timestamp)>& progress) {
  LogReplaySummary summary;
  const auto timed = [&summary](auto&& work) {
    const auto start = std::chrono::steady_clock::now();
    auto result = work();
    summary.push_seconds += std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    return result;
  };
  io::LogEntry entry;
  while (true) {
    Result<bool> more = reader.next(entry);
    if (!more) {
      ++summary.unread;
      continue;
    }
    if (!*more) break;
    auto* message = std::get_if<msgs::SensorMessage>(&entry.message);
    if (message == nullptr) continue;  // pose estimates in the log (e.g. ground truth)
    const config::SensorConfig* sensor = session.frontend().sensor_for_topic(entry.topic);
    if (sensor == nullptr) {
      ++summary.unmapped_topics[entry.topic];
      continue;
    }
    ++summary.messages;
    if (summary.first.is_zero()) summary.first = entry.log_time;
    summary.last = entry.log_time;
    const Status pushed = timed([&] { return session.push(sensor->name, std::move(*message)); });
    if (!pushed) ++summary.rejected;
    if (progress) progress(entry.log_time);
  }
  timed([&] {
    session.flush();
    return 0;
  });
  return summary;
}

}  // namespace hanzo::fusion::pipeline
