#include "message_conversion.hpp"

#include <cstring>
#include <optional>
#include <string>

#include <fmt/format.h>
#include <pybind11/eigen.h>
#include <pybind11/numpy.h>
#include <pybind11/stl.h>

namespace py = pybind11;

namespace hanzo::fusion::python {
namespace {

py::module_ messages_module() { return py::module_::import("hanzo.fusion.messages"); }

template <typename Scalar>
using Array = py::array_t<Scalar, py::array::c_style | py::array::forcecast>;

// A field's array with the element count the dataclass promised (it checked the shape).
template <typename Scalar>
Array<Scalar> array_field(py::handle message, const char* name) {
  return py::cast<Array<Scalar>>(message.attr(name));
}

template <typename Matrix>
std::optional<Matrix> optional_matrix(py::handle message, const char* name) {
  const py::object value = message.attr(name);
  if (value.is_none()) return std::nullopt;
  const Array<double> array = py::cast<Array<double>>(value);
  if (array.size() != Matrix::SizeAtCompileTime) {
    throw py::value_error(fmt::format("{}: expected {} values, got {}", name, Matrix::SizeAtCompileTime, array.size()));
  }
  // Row-major in numpy; Eigen's fixed matrices are column-major (vectors are both).
  constexpr int kRows = Matrix::RowsAtCompileTime, kCols = Matrix::ColsAtCompileTime;
  return Eigen::Map<const Eigen::Matrix<double, kRows, kCols, kCols == 1 ? Eigen::ColMajor : Eigen::RowMajor>>(array.data());
}

Timestamp timestamp_field(py::handle message) { return Timestamp::from_nanoseconds(py::cast<int64_t>(message.attr("timestamp_ns"))); }

template <typename Scalar>
Array<Scalar> copy_to_numpy(const Scalar* data, std::vector<py::ssize_t> shape) {
  Array<Scalar> array(shape);
  std::memcpy(array.mutable_data(), data, static_cast<std::size_t>(array.size()) * sizeof(Scalar));
  return array;
}

py::object optional_to_numpy(const std::optional<Eigen::Matrix3d>& matrix) {
  if (!matrix) return py::none();
  const Eigen::Matrix<double, 3, 3, Eigen::RowMajor> rows = *matrix;
  return copy_to_numpy(rows.data(), {3, 3});
}

msgs::ImuMessage imu_from(py::handle message) {
  msgs::ImuMessage imu;
  imu.timestamp = timestamp_field(message);
  imu.frame_id = py::cast<std::string>(message.attr("frame_id"));
  imu.linear_acceleration = *optional_matrix<Eigen::Vector3d>(message, "linear_acceleration");
  imu.angular_velocity = *optional_matrix<Eigen::Vector3d>(message, "angular_velocity");
  imu.acceleration_covariance = optional_matrix<Eigen::Matrix3d>(message, "acceleration_covariance");
  imu.gyroscope_covariance = optional_matrix<Eigen::Matrix3d>(message, "gyroscope_covariance");
  if (const std::optional<Eigen::Vector4d> q = optional_matrix<Eigen::Vector4d>(message, "orientation")) {
    imu.orientation = Eigen::Quaterniond((*q)[0], (*q)[1], (*q)[2], (*q)[3]);
  }
  imu.orientation_covariance = optional_matrix<Eigen::Matrix3d>(message, "orientation_covariance");
  return imu;
}

msgs::PointCloudMessage point_cloud_from(py::handle message) {
  msgs::PointCloudMessage cloud;
  cloud.timestamp = timestamp_field(message);
  cloud.frame_id = py::cast<std::string>(message.attr("frame_id"));
  const Array<float> points = array_field<float>(message, "points");
  const std::size_t count = static_cast<std::size_t>(points.size() / 3);
  cloud.points.resize(count);
  for (std::size_t i = 0; i < count; ++i) cloud.points[i] = Eigen::Vector3f(points.data()[3 * i], points.data()[3 * i + 1], points.data()[3 * i + 2]);
  const auto per_point = [&](const char* name, auto& out) {
    using Scalar = typename std::decay_t<decltype(out)>::value_type;
    const py::object value = message.attr(name);
    if (value.is_none()) return;
    const Array<Scalar> array = py::cast<Array<Scalar>>(value);
    if (static_cast<std::size_t>(array.size()) != count) throw py::value_error(fmt::format("{}: expected {} values (one per point), got {}", name, count, array.size()));
    out.assign(array.data(), array.data() + array.size());
  };
  per_point("intensities", cloud.intensities);
  per_point("ring_ids", cloud.ring_ids);
  std::vector<int64_t> times_ns;
  per_point("point_timestamps_ns", times_ns);
  for (const int64_t time_ns : times_ns) cloud.point_timestamps.push_back(Timestamp::from_nanoseconds(time_ns));
  return cloud;
}

msgs::ImageMessage image_from(py::handle message) {
  msgs::ImageMessage image;
  image.timestamp = timestamp_field(message);
  image.frame_id = py::cast<std::string>(message.attr("frame_id"));
  const std::string encoding = py::cast<std::string>(message.attr("encoding"));
  const std::optional<msgs::ImageEncoding> parsed = msgs::image_encoding_from_string(encoding);
  if (!parsed) throw py::value_error(fmt::format("encoding: unknown image encoding '{}'", encoding));
  image.encoding = *parsed;
  const py::array pixels = py::cast<py::array>(message.attr("pixels"));
  if (pixels.ndim() < 2) throw py::value_error("pixels: expected an H x W (x channels) array");
  if (!(pixels.flags() & py::array::c_style)) throw py::value_error("pixels: expected a C-contiguous array");
  image.height = static_cast<uint32_t>(pixels.shape(0));
  image.width = static_cast<uint32_t>(pixels.shape(1));
  const auto* bytes = static_cast<const uint8_t*>(pixels.data());
  image.data.assign(bytes, bytes + pixels.nbytes());
  if (const py::object intrinsics = message.attr("intrinsics"); !intrinsics.is_none()) {
    msgs::CameraIntrinsics camera;
    camera.fx = py::cast<double>(intrinsics.attr("fx"));
    camera.fy = py::cast<double>(intrinsics.attr("fy"));
    camera.cx = py::cast<double>(intrinsics.attr("cx"));
    camera.cy = py::cast<double>(intrinsics.attr("cy"));
    camera.width = py::cast<uint32_t>(intrinsics.attr("width"));
    camera.height = py::cast<uint32_t>(intrinsics.attr("height"));
    image.intrinsics = camera;
  }
  if (const py::object distortion = message.attr("distortion"); !distortion.is_none()) {
    const std::string model = py::cast<std::string>(distortion.attr("model"));
    const std::optional<msgs::DistortionType> type = msgs::distortion_type_from_string(model);
    if (!type) throw py::value_error(fmt::format("distortion.model: expected none, radtan or equidistant, got '{}'", model));
    image.distortion = msgs::DistortionModel{*type, py::cast<std::vector<double>>(distortion.attr("coefficients"))};
  }
  return image;
}

msgs::GnssMessage gnss_from(py::handle message) {
  msgs::GnssMessage gnss;
  gnss.timestamp = timestamp_field(message);
  gnss.latitude = py::cast<double>(message.attr("latitude"));
  gnss.longitude = py::cast<double>(message.attr("longitude"));
  gnss.altitude = py::cast<double>(message.attr("altitude"));
  const std::string fix = py::cast<std::string>(message.attr("fix_type"));
  const std::optional<msgs::GnssFixType> type = msgs::gnss_fix_type_from_string(fix);
  if (!type) throw py::value_error(fmt::format("fix_type: expected NO_FIX, FIX_2D, FIX_3D, RTK_FLOAT or RTK_FIXED, got '{}'", fix));
  gnss.fix_type = *type;
  gnss.position_covariance = optional_matrix<Eigen::Matrix3d>(message, "position_covariance");
  gnss.satellites_used = py::cast<uint32_t>(message.attr("satellites_used"));
  gnss.hdop = py::cast<float>(message.attr("hdop"));
  return gnss;
}

msgs::WheelOdometryMessage wheels_from(py::handle message) {
  msgs::WheelOdometryMessage wheels;
  wheels.timestamp = timestamp_field(message);
  wheels.frame_id = py::cast<std::string>(message.attr("frame_id"));
  wheels.left_distance = py::cast<double>(message.attr("left_distance"));
  wheels.right_distance = py::cast<double>(message.attr("right_distance"));
  wheels.wheel_separation = py::cast<double>(message.attr("wheel_separation"));
  wheels.wheel_radius = py::cast<double>(message.attr("wheel_radius"));
  return wheels;
}

msgs::RadarMessage radar_from(py::handle message) {
  msgs::RadarMessage radar;
  radar.timestamp = timestamp_field(message);
  radar.frame_id = py::cast<std::string>(message.attr("frame_id"));
  const Array<float> targets = array_field<float>(message, "targets");
  for (py::ssize_t i = 0; i + 5 <= targets.size(); i += 5) {
    const float* row = targets.data() + i;
    radar.targets.push_back({row[0], row[1], row[2], row[3], row[4]});
  }
  return radar;
}

msgs::RangeMessage range_from(py::handle message) {
  msgs::RangeMessage range;
  range.timestamp = timestamp_field(message);
  range.frame_id = py::cast<std::string>(message.attr("frame_id"));
  range.radiation = py::cast<std::string>(message.attr("radiation")) == "infrared" ? msgs::RangeRadiation::kInfrared : msgs::RangeRadiation::kUltrasound;
  range.field_of_view = py::cast<float>(message.attr("field_of_view"));
  range.min_range = py::cast<float>(message.attr("min_range"));
  range.max_range = py::cast<float>(message.attr("max_range"));
  range.range = py::cast<float>(message.attr("range"));
  range.variance = py::cast<float>(message.attr("variance"));
  return range;
}

msgs::DetectionsMessage detections_from(py::handle message) {
  msgs::DetectionsMessage detections;
  detections.timestamp = timestamp_field(message);
  detections.frame_id = py::cast<std::string>(message.attr("frame_id"));
  detections.image_width = py::cast<uint32_t>(message.attr("image_width"));
  detections.image_height = py::cast<uint32_t>(message.attr("image_height"));
  for (py::handle item : message.attr("detections")) {
    msgs::Detection2D& detection = detections.detections.emplace_back();
    detection.class_name = py::cast<std::string>(item.attr("class_name"));
    detection.score = py::cast<float>(item.attr("score"));
    detection.track_id = py::cast<int64_t>(item.attr("track_id"));
    const Array<float> box = array_field<float>(item, "box");
    if (box.size() != 4) throw py::value_error("Detection.box: expected (x_min, y_min, x_max, y_max)");
    detection.x_min = box.data()[0];
    detection.y_min = box.data()[1];
    detection.x_max = box.data()[2];
    detection.y_max = box.data()[3];
    if (const py::object mask = item.attr("mask"); !mask.is_none()) {
      const Array<uint8_t> pixels = py::cast<Array<uint8_t>>(mask);
      if (pixels.ndim() != 2) throw py::value_error("Detection.mask: expected rows x columns");
      detection.mask_height = static_cast<uint32_t>(pixels.shape(0));
      detection.mask_width = static_cast<uint32_t>(pixels.shape(1));
      detection.mask.assign(pixels.data(), pixels.data() + pixels.size());
    }
  }
  if (const py::object segmentation = message.attr("segmentation"); !segmentation.is_none()) {
    const Array<uint8_t> pixels = py::cast<Array<uint8_t>>(segmentation);
    detections.segmentation.assign(pixels.data(), pixels.data() + pixels.size());
  }
  detections.segmentation_classes = py::cast<std::vector<std::string>>(message.attr("segmentation_classes"));
  return detections;
}

}  // namespace

msgs::SensorMessage sensor_message_from_python(py::handle message) {
  const py::module_ module = messages_module();
  if (py::isinstance(message, module.attr("Imu"))) return imu_from(message);
  if (py::isinstance(message, module.attr("PointCloud"))) return point_cloud_from(message);
  if (py::isinstance(message, module.attr("Image"))) return image_from(message);
  if (py::isinstance(message, module.attr("Gnss"))) return gnss_from(message);
  if (py::isinstance(message, module.attr("WheelOdometry"))) return wheels_from(message);
  if (py::isinstance(message, module.attr("Radar"))) return radar_from(message);
  if (py::isinstance(message, module.attr("Range"))) return range_from(message);
  if (py::isinstance(message, module.attr("Detections"))) return detections_from(message);
  throw py::type_error(fmt::format("expected a sensor message of hanzo.fusion.messages (Imu, PointCloud, Image, Gnss, WheelOdometry, Radar, Range, "
                                   "Detections), got {}",
                                   py::str(py::type::of(message)).cast<std::string>()));
}

py::object to_python(const msgs::SensorMessage& message) {
  const py::module_ module = messages_module();
  struct Visitor {
    const py::module_& module;
    py::object operator()(const msgs::ImuMessage& imu) const {
      py::object orientation = py::none();
      if (imu.orientation) {
        const Eigen::Vector4d wxyz(imu.orientation->w(), imu.orientation->x(), imu.orientation->y(), imu.orientation->z());
        orientation = copy_to_numpy(wxyz.data(), {4});
      }
      return module.attr("Imu")(imu.timestamp.nanoseconds(), copy_to_numpy(imu.linear_acceleration.data(), {3}),
                                copy_to_numpy(imu.angular_velocity.data(), {3}), imu.frame_id, optional_to_numpy(imu.acceleration_covariance),
                                optional_to_numpy(imu.gyroscope_covariance), orientation, optional_to_numpy(imu.orientation_covariance));
    }
    py::object operator()(const msgs::PointCloudMessage& cloud) const {
      const py::ssize_t count = static_cast<py::ssize_t>(cloud.points.size());
      Array<float> points({count, py::ssize_t{3}});
      float* out = points.mutable_data();
      for (const Eigen::Vector3f& p : cloud.points) out = std::copy(p.data(), p.data() + 3, out);
      py::object intensities = py::none(), rings = py::none(), times = py::none();
      if (!cloud.intensities.empty()) intensities = copy_to_numpy(cloud.intensities.data(), {count});
      if (!cloud.ring_ids.empty()) rings = copy_to_numpy(cloud.ring_ids.data(), {count});
      if (!cloud.point_timestamps.empty()) {
        std::vector<int64_t> ns;
        ns.reserve(cloud.point_timestamps.size());
        for (const Timestamp t : cloud.point_timestamps) ns.push_back(t.nanoseconds());
        times = copy_to_numpy(ns.data(), {count});
      }
      return module.attr("PointCloud")(cloud.timestamp.nanoseconds(), points, cloud.frame_id, intensities, rings, times);
    }
    py::object operator()(const msgs::ImageMessage& image) const {
      const py::ssize_t rows = image.height, cols = image.width;
      py::array pixels;
      switch (image.encoding) {
        case msgs::ImageEncoding::kMono8: pixels = copy_to_numpy(image.data.data(), {rows, cols}); break;
        case msgs::ImageEncoding::kRgb8:
        case msgs::ImageEncoding::kBgr8: pixels = copy_to_numpy(image.data.data(), {rows, cols, py::ssize_t{3}}); break;
        case msgs::ImageEncoding::kDepth16: pixels = copy_to_numpy(reinterpret_cast<const uint16_t*>(image.data.data()), {rows, cols}); break;
        case msgs::ImageEncoding::kDepth32f: pixels = copy_to_numpy(reinterpret_cast<const float*>(image.data.data()), {rows, cols}); break;
      }
      py::object intrinsics = py::none(), distortion = py::none();
      if (image.intrinsics) {
        const msgs::CameraIntrinsics& c = *image.intrinsics;
        intrinsics = module.attr("CameraIntrinsics")(c.fx, c.fy, c.cx, c.cy, c.width, c.height);
      }
      if (image.distortion) distortion = module.attr("Distortion")(std::string(msgs::to_string(image.distortion->type)), image.distortion->coefficients);
      return module.attr("Image")(image.timestamp.nanoseconds(), pixels, std::string(msgs::to_string(image.encoding)), image.frame_id,
                                  intrinsics, distortion);
    }
    py::object operator()(const msgs::GnssMessage& gnss) const {
      return module.attr("Gnss")(gnss.timestamp.nanoseconds(), gnss.latitude, gnss.longitude, gnss.altitude,
                                 std::string(msgs::to_string(gnss.fix_type)), optional_to_numpy(gnss.position_covariance),
                                 gnss.satellites_used, gnss.hdop);
    }
    py::object operator()(const msgs::WheelOdometryMessage& wheels) const {
      return module.attr("WheelOdometry")(wheels.timestamp.nanoseconds(), wheels.left_distance, wheels.right_distance,
                                          wheels.wheel_separation, wheels.wheel_radius, wheels.frame_id);
    }
    py::object operator()(const msgs::RadarMessage& radar) const {
      std::vector<float> values;
      values.reserve(radar.targets.size() * 5);
      for (const msgs::RadarTarget& t : radar.targets) values.insert(values.end(), {t.range, t.azimuth, t.elevation, t.radial_velocity, t.rcs});
      return module.attr("Radar")(radar.timestamp.nanoseconds(),
                                  copy_to_numpy(values.data(), {static_cast<py::ssize_t>(radar.targets.size()), py::ssize_t{5}}), radar.frame_id);
    }
    py::object operator()(const msgs::RangeMessage& range) const {
      return module.attr("Range")(range.timestamp.nanoseconds(), range.range, range.min_range, range.max_range, range.field_of_view,
                                  range.radiation == msgs::RangeRadiation::kInfrared ? "infrared" : "ultrasound", range.variance, range.frame_id);
    }
    py::object operator()(const msgs::DetectionsMessage& detections) const {
      py::list items;
      for (const msgs::Detection2D& d : detections.detections) {
        const float box[4] = {d.x_min, d.y_min, d.x_max, d.y_max};
        py::object mask = py::none();
        if (!d.mask.empty()) mask = copy_to_numpy(d.mask.data(), {static_cast<py::ssize_t>(d.mask_height), static_cast<py::ssize_t>(d.mask_width)});
        items.append(module.attr("Detection")(d.class_name, copy_to_numpy(box, {4}), d.score, d.track_id, mask));
      }
      py::object segmentation = py::none();
      if (!detections.segmentation.empty()) {
        segmentation = copy_to_numpy(detections.segmentation.data(),
                                     {static_cast<py::ssize_t>(detections.image_height), static_cast<py::ssize_t>(detections.image_width)});
      }
      return module.attr("Detections")(detections.timestamp.nanoseconds(), detections.image_width, detections.image_height, items, detections.frame_id,
                                        segmentation, py::cast(detections.segmentation_classes));
    }
  };
  return std::visit(Visitor{module}, message);
}

py::object to_python(const msgs::PoseEstimate& pose) {
  const Eigen::Quaterniond& q = pose.T_world_body.orientation;
  const Eigen::Vector4d wxyz(q.w(), q.x(), q.y(), q.z());
  py::object covariance = py::none();
  if (pose.pose_covariance) {
    const Eigen::Matrix<double, 6, 6, Eigen::RowMajor> rows = *pose.pose_covariance;
    covariance = copy_to_numpy(rows.data(), {6, 6});
  }
  return messages_module().attr("PoseEstimate")(pose.timestamp.nanoseconds(), copy_to_numpy(pose.T_world_body.position.data(), {3}),
                                                copy_to_numpy(wxyz.data(), {4}), copy_to_numpy(pose.velocity.data(), {3}), covariance,
                                                std::string(msgs::to_string(pose.status.state)));
}

}  // namespace hanzo::fusion::python
