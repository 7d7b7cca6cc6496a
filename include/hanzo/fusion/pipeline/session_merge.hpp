#pragma once
// merge_sessions(): the maps of several sessions that saw the same places joined into one
// optimized keyframe graph and one FusionMap, without an initial guess. Each map must carry its
// LiDAR keyframes (FusionMap::lidar_keyframes: the deskewed sweeps at their poses, as Sessions
// write them) or its visual keyframes (FusionMap::visual_landmarks: landmarks with descriptors
// and the keyframes that saw them); a map with both joins by either.
//
//  1. Candidates. LiDAR (Kim & Kim, Scan Context, IROS 2018): every keyframe of a later map at
//     least query_spacing metres of path after the previous query is described and searched in
//     each earlier map's Scan Context database (ring key, then the full distance over all yaws).
//     Cameras: every visual keyframe of a later map, by its landmarks' descriptors, among each
//     earlier map's keyframes of the same descriptor type (bag of words for ORB maps, VLAD or
//     matched landmarks for learned ones; vision::LandmarkPlaceIndex).
//  2. Verification. LiDAR: the query's sweep is localized in the earlier map's points around the
//     candidate (lidar::MapLocalizer: 2D branch and bound within candidate_window metres and
//     candidate_angular_window of the candidate's pose turned by the descriptor's yaw, then 3D
//     registration and the free-space check; keyframes of one map lie several metres apart at
//     speed, so the query is rarely where the candidate is), then registered to the submap of the
//     candidate's neighbours (loop.submap_keyframes on each side) from there, coarse then fine
//     (lidar::register_to_submap; loop.max_rmse, loop.min_inlier_fraction, degeneracy).
//     Cameras: the query's landmarks matched to the candidate's and its neighbours', and the
//     similarity between the two maps' frames found by RANSAC over the 3D-3D pairs
//     (vision::LandmarkMapAligner: scale 1 unless a map is monocular, `scale_free`).
//  3. Joining: the maps join the merge one at a time, from the first. Each loop between a map
//     and a map already joined says where the map's frame lies in the merged one (and, for a
//     monocular map, its scale); the loops agreeing with the hypothesis most of them agree with
//     (each loop's keyframe placed by it within agreement_translation / agreement_rotation of
//     where the loop itself puts it, the scales within agreement_scale) join the map when there
//     are at least min_agreeing_loops and no disagreeing hypothesis has that many too (a place
//     symmetric under a turn: refused as ambiguous, not joined by the larger set); each round the
//     map with the most agreeing loops joins. Loops that disagree are dropped as perceptual
//     aliasing (streets and aisles alike); loops between maps that joined through others enter
//     the graph where they agree.
//  4. One graph: a pose node per keyframe of every map (LiDAR and visual in time order), between
//     factors along each map's keyframes (their relative poses in the map at the map's scale;
//     sigmas min + per metre, as LidarSlam's), the agreeing inter-session loops as between
//     factors under a DCS kernel, the first map's first keyframe held; initialized by chaining
//     the maps' similarities from the first map; batch Levenberg-Marquardt
//     (graph/batch_optimizer.hpp).
//  5. The merged map: the first map's metadata, frame and datum; every LiDAR keyframe at its
//     optimized pose in lidar_keyframes and every visual keyframe in visual_landmarks, each with
//     its source (the maps' ids, or the sources of a merged input); landmarks moved with the
//     first keyframe that saw them, uncertainties scaled with their map; points and 2D
//     occupancy rebuilt from the LiDAR keyframes (maps::MapBuilder at the first map's point voxel
//     and occupancy resolution); provenance with every map's input logs. The inputs' other layers
//     (splats, meshes, ...; visual landmarks of another descriptor type than the first visual
//     map's; points of maps without LiDAR keyframes) are not moved: listed in dropped_layers.
//
// Frames: every map z up (gravity-aligned, as Sessions make them) or, for camera maps without
// gravity, any frame (the similarity turns freely); the merged map is in the first map's frame
// and units. Failure: fewer than two maps, a map without keyframes of either kind, and a map that
// shares no place with the others (the error names it with its candidate and loop counts;
// nothing is merged then).

#include <cstddef>
#include <string>
#include <vector>

#include "hanzo/fusion/core/result.hpp"
#include "hanzo/fusion/core/se3.hpp"
#include "hanzo/fusion/lidar/lidar_odometry.hpp"
#include "hanzo/fusion/lidar/loop_closure.hpp"
#include "hanzo/fusion/lidar/map_localization.hpp"
#include "hanzo/fusion/maps/map_builder.hpp"
#include "hanzo/fusion/msgs/map_messages.hpp"
#include "hanzo/fusion/vision/landmark_map_alignment.hpp"

namespace hanzo::fusion::pipeline {

struct SessionMergeConfig {
  /// Scan Context and verification settings. Without a position prior a query is compared
  /// with the 50 keyframes of the nearest ring keys (a session's own search: 10).
  lidar::LoopClosureConfig loop = [] {
    lidar::LoopClosureConfig config;
    config.scan_context.candidates = 50;
    config.scan_context.exclude_recent = 0;
    return config;
  }();
  lidar::LidarOdometryConfig odometry;  ///< registration settings (map and source voxels)
  lidar::MapLocalizerConfig localizer;  ///< the candidates' windowed localization
  vision::LandmarkMapAlignmentConfig landmarks;  ///< visual keyframes' candidates and verification
  double candidate_window = 10.0;         ///< m, +- around the candidate's position
  double candidate_angular_window = 0.3;  ///< rad, +- around the descriptor's heading
  double query_spacing = 1.0;           ///< m of path between a map's query keyframes
  std::size_t min_agreeing_loops = 3;   ///< loops that must agree to join two maps
  double agreement_translation = 1.5;   ///< m
  double agreement_rotation = 0.05;     ///< rad
  double agreement_scale = 0.1;         ///< |log of the scales' ratio| (monocular maps)
  /// Between-factor sigmas along a map's keyframes: min + per_meter x their distance.
  double min_translation_sigma = 0.02;       ///< m
  double translation_sigma_per_meter = 0.002;
  double min_rotation_sigma = 0.002;         ///< rad
  double rotation_sigma_per_meter = 0.0001;  ///< rad/m
  double loop_translation_sigma = 0.05;      ///< m
  double loop_rotation_sigma = 0.005;        ///< rad
  /// DCS phi of the inter-session loops: large, because the sessions' drift puts a correct loop
  /// far off the initial graph; step 3 keeps the wrong ones out.
  double loop_dcs_phi = 1e5;
  /// The merged map's layers built from the keyframes; the point voxel and occupancy resolution
  /// are the first map's when it has those layers.
  maps::MapBuilderConfig map;

  Status validate() const;
};

/// How a map joined the merge.
struct SessionJoin {
  std::size_t map = 0;        ///< index of the map
  std::size_t joined_to = 0;  ///< index of the joined map with the most of its agreeing loops
  SE3 T_joined_map;           ///< the later map's frame in the earlier one's (consensus loop)
  double scale = 1.0;         ///< the earlier map's units per the later map's unit (1 unless monocular)
  std::size_t loops = 0;      ///< agreeing loops that joined it (with joined_to and other joined maps)
};

struct SessionMergeResult {
  msgs::FusionMap merged;
  std::vector<SE3> T_merged_map;     ///< each map's frame in the merged one before optimization
  std::vector<double> merged_scale;  ///< each map's scale in the merged one (1 unless monocular)
  std::vector<SessionJoin> joins;    ///< one per map but the first, in the order they joined
  std::size_t queries = 0;           ///< LiDAR keyframes searched in other maps
  std::size_t candidates = 0;        ///< Scan Context matches below loop.scan_context.max_distance
  std::size_t verified = 0;          ///< of which registration verified
  std::size_t visual_queries = 0;    ///< visual keyframes searched in other maps
  std::size_t visual_verified = 0;   ///< of which landmark alignment verified
  std::size_t inter_session_loops = 0;  ///< of which agreeing with the joins (in the graph)
  std::size_t keyframes = 0;
  double initial_chi2 = 0.0, final_chi2 = 0.0;
  int iterations = 0;
  std::vector<std::string> dropped_layers;  ///< layers of the inputs not moved (step 5)
};

Result<SessionMergeResult> merge_sessions(const std::vector<msgs::FusionMap>& maps, const SessionMergeConfig& config = {});

}  // namespace hanzo::fusion::pipeline
