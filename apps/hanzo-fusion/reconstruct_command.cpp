// hanzo-fusion reconstruct splats TRANSFORMS --out DIR: trains 3D Gaussian splats on posed images
// (a NeRF / Blender-style transforms.json; neural/splat_trainer.hpp) and writes DIR/splats.ply
// (the 3DGS viewers' layout) and DIR/reconstruction.json (provenance and metrics).
// hanzo-fusion render DIR --poses POSES.json --out VIEWS: renders DIR's splats at every camera of
// a transforms-style JSON, in its frame order and at its resolution, one PNG per frame (depth as
// 16-bit PNG on request); where the poses file's images exist, PSNR and SSIM against them.

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
#include "hanzo/fusion/neural/splat_ply.hpp"
#include "hanzo/fusion/neural/splat_trainer.hpp"
#include "hanzo/fusion/neural/view_dataset.hpp"

namespace hanzo::fusion::app {
namespace {

struct ReconstructOptions {
  std::string transforms;
  std::string out;
  std::string eval;    // held-back views (a transforms file)
  int hold_every = 0;  // hold back every N-th frame of TRANSFORMS instead
  int downscale = 1;
  int iterations = neural::SplatTrainingConfig{}.iterations;
  int max_gaussians = neural::SplatTrainingConfig{}.max_gaussians;
  int initial_gaussians = neural::SplatTrainingConfig{}.initial_gaussians;
  int sh_degree = neural::SplatTrainingConfig{}.sh_degree;
  std::string background = "white";
  uint64_t seed = 1;
  int threads = 0;
  double progress_seconds = 10.0;
  double max_seconds = 0.0;  // 0: no limit
  double coarse_share = 0.5;  // share of the first steps trained at half resolution
};

struct RenderOptions {
  std::string splats;  // folder with splats.ply, or the .ply
  std::string poses;
  std::string out;
  int downscale = 1;
  bool depth = false;
  std::string background = "white";
  int threads = 0;
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

int run_reconstruct_splats(const Output& output, const ReconstructOptions& options) {
  nlohmann::json result = {{"transforms", options.transforms}, {"out", options.out}};
  std::unique_ptr<tbb::global_control> threads;
  if (options.threads > 0) threads = std::make_unique<tbb::global_control>(tbb::global_control::max_allowed_parallelism, options.threads);
  Result<Eigen::Vector3f> background = background_colour(options.background);
  if (!background) return report_failure(output, result, background.error().message);
  neural::ViewDatasetConfig dataset_config;
  dataset_config.downscale = options.downscale;
  dataset_config.background = *background;
  dataset_config.skip_every = options.hold_every;
  Result<neural::ViewDataset> train = neural::load_transforms(options.transforms, dataset_config);
  if (!train) return report_failure(output, result, train.error().message);
  // Coarse to fine: the first steps see the images at half resolution (a quarter of the pixels).
  std::vector<neural::PosedView> coarse_views;
  if (options.coarse_share > 0.0 && train->views.front().camera.width >= 64) {
    neural::ViewDatasetConfig coarse_config = dataset_config;
    coarse_config.downscale = 2 * options.downscale;
    Result<neural::ViewDataset> coarse = neural::load_transforms(options.transforms, coarse_config);
    if (!coarse) return report_failure(output, result, coarse.error().message);
    coarse_views = std::move(coarse->views);
  }
  const int coarse_steps = coarse_views.empty() ? 0 : static_cast<int>(options.coarse_share * options.iterations);
  std::vector<neural::PosedView> held_back;
  if (!options.eval.empty() || options.hold_every > 0) {
    neural::ViewDatasetConfig eval_config = dataset_config;
    eval_config.skip_every = 0;
    eval_config.only_every = options.hold_every;
    Result<neural::ViewDataset> eval = neural::load_transforms(options.eval.empty() ? options.transforms : options.eval, eval_config);
    if (!eval) return report_failure(output, result, eval.error().message);
    held_back = std::move(eval->views);
  }
  std::error_code created;
  std::filesystem::create_directories(options.out, created);
  if (created) return report_failure(output, result, fmt::format("{}: cannot create the folder ({})", options.out, created.message()));

  neural::SplatTrainingConfig config;
  config.iterations = options.iterations;
  config.max_gaussians = options.max_gaussians;
  config.initial_gaussians = options.initial_gaussians;
  config.sh_degree = options.sh_degree;
  config.seed = options.seed;
  config.rasterizer.background = *background;
  if (Status valid = neural::validate(config); !valid) return report_failure(output, result, valid.error().message);
  // The scene: half the cameras' mean distance around where they look; extent as 3DGS takes it.
  const double extent = 1.1 * train->camera_distance;
  neural::GaussianCloud initial =
      neural::initialize_gaussians(train->views, train->scene_centre, 0.5 * train->camera_distance, config.initial_gaussians, config.sh_degree, config.seed);
  Result<neural::SplatTrainer> trainer = neural::SplatTrainer::create(std::move(initial), extent, config);
  if (!trainer) return report_failure(output, result, trainer.error().message);

  std::mt19937_64 order_random(config.seed);
  std::vector<std::size_t> order;
  const auto start = std::chrono::steady_clock::now();
  auto last_report = start;
  double loss_sum = 0.0;
  int loss_count = 0;
  int steps = 0;
  for (int iteration = 0; iteration < config.iterations; ++iteration) {
    if (options.max_seconds > 0.0 && std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count() >= options.max_seconds) {
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
    const auto now = std::chrono::steady_clock::now();
    if (std::chrono::duration<double>(now - last_report).count() >= options.progress_seconds || iteration + 1 == config.iterations) {
      const double seconds = std::chrono::duration<double>(now - start).count();
      // Time left by work done: a half-resolution step counts a quarter of a full one.
      const auto work = [&](int step) { return 0.25 * std::min(step, coarse_steps) + std::max(0, step - coarse_steps); };
      const double left = seconds / work(iteration + 1) * (work(config.iterations) - work(iteration + 1));
      fmt::print(stderr, "reconstruct splats: step {}/{}, loss {:.4f}, {} Gaussians, {:.0f} s, about {:.0f} s left\n", iteration + 1, config.iterations,
                 loss_sum / loss_count, trainer->cloud().size(), seconds, left);
      loss_sum = 0.0;
      loss_count = 0;
      last_report = now;
    }
  }
  const double training_seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  const std::string ply = (std::filesystem::path(options.out) / "splats.ply").string();
  if (Status written = neural::write_splat_ply(ply, trainer->cloud()); !written) return report_failure(output, result, written.error().message);
  const neural::RasterizerConfig render_config = trainer->render_config();
  result["ok"] = true;
  result["splats"] = ply;
  result["gaussians"] = trainer->cloud().size();
  result["iterations"] = steps;
  result["iterations_planned"] = config.iterations;
  result["training_seconds"] = training_seconds;
  result["train_views"] = train->views.size();
  result["model_bytes"] = std::filesystem::file_size(ply);
  result["sh_degree"] = config.sh_degree;
  result["background"] = options.background;
  result["resolution"] = {train->views.front().camera.width, train->views.front().camera.height};
  std::string text = fmt::format("{}: {} Gaussians after {} steps on {} views ({:.0f} s, {:.1f} MB)\n", ply, trainer->cloud().size(), steps,
                                 train->views.size(), training_seconds, static_cast<double>(std::filesystem::file_size(ply)) / 1e6);
  if (!held_back.empty()) {
    const neural::EvaluationSummary scores = neural::evaluate_splats(trainer->cloud(), held_back, render_config);
    result["eval"] = scores_json(scores);
    text += fmt::format("held-back views: {}, PSNR {:.2f} dB, SSIM {:.4f}, {:.0f} ms per view\n", scores.views.size(), scores.mean_psnr, scores.mean_ssim,
                        1000.0 * scores.seconds_per_view);
  }
  const std::string provenance = (std::filesystem::path(options.out) / "reconstruction.json").string();
  if (Status written = write_file_durably(provenance, result.dump(2) + "\n"); !written) return report_failure(output, result, written.error().message);
  return report_success(output, result, text);
}

int run_render(const Output& output, const RenderOptions& options) {
  nlohmann::json result = {{"splats", options.splats}, {"poses", options.poses}, {"out", options.out}};
  std::unique_ptr<tbb::global_control> threads;
  if (options.threads > 0) threads = std::make_unique<tbb::global_control>(tbb::global_control::max_allowed_parallelism, options.threads);
  Result<Eigen::Vector3f> background = background_colour(options.background);
  if (!background) return report_failure(output, result, background.error().message);
  const std::string ply = std::filesystem::is_directory(options.splats) ? (std::filesystem::path(options.splats) / "splats.ply").string() : options.splats;
  Result<neural::GaussianCloud> cloud = neural::read_splat_ply(ply);
  if (!cloud) return report_failure(output, result, cloud.error().message);
  neural::ViewDatasetConfig dataset_config;
  dataset_config.downscale = options.downscale;
  dataset_config.background = *background;
  dataset_config.load_images = false;
  Result<neural::ViewDataset> poses = neural::load_transforms(options.poses, dataset_config);
  if (!poses) return report_failure(output, result, poses.error().message);
  // Reference images where the poses file's images can be read (for PSNR and SSIM).
  dataset_config.load_images = true;
  Result<neural::ViewDataset> references = neural::load_transforms(options.poses, dataset_config);
  std::error_code created;
  std::filesystem::create_directories(options.out, created);
  if (created) return report_failure(output, result, fmt::format("{}: cannot create the folder ({})", options.out, created.message()));
  neural::RasterizerConfig config;
  config.background = *background;
  double seconds = 0.0;
  nlohmann::json files = nlohmann::json::array();
  for (std::size_t i = 0; i < poses->views.size(); ++i) {
    const neural::PosedView& view = poses->views[i];
    const auto begin = std::chrono::steady_clock::now();
    const neural::SplatRender render = neural::render_splats(*cloud, view.camera, config);
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
  result["gaussians"] = cloud->size();
  result["render_ms_per_view"] = 1000.0 * seconds / static_cast<double>(poses->views.size());
  result["files"] = files;
  std::string text = fmt::format("{}: {} views of {} Gaussians, {:.0f} ms per view\n", options.out, poses->views.size(), cloud->size(),
                                 1000.0 * seconds / static_cast<double>(poses->views.size()));
  if (references) {
    const neural::EvaluationSummary scores = neural::evaluate_splats(*cloud, references->views, config);
    result["eval"] = scores_json(scores);
    text += fmt::format("against the poses file's images: PSNR {:.2f} dB, SSIM {:.4f}\n", scores.mean_psnr, scores.mean_ssim);
  }
  return report_success(output, result, text);
}

}  // namespace

void add_reconstruct_command(CLI::App& app, const Output& output, Command& run) {
  CLI::App* reconstruct = app.add_subcommand("reconstruct", "Neural reconstruction from posed images: 3D Gaussian splats");
  reconstruct->require_subcommand(1);
  auto splats = std::make_shared<ReconstructOptions>();
  CLI::App* splats_app = reconstruct->add_subcommand("splats", "Train 3D Gaussian splats on the images of a transforms.json");
  splats_app->add_option("TRANSFORMS", splats->transforms, "NeRF / Blender-style transforms.json (camera-to-world poses, intrinsics, image paths)")
      ->required();
  splats_app->add_option("--out", splats->out, "Folder for splats.ply and reconstruction.json")->required();
  splats_app->add_option("--eval", splats->eval, "Held-back views (a transforms.json) scored after training");
  splats_app->add_option("--hold-every", splats->hold_every, "Hold back every N-th frame of TRANSFORMS and score them after training")->check(CLI::Range(2, 1000));
  splats_app->add_option("--downscale", splats->downscale, "Divide the images' resolution by this")->check(CLI::Range(1, 64));
  splats_app->add_option("--iterations", splats->iterations, "Training steps (one view each)")->check(CLI::Range(1, 10000000));
  splats_app->add_option("--max-gaussians", splats->max_gaussians, "Most Gaussians densification may make")->check(CLI::Range(1, 100000000));
  splats_app->add_option("--initial-gaussians", splats->initial_gaussians, "Gaussians of the random initialization")->check(CLI::Range(1, 100000000));
  splats_app->add_option("--sh-degree", splats->sh_degree, "Spherical-harmonics degree of the colours")->check(CLI::Range(0, 3));
  splats_app->add_option("--background", splats->background, "Behind transparent pixels and the Gaussians: white or black");
  splats_app->add_option("--seed", splats->seed, "Random seed (initialization, view order, splits)");
  splats_app->add_option("--threads", splats->threads, "Worker threads (default: all cores)")->check(CLI::Range(1, 1024));
  splats_app->add_option("--coarse-share", splats->coarse_share, "Share of the first steps trained at half resolution (0: none)")->check(CLI::Range(0.0, 1.0));
  splats_app->add_option("--max-seconds", splats->max_seconds, "Stop training after this many seconds (0: run every step)")->check(CLI::Range(0.0, 1e7));
  splats_app->add_option("--progress-seconds", splats->progress_seconds, "Seconds between progress lines on stderr")->check(CLI::Range(0.0, 1e6));
  splats_app->callback([&output, &run, splats] { run = [&output, splats] { return run_reconstruct_splats(output, *splats); }; });

  auto render = std::make_shared<RenderOptions>();
  CLI::App* render_app = app.add_subcommand("render", "Render trained splats at the cameras of a transforms.json, one PNG per frame");
  render_app->add_option("SPLATS", render->splats, "Folder written by reconstruct splats, or its splats.ply")->required();
  render_app->add_option("--poses", render->poses, "transforms.json whose frames give the cameras (and reference images, when present)")->required();
  render_app->add_option("--out", render->out, "Folder for the PNGs (0000.png, ... in frame order)")->required();
  render_app->add_option("--downscale", render->downscale, "Divide the poses' resolution by this")->check(CLI::Range(1, 64));
  render_app->add_flag("--depth", render->depth, "Also write depth (16-bit PNG, millimetres of the scene unit)");
  render_app->add_option("--background", render->background, "white or black");
  render_app->add_option("--threads", render->threads, "Worker threads (default: all cores)")->check(CLI::Range(1, 1024));
  render_app->callback([&output, &run, render] { run = [&output, render] { return run_render(output, *render); }; });
}

}  // namespace hanzo::fusion::app
