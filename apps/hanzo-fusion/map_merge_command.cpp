// hanzo-fusion map merge A.fmap B.fmap [C.fmap ...] --out M.fmap: the maps of sessions that saw
// the same place joined in A's frame without an initial guess (pipeline/map_merge.hpp): each
// further map is localized in the merge so far and its points added. Prints where each map
// went and the checks' numbers (--json: one object); exits 1 with the reason when a map shares
// no place with the others for certain (nothing is written then).

#include <memory>
#include <numbers>
#include <string>
#include <vector>

#include <fmt/format.h>

#include "commands.hpp"
#include "hanzo/fusion/maps/fusion_map_file.hpp"
#include "hanzo/fusion/pipeline/map_merge.hpp"

namespace hanzo::fusion::app {
namespace {

struct MergeOptions {
  std::vector<std::string> maps;
  std::string out;
  std::string map_id = "merged";
  bool indoor = false;
};

int run_merge(const Output& output, const MergeOptions& options) {
  nlohmann::json result = {{"maps", options.maps}, {"out", options.out}};
  const auto fail = [&](const std::string& reason) { return report_failure(output, result, reason); };
  if (options.maps.size() < 2) return fail("give two or more maps: the first is the frame the others join");
  auto merged = maps::read_fusion_map(options.maps.front());
  if (!merged) return fail(merged.error().message);
  pipeline::MapMergeConfig config;
  if (options.indoor) {
    config.odometry.map.voxel_size = 0.5;
    config.odometry.source_voxel_size = 0.25;
  }
  nlohmann::json joined = nlohmann::json::array();
  std::string text;
  for (std::size_t i = 1; i < options.maps.size(); ++i) {
    auto map = maps::read_fusion_map(options.maps[i]);
    if (!map) return fail(map.error().message);
    Result<pipeline::MapMergeResult> done = pipeline::merge_maps(*merged, *map, config);
    if (!done) return fail(fmt::format("{}: {}", options.maps[i], done.error().message));
    const Eigen::Vector3d t = done->T_a_b.translation();
    const Eigen::Matrix3d R = done->T_a_b.rotation().matrix();
    const double yaw_deg = std::atan2(R(1, 0), R(0, 0)) * 180.0 / std::numbers::pi;
    joined.push_back({{"map", options.maps[i]}, {"translation", {t.x(), t.y(), t.z()}}, {"yaw_deg", yaw_deg}, {"views", done->views},
                      {"localized", done->localized}, {"agreeing", done->agreeing}, {"points_added", done->points_from_b},
                      {"dropped_layers", done->dropped_layers}});
    text += fmt::format("{}: at {:.3f} {:.3f} {:.3f} m, yaw {:.2f} deg in {} ({} of {} views localized, {} agree); {} points added{}\n",
                        options.maps[i], t.x(), t.y(), t.z(), yaw_deg, options.maps.front(), done->localized, done->views, done->agreeing,
                        done->points_from_b, done->dropped_layers.empty() ? "" : fmt::format(" (its {} not moved)", fmt::join(done->dropped_layers, ", ")));
    merged = std::move(done->merged);
  }
  merged->map_id = options.map_id;
  merged->parent_version = 0;
  merged->provenance.algorithm = "pipeline/map_merge";
  if (Status written = maps::write_fusion_map(options.out, *merged); !written) return fail(written.error().message);
  result["joined"] = joined;
  result["points"] = merged->points->points.size();
  text += fmt::format("{} points in {}", merged->points->points.size(), options.out);
  return report_success(output, result, text);
}

}  // namespace

void add_map_merge_command(CLI::App& map_app, const Output& output, Command& run) {
  auto options = std::make_shared<MergeOptions>();
  CLI::App* command = map_app.add_subcommand("merge", "Join maps of the same place without an initial guess (the first map's frame)");
  command->add_option("MAPS", options->maps, "FusionMap files with point layers (z up); the first is the frame the others join")->required()->check(CLI::ExistingFile);
  command->add_option("--out", options->out, "The merged FusionMap file")->required();
  command->add_option("--map-id", options->map_id, "The merged map's id")->capture_default_str();
  command->add_flag("--indoor", options->indoor, "Indoor registration settings (0.25 m points, 0.5 m map voxels)");
  command->callback([&output, &run, options] { run = [&output, options] { return run_merge(output, *options); }; });
}

}  // namespace hanzo::fusion::app
