// The camera renderer: checkerboard corners projected with OpenCV's own camera models land on
// the rendered corners (sub-pixel), for radtan and equidistant lenses; the faults change the
// image as they should; rendering is deterministic.

#include <cmath>
#include <cstring>

#include <gtest/gtest.h>
#include <opencv2/calib3d.hpp>
#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>

#include "hanzo/fusion/msgs/validate.hpp"
#include "hanzo/fusion/sim/camera_simulator.hpp"

namespace hanzo::fusion::sim {
namespace {

const Timestamp kStart = Timestamp::from_nanoseconds(1'700'000'000'000'000'000);
constexpr double kSquare = 0.25;  // metres
constexpr double kCameraHeight = 1.5;

// A checkerboard wall whose face is the plane x = 5 (|y| < 3, 0 < z < 3): its corners are at
// (5, -3 + i * kSquare, j * kSquare).
World checker_world() {
  WorldDescription description;
  Box wall;
  wall.center = {5.5, 0.0, 1.5};
  wall.half_size = {0.5, 3.0, 1.5};
  wall.material.texture.type = TextureType::kChecker;
  wall.material.texture.scale = kSquare;
  wall.material.texture.color_a = Eigen::Vector3f::Constant(1.0F);
  wall.material.texture.color_b = Eigen::Vector3f::Constant(0.05F);
  description.boxes.push_back(wall);
  return World(description);
}

// Standing still, or moving sideways at `speed` m/s, at kCameraHeight, for 5.5 s.
SplineTrajectory trajectory(double speed = 0.0) {
  std::vector<SE3> poses;
  for (int i = 0; i < 14; ++i) poses.emplace_back(SO3(), Eigen::Vector3d(0.0, speed * 0.5 * (i - 1), kCameraHeight));
  return *SplineTrajectory::create(kStart, Duration::from_milliseconds(500), poses);
}

// Optical frame (x right, y down, z forward) looking along the body x axis.
SE3 forward_camera() {
  Eigen::Matrix3d R_body_camera;
  R_body_camera << 0, 0, 1, -1, 0, 0, 0, -1, 0;
  return SE3(SO3::from_matrix(R_body_camera), Eigen::Vector3d::Zero());
}

cv::Mat as_mat(const msgs::ImageMessage& image) {
  return cv::Mat(static_cast<int>(image.height), static_cast<int>(image.width), CV_8UC1, const_cast<uint8_t*>(image.data.data()))
      .clone();
}

struct CornerErrors {
  int count = 0;
  double mean = 0.0;
  double max = 0.0;
};

// Projects every board corner with OpenCV, refines it in the rendered image from a guess 0.6 px
// away, and measures how far the refined corner is from the projection.
CornerErrors corner_errors(const CameraSimulatorConfig& config) {
  const World world = checker_world();
  const SplineTrajectory still = trajectory();
  Result<CameraSimulator> camera = CameraSimulator::create(config, world, still);
  EXPECT_TRUE(camera);
  const msgs::ImageMessage image = camera->measure(kStart + Duration::from_seconds(1.0));
  EXPECT_TRUE(msgs::validate(image));
  const cv::Mat gray = as_mat(image);

  std::vector<cv::Point3d> corners_camera;  // board corners in the camera frame
  for (int i = 1; i < 24; ++i) {
    for (int j = 1; j < 12; ++j) {
      const Eigen::Vector3d world_point(5.0, -3.0 + i * kSquare, j * kSquare);
      const Eigen::Vector3d p = config.T_body_camera.inverse() * (world_point - Eigen::Vector3d(0.0, 0.0, kCameraHeight));
      corners_camera.emplace_back(p.x(), p.y(), p.z());
    }
  }
  const msgs::CameraIntrinsics& k = config.intrinsics;
  const cv::Matx33d camera_matrix(k.fx, 0, k.cx, 0, k.fy, k.cy, 0, 0, 1);
  std::vector<cv::Point2d> projected;
  if (config.distortion.type == msgs::DistortionType::kEquidistant) {
    cv::fisheye::projectPoints(corners_camera, projected, cv::Vec3d::all(0), cv::Vec3d::all(0), camera_matrix,
                               config.distortion.coefficients);
  } else {
    cv::projectPoints(corners_camera, cv::Vec3d::all(0), cv::Vec3d::all(0), camera_matrix, config.distortion.coefficients,
                      projected);
  }
  std::vector<cv::Point2f> refined;
  std::vector<cv::Point2d> expected;
  for (const cv::Point2d& point : projected) {
    if (point.x < 15 || point.y < 15 || point.x > k.width - 16.0 || point.y > k.height - 16.0) continue;
    refined.emplace_back(static_cast<float>(point.x + 0.6), static_cast<float>(point.y - 0.6));
    expected.push_back(point);
  }
  cv::cornerSubPix(gray, refined, cv::Size(5, 5), cv::Size(-1, -1),
                   cv::TermCriteria(cv::TermCriteria::EPS + cv::TermCriteria::COUNT, 100, 1e-4));
  CornerErrors errors;
  for (std::size_t i = 0; i < refined.size(); ++i) {
    const double error = std::hypot(refined[i].x - expected[i].x, refined[i].y - expected[i].y);
    errors.mean += error;
    errors.max = std::max(errors.max, error);
    ++errors.count;
  }
  if (errors.count > 0) errors.mean /= errors.count;
  return errors;
}

CameraSimulatorConfig clean_config() {
  CameraSimulatorConfig config;
  config.T_body_camera = forward_camera();
  config.pixel_noise = 0.0;
  config.supersampling = 4;
  return config;
}

TEST(CameraSimulator, CheckerCornersLandWhereOpenCvProjectsThemWithRadtanDistortion) {
  CameraSimulatorConfig config = clean_config();
  config.intrinsics = {458.654, 457.296, 367.215, 248.375, 752, 480};  // EuRoC cam0
  config.distortion = {msgs::DistortionType::kRadtan, {-0.28340811, 0.07395907, 0.00019359, 1.76187114e-05}};
  const CornerErrors errors = corner_errors(config);
  EXPECT_GT(errors.count, 80);
  // cornerSubPix itself is biased a little by the strongly curved edges of this lens.
  EXPECT_LT(errors.mean, 0.15);
  EXPECT_LT(errors.max, 0.4);
}

TEST(CameraSimulator, CheckerCornersLandWhereOpenCvProjectsThemWithEquidistantDistortion) {
  CameraSimulatorConfig config = clean_config();
  config.intrinsics = {280.0, 280.0, 319.5, 239.5, 640, 480};
  config.distortion = {msgs::DistortionType::kEquidistant, {0.0034823894, 0.000715034, -0.0020532361, 0.0002029532}};
  const CornerErrors errors = corner_errors(config);
  EXPECT_GT(errors.count, 80);
  EXPECT_LT(errors.mean, 0.1);
  EXPECT_LT(errors.max, 0.3);
}

TEST(CameraSimulator, PixelRaysProjectBackOntoTheirPixelsWithOpenCv) {
  const World world = checker_world();
  const SplineTrajectory still = trajectory();
  for (const msgs::DistortionModel& distortion :
       {msgs::DistortionModel{msgs::DistortionType::kRadtan, {-0.28340811, 0.07395907, 0.00019359, 1.76187114e-05, 0.01}},
        msgs::DistortionModel{msgs::DistortionType::kEquidistant, {0.0034823894, 0.000715034, -0.0020532361, 0.0002029532}}}) {
    CameraSimulatorConfig config;
    config.intrinsics = {458.654, 457.296, 367.215, 248.375, 752, 480};
    config.distortion = distortion;
    const CameraSimulator camera = *CameraSimulator::create(config, world, still);
    std::vector<cv::Point3d> rays;
    std::vector<cv::Point2d> pixels;
    for (double u = 0.0; u < 752.0; u += 37.3) {
      for (double v = 0.0; v < 480.0; v += 29.1) {
        const Eigen::Vector3d ray = camera.pixel_ray(u, v);
        rays.emplace_back(ray.x(), ray.y(), ray.z());
        pixels.emplace_back(u, v);
      }
    }
    const cv::Matx33d K(458.654, 0, 367.215, 0, 457.296, 248.375, 0, 0, 1);
    std::vector<cv::Point2d> projected;
    if (distortion.type == msgs::DistortionType::kEquidistant) {
      cv::fisheye::projectPoints(rays, projected, cv::Vec3d::all(0), cv::Vec3d::all(0), K, distortion.coefficients);
    } else {
      cv::projectPoints(rays, cv::Vec3d::all(0), cv::Vec3d::all(0), K, distortion.coefficients, projected);
    }
    for (std::size_t i = 0; i < pixels.size(); ++i) {
      ASSERT_LT(cv::norm(projected[i] - pixels[i]), 1e-6) << msgs::to_string(distortion.type) << " " << pixels[i];
    }
  }
}

TEST(CameraSimulator, PinholeWithoutSupersamplingIsStillSubPixel) {
  CameraSimulatorConfig config = clean_config();
  config.supersampling = 1;
  const CornerErrors errors = corner_errors(config);
  EXPECT_GT(errors.count, 80);
  EXPECT_LT(errors.mean, 0.25);
}

double mean_intensity(const msgs::ImageMessage& image) {
  double sum = 0.0;
  for (uint8_t value : image.data) sum += value;
  return sum / static_cast<double>(image.data.size());
}

double sharpness(const msgs::ImageMessage& image) {
  cv::Mat laplacian;
  cv::Laplacian(as_mat(image), laplacian, CV_64F);
  cv::Scalar mean, std_dev;
  cv::meanStdDev(laplacian, mean, std_dev);
  return std_dev[0] * std_dev[0];
}

TEST(CameraSimulator, DarknessGlareAndMotionBlur) {
  const World world = checker_world();
  const SplineTrajectory moving = trajectory(0.5);
  CameraSimulatorConfig config;
  config.T_body_camera = forward_camera();
  config.encoding = msgs::ImageEncoding::kRgb8;
  config.faults.push_back({CameraFaultType::kDarkness, kStart + Duration::from_seconds(1.0), kStart + Duration::from_seconds(2.0)});
  CameraFaultEpisode glare;
  glare.type = CameraFaultType::kGlare;
  glare.start = kStart + Duration::from_seconds(2.0);
  glare.end = kStart + Duration::from_seconds(2.5);
  glare.center = {100.0, 100.0};
  config.faults.push_back(glare);
  CameraFaultEpisode blur;
  blur.type = CameraFaultType::kMotionBlur;
  blur.start = kStart + Duration::from_seconds(3.0);
  blur.end = kStart + Duration::from_seconds(4.0);
  blur.exposure_time = 0.2;  // 10 cm of motion: 8 px at 5 m with f = 400
  config.faults.push_back(blur);
  CameraSimulator camera = *CameraSimulator::create(config, world, moving);
  const msgs::ImageMessage normal = camera.measure(kStart + Duration::from_seconds(0.5));
  const msgs::ImageMessage dark = camera.measure(kStart + Duration::from_seconds(1.5));
  const msgs::ImageMessage glaring = camera.measure(kStart + Duration::from_seconds(2.2));
  const msgs::ImageMessage sharp = camera.measure(kStart + Duration::from_seconds(2.8));
  const msgs::ImageMessage blurred = camera.measure(kStart + Duration::from_seconds(3.5));
  ASSERT_TRUE(msgs::validate(normal));
  EXPECT_EQ(normal.data.size(), 640U * 480U * 3U);
  EXPECT_LT(mean_intensity(dark), 0.15 * mean_intensity(normal));
  const std::size_t glare_centre = (100 * 640 + 100) * 3;
  EXPECT_EQ(glaring.data[glare_centre], 255);
  EXPECT_LT(normal.data[glare_centre], 255);
  EXPECT_GT(mean_intensity(glaring), mean_intensity(normal));
  auto gray = [](const msgs::ImageMessage& rgb) {
    msgs::ImageMessage mono = rgb;
    mono.encoding = msgs::ImageEncoding::kMono8;
    mono.data.resize(rgb.data.size() / 3);
    for (std::size_t p = 0; p < mono.data.size(); ++p) mono.data[p] = rgb.data[3 * p + 1];
    return mono;
  };
  EXPECT_LT(sharpness(gray(blurred)), 0.7 * sharpness(gray(sharp)));

  // Deterministic: a second simulator with the same seed renders the same bytes.
  CameraSimulator again = *CameraSimulator::create(config, world, moving);
  EXPECT_EQ(again.measure(kStart + Duration::from_seconds(0.5)).data, normal.data);
}

// A depth camera facing a wall 5 m ahead: every pixel on the wall reads its z-depth (5 m; in
// millimetres for depth16, metres for depth32f), the sky nothing, noise as configured, and a
// range that ends before the wall leaves it out.
TEST(CameraSimulator, DepthImagesHoldEachPixelsZDepth) {
  WorldDescription description;
  description.has_ground = false;
  Box wall;
  wall.center = {5.5, 0.0, 1.5};
  wall.half_size = {0.5, 3.0, 1.5};
  description.boxes.push_back(wall);
  const World world(description);
  const SplineTrajectory still = trajectory();
  CameraSimulatorConfig config;
  config.T_body_camera = forward_camera();
  config.depth_noise = 0.0;
  for (const msgs::ImageEncoding encoding : {msgs::ImageEncoding::kDepth16, msgs::ImageEncoding::kDepth32f}) {
    config.encoding = encoding;
    Result<CameraSimulator> camera = CameraSimulator::create(config, world, still);
    ASSERT_TRUE(camera) << camera.error().message;
    const msgs::ImageMessage image = camera->measure(kStart + Duration::from_seconds(1.0));
    ASSERT_TRUE(msgs::validate(image));
    ASSERT_EQ(image.encoding, encoding);
    int on_wall = 0, empty = 0;
    for (uint32_t row = 0; row < image.height; ++row) {
      for (uint32_t column = 0; column < image.width; ++column) {
        const std::size_t p = std::size_t{row} * image.width + column;
        double depth = 0.0;
        if (encoding == msgs::ImageEncoding::kDepth16) {
          uint16_t millimetres = 0;
          std::memcpy(&millimetres, &image.data[2 * p], 2);
          depth = millimetres * 1e-3;
        } else {
          float metres = 0.0F;
          std::memcpy(&metres, &image.data[4 * p], 4);
          depth = std::isfinite(metres) ? metres : 0.0;
        }
        if (depth == 0.0) {
          ++empty;
          continue;
        }
        EXPECT_NEAR(depth, 5.0, encoding == msgs::ImageEncoding::kDepth16 ? 0.0006 : 1e-4) << row << ", " << column;
        ++on_wall;
      }
    }
    EXPECT_GT(on_wall, 100000);  // the wall, 3 m high and 6 m wide
    EXPECT_GT(empty, 10000);     // the sky around it
  }
  config.encoding = msgs::ImageEncoding::kDepth32f;
  config.depth_noise = 0.0014;
  Result<CameraSimulator> noisy = CameraSimulator::create(config, world, still);
  const msgs::ImageMessage image = noisy->measure(kStart + Duration::from_seconds(1.0));
  const float* depth = reinterpret_cast<const float*>(image.data.data());
  double sum = 0.0, squares = 0.0;
  int count = 0;
  for (std::size_t p = 0; p < std::size_t{image.width} * image.height; ++p) {
    if (!std::isfinite(depth[p])) continue;
    sum += depth[p] - 5.0;
    squares += (depth[p] - 5.0) * (depth[p] - 5.0);
    ++count;
  }
  EXPECT_NEAR(sum / count, 0.0, 0.002);
  EXPECT_NEAR(std::sqrt(squares / count), 0.0014 * 25.0, 0.004);
  config.depth_range = {0.3, 4.0};
  const msgs::ImageMessage out_of_range = CameraSimulator::create(config, world, still)->measure(kStart + Duration::from_seconds(1.0));
  const float* beyond = reinterpret_cast<const float*>(out_of_range.data.data());
  EXPECT_TRUE(std::none_of(beyond, beyond + std::size_t{out_of_range.width} * out_of_range.height, [](float d) { return std::isfinite(d); }));
}

TEST(CameraSimulator, RejectsBadConfigurations) {
  const World world = checker_world();
  const SplineTrajectory still = trajectory();
  CameraSimulatorConfig config;
  config.distortion = {msgs::DistortionType::kRadtan, {0.1, 0.2}};
  Result<CameraSimulator> bad = CameraSimulator::create(config, world, still);
  ASSERT_FALSE(bad);
  EXPECT_NE(bad.error().message.find("coefficients"), std::string::npos);
  config = CameraSimulatorConfig{};
  config.encoding = msgs::ImageEncoding::kBgr8;
  EXPECT_FALSE(CameraSimulator::create(config, world, still));
  config.encoding = msgs::ImageEncoding::kDepth16;
  config.depth_range = {2.0, 1.0};
  EXPECT_FALSE(CameraSimulator::create(config, world, still));
  config = CameraSimulatorConfig{};
  config.intrinsics.width = 0;
  EXPECT_FALSE(CameraSimulator::create(config, world, still));
}

}  // namespace
}  // namespace hanzo::fusion::sim
