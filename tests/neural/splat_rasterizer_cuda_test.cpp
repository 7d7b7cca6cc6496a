// The CUDA splat rasterizer against the CPU's: the same renders (image, depth, alpha, the
// Gaussians drawn and each pixel's contributors) and the same gradients up to float rounding, on
// a scene of a few thousand overlapping Gaussians with degree-3 colours. Skipped without a CUDA
// device; without one (or without CUDA in the build) creating the rasterizer fails with the
// reason, which the CLI reports.

#include <algorithm>
#include <cmath>
#include <random>

#include <gtest/gtest.h>

#include "hanzo/fusion/neural/splat_rasterizer.hpp"
#include "hanzo/fusion/neural/splat_rasterizer_cuda.hpp"
#include "hanzo/fusion/neural/splat_trainer.hpp"

namespace hanzo::fusion::neural {
namespace {

SplatCamera camera_of_scene() {
  SplatCamera camera;
  camera.width = 203;  // not a multiple of the tile size
  camera.height = 151;
  camera.fx = camera.fy = 180.0;
  camera.cx = 101.0;
  camera.cy = 75.0;
  camera.R_camera_world = Eigen::AngleAxisd(0.2, Eigen::Vector3d::UnitY()).toRotationMatrix();
  camera.t_camera_world = Eigen::Vector3d(0.1, -0.05, 0.3);
  return camera;
}

// 4000 Gaussians in a box 1.5 to 5 units ahead, some partly outside the view, anisotropic,
// semi-transparent, with degree-3 colours (some clamped at 0).
GaussianCloud scene() {
  GaussianCloud cloud;
  cloud.sh_degree = 3;
  std::mt19937 random(11);
  std::uniform_real_distribution<float> u(-1.0f, 1.0f);
  for (int i = 0; i < 4000; ++i) {
    const Eigen::Vector3f mean(1.6f * u(random), 1.2f * u(random), 3.2f + 1.7f * u(random));
    const Eigen::Vector3f log_scale(std::log(0.04f) + 0.8f * u(random), std::log(0.04f) + 0.8f * u(random), std::log(0.03f) + 0.8f * u(random));
    const Eigen::Vector4f rotation(u(random), u(random), u(random), u(random));
    cloud.add(mean, log_scale, rotation, 1.5f * u(random), Eigen::Vector3f(1.2f * u(random), 1.2f * u(random), 1.2f * u(random)));
    float* sh = &cloud.sh[cloud.sh.size() - static_cast<std::size_t>(cloud.sh_floats())];
    for (int k = 3; k < cloud.sh_floats(); ++k) sh[k] = 0.3f * u(random);
  }
  return cloud;
}

double relative_error(const std::vector<float>& value, const std::vector<float>& reference) {
  double difference = 0.0, norm = 0.0;
  for (std::size_t i = 0; i < value.size(); ++i) {
    difference += std::pow(static_cast<double>(value[i]) - reference[i], 2);
    norm += std::pow(static_cast<double>(reference[i]), 2);
  }
  return std::sqrt(difference / std::max(norm, 1e-30));
}

}  // namespace

TEST(CudaSplatRasterizer, RendersAndGradientsAgreeWithTheCpu) {
  std::string reason;
  if (!CudaSplatRasterizer::available(&reason)) GTEST_SKIP() << reason;
  auto created = CudaSplatRasterizer::create();
  ASSERT_TRUE(created.ok()) << created.error().message;
  CudaSplatRasterizer gpu = std::move(created).value();
  std::printf("CUDA device: %s\n", gpu.device_name().c_str());
  const GaussianCloud cloud = scene();
  const SplatCamera camera = camera_of_scene();
  RasterizerConfig config;
  config.background = Eigen::Vector3f(0.2f, 0.5f, 0.9f);
  ASSERT_TRUE(gpu.upload(cloud).ok());

  const SplatRender cpu_render = render_splats(cloud, camera, config);
  auto gpu_result = gpu.render(camera, config);
  ASSERT_TRUE(gpu_result.ok()) << gpu_result.error().message;
  const SplatRender& gpu_render = gpu_result.value();
  ASSERT_GT(cpu_render.drawn(), 1000);
  // Drawn or not and each footprint's radius: the same but where a value rounds across a cut.
  int radius_differences = 0;
  for (std::size_t i = 0; i < cloud.size(); ++i) radius_differences += gpu_render.radius[i] != cpu_render.radius[i];
  EXPECT_LE(radius_differences, 4);
  double image_error = 0.0, worst = 0.0;
  for (std::size_t i = 0; i < cpu_render.image.size(); ++i) {
    const double difference = std::abs(static_cast<double>(gpu_render.image[i]) - cpu_render.image[i]);
    image_error += difference;
    worst = std::max(worst, difference);
  }
  image_error /= static_cast<double>(cpu_render.image.size());
  std::size_t same_contributors = 0;
  for (std::size_t p = 0; p < cpu_render.contributors.size(); ++p) same_contributors += gpu_render.contributors[p] == cpu_render.contributors[p];
  const double same_share = static_cast<double>(same_contributors) / static_cast<double>(cpu_render.contributors.size());
  std::printf("render: mean |GPU - CPU| %.2e, worst %.2e, same contributors %.4f of the pixels, depth error %.2e\n", image_error, worst, same_share,
              relative_error(gpu_render.depth, cpu_render.depth));
  EXPECT_LT(image_error, 1e-5);
  EXPECT_LT(worst, 2e-2);  // a Gaussian at the 1/255 cut on one side only
  EXPECT_GT(same_share, 0.999);
  EXPECT_LT(relative_error(gpu_render.depth, cpu_render.depth), 1e-4);
  EXPECT_LT(relative_error(gpu_render.alpha, cpu_render.alpha), 1e-4);

  std::mt19937 random(5);
  std::uniform_real_distribution<float> u(-1.0f, 1.0f);
  std::vector<float> loss_gradient(cpu_render.image.size());
  for (float& value : loss_gradient) value = u(random);
  GaussianGradients cpu_gradients, gpu_gradients;
  cpu_gradients.resize_like(cloud);
  gpu_gradients.resize_like(cloud);
  render_splats_backward(cloud, camera, config, cpu_render, loss_gradient, cpu_gradients);
  ASSERT_TRUE(gpu.backward(loss_gradient, gpu_gradients).ok());
  const char* names[] = {"position", "log_scale", "rotation", "opacity_logit", "sh"};
  const std::vector<std::span<float>> cpu_groups = cpu_gradients.parameters(), gpu_groups = gpu_gradients.parameters();
  for (std::size_t group = 0; group < cpu_groups.size(); ++group) {
    const std::vector<float> cpu_values(cpu_groups[group].begin(), cpu_groups[group].end());
    const std::vector<float> gpu_values(gpu_groups[group].begin(), gpu_groups[group].end());
    const double error = relative_error(gpu_values, cpu_values);
    std::printf("%-13s relative gradient difference %.2e\n", names[group], error);
    EXPECT_LT(error, 1e-3) << names[group];
  }
  int visible_differences = 0;
  for (std::size_t i = 0; i < cloud.size(); ++i) visible_differences += gpu_gradients.visible_views[i] != cpu_gradients.visible_views[i];
  EXPECT_LE(visible_differences, 4);
  EXPECT_LT(relative_error(gpu_gradients.screen_gradient_norm, cpu_gradients.screen_gradient_norm), 1e-3);
}

// A view for display: the same kernels as render(), the image alone (or with depth and alpha)
// downloaded; backward() then asks for a render() first.
TEST(CudaSplatRasterizer, AViewForDisplayIsTheRendersImage) {
  std::string reason;
  if (!CudaSplatRasterizer::available(&reason)) GTEST_SKIP() << reason;
  CudaSplatRasterizer gpu = CudaSplatRasterizer::create().value();
  const GaussianCloud cloud = scene();
  const SplatCamera camera = camera_of_scene();
  ASSERT_TRUE(gpu.upload(cloud).ok());
  const SplatRender full = gpu.render(camera, RasterizerConfig{}).value();
  SplatView view;
  ASSERT_TRUE(gpu.render_view(camera, RasterizerConfig{}, view).ok());
  EXPECT_EQ(view.width, camera.width);
  EXPECT_EQ(view.height, camera.height);
  EXPECT_EQ(view.image, full.image);
  EXPECT_TRUE(view.depth.empty());
  ASSERT_TRUE(gpu.render_view(camera, RasterizerConfig{}, view, true).ok());
  EXPECT_EQ(view.image, full.image);
  EXPECT_EQ(view.depth, full.depth);
  EXPECT_EQ(view.alpha, full.alpha);
  GaussianGradients gradients;
  gradients.resize_like(cloud);
  const Status refused = gpu.backward(std::vector<float>(full.image.size(), 0.1f), gradients);
  ASSERT_FALSE(refused.ok());
  EXPECT_NE(refused.error().message.find("render()"), std::string::npos) << refused.error().message;
}

TEST(CudaSplatRasterizer, CreationSaysWhyWhenThereIsNoDevice) {
  std::string reason;
  if (CudaSplatRasterizer::available(&reason)) {
    auto missing = CudaSplatRasterizer::create(1000);
    ASSERT_FALSE(missing.ok());
    EXPECT_NE(missing.error().message.find("does not exist"), std::string::npos) << missing.error().message;
    return;
  }
  EXPECT_FALSE(reason.empty());
  auto created = CudaSplatRasterizer::create();
  ASSERT_FALSE(created.ok());
  EXPECT_EQ(created.error().message, reason);
}

// The trainer on device cuda: refused without a device; with one, its steps run there and fit
// a view as the CPU's do (the same loss after 30 steps within 1 %: the schedule rounds differently).
TEST(CudaSplatRasterizer, TrainerRunsOnTheDeviceOrIsRefused) {
  const SplatCamera camera = camera_of_scene();
  PosedView view;
  view.camera = camera;
  view.image.width = camera.width;
  view.image.height = camera.height;
  view.image.pixels.assign(3 * static_cast<std::size_t>(camera.width) * static_cast<std::size_t>(camera.height), 0.3f);
  for (std::size_t i = 0; i < view.image.pixels.size(); i += 7) view.image.pixels[i] = 0.8f;
  SplatTrainingConfig config;
  config.iterations = 30;
  config.densify_until = 1;  // no densification: both runs keep the same Gaussians
  config.device = SplatDevice::kCuda;
  auto gpu_trainer = SplatTrainer::create(scene(), 5.0, config);
  std::string reason;
  if (!CudaSplatRasterizer::available(&reason)) {
    ASSERT_FALSE(gpu_trainer.ok());
    EXPECT_NE(gpu_trainer.error().message.find("device cuda"), std::string::npos) << gpu_trainer.error().message;
    return;
  }
  ASSERT_TRUE(gpu_trainer.ok()) << gpu_trainer.error().message;
  EXPECT_NE(gpu_trainer->device_name(), "cpu");
  config.device = SplatDevice::kCpu;
  auto cpu_trainer = SplatTrainer::create(scene(), 5.0, config);
  ASSERT_TRUE(cpu_trainer.ok());
  double gpu_loss = 0.0, cpu_loss = 0.0;
  for (int step = 0; step < config.iterations; ++step) {
    gpu_loss = gpu_trainer->step(view);
    cpu_loss = cpu_trainer->step(view);
  }
  std::printf("loss after %d steps: GPU %.6f, CPU %.6f\n", config.iterations, gpu_loss, cpu_loss);
  EXPECT_EQ(gpu_trainer->device_name().empty(), false);
  EXPECT_NEAR(gpu_loss, cpu_loss, 1e-2 * cpu_loss);
}

TEST(SplatDevice, ParsesTheThreeNamesAndRefusesOthers) {
  EXPECT_EQ(parse_splat_device("cpu").value(), SplatDevice::kCpu);
  EXPECT_EQ(parse_splat_device("cuda").value(), SplatDevice::kCuda);
  EXPECT_EQ(parse_splat_device("auto").value(), SplatDevice::kAuto);
  auto bad = parse_splat_device("gpu");
  ASSERT_FALSE(bad.ok());
  EXPECT_NE(bad.error().message.find("'gpu'"), std::string::npos);
}

}  // namespace hanzo::fusion::neural
