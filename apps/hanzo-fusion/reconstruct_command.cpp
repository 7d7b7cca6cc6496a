// hanzo-fusion reconstruct splats TRANSFORMS --out DIR: trains 3D Gaussian splats on posed images
// (a NeRF / Blender-style transforms.json; neural/splat_trainer.hpp) and writes DIR/splats.ply
// (the 3DGS viewers' layout) and DIR/reconstruction.json (provenance and metrics).
// hanzo-fusion reconstruct nerf TRANSFORMS --out DIR: trains a hash-grid NeRF
// (neural/nerf_trainer.hpp) and writes DIR/nerf.hznerf and DIR/reconstruction.json.
// Both take a sensor log instead of TRANSFORMS: --log LOG --trajectory T.tum --calibration C.yaml
// (neural/log_views.hpp).
// With --map MAP.fmap the splats or the NeRF also become a layer of that FusionMap (created when
// missing, else its next version; neural/map_layers.hpp).
// hanzo-fusion reconstruct surface MODEL --out DIR: the NeRF's surface by marching cubes on its
// density (neural/surface.hpp) and, with --poses, the depth rendered at those cameras fused
// into a TSDF (neural::fuse_rendered_depth) and meshed: DIR/surface.ply, DIR/depth_mesh.ply; --map stores them
// as the map's mesh and tsdf layers.
// hanzo-fusion render DIR --poses POSES.json --out VIEWS: renders DIR's (or a FusionMap's) splats or NeRF at every
// camera of a transforms-style JSON, in its frame order and at its resolution, one PNG per frame
// (depth as 16-bit PNG on request); where the poses file's images exist, PSNR and SSIM against them.

#include <algorithm>
#include <chrono>
#include <cmath>
#include <filesystem>
#include <memory>
#include <numeric>
#include <random>
#include <string>

#include <fmt/format.h>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <tbb/global_control.h>

#include "commands.hpp"
#include "hanzo/fusion/core/files.hpp"
#include "hanzo/fusion/core/logging.hpp"
#include "hanzo/fusion/maps/fusion_map_file.hpp"
#include "hanzo/fusion/maps/map_export.hpp"
#include "hanzo/fusion/maps/tsdf.hpp"
#include "hanzo/fusion/maps/map_store.hpp"
#include "hanzo/fusion/neural/log_views.hpp"
#include "hanzo/fusion/neural/map_layers.hpp"
#include "hanzo/fusion/neural/surface.hpp"
#include "hanzo/fusion/neural/nerf_trainer.hpp"
#include "hanzo/fusion/neural/splat_ply.hpp"
#include "hanzo/fusion/neural/splat_rasterizer_cuda.hpp"
#include "hanzo/fusion/neural/view_points.hpp"
#include "hanzo/fusion/neural/splat_trainer.hpp"
#include "hanzo/fusion/neural/view_dataset.hpp"

namespace hanzo::fusion::app {
namespace {

/// Triangulated points below this start no splats (random ones in the box instead).
constexpr std::size_t kMinTriangulatedPoints = 1000;

/// Where the posed images come from: a transforms.json, or a sensor log with a trajectory and a
/// calibration; which are held back for scoring.
struct InputOptions {
  std::string transforms;
  std::string log, trajectory, calibration, camera, topic;
  int max_views = neural::LogViewsConfig{}.max_views;
  std::string eval;    // held-back views (a transforms file)
  int hold_every = 0;  // hold back every N-th view instead
  int downscale = 1;
  std::string background = "white";
  std::string map;     // FusionMap file that also gets the result as a layer
};

struct ReconstructOptions {
  InputOptions input;
  std::string out;
  int iterations = neural::SplatTrainingConfig{}.iterations;
  int max_gaussians = neural::SplatTrainingConfig{}.max_gaussians;
  int initial_gaussians = neural::SplatTrainingConfig{}.initial_gaussians;
  std::string points;  // FusionMap whose point layer places the initial Gaussians
  int sh_degree = neural::SplatTrainingConfig{}.sh_degree;
  uint64_t seed = 1;
  int threads = 0;
  double progress_seconds = 10.0;
  double max_seconds = 0.0;  // 0: no limit
  double coarse_share = 0.5;  // share of the first steps trained at half resolution
  std::string device = "cpu";  // cpu, cuda or auto
};

struct NerfOptions {
  InputOptions input;
  std::string out;
  int iterations = neural::NerfTrainingConfig{}.iterations;
  int samples_per_step = neural::NerfTrainingConfig{}.samples_per_step;
  uint64_t seed = 1;
  int threads = 0;
  double progress_seconds = 10.0;
  double max_seconds = 0.0;
};

struct SurfaceOptions {
  std::string model;  // as RenderOptions::model
  std::string layer;
  std::string poses;  // cameras whose rendered depth is fused into a TSDF
  std::string out;
  int resolution = neural::NerfSurfaceConfig{}.resolution;
  float density_threshold = neural::NerfSurfaceConfig{}.density_threshold;
  double voxel = 0.0;         // TSDF voxel (scene units); 0: the scene's extent / 256
  double min_opacity = 0.5;   // rendered pixels less opaque give no depth
  int downscale = 1;
  std::string map;
  int threads = 0;
};

struct RenderOptions {
  std::string model;  // folder with splats.ply or nerf.hznerf, the file itself, or a FusionMap (.fmap)
  std::string layer;  // of a FusionMap: "splats" or "nerf" (default: splats when it has them)
  std::string poses;
  std::string out;
  int downscale = 1;
  bool depth = false;
  std::string background = "white";
  int threads = 0;
  std::string device = "cpu";  // splats: cpu, cuda or auto
};

Result<Eigen::Vector3f> background_colour(const std::string& name) {
  if (name == "white") return Eigen::Vector3f(Eigen::Vector3f::Ones());
  if (name == "black") return Eigen::Vector3f(Eigen::Vector3f::Zero());
  return Error(fmt::format("--background: '{}' (white or black)", name));
}

nlohmann::json scores_json(const neural::EvaluationSummary& summary) {
  nlohmann::json views = nlohmann::json::array();
  for (const neural::ViewScore& view : summary.views) views.push_back({{"name", view.name}, {"psnr", view.psnr}, {"ssim", view.ssim}});
  return {{"views", summary.views.size()}, {"psnr", summary.mean_psnr}, {"ssim", summary.mean_ssim}, {"render_ms_per_view", 1000.0 * summary.seconds_per_view},
          {"per_view", views}};
}

/// Training views (every frame but the held-back ones) and held-back views with images.
struct Inputs {
  neural::ViewDataset train;
  std::vector<neural::PosedView> held_back;
  nlohmann::json source;  // where the views came from, for the provenance
  Eigen::Vector3f background = Eigen::Vector3f::Ones();
};

Status create_folder(const std::string& folder);

/// The views from a transforms.json or a sensor log, with held-back ones, on `background`.
Result<Inputs> load_inputs_from(const InputOptions& options, const Eigen::Vector3f& background);
/// load_inputs_from() on the --background colour, with the output folder `out` created.
Result<Inputs> load_inputs(const InputOptions& options, const std::string& out) {
  Eigen::Vector3f background;
  HANZO_ASSIGN_OR_RETURN(background, background_colour(options.background));
  Inputs inputs;
  HANZO_ASSIGN_OR_RETURN(inputs, load_inputs_from(options, background));
  inputs.background = background;
  HANZO_RETURN_IF_ERROR(create_folder(out));
  return inputs;
}

Result<Inputs> load_inputs_from(const InputOptions& options, const Eigen::Vector3f& background) {
  Inputs inputs;
  if (options.transforms.empty() == options.log.empty()) return Error("give either TRANSFORMS or --log (with --trajectory and --calibration)");
  if (!options.log.empty()) {
    if (options.trajectory.empty() || options.calibration.empty()) return Error("--log needs --trajectory and --calibration");
    if (!options.eval.empty()) return Error("--eval takes a transforms.json; with --log hold views back by --hold-every");
    neural::LogViewsConfig config;
    config.camera = options.camera;
    config.topic = options.topic;
    config.max_views = options.max_views;
    config.downscale = options.downscale;
    neural::LogViews views;
    HANZO_ASSIGN_OR_RETURN(views, neural::load_log_views(options.log, options.trajectory, options.calibration, config));
    inputs.train = std::move(views.dataset);
    inputs.source = {{"log", options.log},           {"trajectory", options.trajectory}, {"calibration", options.calibration}, {"topic", views.topic},
                     {"images", views.images}, {"without_pose", views.outside_trajectory}};
    if (options.hold_every > 0) {
      std::vector<neural::PosedView> train;
      for (std::size_t i = 0; i < inputs.train.views.size(); ++i) {
        (static_cast<int>(i + 1) % options.hold_every == 0 ? inputs.held_back : train).push_back(std::move(inputs.train.views[i]));
      }
      if (train.empty()) return Error(fmt::format("--hold-every {} leaves no view to train on", options.hold_every));
      inputs.train.views = std::move(train);
    }
    return inputs;
  }
  neural::ViewDatasetConfig dataset_config;
  dataset_config.downscale = options.downscale;
  dataset_config.background = background;
  neural::ViewDatasetConfig train_config = dataset_config;
  train_config.skip_every = options.hold_every;
  HANZO_ASSIGN_OR_RETURN(inputs.train, neural::load_transforms(options.transforms, train_config));
  inputs.source = {{"transforms", options.transforms}};
  if (!options.eval.empty() || options.hold_every > 0) {
    neural::ViewDatasetConfig eval_config = dataset_config;
    eval_config.only_every = options.hold_every;
    neural::ViewDataset eval_set;
    HANZO_ASSIGN_OR_RETURN(eval_set, neural::load_transforms(options.eval.empty() ? options.transforms : options.eval, eval_config));
    inputs.held_back = std::move(eval_set.views);
  }
  return inputs;
}

/// The input and held-back options both reconstruct commands take.
void add_input_options(CLI::App* command, InputOptions& input) {
  command->add_option("TRANSFORMS", input.transforms, "NeRF / Blender-style transforms.json (camera-to-world poses, intrinsics, image paths)");
  command->add_option("--log", input.log, "Sensor log whose camera images to use (instead of TRANSFORMS)");
  command->add_option("--trajectory", input.trajectory, "With --log: T_world_body of the session (TUM), e.g. its optimized trajectory");
  command->add_option("--calibration", input.calibration, "With --log: calibration.yaml with the camera's intrinsics and camera_to_body");
  command->add_option("--camera", input.camera, "With --log: the calibration's camera (default: its first)");
  command->add_option("--topic", input.topic, "With --log: the images' topic (default: /sensors/<camera>)");
  command->add_option("--max-views", input.max_views, "With --log: most views kept (evenly thinned)")->check(CLI::Range(1, 100000));
  command->add_option("--eval", input.eval, "Held-back views (a transforms.json) scored after training");
  command->add_option("--hold-every", input.hold_every, "Hold back every N-th view and score them after training")->check(CLI::Range(2, 1000));
  command->add_option("--downscale", input.downscale, "Divide the images' resolution by this")->check(CLI::Range(1, 64));
  command->add_option("--background", input.background, "Behind transparent pixels and the scene: white or black");
  command->add_option("--map", input.map, "Also store the result as a layer of this FusionMap (.fmap; created when missing, else its next version)");
}

/// How the layer was trained, for its provenance.
msgs::NeuralProvenance neural_provenance(const nlohmann::json& result) {
  msgs::NeuralProvenance provenance;
  provenance.source = result.value("source", nlohmann::json::object()).dump();
  provenance.views = result.value("train_views", 0u);
  provenance.iterations = result.value("iterations", uint64_t{0});
  provenance.training_seconds = result.value("training_seconds", 0.0);
  if (result.contains("eval")) {
    provenance.evaluated_views = result["eval"].value("views", 0u);
    provenance.psnr_db = result["eval"].value("psnr", 0.0);
    provenance.ssim = result["eval"].value("ssim", 0.0);
  }
  return provenance;
}

/// Puts a layer into the FusionMap at `path` (read when it exists: its next version, the other
/// layers kept; else a new map) and writes it atomically; reports the map in `result["map"]`.
Status store_layer(const std::string& path, const std::string& layer_name, const std::function<void(msgs::FusionMap&)>& set_layer,
                   nlohmann::json& result) {
  msgs::FusionMap map;
  if (std::filesystem::exists(path)) {
    HANZO_ASSIGN_OR_RETURN(map, maps::read_fusion_map(path));
    map.parent_version = map.version;
    ++map.version;
  } else {
    map.map_id = maps::generate_map_id();
    map.version = 1;
    map.created = Timestamp::wall_clock_now();
    map.provenance.algorithm = "neural/reconstruct";
    map.provenance.software_version = HANZO_FUSION_VERSION;
  }
  set_layer(map);
  HANZO_RETURN_IF_ERROR(maps::write_fusion_map(path, map));
  result["map"] = {{"path", path}, {"map_id", map.map_id}, {"version", map.version}, {"layer", layer_name}};
  return ok_status();
}

Status create_folder(const std::string& folder) {
  std::error_code created;
  std::filesystem::create_directories(folder, created);
  if (created) return Error(fmt::format("{}: cannot create the folder ({})", folder, created.message()));
  return ok_status();
}

/// A progress line on stderr with the time left, at most every `interval` seconds.
class ProgressReporter {
 public:
  ProgressReporter(std::string what, double interval) : what_(std::move(what)), interval_(interval) {}
  double seconds() const { return std::chrono::duration<double>(std::chrono::steady_clock::now() - start_).count(); }
  /// Whether a line is due (`interval` passed since the last one).
  bool due() const { return std::chrono::duration<double>(std::chrono::steady_clock::now() - last_).count() >= interval_; }
  /// `done` and `total` in units of work; `detail` follows the step count.
  void report(int step, int steps, double done, double total, const std::string& detail) {
    const auto now = std::chrono::steady_clock::now();
    const double elapsed = seconds();
    fmt::print(stderr, "{}: step {}/{}, {}, {:.0f} s, about {:.0f} s left\n", what_, step, steps, detail, elapsed, elapsed / done * (total - done));
    last_ = now;
  }

 private:
  std::string what_;
  double interval_;
  std::chrono::steady_clock::time_point start_ = std::chrono::steady_clock::now(), last_ = start_;
};

/// Writes DIR/reconstruction.json and reports the result.
int finish_reconstruction(const Output& output, nlohmann::json& result, const std::string& out, const std::string& text) {
  const std::string provenance = (std::filesystem::path(out) / "reconstruction.json").string();
  if (Status written = write_file_durably(provenance, result.dump(2) + "\n"); !written) return report_failure(output, result, written.error().message);
  return report_success(output, result, text);
}

int run_reconstruct_splats(const Output& output, const ReconstructOptions& options) {
  nlohmann::json result = {{"out", options.out}};
  std::unique_ptr<tbb::global_control> threads;
  if (options.threads > 0) threads = std::make_unique<tbb::global_control>(tbb::global_control::max_allowed_parallelism, options.threads);
  Result<Inputs> inputs = load_inputs(options.input, options.out);
  if (!inputs) return report_failure(output, result, inputs.error().message);
  result["source"] = inputs->source;
  const Eigen::Vector3f* background = &inputs->background;
  const neural::ViewDataset* train = &inputs->train;
  const std::vector<neural::PosedView>& held_back = inputs->held_back;
  // Coarse to fine: the first steps see the images at half resolution (a quarter of the pixels).
  std::vector<neural::PosedView> coarse_views;
  if (options.coarse_share > 0.0 && train->views.front().camera.width >= 64) coarse_views = neural::downscaled(train->views, 2);
  const int coarse_steps = coarse_views.empty() ? 0 : static_cast<int>(options.coarse_share * options.iterations);

  neural::SplatTrainingConfig config;
  config.iterations = options.iterations;
  config.max_gaussians = options.max_gaussians;
  config.initial_gaussians = options.initial_gaussians;
  config.sh_degree = options.sh_degree;
  config.seed = options.seed;
  Result<neural::SplatDevice> device = neural::parse_splat_device(options.device);
  if (!device) return report_failure(output, result, "--device: " + device.error().message);
  config.device = *device;
  config.rasterizer.background = *background;
  if (Status valid = neural::validate(config); !valid) return report_failure(output, result, valid.error().message);
  // The scene: the reader's box, else half the cameras' mean distance around where they look;
  // extent as 3DGS takes it (1.1 x the cameras' distance).
  const bool boxed = train->box_half_size > 0.0;
  const Eigen::Vector3d centre = boxed ? train->box_centre : train->scene_centre;
  const double half_size = boxed ? train->box_half_size : 0.5 * train->camera_distance;
  const double extent = 2.2 * half_size;
  neural::GaussianCloud initial;
  if (!options.points.empty()) {
    Result<msgs::FusionMap> map = maps::read_fusion_map(options.points);
    if (!map) return report_failure(output, result, map.error().message);
    if (!map->points || map->points->points.empty()) return report_failure(output, result, fmt::format("{}: no point layer to start the Gaussians from", options.points));
    initial = neural::initialize_gaussians_at_points(train->views, map->points->points, config.initial_gaussians, config.sh_degree, config.seed);
    if (initial.size() == 0) return report_failure(output, result, fmt::format("{}: none of its points is in front of a view", options.points));
    result["initial_points"] = {{"map", options.points}, {"points", map->points->points.size()}, {"gaussians", initial.size()}};
  } else {
    // Without masks (a real capture: the scene reaches beyond any box) the Gaussians start at
    // points triangulated from the views' features, as 3DGS starts at SfM points; with masks, or
    // where too few triangulate, random ones in the box (on the masks' visual hull).
    std::vector<Eigen::Vector3f> points;
    const bool masked = std::any_of(train->views.begin(), train->views.end(), [](const neural::PosedView& view) { return !view.mask.empty(); });
    if (!masked) points = neural::triangulate_view_points(train->views);
    if (points.size() >= kMinTriangulatedPoints) {
      initial = neural::initialize_gaussians_at_points(train->views, points, config.initial_gaussians, config.sh_degree, config.seed);
      result["initial_points"] = {{"triangulated", points.size()}, {"gaussians", initial.size()}};
    } else {
      initial = neural::initialize_gaussians(train->views, centre, half_size, config.initial_gaussians, config.sh_degree, config.seed);
    }
  }
  Result<neural::SplatTrainer> trainer = neural::SplatTrainer::create(std::move(initial), extent, config);
  if (!trainer) return report_failure(output, result, trainer.error().message);

  std::mt19937_64 order_random(config.seed);
  std::vector<std::size_t> order;
  ProgressReporter progress("reconstruct splats", options.progress_seconds);
  // Time left by work done: a half-resolution step counts a quarter of a full one.
  const auto work = [&](int step) { return 0.25 * std::min(step, coarse_steps) + std::max(0, step - coarse_steps); };
  double loss_sum = 0.0;
  int loss_count = 0;
  int steps = 0;
  for (int iteration = 0; iteration < config.iterations; ++iteration) {
    if (options.max_seconds > 0.0 && progress.seconds() >= options.max_seconds) {
      logger()->warn("reconstruct splats: stopped after {} of {} steps (--max-seconds {})", iteration, config.iterations, options.max_seconds);
      break;
    }
    if (order.empty()) {
      order.resize(train->views.size());
      std::iota(order.begin(), order.end(), 0);
      std::shuffle(order.begin(), order.end(), order_random);
    }
    const std::size_t view = order.back();
    order.pop_back();
    const double loss = trainer->step(iteration < coarse_steps ? coarse_views[view] : train->views[view]);
    if (!std::isfinite(loss)) return report_failure(output, result, fmt::format("training diverged at step {} (loss {})", iteration + 1, loss));
    loss_sum += loss;
    ++loss_count;
    steps = iteration + 1;
    if (progress.due() || steps == config.iterations) {
      const std::string detail = fmt::format("loss {:.4f}, {} Gaussians", loss_sum / loss_count, trainer->cloud().size());
      progress.report(steps, config.iterations, work(steps), work(config.iterations), detail);
      loss_sum = 0.0;
      loss_count = 0;
    }
  }
  const double training_seconds = progress.seconds();
  const std::string ply = (std::filesystem::path(options.out) / "splats.ply").string();
  if (Status written = neural::write_splat_ply(ply, trainer->cloud()); !written) return report_failure(output, result, written.error().message);
  const neural::RasterizerConfig render_config = trainer->render_config();
  result["ok"] = true;
  result["splats"] = ply;
  result["gaussians"] = trainer->cloud().size();
  result["iterations"] = steps;
  result["iterations_planned"] = config.iterations;
  result["device"] = trainer->device_name();
  result["training_seconds"] = training_seconds;
  result["train_views"] = train->views.size();
  result["model_bytes"] = std::filesystem::file_size(ply);
  result["sh_degree"] = config.sh_degree;
  result["background"] = options.input.background;
  result["resolution"] = {train->views.front().camera.width, train->views.front().camera.height};
  std::string text = fmt::format("{}: {} Gaussians after {} steps on {} views ({:.0f} s, {:.1f} MB)\n", ply, trainer->cloud().size(), steps,
                                 train->views.size(), training_seconds, static_cast<double>(std::filesystem::file_size(ply)) / 1e6);
  if (!held_back.empty()) {
    const neural::EvaluationSummary scores = neural::evaluate_splats(trainer->cloud(), held_back, render_config);
    result["eval"] = scores_json(scores);
    text += fmt::format("held-back views: {}, PSNR {:.2f} dB, SSIM {:.4f}, {:.0f} ms per view\n", scores.views.size(), scores.mean_psnr, scores.mean_ssim,
                        1000.0 * scores.seconds_per_view);
  }
  if (!options.input.map.empty()) {
    const msgs::GaussianSplatLayer layer = neural::to_splat_layer(trainer->cloud(), neural_provenance(result));
    const Status stored = store_layer(options.input.map, "gaussian_splats", [&layer](msgs::FusionMap& map) { map.gaussian_splats = layer; }, result);
    if (!stored) return report_failure(output, result, stored.error().message);
    text += fmt::format("{}: version {} with the splats\n", options.input.map, result["map"]["version"].get<uint64_t>());
  }
  return finish_reconstruction(output, result, options.out, text);
}

int run_reconstruct_nerf(const Output& output, const NerfOptions& options) {
  nlohmann::json result = {{"out", options.out}};
  std::unique_ptr<tbb::global_control> threads;
  if (options.threads > 0) threads = std::make_unique<tbb::global_control>(tbb::global_control::max_allowed_parallelism, options.threads);
  Result<Inputs> inputs = load_inputs(options.input, options.out);
  if (!inputs) return report_failure(output, result, inputs.error().message);
  result["source"] = inputs->source;
  const Eigen::Vector3f* background = &inputs->background;

  neural::NerfFieldConfig field_config;
  field_config.seed = options.seed;
  neural::set_scene_box(inputs->train, field_config);
  Result<neural::NerfField> field = neural::NerfField::create(field_config);
  if (!field) return report_failure(output, result, field.error().message);
  neural::NerfTrainingConfig config;
  config.iterations = options.iterations;
  config.samples_per_step = options.samples_per_step;
  config.image_background = *background;
  config.seed = options.seed;
  Result<neural::NerfTrainer> trainer = neural::NerfTrainer::create(std::move(*field), inputs->train.views, config);
  if (!trainer) return report_failure(output, result, trainer.error().message);

  ProgressReporter progress("reconstruct nerf", options.progress_seconds);
  double loss_sum = 0.0;
  int loss_count = 0;
  int steps = 0;
  for (int iteration = 0; iteration < config.iterations; ++iteration) {
    if (options.max_seconds > 0.0 && progress.seconds() >= options.max_seconds) {
      logger()->warn("reconstruct nerf: stopped after {} of {} steps (--max-seconds {})", iteration, config.iterations, options.max_seconds);
      break;
    }
    const double loss = trainer->step();
    if (!std::isfinite(loss)) return report_failure(output, result, fmt::format("training diverged at step {} (loss {})", iteration + 1, loss));
    loss_sum += loss;
    ++loss_count;
    steps = iteration + 1;
    if (progress.due() || steps == config.iterations) {
      const std::string detail = fmt::format("PSNR {:.2f} dB, {:.0f} samples a ray, {} rays, {} occupied cells", -10.0 * std::log10(loss_sum / loss_count),
                                             trainer->samples_per_ray(), trainer->rays_per_step(), trainer->field().occupancy().occupied_count());
      progress.report(steps, config.iterations, steps, config.iterations, detail);
      loss_sum = 0.0;
      loss_count = 0;
    }
  }
  const double training_seconds = progress.seconds();
  const std::string model = (std::filesystem::path(options.out) / "nerf.hznerf").string();
  if (Status written = neural::save_nerf(model, trainer->field()); !written) return report_failure(output, result, written.error().message);
  const neural::ViewDataset& train = inputs->train;
  result["ok"] = true;
  result["nerf"] = model;
  result["parameters"] = trainer->field().parameter_count();
  result["iterations"] = steps;
  result["iterations_planned"] = config.iterations;
  result["training_seconds"] = training_seconds;
  result["train_views"] = train.views.size();
  result["model_bytes"] = std::filesystem::file_size(model);
  result["background"] = options.input.background;
  result["resolution"] = {train.views.front().camera.width, train.views.front().camera.height};
  const neural::NerfFieldConfig& box = trainer->field().config();
  result["box"] = {{"centre", {box.box_centre.x(), box.box_centre.y(), box.box_centre.z()}}, {"half_size", box.box_half_size}};
  std::string text = fmt::format("{}: {} parameters after {} steps on {} views ({:.0f} s, {:.1f} MB)\n", model, trainer->field().parameter_count(), steps,
                                 train.views.size(), training_seconds, static_cast<double>(std::filesystem::file_size(model)) / 1e6);
  if (!inputs->held_back.empty()) {
    const neural::EvaluationSummary scores = neural::evaluate_nerf(trainer->field(), inputs->held_back, *background);
    result["eval"] = scores_json(scores);
    text += fmt::format("held-back views: {}, PSNR {:.2f} dB, SSIM {:.4f}, {:.0f} ms per view\n", scores.views.size(), scores.mean_psnr, scores.mean_ssim,
                        1000.0 * scores.seconds_per_view);
  }
  if (!options.input.map.empty()) {
    const msgs::NeuralFieldLayer layer = neural::to_neural_field_layer(trainer->field(), neural_provenance(result));
    const Status stored = store_layer(options.input.map, "neural_field", [&layer](msgs::FusionMap& map) { map.neural_field = layer; }, result);
    if (!stored) return report_failure(output, result, stored.error().message);
    text += fmt::format("{}: version {} with the neural field\n", options.input.map, result["map"]["version"].get<uint64_t>());
  }
  return finish_reconstruction(output, result, options.out, text);
}

/// A trained scene (splats or a NeRF) that renders colour and depth at a camera.
struct Scene {
  std::string kind;  // "splats" or "nerf"
  std::shared_ptr<const neural::NerfField> nerf;  // the field, for a NeRF
  std::string file;
  std::string device = "cpu";  // where it renders: cpu or the CUDA device's name
  std::size_t size = 0;  // Gaussians or parameters
  std::function<neural::NerfRender(const neural::SplatCamera&)> render;
};

Scene nerf_scene(neural::NerfField field, const Eigen::Vector3f& background) {
  Scene scene;
  scene.kind = "nerf";
  scene.size = field.parameter_count();
  auto shared = std::make_shared<neural::NerfField>(std::move(field));
  scene.render = [shared, background](const neural::SplatCamera& camera) { return shared->render(camera, background); };
  scene.nerf = shared;
  return scene;
}

/// Splats rendered on the CPU or a CUDA device (`auto`: CUDA when present); a device error while
/// rendering moves the rest to the CPU (logged).
Result<Scene> splat_scene(neural::GaussianCloud cloud, const Eigen::Vector3f& background, neural::SplatDevice device) {
  Scene scene;
  scene.kind = "splats";
  scene.size = cloud.size();
  auto shared = std::make_shared<neural::GaussianCloud>(std::move(cloud));
  neural::RasterizerConfig config;
  config.background = background;
  std::shared_ptr<neural::CudaSplatRasterizer> gpu;
  if (device != neural::SplatDevice::kCpu) {
    Result<neural::CudaSplatRasterizer> created = neural::CudaSplatRasterizer::create();
    Status uploaded = created ? created->upload(*shared) : Status(created.error());
    if (uploaded) {
      gpu = std::make_shared<neural::CudaSplatRasterizer>(std::move(created).value());
      scene.device = gpu->device_name();
    } else if (device == neural::SplatDevice::kCuda) {
      return Error("--device cuda: " + uploaded.error().message);
    } else {
      logger()->info("rendering on the CPU ({})", uploaded.error().message);
    }
  }
  scene.render = [shared, config, gpu](const neural::SplatCamera& camera) mutable {
    if (gpu) {
      neural::SplatView view;
      if (Status rendered = gpu->render_view(camera, config, view, true); rendered) {
        return neural::NerfRender{view.width, view.height, std::move(view.image), std::move(view.depth), std::move(view.alpha)};
      } else {
        logger()->warn("the CUDA device failed ({}); rendering continues on the CPU", rendered.error().message);
        gpu.reset();
      }
    }
    neural::SplatRender splats = neural::render_splats(*shared, camera, config);
    return neural::NerfRender{splats.width, splats.height, std::move(splats.image), std::move(splats.depth), std::move(splats.alpha)};
  };
  return scene;
}

/// A FusionMap's splats or neural field (`layer`: "splats", "nerf", or empty: splats when there).
Result<Scene> load_map_scene(const std::string& path, const std::string& layer, const Eigen::Vector3f& background, neural::SplatDevice device) {
  msgs::FusionMap map;
  HANZO_ASSIGN_OR_RETURN(map, maps::read_fusion_map(path));
  if (layer != "" && layer != "splats" && layer != "nerf") return Error(fmt::format("--layer: '{}' (splats or nerf)", layer));
  if (layer != "nerf" && map.gaussian_splats) {
    neural::GaussianCloud cloud;
    HANZO_ASSIGN_OR_RETURN(cloud, neural::from_splat_layer(*map.gaussian_splats));
    return splat_scene(std::move(cloud), background, device);
  }
  if (layer != "splats" && map.neural_field) {
    Result<neural::NerfField> field = neural::from_neural_field_layer(*map.neural_field);
    if (!field) return Error(fmt::format("{}: {}", path, field.error().message));
    return nerf_scene(std::move(*field), background);
  }
  return Error(fmt::format("{}: no {} layer in this map (reconstruct splats|nerf --map adds one)", path,
                           layer == "nerf" ? "neural_field" : layer == "splats" ? "gaussian_splats" : "gaussian_splats or neural_field"));
}

Result<Scene> load_scene(const std::string& path, const std::string& layer, const Eigen::Vector3f& background,
                         neural::SplatDevice device = neural::SplatDevice::kCpu) {
  std::string file = path;
  if (std::filesystem::is_directory(path)) {
    const std::filesystem::path nerf = std::filesystem::path(path) / "nerf.hznerf";
    file = std::filesystem::exists(nerf) ? nerf.string() : (std::filesystem::path(path) / "splats.ply").string();
  }
  Scene scene;
  if (std::filesystem::path(file).extension() == ".fmap") {
    HANZO_ASSIGN_OR_RETURN(scene, load_map_scene(file, layer, background, device));
  } else if (!layer.empty()) {
    return Error("--layer applies to a FusionMap (.fmap) only");
  } else if (std::filesystem::path(file).extension() == ".hznerf") {
    Result<neural::NerfField> field = neural::load_nerf(file);
    if (!field) return field.error();
    scene = nerf_scene(std::move(*field), background);
  } else {
    neural::GaussianCloud cloud;
    HANZO_ASSIGN_OR_RETURN(cloud, neural::read_splat_ply(file));
    HANZO_ASSIGN_OR_RETURN(scene, splat_scene(std::move(cloud), background, device));
  }
  scene.file = file;
  return scene;
}


int run_render(const Output& output, const RenderOptions& options) {
  nlohmann::json result = {{"model", options.model}, {"poses", options.poses}, {"out", options.out}};
  std::unique_ptr<tbb::global_control> threads;
  if (options.threads > 0) threads = std::make_unique<tbb::global_control>(tbb::global_control::max_allowed_parallelism, options.threads);
  Result<Eigen::Vector3f> background = background_colour(options.background);
  if (!background) return report_failure(output, result, background.error().message);
  Result<neural::SplatDevice> device = neural::parse_splat_device(options.device);
  if (!device) return report_failure(output, result, "--device: " + device.error().message);
  Result<Scene> scene = load_scene(options.model, options.layer, *background, *device);
  if (!scene) return report_failure(output, result, scene.error().message);
  neural::ViewDatasetConfig dataset_config;
  dataset_config.downscale = options.downscale;
  dataset_config.background = *background;
  dataset_config.load_images = false;
  Result<neural::ViewDataset> poses = neural::load_transforms(options.poses, dataset_config);
  if (!poses) return report_failure(output, result, poses.error().message);
  // Reference images where the poses file's images can be read (for PSNR and SSIM).
  dataset_config.load_images = true;
  Result<neural::ViewDataset> references = neural::load_transforms(options.poses, dataset_config);
  if (Status created = create_folder(options.out); !created) return report_failure(output, result, created.error().message);
  double seconds = 0.0;
  nlohmann::json files = nlohmann::json::array();
  for (std::size_t i = 0; i < poses->views.size(); ++i) {
    const neural::PosedView& view = poses->views[i];
    const auto begin = std::chrono::steady_clock::now();
    const neural::NerfRender render = scene->render(view.camera);
    seconds += std::chrono::duration<double>(std::chrono::steady_clock::now() - begin).count();
    cv::Mat rgb(render.height, render.width, CV_32FC3, const_cast<float*>(render.image.data()));
    cv::Mat bgr8;
    cv::cvtColor(rgb, bgr8, cv::COLOR_RGB2BGR);
    bgr8.convertTo(bgr8, CV_8UC3, 255.0);
    const std::string name = fmt::format("{:04d}.png", i);
    const std::string path = (std::filesystem::path(options.out) / name).string();
    if (!cv::imwrite(path, bgr8)) return report_failure(output, result, fmt::format("{}: cannot write", path));
    nlohmann::json file = {{"frame", view.name}, {"image", path}};
    if (options.depth) {
      // Depth in millimetres of the scene's unit, 16-bit (0: nothing drawn).
      cv::Mat depth(render.height, render.width, CV_32FC1, const_cast<float*>(render.depth.data()));
      cv::Mat depth16;
      depth.convertTo(depth16, CV_16UC1, 1000.0);
      const std::string depth_path = (std::filesystem::path(options.out) / fmt::format("{:04d}_depth.png", i)).string();
      if (!cv::imwrite(depth_path, depth16)) return report_failure(output, result, fmt::format("{}: cannot write", depth_path));
      file["depth"] = depth_path;
    }
    files.push_back(file);
  }
  result["ok"] = true;
  result["views"] = poses->views.size();
  result["kind"] = scene->kind;
  result["device"] = scene->device;
  result["model"] = scene->file;
  result[scene->kind == "nerf" ? "parameters" : "gaussians"] = scene->size;
  result["render_ms_per_view"] = 1000.0 * seconds / static_cast<double>(poses->views.size());
  result["files"] = files;
  std::string text = fmt::format("{}: {} views of {} ({} {}), {:.0f} ms per view\n", options.out, poses->views.size(), scene->file, scene->size,
                                 scene->kind == "nerf" ? "parameters" : "Gaussians", 1000.0 * seconds / static_cast<double>(poses->views.size()));
  if (references) {
    const neural::EvaluationSummary scores = neural::score_views(references->views, [&](const neural::SplatCamera& camera) { return scene->render(camera).image; });
    result["eval"] = scores_json(scores);
    text += fmt::format("against the poses file's images: PSNR {:.2f} dB, SSIM {:.4f}\n", scores.mean_psnr, scores.mean_ssim);
  }
  return report_success(output, result, text);
}

int run_surface(const Output& output, const SurfaceOptions& options) {
  nlohmann::json result = {{"model", options.model}, {"out", options.out}};
  std::unique_ptr<tbb::global_control> threads;
  if (options.threads > 0) threads = std::make_unique<tbb::global_control>(tbb::global_control::max_allowed_parallelism, options.threads);
  Result<Scene> scene = load_scene(options.model, options.layer, Eigen::Vector3f::Zero());
  if (!scene) return report_failure(output, result, scene.error().message);
  if (!scene->nerf && options.poses.empty()) {
    return report_failure(output, result, fmt::format("{}: splats have no density to mesh; give --poses to fuse their rendered depth", scene->file));
  }
  if (Status created = create_folder(options.out); !created) return report_failure(output, result, created.error().message);
  std::string text;
  std::optional<msgs::MeshLayer> surface;
  if (scene->nerf) {
    Result<msgs::MeshLayer> mesh = neural::extract_surface(*scene->nerf, {options.resolution, options.density_threshold});
    if (!mesh) return report_failure(output, result, mesh.error().message);
    const std::string path = (std::filesystem::path(options.out) / "surface.ply").string();
    if (Status written = maps::write_mesh(path, *mesh); !written) return report_failure(output, result, written.error().message);
    result["surface"] = {{"mesh", path}, {"vertices", mesh->vertices.size()}, {"triangles", mesh->triangle_indices.size() / 3},
                         {"resolution", options.resolution}, {"density_threshold", options.density_threshold}};
    text += fmt::format("{}: {} triangles where the density crosses {}\n", path, mesh->triangle_indices.size() / 3, options.density_threshold);
    surface = std::move(*mesh);
  }
  std::optional<msgs::TsdfLayer> tsdf;
  if (!options.poses.empty()) {
    neural::ViewDatasetConfig dataset_config;
    dataset_config.downscale = options.downscale;
    dataset_config.load_images = false;
    Result<neural::ViewDataset> poses = neural::load_transforms(options.poses, dataset_config);
    if (!poses) return report_failure(output, result, poses.error().message);
    if (poses->views.empty()) return report_failure(output, result, fmt::format("{}: no frames", options.poses));
    // The voxel: two pixels at the first view's median rendered depth unless given (the detail
    // the renders hold; a scene's scale is its own).
    double voxel = options.voxel;
    if (voxel <= 0.0) {
      const neural::PosedView& first = poses->views.front();
      const neural::NerfRender render = scene->render(first.camera);
      std::vector<float> depths;
      for (std::size_t i = 0; i < render.depth.size(); ++i) {
        if (render.depth[i] > 0.0f && (render.opacity.empty() || render.opacity[i] >= options.min_opacity)) depths.push_back(render.depth[i]);
      }
      if (depths.empty()) return report_failure(output, result, fmt::format("{}: nothing rendered at the first camera of {}; give --voxel", scene->file, options.poses));
      std::nth_element(depths.begin(), depths.begin() + static_cast<std::ptrdiff_t>(depths.size() / 2), depths.end());
      voxel = 2.0 * depths[depths.size() / 2] / first.camera.fx;
    }
    Result<maps::TsdfVolume> volume = neural::fuse_rendered_depth(scene->render, poses->views, {voxel, options.min_opacity});
    if (!volume) return report_failure(output, result, volume.error().message);
    const msgs::MeshLayer mesh = volume->extract_mesh();
    const std::string path = (std::filesystem::path(options.out) / "depth_mesh.ply").string();
    if (Status written = maps::write_mesh(path, mesh); !written) return report_failure(output, result, written.error().message);
    result["depth_fusion"] = {{"mesh", path}, {"views", poses->views.size()}, {"voxel", voxel}, {"blocks", volume->block_count()},
                              {"vertices", mesh.vertices.size()}, {"triangles", mesh.triangle_indices.size() / 3}};
    text += fmt::format("{}: {} triangles from the depth of {} views fused at {:.4g} voxels\n", path, mesh.triangle_indices.size() / 3, poses->views.size(), voxel);
    tsdf = volume->to_layer();
    if (!surface) surface = mesh;
  }
  if (!options.map.empty()) {
    const Status stored = store_layer(options.map, "mesh", [&](msgs::FusionMap& map) {
      map.mesh = surface;
      if (tsdf) map.tsdf = tsdf;
    }, result);
    if (!stored) return report_failure(output, result, stored.error().message);
    text += fmt::format("{}: version {} with the mesh{}\n", options.map, result["map"]["version"].get<uint64_t>(), tsdf ? " and the TSDF" : "");
  }
  result["ok"] = true;
  result["kind"] = scene->kind;
  return report_success(output, result, text);
}

}  // namespace

void add_reconstruct_command(CLI::App& app, const Output& output, Command& run) {
  CLI::App* reconstruct = app.add_subcommand("reconstruct", "Neural reconstruction from posed images: 3D Gaussian splats or a hash-grid NeRF");
  reconstruct->require_subcommand(1);
  auto splats = std::make_shared<ReconstructOptions>();
  CLI::App* splats_app = reconstruct->add_subcommand("splats", "Train 3D Gaussian splats on the images of a transforms.json");
  add_input_options(splats_app, splats->input);
  splats_app->add_option("--out", splats->out, "Folder for splats.ply and reconstruction.json")->required();
  splats_app->add_option("--iterations", splats->iterations, "Training steps (one view each)")->check(CLI::Range(1, 10000000));
  splats_app->add_option("--max-gaussians", splats->max_gaussians, "Most Gaussians densification may make")->check(CLI::Range(1, 100000000));
  splats_app->add_option("--initial-gaussians", splats->initial_gaussians, "Gaussians of the initialization (random, or at most this many map points)")->check(CLI::Range(1, 100000000));
  splats_app->add_option("--points", splats->points, "Start the Gaussians at this FusionMap's points (a session's map.fmap, in the trajectory's world) instead of random ones");
  splats_app->add_option("--sh-degree", splats->sh_degree, "Spherical-harmonics degree of the colours")->check(CLI::Range(0, 3));
  splats_app->add_option("--seed", splats->seed, "Random seed (initialization, view order, splits)");
  splats_app->add_option("--threads", splats->threads, "Worker threads (default: all cores)")->check(CLI::Range(1, 1024));
  splats_app->add_option("--coarse-share", splats->coarse_share, "Share of the first steps trained at half resolution (0: none)")->check(CLI::Range(0.0, 1.0));
  splats_app->add_option("--max-seconds", splats->max_seconds, "Stop training after this many seconds (0: run every step)")->check(CLI::Range(0.0, 1e7));
  splats_app->add_option("--progress-seconds", splats->progress_seconds, "Seconds between progress lines on stderr")->check(CLI::Range(0.0, 1e6));
  splats_app->add_option("--device", splats->device, "Where the rasterizer runs: cpu (deterministic), cuda (fails without a device) or auto");
  splats_app->callback([&output, &run, splats] { run = [&output, splats] { return run_reconstruct_splats(output, *splats); }; });

  auto nerf = std::make_shared<NerfOptions>();
  CLI::App* nerf_app = reconstruct->add_subcommand("nerf", "Train a hash-grid NeRF (instant-ngp layout) on the images of a transforms.json");
  add_input_options(nerf_app, nerf->input);
  nerf_app->add_option("--out", nerf->out, "Folder for nerf.hznerf and reconstruction.json")->required();
  nerf_app->add_option("--iterations", nerf->iterations, "Training steps")->check(CLI::Range(1, 10000000));
  nerf_app->add_option("--samples-per-step", nerf->samples_per_step, "Field evaluations per step")->check(CLI::Range(256, 1 << 24));
  nerf_app->add_option("--seed", nerf->seed, "Random seed (weights, rays)");
  nerf_app->add_option("--threads", nerf->threads, "Worker threads (default: all cores)")->check(CLI::Range(1, 1024));
  nerf_app->add_option("--max-seconds", nerf->max_seconds, "Stop training after this many seconds (0: run every step)")->check(CLI::Range(0.0, 1e7));
  nerf_app->add_option("--progress-seconds", nerf->progress_seconds, "Seconds between progress lines on stderr")->check(CLI::Range(0.0, 1e6));
  nerf_app->callback([&output, &run, nerf] { run = [&output, nerf] { return run_reconstruct_nerf(output, *nerf); }; });

  auto surface = std::make_shared<SurfaceOptions>();
  CLI::App* surface_app = reconstruct->add_subcommand("surface", "Mesh a NeRF's density by marching cubes; with --poses, fuse the rendered depth into a TSDF");
  surface_app->add_option("MODEL", surface->model, "Folder written by reconstruct splats|nerf, its model file, or a FusionMap (.fmap) with such a layer")->required();
  surface_app->add_option("--layer", surface->layer, "Of a FusionMap with both: splats or nerf (default: splats)");
  surface_app->add_option("--poses", surface->poses, "transforms.json whose cameras' rendered depth is fused into a TSDF");
  surface_app->add_option("--out", surface->out, "Folder for surface.ply and depth_mesh.ply")->required();
  surface_app->add_option("--resolution", surface->resolution, "Density samples along each axis of the NeRF's box")->check(CLI::Range(2, 1024));
  surface_app->add_option("--density-threshold", surface->density_threshold, "Density at the surface (per unit-cube length)")->check(CLI::PositiveNumber);
  surface_app->add_option("--voxel", surface->voxel, "TSDF voxel in scene units (default: two pixels at the first view's median depth)")->check(CLI::NonNegativeNumber);
  surface_app->add_option("--min-opacity", surface->min_opacity, "Rendered pixels less opaque give no depth")->check(CLI::Range(0.0, 1.0));
  surface_app->add_option("--downscale", surface->downscale, "Divide the poses' resolution by this")->check(CLI::Range(1, 64));
  surface_app->add_option("--map", surface->map, "Also store the mesh (and the TSDF) as layers of this FusionMap (created when missing, else its next version)");
  surface_app->add_option("--threads", surface->threads, "Worker threads (default: all cores)")->check(CLI::Range(1, 1024));
  surface_app->callback([&output, &run, surface] { run = [&output, surface] { return run_surface(output, *surface); }; });

  auto render = std::make_shared<RenderOptions>();
  CLI::App* render_app = app.add_subcommand("render", "Render trained splats or a NeRF at the cameras of a transforms.json, one PNG per frame");
  render_app->add_option("MODEL", render->model, "Folder written by reconstruct splats|nerf, its splats.ply / nerf.hznerf, or a FusionMap (.fmap) with such a layer")->required();
  render_app->add_option("--layer", render->layer, "Of a FusionMap with both: splats or nerf (default: splats)");
  render_app->add_option("--poses", render->poses, "transforms.json whose frames give the cameras (and reference images, when present)")->required();
  render_app->add_option("--out", render->out, "Folder for the PNGs (0000.png, ... in frame order)")->required();
  render_app->add_option("--downscale", render->downscale, "Divide the poses' resolution by this")->check(CLI::Range(1, 64));
  render_app->add_flag("--depth", render->depth, "Also write depth (16-bit PNG, millimetres of the scene unit)");
  render_app->add_option("--background", render->background, "white or black");
  render_app->add_option("--threads", render->threads, "Worker threads (default: all cores)")->check(CLI::Range(1, 1024));
  render_app->add_option("--device", render->device, "Where splats render: cpu, cuda (fails without a device) or auto");
  render_app->callback([&output, &run, render] { run = [&output, render] { return run_render(output, *render); }; });
}

}  // namespace hanzo::fusion::app
