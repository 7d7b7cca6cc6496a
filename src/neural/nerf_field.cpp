#include "hanzo/fusion/neural/nerf_field.hpp"

#include <algorithm>
#include <cmath>
#include <random>
#include <utility>

#include <fmt/format.h>
#include <tbb/parallel_for.h>

#include "nerf_network.hpp"
#include "spherical_harmonics.hpp"

namespace hanzo::fusion::neural {

namespace {

constexpr float kMinTransmittance = 1e-4f;
constexpr float kLogDensityLimit = 15.0f;

float density_of(float log_density) { return std::exp(std::clamp(log_density, -kLogDensityLimit, kLogDensityLimit)); }

}  // namespace

Status validate(const NerfFieldConfig& config) {
  HANZO_RETURN_IF_ERROR(validate(config.encoding));
  if (config.hidden_width < 1 || config.hidden_width > 1024) return Error("NerfFieldConfig.hidden_width: must be 1..1024", "hidden_width");
  if (config.steps_per_diagonal < 8 || config.steps_per_diagonal > 65536) return Error("NerfFieldConfig.steps_per_diagonal: must be 8..65536", "steps_per_diagonal");
  if (config.occupancy.resolution < 1 || config.occupancy.resolution > 1024) return Error("NerfFieldConfig.occupancy.resolution: must be 1..1024", "resolution");
  if (!(config.near >= 0.0 && std::isfinite(config.near))) return Error("NerfFieldConfig.near: must be finite and >= 0", "near");
  if (!(config.box_half_size > 0.0 && std::isfinite(config.box_half_size)) || !config.box_centre.allFinite()) {
    return Error("NerfFieldConfig: the scene box needs a finite centre and a positive half size", "box_half_size");
  }
  return ok_status();
}

NerfField::Network::Network(const NerfFieldConfig& field_config)
    : config(field_config),
      encoding(field_config.encoding),
      density_network(MlpShape{encoding.output_width(), field_config.hidden_width, 1, kDensityOutputs}),
      colour_network(MlpShape{kDensityOutputs + kDirectionFeatures, field_config.hidden_width, 2, 3}),
      occupancy(field_config.occupancy) {
  std::mt19937_64 random(config.seed);
  // The table starts near zero (uniform +-1e-4, the paper's Sec. 4), the networks Xavier-uniform.
  std::uniform_real_distribution<float> small(-1e-4f, 1e-4f);
  table.resize(encoding.parameter_count());
  for (float& value : table) value = small(random);
  density_weights.resize(density_network.parameter_count());
  density_network.initialize(density_weights.data(), random);
  colour_weights.resize(colour_network.parameter_count());
  colour_network.initialize(colour_weights.data(), random);
}

std::vector<std::span<float>> NerfField::Network::parameters() { return {table, density_weights, colour_weights}; }
std::vector<std::span<const float>> NerfField::Network::parameters() const { return {table, density_weights, colour_weights}; }

void NerfField::Network::density(const float* positions, std::size_t count, float* out) const {
  std::vector<float> encoded(count * static_cast<std::size_t>(encoding.output_width()));
  encoding.forward(table.data(), positions, count, encoded.data());
  std::vector<float> outputs(count * kDensityOutputs);
  density_network.forward(density_weights.data(), encoded.data(), count, outputs.data());
  for (std::size_t i = 0; i < count; ++i) out[i] = density_of(outputs[i * kDensityOutputs]);
}

void NerfField::Network::forward(const float* positions, const float* directions, std::size_t count, float* density, float* colour, Cache* cache) const {
  Cache local;
  Cache& c = cache != nullptr ? *cache : local;
  c.encoded.resize(count * static_cast<std::size_t>(encoding.output_width()));
  encoding.forward(table.data(), positions, count, c.encoded.data());
  c.density_output.resize(count * kDensityOutputs);
  c.density_hidden.resize(cache != nullptr ? count * density_network.activation_floats() : 0);
  density_network.forward(density_weights.data(), c.encoded.data(), count, c.density_output.data(), cache != nullptr ? c.density_hidden.data() : nullptr);
  constexpr int kColourInputs = kDensityOutputs + kDirectionFeatures;
  c.colour_input.resize(count * kColourInputs);
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, count, 4096), [&](const tbb::blocked_range<std::size_t>& range) {
    for (std::size_t i = range.begin(); i != range.end(); ++i) {
      float* in = &c.colour_input[i * kColourInputs];
      std::copy_n(&c.density_output[i * kDensityOutputs], kDensityOutputs, in);
      detail::sh_basis(3, directions[3 * i], directions[3 * i + 1], directions[3 * i + 2], in + kDensityOutputs);
      density[i] = density_of(c.density_output[i * kDensityOutputs]);
    }
  });
  c.colour_hidden.resize(cache != nullptr ? count * colour_network.activation_floats() : 0);
  c.colour.resize(3 * count);
  colour_network.forward(colour_weights.data(), c.colour_input.data(), count, c.colour.data(), cache != nullptr ? c.colour_hidden.data() : nullptr);
  for (std::size_t i = 0; i < 3 * count; ++i) {
    c.colour[i] = 1.0f / (1.0f + std::exp(-c.colour[i]));  // sigmoid
    colour[i] = c.colour[i];
  }
}

void NerfField::Network::backward(const float* positions, std::size_t count, Cache& c, const float* density_gradient, const float* colour_gradient,
                                  std::vector<std::vector<float>>& gradients) const {
  constexpr int kColourInputs = kDensityOutputs + kDirectionFeatures;
  // Through the sigmoid, then the colour network.
  std::vector<float> raw_gradient(3 * count);
  for (std::size_t i = 0; i < 3 * count; ++i) raw_gradient[i] = colour_gradient[i] * c.colour[i] * (1.0f - c.colour[i]);
  std::vector<float> colour_input_gradient(count * kColourInputs);
  colour_network.backward(colour_weights.data(), c.colour_input.data(), c.colour_hidden.data(), count, raw_gradient.data(), gradients[2].data(),
                          colour_input_gradient.data());
  // The density network's outputs: their share of the colour input, and the density through exp.
  std::vector<float> density_output_gradient(count * kDensityOutputs);
  for (std::size_t i = 0; i < count; ++i) {
    std::copy_n(&colour_input_gradient[i * kColourInputs], kDensityOutputs, &density_output_gradient[i * kDensityOutputs]);
    const float log_density = c.density_output[i * kDensityOutputs];
    if (std::abs(log_density) < kLogDensityLimit) density_output_gradient[i * kDensityOutputs] += density_gradient[i] * density_of(log_density);
  }
  std::vector<float> encoded_gradient(c.encoded.size());
  density_network.backward(density_weights.data(), c.encoded.data(), c.density_hidden.data(), count, density_output_gradient.data(), gradients[1].data(),
                           encoded_gradient.data());
  encoding.backward(positions, count, encoded_gradient.data(), gradients[0].data());
}

NerfField::NerfField() = default;
NerfField::NerfField(NerfField&&) noexcept = default;
NerfField& NerfField::operator=(NerfField&&) noexcept = default;
NerfField::~NerfField() = default;

Result<NerfField> NerfField::create(const NerfFieldConfig& config) {
  HANZO_RETURN_IF_ERROR(validate(config));
  NerfField field;
  field.network_ = std::make_unique<Network>(config);
  return field;
}

const NerfFieldConfig& NerfField::config() const { return network_->config; }
const HashGrid& NerfField::encoding() const { return network_->encoding; }
OccupancyGrid& NerfField::occupancy() { return network_->occupancy; }
const OccupancyGrid& NerfField::occupancy() const { return network_->occupancy; }
NerfField::Network& NerfField::network() { return *network_; }
const NerfField::Network& NerfField::network() const { return *network_; }
float NerfField::step() const { return std::sqrt(3.0f) / static_cast<float>(network_->config.steps_per_diagonal); }

std::size_t NerfField::parameter_count() const {
  std::size_t count = 0;
  for (std::span<const float> group : std::as_const(*network_).parameters()) count += group.size();
  return count;
}

Eigen::Vector3f NerfField::to_unit(const Eigen::Vector3d& point_scene) const {
  const NerfFieldConfig& c = network_->config;
  return ((point_scene - c.box_centre) / (2.0 * c.box_half_size) + Eigen::Vector3d::Constant(0.5)).cast<float>();
}

bool NerfField::ray_span(const Eigen::Vector3f& origin, const Eigen::Vector3f& direction, float& t_begin, float& t_end) const {
  if (!OccupancyGrid::intersect(origin, direction, t_begin, t_end)) return false;
  t_begin = std::max(t_begin, static_cast<float>(network_->config.near / unit_to_scene_length()));
  return t_begin < t_end;
}

void NerfField::density(const float* positions, std::size_t count, float* density) const { network_->density(positions, count, density); }

NerfRender NerfField::render(const SplatCamera& camera, const Eigen::Vector3f& background, std::size_t rays_per_batch) const {
  NerfRender out;
  out.width = camera.width;
  out.height = camera.height;
  const std::size_t pixels = static_cast<std::size_t>(camera.width) * static_cast<std::size_t>(camera.height);
  out.image.assign(3 * pixels, 0.0f);
  out.depth.assign(pixels, 0.0f);
  out.opacity.assign(pixels, 0.0f);
  const Eigen::Vector3f origin = to_unit(camera.centre_world());
  const Eigen::Matrix3d R_world_camera = camera.R_camera_world.transpose();
  const float step_length = step();
  const auto scene_per_unit = static_cast<float>(unit_to_scene_length());

  struct RayState {
    std::size_t pixel;
    Eigen::Vector3f direction;  // unit vector, world axes
    float z_per_t;              // camera z per unit of t (scene units)
    float t, t_end;
    float transmittance = 1.0f, colour[3] = {0, 0, 0}, depth = 0.0f;
  };
  for (std::size_t first = 0; first < pixels; first += rays_per_batch) {
    const std::size_t last = std::min(pixels, first + rays_per_batch);
    std::vector<RayState> rays;
    for (std::size_t pixel = first; pixel < last; ++pixel) {
      const double u = static_cast<double>(pixel % static_cast<std::size_t>(camera.width));
      const double v = static_cast<double>(pixel / static_cast<std::size_t>(camera.width));
      const Eigen::Vector3d ray_camera((u - camera.cx) / camera.fx, (v - camera.cy) / camera.fy, 1.0);
      RayState ray;
      ray.pixel = pixel;
      ray.direction = (R_world_camera * ray_camera.normalized()).cast<float>();
      ray.z_per_t = static_cast<float>(scene_per_unit / ray_camera.norm());
      if (!ray_span(origin, ray.direction, ray.t, ray.t_end)) {
        for (int k = 0; k < 3; ++k) out.image[3 * pixel + static_cast<std::size_t>(k)] = background[k];
        continue;
      }
      rays.push_back(ray);
    }
    // March in rounds of a few samples per ray, evaluating the field on the round's samples.
    int round_samples = 4;
    while (!rays.empty()) {
      RaySamples samples;
      for (RayState& ray : rays) occupancy().march(origin, ray.direction, step_length, ray.t_end, round_samples, ray.t, samples);
      std::vector<float> directions(samples.position.size());
      for (std::size_t r = 0; r < rays.size(); ++r) {
        for (uint32_t i = samples.ray_begin[r]; i < samples.ray_begin[r + 1]; ++i) std::copy_n(rays[r].direction.data(), 3, &directions[3 * i]);
      }
      std::vector<float> density(samples.size()), colour(3 * samples.size());
      if (samples.size() > 0) network_->forward(samples.position.data(), directions.data(), samples.size(), density.data(), colour.data());
      std::vector<RayState> active;
      for (std::size_t r = 0; r < rays.size(); ++r) {
        RayState& ray = rays[r];
        const uint32_t begin = samples.ray_begin[r], end = samples.ray_begin[r + 1];
        for (uint32_t i = begin; i < end && ray.transmittance >= kMinTransmittance; ++i) {
          const float alpha = 1.0f - std::exp(-density[i] * samples.dt[i]);
          const float weight = ray.transmittance * alpha;
          for (int k = 0; k < 3; ++k) ray.colour[k] += weight * colour[3 * i + static_cast<std::size_t>(k)];
          ray.depth += weight * samples.t[i] * ray.z_per_t;
          ray.transmittance *= 1.0f - alpha;
        }
        if (end > begin && ray.transmittance >= kMinTransmittance && ray.t < ray.t_end) {
          active.push_back(ray);
          continue;
        }
        for (int k = 0; k < 3; ++k) out.image[3 * ray.pixel + static_cast<std::size_t>(k)] = ray.colour[k] + ray.transmittance * background[k];
        out.opacity[ray.pixel] = 1.0f - ray.transmittance;
        out.depth[ray.pixel] = out.opacity[ray.pixel] > 0.0f ? ray.depth / out.opacity[ray.pixel] : 0.0f;
      }
      rays = std::move(active);
      round_samples = std::min(64, 2 * round_samples);
    }
  }
  return out;
}

}  // namespace hanzo::fusion::neural
