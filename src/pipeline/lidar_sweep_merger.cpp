#include "hanzo/fusion/pipeline/lidar_sweep_merger.hpp"

#include <algorithm>

#include <fmt/format.h>

namespace hanzo::fusion::pipeline {
namespace {

// Sweeps buffered per secondary: 2 s at 10 Hz. More means the primary stopped (nothing merges
// then); the oldest go as late.
constexpr std::size_t kMaxBufferedSweeps = 20;

}  // namespace

Status LidarSweepMergerConfig::validate() const {
  if (!(min_range >= 0) || !(max_range > min_range)) return Error(fmt::format("min_range {} / max_range {}: need 0 <= min < max", min_range, max_range));
  if (!(start_tolerance_s >= 0) || !(untimed_window_s >= 0) || !(wait_s >= 0) || !(silent_after_s > 0)) {
    return Error("start_tolerance_s, untimed_window_s and wait_s must be >= 0, silent_after_s > 0");
  }
  return ok_status();
}

LidarSweepMerger::LidarSweepMerger(std::vector<Secondary> secondaries, LidarSweepMergerConfig config)
    : secondaries_(std::move(secondaries)), config_(config), buffers_(secondaries_.size()) {}

Status LidarSweepMerger::add(std::size_t index, const msgs::PointCloudMessage& sweep) {
  if (index >= secondaries_.size()) return Error(fmt::format("LiDAR sweep merger: no secondary LiDAR {} (have {})", index, secondaries_.size()));
  Result<cloud::PointCloud> converted = cloud::from_message(sweep);
  if (!converted) return Error(fmt::format("{}: {}", secondaries_[index].sensor, converted.error().message));
  Buffer& buffer = buffers_[index];
  ++buffer.statistics.sweeps;
  cloud::PointCloud points = cloud::crop_range(*converted, config_.min_range, config_.max_range);
  cloud::transform_in_place(points, secondaries_[index].T_primary_secondary);
  if (points.has_rings()) buffer.ring_count = std::max<uint16_t>(buffer.ring_count, *std::max_element(points.rings.begin(), points.rings.end()) + 1);
  const double length = points.has_times() ? std::max(0.0F, *std::max_element(points.times.begin(), points.times.end())) : 0.0;
  const Timestamp end = sweep.timestamp + Duration::from_seconds(length);
  if (!buffer.latest_end || end > *buffer.latest_end) buffer.latest_end = end;
  if (points.empty()) {
    ++buffer.statistics.late_sweeps;  // nothing in range: nothing any primary sweep could take
    return ok_status();
  }
  buffer.sweeps.push_back({sweep.timestamp, std::move(points), false});
  while (buffer.sweeps.size() > kMaxBufferedSweeps) {
    const Sweep& oldest = buffer.sweeps.front();
    buffer.statistics.late_points += oldest.cloud.size();
    ++(oldest.took_points ? buffer.statistics.merged_sweeps : buffer.statistics.late_sweeps);
    buffer.sweeps.pop_front();
  }
  return ok_status();
}

bool LidarSweepMerger::ready(Timestamp primary_end, Timestamp now) const {
  for (const Buffer& buffer : buffers_) {
    if (!buffer.latest_end || *buffer.latest_end >= primary_end) continue;        // never heard, or there
    if ((primary_end - *buffer.latest_end).seconds() > config_.silent_after_s) continue;  // stopped
    if ((now - primary_end).seconds() > config_.wait_s) continue;                 // waited long enough
    return false;
  }
  return true;
}

std::size_t LidarSweepMerger::merge(cloud::PointCloud& primary, Timestamp primary_start) {
  const bool timed = primary.has_times();
  const float length = timed ? std::max(0.0F, *std::max_element(primary.times.begin(), primary.times.end())) : 0.0F;
  const Timestamp upper = primary_start + Duration::from_seconds(length);
  const Timestamp lower = primary_start - Duration::from_seconds(timed ? config_.start_tolerance_s : config_.untimed_window_s);
  uint32_t ring_offset = primary.has_rings() ? *std::max_element(primary.rings.begin(), primary.rings.end()) + 1U : 0U;
  const std::size_t before = primary.size();
  for (Buffer& buffer : buffers_) {
    for (auto sweep = buffer.sweeps.begin(); sweep != buffer.sweeps.end();) {
      const cloud::PointCloud& points = sweep->cloud;
      std::vector<uint32_t> kept;
      bool took = false;
      for (std::size_t i = 0; i < points.size(); ++i) {
        const Timestamp time = points.has_times() ? sweep->start + Duration::from_seconds(points.times[i]) : sweep->start;
        if (time > upper) {
          kept.push_back(static_cast<uint32_t>(i));
          continue;
        }
        if (time < lower) {
          ++buffer.statistics.late_points;
          continue;
        }
        took = true;
        ++buffer.statistics.merged_points;
        primary.positions.push_back(points.positions[i]);
        if (timed) primary.times.push_back(std::clamp(static_cast<float>((time - primary_start).seconds()), 0.0F, length));
        if (primary.has_rings()) primary.rings.push_back(static_cast<uint16_t>(ring_offset + (points.has_rings() ? points.rings[i] : 0U)));
        if (primary.has_intensities()) primary.intensities.push_back(points.has_intensities() ? points.intensities[i] : 0.0F);
      }
      sweep->took_points = sweep->took_points || took;
      if (!kept.empty()) {
        if (kept.size() < points.size()) sweep->cloud = cloud::select(points, kept);
        ++sweep;
        continue;
      }
      ++(sweep->took_points ? buffer.statistics.merged_sweeps : buffer.statistics.late_sweeps);
      sweep = buffer.sweeps.erase(sweep);
    }
    ring_offset += buffer.ring_count;
  }
  return primary.size() - before;
}

}  // namespace hanzo::fusion::pipeline
