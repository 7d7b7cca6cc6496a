#pragma once
// validate(message): the checks every message built outside the engine (drivers, importers,
// the network) must pass before it is fused. On failure the Error names the message, field and
// value, e.g. "ImuMessage.angular_velocity.x: non-finite value nan", and Error::field holds
// the field path ("angular_velocity.x").
//
// Rejected, for every message: zero timestamp; non-finite numbers; covariances that are
// non-symmetric (relative 1e-9) or have a negative diagonal; quaternions whose norm differs
// from 1 by more than kUnitQuaternionTolerance. Per message: see the comments below.

#include "hanzo/fusion/core/result.hpp"
#include "hanzo/fusion/msgs/estimate_messages.hpp"
#include "hanzo/fusion/msgs/sensor_messages.hpp"

namespace hanzo::fusion::msgs {

/// Quaternions from files and sensors are accepted when | |q| - 1 | <= this (float32 and
/// 3-decimal rounding pass; a typo does not). They are normalized where used.
inline constexpr double kUnitQuaternionTolerance = 1e-3;

/// Plus: orientation covariance without orientation.
Status validate(const ImuMessage& message);
/// Plus: no points; intensities / ring_ids / point_timestamps neither empty nor one per
/// point; intensity outside [0, 1]; zero per-point timestamp.
Status validate(const PointCloudMessage& message);
/// Plus: zero width or height; data size != width * height * bytes per pixel; intrinsics with
/// non-positive focal length or a principal point outside the image; distortion coefficient
/// count wrong for the model (radtan 4 or 5, equidistant 4, none 0).
Status validate(const ImageMessage& message);
Status validate(const CameraIntrinsics& intrinsics, std::string_view field_prefix = "intrinsics");
Status validate(const DistortionModel& distortion, std::string_view field_prefix = "distortion");
/// Plus: latitude outside +-90, longitude outside +-180, impossible altitude, negative hdop.
Status validate(const GnssMessage& message);
/// Plus: wheel_separation <= 0, negative wheel_radius.
Status validate(const WheelOdometryMessage& message);
/// Plus: negative range, azimuth outside [-pi, pi], elevation outside [-pi/2, pi/2].
Status validate(const RadarMessage& message);
Status validate(const RangeMessage& message);
/// Boxes inside the image (at most half a pixel outside), ordered corners, finite scores in
/// [0, 1], a class name, a mask of mask_width x mask_height bytes or none.
Status validate(const DetectionsMessage& message);
Status validate(const PoseEstimate& message);
/// Plus: relative covariance without relative pose.
Status validate(const Keyframe& message);
Status validate(const SensorMessage& message);

}  // namespace hanzo::fusion::msgs
