// The Gaussian-splat rasterizer: a single Gaussian drawn where and how bright the projection says,
// every parameter's gradient against central finite differences of the rendered loss, SSIM's
// gradient likewise, and the PLY layout of 3DGS viewers read back exactly.

#include <cmath>
#include <filesystem>
#include <fstream>
#include <memory>
#include <random>

#include <gtest/gtest.h>

#include "hanzo/fusion/neural/image_metrics.hpp"
#include "hanzo/fusion/neural/splat_ply.hpp"
#include "hanzo/fusion/neural/splat_rasterizer.hpp"

namespace hanzo::fusion::neural {
namespace {

SplatCamera small_camera() {
  SplatCamera camera;
  camera.width = 24;
  camera.height = 20;
  camera.fx = camera.fy = 24.0;
  camera.cx = 11.5;
  camera.cy = 9.5;
  camera.R_camera_world = Eigen::AngleAxisd(0.1, Eigen::Vector3d::UnitY()).toRotationMatrix();
  camera.t_camera_world = Eigen::Vector3d(0.05, -0.02, 0.1);
  return camera;
}

// A few overlapping, anisotropic, coloured Gaussians in front of the camera (degree 2 colours),
// wide enough that each one's alpha stays above the 1/255 cut on every pixel: a finite
// difference then sees no pixel switch a Gaussian on or off.
GaussianCloud small_scene() {
  GaussianCloud cloud;
  cloud.sh_degree = 2;
  std::mt19937 random(3);
  std::uniform_real_distribution<float> u(-1.0f, 1.0f);
  for (int i = 0; i < 6; ++i) {
    const Eigen::Vector3f mean(0.1f * u(random), 0.1f * u(random), 2.0f + 0.3f * u(random));
    const Eigen::Vector3f log_scale(std::log(1.6f + 0.4f * u(random)), std::log(1.8f + 0.4f * u(random)), std::log(1.5f + 0.3f * u(random)));
    const Eigen::Vector4f rotation(1.0f + 0.3f * u(random), 0.4f * u(random), 0.4f * u(random), 0.4f * u(random));
    cloud.add(mean, log_scale, rotation, 0.3f * u(random), Eigen::Vector3f(0.8f * u(random), 0.8f * u(random), 0.8f * u(random)));
    float* sh = &cloud.sh[cloud.sh.size() - static_cast<std::size_t>(cloud.sh_floats())];
    for (int k = 3; k < cloud.sh_floats(); ++k) sh[k] = 0.2f * u(random);
  }
  return cloud;
}

// A smooth loss of the image: sum of w . image with fixed random weights.
std::vector<float> loss_weights(std::size_t size) {
  std::mt19937 random(7);
  std::uniform_real_distribution<float> u(-1.0f, 1.0f);
  std::vector<float> weights(size);
  for (float& w : weights) w = u(random);
  return weights;
}

double loss_of(const GaussianCloud& cloud, const SplatCamera& camera, const RasterizerConfig& config, const std::vector<float>& weights) {
  const SplatRender render = render_splats(cloud, camera, config);
  double sum = 0.0;
  for (std::size_t i = 0; i < weights.size(); ++i) sum += static_cast<double>(weights[i]) * render.image[i];
  return sum;
}

TEST(SplatRasterizer, OneGaussianIsDrawnAtItsProjectionWithItsOpacityAndColour) {
  SplatCamera camera = small_camera();
  camera.R_camera_world.setIdentity();
  camera.t_camera_world.setZero();
  GaussianCloud cloud;
  cloud.sh_degree = 0;
  const Eigen::Vector3f colour(0.9f, 0.2f, 0.4f);
  cloud.add({0.1f, -0.05f, 2.0f}, Eigen::Vector3f::Constant(std::log(0.05f)), {1, 0, 0, 0}, logit(0.8f), sh_dc_of_colour(colour));
  RasterizerConfig config;
  config.background = Eigen::Vector3f::Zero();
  const SplatRender render = render_splats(cloud, camera, config);
  ASSERT_EQ(render.drawn(), 1);
  // Projection: (24 * 0.1 / 2 + 11.5, 24 * -0.05 / 2 + 9.5) = (12.7, 8.9).
  EXPECT_NEAR(render.mean_2d[0].x(), 12.7f, 1e-4f);
  EXPECT_NEAR(render.mean_2d[0].y(), 8.9f, 1e-4f);
  // 2D variance: (24 * 0.05 / 2)^2 + 0.3 = 0.66 pixels^2; at pixel (13, 9) d = (-0.3, -0.1).
  const float expected_alpha = 0.8f * std::exp(-0.5f * (0.09f + 0.01f) / 0.66f);
  const std::size_t pixel = 9 * 24 + 13;
  for (int c = 0; c < 3; ++c) EXPECT_NEAR(render.image[3 * pixel + static_cast<std::size_t>(c)], colour[c] * expected_alpha, 2e-4f);
  EXPECT_NEAR(render.alpha[pixel], expected_alpha, 1e-4f);
  EXPECT_NEAR(render.depth[pixel], 2.0f, 1e-4f);
  EXPECT_EQ(render.image[0], 0.0f);  // far corner: background only
}

TEST(SplatRasterizer, GradientsMatchFiniteDifferences) {
  const SplatCamera camera = small_camera();
  GaussianCloud cloud = small_scene();
  RasterizerConfig config;
  config.background = Eigen::Vector3f(0.2f, 0.5f, 0.7f);
  config.active_sh_degree = 2;
  const SplatRender forward = render_splats(cloud, camera, config);
  ASSERT_EQ(forward.drawn(), 6);
  const std::vector<float> weights = loss_weights(forward.image.size());
  GaussianGradients gradients;
  gradients.resize_like(cloud);
  render_splats_backward(cloud, camera, config, forward, weights, gradients);

  std::vector<std::span<float>> parameters = cloud.parameters();
  const std::vector<std::span<float>> analytic = gradients.parameters();
  const char* names[] = {"position", "log_scale", "rotation", "opacity_logit", "sh"};
  for (std::size_t group = 0; group < parameters.size(); ++group) {
    double worst = 0.0;
    for (std::size_t i = 0; i < parameters[group].size(); ++i) {
      const float saved = parameters[group][i];
      const float step = 1e-3f;
      parameters[group][i] = saved + step;
      const double plus = loss_of(cloud, camera, config, weights);
      parameters[group][i] = saved - step;
      const double minus = loss_of(cloud, camera, config, weights);
      parameters[group][i] = saved;
      const double numeric = (plus - minus) / (2.0 * step);
      const double error = std::abs(numeric - analytic[group][i]) / std::max(1.0, std::abs(numeric));
      worst = std::max(worst, error);
      EXPECT_LT(error, 5e-3) << names[group] << "[" << i << "]: analytic " << analytic[group][i] << ", numeric " << numeric;
    }
    std::printf("%-13s worst relative gradient error %.2e\n", names[group], worst);
  }
  for (int visible : gradients.visible_views) EXPECT_EQ(visible, 1);
}

TEST(SplatRasterizer, GradientsDoNotDependOnTheThreadSchedule) {
  const SplatCamera camera = small_camera();
  const GaussianCloud cloud = small_scene();
  RasterizerConfig config;
  const SplatRender forward = render_splats(cloud, camera, config);
  const std::vector<float> weights = loss_weights(forward.image.size());
  GaussianGradients first, second;
  first.resize_like(cloud);
  second.resize_like(cloud);
  render_splats_backward(cloud, camera, config, forward, weights, first);
  render_splats_backward(cloud, camera, config, render_splats(cloud, camera, config), weights, second);
  EXPECT_EQ(first.position, second.position);
  EXPECT_EQ(first.sh, second.sh);
}

TEST(ImageMetrics, SsimGradientMatchesFiniteDifferencesAndPsnrIsExact) {
  const int width = 24, height = 20;
  std::mt19937 random(5);
  std::uniform_real_distribution<float> u(0.0f, 1.0f);
  std::vector<float> image(3 * width * height), reference(3 * width * height);
  for (std::size_t i = 0; i < image.size(); ++i) {
    reference[i] = u(random);
    image[i] = std::clamp(reference[i] + 0.2f * (u(random) - 0.5f), 0.0f, 1.0f);
  }
  std::vector<float> gradient;
  const double value = ssim(image, reference, width, height, &gradient);
  EXPECT_GT(value, 0.0);
  EXPECT_LT(value, 1.0);
  EXPECT_NEAR(ssim(reference, reference, width, height), 1.0, 1e-9);
  for (std::size_t i : {0ul, 37ul, 500ul, image.size() - 1}) {
    const float saved = image[i];
    image[i] = saved + 1e-3f;
    const double plus = ssim(image, reference, width, height);
    image[i] = saved - 1e-3f;
    const double minus = ssim(image, reference, width, height);
    image[i] = saved;
    EXPECT_NEAR(gradient[i], (plus - minus) / 2e-3, 1e-6 + 1e-3 * std::abs(gradient[i])) << i;
  }
  std::vector<float> offset = reference;
  for (float& v : offset) v += 0.1f;
  EXPECT_NEAR(psnr(offset, reference), 20.0, 1e-4);
}

TEST(SplatPly, WritesTheViewersLayoutAndReadsItBackExactly) {
  const GaussianCloud cloud = small_scene();
  const std::string path = (std::filesystem::temp_directory_path() / "hanzo_splats_test.ply").string();
  ASSERT_TRUE(write_splat_ply(path, cloud));
  const Result<GaussianCloud> read = read_splat_ply(path);
  ASSERT_TRUE(read) << read.error().message;
  EXPECT_EQ(read->sh_degree, 2);
  EXPECT_EQ(read->position, cloud.position);
  EXPECT_EQ(read->log_scale, cloud.log_scale);
  EXPECT_EQ(read->rotation, cloud.rotation);
  EXPECT_EQ(read->opacity_logit, cloud.opacity_logit);
  EXPECT_EQ(read->sh, cloud.sh);
  // A truncated file is refused by name.
  const std::string bytes = std::string(std::istreambuf_iterator<char>(*std::make_unique<std::ifstream>(path, std::ios::binary)), {});
  std::ofstream(path, std::ios::binary | std::ios::trunc) << bytes.substr(0, bytes.size() - 5);
  const Result<GaussianCloud> truncated = read_splat_ply(path);
  ASSERT_FALSE(truncated);
  EXPECT_NE(truncated.error().message.find("bytes of vertices"), std::string::npos) << truncated.error().message;
  std::filesystem::remove(path);
}

}  // namespace
}  // namespace hanzo::fusion::neural
