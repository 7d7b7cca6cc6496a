// WheelSlipMonitor: wheels compared with the LiDAR odometry's forward travel over a window.

#include "hanzo/fusion/pipeline/wheel_slip_monitor.hpp"

#include <gtest/gtest.h>

#include "hanzo/fusion/pipeline/session.hpp"

namespace hanzo::fusion::pipeline {
namespace {

const Timestamp kStart = Timestamp::from_seconds(1700000000.0);

Timestamp at(double seconds) { return kStart + Duration::from_seconds(seconds); }

// A robot at 1 m/s: wheels at 50 Hz reading `wheel_scale` x the true distance between
// slip_start and slip_end (the true scale elsewhere), LiDAR sweeps at 10 Hz.
struct Drive {
  WheelSlipMonitor monitor;
  double wheel_distance = 0.0;
  std::vector<std::pair<double, bool>> slipping;  // (time, slipping) after each sweep

  void run(double duration, double slip_start, double slip_end, double wheel_scale, bool degenerate_during_slip = false) {
    for (int step = 0; step <= static_cast<int>(duration * 50); ++step) {
      const double t = step / 50.0;
      if (step > 0) wheel_distance += 0.02 * ((t > slip_start && t <= slip_end) ? wheel_scale : 1.0);
      monitor.add_wheels(at(t), wheel_distance);
      if (step % 5 == 0 && step > 0) {
        const bool in_slip = t > slip_start && t <= slip_end;
        monitor.add_lidar_motion(at(t - 0.1), at(t), 0.1, !(degenerate_during_slip && in_slip));
        slipping.emplace_back(t, monitor.slipping());
      }
    }
  }
  bool slipping_at(double t) const {
    for (const auto& [time, state] : slipping) {
      if (time >= t - 1e-9) return state;
    }
    return slipping.back().second;
  }
};

TEST(WheelSlipMonitor, AgreeingWheelsAreNeverFlagged) {
  Drive drive;
  drive.run(20.0, 5.0, 5.0, 1.0);
  for (const auto& [time, state] : drive.slipping) EXPECT_FALSE(state) << time;
  EXPECT_EQ(drive.monitor.episodes(), 0U);
  // A calibrated wheel 1 % off stays trusted (the tolerance is 5 % + 3 cm per window).
  Drive scaled;
  scaled.run(20.0, 0.0, 20.0, 1.01);
  EXPECT_EQ(scaled.monitor.episodes(), 0U);
}

TEST(WheelSlipMonitor, SlipIsFlaggedWithinAWindowAndClearedAfterTheRecoveryTime) {
  Drive drive;
  drive.run(20.0, 8.0, 12.0, 1.35);  // the warehouse scenario's left wheel: +17.5 % on the mean
  EXPECT_FALSE(drive.slipping_at(7.9));
  EXPECT_TRUE(drive.slipping_at(8.6));   // judged on the first window with enough slip in it
  EXPECT_TRUE(drive.slipping_at(11.9));
  EXPECT_TRUE(drive.slipping_at(12.9));  // the last disagreeing window ends ~12.4 s; 1 s of agreement needed
  EXPECT_FALSE(drive.slipping_at(14.0));
  EXPECT_EQ(drive.monitor.episodes(), 1U);
  EXPECT_GT(drive.monitor.last_difference(), -0.01);
}

TEST(WheelSlipMonitor, WindowsWithoutReliableLidarOrWheelDataAreNotJudged) {
  Drive degenerate;
  degenerate.run(20.0, 8.0, 12.0, 1.35, /*degenerate_during_slip=*/true);
  EXPECT_EQ(degenerate.monitor.episodes(), 0U);  // a corridor: the LiDAR cannot tell the distance

  WheelSlipMonitor no_wheels;
  for (int k = 1; k <= 50; ++k) no_wheels.add_lidar_motion(at(0.1 * (k - 1)), at(0.1 * k), 0.1, true);
  EXPECT_FALSE(no_wheels.slipping());
  EXPECT_EQ(no_wheels.episodes(), 0U);
}

TEST(WheelSlipMonitor, SessionRefusesSettingsThatCannotWork) {
  const config::FusionConfig config = config::load_fusion_config("examples/data/fusion.yaml").value();
  SessionConfig settings = SessionConfig::from(config);
  settings.wheel_slip.window_s = 0.0;
  const auto refused = Session::create(config, calib::Calibration{}, settings);
  ASSERT_FALSE(refused.ok());
  EXPECT_NE(refused.error().message.find("wheel_slip"), std::string::npos) << refused.error().message;
  EXPECT_TRUE(Session::create(config, calib::Calibration{}).ok());
}

}  // namespace
}  // namespace hanzo::fusion::pipeline
