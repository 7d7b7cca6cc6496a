#pragma once
// The JSON shape of a motion calibration's result: the answer of POST /v1/calibrate and of
// `hanzo-fusion calib motion --json` (docs/calibration.md; docs/openapi.json "Calibration").
#include <nlohmann/json.hpp>

#include "hanzo/fusion/calib/motion_calibration.hpp"

namespace hanzo::fusion::service {

/// {"sensor", "rotation_wxyz", "translation", "time_offset_ns", "translation_estimated",
///  "unobservable_translation_axis" (null or a unit vector), "gyro_bias", "pairs",
///  "rotation_pairs", "outlier_pairs", "rotation_residual_rms_deg", "translation_residual_rms_m",
///  "rotation_axis_spread", "translation_observability", "calibration_yaml" (the entry in the
///  calibration file's layout)}.
nlohmann::json motion_calibration_to_json(const calib::MotionCalibrationSummary& summary);

}  // namespace hanzo::fusion::service
