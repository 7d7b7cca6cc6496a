#pragma once
// Lossless conversion between the engine's message structs and the hanzo.fusion.v1 protobuf
// messages. to_proto() never fails. from_proto() rejects what the struct cannot hold (a
// timestamp above INT64_MAX, a covariance with other than 0 or 9/36 values, an unknown image
// encoding or enum value, a missing required submessage) and then runs validate(), so a
// message that came over the wire is checked once, here. Every valid message survives
// struct -> proto -> struct bit for bit.

#include "hanzo/fusion/core/result.hpp"
#include "hanzo/fusion/msgs/estimate_messages.hpp"
#include "hanzo/fusion/msgs/sensor_messages.hpp"
#include "hanzo/fusion/v1/estimates.pb.h"
#include "hanzo/fusion/v1/sensors.pb.h"

namespace hanzo::fusion::msgs {

v1::ImuMessage to_proto(const ImuMessage& message);
v1::PointCloudMessage to_proto(const PointCloudMessage& message);
/// How a sweep's points go on the wire: the spec's `points` (a Point3 message per point), or
/// `packed_points` (x, y, z floats in one packed field; an order of magnitude cheaper to encode
/// and decode). from_proto reads either.
/// How a sweep's points go on the wire: one Point3 per point (the spec's layout), packed floats
/// (exact, cheapest to encode), or quantized deltas (multiples of point_resolution m, smallest;
/// falls back to packed when a point lies beyond +-2^30 resolutions). Packed and quantized also
/// carry per-point times as fixed-width offsets when they fit.
enum class PointEncoding { kPoint3, kPacked, kQuantized };
/// Overwrites *out with the sweep, reusing its storage: a stream writing sweeps at sensor rate
/// keeps one message instead of allocating ~30k points per sweep.
void to_proto(const PointCloudMessage& message, v1::PointCloudMessage* out, PointEncoding encoding = PointEncoding::kPoint3,
              double point_resolution = 0.001);
v1::ImageMessage to_proto(const ImageMessage& message);
v1::GnssMessage to_proto(const GnssMessage& message);
v1::WheelOdometryMessage to_proto(const WheelOdometryMessage& message);
v1::RadarMessage to_proto(const RadarMessage& message);
v1::RangeMessage to_proto(const RangeMessage& message);
v1::DetectionsMessage to_proto(const DetectionsMessage& message);
v1::PoseEstimate to_proto(const PoseEstimate& message);
v1::Keyframe to_proto(const Keyframe& message);

Result<ImuMessage> from_proto(const v1::ImuMessage& message);
Result<PointCloudMessage> from_proto(const v1::PointCloudMessage& message);
Result<ImageMessage> from_proto(const v1::ImageMessage& message);
Result<GnssMessage> from_proto(const v1::GnssMessage& message);
Result<WheelOdometryMessage> from_proto(const v1::WheelOdometryMessage& message);
Result<RadarMessage> from_proto(const v1::RadarMessage& message);
Result<RangeMessage> from_proto(const v1::RangeMessage& message);
Result<DetectionsMessage> from_proto(const v1::DetectionsMessage& message);
Result<PoseEstimate> from_proto(const v1::PoseEstimate& message);
Result<Keyframe> from_proto(const v1::Keyframe& message);

}  // namespace hanzo::fusion::msgs
