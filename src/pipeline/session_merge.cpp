#include "hanzo/fusion/pipeline/session_merge.hpp"

#include <algorithm>
#include <cmath>
#include <deque>
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

namespace hanzo::fusion::pipeline {
namespace {

/// A verified loop between keyframe `candidate` of map a and keyframe `query` of map b (a < b).
struct Loop {
  std::size_t a = 0, candidate = 0, b = 0, query = 0;
  SE3 T_candidate_query;
  double rmse = 0.0;
  SE3 T_a_b;  ///< b's frame in a's that the loop implies
};

SE3 pose_of(const msgs::LidarKeyframe& keyframe) { return keyframe.T_world_lidar.to_se3(); }

Result<graph::GaussianNoise> pose_noise(double translation_sigma, double rotation_sigma) {
  Eigen::VectorXd sigmas(6);
  sigmas << Eigen::Vector3d::Constant(translation_sigma), Eigen::Vector3d::Constant(rotation_sigma);
  return graph::GaussianNoise::from_sigmas(sigmas);
}

/// Whether `hypothesis` (T_a_b) puts the loop's query where the loop does.
bool agrees(const SE3& hypothesis, const Loop& loop, const std::vector<msgs::FusionMap>& maps, const SessionMergeConfig& config) {
  const SE3 T_b_query = pose_of(maps[loop.b].lidar_keyframes->keyframes[loop.query]);
  const SE3 difference = (hypothesis * T_b_query).inverse() * (loop.T_a_b * T_b_query);
  return difference.translation().norm() <= config.agreement_translation && difference.rotation().angle() <= config.agreement_rotation;
}

/// The largest set of loops agreeing with one of them (the best-fitting set of that size).
std::vector<Loop> largest_agreeing(const std::vector<Loop>& loops, const std::vector<msgs::FusionMap>& maps, const SessionMergeConfig& config) {
  std::vector<Loop> best;
  double best_rmse = 0.0;
  for (const Loop& hypothesis : loops) {
    std::vector<Loop> agreeing;
    double rmse = 0.0;
    for (const Loop& loop : loops) {
      if (!agrees(hypothesis.T_a_b, loop, maps, config)) continue;
      agreeing.push_back(loop);
      rmse += loop.rmse;
    }
    if (agreeing.size() > best.size() || (agreeing.size() == best.size() && rmse < best_rmse)) {
      best = std::move(agreeing);
      best_rmse = rmse;
    }
  }
  return best;
}

/// The loops between maps a and b that join them: the largest agreeing set, when it has
/// min_agreeing_loops and no other hypothesis (loops that disagree with it) has as many and
/// half its size (a symmetric place seen from two sides); else none, with the reason.
std::vector<Loop> consistent(const std::vector<Loop>& loops, const std::vector<msgs::FusionMap>& maps, const SessionMergeConfig& config,
                             std::string& reason) {
  std::vector<Loop> best = largest_agreeing(loops, maps, config);
  if (best.size() < config.min_agreeing_loops) {
    reason = fmt::format("{} verified loops, at most {} agree", loops.size(), best.size());
    return {};
  }
  std::vector<Loop> others;
  std::copy_if(loops.begin(), loops.end(), std::back_inserter(others), [&](const Loop& loop) { return !agrees(best.front().T_a_b, loop, maps, config); });
  const std::vector<Loop> second = largest_agreeing(others, maps, config);
  if (second.size() >= config.min_agreeing_loops && 2 * second.size() >= best.size()) {
    reason = fmt::format("ambiguous: {} loops agree on one place, {} on another", best.size(), second.size());
    return {};
  }
  return best;
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

std::vector<std::string> moved_layers_not_kept(const msgs::FusionMap& map) {
  std::vector<std::string> names;
  if (map.tsdf) names.emplace_back("tsdf");
  if (map.mesh) names.emplace_back("mesh");
  if (map.visual_landmarks) names.emplace_back("visual_landmarks");
  if (map.gaussian_splats) names.emplace_back("gaussian_splats");
  if (map.neural_field) names.emplace_back("neural_field");
  return names;
}

}  // namespace

Status SessionMergeConfig::validate() const {
  HANZO_RETURN_IF_ERROR(with_context(loop.validate(), "loop"));
  HANZO_RETURN_IF_ERROR(with_context(map.validate(), "map"));
  for (const auto& [name, value] : {std::pair{"query_spacing", query_spacing}, {"agreement_translation", agreement_translation},
                                    {"agreement_rotation", agreement_rotation}, {"min_translation_sigma", min_translation_sigma},
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
  for (const msgs::FusionMap& map : maps) {
    if (!map.lidar_keyframes || map.lidar_keyframes->keyframes.empty()) {
      return Error(fmt::format("map {}: no LiDAR keyframes (lidar_keyframes layer) to join by", map.map_id));
    }
  }
  SessionMergeResult result;

  // 1. Scan Context databases, one per map.
  std::vector<lidar::ScanContextDatabase> databases;
  std::vector<std::vector<lidar::ScanContext>> descriptors(maps.size());
  for (std::size_t m = 0; m < maps.size(); ++m) {
    databases.emplace_back(config.loop.scan_context);
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

  // 2-3. Verified loops of each later map's queries in each earlier map, kept where they agree.
  std::map<std::pair<std::size_t, std::size_t>, std::vector<Loop>> agreeing;  // (a, b) -> loops
  std::vector<std::string> refusals;  // pairs with verified loops that did not join
  for (std::size_t b = 1; b < maps.size(); ++b) {
    const auto& queries_of_b = maps[b].lidar_keyframes->keyframes;
    const std::vector<std::size_t> queries = query_keyframes(maps[b], config.query_spacing);
    for (std::size_t a = 0; a < b; ++a) {
      std::vector<Loop> loops;
      for (const std::size_t q : queries) {
        if (descriptors[b][q].ring_key.size() == 0) continue;
        ++result.queries;
        Result<std::optional<lidar::ScanContextMatch>> match = databases[a].query(descriptors[b][q]);
        if (!match || !*match) continue;
        ++result.candidates;
        const auto c = static_cast<std::size_t>((*match)->id);
        const SE3 guess(SO3::exp(Eigen::Vector3d(0, 0, (*match)->distance.yaw)), Eigen::Vector3d::Zero());
        const Result<lidar::SubmapRegistration> registered =
            lidar::register_to_submap(submap_around(maps[a], c, config.loop.submap_keyframes), queries_of_b[q].points, guess, config.loop, config.odometry);
        if (!registered) continue;
        ++result.verified;
        const SE3 T_a_b = pose_of(maps[a].lidar_keyframes->keyframes[c]) * registered->T_submap_query * pose_of(queries_of_b[q]).inverse();
        loops.push_back({a, c, b, q, registered->T_submap_query, registered->inlier_rmse, T_a_b});
      }
      std::string reason;
      std::vector<Loop> kept = consistent(loops, maps, config, reason);
      if (kept.empty()) {
        logger()->info("session merge: {} not joined to {}: {}", maps[b].map_id, maps[a].map_id, reason);
        if (!loops.empty()) refusals.push_back(fmt::format("{} in {}: {}", maps[b].map_id, maps[a].map_id, reason));
        continue;
      }
      logger()->info("session merge: {} in {}: {} verified loops, {} agree", maps[b].map_id, maps[a].map_id, loops.size(), kept.size());
      agreeing[{a, b}] = std::move(kept);
    }
  }

  // The maps' frames in the first's, through the pairs with the most loops (breadth first).
  std::vector<std::optional<SE3>> T_merged_map(maps.size());
  T_merged_map[0] = SE3();
  std::deque<std::size_t> frontier{0};
  while (!frontier.empty()) {
    const std::size_t m = frontier.front();
    frontier.pop_front();
    for (std::size_t other = 0; other < maps.size(); ++other) {
      if (T_merged_map[other]) continue;
      const auto found = agreeing.find({std::min(m, other), std::max(m, other)});
      if (found == agreeing.end()) continue;
      const SE3 T_a_b = found->second.front().T_a_b;
      T_merged_map[other] = *T_merged_map[m] * (m < other ? T_a_b : T_a_b.inverse());
      result.joins.push_back({other, m, m < other ? T_a_b : T_a_b.inverse(), found->second.size()});
      frontier.push_back(other);
    }
  }
  std::vector<std::string> unjoined;
  for (std::size_t m = 0; m < maps.size(); ++m) {
    if (!T_merged_map[m]) unjoined.push_back(maps[m].map_id);
  }
  if (!unjoined.empty()) {
    return Error(fmt::format("session merge: {} share(s) no place with {} for certain ({} queries, {} Scan Context candidates, {} verified by "
                             "registration, no {} agreeing loops joining them{}{})",
                             fmt::join(unjoined, ", "), maps[0].map_id, result.queries, result.candidates, result.verified,
                             config.min_agreeing_loops, refusals.empty() ? "" : "; ", fmt::join(refusals, "; ")));
  }
  for (const auto& entry : T_merged_map) result.T_merged_map.push_back(*entry);

  // 4. One graph over every keyframe.
  std::vector<std::size_t> first_node(maps.size(), 0);
  graph::FactorGraph graph;
  graph::Values values;
  std::size_t node = 0;
  for (std::size_t m = 0; m < maps.size(); ++m) {
    first_node[m] = node;
    const auto& keyframes = maps[m].lidar_keyframes->keyframes;
    for (std::size_t k = 0; k < keyframes.size(); ++k, ++node) {
      values.insert(graph::X(node), result.T_merged_map[m] * pose_of(keyframes[k]));
      if (k == 0) continue;
      const SE3 relative = pose_of(keyframes[k - 1]).inverse() * pose_of(keyframes[k]);
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
  for (const auto& [pair, loops] : agreeing) {
    for (const Loop& loop : loops) {
      graph.emplace_robust<graph::BetweenFactorSE3>(graph::RobustKernel{graph::RobustKernel::Type::kDcs, config.loop_dcs_phi},
                                                    graph::X(first_node[loop.a] + loop.candidate), graph::X(first_node[loop.b] + loop.query),
                                                    loop.T_candidate_query, loop_noise);
      ++result.inter_session_loops;
    }
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
  msgs::LidarKeyframeLayer layer;
  for (std::size_t m = 0; m < maps.size(); ++m) {
    if (m > 0) {
      const auto& logs = maps[m].provenance.input_logs;
      merged.provenance.input_logs.insert(merged.provenance.input_logs.end(), logs.begin(), logs.end());
    }
    const msgs::LidarKeyframeLayer& input = *maps[m].lidar_keyframes;
    // A merged input's keyframes keep their sources; a session's are the map's own, named by its
    // id (with its place among the inputs when another input has the same id).
    const bool shared_id = std::count_if(maps.begin(), maps.end(), [&](const msgs::FusionMap& other) { return other.map_id == maps[m].map_id; }) > 1;
    const std::string own = shared_id ? fmt::format("{}#{}", maps[m].map_id, m + 1) : maps[m].map_id;
    std::vector<uint32_t> source_index;
    const std::vector<std::string> sources = input.sources.empty() ? std::vector<std::string>{own} : input.sources;
    for (const std::string& source : sources) {
      const auto found = std::find(layer.sources.begin(), layer.sources.end(), source);
      source_index.push_back(static_cast<uint32_t>(found - layer.sources.begin()));
      if (found == layer.sources.end()) layer.sources.push_back(source);
    }
    for (std::size_t k = 0; k < input.keyframes.size(); ++k) {
      SE3 T_merged_lidar;
      HANZO_ASSIGN_OR_RETURN(T_merged_lidar, values.at<SE3>(graph::X(first_node[m] + k)));
      const msgs::LidarKeyframe& keyframe = input.keyframes[k];
      cloud::PointCloud cloud;
      cloud.positions = keyframe.points;
      if (Status inserted = builder.insert(T_merged_lidar, cloud); !inserted) {
        logger()->warn("session merge: keyframe {} of {} not in the merged map: {}", k, maps[m].map_id, inserted.error().message);
      }
      layer.keyframes.push_back({keyframe.time, msgs::Pose::from_se3(T_merged_lidar), keyframe.points, source_index.at(keyframe.source)});
    }
    for (const std::string& name : moved_layers_not_kept(maps[m])) {
      if (std::find(result.dropped_layers.begin(), result.dropped_layers.end(), name) == result.dropped_layers.end()) result.dropped_layers.push_back(name);
    }
  }
  builder.write_map(merged);
  merged.lidar_keyframes = std::move(layer);
  logger()->info("session merge: {} maps, {} keyframes, {} inter-session loops ({} candidates, {} verified); chi2 {:.1f} -> {:.1f}", maps.size(),
                 result.keyframes, result.inter_session_loops, result.candidates, result.verified, result.initial_chi2, result.final_chi2);
  return result;
}

}  // namespace hanzo::fusion::pipeline
