// Visual-inertial odometry on real data: EuRoC V1_01's first 95 stereo frames
// (../shared/data/euroc_v101_micro), the MAV standing with its rotors running. The feature
// tracker and the MSCKF, started by static alignment on the first second of the IMU, must keep
// the position within 2 cm of OpenVINS's ground truth through the frames.

#include <cmath>
#include <fstream>
#include <string>
#include <vector>

#include <gtest/gtest.h>
#include <opencv2/imgcodecs.hpp>

#include "hanzo/fusion/estimate/static_alignment.hpp"
#include "hanzo/fusion/io/euroc_import.hpp"
#include "hanzo/fusion/vision/feature_tracker.hpp"
#include "hanzo/fusion/vision/msckf.hpp"
#include "support/euroc_micro.hpp"

namespace hanzo::fusion::vision {
namespace {

struct Frame {
  Timestamp timestamp;
  std::string left, right;
};

std::vector<Frame> read_frames(const std::string& mav) {
  std::vector<Frame> frames;
  std::ifstream list(mav + "/cam0/data.csv");
  std::string line;
  while (std::getline(list, line)) {
    if (line.empty() || line[0] == '#') continue;
    const std::string name = line.substr(line.find(',') + 1);
    frames.push_back({Timestamp::from_nanoseconds(std::stoll(line.substr(0, line.find(',')))), mav + "/cam0/data/" + name,
                      mav + "/cam1/data/" + name});
  }
  return frames;
}

TEST(MsckfEuroc, StandingMavStaysWithinTwoCentimetresOfOpenVins) {
  const std::string data = test_support::euroc_micro_dir();
  // The calibration (cameras to the body = IMU frame) from the cameras' sensor.yaml.
  const auto cam0 = io::read_euroc_camera_calibration(data + "/mav0/cam0/sensor.yaml", "cam0");
  const auto cam1 = io::read_euroc_camera_calibration(data + "/mav0/cam1/sensor.yaml", "cam1");
  ASSERT_TRUE(cam0 && cam1);
  const PinholeCamera left = cam0->camera->pinhole_camera(), right = cam1->camera->pinhole_camera();
  const SE3 T_body_left = cam0->T_body_sensor(), T_body_right = cam1->T_body_sensor();

  // Static alignment on the first second; the filter starts there.
  const std::vector<estimate::ImuSample> imu = test_support::read_euroc_imu(data + "/mav0/imu0/data.csv", 0.0, 6.0);
  const std::vector<estimate::ImuSample> still(imu.begin(), imu.begin() + 200);
  const auto aligned = estimate::align_static(still, estimate::ImuMounting{}, 0.0);
  ASSERT_TRUE(aligned) << aligned.error().message;
  estimate::NavigationState state;
  state.timestamp = still.back().timestamp;
  state.R_world_body = aligned->R_world_body;
  state.gyro_bias = aligned->gyro_bias;
  state.gravity = Eigen::Vector3d(0, 0, -aligned->gravity_magnitude);
  Eigen::Matrix<double, 15, 1> sigma;
  sigma << Eigen::Vector3d::Constant(1e-3), Eigen::Vector3d(0.01, 0.01, 1e-3), Eigen::Vector3d::Constant(0.01),
      Eigen::Vector3d::Constant(0.1), Eigen::Vector3d::Constant(0.005);
  MsckfConfig config;
  // EuRoC's sensor.yaml densities (gyro 1.7e-4 rad/s/sqrt(Hz), accel 2.0e-3 m/s^2/sqrt(Hz)) as
  // per-sample stds at 200 Hz, inflated 5x as OpenVINS does for the rotors' vibration.
  config.imu_noise.sample_interval = 0.005;
  config.imu_noise.process_noise_gyro = 5 * 1.6968e-4 * std::sqrt(200.0);
  config.imu_noise.process_noise_accel = 5 * 2.0e-3 * std::sqrt(200.0);
  config.imu_noise.gyro_bias_random_walk = 1.9393e-5;
  config.imu_noise.accel_bias_random_walk = 3.0e-3;
  Msckf filter = Msckf::create(config, {{T_body_left, left.fx}, {T_body_right, right.fx}}, state,
                               sigma.array().square().matrix().asDiagonal().toDenseMatrix())
                     .value();
  auto tracker = FeatureTracker::create_stereo(left, right, T_body_left.inverse() * T_body_right, cv::Size(752, 480));
  ASSERT_TRUE(tracker) << tracker.error().message;

  const std::vector<test_support::OpenVinsState> truth =
      test_support::read_openvins_ground_truth(data + "/groundtruth_openvins/V1_01_easy_ovcorrected.csv");
  auto truth_at = [&](Timestamp time) -> const test_support::OpenVinsState* {
    for (const auto& row : truth) {
      if (std::abs((row.timestamp - time).seconds()) < 1e-3) return &row;
    }
    return nullptr;
  };

  size_t next_sample = 200;
  std::optional<SE3> first_estimate, first_truth;
  double max_error = 0.0;
  int frames = 0, features_used = 0, stereo_matches = 0, zero_velocity_frames = 0;
  for (const Frame& frame : read_frames(data + "/mav0")) {
    if (frame.timestamp <= state.timestamp) continue;
    while (next_sample < imu.size() && imu[next_sample].timestamp <= filter.body_time(frame.timestamp)) ASSERT_TRUE(filter.propagate(imu[next_sample++]));
    const cv::Mat left_image = cv::imread(frame.left, cv::IMREAD_GRAYSCALE), right_image = cv::imread(frame.right, cv::IMREAD_GRAYSCALE);
    if (left_image.empty() || right_image.empty()) break;  // data.csv lists frames past the excerpt's 95
    const auto tracked = (*tracker)->track(left_image, right_image);
    ASSERT_TRUE(tracked) << tracked.error().message;
    stereo_matches += tracked->stereo_matches;
    const auto summary = filter.process_frame(frame.timestamp, tracked->observations);
    ASSERT_TRUE(summary) << summary.error().message;
    features_used += summary->features_used;
    zero_velocity_frames += summary->zero_velocity;
    ++frames;
    const test_support::OpenVinsState* reference = truth_at(frame.timestamp);
    ASSERT_NE(reference, nullptr);
    const SE3 estimate(filter.state().R_world_body, filter.state().position);
    if (!first_estimate) {
      first_estimate = estimate;
      first_truth = reference->T_world_imu;
    }
    // Displacements since the first frame, the estimate's rotated into OpenVINS's world.
    const Eigen::Vector3d moved_estimate = first_truth->rotation() * (first_estimate->rotation().inverse() * (estimate.translation() - first_estimate->translation()));
    const Eigen::Vector3d moved_truth = reference->T_world_imu.translation() - first_truth->translation();
    max_error = std::max(max_error, (moved_estimate - moved_truth).norm());
  }
  std::printf("EuRoC V1_01 standing: %d frames (%d zero-velocity updates), %.1f stereo matches and %.1f features used per frame, "
              "max position error %.4f m\n", frames, zero_velocity_frames, static_cast<double>(stereo_matches) / frames,
              static_cast<double>(features_used) / frames, max_error);
  EXPECT_GE(frames, 70);
  // The features stand still (KLT jitter well under 0.5 px): zero-velocity updates instead of clones.
  EXPECT_GT(stereo_matches, 50 * frames);
  EXPECT_GT(zero_velocity_frames, frames * 9 / 10);
  EXPECT_LT(max_error, 0.02);
}

}  // namespace
}  // namespace hanzo::fusion::vision
