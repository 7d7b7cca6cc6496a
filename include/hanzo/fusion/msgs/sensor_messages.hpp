#pragma once
// The engine's sensor messages: plain C++ mirrors of the hanzo.fusion.v1 protobuf schemas
// (proto/hanzo/fusion/v1/sensors.proto) with Eigen types. Conventions of the spec: timestamps
// int64 ns since the Unix epoch, SI units, body FLU, world ENU, quaternions (w, x, y, z).
// Optional fields are std::optional: absence is explicit, never encoded as zeros.
// Convert to and from protobuf with msgs/convert.hpp; check with validate() in
// msgs/validate.hpp before trusting a message built outside the engine.

#include <cstdint>
#include <optional>
#include <string>
#include <string_view>
#include <variant>
#include <vector>

#include <Eigen/Core>
#include <Eigen/Geometry>

#include "hanzo/fusion/core/geodesy.hpp"
#include "hanzo/fusion/core/time.hpp"

namespace hanzo::fusion::msgs {

struct ImuMessage {
  Timestamp timestamp;
  std::string frame_id;
  Eigen::Vector3d linear_acceleration = Eigen::Vector3d::Zero();  // m/s^2, IMU frame (specific force)
  Eigen::Vector3d angular_velocity = Eigen::Vector3d::Zero();     // rad/s, IMU frame
  std::optional<Eigen::Matrix3d> acceleration_covariance;         // (m/s^2)^2
  std::optional<Eigen::Matrix3d> gyroscope_covariance;            // (rad/s)^2
  /// R_world_imu reported by the IMU itself (world ENU), when it reports attitude.
  std::optional<Eigen::Quaterniond> orientation;
  /// Covariance of the orientation as a rotation-vector error, rad^2 (only with orientation).
  std::optional<Eigen::Matrix3d> orientation_covariance;
};

struct PointCloudMessage {
  Timestamp timestamp;
  std::string frame_id;
  std::vector<Eigen::Vector3f> points;   // meters, sensor frame; never empty
  std::vector<float> intensities;        // empty, or one per point in [0, 1]
  std::vector<uint32_t> ring_ids;        // empty, or one per point
  std::vector<Timestamp> point_timestamps;  // empty, or one per point
};

struct CameraIntrinsics {
  double fx = 0.0;  // pixels
  double fy = 0.0;
  double cx = 0.0;
  double cy = 0.0;
  uint32_t width = 0;   // pixels, 0 when unknown
  uint32_t height = 0;
};

enum class DistortionType {
  kNone,         // ideal pinhole: no coefficients
  kRadtan,       // k1, k2, p1, p2 [, k3] (OpenCV plumb_bob)
  kEquidistant,  // k1, k2, k3, k4 (Kannala-Brandt, OpenCV fisheye)
};

struct DistortionModel {
  DistortionType type = DistortionType::kNone;
  std::vector<double> coefficients;
};

/// Name used in files ("none", "radtan", "equidistant").
std::string_view to_string(DistortionType type);
std::optional<DistortionType> distortion_type_from_string(std::string_view name);

enum class ImageEncoding { kRgb8, kBgr8, kMono8, kDepth16, kDepth32f };

/// "rgb8", "bgr8", "mono8", "depth16", "depth32f".
std::string_view to_string(ImageEncoding encoding);
std::optional<ImageEncoding> image_encoding_from_string(std::string_view name);
size_t bytes_per_pixel(ImageEncoding encoding);

struct ImageMessage {
  Timestamp timestamp;
  std::string frame_id;
  uint32_t width = 0;
  uint32_t height = 0;
  ImageEncoding encoding = ImageEncoding::kMono8;
  std::vector<uint8_t> data;  // row-major, no padding: width * height * bytes_per_pixel(encoding)
  std::optional<CameraIntrinsics> intrinsics;
  std::optional<DistortionModel> distortion;
};

enum class GnssFixType { kNoFix, kFix2d, kFix3d, kRtkFloat, kRtkFixed };

/// "NO_FIX", "FIX_2D", "FIX_3D", "RTK_FLOAT", "RTK_FIXED" as in the spec.
std::string_view to_string(GnssFixType fix_type);
/// The fix type a name of to_string() stands for; none for any other text.
std::optional<GnssFixType> gnss_fix_type_from_string(std::string_view name);

struct GnssMessage {
  Timestamp timestamp;
  double latitude = 0.0;   // WGS84 degrees
  double longitude = 0.0;  // WGS84 degrees
  double altitude = 0.0;   // meters above the ellipsoid
  GnssFixType fix_type = GnssFixType::kNoFix;
  std::optional<Eigen::Matrix3d> position_covariance;  // m^2, ENU
  uint32_t satellites_used = 0;
  float hdop = 0.0F;

  GeodeticPoint geodetic() const { return {latitude, longitude, altitude}; }
};

struct WheelOdometryMessage {
  Timestamp timestamp;
  std::string frame_id;
  double left_distance = 0.0;     // meters, cumulative
  double right_distance = 0.0;    // meters, cumulative
  double wheel_separation = 0.0;  // meters, > 0
  double wheel_radius = 0.0;      // meters, 0 when unknown
};

struct RadarTarget {
  float range = 0.0F;            // meters, >= 0
  float azimuth = 0.0F;          // radians, [-pi, pi]
  float elevation = 0.0F;        // radians, [-pi/2, pi/2]
  float radial_velocity = 0.0F;  // m/s, positive = moving away
  float rcs = 0.0F;              // dBsm
};

struct RadarMessage {
  Timestamp timestamp;
  std::string frame_id;
  std::vector<RadarTarget> targets;  // may be empty (nothing detected)
};

/// What a rangefinder emits (sensor_msgs/Range's radiation_type).
enum class RangeRadiation : uint8_t { kUltrasound = 0, kInfrared = 1 };

/// One reading of a single-beam rangefinder (ultrasonic, infrared): the distance to the nearest
/// object within a cone of full angle field_of_view about the sensor frame's +x axis (as
/// sensor_msgs/Range). A range of +inf says nothing was within max_range, -inf that something
/// was nearer than min_range (REP 117); a finite range lies in [min_range, max_range].
struct RangeMessage {
  Timestamp timestamp;
  std::string frame_id;
  RangeRadiation radiation = RangeRadiation::kUltrasound;
  float field_of_view = 0.0F;  // radians, full cone angle, (0, pi)
  float min_range = 0.0F;      // meters, >= 0
  float max_range = 0.0F;      // meters, > min_range
  float range = 0.0F;          // meters, or +-inf (above)
  float variance = 0.0F;       // m^2, 0 when unknown
};

/// One object a detector found in a camera image (as vision_msgs/Detection2D): its class, the
/// detector's confidence, its axis-aligned box in pixels (OpenCV convention: integer
/// coordinates are pixel centres; x right, y down) and optionally a tracker's id and an
/// instance mask over the box.
struct Detection2D {
  std::string class_name;  // the detector's label, e.g. "person", "car", "forklift"
  float score = 1.0F;      // [0, 1]
  float x_min = 0.0F, y_min = 0.0F, x_max = 0.0F, y_max = 0.0F;  // pixels, x_min <= x_max, y_min <= y_max
  int64_t track_id = -1;   // the same object in other frames; -1 when not tracked
  /// Instance mask (optional): mask_width x mask_height bytes, row-major, stretched over the
  /// box; non-zero where the object is. Empty: the whole box.
  uint32_t mask_width = 0;
  uint32_t mask_height = 0;
  std::vector<uint8_t> mask;
};

/// A segmentation's "no class" value (a pixel the segmenter left unlabelled).
inline constexpr uint8_t kUnlabelledPixel = 255;

/// A vision pipeline's output for one camera image (HIP-0081): object detections and/or a dense
/// semantic segmentation, sent on the camera's sensor name with the image's timestamp (camera
/// clock) and size, which is how the Session matches it to that image.
struct DetectionsMessage {
  Timestamp timestamp;
  std::string frame_id;
  uint32_t image_width = 0;   // the image the boxes are in, pixels
  uint32_t image_height = 0;
  std::vector<Detection2D> detections;  // may be empty (nothing detected: the image is checked)
  /// Dense segmentation (optional, as a sensor_msgs/Image label image): empty, or one class id
  /// per pixel (image_width x image_height, row-major), an index into segmentation_classes;
  /// kUnlabelledPixel (255) where the segmenter gives no class.
  std::vector<uint8_t> segmentation;
  /// The label table: the name of each class id ("floor", "wall", "person", ...), at most 255.
  std::vector<std::string> segmentation_classes;
};

/// Any of the eight sensor messages, as the Frontend and the sensor log carry them.
using SensorMessage = std::variant<ImuMessage, PointCloudMessage, ImageMessage, GnssMessage, WheelOdometryMessage, RadarMessage, RangeMessage,
                                   DetectionsMessage>;

Timestamp timestamp_of(const SensorMessage& message);
/// "imu", "point_cloud", "image", "gnss", "wheel_odometry", "radar", "range", "detections".
std::string_view modality_name(const SensorMessage& message);

}  // namespace hanzo::fusion::msgs
