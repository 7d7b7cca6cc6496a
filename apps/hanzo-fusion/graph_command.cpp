// hanzo-fusion graph optimize IN.g2o --out OUT.g2o [--objective geodesic|chordal]
//   [--initialize best|file|chordal] [--incremental] [--no-certificate] [--plot DIR]:
// batch optimization of a pose graph; prints g2o's chi2 and SE-Sync's objective before and after,
// iterations and time, and whether the solution is certified globally optimal
// (graph/optimality_certificate.hpp).

#include <algorithm>
#include <chrono>
#include <optional>
#include <filesystem>

#include <fmt/format.h>

#include "commands.hpp"
#include "hanzo/fusion/eval/plots.hpp"
#include "hanzo/fusion/graph/batch_optimizer.hpp"
#include "hanzo/fusion/graph/chordal_initialization.hpp"
#include "hanzo/fusion/graph/g2o_io.hpp"
#include "hanzo/fusion/graph/incremental_smoother.hpp"
#include "hanzo/fusion/graph/optimality_certificate.hpp"

namespace hanzo::fusion::app {
namespace {

struct GraphOptions {
  std::string input;
  std::string out;
  std::string objective = "geodesic";
  std::string initialize = "best";
  std::string plot_dir;
  int max_iterations = 100;
  bool incremental = false;
  bool certificate = true;
};

// The graph fed pose by pose to an IncrementalSmoother; fills `values` with the estimate after
// wait_for_batch() and `result` with the update latencies and both costs.
Status optimize_incrementally(const graph::PoseGraph& pose_graph, graph::PoseGraph::Objective objective, int max_iterations,
                              graph::Values& values, graph::OptimizationSummary& summary, nlohmann::json& result, std::string& text) {
  std::vector<graph::GraphUpdate> updates;
  HANZO_ASSIGN_OR_RETURN(updates, pose_graph.incremental_updates(objective));
  graph::IncrementalSmootherConfig config;
  config.batch.fixed = pose_graph.fixed;
  config.batch.max_iterations = max_iterations;
  graph::IncrementalSmoother smoother(config);
  std::vector<double> milliseconds;
  const auto start = std::chrono::steady_clock::now();
  for (const graph::GraphUpdate& update : updates) {
    const auto update_start = std::chrono::steady_clock::now();
    if (auto updated = smoother.update(update.factors, update.values); !updated) return updated.error();
    milliseconds.push_back(std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - update_start).count());
  }
  const double update_seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  const double latest_objective = graph::se_sync_objective(pose_graph, smoother.estimate()).value();
  const auto batch_start = std::chrono::steady_clock::now();
  auto final_batch = smoother.wait_for_batch();
  if (!final_batch) return final_batch.error();
  summary = *final_batch;
  const double batch_seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - batch_start).count();
  values = smoother.estimate();
  std::sort(milliseconds.begin(), milliseconds.end());
  const auto percentile = [&](double p) {
    return milliseconds.empty() ? 0.0 : milliseconds[static_cast<size_t>(p * static_cast<double>(milliseconds.size() - 1))];
  };
  result["incremental"] = {{"updates", milliseconds.size()},
                           {"update_seconds", update_seconds},
                           {"update_ms", {{"p50", percentile(0.5)}, {"p99", percentile(0.99)}, {"max", percentile(1.0)}}},
                           {"latest_se_sync_objective", latest_objective},
                           {"batches_merged", smoother.batches_merged()},
                           {"final_batch_seconds", batch_seconds}};
  text += fmt::format("  incremental: {} updates in {:.2f} s (p50 {:.2f} ms, p99 {:.2f} ms, max {:.2f} ms); latest estimate {:.6g};\n"
                      "  final batch {:.2f} s\n",
                      milliseconds.size(), update_seconds, percentile(0.5), percentile(0.99), percentile(1.0), latest_objective, batch_seconds);
  return ok_status();
}

// The graph's poses in vertex order as a trajectory (times are the vertex order), for plots.
io::Trajectory as_trajectory(const graph::PoseGraph& pose_graph, const graph::Values& values) {
  io::Trajectory trajectory;
  int64_t index = 1;
  for (graph::Key key : pose_graph.vertices) {
    Eigen::Matrix4d pose = Eigen::Matrix4d::Identity();
    if (const auto se3 = values.at<SE3>(key)) {
      pose = se3->matrix();
    } else if (const auto se2 = values.at<SE2>(key)) {
      pose = io::pose_matrix(*se2);
    }
    trajectory.timestamps.push_back(Timestamp::from_nanoseconds(index++));
    trajectory.poses.push_back(pose);
  }
  return trajectory;
}

int run_optimize(const Output& output, const GraphOptions& options) {
  nlohmann::json result = {{"input", options.input}, {"out", options.out}};
  const auto fail = [&](const std::string& reason) { return report_failure(output, result, reason); };
  if (options.objective != "geodesic" && options.objective != "chordal") {
    return fail(fmt::format("--objective: expected geodesic or chordal, got '{}'", options.objective));
  }
  if (options.initialize != "file" && options.initialize != "chordal" && options.initialize != "best") {
    return fail(fmt::format("--initialize: expected best, file or chordal, got '{}'", options.initialize));
  }
  if (options.incremental && options.initialize == "chordal") {
    return fail("--incremental: new poses start from odometry; --initialize chordal does not apply");
  }
  auto pose_graph = graph::read_g2o(options.input);
  if (!pose_graph) return fail(pose_graph.error().message);
  const auto objective = options.objective == "chordal" ? graph::PoseGraph::Objective::kChordal : graph::PoseGraph::Objective::kGeodesic;
  auto factors = pose_graph->factor_graph(objective);
  if (!factors) return fail(factors.error().message);
  // The objective being minimized, to compare the starts.
  const auto cost = [&](const graph::Values& v) {
    return objective == graph::PoseGraph::Objective::kChordal ? graph::se_sync_objective(*pose_graph, v).value() : graph::g2o_chi2(*pose_graph, v).value();
  };
  graph::Values values = pose_graph->initial;
  double initialization_seconds = 0.0;
  std::optional<graph::Values> chordal;
  if (options.initialize != "file" && !options.incremental) {
    const auto start = std::chrono::steady_clock::now();
    auto initialized = graph::chordal_initialization(*pose_graph);
    if (!initialized && options.initialize == "chordal") return fail(initialized.error().message);
    if (initialized) chordal = std::move(*initialized);
    initialization_seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  }
  if (options.initialize == "chordal") values = *chordal;
  const double initial_chi2 = graph::g2o_chi2(*pose_graph, values).value();
  const double initial_objective = graph::se_sync_objective(*pose_graph, values).value();
  graph::BatchOptimizerConfig config;
  config.fixed = pose_graph->fixed;
  config.max_iterations = options.max_iterations;
  std::string incremental_text;
  graph::OptimizationSummary summary;
  std::string started_from = options.initialize == "chordal" ? "chordal" : "file";
  if (options.incremental) {
    if (Status done = optimize_incrementally(*pose_graph, objective, options.max_iterations, values, summary, result, incremental_text); !done) {
      return fail(done.error().message);
    }
  } else {
    auto solved = graph::optimize(*factors, values, config);
    if (!solved) return fail(solved.error().message);
    summary = *solved;
    // best: the file's start and the chordal one both optimized, the lower cost kept (a start
    // far from the optimum ends in a local minimum; the chordal one rarely does).
    if (options.initialize == "best" && chordal) {
      graph::Values from_chordal = *chordal;
      auto other = graph::optimize(*factors, from_chordal, config);
      result["final_cost_by_start"] = {{"file", cost(values)}, {"chordal", other ? nlohmann::json(cost(from_chordal)) : nlohmann::json(nullptr)}};
      if (other && cost(from_chordal) < cost(values)) {
        values = std::move(from_chordal);
        summary = *other;
        started_from = "chordal";
      }
    }
  }
  // The certificate is about SE-Sync's objective: for it the refined poses are written (they
  // can only be better); geodesic poses are kept and the distance to the certified ones told.
  std::string certificate_text;
  bool written_certified = false;
  if (options.certificate) {
    auto certificate = graph::certify_global_optimality(*pose_graph, values);
    if (!certificate) return fail(certificate.error().message);
    if (objective == graph::PoseGraph::Objective::kChordal && certificate->objective_refined <= cost(values)) values = certificate->refined;
    // The certificate is about the refined poses: those are the written ones only for chordal.
    written_certified = certificate->certified && objective == graph::PoseGraph::Objective::kChordal;
    result["certified"] = written_certified;
    result["certificate"] = {{"certified", certificate->certified},
                             {"about", written_certified || objective == graph::PoseGraph::Objective::kChordal
                                           ? "the written poses"
                                           : "SE-Sync's optimum near the written poses (not written: --objective chordal writes it)"},
                             {"min_eigenvalue", certificate->min_eigenvalue},
                             {"eigenvalue_tolerance", certificate->eigenvalue_tolerance},
                             {"se_sync_objective", certificate->objective_refined},
                             {"max_translation_change", certificate->max_translation_change},
                             {"max_rotation_change", certificate->max_rotation_change},
                             {"seconds", certificate->seconds},
                             {"message", certificate->message}};
    certificate_text = fmt::format("  certificate: {} (SE-Sync objective {:.6g}, smallest eigenvalue {:.3g}, tolerance {:.3g}, {:.2f} s)\n",
                                   certificate->message, certificate->objective_refined, certificate->min_eigenvalue,
                                   certificate->eigenvalue_tolerance, certificate->seconds);
    if (objective == graph::PoseGraph::Objective::kGeodesic) {
      certificate_text += fmt::format(
          "  the certificate is about SE-Sync's optimum, within {:.3g} m and {:.3g} deg of the written (geodesic) poses; "
          "--objective chordal writes it\n",
          certificate->max_translation_change, certificate->max_rotation_change * 180.0 / M_PI);
    }
  }
  const double final_chi2 = graph::g2o_chi2(*pose_graph, values).value();
  const double final_objective = graph::se_sync_objective(*pose_graph, values).value();
  const bool toro_out = std::filesystem::path(options.out).extension() == ".graph";
  if (Status written = toro_out ? graph::write_toro(options.out, *pose_graph, values) : graph::write_g2o(options.out, *pose_graph, values);
      !written) {
    return fail(written.error().message);
  }

  result["ok"] = true;
  result["dimension"] = pose_graph->dimension;
  result["poses"] = pose_graph->vertices.size();
  result["edges"] = pose_graph->edges.size();
  result["skipped_equivalences"] = pose_graph->skipped_equivalences;
  nlohmann::json warnings = nlohmann::json::array();
  std::string warnings_text;
  for (const graph::WarningGroup& group : graph::group_warnings(pose_graph->warnings)) {
    warnings.push_back({{"kind", group.kind}, {"count", group.count}, {"first", group.first}});
    warnings_text += fmt::format("  warning: {} edges {}; first: {}\n", group.count, group.kind, group.first.front());
  }
  result["warnings"] = warnings;
  result["objective"] = options.objective;
  // What the written poses minimize: g2o's geodesic errors with the (repaired) information, or
  // SE-Sync's chordal objective.
  result["written_poses_minimize"] = objective == graph::PoseGraph::Objective::kChordal ? "se_sync_chordal" : "g2o_geodesic";
  result["g2o_chi2"] = {{"initial", initial_chi2}, {"final", final_chi2}};
  result["se_sync_objective"] = {{"initial", initial_objective}, {"final", final_objective}};
  result["initialize"] = options.initialize;
  result["started_from"] = started_from;
  result["initialization_seconds"] = initialization_seconds;
  result["iterations"] = summary.iterations;
  result["seconds"] = summary.seconds;
  result["converged"] = summary.converged;
  std::string text = fmt::format(
      "{}: {}D, {} poses, {} edges, {} objective\n{}  g2o chi2:           {:.6g} -> {:.6g}\n  SE-Sync objective:  {:.6g} -> {:.6g}\n"
      "{}  initialization: {} ({:.3f} s); {} iterations in {:.3f} s ({})\n{}wrote {} (poses minimizing {}{})\n",
      options.input, pose_graph->dimension, pose_graph->vertices.size(), pose_graph->edges.size(), options.objective, warnings_text,
      initial_chi2, final_chi2, initial_objective, final_objective, incremental_text,
      options.initialize == "best" ? "best start: " + started_from : options.initialize, initialization_seconds, summary.iterations,
      summary.seconds, summary.converged ? "converged" : summary.message, certificate_text, options.out,
      objective == graph::PoseGraph::Objective::kChordal ? "SE-Sync's chordal objective" : "g2o's geodesic errors",
      written_certified ? ", certified globally optimal" : (options.certificate ? ", not certified" : ""));
  if (!options.plot_dir.empty()) {
    std::error_code ec;
    std::filesystem::create_directories(options.plot_dir, ec);
    if (ec) return fail(fmt::format("{}: cannot create plot folder ({})", options.plot_dir, ec.message()));
    const io::Trajectory before = as_trajectory(*pose_graph, pose_graph->initial);
    const io::Trajectory after = as_trajectory(*pose_graph, values);
    std::vector<double> moved;
    for (size_t i = 0; i < before.size(); ++i) moved.push_back((after.position(i) - before.position(i)).norm());
    const std::string path = (std::filesystem::path(options.plot_dir) / "graph_before_after.svg").string();
    if (Status s = eval::write_svg(path, eval::trajectory_top_view_svg(before, after, moved,
                                                                      {"Pose graph: initial (grey) and optimized, coloured by displacement",
                                                                       "displacement (m)"}));
        !s) {
      return fail(s.error().message);
    }
    result["plots"] = {path};
    text += fmt::format("plot: {}\n", path);
  }
  return report_success(output, result, text);
}

}  // namespace

void add_graph_command(CLI::App& app, const Output& output, Command& run) {
  CLI::App* graph = app.add_subcommand("graph", "Pose graphs: batch optimization of g2o files");
  graph->require_subcommand(1);
  auto options = std::make_shared<GraphOptions>();
  CLI::App* optimize = graph->add_subcommand("optimize", "Optimize a g2o pose graph (2D or 3D)");
  optimize->add_option("IN", options->input, "g2o file (VERTEX_SE2/EDGE_SE2 or VERTEX_SE3:QUAT/EDGE_SE3:QUAT) or TORO file (VERTEX2/EDGE2, VERTEX3/EDGE3)")->required();
  optimize->add_option("--out", options->out, "Optimized pose graph to write: TORO when it ends in .graph, g2o otherwise")->required();
  optimize->add_option("--objective", options->objective, "geodesic (g2o's errors) or chordal (SE-Sync's objective)")->capture_default_str();
  optimize->add_option("--initialize", options->initialize,
                       "best (optimize from both starts, keep the lower cost), file (the VERTEX lines, chained odometry for missing ones) "
                       "or chordal (rotation relaxation)")
      ->capture_default_str();
  optimize->add_flag("--incremental", options->incremental,
                     "Feed the graph pose by pose to the incremental smoother (odometry starts) and report update latencies");
  optimize->add_flag("!--no-certificate", options->certificate,
                     "Skip the global-optimality certificate (SE-Sync's verification, run on the result by default)");
  optimize->add_option("--max-iterations", options->max_iterations, "Levenberg-Marquardt iterations")->capture_default_str();
  optimize->add_option("--plot", options->plot_dir, "Write an SVG of the graph before and after into this folder");
  optimize->callback([&output, &run, options] { run = [&output, options] { return run_optimize(output, *options); }; });
}

}  // namespace hanzo::fusion::app
