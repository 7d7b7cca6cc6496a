#include "hanzo/fusion/msgs/estimate_messages.hpp"
#include "hanzo/fusion/msgs/sensor_messages.hpp"

#include <array>
#include <utility>

#include "hanzo/fusion/core/enum_names.hpp"

namespace hanzo::fusion::msgs {
namespace {

constexpr EnumNames<DistortionType, 3> kDistortionNames{{
    {DistortionType::kNone, "none"}, {DistortionType::kRadtan, "radtan"}, {DistortionType::kEquidistant, "equidistant"}}};

constexpr EnumNames<ImageEncoding, 5> kEncodingNames{{{ImageEncoding::kRgb8, "rgb8"},
                                                                                    {ImageEncoding::kBgr8, "bgr8"},
                                                                                    {ImageEncoding::kMono8, "mono8"},
                                                                                    {ImageEncoding::kDepth16, "depth16"},
                                                                                    {ImageEncoding::kDepth32f, "depth32f"}}};

}  // namespace

std::string_view to_string(DistortionType type) { return enum_name(kDistortionNames, type); }
std::optional<DistortionType> distortion_type_from_string(std::string_view name) { return enum_from_name(kDistortionNames, name); }

std::string_view to_string(ImageEncoding encoding) { return enum_name(kEncodingNames, encoding); }
std::optional<ImageEncoding> image_encoding_from_string(std::string_view name) { return enum_from_name(kEncodingNames, name); }

size_t bytes_per_pixel(ImageEncoding encoding) {
  switch (encoding) {
    case ImageEncoding::kRgb8:
    case ImageEncoding::kBgr8: return 3;
    case ImageEncoding::kMono8: return 1;
    case ImageEncoding::kDepth16: return 2;
    case ImageEncoding::kDepth32f: return 4;
  }
  return 0;
}

std::string_view to_string(GnssFixType fix_type) {
  switch (fix_type) {
    case GnssFixType::kNoFix: return "NO_FIX";
    case GnssFixType::kFix2d: return "FIX_2D";
    case GnssFixType::kFix3d: return "FIX_3D";
    case GnssFixType::kRtkFloat: return "RTK_FLOAT";
    case GnssFixType::kRtkFixed: return "RTK_FIXED";
  }
  return "invalid";
}

std::optional<GnssFixType> gnss_fix_type_from_string(std::string_view name) {
  for (GnssFixType type : {GnssFixType::kNoFix, GnssFixType::kFix2d, GnssFixType::kFix3d, GnssFixType::kRtkFloat, GnssFixType::kRtkFixed}) {
    if (to_string(type) == name) return type;
  }
  return std::nullopt;
}

std::string_view to_string(TrackingState state) {
  switch (state) {
    case TrackingState::kUnspecified: return "UNSPECIFIED";
    case TrackingState::kInitializing: return "INITIALIZING";
    case TrackingState::kTracking: return "TRACKING";
    case TrackingState::kDegraded: return "DEGRADED";
    case TrackingState::kLost: return "LOST";
  }
  return "invalid";
}

std::string_view to_string(HealthState state) {
  switch (state) {
    case HealthState::kOk: return "ok";
    case HealthState::kDegraded: return "degraded";
    case HealthState::kLost: return "lost";
  }
  return "invalid";
}

std::string_view to_string(HealthReason reason) {
  switch (reason) {
    case HealthReason::kNone: return "";
    case HealthReason::kTimeout: return "timeout";
    case HealthReason::kGated: return "gated";
    case HealthReason::kNoFix: return "no_fix";
    case HealthReason::kDegenerateGeometry: return "degenerate_geometry";
    case HealthReason::kWeather: return "weather";
    case HealthReason::kSlip: return "slip";
    case HealthReason::kNotRegistered: return "not_registered";
    case HealthReason::kNotFused: return "not_fused";
    case HealthReason::kDark: return "dark";
    case HealthReason::kGlare: return "glare";
    case HealthReason::kMotionBlur: return "motion_blur";
    case HealthReason::kFewFeatures: return "few_features";
  }
  return "invalid";
}

Timestamp timestamp_of(const SensorMessage& message) {
  return std::visit([](const auto& m) { return m.timestamp; }, message);
}

std::string_view modality_name(const SensorMessage& message) {
  constexpr std::array<std::string_view, 8> kNames{"imu", "point_cloud", "image", "gnss", "wheel_odometry", "radar", "range", "detections"};
  static_assert(kNames.size() == std::variant_size_v<SensorMessage>);
  return kNames[message.index()];
}

}  // namespace hanzo::fusion::msgs
