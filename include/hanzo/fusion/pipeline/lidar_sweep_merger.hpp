#pragma once
// LidarSweepMerger: the sweeps of a session's other 3D LiDARs joined to its first LiDAR's (the
// primary's), so that one registration sees every LiDAR's points: a rig of two LiDARs facing
// front and back, or one on each corner, registers as one sensor with their joint view.
//
// Frames and clocks: a secondary sweep comes in the body clock (its calibrated time offset
// applied) and in its own frame. It is cropped to [min_range, max_range] there (returns off its
// own mount go before the move) and moved into the primary LiDAR's frame by the calibration,
// T_primary_secondary = T_body_primary^-1 T_body_secondary. Both LiDARs are rigid on the body,
// so a point moved this way stays where the primary would have seen it at the point's own time,
// and the odometry's deskewing (which uses each point's time) moves it like the primary's own.
//
// Which points join which primary sweep (start t, point times up to L, so ending at t + L):
//  - a primary sweep with point times takes the secondary points timed in
//    [t - start_tolerance_s, t + L], their times made relative to t (clamped to [0, L]);
//  - one without point times (nothing to deskew) takes the secondary points timed in
//    [t - untimed_window_s, t], without times.
// Points are taken once. Points older than a primary sweep's window are dropped: a sweep whose
// points all went that way counts as late (its LiDAR runs behind the primary by more than the
// session waits). A secondary without point times has all its points at its sweep's time.
// Rings are renumbered after the primary's, each LiDAR's apart (the odometry's range image, and
// so its phantom filter, keeps them on rings of their own); intensities are kept where the
// primary has them (0 for a secondary without).
//
// Waiting: the primary sweep ending at t + L is ready() once every secondary has delivered a
// sweep reaching t + L, or has been silent since silent_after_s before it (a LiDAR that stopped
// is not waited for), or the IMU ran wait_s past t + L.
//
// Use from one thread.

#include <cstddef>
#include <cstdint>
#include <deque>
#include <optional>
#include <string>
#include <vector>

#include "hanzo/fusion/cloud/point_cloud.hpp"
#include "hanzo/fusion/core/result.hpp"
#include "hanzo/fusion/core/se3.hpp"
#include "hanzo/fusion/core/time.hpp"
#include "hanzo/fusion/msgs/sensor_messages.hpp"

namespace hanzo::fusion::pipeline {

struct LidarSweepMergerConfig {
  double min_range = 1.0;            ///< m, in each secondary's own frame (the odometry's min_range)
  double max_range = 100.0;          ///< m
  double start_tolerance_s = 0.005;  ///< s: secondary points this much before a timed primary sweep still join it
  double untimed_window_s = 0.2;     ///< s: the secondary points an untimed primary sweep takes, back from its time
  double wait_s = 0.2;               ///< s of IMU time past a primary sweep's end spent waiting for the secondaries
  double silent_after_s = 1.0;       ///< s: a secondary with nothing this close to the sweep's end is not waited for

  Status validate() const;
};

/// One secondary LiDAR's counts.
struct LidarSweepMergerStatistics {
  uint64_t sweeps = 0;         ///< sweeps added
  uint64_t merged_sweeps = 0;  ///< sweeps whose points all went into primary sweeps (some may have been late)
  uint64_t late_sweeps = 0;    ///< sweeps whose points were all too old for any primary sweep
  uint64_t merged_points = 0;
  uint64_t late_points = 0;
};

class LidarSweepMerger {
 public:
  struct Secondary {
    std::string sensor;
    SE3 T_primary_secondary;
  };
  LidarSweepMerger(std::vector<Secondary> secondaries, LidarSweepMergerConfig config = {});

  /// Buffers a sweep of secondary `index` (times in the body clock). Fails, keeping nothing, on
  /// an index out of range or a message that is not a valid point cloud.
  Status add(std::size_t index, const msgs::PointCloudMessage& sweep);
  /// Whether the primary sweep ending at `primary_end` may be merged now that the IMU (the
  /// Frontend's newest pose) is at `now` (see the header comment).
  bool ready(Timestamp primary_end, Timestamp now) const;
  /// Appends the secondary points of the primary sweep that starts at `primary_start` to
  /// `primary` (its cloud in the primary LiDAR's frame, point times relative to primary_start).
  /// Returns the number of points appended.
  std::size_t merge(cloud::PointCloud& primary, Timestamp primary_start);

  std::size_t size() const { return secondaries_.size(); }
  const Secondary& secondary(std::size_t index) const { return secondaries_[index]; }
  const LidarSweepMergerStatistics& statistics(std::size_t index) const { return buffers_[index].statistics; }

 private:
  struct Sweep {
    Timestamp start;
    cloud::PointCloud cloud;   // primary frame; times relative to start (empty: all at start)
    bool took_points = false;  // some of its points joined a primary sweep
  };
  struct Buffer {
    std::deque<Sweep> sweeps;
    std::optional<Timestamp> latest_end;  // of the sweeps added
    uint16_t ring_count = 1;              // rings seen so far (max ring + 1)
    LidarSweepMergerStatistics statistics;
  };

  std::vector<Secondary> secondaries_;
  LidarSweepMergerConfig config_;
  std::vector<Buffer> buffers_;
};

}  // namespace hanzo::fusion::pipeline
