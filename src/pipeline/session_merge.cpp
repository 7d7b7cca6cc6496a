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

namespace hanzo::fusion::pipeline {
namespace {

/// A verified loop between keyframe `candidate` of map a and keyframe `query` of map b (a < b).
struct Loop {
  std::size_t a = 0, candidate = 0, b = 0, query = 0;
  SE3 T_candidate_query;
  double rmse = 0.0;
};

SE3 pose_of(const msgs::LidarKeyframe& keyframe) { return keyframe.T_world_lidar.to_se3(); }

Result<graph::GaussianNoise> pose_noise(double translation_sigma, double rotation_sigma) {
  Eigen::VectorXd sigmas(6);
  sigmas << Eigen::Vector3d::Constant(translation_sigma), Eigen::Vector3d::Constant(rotation_sigma);
  return graph::GaussianNoise::from_sigmas(sigmas);
}

/// What a loop between a joining map and a map of the merge says: the joining map's frame in
/// the merged one, and the joining map's keyframe of the loop (in its own frame).
struct Placement {
  const Loop* loop = nullptr;
  SE3 T_merged_map;
  SE3 T_map_keyframe;
};

Placement placement(const Loop& loop, std::size_t joining, const SE3& T_merged_other, const std::vector<msgs::FusionMap>& maps) {
  const SE3 T_a_candidate = pose_of(maps[loop.a].lidar_keyframes->keyframes[loop.candidate]);
  const SE3 T_b_query = pose_of(maps[loop.b].lidar_keyframes->keyframes[loop.query]);
  const SE3 T_a_b = T_a_candidate * loop.T_candidate_query * T_b_query.inverse();
  if (joining == loop.b) return {&loop, T_merged_other * T_a_b, T_b_query};
  return {&loop, T_merged_other * T_a_b.inverse(), T_a_candidate};
}

/// Whether `hypothesis` (the joining map's frame in the merged one) puts the placement's
/// keyframe where its loop does.
bool agrees(const SE3& hypothesis, const Placement& placement, const SessionMergeConfig& config) {
  const SE3 difference = (hypothesis * placement.T_map_keyframe).inverse() * (placement.T_merged_map * placement.T_map_keyframe);
  return difference.translation().norm() <= config.agreement_translation && difference.rotation().angle() <= config.agreement_rotation;
}

/// The largest set of placements agreeing with one of them (the best-fitting set of that size).
std::vector<Placement> largest_agreeing(const std::vector<Placement>& placements, const SessionMergeConfig& config) {
  std::vector<Placement> best;
  double best_rmse = 0.0;
  for (const Placement& hypothesis : placements) {
    std::vector<Placement> agreeing;
    double rmse = 0.0;
    for (const Placement& other : placements) {
      if (!agrees(hypothesis.T_merged_map, other, config)) continue;
      agreeing.push_back(other);
      rmse += other.loop->rmse;
    }
    if (agreeing.size() > best.size() || (agreeing.size() == best.size() && rmse < best_rmse)) {
      best = std::move(agreeing);
      best_rmse = rmse;
    }
  }
  return best;
}

/// The placements that join a map to the merge: the largest agreeing set, when it has
/// min_agreeing_loops and no other hypothesis (placements that disagree with it) has that many
/// too (a symmetric place seen from two sides); else none, with the reason.
std::vector<Placement> consistent(const std::vector<Placement>& placements, const SessionMergeConfig& config, std::string& reason) {
  std::vector<Placement> best = largest_agreeing(placements, config);
  if (best.size() < config.min_agreeing_loops) {
    reason = fmt::format("{} verified loops, at most {} agree", placements.size(), best.size());
    return {};
  }
  std::vector<Placement> others;
  std::copy_if(placements.begin(), placements.end(), std::back_inserter(others),
               [&](const Placement& other) { return !agrees(best.front().T_merged_map, other, config); });
  const std::vector<Placement> second = largest_agreeing(others, config);
  if (second.size() >= config.min_agreeing_loops) {
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

  // 2. Verified loops of each later map's queries in each earlier map.
  std::vector<std::optional<Result<lidar::MapLocalizer>>> localizers(maps.size());  // made when first needed
  std::vector<Loop> loops;
  for (std::size_t b = 1; b < maps.size(); ++b) {
    const auto& queries_of_b = maps[b].lidar_keyframes->keyframes;
    const std::vector<std::size_t> queries = query_keyframes(maps[b], config.query_spacing);
    for (std::size_t a = 0; a < b; ++a) {
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
        loops.push_back({a, c, b, q, registered->T_submap_query, registered->inlier_rmse});
      }
    }
  }

  // 3. The maps join the merge one at a time, from the first: each round the map whose loops
  // with the maps joined so far agree best on its place.
  std::vector<std::optional<SE3>> T_merged_map(maps.size());
  T_merged_map[0] = SE3();
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
        if (other != m && T_merged_map[other]) placements.push_back(placement(loop, m, *T_merged_map[other], maps));
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
    result.joins.push_back({*best_map, joined_to, T_merged_map[joined_to]->inverse() * consensus.T_merged_map, best_placements.size()});
    logger()->info("session merge: {} joined ({} agreeing loops, most with {})", maps[*best_map].map_id, best_placements.size(), maps[joined_to].map_id);
  }
  std::vector<std::string> unjoined, reasons;
  for (std::size_t m = 0; m < maps.size(); ++m) {
    if (T_merged_map[m]) continue;
    unjoined.push_back(maps[m].map_id);
    if (refusals.count(m)) reasons.push_back(refusals[m]);
  }
  if (!unjoined.empty()) {
    return Error(fmt::format("session merge: {} not joined to {} ({} queries, {} Scan Context candidates, {} verified by registration; {})",
                             fmt::join(unjoined, ", "), maps[0].map_id, result.queries, result.candidates, result.verified,
                             reasons.empty() ? fmt::format("no verified loop with the maps joined: no place shared for certain") : fmt::format("{}", fmt::join(reasons, "; "))));
  }
  // Loops between maps joined through others, where they agree with the joins, join the graph too.
  for (const Loop& loop : loops) {
    if (std::find(graph_loops.begin(), graph_loops.end(), &loop) != graph_loops.end()) continue;
    if (agrees(*T_merged_map[loop.b], placement(loop, loop.b, *T_merged_map[loop.a], maps), config)) graph_loops.push_back(&loop);
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
  for (const Loop* loop : graph_loops) {
    graph.emplace_robust<graph::BetweenFactorSE3>(graph::RobustKernel{graph::RobustKernel::Type::kDcs, config.loop_dcs_phi},
                                                  graph::X(first_node[loop->a] + loop->candidate), graph::X(first_node[loop->b] + loop->query),
                                                  loop->T_candidate_query, loop_noise);
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
    for (const std::string& name : layers_besides_points(maps[m])) {  // occupancy and keyframes are rebuilt
      if (name == "occupancy" || name == "lidar_keyframes") continue;
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
