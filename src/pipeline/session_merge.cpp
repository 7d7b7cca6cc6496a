#include "hanzo/fusion/pipeline/session_merge.hpp"

#include <algorithm>
#include <cmath>
#include <iterator>
#include <map>
#include <optional>

#include <fmt/format.h>

#include "hanzo/fusion/core/logging.hpp"
#include "hanzo/fusion/graph/batch_optimizer.hpp"
#include "hanzo/fusion/graph/factor_graph.hpp"
#include "hanzo/fusion/graph/keys.hpp"
#include "hanzo/fusion/graph/pose_factors.hpp"
#include "hanzo/fusion/lidar/scan_context.hpp"
#include "hanzo/fusion/pipeline/map_merge.hpp"
#include "hanzo/fusion/vision/landmark_map_alignment.hpp"

namespace hanzo::fusion::pipeline {
namespace {

SE3 pose_of(const msgs::LidarKeyframe& keyframe) { return keyframe.T_world_lidar.to_se3(); }

/// x_to = scale * (T.rotation() * x_from) + T.translation(): one map's frame in another's, scaled
/// when a monocular map joins.
struct Similarity {
  double scale = 1.0;
  SE3 T;

  Eigen::Vector3d apply(const Eigen::Vector3d& point) const { return scale * (T.rotation() * point) + T.translation(); }
  /// A pose in the `from` frame as a pose in the `to` frame (its translation scaled).
  SE3 apply(const SE3& pose) const { return SE3(T.rotation() * pose.rotation(), apply(pose.translation())); }
  Similarity operator*(const Similarity& other) const { return {scale * other.scale, SE3(T.rotation() * other.T.rotation(), apply(other.T.translation()))}; }
  Similarity inverse() const {
    const SO3 R_inverse = T.rotation().inverse();
    return {1.0 / scale, SE3(R_inverse, -(R_inverse * T.translation()) / scale)};
  }
};

/// A keyframe of a map in the graph: a LiDAR keyframe or a visual one.
struct Node {
  enum class Kind { kLidar, kVisual } kind = Kind::kLidar;
  std::size_t index = 0;  ///< into the map's lidar_keyframes or visual_landmarks keyframes
  Timestamp time;
  SE3 T_map_sensor;
};

/// Every keyframe of a map, LiDAR and visual, in time order.
std::vector<Node> nodes_of(const msgs::FusionMap& map) {
  std::vector<Node> nodes;
  if (map.lidar_keyframes) {
    for (std::size_t k = 0; k < map.lidar_keyframes->keyframes.size(); ++k) {
      nodes.push_back({Node::Kind::kLidar, k, map.lidar_keyframes->keyframes[k].time, pose_of(map.lidar_keyframes->keyframes[k])});
    }
  }
  if (map.visual_landmarks) {
    for (std::size_t k = 0; k < map.visual_landmarks->keyframes.size(); ++k) {
      const msgs::VisualKeyframe& keyframe = map.visual_landmarks->keyframes[k];
      nodes.push_back({Node::Kind::kVisual, k, keyframe.time, keyframe.T_world_camera.to_se3()});
    }
  }
  std::stable_sort(nodes.begin(), nodes.end(), [](const Node& x, const Node& y) { return x.time < y.time; });
  return nodes;
}

/// For each keyframe of one kind, its node.
std::vector<std::size_t> node_of(const std::vector<Node>& nodes, Node::Kind kind) {
  std::vector<std::size_t> of;
  for (std::size_t n = 0; n < nodes.size(); ++n) {
    if (nodes[n].kind != kind) continue;
    if (of.size() <= nodes[n].index) of.resize(nodes[n].index + 1);
    of[nodes[n].index] = n;
  }
  return of;
}

/// A verified loop between node `candidate` of map a and node `query` of map b (a < b): b's
/// frame in a's as the loop places it.
struct Loop {
  std::size_t a = 0, candidate = 0, b = 0, query = 0;
  Similarity T_a_b;
  double rmse = 0.0;  ///< registration or landmark inlier RMSE (map a's units)
};

Result<graph::GaussianNoise> pose_noise(double translation_sigma, double rotation_sigma) {
  Eigen::VectorXd sigmas(6);
  sigmas << Eigen::Vector3d::Constant(translation_sigma), Eigen::Vector3d::Constant(rotation_sigma);
  return graph::GaussianNoise::from_sigmas(sigmas);
}

/// What a loop between a joining map and a map of the merge says: the joining map's frame in
/// the merged one, and the joining map's keyframe of the loop (in its own frame).
struct Placement {
  const Loop* loop = nullptr;
  Similarity T_merged_map;
  SE3 T_map_keyframe;
};

Placement placement(const Loop& loop, std::size_t joining, const Similarity& T_merged_other, const std::vector<std::vector<Node>>& nodes) {
  if (joining == loop.b) return {&loop, T_merged_other * loop.T_a_b, nodes[loop.b][loop.query].T_map_sensor};
  return {&loop, T_merged_other * loop.T_a_b.inverse(), nodes[loop.a][loop.candidate].T_map_sensor};
}

/// Whether `hypothesis` (the joining map's frame in the merged one) puts the placement's
/// keyframe where its loop does, at its scale; `slack` multiplies the tolerances.
bool agrees(const Similarity& hypothesis, const Placement& placement, const SessionMergeConfig& config, double slack = 1.0) {
  const SE3 difference = hypothesis.apply(placement.T_map_keyframe).inverse() * placement.T_merged_map.apply(placement.T_map_keyframe);
  return difference.translation().norm() <= slack * config.agreement_translation && difference.rotation().angle() <= slack * config.agreement_rotation &&
         std::abs(std::log(hypothesis.scale / placement.T_merged_map.scale)) <= slack * config.agreement_scale;
}

/// The largest set of placements agreeing with one of them, the hypothesis (the best-fitting set
/// of that size).
struct Agreement {
  const Placement* hypothesis = nullptr;
  std::vector<Placement> agreeing;
};

Agreement largest_agreeing(const std::vector<Placement>& placements, const SessionMergeConfig& config) {
  Agreement best;
  double best_rmse = 0.0;
  for (const Placement& hypothesis : placements) {
    std::vector<Placement> agreeing;
    double rmse = 0.0;
    for (const Placement& other : placements) {
      if (!agrees(hypothesis.T_merged_map, other, config)) continue;
      agreeing.push_back(other);
      rmse += other.loop->rmse;
    }
    if (agreeing.size() > best.agreeing.size() || (agreeing.size() == best.agreeing.size() && rmse < best_rmse)) {
      best = {&hypothesis, std::move(agreeing)};
      best_rmse = rmse;
    }
  }
  return best;
}

/// The placements that join a map to the merge: the largest agreeing set, when it has
/// min_agreeing_loops and no other hypothesis has that many too among the placements that
/// disagree with it, placing the map elsewhere (beyond three times the agreement tolerances: a
/// symmetric place seen from two sides, not the spread of one place's loops); else none, with
/// the reason.
std::vector<Placement> consistent(const std::vector<Placement>& placements, const SessionMergeConfig& config, std::string& reason) {
  Agreement best = largest_agreeing(placements, config);
  if (best.agreeing.size() < config.min_agreeing_loops) {
    reason = fmt::format("{} verified loops, at most {} agree", placements.size(), best.agreeing.size());
    return {};
  }
  std::vector<Placement> others;
  std::copy_if(placements.begin(), placements.end(), std::back_inserter(others),
               [&](const Placement& other) { return !agrees(best.hypothesis->T_merged_map, other, config); });
  const Agreement second = largest_agreeing(others, config);
  if (second.agreeing.size() >= config.min_agreeing_loops && !agrees(best.hypothesis->T_merged_map, *second.hypothesis, config, 3.0)) {
    reason = fmt::format("ambiguous: {} loops agree on one place, {} on another", best.agreeing.size(), second.agreeing.size());
    return {};
  }
  return best.agreeing;
}

/// The keyframes of map m around keyframe k, in k's frame.
std::vector<lidar::SubmapKeyframe> submap_around(const msgs::FusionMap& map, std::size_t k, int half) {
  const auto& keyframes = map.lidar_keyframes->keyframes;
  const SE3 T_k_world = pose_of(keyframes[k]).inverse();
  std::vector<lidar::SubmapKeyframe> submap;
  const std::size_t first = k >= static_cast<std::size_t>(half) ? k - static_cast<std::size_t>(half) : 0;
  const std::size_t last = std::min(keyframes.size() - 1, k + static_cast<std::size_t>(half));
  for (std::size_t j = first; j <= last; ++j) submap.push_back({&keyframes[j].points, T_k_world * pose_of(keyframes[j])});
  return submap;
}

/// The keyframes of `map` a query is made of: the first, then one every query_spacing of path.
std::vector<std::size_t> query_keyframes(const msgs::FusionMap& map, double spacing) {
  std::vector<std::size_t> queries;
  const auto& keyframes = map.lidar_keyframes->keyframes;
  double path = 0.0, last_query = 0.0;
  for (std::size_t k = 0; k < keyframes.size(); ++k) {
    if (k > 0) path += (pose_of(keyframes[k - 1]).inverse() * pose_of(keyframes[k])).translation().norm();
    if (queries.empty() || path - last_query >= spacing) {
      queries.push_back(k);
      last_query = path;
    }
  }
  return queries;
}

/// The map's points to localize candidates in: its point layer, else its keyframes' points.
Result<lidar::MapLocalizer> make_localizer(const msgs::FusionMap& map, const SessionMergeConfig& config) {
  std::vector<Eigen::Vector3f> points;
  if (map.points && !map.points->points.empty()) {
    points = map.points->points;
  } else {
    for (const msgs::LidarKeyframe& keyframe : map.lidar_keyframes->keyframes) {
      cloud::PointCloud cloud;
      cloud.positions = keyframe.points;
      const std::vector<Eigen::Vector3f> in_map = cloud::transformed(cloud, pose_of(keyframe)).positions;
      points.insert(points.end(), in_map.begin(), in_map.end());
    }
  }
  Result<lidar::MapLocalizer> localizer = lidar::MapLocalizer::create(std::move(points), config.localizer, config.odometry);
  if (!localizer) logger()->warn("session merge: map {}: candidates verified without localization ({})", map.map_id, localizer.error().message);
  return localizer;
}

/// The roll and pitch of a pose: its rotation without the heading (R_up_sensor).
SO3 level_part(const SE3& T_world_sensor) {
  const Eigen::Matrix3d R = T_world_sensor.rotation().matrix();
  return SO3::from_axis_angle(Eigen::Vector3d::UnitZ(), -std::atan2(R(1, 0), R(0, 0))) * T_world_sensor.rotation();
}

bool has_lidar_keyframes(const msgs::FusionMap& map) { return map.lidar_keyframes && !map.lidar_keyframes->keyframes.empty(); }
bool has_visual_keyframes(const msgs::FusionMap& map) { return map.visual_landmarks && !map.visual_landmarks->keyframes.empty(); }

/// Step 2 for LiDAR: verified loops of each later map's queries in each earlier map.
Status add_lidar_loops(const std::vector<msgs::FusionMap>& maps, const std::vector<std::vector<Node>>& nodes, const SessionMergeConfig& config,
                       SessionMergeResult& result, std::vector<Loop>& loops) {
  // Scan Context databases, one per map.
  std::vector<lidar::ScanContextDatabase> databases;
  std::vector<std::vector<lidar::ScanContext>> descriptors(maps.size());
  for (std::size_t m = 0; m < maps.size(); ++m) {
    databases.emplace_back(config.loop.scan_context);
    if (!has_lidar_keyframes(maps[m])) continue;
    const auto& keyframes = maps[m].lidar_keyframes->keyframes;
    descriptors[m].resize(keyframes.size());
    for (std::size_t k = 0; k < keyframes.size(); ++k) {
      cloud::PointCloud cloud;
      cloud.positions = keyframes[k].points;
      Result<lidar::ScanContext> descriptor = lidar::make_scan_context(cloud, config.loop.scan_context);
      if (!descriptor) continue;  // a keyframe with no point in range: never a candidate
      descriptors[m][k] = *descriptor;
      HANZO_RETURN_IF_ERROR(databases[m].add(k, std::move(descriptor).value()));
    }
  }
  std::vector<std::optional<Result<lidar::MapLocalizer>>> localizers(maps.size());  // made when first needed
  for (std::size_t b = 1; b < maps.size(); ++b) {
    if (!has_lidar_keyframes(maps[b])) continue;
    const auto& queries_of_b = maps[b].lidar_keyframes->keyframes;
    const std::vector<std::size_t> queries = query_keyframes(maps[b], config.query_spacing);
    const std::vector<std::size_t> nodes_of_b = node_of(nodes[b], Node::Kind::kLidar);
    for (std::size_t a = 0; a < b; ++a) {
      if (!has_lidar_keyframes(maps[a])) continue;
      const std::vector<std::size_t> nodes_of_a = node_of(nodes[a], Node::Kind::kLidar);
      for (const std::size_t q : queries) {
        if (descriptors[b][q].ring_key.size() == 0) continue;
        ++result.queries;
        Result<std::optional<lidar::ScanContextMatch>> match = databases[a].query(descriptors[b][q]);
        if (!match || !*match) continue;
        ++result.candidates;
        const auto c = static_cast<std::size_t>((*match)->id);
        const SE3 T_a_c = pose_of(maps[a].lidar_keyframes->keyframes[c]);
        SE3 guess(SO3::exp(Eigen::Vector3d(0, 0, (*match)->distance.yaw)), Eigen::Vector3d::Zero());
        if (!localizers[a]) localizers[a] = make_localizer(maps[a], config);
        if (*localizers[a]) {
          const lidar::MapLocalizationQuery query{T_a_c * guess, config.candidate_window, config.candidate_angular_window};
          const Result<lidar::MapLocalization> localized = (**localizers[a]).localize(queries_of_b[q].points, level_part(pose_of(queries_of_b[q])), query);
          if (!localized) continue;  // registration alone takes look-alike streets for the same one
          guess = T_a_c.inverse() * localized->T_map_sensor;
        }
        const Result<lidar::SubmapRegistration> registered =
            lidar::register_to_submap(submap_around(maps[a], c, config.loop.submap_keyframes), queries_of_b[q].points, guess, config.loop, config.odometry);
        if (!registered) continue;
        ++result.verified;
        const SE3 T_a_b = T_a_c * registered->T_submap_query * pose_of(queries_of_b[q]).inverse();
        loops.push_back({a, nodes_of_a[c], b, nodes_of_b[q], {1.0, T_a_b}, registered->inlier_rmse});
      }
    }
  }
  return ok_status();
}

/// Step 2 for cameras: every visual keyframe of a later map aligned with each earlier map of the
/// same descriptor type (vision::LandmarkMapAligner).
Status add_visual_loops(const std::vector<msgs::FusionMap>& maps, const std::vector<std::vector<Node>>& nodes, const SessionMergeConfig& config,
                        SessionMergeResult& result, std::vector<Loop>& loops) {
  std::vector<std::optional<vision::LandmarkMapAligner>> aligners(maps.size());  // made when first needed
  for (std::size_t b = 1; b < maps.size(); ++b) {
    if (!has_visual_keyframes(maps[b])) continue;
    const msgs::VisualLandmarkLayer& map_b = *maps[b].visual_landmarks;
    std::optional<cv::Mat> descriptors_b;
    const std::vector<std::size_t> nodes_of_b = node_of(nodes[b], Node::Kind::kVisual);
    for (std::size_t a = 0; a < b; ++a) {
      if (!has_visual_keyframes(maps[a]) || maps[a].visual_landmarks->descriptor_type != map_b.descriptor_type) continue;
      if (!aligners[a]) {
        Result<vision::LandmarkMapAligner> created = vision::LandmarkMapAligner::create(*maps[a].visual_landmarks, config.landmarks);
        if (!created) return Error(fmt::format("map {}: visual landmarks: {}", maps[a].map_id, created.error().message));
        aligners[a].emplace(std::move(*created));
      }
      if (!descriptors_b) {
        Result<cv::Mat> described = vision::landmark_descriptors(map_b);
        if (!described) return Error(fmt::format("map {}: visual landmarks: {}", maps[b].map_id, described.error().message));
        descriptors_b = std::move(*described);
      }
      const std::vector<std::size_t> nodes_of_a = node_of(nodes[a], Node::Kind::kVisual);
      for (std::size_t q = 0; q < map_b.keyframes.size(); ++q) {
        ++result.visual_queries;
        const Result<vision::LandmarkMapLoop> aligned = aligners[a]->align(map_b, *descriptors_b, q);
        if (!aligned) continue;
        ++result.visual_verified;
        loops.push_back({a, nodes_of_a[aligned->keyframe_a], b, nodes_of_b[q], {aligned->scale, aligned->T_a_b}, aligned->rmse});
      }
    }
  }
  return ok_status();
}

/// The id a map's own keyframes carry in the merged map: its map id, with its place among the
/// inputs when another input has the same id.
std::string own_source(const std::vector<msgs::FusionMap>& maps, std::size_t m) {
  const bool shared_id = std::count_if(maps.begin(), maps.end(), [&](const msgs::FusionMap& other) { return other.map_id == maps[m].map_id; }) > 1;
  return shared_id ? fmt::format("{}#{}", maps[m].map_id, m + 1) : maps[m].map_id;
}

/// For each of a layer's sources (or the map's own id when it has none), its index in `merged`
/// (appended when new).
std::vector<uint32_t> source_indices(const std::vector<std::string>& sources, const std::string& own, std::vector<std::string>& merged) {
  std::vector<uint32_t> indices;
  for (const std::string& source : sources.empty() ? std::vector<std::string>{own} : sources) {
    const auto found = std::find(merged.begin(), merged.end(), source);
    indices.push_back(static_cast<uint32_t>(found - merged.begin()));
    if (found == merged.end()) merged.push_back(source);
  }
  return indices;
}

/// Map m's visual landmarks appended to the merged layer: keyframes at their optimized poses
/// (`optimized`, one per keyframe), each landmark moved with the first keyframe that sees it
/// (the others by the map's similarity), uncertainties scaled.
void append_visual_layer(const msgs::VisualLandmarkLayer& input, const Similarity& T_merged_map, const std::vector<SE3>& optimized, const std::string& own,
                         msgs::VisualLandmarkLayer& merged) {
  const auto offset = static_cast<uint32_t>(merged.positions.size());
  std::vector<std::optional<std::size_t>> anchor(input.positions.size());
  for (std::size_t k = 0; k < input.keyframes.size(); ++k) {
    for (uint32_t landmark : input.keyframes[k].landmarks) {
      if (!anchor[landmark]) anchor[landmark] = k;
    }
  }
  for (std::size_t i = 0; i < input.positions.size(); ++i) {
    Eigen::Vector3d position = T_merged_map.apply(input.positions[i].cast<double>());
    if (anchor[i]) {
      const SE3 before = T_merged_map.apply(input.keyframes[*anchor[i]].T_world_camera.to_se3());
      position = optimized[*anchor[i]] * (before.inverse() * position);
    }
    merged.positions.push_back(position.cast<float>());
  }
  merged.descriptors.insert(merged.descriptors.end(), input.descriptors.begin(), input.descriptors.end());
  merged.float_descriptors.insert(merged.float_descriptors.end(), input.float_descriptors.begin(), input.float_descriptors.end());
  const bool with_std = !input.position_std.empty() && (offset == 0 || !merged.position_std.empty());
  if (!with_std) merged.position_std.clear();
  for (std::size_t i = 0; with_std && i < input.position_std.size(); ++i) merged.position_std.push_back(static_cast<float>(input.position_std[i] * T_merged_map.scale));
  const bool with_observations = !input.observations.empty() && (offset == 0 || !merged.observations.empty());
  if (!with_observations) merged.observations.clear();
  if (with_observations) merged.observations.insert(merged.observations.end(), input.observations.begin(), input.observations.end());
  const std::vector<uint32_t> sources = source_indices(input.sources, own, merged.sources);
  for (std::size_t k = 0; k < input.keyframes.size(); ++k) {
    msgs::VisualKeyframe keyframe = input.keyframes[k];
    keyframe.T_world_camera = msgs::Pose::from_se3(optimized[k]);
    for (uint32_t& landmark : keyframe.landmarks) landmark += offset;
    keyframe.source = sources.at(keyframe.source);
    merged.keyframes.push_back(std::move(keyframe));
  }
}

}  // namespace

Status SessionMergeConfig::validate() const {
  HANZO_RETURN_IF_ERROR(with_context(loop.validate(), "loop"));
  HANZO_RETURN_IF_ERROR(with_context(map.validate(), "map"));
  HANZO_RETURN_IF_ERROR(with_context(landmarks.validate(), "landmarks"));
  for (const auto& [name, value] : {std::pair{"query_spacing", query_spacing}, {"agreement_translation", agreement_translation},
                                    {"agreement_rotation", agreement_rotation}, {"agreement_scale", agreement_scale}, {"min_translation_sigma", min_translation_sigma},
                                    {"min_rotation_sigma", min_rotation_sigma}, {"loop_translation_sigma", loop_translation_sigma},
                                    {"loop_rotation_sigma", loop_rotation_sigma}, {"loop_dcs_phi", loop_dcs_phi}}) {
    if (!(value > 0)) return Error(fmt::format("{}: {} (expected > 0)", name, value));
  }
  if (!(translation_sigma_per_meter >= 0) || !(rotation_sigma_per_meter >= 0)) return Error("sigma per meter: expected >= 0");
  if (min_agreeing_loops < 1) return Error("min_agreeing_loops: 0 (expected >= 1)");
  return ok_status();
}

Result<SessionMergeResult> merge_sessions(const std::vector<msgs::FusionMap>& maps, const SessionMergeConfig& config) {
  HANZO_RETURN_IF_ERROR(config.validate());
  if (maps.size() < 2) return Error(fmt::format("session merge: {} map(s) given, two or more needed", maps.size()));
  std::vector<std::vector<Node>> nodes;
  for (const msgs::FusionMap& map : maps) {
    if (!has_lidar_keyframes(map) && !has_visual_keyframes(map)) {
      return Error(fmt::format("map {}: no LiDAR keyframes (lidar_keyframes layer) or visual keyframes (visual_landmarks layer) to join by", map.map_id));
    }
    nodes.push_back(nodes_of(map));
  }
  SessionMergeResult result;

  // 1-2. Candidates and verified loops between the maps, LiDAR and camera.
  std::vector<Loop> loops;
  HANZO_RETURN_IF_ERROR(add_lidar_loops(maps, nodes, config, result, loops));
  HANZO_RETURN_IF_ERROR(add_visual_loops(maps, nodes, config, result, loops));

  // 3. The maps join the merge one at a time, from the first: each round the map whose loops
  // with the maps joined so far agree best on its place.
  std::vector<std::optional<Similarity>> T_merged_map(maps.size());
  T_merged_map[0] = Similarity{};
  std::vector<const Loop*> graph_loops;
  std::map<std::size_t, std::string> refusals;  // map -> why it did not join (with loops)
  while (true) {
    std::optional<std::size_t> best_map;
    std::vector<Placement> best_placements;
    for (std::size_t m = 0; m < maps.size(); ++m) {
      if (T_merged_map[m]) continue;
      std::vector<Placement> placements;
      for (const Loop& loop : loops) {
        const std::size_t other = loop.a == m ? loop.b : loop.b == m ? loop.a : m;
        if (other != m && T_merged_map[other]) placements.push_back(placement(loop, m, *T_merged_map[other], nodes));
      }
      std::string reason;
      std::vector<Placement> kept = consistent(placements, config, reason);
      if (kept.empty()) {
        if (!placements.empty()) refusals[m] = fmt::format("{}: {}", maps[m].map_id, reason);
        continue;
      }
      refusals.erase(m);
      if (kept.size() > best_placements.size()) {
        best_map = m;
        best_placements = std::move(kept);
      }
    }
    if (!best_map) break;
    // The consensus: the agreeing placement with the lowest RMSE; reported against the joined
    // map with the most of its loops.
    const Placement& consensus = *std::min_element(best_placements.begin(), best_placements.end(),
                                                   [](const Placement& x, const Placement& y) { return x.loop->rmse < y.loop->rmse; });
    T_merged_map[*best_map] = consensus.T_merged_map;
    std::map<std::size_t, std::size_t> loops_with;
    for (const Placement& kept : best_placements) {
      graph_loops.push_back(kept.loop);
      ++loops_with[kept.loop->a == *best_map ? kept.loop->b : kept.loop->a];
    }
    const std::size_t joined_to = std::max_element(loops_with.begin(), loops_with.end(), [](const auto& x, const auto& y) { return x.second < y.second; })->first;
    const Similarity T_joined_map = T_merged_map[joined_to]->inverse() * consensus.T_merged_map;
    result.joins.push_back({*best_map, joined_to, T_joined_map.T, T_joined_map.scale, best_placements.size()});
    logger()->info("session merge: {} joined ({} agreeing loops, most with {}, scale {:.4f})", maps[*best_map].map_id, best_placements.size(),
                   maps[joined_to].map_id, T_joined_map.scale);
  }
  std::vector<std::string> unjoined, reasons;
  for (std::size_t m = 0; m < maps.size(); ++m) {
    if (T_merged_map[m]) continue;
    unjoined.push_back(maps[m].map_id);
    if (refusals.count(m)) reasons.push_back(refusals[m]);
  }
  if (!unjoined.empty()) {
    std::vector<std::string> counts;
    if (result.queries > 0 || result.visual_queries == 0) {
      counts.push_back(fmt::format("{} queries, {} Scan Context candidates, {} verified by registration", result.queries, result.candidates, result.verified));
    }
    if (result.visual_queries > 0) counts.push_back(fmt::format("{} visual keyframes searched, {} aligned by their landmarks", result.visual_queries, result.visual_verified));
    return Error(fmt::format("session merge: {} not joined to {} ({}; {})", fmt::join(unjoined, ", "), maps[0].map_id, fmt::join(counts, "; "),
                             reasons.empty() ? fmt::format("no verified loop with the maps joined: no place shared for certain") : fmt::format("{}", fmt::join(reasons, "; "))));
  }
  // Loops between maps joined through others, where they agree with the joins, join the graph too.
  for (const Loop& loop : loops) {
    if (std::find(graph_loops.begin(), graph_loops.end(), &loop) != graph_loops.end()) continue;
    if (agrees(*T_merged_map[loop.b], placement(loop, loop.b, *T_merged_map[loop.a], nodes), config)) graph_loops.push_back(&loop);
  }
  for (const auto& entry : T_merged_map) {
    result.T_merged_map.push_back(entry->T);
    result.merged_scale.push_back(entry->scale);
  }

  // 4. One graph over every keyframe, each map's at its join's scale.
  std::vector<std::size_t> first_node(maps.size(), 0);
  graph::FactorGraph graph;
  graph::Values values;
  std::size_t node = 0;
  for (std::size_t m = 0; m < maps.size(); ++m) {
    first_node[m] = node;
    for (std::size_t k = 0; k < nodes[m].size(); ++k, ++node) {
      values.insert(graph::X(node), T_merged_map[m]->apply(nodes[m][k].T_map_sensor));
      if (k == 0) continue;
      const SE3 relative = T_merged_map[m]->apply(nodes[m][k - 1].T_map_sensor).inverse() * T_merged_map[m]->apply(nodes[m][k].T_map_sensor);
      const double distance = relative.translation().norm();
      graph::GaussianNoise noise;
      HANZO_ASSIGN_OR_RETURN(noise, pose_noise(config.min_translation_sigma + config.translation_sigma_per_meter * distance,
                                               config.min_rotation_sigma + config.rotation_sigma_per_meter * distance));
      graph.emplace<graph::BetweenFactorSE3>(graph::X(node - 1), graph::X(node), relative, std::move(noise));
    }
  }
  result.keyframes = node;
  graph::GaussianNoise loop_noise;
  HANZO_ASSIGN_OR_RETURN(loop_noise, pose_noise(config.loop_translation_sigma, config.loop_rotation_sigma));
  for (const Loop* loop : graph_loops) {
    // The query's pose relative to the candidate's as the loop places it, in merged units.
    const Similarity& T_merged_a = *T_merged_map[loop->a];
    const SE3 T_candidate_query = T_merged_a.apply(nodes[loop->a][loop->candidate].T_map_sensor).inverse() *
                                  (T_merged_a * loop->T_a_b).apply(nodes[loop->b][loop->query].T_map_sensor);
    graph.emplace_robust<graph::BetweenFactorSE3>(graph::RobustKernel{graph::RobustKernel::Type::kDcs, config.loop_dcs_phi},
                                                  graph::X(first_node[loop->a] + loop->candidate), graph::X(first_node[loop->b] + loop->query),
                                                  T_candidate_query, loop_noise);
    ++result.inter_session_loops;
  }
  graph::BatchOptimizerConfig batch;
  batch.fixed = {graph::X(0)};
  graph::OptimizationSummary optimized;
  HANZO_ASSIGN_OR_RETURN(optimized, graph::optimize(graph, values, batch));
  result.initial_chi2 = optimized.initial_chi2;
  result.final_chi2 = optimized.final_chi2;
  result.iterations = optimized.iterations;

  // 5. The merged map.
  msgs::FusionMap& merged = result.merged;
  merged.format_version = maps[0].format_version;
  merged.map_id = maps[0].map_id;
  merged.created = maps[0].created;
  merged.frame_id = maps[0].frame_id;
  merged.datum = maps[0].datum;
  merged.sensor_configuration = maps[0].sensor_configuration;
  merged.provenance = maps[0].provenance;
  merged.provenance.algorithm = "pipeline/session_merge";
  merged.semantic_classes = maps[0].semantic_classes;
  maps::MapBuilderConfig map_config = config.map;
  if (maps[0].points && maps[0].points->voxel_size > 0) map_config.point_map.voxel_size = maps[0].points->voxel_size;
  if (maps[0].occupancy) map_config.occupancy_2d_config.resolution = maps[0].occupancy->resolution;
  Result<maps::MapBuilder> created = maps::MapBuilder::create(map_config);
  if (!created) return Error(fmt::format("session merge: the merged map's layers: {}", created.error().message));
  maps::MapBuilder& builder = *created;
  const bool any_lidar = std::any_of(maps.begin(), maps.end(), has_lidar_keyframes);
  const auto visual_input = std::find_if(maps.begin(), maps.end(), has_visual_keyframes);
  msgs::LidarKeyframeLayer lidar_layer;
  std::optional<msgs::VisualLandmarkLayer> visual_layer;
  if (visual_input != maps.end()) {
    visual_layer.emplace();
    visual_layer->camera = visual_input->visual_landmarks->camera;
    visual_layer->descriptor_type = visual_input->visual_landmarks->descriptor_type;
    visual_layer->float_descriptor_size = visual_input->visual_landmarks->float_descriptor_size;
    visual_layer->scale_free = !has_lidar_keyframes(maps[0]) && maps[0].visual_landmarks && maps[0].visual_landmarks->scale_free;
  }
  std::vector<std::string> moved;  // layers rebuilt or moved with the keyframes
  for (std::size_t m = 0; m < maps.size(); ++m) {
    if (m > 0) {
      const auto& logs = maps[m].provenance.input_logs;
      merged.provenance.input_logs.insert(merged.provenance.input_logs.end(), logs.begin(), logs.end());
    }
    std::vector<SE3> optimized_lidar, optimized_visual;
    for (std::size_t k = 0; k < nodes[m].size(); ++k) {
      SE3 T_merged_sensor;
      HANZO_ASSIGN_OR_RETURN(T_merged_sensor, values.at<SE3>(graph::X(first_node[m] + k)));
      std::vector<SE3>& poses = nodes[m][k].kind == Node::Kind::kLidar ? optimized_lidar : optimized_visual;
      if (poses.size() <= nodes[m][k].index) poses.resize(nodes[m][k].index + 1);
      poses[nodes[m][k].index] = T_merged_sensor;
    }
    const std::string own = own_source(maps, m);
    if (has_lidar_keyframes(maps[m])) {
      const msgs::LidarKeyframeLayer& input = *maps[m].lidar_keyframes;
      const std::vector<uint32_t> sources = source_indices(input.sources, own, lidar_layer.sources);
      for (std::size_t k = 0; k < input.keyframes.size(); ++k) {
        const msgs::LidarKeyframe& keyframe = input.keyframes[k];
        cloud::PointCloud cloud;
        cloud.positions = keyframe.points;
        if (Status inserted = builder.insert(optimized_lidar[k], cloud); !inserted) {
          logger()->warn("session merge: keyframe {} of {} not in the merged map: {}", k, maps[m].map_id, inserted.error().message);
        }
        lidar_layer.keyframes.push_back({keyframe.time, msgs::Pose::from_se3(optimized_lidar[k]), keyframe.points, sources.at(keyframe.source)});
      }
    }
    const bool visual_moved = has_visual_keyframes(maps[m]) && maps[m].visual_landmarks->descriptor_type == visual_layer->descriptor_type &&
                              maps[m].visual_landmarks->float_descriptor_size == visual_layer->float_descriptor_size;
    if (visual_moved) append_visual_layer(*maps[m].visual_landmarks, *T_merged_map[m], optimized_visual, own, *visual_layer);
    for (const std::string& name : layers_besides_points(maps[m])) {
      if ((any_lidar && (name == "occupancy" || name == "lidar_keyframes")) || (visual_moved && name == "visual_landmarks")) continue;
      if (std::find(result.dropped_layers.begin(), result.dropped_layers.end(), name) == result.dropped_layers.end()) result.dropped_layers.push_back(name);
    }
    if (!any_lidar && maps[m].points && !maps[m].points->points.empty() &&
        std::find(result.dropped_layers.begin(), result.dropped_layers.end(), "points") == result.dropped_layers.end()) {
      result.dropped_layers.push_back("points");
    }
  }
  if (any_lidar) {
    builder.write_map(merged);
    merged.lidar_keyframes = std::move(lidar_layer);
  }
  merged.visual_landmarks = std::move(visual_layer);
  logger()->info("session merge: {} maps, {} keyframes, {} inter-session loops ({} Scan Context candidates, {} verified; {} visual keyframes aligned of {}); chi2 {:.1f} -> {:.1f}",
                 maps.size(), result.keyframes, result.inter_session_loops, result.candidates, result.verified, result.visual_verified, result.visual_queries,
                 result.initial_chi2, result.final_chi2);
  return result;
}

}  // namespace hanzo::fusion::pipeline
