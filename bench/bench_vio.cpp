// Visual-inertial odometry, one thread (cv::setNumThreads(1)):
//   - the MSCKF update with 11 clones and 100 features ending their tracks (each seen in all 11
//     clones: 1,900 rows after the null-space projection), with the clone it augments and the one
//     it marginalizes, the camera's extrinsics calibrated online;
//   - the KLT feature tracker on EuRoC V1_01 stereo pairs (752 x 480, 200 features) against the
//     same steps done with OpenCV alone (cv::goodFeaturesToTrack + cv::calcOpticalFlowPyrLK left
//     to right, no grid, no checks): the peer for the tracker's own bookkeeping and checks;
//   - the whole VIO step per stereo frame on EuRoC (tracking + propagation + update);
//   - the image-quality check per EuRoC image (dark / glare / motion blur) against the usual
//     blur check done with OpenCV alone (the variance of the Laplacian at full resolution);
//   - a visual place of the loop detector (ORB features, triangulation with its neighbours, the
//     bag-of-words query over 300 places and the candidates' PnP) against OpenCV's ORB
//     detectAndCompute alone on the same image (1000 features), the step it cannot skip.
// No VIO library is packaged for Debian (OpenVINS, VINS-Fusion, Kimera are not): the MSCKF has no
// peer on the machine; OpenVINS's and VINS-Fusion's published timings are in docs/vision.md.

#include <filesystem>
#include <random>
#include <string>
#include <vector>

#include <benchmark/benchmark.h>
#include <opencv2/core/utility.hpp>
#include <opencv2/features2d.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <opencv2/video/tracking.hpp>

#include "hanzo/fusion/io/euroc_import.hpp"
#include "hanzo/fusion/vision/feature_tracker.hpp"
#include "hanzo/fusion/vision/image_quality.hpp"
#include "hanzo/fusion/vision/msckf.hpp"
#include "hanzo/fusion/vision/visual_loop_detector.hpp"

namespace {

using namespace hanzo::fusion;
using namespace hanzo::fusion::vision;

// Body FLU, camera looking along the body's x axis.
SE3 forward_camera() {
  Eigen::Matrix3d R_body_camera;
  R_body_camera << 0, 0, 1, -1, 0, 0, 0, -1, 0;
  return SE3(SO3::from_matrix(R_body_camera), Eigen::Vector3d::Zero());
}

// A filter flying sideways at 1 m/s with 100 features seen in each of its 11 clones (20 Hz).
Msckf full_window() {
  estimate::NavigationState state;
  state.timestamp = Timestamp::from_seconds(100.0);
  state.velocity = Eigen::Vector3d(0.0, 1.0, 0.0);  // sideways: every feature gets parallax
  const Eigen::MatrixXd covariance = 1e-4 * Eigen::MatrixXd::Identity(15, 15);
  MsckfConfig config;
  config.calibrate_time_offset = false;  // the observations below are made at the frame times
  Msckf filter = Msckf::create(config, {{forward_camera(), 458.0}}, state, covariance).value();
  std::mt19937_64 random(3);
  std::uniform_real_distribution<double> lateral(-1.5, 1.5), depth(2.0, 5.0);
  std::vector<Eigen::Vector3d> points;
  for (int i = 0; i < 100; ++i) points.emplace_back(depth(random), lateral(random), 1.5 * lateral(random) / 2.0);
  const estimate::ImuSample level{state.timestamp, Eigen::Vector3d::Zero(), Eigen::Vector3d(0, 0, estimate::kStandardGravity)};
  for (int frame = 1; frame <= 11; ++frame) {
    const Timestamp time = state.timestamp + Duration::from_milliseconds(50 * frame);
    for (Timestamp t = filter.state().timestamp + Duration::from_milliseconds(5); t <= time; t += Duration::from_milliseconds(5)) {
      estimate::ImuSample sample = level;
      sample.timestamp = t;
      (void)filter.propagate(sample);
    }
    const SE3 T_camera_world = (SE3(filter.state().R_world_body, filter.state().position) * forward_camera()).inverse();
    std::vector<FeatureObservation> observations;
    for (size_t i = 0; i < points.size(); ++i) {
      const Eigen::Vector3d in_camera = T_camera_world * points[i];
      observations.push_back({i, 0, in_camera.head<2>() / in_camera.z()});
    }
    (void)filter.process_frame(time, observations).value();
  }
  return filter;
}

void BM_MsckfUpdate11Clones100Features(benchmark::State& state) {
  const Msckf prepared = full_window();
  const Timestamp next = prepared.clones().back().timestamp + Duration::from_milliseconds(50);
  MsckfUpdateSummary summary;
  for (auto _ : state) {
    state.PauseTiming();
    Msckf filter = prepared;
    state.ResumeTiming();
    summary = filter.process_frame(next, {}).value();
  }
  state.counters["features"] = summary.features_used;
  state.counters["rows"] = summary.residual_rows;
}
BENCHMARK(BM_MsckfUpdate11Clones100Features)->Unit(benchmark::kMillisecond);

struct EurocStereo {
  std::vector<cv::Mat> left, right;
  std::vector<Timestamp> times;
  PinholeCamera left_camera, right_camera;
  SE3 T_body_left, T_body_right;
};

const EurocStereo& euroc() {
  static const EurocStereo data = [] {
    EurocStereo out;
    const std::string mav = std::string(HANZO_DATA_DIR) + "/euroc_v101_micro/mav0";
    const auto cam0 = io::read_euroc_camera_calibration(mav + "/cam0/sensor.yaml", "cam0").value();
    const auto cam1 = io::read_euroc_camera_calibration(mav + "/cam1/sensor.yaml", "cam1").value();
    out.left_camera = cam0.camera->pinhole_camera();
    out.right_camera = cam1.camera->pinhole_camera();
    out.T_body_left = cam0.T_body_sensor();
    out.T_body_right = cam1.T_body_sensor();
    std::vector<std::string> names;
    for (const auto& entry : std::filesystem::directory_iterator(mav + "/cam0/data")) names.push_back(entry.path().filename().string());
    std::sort(names.begin(), names.end());
    for (const std::string& name : names) {
      cv::Mat right = cv::imread(mav + "/cam1/data/" + name, cv::IMREAD_GRAYSCALE);
      if (right.empty()) continue;
      out.left.push_back(cv::imread(mav + "/cam0/data/" + name, cv::IMREAD_GRAYSCALE));
      out.right.push_back(right);
      out.times.push_back(Timestamp::from_nanoseconds(std::stoll(name.substr(0, name.find('.')))));
    }
    return out;
  }();
  return data;
}

void BM_FeatureTrackerStereo_Hanzo(benchmark::State& state) {
  cv::setNumThreads(1);
  const EurocStereo& data = euroc();
  auto tracker = FeatureTracker::create_stereo(data.left_camera, data.right_camera, data.T_body_left.inverse() * data.T_body_right,
                                               data.left.front().size())
                     .value();
  size_t frame = 0;
  int matches = 0;
  for (auto _ : state) {
    matches = tracker->track(data.left[frame], data.right[frame]).value().stereo_matches;
    frame = (frame + 1) % data.left.size();
  }
  state.counters["stereo_matches"] = matches;
}
BENCHMARK(BM_FeatureTrackerStereo_Hanzo)->Unit(benchmark::kMillisecond);

void BM_ImageQuality_Hanzo(benchmark::State& state) {
  cv::setNumThreads(1);
  const EurocStereo& data = euroc();
  ImageQualityMonitor monitor = ImageQualityMonitor::create().value();
  size_t frame = 0;
  for (auto _ : state) {
    benchmark::DoNotOptimize(monitor.assess(data.left[frame]).value().sharpness);
    frame = (frame + 1) % data.left.size();
  }
}
BENCHMARK(BM_ImageQuality_Hanzo)->Unit(benchmark::kMillisecond);

void BM_ImageQuality_OpenCVLaplacianVariance(benchmark::State& state) {
  cv::setNumThreads(1);
  const EurocStereo& data = euroc();
  size_t frame = 0;
  for (auto _ : state) {
    cv::Mat laplacian;
    cv::Laplacian(data.left[frame], laplacian, CV_64F);
    cv::Scalar mean, deviation;
    cv::meanStdDev(laplacian, mean, deviation);
    benchmark::DoNotOptimize(deviation[0]);
    frame = (frame + 1) % data.left.size();
  }
}
BENCHMARK(BM_ImageQuality_OpenCVLaplacianVariance)->Unit(benchmark::kMillisecond);

void BM_FeatureTrackerStereo_OpenCV(benchmark::State& state) {
  cv::setNumThreads(1);
  const EurocStereo& data = euroc();
  const cv::Size window(21, 21);
  std::vector<cv::Point2f> points, moved, right;
  cv::Mat previous;
  size_t frame = 0;
  int matches = 0;
  for (auto _ : state) {
    std::vector<unsigned char> status;
    std::vector<float> error;
    if (!previous.empty() && !points.empty()) {
      cv::calcOpticalFlowPyrLK(previous, data.left[frame], points, moved, status, error, window, 3);
      std::vector<cv::Point2f> kept;
      for (size_t i = 0; i < moved.size(); ++i) {
        if (status[i]) kept.push_back(moved[i]);
      }
      points = kept;
    }
    if (points.size() < 200) {
      std::vector<cv::Point2f> corners;
      cv::goodFeaturesToTrack(data.left[frame], corners, static_cast<int>(200 - points.size()), 0.01, 20.0);
      points.insert(points.end(), corners.begin(), corners.end());
    }
    cv::calcOpticalFlowPyrLK(data.left[frame], data.right[frame], points, right, status, error, window, 3);
    matches = static_cast<int>(std::count(status.begin(), status.end(), 1));
    previous = data.left[frame];
    frame = (frame + 1) % data.left.size();
  }
  state.counters["stereo_matches"] = matches;
}
BENCHMARK(BM_FeatureTrackerStereo_OpenCV)->Unit(benchmark::kMillisecond);

// The whole step per stereo frame on EuRoC V1_01's first 95 frames: tracking, IMU propagation
// (10 samples) and the MSCKF update.
void BM_VioStepEurocStereo(benchmark::State& state) {
  cv::setNumThreads(1);
  const EurocStereo& data = euroc();
  int frames = 0;
  for (auto _ : state) {
    auto tracker = FeatureTracker::create_stereo(data.left_camera, data.right_camera, data.T_body_left.inverse() * data.T_body_right,
                                                 data.left.front().size())
                       .value();
    estimate::NavigationState start;
    start.timestamp = data.times.front() - Duration::from_milliseconds(5);
    start.R_world_body = SO3::exp(Eigen::Vector3d(0.0, -M_PI / 2, 0.0));  // EuRoC's IMU x axis points up
    Msckf filter = Msckf::create(MsckfConfig{}, {{data.T_body_left, data.left_camera.fx}, {data.T_body_right, data.right_camera.fx}}, start,
                                 1e-4 * Eigen::MatrixXd::Identity(15, 15))
                       .value();
    for (size_t i = 0; i < data.left.size(); ++i) {
      for (int k = 9; k >= 0; --k) {
        const estimate::ImuSample still{data.times[i] - Duration::from_milliseconds(5 * k), Eigen::Vector3d::Zero(),
                                        start.R_world_body.inverse() * Eigen::Vector3d(0, 0, estimate::kStandardGravity)};
        (void)filter.propagate(still);
      }
      const TrackedFrame tracked = tracker->track(data.left[i], data.right[i]).value();
      benchmark::DoNotOptimize(filter.process_frame(data.times[i], tracked.observations));
    }
    frames = static_cast<int>(data.left.size());
  }
  state.SetItemsProcessed(state.iterations() * frames);
  state.counters["ms_per_frame"] = benchmark::Counter(static_cast<double>(state.iterations() * frames), benchmark::Counter::kIsRate | benchmark::Counter::kInvert);
}
BENCHMARK(BM_VioStepEurocStereo)->Unit(benchmark::kMillisecond)->Iterations(3);

// Places 1 m apart along the camera's x axis, EuRoC's images in turn (the MAV stands still in
// them: few points survive triangulation, so candidates are queried and mostly refused).
void BM_VisualLoopDetectorPlace_Hanzo(benchmark::State& state) {
  cv::setNumThreads(1);
  const EurocStereo& data = euroc();
  VisualLoopDetector detector = VisualLoopDetector::create(data.left_camera).value();
  int place = 0;
  const auto add = [&] {
    const SE3 pose(SO3(), Eigen::Vector3d(place, 0.0, 0.0));
    benchmark::DoNotOptimize(detector.add(data.left[static_cast<size_t>(place) % data.left.size()], pose).value());
    ++place;
  };
  while (place < 300) add();
  for (auto _ : state) add();
  state.counters["candidates_per_place"] = static_cast<double>(detector.candidates_checked()) / place;
}
BENCHMARK(BM_VisualLoopDetectorPlace_Hanzo)->Unit(benchmark::kMillisecond);

void BM_VisualLoopDetectorPlace_OpenCVOrb(benchmark::State& state) {
  cv::setNumThreads(1);
  const EurocStereo& data = euroc();
  cv::Ptr<cv::ORB> orb = cv::ORB::create(1000);
  size_t frame = 0;
  for (auto _ : state) {
    std::vector<cv::KeyPoint> keypoints;
    cv::Mat descriptors;
    orb->detectAndCompute(data.left[frame], cv::noArray(), keypoints, descriptors);
    benchmark::DoNotOptimize(descriptors.data);
    frame = (frame + 1) % data.left.size();
  }
}
BENCHMARK(BM_VisualLoopDetectorPlace_OpenCVOrb)->Unit(benchmark::kMillisecond);

}  // namespace

BENCHMARK_MAIN();
