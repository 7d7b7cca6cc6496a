#include "hanzo/fusion/cloud/point_cloud.hpp"

#include <cmath>

#include <fmt/format.h>

#include "hanzo/fusion/core/finite.hpp"

#include "hanzo/fusion/msgs/sensor_messages.hpp"
#include "hanzo/fusion/msgs/validate.hpp"

namespace hanzo::fusion::cloud {
namespace {

template <typename Attribute>
Status check_size(const std::vector<Attribute>& values, size_t points, const char* name) {
  if (values.empty() || values.size() == points) return ok_status();
  return Error(fmt::format("PointCloud.{}: {} values for {} points", name, values.size(), points), name);
}

template <typename Matrix>
Status check_finite(const std::vector<Matrix>& values, const char* name) {
  static_assert(sizeof(Matrix) == sizeof(float) * Matrix::SizeAtCompileTime, "packed float matrices");
  if (all_finite(values.empty() ? nullptr : values.front().data(), values.size() * Matrix::SizeAtCompileTime)) return ok_status();
  static constexpr const char* kAxes[] = {"x", "y", "z"};
  for (size_t i = 0; i < values.size(); ++i) {
    if (values[i].allFinite()) continue;
    for (Eigen::Index k = 0; k < values[i].size(); ++k) {
      if (std::isfinite(values[i](k))) continue;
      const std::string element = Matrix::ColsAtCompileTime == 1 ? kAxes[k] : fmt::format("({},{})", k % 3, k / 3);
      return Error(fmt::format("PointCloud.{}[{}].{}: {}", name, i, element, values[i](k)), name);
    }
  }
  return ok_status();
}

Status check_finite(const std::vector<float>& values, const char* name) {
  if (all_finite(values.data(), values.size())) return ok_status();
  for (size_t i = 0; i < values.size(); ++i) {
    if (!std::isfinite(values[i])) return Error(fmt::format("PointCloud.{}[{}]: {}", name, i, values[i]), name);
  }
  return ok_status();
}

}  // namespace

void PointCloud::reserve(size_t count) {
  positions.reserve(count);
  if (has_intensities()) intensities.reserve(count);
  if (has_rings()) rings.reserve(count);
  if (has_times()) times.reserve(count);
  if (has_normals()) normals.reserve(count);
  if (has_covariances()) covariances.reserve(count);
}

void PointCloud::clear() { *this = PointCloud{}; }

Status PointCloud::validate() const {
  const size_t n = size();
  HANZO_RETURN_IF_ERROR(check_size(intensities, n, "intensities"));
  HANZO_RETURN_IF_ERROR(check_size(rings, n, "rings"));
  HANZO_RETURN_IF_ERROR(check_size(times, n, "times"));
  HANZO_RETURN_IF_ERROR(check_size(normals, n, "normals"));
  HANZO_RETURN_IF_ERROR(check_size(covariances, n, "covariances"));
  HANZO_RETURN_IF_ERROR(check_finite(positions, "positions"));
  HANZO_RETURN_IF_ERROR(check_finite(intensities, "intensities"));
  HANZO_RETURN_IF_ERROR(check_finite(times, "times"));
  HANZO_RETURN_IF_ERROR(check_finite(normals, "normals"));
  return check_finite(covariances, "covariances");
}

PointCloud select(const PointCloud& cloud, const std::vector<uint32_t>& indices) {
  PointCloud out;
  const auto pick = [&indices](const auto& from, auto& to) {
    if (from.empty()) return;
    to.reserve(indices.size());
    for (uint32_t i : indices) to.push_back(from[i]);
  };
  pick(cloud.positions, out.positions);
  pick(cloud.intensities, out.intensities);
  pick(cloud.rings, out.rings);
  pick(cloud.times, out.times);
  pick(cloud.normals, out.normals);
  pick(cloud.covariances, out.covariances);
  return out;
}

void transform_in_place(PointCloud& cloud, const SE3& T_new_old) {
  const Eigen::Matrix3f rotation = T_new_old.rotation().matrix().cast<float>();
  const Eigen::Vector3f translation = T_new_old.translation().cast<float>();
  for (auto& p : cloud.positions) p = rotation * p + translation;
  for (auto& n : cloud.normals) n = rotation * n;
  for (auto& c : cloud.covariances) c = rotation * c * rotation.transpose();
}

PointCloud transformed(const PointCloud& cloud, const SE3& T_new_old) {
  PointCloud out = cloud;
  transform_in_place(out, T_new_old);
  return out;
}

PointCloud crop_range(const PointCloud& cloud, double min_range, double max_range) {
  std::vector<uint32_t> kept;
  kept.reserve(cloud.size());
  const double min_sq = min_range * min_range;
  const double max_sq = max_range > 0.0 ? max_range * max_range : std::numeric_limits<double>::infinity();
  for (size_t i = 0; i < cloud.size(); ++i) {
    const Eigen::Vector3f& p = cloud.positions[i];
    if (!p.allFinite()) continue;
    const double range_sq = p.squaredNorm();
    if (range_sq >= min_sq && range_sq <= max_sq) kept.push_back(static_cast<uint32_t>(i));
  }
  return select(cloud, kept);
}

Result<PointCloud> from_message(const msgs::PointCloudMessage& message) {
  HANZO_RETURN_IF_ERROR(msgs::validate(message));
  PointCloud out;
  out.positions = message.points;
  out.intensities = message.intensities;
  out.rings.reserve(message.ring_ids.size());
  for (uint32_t ring : message.ring_ids) {
    if (ring > std::numeric_limits<uint16_t>::max()) {
      return Error(fmt::format("PointCloudMessage.ring_ids: ring {} exceeds 65535", ring), "ring_ids");
    }
    out.rings.push_back(static_cast<uint16_t>(ring));
  }
  out.times.reserve(message.point_timestamps.size());
  for (const Timestamp& stamp : message.point_timestamps) {
    out.times.push_back(static_cast<float>((stamp - message.timestamp).seconds()));
  }
  return out;
}

}  // namespace hanzo::fusion::cloud
