#pragma once
// Conversions into Foxglove's visualization schemas (proto/foxglove/), for the mirror channels
// SensorLogWriter writes next to the hanzo.fusion.v1 ones. Internal to the io module.
//
//   PoseEstimate       -> foxglove.PoseInFrame  (frame_id = the world frame, pose = T_world_body)
//   PointCloudMessage  -> foxglove.PointCloud   (float32 x y z at 0/4/8; then, when present,
//                         float32 intensity, uint32 ring, float32 time = seconds after the
//                         cloud's timestamp; pose identity: points stay in the sensor frame)
//   GnssMessage        -> foxglove.LocationFix  (covariance type KNOWN when the message has one)
//   ImageMessage       -> foxglove.RawImage     (depth16 -> "16UC1", depth32f -> "32FC1")
//   stored PNG / JPEG  -> foxglove.CompressedImage (the same file, format "png" / "jpeg")
// Radar, IMU and wheel odometry have no Foxglove schema and are not mirrored.

#include <optional>
#include <string>

#include <google/protobuf/message.h>

#include "hanzo/fusion/msgs/estimate_messages.hpp"
#include "hanzo/fusion/msgs/sensor_messages.hpp"
#include "hanzo/fusion/v1/sensors.pb.h"

namespace hanzo::fusion::io::foxglove_mirror {

std::unique_ptr<google::protobuf::Message> to_foxglove(const msgs::PoseEstimate& pose);
/// An image stored compressed (v1::ImageMessage with `compression` set): the file itself.
std::unique_ptr<google::protobuf::Message> compressed_image(const v1::ImageMessage& image, const std::string& frame_id_fallback);
/// nullptr for message types Foxglove has no schema for.
std::unique_ptr<google::protobuf::Message> to_foxglove(const msgs::SensorMessage& message, const std::string& frame_id_fallback);

}  // namespace hanzo::fusion::io::foxglove_mirror
