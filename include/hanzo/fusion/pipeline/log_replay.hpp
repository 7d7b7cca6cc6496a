#pragma once
// Replaying a sensor log through a Session: what `hanzo-fusion run` and Python's
// Session.replay() do. Every sensor message whose topic a configured sensor reads is pushed in
// log order (rejections are counted, the replay goes on), then the Session is flushed.
// Messages that do not decode are counted and skipped; other topics (ground truth, sensors the
// configuration leaves out) are counted per topic. A corrupted chunk is skipped (its messages
// are lost, the rest of the file is read) and a truncated file ends where its last complete
// record does: LogReplaySummary::incomplete() then says what was lost and how much was read, and
// callers report the run as failed unless the user accepted a partial replay.

#include <cstdint>
#include <functional>
#include <map>
#include <string>

#include "hanzo/fusion/core/time.hpp"
#include "hanzo/fusion/io/sensor_log.hpp"
#include "hanzo/fusion/pipeline/session.hpp"

namespace hanzo::fusion::pipeline {

struct LogReplaySummary {
  uint64_t messages = 0;   ///< pushed
  uint64_t rejected = 0;   ///< of those, refused by the input checks (Session::push errors)
  uint64_t unread = 0;     ///< records that did not decode
  std::map<std::string, uint64_t> unmapped_topics;  ///< sensor messages no configured sensor reads
  Timestamp first, last;   ///< log times of the first and last pushed message
  double push_seconds = 0.0;  ///< time spent in push() and flush() (this machine's clock)
  uint64_t records_read = 0;  ///< messages of every topic read from the file (decoded or not)
  uint64_t records_in_file = 0;  ///< the file's message count (its statistics)
  Timestamp file_start, file_end;  ///< the file's first and last message times (its statistics)
  Timestamp read_until;     ///< log time of the last message read, of any topic
  std::string first_unread_error;  ///< the first message that did not decode, and why
  uint64_t corrupted_chunks = 0;  ///< chunks skipped because they are corrupted
  std::string first_chunk_error;  ///< the first of them, and why
  std::string truncation;   ///< the reader's note when the file ends early ("" when complete)

  /// "" when the whole file was read and decoded; otherwise one line: what went wrong first and
  /// how much of the log was read, e.g. "1 corrupted chunk skipped (L.mcap: chunk at byte ...:
  /// CRC mismatch ...): read 32.1 s of 33.0 s of log (98100 of 99400 messages)".
  std::string incomplete() const;
};

/// `progress` (optional) is called with each pushed message's log time.
LogReplaySummary replay_log(Session& session, io::SensorLogReader& reader, const std::function<void(Timestamp)>& progress = {});

/// The Session's map as a replay's map file holds it: `map_id`, version 1, created at `created`
/// (the last pose's time: the same log gives the same file), the configuration file's text and
/// the log's SHA-256 as provenance, `software_version`; empty point and occupancy layers left
/// out (a camera-only run). Fails naming a configuration or log file that cannot be read.
Result<msgs::FusionMap> replayed_map(const Session& session, const std::string& map_id, Timestamp created, const std::string& config_path,
                                     const std::string& log_path, const std::string& software_version);

}  // namespace hanzo::fusion::pipeline
