#include "hanzo/fusion/pipeline/log_replay.hpp"

#include <algorithm>
#include <chrono>
#include <utility>
#include <vector>

#include <fmt/format.h>
#include <fmt/ranges.h>

#include "hanzo/fusion/core/files.hpp"
#include "hanzo/fusion/maps/provenance.hpp"

namespace hanzo::fusion::pipeline {

LogReplaySummary replay_log(Session& session, io::SensorLogReader& reader, const std::function<void(Timestamp)>& progress) {
  LogReplaySummary summary;
  const auto timed = [&summary](auto&& work) {
    const auto start = std::chrono::steady_clock::now();
    auto result = work();
    summary.push_seconds += std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    return result;
  };
  const io::mcap::Statistics& statistics = reader.mcap().statistics();
  summary.records_in_file = statistics.message_count;
  summary.file_start = Timestamp::from_nanoseconds(static_cast<int64_t>(statistics.message_start_time));
  summary.file_end = Timestamp::from_nanoseconds(static_cast<int64_t>(statistics.message_end_time));
  if (reader.mcap().warning()) summary.truncation = *reader.mcap().warning();
  io::LogEntry entry;
  while (true) {
    Result<bool> more = reader.next(entry);
    summary.records_read = reader.records_read();
    summary.read_until = std::max(summary.read_until, reader.last_log_time());
    if (!more) {
      if (reader.corrupted_chunks() > summary.corrupted_chunks) {  // a corrupted chunk, skipped
        summary.corrupted_chunks = reader.corrupted_chunks();
        summary.first_chunk_error = reader.first_chunk_error();
      } else if (summary.unread++ == 0) {
        summary.first_unread_error = more.error().message;
      }
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

std::string LogReplaySummary::incomplete() const {
  std::vector<std::string> what;
  if (corrupted_chunks > 0) what.push_back(fmt::format("{} corrupted chunk{} skipped ({})", corrupted_chunks, corrupted_chunks == 1 ? "" : "s", first_chunk_error));
  if (!truncation.empty()) what.push_back(truncation);
  if (unread > 0) what.push_back(fmt::format("{} message{} did not decode (first: {})", unread, unread == 1 ? "" : "s", first_unread_error));
  if (what.empty()) return "";
  const double read_seconds = read_until > file_start ? (read_until - file_start).seconds() : 0.0;
  const double file_seconds = file_end > file_start ? (file_end - file_start).seconds() : 0.0;
  return fmt::format("{}: read {:.1f} s of {:.1f} s of log ({} of {} messages)", fmt::join(what, "; "), read_seconds, file_seconds, records_read, records_in_file);
}

Result<msgs::FusionMap> replayed_map(const Session& session, const std::string& map_id, Timestamp created, const std::string& config_path,
                                     const std::string& log_path, const std::string& software_version) {
  msgs::FusionMap map = session.map();
  if (map.occupancy && map.occupancy->occupancy.empty()) map.occupancy.reset();
  if (map.points && map.points->points.empty()) map.points.reset();
  map.map_id = map_id;
  map.version = 1;
  map.created = created;
  map.provenance.software_version = software_version;
  HANZO_ASSIGN_OR_RETURN(map.sensor_configuration, read_file(config_path));
  msgs::InputLog input;
  HANZO_ASSIGN_OR_RETURN(input, maps::describe_input_file(log_path));
  map.provenance.input_logs.push_back(input);
  return map;
}

}  // namespace hanzo::fusion::pipeline
