#pragma once
// Replaying a sensor log through a Session: what `hanzo-fusion run` and Python's
// Session.replay() do. Every sensor message whose topic a configured sensor reads is pushed in
// log order (rejections are counted, the replay goes on), then the Session is flushed.
// Messages that do not decode are counted and skipped; other topics (ground truth, sensors the
// configuration leaves out) are counted per topic.

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
};

/// `progress` (optional) is called with each pushed message's log time.
LogReplaySummary replay_log(Session& session, io::SensorLogReader& reader, const std::function<void(Timestamp)>& progress = {});

}  // namespace hanzo::fusion::pipeline
