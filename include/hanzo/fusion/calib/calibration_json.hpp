#pragma once
// The JSON shapes of calibration results: the answers of POST /v1/calibrate and of
// `hanzo-fusion calib motion|camera --json` (docs/calibration.md; docs/openapi.json
// "Calibration", "CameraCalibration").
#include <nlohmann/json.hpp>

#include "hanzo/fusion/calib/camera_calibration.hpp"
#include "hanzo/fusion/calib/motion_calibration.hpp"

namespace hanzo::fusion::calib {

/// {"sensor", "rotation_wxyz", "translation", "time_offset_ns", "translation_estimated",
///  "unobservable_translation_axis" (null or a unit vector), "gyro_bias", "pairs",
///  "rotation_pairs", "outlier_pairs", "rotation_residual_rms_deg", "translation_residual_rms_m",
///  "rotation_axis_spread", "translation_observability", "calibration_yaml" (the entry in the
///  calibration file's layout)}.
nlohmann::json motion_calibration_to_json(const MotionCalibrationSummary& summary);

/// {"intrinsics": {"fx", "fy", "cx", "cy", "width", "height"}, "intrinsics_std" (null or one
///  sigma of fx, fy, cx, cy in px), "distortion_model", "distortion_coeffs", "rms_px", "images",
///  "views_found", "views_used", "views": [{"timestamp_ns", "used", "rms_px"} of each image where
///  the board was found]}. The keys are those of a camera's calibration-file entry.
nlohmann::json camera_calibration_to_json(const CameraCalibrationResult& result);

}  // namespace hanzo::fusion::calib
