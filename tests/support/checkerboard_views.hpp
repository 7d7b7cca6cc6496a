#pragma once
// Views of a checkerboard rendered by the simulator through a given lens (calibration tests):
// a 9 x 7 square board (8 x 6 inner corners, 8 cm squares) 1.2 m up, in front of a light wall.

#include <cmath>
#include <random>
#include <vector>

#include <gtest/gtest.h>

#include "hanzo/fusion/sim/camera_simulator.hpp"

namespace hanzo::fusion::test_support {

inline const Timestamp kBoardViewsStart = Timestamp::from_nanoseconds(1'700'000'000'000'000'000);
inline constexpr double kSquare = 0.08;  // m
inline constexpr int kCornersX = 8, kCornersY = 6;
inline const Eigen::Vector3d kBoardCenter(0.0, 0.0, 1.2);

// A 9 x 7 square board whose face is the plane x = 0, in front of a light wall.
inline sim::World board_world() {
  sim::WorldDescription description;
  description.has_ground = false;
  sim::Box board;
  const double width = (kCornersX + 1) * kSquare, height = (kCornersY + 1) * kSquare;
  board.center = kBoardCenter + Eigen::Vector3d(0.005, 0.0, 0.0);
  board.half_size = {0.005, width / 2, height / 2};
  board.material.texture.type = sim::TextureType::kChecker;
  board.material.texture.scale = kSquare;
  board.material.texture.color_a = Eigen::Vector3f::Constant(0.05F);
  board.material.texture.color_b = Eigen::Vector3f::Constant(1.0F);
  description.boxes.push_back(board);
  sim::Box wall;
  wall.center = {1.0, 0.0, 1.5};
  wall.half_size = {0.2, 6.0, 4.0};
  wall.material.texture.type = sim::TextureType::kUniform;
  wall.material.texture.color_a = Eigen::Vector3f::Constant(0.85F);
  description.boxes.push_back(wall);
  return sim::World(description);
}

// Optical frame (x right, y down, z forward) looking along the body x axis.
inline SE3 forward_camera() {
  Eigen::Matrix3d R_body_camera;
  R_body_camera << 0, 0, 1, -1, 0, 0, 0, -1, 0;
  return SE3(SO3::from_matrix(R_body_camera), Eigen::Vector3d::Zero());
}

// `count` views from 0.75-1.05 m, looking at points up to `aim` (m, horizontal and vertical)
// from the board's centre (so that the board falls on different parts of the image), rolled
// up to 25 deg.
inline std::vector<msgs::ImageMessage> render_views(const sim::CameraSimulatorConfig& config, int count, const Eigen::Vector2d& aim) {
  const sim::World world = board_world();
  std::mt19937 random(7);
  std::uniform_real_distribution<double> unit(-1.0, 1.0);
  std::vector<msgs::ImageMessage> images;
  for (int v = 0; v < count; ++v) {
    const double distance = 0.9 + 0.15 * unit(random);
    const Eigen::Vector3d position = kBoardCenter + Eigen::Vector3d(-distance, 0.45 * unit(random), 0.3 * unit(random));
    const Eigen::Vector3d target = kBoardCenter + Eigen::Vector3d(0.0, aim.x() * unit(random), aim.y() * unit(random));
    const Eigen::Vector3d d = target - position;
    const SO3 R_world_body = SO3::exp(Eigen::Vector3d(0, 0, std::atan2(d.y(), d.x()))) *
                             SO3::exp(Eigen::Vector3d(0, -std::atan2(d.z(), std::hypot(d.x(), d.y())), 0)) *
                             SO3::exp(Eigen::Vector3d(0.44 * unit(random), 0, 0));
    const auto still = sim::SplineTrajectory::create(kBoardViewsStart, Duration::from_milliseconds(500), std::vector<SE3>(6, SE3(R_world_body, position)));
    EXPECT_TRUE(still);
    auto camera = sim::CameraSimulator::create(config, world, *still);
    EXPECT_TRUE(camera) << camera.error().message;
    msgs::ImageMessage image = camera->measure(kBoardViewsStart + Duration::from_seconds(1.0));
    image.timestamp = kBoardViewsStart + Duration::from_seconds(v);
    images.push_back(std::move(image));
  }
  return images;
}

inline sim::CameraSimulatorConfig lens(msgs::CameraIntrinsics intrinsics, msgs::DistortionModel distortion) {
  sim::CameraSimulatorConfig config;
  config.T_body_camera = forward_camera();
  config.intrinsics = intrinsics;
  config.distortion = std::move(distortion);
  config.supersampling = 2;
  config.pixel_noise = 1.0;
  return config;
}

}  // namespace hanzo::fusion::test_support
