#include "foxglove_convert.hpp"

#include <cstring>

#include "foxglove/LocationFix.pb.h"
#include "foxglove/PointCloud.pb.h"
#include "foxglove/PoseInFrame.pb.h"
#include "foxglove/CompressedImage.pb.h"
#include "foxglove/RawImage.pb.h"

namespace hanzo::fusion::io::foxglove_mirror {
namespace {

void set_time(google::protobuf::Timestamp& out, Timestamp time) {
  const int64_t ns = time.nanoseconds();
  out.set_seconds(ns / 1'000'000'000);
  out.set_nanos(static_cast<int32_t>(ns % 1'000'000'000));
}

void set_pose(foxglove::Pose& out, const Eigen::Vector3d& position, const Eigen::Quaterniond& orientation) {
  out.mutable_position()->set_x(position.x());
  out.mutable_position()->set_y(position.y());
  out.mutable_position()->set_z(position.z());
  out.mutable_orientation()->set_x(orientation.x());
  out.mutable_orientation()->set_y(orientation.y());
  out.mutable_orientation()->set_z(orientation.z());
  out.mutable_orientation()->set_w(orientation.w());
}

template <typename T>
void put(std::string& data, std::size_t offset, T value) {
  std::memcpy(data.data() + offset, &value, sizeof value);  // little endian on every supported target
}

std::unique_ptr<google::protobuf::Message> point_cloud(const msgs::PointCloudMessage& cloud, const std::string& frame_id) {
  auto out = std::make_unique<foxglove::PointCloud>();
  set_time(*out->mutable_timestamp(), cloud.timestamp);
  out->set_frame_id(frame_id);
  set_pose(*out->mutable_pose(), Eigen::Vector3d::Zero(), Eigen::Quaterniond::Identity());
  uint32_t stride = 0;
  auto add_field = [&](const char* name, foxglove::PackedElementField::NumericType type) {
    auto* field = out->add_fields();
    field->set_name(name);
    field->set_offset(stride);
    field->set_type(type);
    stride += 4;
    return field->offset();
  };
  add_field("x", foxglove::PackedElementField::FLOAT32);
  add_field("y", foxglove::PackedElementField::FLOAT32);
  add_field("z", foxglove::PackedElementField::FLOAT32);
  const bool has_intensity = !cloud.intensities.empty();
  const bool has_ring = !cloud.ring_ids.empty();
  const bool has_time = !cloud.point_timestamps.empty();
  const uint32_t intensity_offset = has_intensity ? add_field("intensity", foxglove::PackedElementField::FLOAT32) : 0;
  const uint32_t ring_offset = has_ring ? add_field("ring", foxglove::PackedElementField::UINT32) : 0;
  const uint32_t time_offset = has_time ? add_field("time", foxglove::PackedElementField::FLOAT32) : 0;
  out->set_point_stride(stride);
  std::string& data = *out->mutable_data();
  data.assign(cloud.points.size() * stride, '\0');
  for (std::size_t i = 0; i < cloud.points.size(); ++i) {
    const std::size_t base = i * stride;
    put(data, base, cloud.points[i].x());
    put(data, base + 4, cloud.points[i].y());
    put(data, base + 8, cloud.points[i].z());
    if (has_intensity) put(data, base + intensity_offset, cloud.intensities[i]);
    if (has_ring) put(data, base + ring_offset, cloud.ring_ids[i]);
    if (has_time) put(data, base + time_offset, static_cast<float>((cloud.point_timestamps[i] - cloud.timestamp).seconds()));
  }
  return out;
}

std::unique_ptr<google::protobuf::Message> location_fix(const msgs::GnssMessage& fix, const std::string& frame_id) {
  auto out = std::make_unique<foxglove::LocationFix>();
  set_time(*out->mutable_timestamp(), fix.timestamp);
  out->set_frame_id(frame_id);
  out->set_latitude(fix.latitude);
  out->set_longitude(fix.longitude);
  out->set_altitude(fix.altitude);
  if (fix.position_covariance) {
    for (int row = 0; row < 3; ++row) {
      for (int col = 0; col < 3; ++col) out->add_position_covariance((*fix.position_covariance)(row, col));
    }
    out->set_position_covariance_type(foxglove::LocationFix::KNOWN);
  } else {
    out->mutable_position_covariance()->Resize(9, 0.0);
    out->set_position_covariance_type(foxglove::LocationFix::UNKNOWN);
  }
  return out;
}

const char* ros_encoding(msgs::ImageEncoding encoding) {
  switch (encoding) {
    case msgs::ImageEncoding::kRgb8: return "rgb8";
    case msgs::ImageEncoding::kBgr8: return "bgr8";
    case msgs::ImageEncoding::kMono8: return "mono8";
    case msgs::ImageEncoding::kDepth16: return "16UC1";
    case msgs::ImageEncoding::kDepth32f: return "32FC1";
  }
  return "mono8";
}

std::unique_ptr<google::protobuf::Message> raw_image(const msgs::ImageMessage& image, const std::string& frame_id) {
  auto out = std::make_unique<foxglove::RawImage>();
  set_time(*out->mutable_timestamp(), image.timestamp);
  out->set_frame_id(frame_id);
  out->set_width(image.width);
  out->set_height(image.height);
  out->set_encoding(ros_encoding(image.encoding));
  out->set_step(static_cast<uint32_t>(image.width * msgs::bytes_per_pixel(image.encoding)));
  out->set_data(image.data.data(), image.data.size());
  return out;
}

}  // namespace

std::unique_ptr<google::protobuf::Message> to_foxglove(const msgs::PoseEstimate& pose) {
  auto out = std::make_unique<foxglove::PoseInFrame>();
  set_time(*out->mutable_timestamp(), pose.timestamp);
  out->set_frame_id(pose.frame_id);
  set_pose(*out->mutable_pose(), pose.T_world_body.position, pose.T_world_body.orientation);
  return out;
}

std::unique_ptr<google::protobuf::Message> compressed_image(const v1::ImageMessage& image, const std::string& frame_id_fallback) {
  auto out = std::make_unique<foxglove::CompressedImage>();
  set_time(*out->mutable_timestamp(), Timestamp::from_nanoseconds(static_cast<int64_t>(image.timestamp_ns())));
  out->set_frame_id(image.frame_id().empty() ? frame_id_fallback : image.frame_id());
  out->set_data(image.data());
  out->set_format(image.compression());
  return out;
}

std::unique_ptr<google::protobuf::Message> to_foxglove(const msgs::SensorMessage& message, const std::string& frame_id_fallback) {
  auto frame = [&](const std::string& frame_id) { return frame_id.empty() ? frame_id_fallback : frame_id; };
  if (const auto* cloud = std::get_if<msgs::PointCloudMessage>(&message)) return point_cloud(*cloud, frame(cloud->frame_id));
  if (const auto* fix = std::get_if<msgs::GnssMessage>(&message)) return location_fix(*fix, frame_id_fallback);
  if (const auto* image = std::get_if<msgs::ImageMessage>(&message)) return raw_image(*image, frame(image->frame_id));
  return nullptr;
}

}  // namespace hanzo::fusion::io::foxglove_mirror
