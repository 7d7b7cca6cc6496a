#include "raw_cloud.hpp"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <limits>

#include <fmt/format.h>

#include "hanzo/fusion/core/logging.hpp"

namespace hanzo::fusion::cloud {
namespace {

const RawField* find_field(const RawCloud& raw, std::initializer_list<const char*> names) {
  for (const char* name : names) {
    for (const auto& field : raw.fields) {
      if (field.name == name) return &field;
    }
  }
  return nullptr;
}

}  // namespace

size_t scalar_size(ScalarType type) {
  switch (type) {
    case ScalarType::kInt8: case ScalarType::kUint8: return 1;
    case ScalarType::kInt16: case ScalarType::kUint16: return 2;
    case ScalarType::kInt32: case ScalarType::kUint32: case ScalarType::kFloat32: return 4;
    default: return 8;
  }
}

bool is_integer(ScalarType type) { return type != ScalarType::kFloat32 && type != ScalarType::kFloat64; }

void store_scalar(ScalarType type, double value, uint8_t* at) {
  const auto store = [at](auto sample) { std::memcpy(at, &sample, sizeof(sample)); };
  switch (type) {
    case ScalarType::kInt8: store(static_cast<int8_t>(value)); break;
    case ScalarType::kUint8: store(static_cast<uint8_t>(value)); break;
    case ScalarType::kInt16: store(static_cast<int16_t>(value)); break;
    case ScalarType::kUint16: store(static_cast<uint16_t>(value)); break;
    case ScalarType::kInt32: store(static_cast<int32_t>(value)); break;
    case ScalarType::kUint32: store(static_cast<uint32_t>(value)); break;
    case ScalarType::kInt64: store(static_cast<int64_t>(value)); break;
    case ScalarType::kUint64: store(static_cast<uint64_t>(value)); break;
    case ScalarType::kFloat32: store(static_cast<float>(value)); break;
    case ScalarType::kFloat64: store(value); break;
  }
}

void RawCloud::add_field(std::string name, ScalarType type) {
  fields.push_back({std::move(name), type, record_size});
  record_size += scalar_size(type);
}

double RawCloud::value(const RawField& field, size_t index) const {
  const uint8_t* at = bytes.data() + index * record_size + field.offset;
  const auto load = [at](auto sample) {
    std::memcpy(&sample, at, sizeof(sample));
    return static_cast<double>(sample);
  };
  switch (field.type) {
    case ScalarType::kInt8: return load(int8_t{});
    case ScalarType::kUint8: return load(uint8_t{});
    case ScalarType::kInt16: return load(int16_t{});
    case ScalarType::kUint16: return load(uint16_t{});
    case ScalarType::kInt32: return load(int32_t{});
    case ScalarType::kUint32: return load(uint32_t{});
    case ScalarType::kInt64: return load(int64_t{});
    case ScalarType::kUint64: return load(uint64_t{});
    case ScalarType::kFloat32: return load(float{});
    case ScalarType::kFloat64: return load(double{});
  }
  return std::numeric_limits<double>::quiet_NaN();
}

Result<PointCloud> to_point_cloud(const RawCloud& raw, bool drop_non_finite) {
  const RawField* x = find_field(raw, {"x"});
  const RawField* y = find_field(raw, {"y"});
  const RawField* z = find_field(raw, {"z"});
  if (!x || !y || !z) return Error("the cloud has no x, y, z fields");
  const RawField* intensity = find_field(raw, {"intensity", "scalar_intensity", "reflectance"});
  const RawField* ring = find_field(raw, {"ring"});
  const RawField* time = find_field(raw, {"time", "t", "offset_time", "timestamp"});
  const RawField* normal[3] = {find_field(raw, {"normal_x", "nx"}), find_field(raw, {"normal_y", "ny"}),
                               find_field(raw, {"normal_z", "nz"})};
  const bool has_normals = normal[0] && normal[1] && normal[2];
  const double time_scale = time && is_integer(time->type) ? 1e-9 : 1.0;  // integer times are ns
  const bool absolute_time = time && time->name == "timestamp";

  PointCloud cloud;
  cloud.positions.reserve(raw.count);
  std::vector<double> times;
  size_t dropped = 0;
  // Indices are the points' positions in the file (0-based), before any point is dropped.
  const auto finite = [&raw](const RawField* field, size_t i) { return field == nullptr || std::isfinite(raw.value(*field, i)); };
  for (size_t i = 0; i < raw.count; ++i) {
    const Eigen::Vector3d position(raw.value(*x, i), raw.value(*y, i), raw.value(*z, i));
    if (!position.allFinite()) {
      if (drop_non_finite) {
        ++dropped;
        continue;
      }
      return Error(fmt::format("point {} of the file has a non-finite coordinate", i));
    }
    if (!finite(intensity, i)) return Error(fmt::format("point {} of the file has a non-finite {}", i, intensity->name));
    if (!finite(time, i)) return Error(fmt::format("point {} of the file has a non-finite {}", i, time->name));
    if (has_normals && !(finite(normal[0], i) && finite(normal[1], i) && finite(normal[2], i))) {
      return Error(fmt::format("point {} of the file has a non-finite normal", i));
    }
    cloud.positions.push_back(position.cast<float>());
    if (intensity) cloud.intensities.push_back(static_cast<float>(raw.value(*intensity, i)));
    if (ring) cloud.rings.push_back(static_cast<uint16_t>(std::clamp(raw.value(*ring, i), 0.0, 65535.0)));
    if (time) times.push_back(raw.value(*time, i) * time_scale);
    if (has_normals) {
      cloud.normals.emplace_back(static_cast<float>(raw.value(*normal[0], i)), static_cast<float>(raw.value(*normal[1], i)),
                                 static_cast<float>(raw.value(*normal[2], i)));
    }
  }
  if (!times.empty()) {
    const double origin = absolute_time ? *std::min_element(times.begin(), times.end()) : 0.0;
    cloud.times.reserve(times.size());
    for (double t : times) cloud.times.push_back(static_cast<float>(t - origin));
  }
  if (dropped > 0) {
    logger()->warn("dropped {} of {} points with a non-finite (NaN or infinite) coordinate: a sensor's missing returns", dropped, raw.count);
  }
  HANZO_RETURN_IF_ERROR(cloud.validate());
  return cloud;
}

RawCloud to_raw_cloud(const PointCloud& cloud) {
  RawCloud raw;
  for (const char* axis : {"x", "y", "z"}) raw.add_field(axis, ScalarType::kFloat32);
  if (cloud.has_intensities()) raw.add_field("intensity", ScalarType::kFloat32);
  if (cloud.has_rings()) raw.add_field("ring", ScalarType::kUint16);
  if (cloud.has_times()) raw.add_field("time", ScalarType::kFloat32);
  if (cloud.has_normals()) {
    for (const char* axis : {"normal_x", "normal_y", "normal_z"}) raw.add_field(axis, ScalarType::kFloat32);
  }
  raw.count = cloud.size();
  raw.bytes.resize(raw.count * raw.record_size);
  uint8_t* at = raw.bytes.data();
  const auto store = [&at](const auto& value) {
    std::memcpy(at, &value, sizeof(value));
    at += sizeof(value);
  };
  for (size_t i = 0; i < cloud.size(); ++i) {
    for (int axis = 0; axis < 3; ++axis) store(cloud.positions[i][axis]);
    if (cloud.has_intensities()) store(cloud.intensities[i]);
    if (cloud.has_rings()) store(cloud.rings[i]);
    if (cloud.has_times()) store(cloud.times[i]);
    if (cloud.has_normals()) {
      for (int axis = 0; axis < 3; ++axis) store(cloud.normals[i][axis]);
    }
  }
  return raw;
}

}  // namespace hanzo::fusion::cloud
