// hanzo-fusion eval ape|rpe|kitti REFERENCE ESTIMATE: trajectory accuracy as evo and the KITTI
// odometry benchmark compute it, with optional SVG plots.

#include <filesystem>
#include <memory>
#include <optional>
#include <string>

#include <fmt/format.h>

#include "commands.hpp"
#include "hanzo/fusion/eval/association.hpp"
#include "hanzo/fusion/eval/kitti_odometry.hpp"
#include "hanzo/fusion/eval/plots.hpp"
#include "hanzo/fusion/eval/pose_error.hpp"

namespace hanzo::fusion::app {
namespace {

struct EvalOptions {
  std::string reference_path;
  std::string estimate_path;
  std::string format = "tum";
  std::string reference_times;  // KITTI times files (optional)
  std::string estimate_times;
  double max_time_difference_s = 0.01;
  std::optional<double> time_offset_s;  // none: 0, or guessed between relative and absolute times
  std::string relation = "trans_part";
  std::string alignment = "none";
  int align_num_poses = -1;
  double delta = 1.0;
  std::string delta_unit = "f";
  bool all_pairs = false;
  bool pairs_from_reference = false;
  std::string plot_dir;
};

struct LoadedPair {
  eval::AssociatedTrajectories associated;
  std::size_t dropped_duplicates = 0;
  bool has_times = true;  // false for KITTI files without times files (times are frame numbers)
  std::string pairing_note;  // how the times were paired when the offset was guessed ("" otherwise), one line
};

std::optional<std::string> optional_path(const std::string& path) {
  return path.empty() ? std::nullopt : std::optional<std::string>(path);
}

// Reads both files and pairs their poses: by index for KITTI (no times in the format unless
// times files are given), by timestamp otherwise.
// Without --t-offset, a ground truth in relative times (a dataset's, from 0) and an estimate in
// absolute ones (or the reverse) are paired by eval::guess_relative_time_offset; `result` gets
// time_pairing and estimate_time_offset_s.
Result<LoadedPair> load_pair(const EvalOptions& options, nlohmann::json& result) {
  io::TrajectoryFormat format;
  HANZO_ASSIGN_OR_RETURN(format, io::trajectory_format_from_name(options.format));
  io::Trajectory reference, estimate;
  HANZO_ASSIGN_OR_RETURN(reference, io::read_trajectory(options.reference_path, format, optional_path(options.reference_times)));
  HANZO_ASSIGN_OR_RETURN(estimate, io::read_trajectory(options.estimate_path, format, optional_path(options.estimate_times)));
  LoadedPair loaded;
  loaded.dropped_duplicates = reference.dropped_duplicate_timestamps + estimate.dropped_duplicate_timestamps;
  if (format == io::TrajectoryFormat::kKitti && options.reference_times.empty()) {
    if (reference.size() != estimate.size()) {
      return Error(fmt::format("KITTI files pair poses by line: {} has {} poses, {} has {}", options.reference_path,
                               reference.size(), options.estimate_path, estimate.size()));
    }
    loaded.has_times = false;
    loaded.associated.reference = std::move(reference);
    loaded.associated.estimate = std::move(estimate);
    return loaded;
  }
  eval::AssociationConfig association{options.max_time_difference_s, options.time_offset_s.value_or(0.0)};
  std::string pairing = options.time_offset_s ? "estimate times shifted by --t-offset" : "times as they are";
  if (!options.time_offset_s) {
    if (const std::optional<eval::TimeOffsetGuess> guess = eval::guess_relative_time_offset(reference, estimate)) {
      association.estimate_time_offset_s = guess->estimate_time_offset_s;
      pairing = guess->description;
      loaded.pairing_note = fmt::format("time pairing: {} (--t-offset sets it)\n", pairing);
    }
  }
  result["time_pairing"] = pairing;
  result["estimate_time_offset_s"] = association.estimate_time_offset_s;
  HANZO_ASSIGN_OR_RETURN(loaded.associated, eval::associate(reference, estimate, association));
  return loaded;
}

nlohmann::json statistics_json(const eval::ErrorStatistics& s) {
  return {{"count", s.count}, {"rmse", s.rmse}, {"mean", s.mean}, {"median", s.median}, {"std", s.std},
          {"min", s.min},     {"max", s.max},   {"sse", s.sse}};
}

std::string statistics_text(const eval::ErrorStatistics& s) {
  return fmt::format("       max\t{:.6f}\n      mean\t{:.6f}\n    median\t{:.6f}\n       min\t{:.6f}\n      rmse\t{:.6f}\n"
                     "       sse\t{:.6f}\n       std\t{:.6f}\n     pairs\t{}\n",
                     s.max, s.mean, s.median, s.min, s.rmse, s.sse, s.std, s.count);
}

nlohmann::json alignment_json(eval::Alignment alignment, const eval::SimilarityTransform& t) {
  return {{"method", eval::alignment_name(alignment)},
          {"rotation", {t.rotation.row(0).eval(), t.rotation.row(1).eval(), t.rotation.row(2).eval()}},
          {"translation", {t.translation.x(), t.translation.y(), t.translation.z()}},
          {"scale", t.scale}};
}

std::string relation_title(eval::PoseRelation relation) {
  switch (relation) {
    case eval::PoseRelation::kTranslation: return "translation part (m)";
    case eval::PoseRelation::kRotationAngleDeg: return "rotation angle (deg)";
    case eval::PoseRelation::kRotationAngleRad: return "rotation angle (rad)";
    case eval::PoseRelation::kRotationPart: return "rotation part (unit-less)";
    case eval::PoseRelation::kFull: return "full transformation (unit-less)";
  }
  return "";
}

// Writes <dir>/<metric>_trajectory.svg and <dir>/<metric>_errors.svg; returns their paths.
Result<std::vector<std::string>> write_plots(const std::string& dir, const std::string& metric,
                                             const io::Trajectory& reference, const io::Trajectory& estimate,
                                             const std::vector<double>& errors, const std::vector<double>& error_times_s,
                                             const eval::ErrorStatistics& statistics, const eval::PlotLabels& labels) {
  std::error_code ec;
  std::filesystem::create_directories(dir, ec);
  if (ec) return Error(fmt::format("{}: cannot create plot folder ({})", dir, ec.message()));
  const std::string top_view = (std::filesystem::path(dir) / (metric + "_trajectory.svg")).string();
  const std::string over_time = (std::filesystem::path(dir) / (metric + "_errors.svg")).string();
  HANZO_RETURN_IF_ERROR(eval::write_svg(top_view, eval::trajectory_top_view_svg(reference, estimate, errors, labels)));
  HANZO_RETURN_IF_ERROR(eval::write_svg(over_time, eval::error_over_time_svg(error_times_s, errors, statistics, labels)));
  return std::vector<std::string>{top_view, over_time};
}

// Plot labels: the title on one line, the error axis named after the metric and its unit.
eval::PlotLabels plot_labels(std::string title, const char* metric, eval::PoseRelation relation, bool has_times) {
  std::replace(title.begin(), title.end(), '\n', ' ');
  return {title, fmt::format("{} ({})", metric, eval::pose_relation_unit(relation)), has_times ? "time (s)" : "frame"};
}

std::vector<double> seconds_of(const io::Trajectory& trajectory) {
  std::vector<double> seconds;
  for (Timestamp t : trajectory.timestamps) seconds.push_back((t - trajectory.timestamps.front()).seconds());
  return seconds;
}

int run_ape(const Output& output, const EvalOptions& options) {
  nlohmann::json result = {{"metric", "ape"}, {"reference", options.reference_path}, {"estimate", options.estimate_path}};
  eval::ApeConfig config;
  config.align_num_poses = options.align_num_poses;
  auto relation = eval::pose_relation_from_name(options.relation);
  if (!relation) return report_failure(output, result, relation.error().message);
  auto alignment = eval::alignment_from_name(options.alignment);
  if (!alignment) return report_failure(output, result, alignment.error().message);
  config.relation = *relation;
  config.alignment = *alignment;
  auto loaded = load_pair(options, result);
  if (!loaded) return report_failure(output, result, loaded.error().message);
  auto ape = eval::compute_ape(loaded->associated.reference, loaded->associated.estimate, config);
  if (!ape) return report_failure(output, result, ape.error().message);

  const std::string title = fmt::format("APE w.r.t. {}\n({})", relation_title(config.relation),
                                        config.alignment == eval::Alignment::kNone
                                            ? std::string("not aligned")
                                            : fmt::format("with {} alignment", eval::alignment_name(config.alignment)));
  result["ok"] = true;
  result["relation"] = eval::pose_relation_name(config.relation);
  result["unit"] = eval::pose_relation_unit(config.relation);
  result["alignment"] = alignment_json(config.alignment, ape->alignment);
  result["statistics"] = statistics_json(ape->statistics);
  result["dropped_duplicate_timestamps"] = loaded->dropped_duplicates;
  std::string text = loaded->pairing_note + title + "\n\n" + statistics_text(ape->statistics);
  if (!options.plot_dir.empty()) {
    auto plots = write_plots(options.plot_dir, "ape", ape->reference, ape->estimate_aligned, ape->errors,
                             seconds_of(ape->reference), ape->statistics,
                             plot_labels(title, "APE", config.relation, loaded->has_times));
    if (!plots) return report_failure(output, result, plots.error().message);
    result["plots"] = *plots;
    text += fmt::format("plots: {}\n", fmt::join(*plots, ", "));
  }
  return report_success(output, result, text);
}

int run_rpe(const Output& output, const EvalOptions& options) {
  nlohmann::json result = {{"metric", "rpe"}, {"reference", options.reference_path}, {"estimate", options.estimate_path}};
  eval::RpeConfig config;
  config.delta = options.delta;
  config.all_pairs = options.all_pairs;
  config.pairs_from_reference = options.pairs_from_reference;
  config.align_num_poses = options.align_num_poses;
  auto relation = eval::pose_relation_from_name(options.relation);
  if (!relation) return report_failure(output, result, relation.error().message);
  auto alignment = eval::alignment_from_name(options.alignment);
  if (!alignment) return report_failure(output, result, alignment.error().message);
  auto unit = eval::delta_unit_from_name(options.delta_unit);
  if (!unit) return report_failure(output, result, unit.error().message);
  config.relation = *relation;
  config.alignment = *alignment;
  config.delta_unit = *unit;
  auto loaded = load_pair(options, result);
  if (!loaded) return report_failure(output, result, loaded.error().message);
  const io::Trajectory& reference = loaded->associated.reference;
  auto rpe = eval::compute_rpe(reference, loaded->associated.estimate, config);
  if (!rpe) return report_failure(output, result, rpe.error().message);

  const std::string title = fmt::format("RPE w.r.t. {}\nfor delta = {} ({}) using {} pairs", relation_title(config.relation),
                                        config.delta, eval::delta_unit_name(config.delta_unit),
                                        config.all_pairs ? "all" : "consecutive");
  result["ok"] = true;
  result["relation"] = eval::pose_relation_name(config.relation);
  result["unit"] = eval::pose_relation_unit(config.relation);
  result["delta"] = config.delta;
  result["delta_unit"] = eval::delta_unit_name(config.delta_unit);
  result["all_pairs"] = config.all_pairs;
  result["alignment"] = alignment_json(config.alignment, rpe->alignment);
  result["statistics"] = statistics_json(rpe->statistics);
  result["dropped_duplicate_timestamps"] = loaded->dropped_duplicates;
  std::string text = loaded->pairing_note + title + "\n\n" + statistics_text(rpe->statistics);
  if (!options.plot_dir.empty()) {
    // Errors belong to the second pose of each pair (evo's convention for plotting).
    std::vector<std::size_t> ends;
    for (const auto& pair : rpe->pairs) ends.push_back(pair.second);
    const io::Trajectory reference_ends = reference.subset(ends);
    std::vector<double> times;
    for (Timestamp t : reference_ends.timestamps) times.push_back((t - reference.timestamps.front()).seconds());
    io::Trajectory estimate_aligned = loaded->associated.estimate;
    io::PoseMatrix T = io::PoseMatrix::Identity();
    T.block<3, 3>(0, 0) = rpe->alignment.rotation;
    T.block<3, 1>(0, 3) = rpe->alignment.translation;
    estimate_aligned.transform(T, rpe->alignment.scale);
    auto plots = write_plots(options.plot_dir, "rpe", reference, estimate_aligned.subset(ends), rpe->errors, times,
                             rpe->statistics, plot_labels(title, "RPE", config.relation, loaded->has_times));
    if (!plots) return report_failure(output, result, plots.error().message);
    result["plots"] = *plots;
    text += fmt::format("plots: {}\n", fmt::join(*plots, ", "));
  }
  return report_success(output, result, text);
}

int run_kitti(const Output& output, const EvalOptions& options) {
  nlohmann::json result = {{"metric", "kitti"}, {"reference", options.reference_path}, {"estimate", options.estimate_path}};
  auto loaded = load_pair(options, result);
  if (!loaded) return report_failure(output, result, loaded.error().message);
  auto kitti = eval::compute_kitti_odometry_error(loaded->associated.reference, loaded->associated.estimate);
  if (!kitti) return report_failure(output, result, kitti.error().message);
  result["ok"] = true;
  result["segments"] = kitti->segments;
  result["translation_error_percent"] = kitti->translation_error_percent;
  result["rotation_error_deg_per_100m"] = kitti->rotation_error_deg_per_100m;
  nlohmann::json per_length = nlohmann::json::array();
  std::string text = loaded->pairing_note + fmt::format("KITTI odometry error over {} segments of 100..800 m\n  translation {:.4f} %\n"
                                 "  rotation    {:.4f} deg/100m\n\n  length  segments  t_err(%)  r_err(deg/100m)\n",
                                 kitti->segments, kitti->translation_error_percent, kitti->rotation_error_deg_per_100m);
  for (const auto& length : kitti->per_length) {
    per_length.push_back({{"length_m", length.length_m},
                          {"segments", length.segments},
                          {"translation_error_percent", length.translation_error_percent},
                          {"rotation_error_deg_per_100m", length.rotation_error_deg_per_100m}});
    text += fmt::format("  {:6.0f}  {:8}  {:8.4f}  {:15.4f}\n", length.length_m, length.segments,
                        length.translation_error_percent, length.rotation_error_deg_per_100m);
  }
  result["per_length"] = per_length;
  return report_success(output, result, text);
}

void add_common_options(CLI::App* command, EvalOptions& options) {
  command->add_option("REFERENCE", options.reference_path, "Ground-truth trajectory file")->required();
  command->add_option("ESTIMATE", options.estimate_path, "Estimated trajectory file")->required();
  command->add_option("--format", options.format, "File format of both: tum, kitti or euroc")->capture_default_str();
  command->add_option("--ref-times", options.reference_times, "KITTI: times file of the reference (one time in s a line)");
  command->add_option("--est-times", options.estimate_times, "KITTI: times file of the estimate");
  command->add_option("--t-max-diff", options.max_time_difference_s, "Largest time difference of a pose pair (s)")
      ->capture_default_str();
  command->add_option("--t-offset", options.time_offset_s,
                      "Added to the estimate's times before pairing (s); default 0, or the importers' time origin when one "
                      "trajectory is in relative times and the other in absolute ones");
}

void add_error_options(CLI::App* command, EvalOptions& options) {
  command->add_option("-r,--relation", options.relation, "trans_part, angle_deg, angle_rad, rot_part or full")
      ->capture_default_str();
  command->add_option("--align", options.alignment, "none, se3, sim3, scale, translation, origin or yaw (rotation about the vertical + translation)")->capture_default_str();
  command->add_option("--n-to-align", options.align_num_poses, "Align on the first N pose pairs only (-1: all)")
      ->capture_default_str();
  command->add_option("--plot", options.plot_dir, "Write SVG plots (top view coloured by error, error over time) here");
}

}  // namespace

void add_eval_command(CLI::App& app, const Output& output, Command& run) {
  CLI::App* eval_command = app.add_subcommand("eval", "Trajectory accuracy: APE, RPE (as evo computes them), KITTI metric");
  eval_command->require_subcommand(1);
  auto options = std::make_shared<EvalOptions>();

  CLI::App* ape = eval_command->add_subcommand("ape", "Absolute pose error");
  add_common_options(ape, *options);
  add_error_options(ape, *options);
  ape->callback([&output, &run, options] { run = [&output, options] { return run_ape(output, *options); }; });

  CLI::App* rpe = eval_command->add_subcommand("rpe", "Relative pose error over pose pairs delta apart");
  add_common_options(rpe, *options);
  add_error_options(rpe, *options);
  rpe->add_option("-d,--delta", options->delta, "Distance between the poses of a pair")->capture_default_str();
  rpe->add_option("-u,--delta-unit", options->delta_unit, "f (frames), m, deg or rad")->capture_default_str();
  rpe->add_flag("--all-pairs", options->all_pairs, "A pair from every pose instead of consecutive pairs");
  rpe->add_flag("--pairs-from-reference", options->pairs_from_reference,
                "Measure delta on the reference instead of the estimate (evo's default)");
  rpe->callback([&output, &run, options] { run = [&output, options] { return run_rpe(output, *options); }; });

  CLI::App* kitti = eval_command->add_subcommand("kitti", "KITTI odometry metric: t_err (%) and r_err (deg/100 m)");
  add_common_options(kitti, *options);
  kitti->callback([&output, &run, options] { run = [&output, options] { return run_kitti(output, *options); }; });
}

}  // namespace hanzo::fusion::app
