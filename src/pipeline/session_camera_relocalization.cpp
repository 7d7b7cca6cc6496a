// Session::relocalize with a visual landmark map: the newest left-camera images placed in a saved
// map, accepted when several agree (session.hpp, CameraRelocalizationRequest).

#include <algorithm>
#include <cmath>

#include <fmt/format.h>

#include "hanzo/fusion/core/logging.hpp"
#include "hanzo/fusion/pipeline/session.hpp"
#include "camera_odometry.hpp"

namespace hanzo::fusion::pipeline {
namespace {

Status validate(const CameraRelocalizationRequest& request) {
  if (request.frames < 1 || request.frames > Session::kRecentCameraImages) {
    return Error(fmt::format("invalid: frames must be in 1..{} (the images the session keeps), got {}", Session::kRecentCameraImages, request.frames));
  }
  if (request.min_agreeing_frames < 1 || request.min_agreeing_frames > request.frames) {
    return Error(fmt::format("invalid: min_agreeing_frames must be in 1..frames ({}), got {}", request.frames, request.min_agreeing_frames));
  }
  if (!(request.agreement_m >= 0.0) || !(request.agreement_rad >= 0.0) || !std::isfinite(request.agreement_m) || !std::isfinite(request.agreement_rad)) {
    return Error("invalid: agreement_m and agreement_rad must be finite and >= 0");
  }
  return ok_status();
}

bool agree(const SE3& a, const SE3& b, const CameraRelocalizationRequest& request) {
  const SE3 difference = a.inverse() * b;
  return difference.translation().norm() <= request.agreement_m && difference.rotation().log().norm() <= request.agreement_rad;
}

// Each placement's inliers or why it was not placed, for a refusal's message.
std::string describe(const std::vector<CameraPlacement>& placements) {
  std::string text;
  for (const CameraPlacement& placement : placements) {
    if (!text.empty()) text += "; ";
    text += placement.placed ? fmt::format("image at {:.3f} s: {} inliers (map keyframe {})", placement.time.seconds(), placement.inliers, placement.map_keyframe)
                             : fmt::format("image at {:.3f} s: {}", placement.time.seconds(), placement.reason);
  }
  return text;
}

}  // namespace

Result<CameraRelocalizationOutcome> Session::relocalize(const msgs::VisualLandmarkLayer& map, const CameraRelocalizationRequest& request) {
  HANZO_RETURN_IF_ERROR(validate(request));
  if (!camera_odometry_) return Error("not_ready: the session has no camera with visual odometry");
  if (!camera_odometry_->metric() && !camera_odometry_->visual_inertial() && !frontend_->has_imu()) {
    return Error("invalid: a single camera without an IMU has no metric scale: the session's world cannot be placed in a metric map "
                 "(stereo, RGB-D or frontend.type msckf can)");
  }
  update_backend();
  if (!latest_keyframe_) return Error("not_ready: the session has no keyframe yet");
  vision::MapRelocalizerConfig relocalizer_config = request.relocalizer;
  if (!relocalizer_config.extractor && map.descriptor_type != "orb") {
    const auto& own = camera_odometry_->extractor();
    if (!own || own->name() != map.descriptor_type) {
      return Error(fmt::format("invalid: the map's landmarks carry {} descriptors, the visual odometry extracts {}", map.descriptor_type,
                               own ? own->name() : std::string("KLT corners (frontend.type msckf)")));
    }
    relocalizer_config.extractor = own;
  }
  Result<vision::MapRelocalizer> relocalizer =
      vision::MapRelocalizer::create(map, camera_odometry_->rigs()[0].left_camera, std::move(relocalizer_config));
  if (!relocalizer) return Error("invalid: " + relocalizer.error().message);

  // The newest images the Frontend has a pose for, each placed on its own.
  CameraRelocalizationOutcome outcome;
  for (auto it = recent_camera_images_.rbegin(); it != recent_camera_images_.rend() && static_cast<int>(outcome.placements.size()) < request.frames; ++it) {
    const std::optional<SE3> T_world_body = frontend_->pose_at(it->first);
    if (!T_world_body) continue;
    CameraPlacement placement;
    placement.time = it->first;
    Result<vision::MapRelocalization> found = relocalizer->relocalize(it->second);
    if (found) {
      placement.placed = true;
      placement.T_map_camera = found->T_world_camera;
      placement.T_map_world = found->T_world_camera * camera_odometry_->T_body_left().inverse() * T_world_body->inverse();
      placement.inliers = found->inliers;
      placement.map_keyframe = found->keyframe;
      placement.place_score = found->score;
      outcome.place_recognition = found->place_recognition;
    } else {
      placement.reason = found.error().message;
    }
    outcome.placements.push_back(std::move(placement));
  }
  if (outcome.placements.empty()) return Error("not_ready: no camera image with a pose from the session yet");
  if (static_cast<int>(outcome.placements.size()) < request.min_agreeing_frames) {
    return Error(fmt::format("not_ready: {} posed camera images, {} must agree", outcome.placements.size(), request.min_agreeing_frames));
  }

  // The placement that most others agree with (ties: the most inliers) is accepted when enough do.
  const CameraPlacement* best = nullptr;
  int best_agreeing = 0;
  for (const CameraPlacement& candidate : outcome.placements) {
    if (!candidate.placed) continue;
    const auto agreeing = static_cast<int>(std::count_if(outcome.placements.begin(), outcome.placements.end(), [&](const CameraPlacement& other) {
      return other.placed && agree(candidate.T_map_world, other.T_map_world, request);
    }));
    if (best == nullptr || agreeing > best_agreeing || (agreeing == best_agreeing && candidate.inliers > best->inliers)) {
      best = &candidate;
      best_agreeing = agreeing;
    }
  }
  const auto placed = std::count_if(outcome.placements.begin(), outcome.placements.end(), [](const CameraPlacement& p) { return p.placed; });
  if (best == nullptr || best_agreeing < request.min_agreeing_frames) {
    return Error(fmt::format("not_found: {} of {} images placed, at most {} in agreement ({} needed): {}", placed, outcome.placements.size(), best_agreeing,
                             request.min_agreeing_frames, describe(outcome.placements)));
  }
  outcome.T_map_world = best->T_map_world;
  for (CameraPlacement& placement : outcome.placements) placement.agrees = placement.placed && agree(outcome.T_map_world, placement.T_map_world, request);
  outcome.agreeing_frames = best_agreeing;
  outcome.keyframe_id = latest_keyframe_->keyframe_id;
  HANZO_ASSIGN_OR_RETURN(outcome.correction_m, move_world_onto_map(outcome.T_map_world));
  logger()->info("session: relocalized in the visual map (moved {:.2f} m; {} of {} images agree, {} inliers)", outcome.correction_m,
                 outcome.agreeing_frames, outcome.placements.size(), best->inliers);
  return outcome;
}

}  // namespace hanzo::fusion::pipeline
