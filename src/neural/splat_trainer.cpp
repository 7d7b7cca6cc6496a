#include "hanzo/fusion/neural/splat_trainer.hpp"

#include <algorithm>
#include <map>
#include <limits>
#include <array>
#include <cmath>
#include <numeric>

#include <fmt/format.h>

#include "hanzo/fusion/core/logging.hpp"
#include "hanzo/fusion/neural/image_metrics.hpp"

namespace hanzo::fusion::neural {

namespace {

constexpr double kAdamBeta1 = 0.9, kAdamBeta2 = 0.999, kAdamEpsilon = 1e-15;
constexpr float kResetOpacity = 0.01f;
enum Group { kPosition = 0, kLogScale, kRotation, kOpacity, kSh, kGroups };

}  // namespace

Status validate(const SplatTrainingConfig& config) {
  if (config.iterations < 1) return Error("SplatTrainingConfig.iterations: must be >= 1", "iterations");
  if (config.sh_degree < 0 || config.sh_degree > kMaxShDegree) return Error("SplatTrainingConfig.sh_degree: must be 0..3", "sh_degree");
  if (config.sh_degree_interval < 1 || config.densify_interval < 1 || config.opacity_reset_interval < 0 || config.densify_from < 0 || config.densify_until < 0) {
    return Error("SplatTrainingConfig: sh_degree_interval and densify_interval must be >= 1, densify_from, densify_until and opacity_reset_interval >= 0");
  }
  if (!(config.max_screen_share > 0.0)) return Error("SplatTrainingConfig.max_screen_share: must be > 0", "max_screen_share");
  for (double rate : {config.position_lr_initial, config.position_lr_final, config.sh_dc_lr, config.sh_rest_lr, config.opacity_lr, config.scale_lr,
                      config.rotation_lr}) {
    if (!(rate >= 0.0 && std::isfinite(rate))) return Error("SplatTrainingConfig: learning rates must be finite and >= 0");
  }
  if (!(config.ssim_weight >= 0.0 && config.ssim_weight <= 1.0)) return Error("SplatTrainingConfig.ssim_weight: must be in [0, 1]", "ssim_weight");
  if (!(config.densify_gradient_threshold > 0.0) || !(config.dense_percent > 0.0) || !(config.min_opacity >= 0.0 && config.min_opacity < 1.0)) {
    return Error("SplatTrainingConfig: densify_gradient_threshold and dense_percent must be > 0, min_opacity in [0, 1)");
  }
  if (config.max_gaussians < 1 || config.initial_gaussians < 1) return Error("SplatTrainingConfig: max_gaussians and initial_gaussians must be >= 1");
  return ok_status();
}

GaussianCloud initialize_gaussians(const std::vector<PosedView>& views, const Eigen::Vector3d& centre, double half_size, int count, int sh_degree,
                                   uint64_t seed) {
  std::mt19937_64 random(seed);
  std::uniform_real_distribution<double> uniform(-half_size, half_size);
  const bool masked = std::any_of(views.begin(), views.end(), [](const PosedView& view) { return !view.mask.empty(); });
  // Inside the foreground of every masked view that sees the point.
  const auto in_hull = [&](const Eigen::Vector3d& point) {
    for (const PosedView& view : views) {
      if (view.mask.empty()) continue;
      const Eigen::Vector3d p = view.camera.R_camera_world * point + view.camera.t_camera_world;
      if (p.z() <= 0.0) continue;
      const auto u = static_cast<int>(std::lround(view.camera.fx * p.x() / p.z() + view.camera.cx));
      const auto v = static_cast<int>(std::lround(view.camera.fy * p.y() / p.z() + view.camera.cy));
      if (u < 0 || v < 0 || u >= view.image.width || v >= view.image.height) continue;
      if (view.mask[static_cast<std::size_t>(v) * static_cast<std::size_t>(view.image.width) + static_cast<std::size_t>(u)] < 0.5f) return false;
    }
    return true;
  };
  std::vector<Eigen::Vector3d> points;
  long tries = 0;
  const long max_tries = 200L * count;
  while (static_cast<int>(points.size()) < count && tries < max_tries) {
    ++tries;
    const Eigen::Vector3d point = centre + Eigen::Vector3d(uniform(random), uniform(random), uniform(random));
    if (!masked || in_hull(point)) points.push_back(point);
  }
  // Spacing of points spread over the accepted share of the cube.
  const double volume = std::pow(2.0 * half_size, 3.0) * static_cast<double>(points.size()) / static_cast<double>(std::max(1L, tries));
  const double spacing = std::cbrt(volume / static_cast<double>(std::max<std::size_t>(1, points.size())));
  GaussianCloud cloud;
  cloud.sh_degree = sh_degree;
  const auto log_scale = static_cast<float>(std::log(0.5 * spacing));
  for (const Eigen::Vector3d& point : points) {
    cloud.add(point.cast<float>(), Eigen::Vector3f::Constant(log_scale), Eigen::Vector4f(1, 0, 0, 0), logit(0.1f), Eigen::Vector3f::Zero());
  }
  return cloud;
}

GaussianCloud initialize_gaussians_at_points(const std::vector<PosedView>& views, const std::vector<Eigen::Vector3f>& points, int count, int sh_degree,
                                            uint64_t seed) {
  // An even selection: every point when there are few enough, else a seeded sample.
  std::vector<std::size_t> chosen(points.size());
  std::iota(chosen.begin(), chosen.end(), std::size_t{0});
  if (count > 0 && chosen.size() > static_cast<std::size_t>(count)) {
    std::mt19937_64 random(seed);
    std::shuffle(chosen.begin(), chosen.end(), random);
    chosen.resize(static_cast<std::size_t>(count));
    std::sort(chosen.begin(), chosen.end());
  }
  // The colour of the first view that sees the point.
  std::vector<Eigen::Vector3f> kept;
  std::vector<Eigen::Vector3f> colours;
  for (const std::size_t index : chosen) {
    const Eigen::Vector3d point = points[index].cast<double>();
    for (const PosedView& view : views) {
      const Eigen::Vector3d p = view.camera.R_camera_world * point + view.camera.t_camera_world;
      if (p.z() <= 0.0) continue;
      const auto u = static_cast<int>(std::lround(view.camera.fx * p.x() / p.z() + view.camera.cx));
      const auto v = static_cast<int>(std::lround(view.camera.fy * p.y() / p.z() + view.camera.cy));
      if (u < 0 || v < 0 || u >= view.image.width || v >= view.image.height) continue;
      const std::size_t pixel = 3 * (static_cast<std::size_t>(v) * static_cast<std::size_t>(view.image.width) + static_cast<std::size_t>(u));
      kept.push_back(points[index]);
      colours.emplace_back(view.image.pixels[pixel], view.image.pixels[pixel + 1], view.image.pixels[pixel + 2]);
      break;
    }
  }
  // Scales: the mean distance to the three nearest kept points (a voxel hash at the mean spacing).
  Eigen::AlignedBox3f box;
  for (const Eigen::Vector3f& point : kept) box.extend(point);
  // The points' mean spacing as if they filled their box, its largest face or its longest edge
  // (a map of surfaces, a floor, a line), whichever is largest.
  double spacing = 1.0;
  if (!kept.empty()) {
    Eigen::Vector3d extent = box.sizes().cast<double>();
    std::sort(extent.data(), extent.data() + 3);
    const auto n = static_cast<double>(kept.size());
    spacing = std::max({std::cbrt(extent.prod() / n), std::sqrt(extent(1) * extent(2) / n), extent(2) / n, 1e-6});
  }
  const auto cell_of = [spacing](const Eigen::Vector3f& point) {
    return std::array<int64_t, 3>{static_cast<int64_t>(std::floor(point.x() / spacing)), static_cast<int64_t>(std::floor(point.y() / spacing)),
                                  static_cast<int64_t>(std::floor(point.z() / spacing))};
  };
  std::map<std::array<int64_t, 3>, std::vector<std::size_t>> cells;
  for (std::size_t i = 0; i < kept.size(); ++i) cells[cell_of(kept[i])].push_back(i);
  GaussianCloud cloud;
  cloud.sh_degree = sh_degree;
  for (std::size_t i = 0; i < kept.size(); ++i) {
    std::array<float, 3> nearest{std::numeric_limits<float>::max(), std::numeric_limits<float>::max(), std::numeric_limits<float>::max()};
    const std::array<int64_t, 3> cell = cell_of(kept[i]);
    for (int64_t dz = -1; dz <= 1; ++dz) {
      for (int64_t dy = -1; dy <= 1; ++dy) {
        for (int64_t dx = -1; dx <= 1; ++dx) {
          const auto found = cells.find({cell[0] + dx, cell[1] + dy, cell[2] + dz});
          if (found == cells.end()) continue;
          for (const std::size_t j : found->second) {
            if (j == i) continue;
            const float distance = (kept[j] - kept[i]).norm();
            if (distance < nearest[2]) {
              nearest[2] = distance;
              std::sort(nearest.begin(), nearest.end());
            }
          }
        }
      }
    }
    float sum = 0.0f;
    int found = 0;
    for (const float distance : nearest) {
      if (distance == std::numeric_limits<float>::max()) continue;
      sum += distance;
      ++found;
    }
    const double scale = found > 0 ? sum / static_cast<float>(found) : spacing;
    cloud.add(kept[i], Eigen::Vector3f::Constant(static_cast<float>(std::log(std::max(1e-6, scale)))), Eigen::Vector4f(1, 0, 0, 0), logit(0.1f),
              sh_dc_of_colour(colours[i]));
  }
  return cloud;
}

Result<SplatTrainer> SplatTrainer::create(GaussianCloud initial, double scene_extent, SplatTrainingConfig config) {
  HANZO_RETURN_IF_ERROR(validate(config));
  if (!initial.consistent()) return Error("SplatTrainer: the initial Gaussians' arrays do not fit their count and degree, or hold non-finite values");
  if (initial.size() == 0) return Error("SplatTrainer: no initial Gaussians");
  if (initial.sh_degree != config.sh_degree) return Error(fmt::format("SplatTrainer: the initial Gaussians are of degree {}, the config's {}", initial.sh_degree, config.sh_degree));
  if (!(scene_extent > 0.0 && std::isfinite(scene_extent))) return Error("SplatTrainer: the scene extent must be positive");
  if (config.densify_until == 0) config.densify_until = config.iterations / 2;
  if (config.densify_from == 0) config.densify_from = std::min(500, config.iterations / 10);
  if (config.opacity_reset_interval == 0) config.opacity_reset_interval = std::max(1000, config.iterations / 10);
  SplatTrainer trainer;
  trainer.cloud_ = std::move(initial);
  trainer.extent_ = scene_extent;
  trainer.config_ = config;
  trainer.random_.seed(config.seed);
  if (config.device != SplatDevice::kCpu) {
    Result<CudaSplatRasterizer> gpu = CudaSplatRasterizer::create();
    if (gpu) {
      trainer.gpu_ = std::make_shared<CudaSplatRasterizer>(std::move(gpu).value());
    } else if (config.device == SplatDevice::kCuda) {
      return Error(fmt::format("SplatTrainer: device cuda: {}", gpu.error().message));
    } else {
      logger()->info("SplatTrainer: training on the CPU ({})", gpu.error().message);
    }
  }
  trainer.gradients_.resize_like(trainer.cloud_);
  for (std::span<float> group : trainer.cloud_.parameters()) {
    trainer.adam_m_.emplace_back(group.size(), 0.0f);
    trainer.adam_v_.emplace_back(group.size(), 0.0f);
  }
  trainer.densify_gradient_sum_.assign(trainer.cloud_.size(), 0.0f);
  trainer.densify_count_.assign(trainer.cloud_.size(), 0);
  trainer.max_screen_share_.assign(trainer.cloud_.size(), 0.0f);
  return trainer;
}

RasterizerConfig SplatTrainer::render_config() const {
  RasterizerConfig config = config_.rasterizer;
  config.active_sh_degree = std::min(config_.sh_degree, iteration_ / config_.sh_degree_interval);
  return config;
}

double SplatTrainer::loss_of(const SplatRender& render, const PosedView& view, std::vector<float>& loss_gradient) const {
  const std::vector<float>& image = view.image.pixels;
  const auto count = static_cast<double>(render.image.size());
  loss_gradient.resize(render.image.size());
  double l1 = 0.0;
  const auto l1_weight = static_cast<float>((1.0 - config_.ssim_weight) / count);
  for (std::size_t i = 0; i < render.image.size(); ++i) {
    const float difference = render.image[i] - image[i];
    l1 += std::abs(difference);
    loss_gradient[i] = difference > 0.0f ? l1_weight : difference < 0.0f ? -l1_weight : 0.0f;
  }
  double loss = (1.0 - config_.ssim_weight) * l1 / count;
  if (config_.ssim_weight > 0.0) {
    std::vector<float> ssim_gradient;
    const double similarity = ssim(render.image, image, render.width, render.height, &ssim_gradient);
    loss += config_.ssim_weight * (1.0 - similarity);
    for (std::size_t i = 0; i < loss_gradient.size(); ++i) loss_gradient[i] -= static_cast<float>(config_.ssim_weight) * ssim_gradient[i];
  }
  return loss;
}

bool SplatTrainer::gpu_pass(const PosedView& view, const RasterizerConfig& rasterizer, SplatRender& render, double& loss) {
  gradients_.set_zero();
  Status status = gpu_->upload(cloud_);
  if (status) {
    Result<SplatRender> rendered = gpu_->render(view.camera, rasterizer);
    if (rendered) {
      render = std::move(rendered).value();
      std::vector<float> loss_gradient;
      loss = loss_of(render, view, loss_gradient);
      status = gpu_->backward(loss_gradient, gradients_);
    } else {
      status = rendered.error();
    }
  }
  if (status) return true;
  logger()->warn("SplatTrainer: the CUDA device failed ({}); training continues on the CPU", status.error().message);
  gpu_.reset();
  return false;
}

std::string SplatTrainer::device_name() const { return gpu_ ? gpu_->device_name() : "cpu"; }

double SplatTrainer::step(const PosedView& view) {
  const RasterizerConfig rasterizer = render_config();
  SplatRender render;
  double loss = 0.0;
  if (!gpu_ || !gpu_pass(view, rasterizer, render, loss)) {
    render = render_splats(cloud_, view.camera, rasterizer);
    std::vector<float> loss_gradient;
    loss = loss_of(render, view, loss_gradient);
    gradients_.set_zero();
    render_splats_backward(cloud_, view.camera, rasterizer, render, loss_gradient, gradients_);
  }

  // Adam (Kingma and Ba, ICLR 2015, Algorithm 1) per parameter group.
  ++iteration_;
  const double progress = std::min(1.0, static_cast<double>(iteration_) / static_cast<double>(config_.iterations));
  const double position_lr = extent_ * std::exp(std::log(config_.position_lr_initial) * (1.0 - progress) + std::log(config_.position_lr_final) * progress);
  const double bias1 = 1.0 - std::pow(kAdamBeta1, iteration_), bias2 = 1.0 - std::pow(kAdamBeta2, iteration_);
  std::vector<std::span<float>> parameters = cloud_.parameters();
  std::vector<std::span<float>> gradient_groups = gradients_.parameters();
  const int dc_floats = 3;
  const int sh_floats = cloud_.sh_floats();
  for (int group = 0; group < kGroups; ++group) {
    std::span<float> values = parameters[static_cast<std::size_t>(group)];
    std::span<const float> gradient = gradient_groups[static_cast<std::size_t>(group)];
    std::vector<float>& m = adam_m_[static_cast<std::size_t>(group)];
    std::vector<float>& v = adam_v_[static_cast<std::size_t>(group)];
    const double base_lr = group == kPosition ? position_lr : group == kLogScale ? config_.scale_lr : group == kRotation ? config_.rotation_lr
                                                            : group == kOpacity  ? config_.opacity_lr : config_.sh_dc_lr;
    for (std::size_t i = 0; i < values.size(); ++i) {
      // Only parameters with a gradient in this view move (sparse Adam: Gaussians out of view keep
      // their moments until they are seen again).
      const float g = gradient[i];
      if (g == 0.0f) continue;
      const double lr = group == kSh && static_cast<int>(i % static_cast<std::size_t>(sh_floats)) >= dc_floats ? config_.sh_rest_lr : base_lr;
      m[i] = static_cast<float>(kAdamBeta1 * m[i] + (1.0 - kAdamBeta1) * g);
      v[i] = static_cast<float>(kAdamBeta2 * v[i] + (1.0 - kAdamBeta2) * static_cast<double>(g) * g);
      values[i] -= static_cast<float>(lr * (m[i] / bias1) / (std::sqrt(v[i] / bias2) + kAdamEpsilon));
    }
  }
  const float image_size = static_cast<float>(std::max(render.width, render.height));
  for (std::size_t i = 0; i < cloud_.size(); ++i) {
    if (gradients_.visible_views[i] == 0) continue;
    densify_gradient_sum_[i] += gradients_.screen_gradient_norm[i];
    densify_count_[i] += 1;
    max_screen_share_[i] = std::max(max_screen_share_[i], static_cast<float>(render.radius[i]) / image_size);
  }

  if (iteration_ < config_.densify_until && iteration_ >= config_.densify_from && iteration_ % config_.densify_interval == 0) densify_and_prune();
  if (iteration_ < config_.densify_until && iteration_ % config_.opacity_reset_interval == 0) reset_opacity();
  return loss;
}

void SplatTrainer::grow_optimizer_state() {
  for (int group = 0; group < kGroups; ++group) {
    const std::size_t size = cloud_.parameters()[static_cast<std::size_t>(group)].size();
    adam_m_[static_cast<std::size_t>(group)].resize(size, 0.0f);
    adam_v_[static_cast<std::size_t>(group)].resize(size, 0.0f);
  }
}

Status SplatTrainer::add_gaussians(const GaussianCloud& more) {
  if (more.sh_degree != cloud_.sh_degree) return Error(fmt::format("SplatTrainer: Gaussians of degree {} added to degree {}", more.sh_degree, cloud_.sh_degree));
  if (!more.consistent()) return Error("SplatTrainer: the added Gaussians' arrays do not fit their count and degree, or hold non-finite values");
  const std::size_t cap = static_cast<std::size_t>(config_.max_gaussians);
  const std::size_t count = std::min(more.size(), cap > cloud_.size() ? cap - cloud_.size() : 0);
  const auto append = [count](std::vector<float>& to, const std::vector<float>& from, std::size_t width) {
    to.insert(to.end(), from.begin(), from.begin() + static_cast<std::ptrdiff_t>(count * width));
  };
  append(cloud_.position, more.position, 3);
  append(cloud_.log_scale, more.log_scale, 3);
  append(cloud_.rotation, more.rotation, 4);
  append(cloud_.opacity_logit, more.opacity_logit, 1);
  append(cloud_.sh, more.sh, static_cast<std::size_t>(cloud_.sh_floats()));
  grow_optimizer_state();
  densify_gradient_sum_.resize(cloud_.size(), 0.0f);
  densify_count_.resize(cloud_.size(), 0);
  max_screen_share_.resize(cloud_.size(), 0.0f);
  gradients_.resize_like(cloud_);
  return ok_status();
}

void SplatTrainer::apply_keep(const std::vector<bool>& keep) {
  cloud_.filter(keep);
  const std::size_t sh_width = static_cast<std::size_t>(cloud_.sh_floats());
  const std::size_t widths[kGroups] = {3, 3, 4, 1, sh_width};
  for (int group = 0; group < kGroups; ++group) {
    for (std::vector<float>* state : {&adam_m_[static_cast<std::size_t>(group)], &adam_v_[static_cast<std::size_t>(group)]}) {
      std::size_t out = 0;
      const std::size_t width = widths[group];
      for (std::size_t i = 0; i < keep.size(); ++i) {
        if (!keep[i]) continue;
        std::copy_n(state->begin() + static_cast<std::ptrdiff_t>(i * width), width, state->begin() + static_cast<std::ptrdiff_t>(out * width));
        ++out;
      }
      state->resize(out * width);
    }
  }
  gradients_.resize_like(cloud_);
}

void SplatTrainer::append_gaussians(const std::vector<std::size_t>& sources, bool split) {
  std::normal_distribution<float> normal(0.0f, 1.0f);
  const int copies = split ? 2 : 1;
  for (std::size_t source : sources) {
    const Eigen::Vector3f mean = Eigen::Map<const Eigen::Vector3f>(&cloud_.position[3 * source]);
    Eigen::Vector3f log_scale = Eigen::Map<const Eigen::Vector3f>(&cloud_.log_scale[3 * source]);
    const Eigen::Vector4f rotation = Eigen::Map<const Eigen::Vector4f>(&cloud_.rotation[4 * source]);
    const Eigen::Quaternionf q(rotation[0], rotation[1], rotation[2], rotation[3]);
    const Eigen::Vector3f scale = log_scale.array().exp();
    if (split) log_scale = (scale / 1.6f).array().log();
    const float opacity = cloud_.opacity_logit[source];
    const std::vector<float> sh(cloud_.sh.begin() + static_cast<std::ptrdiff_t>(source) * cloud_.sh_floats(),
                                cloud_.sh.begin() + static_cast<std::ptrdiff_t>(source + 1) * cloud_.sh_floats());
    for (int c = 0; c < copies; ++c) {
      Eigen::Vector3f position = mean;
      if (split) position += q.normalized() * Eigen::Vector3f(scale.x() * normal(random_), scale.y() * normal(random_), scale.z() * normal(random_));
      cloud_.add(position, log_scale, rotation, opacity, Eigen::Vector3f::Zero());
      std::copy(sh.begin(), sh.end(), cloud_.sh.end() - cloud_.sh_floats());
    }
  }
  grow_optimizer_state();
}

void SplatTrainer::densify_and_prune() {
  const std::size_t n = cloud_.size();
  std::vector<std::pair<float, std::size_t>> candidates;  // mean gradient, index
  for (std::size_t i = 0; i < n; ++i) {
    if (densify_count_[i] == 0) continue;
    const float mean = densify_gradient_sum_[i] / static_cast<float>(densify_count_[i]);
    if (mean >= config_.densify_gradient_threshold) candidates.emplace_back(mean, i);
  }
  // The strongest first, as many as the cap allows (a split adds one net, a clone one).
  std::sort(candidates.begin(), candidates.end(), [](const auto& a, const auto& b) { return a.first > b.first || (a.first == b.first && a.second < b.second); });
  const std::size_t room = static_cast<std::size_t>(config_.max_gaussians) > n ? static_cast<std::size_t>(config_.max_gaussians) - n : 0;
  if (candidates.size() > room) candidates.resize(room);
  std::vector<std::size_t> clones, splits;
  const auto dense_scale = static_cast<float>(config_.dense_percent * extent_);
  for (const auto& [gradient, i] : candidates) {
    const float largest = std::exp(Eigen::Map<const Eigen::Vector3f>(&cloud_.log_scale[3 * i]).maxCoeff());
    (largest <= dense_scale ? clones : splits).push_back(i);
  }
  std::sort(clones.begin(), clones.end());
  std::sort(splits.begin(), splits.end());
  append_gaussians(clones, false);
  append_gaussians(splits, true);
  // Remove the split originals, the transparent and (after an opacity reset) the huge.
  std::vector<bool> keep(cloud_.size(), true);
  for (std::size_t i : splits) keep[i] = false;
  const bool prune_large = iteration_ > config_.opacity_reset_interval;
  for (std::size_t i = 0; i < cloud_.size(); ++i) {
    if (sigmoid(cloud_.opacity_logit[i]) < config_.min_opacity) keep[i] = false;
    if (!prune_large) continue;
    if (std::exp(Eigen::Map<const Eigen::Vector3f>(&cloud_.log_scale[3 * i]).maxCoeff()) > 0.1 * extent_) keep[i] = false;
    if (i < max_screen_share_.size() && max_screen_share_[i] > config_.max_screen_share) keep[i] = false;  // new ones have no record yet
  }
  apply_keep(keep);
  densify_gradient_sum_.assign(cloud_.size(), 0.0f);
  densify_count_.assign(cloud_.size(), 0);
  max_screen_share_.assign(cloud_.size(), 0.0f);
}

void SplatTrainer::reset_opacity() {
  const float ceiling = logit(kResetOpacity);
  for (float& value : cloud_.opacity_logit) value = std::min(value, ceiling);
  std::fill(adam_m_[kOpacity].begin(), adam_m_[kOpacity].end(), 0.0f);
  std::fill(adam_v_[kOpacity].begin(), adam_v_[kOpacity].end(), 0.0f);
}

EvaluationSummary evaluate_splats(const GaussianCloud& cloud, const std::vector<PosedView>& views, const RasterizerConfig& config) {
  return score_views(views, [&](const SplatCamera& camera) { return render_splats(cloud, camera, config).image; });
}

}  // namespace hanzo::fusion::neural
