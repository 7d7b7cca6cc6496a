// hanzo-fusion register SOURCE TARGET [--method gicp] [--init x,y,z,roll,pitch,yaw]: registers
// two point clouds and prints T_target_source, fitness, iterations and time.
// hanzo-fusion cloud filter IN --out OUT [--voxel 0.1] [--sor 10,0.5] [--ground]: the
// point-cloud processing steps, in that order, with the point count after each.

#include <algorithm>
#include <chrono>
#include <cmath>

#include <fmt/format.h>

#include "commands.hpp"
#include "hanzo/fusion/cloud/cloud_io.hpp"
#include "hanzo/fusion/cloud/ground_segmentation.hpp"
#include "hanzo/fusion/cloud/outlier_removal.hpp"
#include "hanzo/fusion/cloud/voxel_grid.hpp"
#include "hanzo/fusion/lidar/registration.hpp"

namespace hanzo::fusion::app {
namespace {

struct RegisterOptions {
  std::string source;
  std::string target;
  std::string method = "gicp";
  std::vector<double> init;         // x, y, z (m), roll, pitch, yaw (deg)
  double voxel = 0.25;              // m, 0: no downsampling
  double max_distance = 1.0;        // m
  double ndt_resolution = 1.0;      // m
  int max_iterations = 64;
  int threads = 1;
};

struct FilterOptions {
  std::string input;
  std::string out;
  double voxel = 0.0;
  std::vector<double> sor;  // min neighbours, radius
  bool ground = false;
};

double milliseconds_since(std::chrono::steady_clock::time_point start) {
  return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
}

nlohmann::json matrix_json(const Eigen::Matrix4d& matrix) {
  nlohmann::json rows = nlohmann::json::array();
  for (int r = 0; r < 4; ++r) rows.push_back({matrix(r, 0), matrix(r, 1), matrix(r, 2), matrix(r, 3)});
  return rows;
}

int run_register(const Output& output, const RegisterOptions& options) {
  nlohmann::json result = {{"source", options.source}, {"target", options.target}, {"method", options.method}};
  const auto fail = [&](const std::string& reason) { return report_failure(output, result, reason); };
  const auto method = lidar::registration_method_from_string(options.method);
  if (!method) return fail(fmt::format("--method: expected icp, icp-plane, gicp or ndt, got '{}'", options.method));
  if (!options.init.empty() && options.init.size() != 6) {
    return fail(fmt::format("--init: expected 6 values x,y,z,roll,pitch,yaw, got {}", options.init.size()));
  }
  if (options.voxel < 0.0 || !std::isfinite(options.voxel)) return fail(fmt::format("--voxel: {} is not >= 0", options.voxel));
  SE3 guess;
  if (!options.init.empty()) {
    const double deg = M_PI / 180.0;
    const Eigen::Quaterniond rotation = Eigen::AngleAxisd(options.init[5] * deg, Eigen::Vector3d::UnitZ()) *
                                        Eigen::AngleAxisd(options.init[4] * deg, Eigen::Vector3d::UnitY()) *
                                        Eigen::AngleAxisd(options.init[3] * deg, Eigen::Vector3d::UnitX());
    guess = SE3(SO3::from_quaternion_normalized(rotation), Eigen::Vector3d(options.init[0], options.init[1], options.init[2]));
  }
  auto source = cloud::read_cloud(options.source);
  if (!source) return fail(source.error().message);
  auto target = cloud::read_cloud(options.target);
  if (!target) return fail(target.error().message);

  lidar::RegistrationConfig config;
  config.method = *method;
  config.max_correspondence_distance = options.max_distance;
  config.max_iterations = options.max_iterations;
  config.ndt.resolution = options.ndt_resolution;
  config.num_threads = options.threads;
  if (Status valid = config.validate(); !valid) return fail(valid.error().message);

  const auto start = std::chrono::steady_clock::now();
  const cloud::PointCloud source_down = options.voxel > 0.0 ? cloud::voxel_downsample(*source, options.voxel, options.threads) : *source;
  const cloud::PointCloud target_down = options.voxel > 0.0 ? cloud::voxel_downsample(*target, options.voxel, options.threads) : *target;
  const double downsample_ms = milliseconds_since(start);
  const auto registration_start = std::chrono::steady_clock::now();
  auto registered = lidar::register_clouds(source_down, target_down, guess, config);
  const double registration_ms = milliseconds_since(registration_start);
  if (!registered) return fail(registered.error().message);

  const SE3& T = registered->T_target_source;
  const Eigen::Matrix3d R = T.rotation().matrix();  // R = Rz(yaw) Ry(pitch) Rx(roll), as --init
  const Eigen::Vector3d rpy = Eigen::Vector3d(std::atan2(R(2, 1), R(2, 2)), -std::asin(std::clamp(R(2, 0), -1.0, 1.0)),
                                              std::atan2(R(1, 0), R(0, 0))) * 180.0 / M_PI;
  result["ok"] = true;
  result["T_target_source"] = matrix_json(T.matrix());
  result["translation"] = {T.translation().x(), T.translation().y(), T.translation().z()};
  result["rotation_deg"] = T.rotation().log().norm() * 180.0 / M_PI;
  result["roll_pitch_yaw_deg"] = {rpy.x(), rpy.y(), rpy.z()};
  result["converged"] = registered->converged;
  result["iterations"] = registered->iterations;
  result["fitness"] = registered->fitness;
  result["inlier_rmse"] = registered->inlier_rmse;
  result["source_points"] = source_down.size();
  result["target_points"] = target_down.size();
  result["voxel"] = options.voxel;
  result["downsample_ms"] = downsample_ms;
  result["registration_ms"] = registration_ms;
  nlohmann::json covariance = nlohmann::json::array();
  for (int r = 0; r < 6; ++r) {
    nlohmann::json row = nlohmann::json::array();
    for (int c = 0; c < 6; ++c) row.push_back(registered->covariance(r, c));
    covariance.push_back(row);
  }
  result["covariance"] = covariance;
  std::string text = fmt::format("{} {} -> {} ({} -> {} points after {} m voxels)\nT_target_source =\n", options.method, options.source,
                                 options.target, source_down.size(), target_down.size(), options.voxel);
  for (int r = 0; r < 4; ++r) {
    text += fmt::format("  {:10.6f} {:10.6f} {:10.6f} {:10.6f}\n", T.matrix()(r, 0), T.matrix()(r, 1), T.matrix()(r, 2), T.matrix()(r, 3));
  }
  text += fmt::format("translation {:.4f} {:.4f} {:.4f} m, rotation {:.3f} deg (roll {:.3f} pitch {:.3f} yaw {:.3f})\n",
                      T.translation().x(), T.translation().y(), T.translation().z(), T.rotation().log().norm() * 180.0 / M_PI,
                      rpy.x(), rpy.y(), rpy.z());
  text += fmt::format("{} after {} iterations, fitness {:.3f}, inlier RMSE {:.4f} m\ntime: downsampling {:.1f} ms, registration {:.1f} ms\n",
                      registered->converged ? "converged" : "NOT converged", registered->iterations, registered->fitness,
                      registered->inlier_rmse, downsample_ms, registration_ms);
  if (!registered->converged) {
    // The estimate is reported (it may still help as a guess), but the command failed.
    if (!output.json) std::cout << text;
    return report_failure(output, result,
                          fmt::format("registration did not converge in {} iterations (fitness {:.3f}, inlier RMSE {:.4f} m): try a better "
                                      "--init, a larger --max-distance or more --max-iterations",
                                      registered->iterations, registered->fitness, registered->inlier_rmse));
  }
  return report_success(output, result, text);
}

int run_filter(const Output& output, const FilterOptions& options) {
  nlohmann::json result = {{"input", options.input}, {"out", options.out}};
  const auto fail = [&](const std::string& reason) { return report_failure(output, result, reason); };
  if (!options.sor.empty() && (options.sor.size() != 2 || options.sor[0] < 0 || !(options.sor[1] > 0))) {
    return fail("--sor: expected K,R with K >= 0 neighbours and R > 0 metres, e.g. 10,0.5");
  }
  if (options.voxel < 0.0 || !std::isfinite(options.voxel)) return fail(fmt::format("--voxel: {} is not >= 0", options.voxel));
  auto cloud = cloud::read_cloud(options.input);
  if (!cloud) return fail(cloud.error().message);
  nlohmann::json steps = nlohmann::json::array();
  std::string text = fmt::format("{}: {} points\n", options.input, cloud->size());
  steps.push_back({{"step", "read"}, {"points", cloud->size()}});
  cloud::PointCloud current = std::move(*cloud);
  if (options.voxel > 0.0) {
    current = cloud::voxel_downsample(current, options.voxel);
    steps.push_back({{"step", "voxel"}, {"voxel", options.voxel}, {"points", current.size()}});
    text += fmt::format("  voxel grid {} m: {} points\n", options.voxel, current.size());
  }
  if (!options.sor.empty()) {
    cloud::OutlierRemovalConfig config;
    config.min_neighbors = static_cast<int>(options.sor[0]);
    config.radius = options.sor[1];
    current = cloud::remove_outliers(current, config);
    steps.push_back({{"step", "outliers"}, {"min_neighbors", config.min_neighbors}, {"radius", config.radius}, {"points", current.size()}});
    text += fmt::format("  outlier removal (< {} neighbours within {} m): {} points\n", config.min_neighbors, config.radius, current.size());
  }
  if (options.ground) {
    const cloud::GroundSegmentation ground = cloud::segment_ground(current);
    nlohmann::json step = {{"step", "ground"}, {"found", ground.found}};
    if (ground.found) {
      current = cloud::select(current, ground.obstacles);
      step["plane"] = {ground.normal.x(), ground.normal.y(), ground.normal.z(), ground.offset};
      step["ground_points"] = ground.ground.size();
      text += fmt::format("  ground plane {:.3f}x + {:.3f}y + {:.3f}z + {:.3f} = 0 removed: {} points left\n", ground.normal.x(),
                          ground.normal.y(), ground.normal.z(), ground.offset, current.size());
    } else {
      step["message"] = ground.message;
      text += fmt::format("  no ground plane: {}\n", ground.message);
    }
    step["points"] = current.size();
    steps.push_back(step);
  }
  if (Status written = cloud::write_cloud(options.out, current); !written) return fail(written.error().message);
  result["ok"] = true;
  result["steps"] = steps;
  result["points"] = current.size();
  text += fmt::format("wrote {} ({} points)\n", options.out, current.size());
  return report_success(output, result, text);
}

}  // namespace

void add_cloud_commands(CLI::App& app, const Output& output, Command& run) {
  auto registration = std::make_shared<RegisterOptions>();
  CLI::App* reg = app.add_subcommand("register", "Register two point clouds (PCD, PLY or KITTI .bin): T_target_source");
  reg->add_option("SOURCE", registration->source, "Cloud to move onto the target")->required();
  reg->add_option("TARGET", registration->target, "Reference cloud")->required();
  reg->add_option("--method", registration->method, "icp, icp-plane, gicp or ndt")->capture_default_str();
  reg->add_option("--init", registration->init, "Initial guess x,y,z (m),roll,pitch,yaw (deg)")->delimiter(',');
  reg->add_option("--voxel", registration->voxel, "Voxel-grid downsampling of both clouds first (m, 0: none)")->capture_default_str();
  reg->add_option("--max-distance", registration->max_distance, "Maximum correspondence distance (m)")->capture_default_str();
  reg->add_option("--ndt-resolution", registration->ndt_resolution, "NDT cell size (m)")->capture_default_str();
  reg->add_option("--max-iterations", registration->max_iterations, "Gauss-Newton iterations")->capture_default_str();
  reg->add_option("--threads", registration->threads, "Threads (0: all cores)")->capture_default_str();
  reg->callback([&output, &run, registration] { run = [&output, registration] { return run_register(output, *registration); }; });

  CLI::App* cloud_app = app.add_subcommand("cloud", "Point-cloud processing");
  cloud_app->require_subcommand(1);
  auto filter = std::make_shared<FilterOptions>();
  CLI::App* filter_app = cloud_app->add_subcommand("filter", "Voxel grid, outlier removal and ground removal, in that order");
  filter_app->add_option("IN", filter->input, "PCD, PLY or KITTI .bin file")->required();
  filter_app->add_option("--out", filter->out, "Output file (.pcd, .ply or .bin)")->required();
  filter_app->add_option("--voxel", filter->voxel, "Voxel size (m); spec defaults 0.05 indoor, 0.2 outdoor");
  filter_app->add_option("--sor", filter->sor, "Drop points with fewer than K neighbours within R m: K,R (spec 10,0.5)")->delimiter(',');
  filter_app->add_flag("--ground", filter->ground, "Remove the ground plane (RANSAC; the cloud's +z must be up)");
  filter_app->callback([&output, &run, filter] { run = [&output, filter] { return run_filter(output, *filter); }; });
}

}  // namespace hanzo::fusion::app
