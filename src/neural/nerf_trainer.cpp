#include "hanzo/fusion/neural/nerf_trainer.hpp"

#include <algorithm>
#include <cmath>

#include <fmt/format.h>
#include <tbb/parallel_for.h>

#include "hanzo/fusion/neural/image_metrics.hpp"
#include "hanzo/fusion/neural/volume_rendering.hpp"
#include "nerf_network.hpp"

namespace hanzo::fusion::neural {

Status validate(const NerfTrainingConfig& config) {
  if (config.iterations < 1) return Error("NerfTrainingConfig.iterations: must be >= 1", "iterations");
  if (config.samples_per_step < 256) return Error("NerfTrainingConfig.samples_per_step: must be >= 256", "samples_per_step");
  if (config.max_samples_per_ray < 1) return Error("NerfTrainingConfig.max_samples_per_ray: must be >= 1", "max_samples_per_ray");
  if (!(config.learning_rate > 0.0) || !(config.final_learning_rate > 0.0)) return Error("NerfTrainingConfig: learning rates must be > 0");
  if (!(config.adam_beta1 >= 0.0 && config.adam_beta1 < 1.0 && config.adam_beta2 >= 0.0 && config.adam_beta2 < 1.0 && config.adam_epsilon >= 0.0)) {
    return Error("NerfTrainingConfig: Adam's betas must be in [0, 1), epsilon >= 0");
  }
  if (config.occupancy_interval < 1 || config.occupancy_warmup < 0 || !(config.occupancy_share > 0.0 && config.occupancy_share <= 1.0)) {
    return Error("NerfTrainingConfig: occupancy_interval >= 1, occupancy_warmup >= 0, occupancy_share in (0, 1]");
  }
  return ok_status();
}

void set_scene_box(const ViewDataset& dataset, NerfFieldConfig& config) {
  if (dataset.box_half_size > 0.0) {
    config.box_centre = dataset.box_centre;
    config.box_half_size = dataset.box_half_size;
  } else if (dataset.aabb_scale > 0.0) {
    config.box_centre = Eigen::Vector3d::Zero();
    config.box_half_size = 1.5 * dataset.aabb_scale;
  } else {
    config.box_centre = dataset.scene_centre;
    config.box_half_size = 0.375 * dataset.camera_distance;
  }
}

NerfTrainer::NerfTrainer(NerfTrainer&&) noexcept = default;
NerfTrainer& NerfTrainer::operator=(NerfTrainer&&) noexcept = default;
NerfTrainer::~NerfTrainer() = default;

Result<NerfTrainer> NerfTrainer::create(NerfField field, const std::vector<PosedView>& views, const NerfTrainingConfig& config) {
  HANZO_RETURN_IF_ERROR(validate(config));
  if (views.empty()) return Error("NerfTrainer: no training views");
  for (const PosedView& view : views) {
    if (view.image.pixels.empty()) return Error(fmt::format("NerfTrainer: view '{}' has no image", view.name));
  }
  NerfTrainer trainer(std::move(field));
  trainer.views_ = &views;
  trainer.config_ = config;
  trainer.random_.seed(config.seed);
  for (std::span<float> group : trainer.field_.network().parameters()) {
    trainer.adam_m_.emplace_back(group.size(), 0.0f);
    trainer.adam_v_.emplace_back(group.size(), 0.0f);
    trainer.gradients_.emplace_back(group.size(), 0.0f);
  }
  trainer.mark_seen_cells();
  return trainer;
}

void NerfTrainer::mark_seen_cells() {
  OccupancyGrid& grid = field_.occupancy();
  const int n = grid.resolution();
  const NerfFieldConfig& c = field_.config();
  std::vector<uint8_t> seen(grid.cells(), 0);
  tbb::parallel_for(0, n, [&](int z) {
    for (int y = 0; y < n; ++y) {
      for (int x = 0; x < n; ++x) {
        const Eigen::Vector3d unit((x + 0.5) / n, (y + 0.5) / n, (z + 0.5) / n);
        const Eigen::Vector3d point = c.box_centre + 2.0 * c.box_half_size * (unit - Eigen::Vector3d::Constant(0.5));
        const std::size_t cell = (static_cast<std::size_t>(z) * static_cast<std::size_t>(n) + static_cast<std::size_t>(y)) * static_cast<std::size_t>(n) +
                                 static_cast<std::size_t>(x);
        for (const PosedView& view : *views_) {
          const Eigen::Vector3d p = view.camera.R_camera_world * point + view.camera.t_camera_world;
          if (p.z() <= c.near) continue;
          const double u = view.camera.fx * p.x() / p.z() + view.camera.cx, v = view.camera.fy * p.y() / p.z() + view.camera.cy;
          if (u >= -0.5 && v >= -0.5 && u < view.camera.width - 0.5 && v < view.camera.height - 0.5) {
            seen[cell] = 1;
            break;
          }
        }
      }
    }
  });
  grid.set_seen(seen);
}

void NerfTrainer::update_occupancy() {
  const bool all = iteration_ < config_.occupancy_warmup;
  field_.occupancy().update([this](const float* positions, std::size_t count, float* density) { field_.density(positions, count, density); },
                            field_.step(), all, config_.occupancy_share, random_);
}

void NerfTrainer::adam_step(double learning_rate) {
  // Adam (Kingma and Ba, ICLR 2015, Algorithm 1); entries without a gradient stay as they are.
  const std::vector<std::span<float>> parameters = field_.network().parameters();
  const double bias1 = 1.0 - std::pow(config_.adam_beta1, iteration_), bias2 = 1.0 - std::pow(config_.adam_beta2, iteration_);
  const auto beta1 = static_cast<float>(config_.adam_beta1), beta2 = static_cast<float>(config_.adam_beta2);
  const auto step_size = static_cast<float>(learning_rate / bias1);
  const auto root_bias2 = static_cast<float>(std::sqrt(bias2));
  const auto epsilon = static_cast<float>(config_.adam_epsilon);
  for (std::size_t group = 0; group < parameters.size(); ++group) {
    float* values = parameters[group].data();
    const float* gradient = gradients_[group].data();
    float* m = adam_m_[group].data();
    float* v = adam_v_[group].data();
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, adam_m_[group].size(), 1 << 16), [&](const tbb::blocked_range<std::size_t>& range) {
      for (std::size_t i = range.begin(); i != range.end(); ++i) {
        const float g = gradient[i];
        if (g == 0.0f) continue;
        m[i] = beta1 * m[i] + (1.0f - beta1) * g;
        v[i] = beta2 * v[i] + (1.0f - beta2) * g * g;
        values[i] -= step_size * m[i] / (std::sqrt(v[i]) / root_bias2 + epsilon);
      }
    });
  }
}

void NerfTrainer::draw_rays(RayBatch& batch) {
  const std::vector<PosedView>& views = *views_;
  std::uniform_int_distribution<std::size_t> any_view(0, views.size() - 1);
  std::uniform_real_distribution<float> unit(0.0f, 1.0f);
  const float step_length = field_.step();
  RaySamples& samples = batch.samples;
  const auto budget = static_cast<std::size_t>(config_.samples_per_step);
  int marched = 0;
  while (marched < rays_ && samples.size() < budget) {
    const PosedView& view = views[any_view(random_)];
    const SplatCamera& camera = view.camera;
    const auto u = static_cast<int>(unit(random_) * static_cast<float>(camera.width)) % camera.width;
    const auto v = static_cast<int>(unit(random_) * static_cast<float>(camera.height)) % camera.height;
    const Eigen::Vector3d ray_camera((u + unit(random_) - 0.5 - camera.cx) / camera.fx, (v + unit(random_) - 0.5 - camera.cy) / camera.fy, 1.0);
    const Eigen::Vector3f direction = (camera.R_camera_world.transpose() * ray_camera.normalized()).cast<float>();
    const Eigen::Vector3f origin = field_.to_unit(camera.centre_world());
    ++marched;
    float t = 0.0f, t_end = 0.0f;
    if (!field_.ray_span(origin, direction, t, t_end)) continue;
    t += unit(random_) * step_length;
    const std::size_t before = samples.size();
    field_.occupancy().march(origin, direction, step_length, t_end, config_.max_samples_per_ray, t, samples);
    if (samples.size() > budget && before > 0) {  // over budget: leave this ray out
      samples.t.resize(before);
      samples.dt.resize(before);
      samples.position.resize(3 * before);
      samples.ray_begin.pop_back();
      break;
    }
    const std::size_t pixel = static_cast<std::size_t>(v) * static_cast<std::size_t>(camera.width) + static_cast<std::size_t>(u);
    Eigen::Vector3f colour = Eigen::Map<const Eigen::Vector3f>(&view.image.pixels[3 * pixel]);
    Eigen::Vector3f back = config_.image_background;
    if (!view.mask.empty() && config_.random_background) {
      back = Eigen::Vector3f(unit(random_), unit(random_), unit(random_));
      colour += (1.0f - view.mask[pixel]) * (back - config_.image_background);
    }
    batch.directions.push_back(direction);
    batch.target.insert(batch.target.end(), colour.data(), colour.data() + 3);
    batch.background.insert(batch.background.end(), back.data(), back.data() + 3);
  }
}

double NerfTrainer::step() {
  if (iteration_ % config_.occupancy_interval == 0) update_occupancy();
  // Rays of random pixels, marched until the step's sample budget is spent.
  RayBatch batch;
  draw_rays(batch);
  const RaySamples& samples = batch.samples;
  const std::vector<float>& target = batch.target;
  const std::vector<float>& background = batch.background;
  const auto budget = static_cast<std::size_t>(config_.samples_per_step);
  const std::size_t rays = samples.rays();
  const std::size_t count = samples.size();
  // The next step's ray count from the running samples per ray.
  const double per_ray = rays > 0 ? static_cast<double>(count) / static_cast<double>(rays) : 1.0;
  samples_per_ray_ = iteration_ == 0 ? per_ray : 0.9 * samples_per_ray_ + 0.1 * per_ray;
  rays_ = static_cast<int>(std::clamp(static_cast<double>(budget) / std::max(1.0, samples_per_ray_), 256.0, 262144.0));
  ++iteration_;
  if (rays == 0 || count == 0) return 0.0;

  std::vector<float> sample_directions(3 * count);
  for (std::size_t r = 0; r < rays; ++r) {
    for (uint32_t i = samples.ray_begin[r]; i < samples.ray_begin[r + 1]; ++i) std::copy_n(batch.directions[r].data(), 3, &sample_directions[3 * i]);
  }
  NerfField::Network& network = field_.network();
  std::vector<float> density(count), colour(3 * count);
  network.forward(samples.position.data(), sample_directions.data(), count, density.data(), colour.data(), &network.training_cache);
  const CompositeResult rendered = composite(samples, density.data(), colour.data(), background.data());
  std::vector<float> colour_gradient(3 * rays);
  double squared = 0.0;
  const float scale = 2.0f / static_cast<float>(3 * rays);
  for (std::size_t i = 0; i < 3 * rays; ++i) {
    const float difference = rendered.colour[i] - target[i];
    squared += static_cast<double>(difference) * difference;
    colour_gradient[i] = scale * difference;
  }
  std::vector<float> density_gradient(count), sample_colour_gradient(3 * count);
  composite_backward(samples, density.data(), colour.data(), rendered, colour_gradient.data(), density_gradient.data(), sample_colour_gradient.data());
  for (std::vector<float>& gradient : gradients_) std::fill(gradient.begin(), gradient.end(), 0.0f);
  network.backward(samples.position.data(), count, network.training_cache, density_gradient.data(), sample_colour_gradient.data(), gradients_);

  const double progress = static_cast<double>(iteration_) / static_cast<double>(config_.iterations);
  const double decay = std::clamp(2.0 * progress - 1.0, 0.0, 1.0);
  const double learning_rate = std::exp(std::log(config_.learning_rate) * (1.0 - decay) + std::log(config_.final_learning_rate) * decay);
  adam_step(learning_rate);
  return squared / static_cast<double>(3 * rays);
}

EvaluationSummary evaluate_nerf(const NerfField& field, const std::vector<PosedView>& views, const Eigen::Vector3f& background) {
  return score_views(views, [&](const SplatCamera& camera) { return field.render(camera, background).image; });
}

}  // namespace hanzo::fusion::neural
