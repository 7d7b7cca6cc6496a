#include "hanzo/fusion/sim/camera_simulator.hpp"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <limits>

#include <Eigen/Dense>
#include <fmt/format.h>
#include <fmt/ranges.h>
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>

#include "hanzo/fusion/core/thread_sanitizer.hpp"
#include "hanzo/fusion/core/enum_names.hpp"

namespace hanzo::fusion::sim {
namespace {

constexpr EnumNames<CameraFaultType, 3> kFaultNames{{{CameraFaultType::kDarkness, "darkness"},
                                                     {CameraFaultType::kGlare, "glare"},
                                                     {CameraFaultType::kMotionBlur, "motion_blur"}}};

// Inverse of the distortion model on normalized image coordinates (z = 1 plane) by Newton's
// method from `guess` (a neighbouring pixel's solution converges in one or two steps):
//   radtan (OpenCV plumb_bob): x_d = x r + 2 p1 x y + p2 (r2 + 2 x^2), y_d = y r + p1 (r2 + 2 y^2)
//     + 2 p2 x y, r = 1 + k1 r2 + k2 r2^2 + k3 r2^3, solved in 2D with the analytic Jacobian;
//   equidistant (OpenCV fisheye): theta_d = theta (1 + k1 theta^2 + ... + k4 theta^8) with
//     theta = atan(|p|), |p_d| = theta_d, solved in 1D for theta.
Eigen::Vector2d undistort(const msgs::DistortionModel& model, const Eigen::Vector2d& distorted, const Eigen::Vector2d& guess) {
  const std::vector<double>& k = model.coefficients;
  switch (model.type) {
    case msgs::DistortionType::kNone: return distorted;
    case msgs::DistortionType::kRadtan: {
      const double k3 = k.size() > 4 ? k[4] : 0.0, p1 = k[2], p2 = k[3];
      Eigen::Vector2d p = guess;
      for (int iteration = 0; iteration < 20; ++iteration) {
        const double x = p.x(), y = p.y(), r2 = x * x + y * y;
        const double radial = 1.0 + r2 * (k[0] + r2 * (k[1] + r2 * k3));
        const double radial_dr2 = k[0] + r2 * (2.0 * k[1] + 3.0 * r2 * k3);
        const Eigen::Vector2d residual(x * radial + 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x) - distorted.x(),
                                       y * radial + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y - distorted.y());
        Eigen::Matrix2d jacobian;
        jacobian << radial + 2.0 * x * x * radial_dr2 + 2.0 * p1 * y + 6.0 * p2 * x, 2.0 * x * y * radial_dr2 + 2.0 * p1 * x + 2.0 * p2 * y,
            2.0 * x * y * radial_dr2 + 2.0 * p1 * x + 2.0 * p2 * y, radial + 2.0 * y * y * radial_dr2 + 6.0 * p1 * y + 2.0 * p2 * x;
        const Eigen::Vector2d step = jacobian.inverse() * residual;
        p -= step;
        if (step.squaredNorm() < 1e-28) break;
      }
      return p;
    }
    case msgs::DistortionType::kEquidistant: {
      const double theta_d = distorted.norm();
      if (theta_d < 1e-15) return distorted;
      double theta = std::atan(guess.norm());
      for (int iteration = 0; iteration < 20; ++iteration) {
        const double t2 = theta * theta;
        const double value = theta * (1.0 + t2 * (k[0] + t2 * (k[1] + t2 * (k[2] + t2 * k[3])))) - theta_d;
        const double slope = 1.0 + t2 * (3.0 * k[0] + t2 * (5.0 * k[1] + t2 * (7.0 * k[2] + t2 * 9.0 * k[3])));
        const double step = value / slope;
        theta -= step;
        if (std::abs(step) < 1e-15) break;
      }
      return distorted * (std::tan(theta) / theta_d);
    }
  }
  return distorted;
}

Eigen::Vector3f sky_color(const Eigen::Vector3d& direction_world) {
  const float up = static_cast<float>(std::clamp(direction_world.z(), 0.0, 1.0));
  return Eigen::Vector3f(0.78F, 0.82F, 0.86F) * (1.0F - up) + Eigen::Vector3f(0.35F, 0.5F, 0.8F) * up;
}

// Shadow rays start this far off the surface (metres) and look this far for an occluder.
constexpr double kShadowOffset = 1e-3;
constexpr double kShadowDistance = 100.0;

// The albedo of a surface point under snow: upward surfaces in 0.4 m patches (a hash of the
// patch, so the same patches every frame), white with a fifth of the texture showing through.
Eigen::Vector3f snowy(const Eigen::Vector3f& albedo, const RayHit& hit, double snow_cover) {
  if (snow_cover <= 0.0 || hit.normal.z() < 0.7) return albedo;
  const auto cell_x = static_cast<int64_t>(std::floor(hit.point.x() / 0.4)), cell_y = static_cast<int64_t>(std::floor(hit.point.y() / 0.4));
  uint64_t hash = static_cast<uint64_t>(cell_x) * 0x9E3779B97F4A7C15ULL ^ static_cast<uint64_t>(cell_y) * 0xC2B2AE3D27D4EB4FULL;
  hash ^= hash >> 31;
  hash *= 0xBF58476D1CE4E5B9ULL;
  hash ^= hash >> 29;
  if (static_cast<double>(hash >> 11) / static_cast<double>(uint64_t{1} << 53) >= snow_cover) return albedo;
  return Eigen::Vector3f::Constant(0.72F) + 0.2F * albedo;
}

}  // namespace

constexpr EnumNames<GroundTruthDetections, 3> kDetectionNames{
    {{GroundTruthDetections::kNone, "none"}, {GroundTruthDetections::kBoxes, "boxes"}, {GroundTruthDetections::kMasks, "masks"}}};
std::string_view to_string(GroundTruthDetections detections) { return enum_name(kDetectionNames, detections); }
std::optional<GroundTruthDetections> ground_truth_detections_from_string(std::string_view name) { return enum_from_name(kDetectionNames, name); }
std::string_view to_string(CameraFaultType type) { return enum_name(kFaultNames, type); }
std::optional<CameraFaultType> camera_fault_type_from_string(std::string_view name) { return enum_from_name(kFaultNames, name); }

Result<CameraSimulator> CameraSimulator::create(CameraSimulatorConfig config, const World& world, const SplineTrajectory& trajectory) {
  const msgs::CameraIntrinsics& k = config.intrinsics;
  if (k.width == 0 || k.height == 0) return Error{"camera intrinsics: width and height are required", "intrinsics"};
  if (!(k.fx > 0.0) || !(k.fy > 0.0)) return Error{fmt::format("camera intrinsics: fx, fy must be > 0, got {}, {}", k.fx, k.fy), "intrinsics"};
  const bool depth = config.encoding == msgs::ImageEncoding::kDepth16 || config.encoding == msgs::ImageEncoding::kDepth32f;
  if (config.encoding != msgs::ImageEncoding::kMono8 && config.encoding != msgs::ImageEncoding::kRgb8 && !depth) {
    return Error{fmt::format("camera encoding: expected mono8, rgb8, depth16 or depth32f, got {}", msgs::to_string(config.encoding)), "encoding"};
  }
  if (depth) {
    if (!(config.depth_range.x() > 0.0 && config.depth_range.y() > config.depth_range.x()) || !(config.depth_noise >= 0.0)) {
      return Error{fmt::format("camera depth: expected 0 < depth_range[0] < depth_range[1] and depth_noise >= 0, got [{}, {}], {}", config.depth_range.x(),
                               config.depth_range.y(), config.depth_noise),
                   "depth_range"};
    }
    config.supersampling = 1;  // one ray through each pixel's centre
  }
  const std::size_t coefficients = config.distortion.coefficients.size();
  const bool counts_ok = config.distortion.type == msgs::DistortionType::kNone      ? coefficients == 0
                         : config.distortion.type == msgs::DistortionType::kRadtan ? (coefficients == 4 || coefficients == 5)
                                                                                    : coefficients == 4;
  if (!counts_ok) {
    return Error{fmt::format("camera distortion {}: wrong number of coefficients ({})", msgs::to_string(config.distortion.type), coefficients),
                 "distortion"};
  }
  if (!(config.exposure > 0.0) || !(config.snow_cover >= 0.0 && config.snow_cover <= 1.0) || !(config.tint.minCoeff() >= 0.0F)) {
    return Error{fmt::format("camera lighting: exposure > 0, snow_cover in [0, 1] and tint >= 0 are required (got {}, {}, [{}])", config.exposure,
                             config.snow_cover, fmt::join(config.tint.data(), config.tint.data() + 3, ", ")),
                 "lighting"};
  }
  if (config.supersampling < 1 || config.supersampling > 4) {
    return Error{fmt::format("camera supersampling: expected 1..4, got {}", config.supersampling), "supersampling"};
  }
  return CameraSimulator(std::move(config), world, trajectory);
}

CameraSimulator::CameraSimulator(CameraSimulatorConfig config, const World& world, const SplineTrajectory& trajectory)
    : config_(std::move(config)), world_(&world), trajectory_(&trajectory), sun_direction_(config_.sun_direction.normalized()),
      random_(config_.seed) {
  // The segmentation's label table and each object's class in it (object ids: ground -1, boxes,
  // cylinders, moving boxes).
  const WorldDescription& description = world.description();
  const auto class_id = [this](const std::string& name) {
    const auto found = std::find(segmentation_classes_.begin(), segmentation_classes_.end(), name);
    if (found != segmentation_classes_.end()) return static_cast<uint8_t>(found - segmentation_classes_.begin());
    if (segmentation_classes_.size() + 1 >= msgs::kUnlabelledPixel) return msgs::kUnlabelledPixel;
    segmentation_classes_.push_back(name);
    return static_cast<uint8_t>(segmentation_classes_.size() - 1);
  };
  class_of_object_.push_back(description.has_ground ? class_id(description.ground_class) : msgs::kUnlabelledPixel);
  for (const Box& box : description.boxes) class_of_object_.push_back(class_id(box.class_name));
  for (const Cylinder& cylinder : description.cylinders) class_of_object_.push_back(class_id(cylinder.class_name));
  for (const MovingBox& mover : description.moving_boxes) class_of_object_.push_back(class_id(mover.class_name));
  std::normal_distribution<float> normal(0.0F, 1.0F);
  normal_table_.resize(std::size_t{1} << kNormalTableBits);
  for (float& value : normal_table_) value = normal(random_);
  const int s = config_.supersampling;
  const auto width = static_cast<int>(config_.intrinsics.width), height = static_cast<int>(config_.intrinsics.height);
  const msgs::CameraIntrinsics& k = config_.intrinsics;
  rays_.resize(static_cast<std::size_t>(width * s) * static_cast<std::size_t>(height * s));
  for (int row = 0; row < height * s; ++row) {
    Eigen::Vector2d previous = Eigen::Vector2d::Zero();
    for (int column = 0; column < width * s; ++column) {
      // Sub-sample centres spread evenly over the pixel [u - 0.5, u + 0.5].
      const double u = (column + 0.5) / s - 0.5, v = (row + 0.5) / s - 0.5;
      const Eigen::Vector2d distorted((u - k.cx) / k.fx, (v - k.cy) / k.fy);
      previous = undistort(config_.distortion, distorted, column == 0 ? distorted : previous);
      rays_[static_cast<std::size_t>(row) * width * s + column] = Eigen::Vector3d(previous.x(), previous.y(), 1.0).normalized().cast<float>();
    }
  }
  // Each tile's pyramid: the range of x / z and y / z over its rays (as cast), widened by a
  // hair so rounding in the world-frame rotation never puts one of its rays outside.
  const int tiles_across = (width + kTilePixels - 1) / kTilePixels, tiles_down = (height + kTilePixels - 1) / kTilePixels;
  tiles_.resize(static_cast<std::size_t>(tiles_across) * tiles_down);
  for (int tile_row = 0; tile_row < tiles_down; ++tile_row) {
    for (int tile_column = 0; tile_column < tiles_across; ++tile_column) {
      double x_min = std::numeric_limits<double>::infinity(), y_min = x_min, x_max = -x_min, y_max = -x_min, z_min = x_min;
      for (int row = tile_row * kTilePixels * s; row < std::min(height, (tile_row + 1) * kTilePixels) * s; ++row) {
        for (int column = tile_column * kTilePixels * s; column < std::min(width, (tile_column + 1) * kTilePixels) * s; ++column) {
          const Eigen::Vector3d ray = rays_[static_cast<std::size_t>(row) * width * s + column].cast<double>();
          z_min = std::min(z_min, ray.z());
          x_min = std::min(x_min, ray.x() / ray.z());
          x_max = std::max(x_max, ray.x() / ray.z());
          y_min = std::min(y_min, ray.y() / ray.z());
          y_max = std::max(y_max, ray.y() / ray.z());
        }
      }
      TilePyramid& tile = tiles_[static_cast<std::size_t>(tile_row) * tiles_across + tile_column];
      tile.valid = z_min > 1e-3;  // fisheye rays at or beyond 90 degrees: no pyramid, plain casts
      constexpr double kSlack = 1e-9;
      tile.inward_normals = {Eigen::Vector3d(-1.0, 0.0, x_max + kSlack), Eigen::Vector3d(1.0, 0.0, -(x_min - kSlack)),
                             Eigen::Vector3d(0.0, -1.0, y_max + kSlack), Eigen::Vector3d(0.0, 1.0, -(y_min - kSlack)),
                             Eigen::Vector3d::UnitZ()};
    }
  }
}

Eigen::Vector3d CameraSimulator::pixel_ray(double u, double v) const {
  const msgs::CameraIntrinsics& k = config_.intrinsics;
  const Eigen::Vector2d distorted((u - k.cx) / k.fx, (v - k.cy) / k.fy);
  const Eigen::Vector2d normalized = undistort(config_.distortion, distorted, distorted);
  return Eigen::Vector3d(normalized.x(), normalized.y(), 1.0).normalized();
}

void CameraSimulator::render(Timestamp time, std::vector<Eigen::Vector3f>& radiance, std::vector<float>* depth, std::vector<int>* object_ids) const {
  const SE3 T_world_camera = trajectory_->sample(time).T_world_body * config_.T_body_camera;
  const Eigen::Matrix3d R_world_camera = T_world_camera.rotation().matrix();
  const Eigen::Vector3d& origin = T_world_camera.translation();
  const int s = config_.supersampling;
  const auto width = static_cast<int>(config_.intrinsics.width), height = static_cast<int>(config_.intrinsics.height);
  const float weight = 1.0F / static_cast<float>(s * s);
  const WorldSnapshot snapshot = world_->at(time);
  if (depth != nullptr) {
    depth->assign(static_cast<std::size_t>(width) * height, std::numeric_limits<float>::quiet_NaN());
  } else {
    radiance.assign(static_cast<std::size_t>(width) * height, Eigen::Vector3f::Zero());
  }
  if (object_ids != nullptr) object_ids->assign(static_cast<std::size_t>(width) * height, -2);
  const int tiles_across = (width + kTilePixels - 1) / kTilePixels, tiles_down = (height + kTilePixels - 1) / kTilePixels;
  // Rows of tiles are independent: render them on up to num_threads threads (same result).
  // Inside a tile every ray goes through the tile's RayGroup (the same hit as a plain cast).
  auto render_tile_rows = [&](const tbb::blocked_range<int>& tile_rows) {
    RayGroup group;
    TextureSampleCache texture_cache;
    std::array<Eigen::Vector3d, 5> inward_normals_world;
    for (int tile_row = tile_rows.begin(); tile_row < tile_rows.end(); ++tile_row) {
      for (int tile_column = 0; tile_column < tiles_across; ++tile_column) {
        const TilePyramid& tile = tiles_[static_cast<std::size_t>(tile_row) * tiles_across + tile_column];
        if (tile.valid) {
          for (std::size_t i = 0; i < inward_normals_world.size(); ++i) inward_normals_world[i] = R_world_camera * tile.inward_normals[i];
          snapshot.group(origin, inward_normals_world, config_.max_distance, &group);
        }
        const int column_end = std::min(width, (tile_column + 1) * kTilePixels) * s;
        for (int row = tile_row * kTilePixels * s; row < std::min(height, (tile_row + 1) * kTilePixels) * s; ++row) {
          int object_hint = -1;  // neighbouring pixels mostly see the same object
          int shadow_hint = -1;
          const Eigen::Vector3f* ray = &rays_[static_cast<std::size_t>(row) * width * s];
          Eigen::Vector3f* pixel_row = &radiance[static_cast<std::size_t>(row / s) * width];
          for (int column = tile_column * kTilePixels * s; column < column_end; ++column) {
            const Eigen::Vector3d direction = R_world_camera * ray[column].cast<double>();
            const std::optional<RayHit> hit =
                tile.valid ? snapshot.cast(group, direction, &object_hint) : snapshot.cast(origin, direction, config_.max_distance, &object_hint);
            if (depth != nullptr) {  // s is 1 for depth cameras
              if (hit) (*depth)[static_cast<std::size_t>(row) * width + column] = static_cast<float>(hit->distance * ray[column].z());
              continue;
            }
            if (object_ids != nullptr && hit && row % s == 0 && column % s == 0) {
              (*object_ids)[static_cast<std::size_t>(row / s) * width + column / s] = hit->object_id;
            }
            Eigen::Vector3f color;
            if (hit) {
              double sunlit = std::max(0.0, hit->normal.dot(sun_direction_));
              if (sunlit > 0.0 && config_.shadows && snapshot.cast(hit->point + kShadowOffset * hit->normal, sun_direction_, kShadowDistance, &shadow_hint)) {
                sunlit = 0.0;
              }
              const Eigen::Vector3f albedo = hit->material->texture.color(hit->surface_uv.x(), hit->surface_uv.y(), &texture_cache).cwiseProduct(config_.tint);
              color = snowy(albedo, *hit, config_.snow_cover) * static_cast<float>(config_.ambient + config_.diffuse * sunlit);
            } else {
              color = sky_color(direction);
            }
            pixel_row[s == 1 ? column : column / s] += weight * color;
          }
        }
      }
    }
  };
  const tbb::blocked_range<int> all_tile_rows(0, tiles_down, 1);
  if (config_.num_threads == 1 || kUnderThreadSanitizer) {  // core/thread_sanitizer.hpp
    render_tile_rows(all_tile_rows);
  } else {
    tbb::task_arena arena(config_.num_threads <= 0 ? tbb::task_arena::automatic : config_.num_threads);
    arena.execute([&] { tbb::parallel_for(all_tile_rows, render_tile_rows); });
  }
}

msgs::ImageMessage CameraSimulator::image_header(Timestamp time) const {
  msgs::ImageMessage image;
  image.timestamp = time;
  image.frame_id = config_.frame_id;
  image.width = config_.intrinsics.width;
  image.height = config_.intrinsics.height;
  image.encoding = config_.encoding;
  image.intrinsics = config_.intrinsics;
  if (config_.distortion.type != msgs::DistortionType::kNone) image.distortion = config_.distortion;
  return image;
}

float CameraSimulator::next_normal(uint64_t& state) const {
  state ^= state << 13;
  state ^= state >> 7;
  state ^= state << 17;
  return normal_table_[state >> (64 - kNormalTableBits)];
}

msgs::ImageMessage CameraSimulator::measure_depth(Timestamp time) {
  std::vector<Eigen::Vector3f> unused;
  std::vector<float> depth;
  render(time, unused, &depth);
  msgs::ImageMessage image = image_header(time);
  const bool millimetres = config_.encoding == msgs::ImageEncoding::kDepth16;
  image.data.resize(depth.size() * (millimetres ? 2 : 4));
  uint64_t state = random_() | 1U;
  for (std::size_t p = 0; p < depth.size(); ++p) {
    float value = depth[p];
    const float normal = next_normal(state);
    if (!(value >= config_.depth_range.x() && value <= config_.depth_range.y())) {
      value = std::numeric_limits<float>::quiet_NaN();
    } else {
      value += static_cast<float>(config_.depth_noise) * value * value * normal;
    }
    if (millimetres) {
      const auto mm = static_cast<uint16_t>(std::isfinite(value) ? std::clamp(std::lround(value * 1000.0F), 0L, 65535L) : 0L);
      std::memcpy(&image.data[2 * p], &mm, 2);
    } else {
      std::memcpy(&image.data[4 * p], &value, 4);
    }
  }
  return image;
}

msgs::ImageMessage CameraSimulator::measure(Timestamp time) {
  if (config_.encoding == msgs::ImageEncoding::kDepth16 || config_.encoding == msgs::ImageEncoding::kDepth32f) return measure_depth(time);
  const auto width = static_cast<int>(config_.intrinsics.width), height = static_cast<int>(config_.intrinsics.height);
  double brightness = config_.exposure, noise = config_.pixel_noise;
  const CameraFaultEpisode* glare = nullptr;
  const CameraFaultEpisode* blur = nullptr;
  for (const CameraFaultEpisode& fault : config_.faults) {
    if (time < fault.start || time > fault.end) continue;
    switch (fault.type) {
      case CameraFaultType::kDarkness:
        brightness *= fault.brightness;
        noise *= fault.noise_scale;
        break;
      case CameraFaultType::kGlare: glare = &fault; break;
      case CameraFaultType::kMotionBlur: blur = &fault; break;
    }
  }

  const bool detects = config_.ground_truth_detections != GroundTruthDetections::kNone || config_.ground_truth_segmentation;
  std::vector<Eigen::Vector3f> radiance;
  if (blur != nullptr && blur->blur_samples > 1) {
    std::vector<Eigen::Vector3f> sub_frame;
    radiance.assign(static_cast<std::size_t>(width) * height, Eigen::Vector3f::Zero());
    for (int i = 0; i < blur->blur_samples; ++i) {
      const double offset = blur->exposure_time * (static_cast<double>(i) / (blur->blur_samples - 1) - 0.5);
      render(time + Duration::from_seconds(offset), sub_frame, nullptr, i == blur->blur_samples / 2 && detects ? &object_ids_ : nullptr);
      for (std::size_t p = 0; p < radiance.size(); ++p) radiance[p] += sub_frame[p] / static_cast<float>(blur->blur_samples);
    }
  } else {
    render(time, radiance, nullptr, detects ? &object_ids_ : nullptr);
  }
  object_ids_time_ = time;

  msgs::ImageMessage image = image_header(time);
  const bool rgb = config_.encoding == msgs::ImageEncoding::kRgb8;
  image.data.resize(radiance.size() * (rgb ? 3 : 1));
  // Pixel noise: standard normal draws from a table filled once from the seed, indexed by a
  // xorshift sequence seeded per frame (a normal_distribution per pixel costs a fifth of a frame).
  uint64_t state = random_() | 1U;
  const auto noise_level = static_cast<float>(noise);
  auto quantize = [&](float value) {
    const float level = value * 255.0F + noise_level * next_normal(state) + 0.5F;
    return static_cast<uint8_t>(std::clamp(level, 0.0F, 255.0F));
  };
  for (int row = 0; row < height; ++row) {
    for (int column = 0; column < width; ++column) {
      const std::size_t p = static_cast<std::size_t>(row) * width + column;
      Eigen::Vector3f color = radiance[p] * static_cast<float>(brightness);
      if (glare != nullptr) {
        const double d2 = (Eigen::Vector2d(column, row) - glare->center).squaredNorm();
        color.array() += static_cast<float>(glare->strength * std::exp(-d2 / (2.0 * glare->radius * glare->radius)));
      }
      if (rgb) {
        for (int channel = 0; channel < 3; ++channel) image.data[3 * p + channel] = quantize(color[channel]);
      } else {
        image.data[p] = quantize(luminance(color));
      }
    }
  }
  return image;
}

std::optional<msgs::DetectionsMessage> CameraSimulator::detections() const {
  if ((config_.ground_truth_detections == GroundTruthDetections::kNone && !config_.ground_truth_segmentation) || object_ids_.empty()) {
    return std::nullopt;
  }
  const auto width = static_cast<int>(config_.intrinsics.width), height = static_cast<int>(config_.intrinsics.height);
  const std::vector<MovingBox>& movers = world_->description().moving_boxes;
  const int first_moving = world_->object_count() - static_cast<int>(movers.size());
  struct Extent {
    int pixels = 0;
    int x_min = std::numeric_limits<int>::max(), y_min = std::numeric_limits<int>::max(), x_max = -1, y_max = -1;
  };
  std::vector<Extent> extents(movers.size());
  for (int row = 0; row < height; ++row) {
    for (int column = 0; column < width; ++column) {
      const int mover = object_ids_[static_cast<std::size_t>(row) * width + column] - first_moving;
      if (mover < 0) continue;
      Extent& extent = extents[static_cast<std::size_t>(mover)];
      ++extent.pixels;
      extent.x_min = std::min(extent.x_min, column);
      extent.x_max = std::max(extent.x_max, column);
      extent.y_min = std::min(extent.y_min, row);
      extent.y_max = std::max(extent.y_max, row);
    }
  }
  msgs::DetectionsMessage message;
  message.timestamp = object_ids_time_;
  message.frame_id = config_.frame_id;
  message.image_width = config_.intrinsics.width;
  message.image_height = config_.intrinsics.height;
  if (config_.ground_truth_segmentation) add_segmentation(message);
  for (std::size_t mover = 0; mover < movers.size() && config_.ground_truth_detections != GroundTruthDetections::kNone; ++mover) {
    const Extent& extent = extents[mover];
    if (extent.pixels < config_.min_detection_pixels) continue;
    msgs::Detection2D detection;
    detection.class_name = movers[mover].class_name;
    detection.score = 1.0F;
    detection.x_min = static_cast<float>(extent.x_min);
    detection.y_min = static_cast<float>(extent.y_min);
    detection.x_max = static_cast<float>(extent.x_max);
    detection.y_max = static_cast<float>(extent.y_max);
    detection.track_id = static_cast<int64_t>(mover);
    if (config_.ground_truth_detections == GroundTruthDetections::kMasks) {
      detection.mask_width = static_cast<uint32_t>(extent.x_max - extent.x_min + 1);
      detection.mask_height = static_cast<uint32_t>(extent.y_max - extent.y_min + 1);
      detection.mask.reserve(static_cast<std::size_t>(detection.mask_width) * detection.mask_height);
      for (int row = extent.y_min; row <= extent.y_max; ++row) {
        for (int column = extent.x_min; column <= extent.x_max; ++column) {
          detection.mask.push_back(object_ids_[static_cast<std::size_t>(row) * width + column] - first_moving == static_cast<int>(mover) ? 255 : 0);
        }
      }
    }
    message.detections.push_back(std::move(detection));
  }
  return message;
}

void CameraSimulator::add_segmentation(msgs::DetectionsMessage& message) const {
  message.segmentation_classes = segmentation_classes_;
  message.segmentation.resize(object_ids_.size());
  const auto classes = static_cast<uint64_t>(segmentation_classes_.size());
  // Noise: a hash of (seed, time, pixel) per pixel, the same whatever the call order.
  const uint64_t frame = config_.seed * 0x9E3779B97F4A7C15ULL ^ static_cast<uint64_t>(object_ids_time_.nanoseconds());
  for (std::size_t p = 0; p < object_ids_.size(); ++p) {
    const int object = object_ids_[p];
    uint8_t id = object < -1 ? msgs::kUnlabelledPixel : class_of_object_[static_cast<std::size_t>(object + 1)];
    if (id != msgs::kUnlabelledPixel && classes > 1 && config_.segmentation_noise > 0.0) {
      uint64_t hash = frame + 0x9E3779B97F4A7C15ULL * (p + 1);
      hash = (hash ^ (hash >> 30)) * 0xBF58476D1CE4E5B9ULL;
      hash = (hash ^ (hash >> 27)) * 0x94D049BB133111EBULL;
      hash ^= hash >> 31;
      if (static_cast<double>(hash >> 11) * 0x1.0p-53 < config_.segmentation_noise) {
        id = static_cast<uint8_t>((id + 1 + (hash & 0xFFFF) % (classes - 1)) % classes);
      }
    }
    message.segmentation[p] = id;
  }
}

}  // namespace hanzo::fusion::sim
