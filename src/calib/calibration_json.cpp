// The JSON of calibration results (calibration_json.hpp).
#include "hanzo/fusion/calib/calibration_json.hpp"

namespace hanzo::fusion::calib {

using nlohmann::json;

json motion_calibration_to_json(const MotionCalibrationSummary& summary) {
  const auto vector = [](const Eigen::Vector3d& v) { return json::array({v.x(), v.y(), v.z()}); };
  const SensorCalibration& result = summary.calibration;
  const Eigen::Vector4d& q = result.rotation_wxyz;
  return {{"sensor", result.sensor},
          {"rotation_wxyz", json::array({q[0], q[1], q[2], q[3]})},
          {"translation", vector(result.translation)},
          {"time_offset_ns", result.time_offset.nanoseconds()},
          {"translation_estimated", summary.translation_estimated},
          {"unobservable_translation_axis",
           summary.unobservable_translation_axis ? vector(*summary.unobservable_translation_axis) : json(nullptr)},
          {"gyro_bias", vector(summary.gyro_bias)},
          {"pairs", summary.pairs},
          {"rotation_pairs", summary.rotation_pairs},
          {"outlier_pairs", summary.outlier_pairs},
          {"rotation_residual_rms_deg", summary.rotation_residual_rms_deg},
          {"translation_residual_rms_m", summary.translation_residual_rms_m},
          {"rotation_axis_spread", summary.rotation_axis_spread},
          {"translation_observability", summary.translation_observability},
          {"calibration_yaml", to_yaml(Calibration{{result}})}};
}

json camera_calibration_to_json(const CameraCalibrationResult& result) {
  json views = json::array();
  for (const CameraCalibrationView& view : result.views) {
    if (!view.board_found) continue;
    views.push_back({{"timestamp_ns", view.time.nanoseconds()}, {"used", view.used}, {"rms_px", view.rms_px}});
  }
  const msgs::CameraIntrinsics& k = result.intrinsics;
  return {{"intrinsics", {{"fx", k.fx}, {"fy", k.fy}, {"cx", k.cx}, {"cy", k.cy}, {"width", k.width}, {"height", k.height}}},
          {"intrinsics_std", result.intrinsics_std ? json(*result.intrinsics_std) : json(nullptr)},
          {"distortion_model", msgs::to_string(result.distortion.type)},
          {"distortion_coeffs", result.distortion.coefficients},
          {"rms_px", result.rms_px},
          {"images", result.views_total},
          {"views_found", result.views_found},
          {"views_used", result.views_used},
          {"views", std::move(views)}};
}

}  // namespace hanzo::fusion::calib
