// Neural-field kernels on the CPU, per training step's worth of samples (131,072): the hash
// encoding forward and backward, and the NeRF's colour network (32 -> 64 -> 64 -> 3, ReLU, no
// biases) forward + backward in this project's Mlp beside the same network in libtorch (Debian's
// libtorch, its BLAS and autograd: the peer on this machine). Also splat rendering at 400 x 400
// and 1920 x 1080 and a training step, on the CPU and on a CUDA device when there is one.

#include <optional>
#include <random>
#include <vector>

#include <benchmark/benchmark.h>
#include <torch/torch.h>

#include "hanzo/fusion/neural/gaussian_cloud.hpp"
#include "hanzo/fusion/neural/hash_encoding.hpp"
#include "hanzo/fusion/neural/mlp.hpp"
#include "hanzo/fusion/neural/splat_rasterizer.hpp"
#include "hanzo/fusion/neural/splat_rasterizer_cuda.hpp"

namespace {

using namespace hanzo::fusion::neural;

constexpr std::size_t kSamples = std::size_t{1} << 17;

std::vector<float> uniform_values(std::size_t count, float low, float high, uint64_t seed) {
  std::mt19937_64 random(seed);
  std::uniform_real_distribution<float> uniform(low, high);
  std::vector<float> values(count);
  for (float& value : values) value = uniform(random);
  return values;
}

/// Samples along rays: runs of 32 points 0.002 apart, as marching makes them.
std::vector<float> ray_samples(std::size_t count) {
  std::mt19937_64 random(1);
  std::uniform_real_distribution<float> uniform(0.2f, 0.8f), direction(-1.0f, 1.0f);
  std::vector<float> positions(3 * count);
  float origin[3] = {0, 0, 0}, step[3] = {0, 0, 0};
  for (std::size_t i = 0; i < count; ++i) {
    if (i % 32 == 0) {
      for (int k = 0; k < 3; ++k) {
        origin[k] = uniform(random);
        step[k] = 0.002f * direction(random);
      }
    }
    for (int k = 0; k < 3; ++k) positions[3 * i + static_cast<std::size_t>(k)] = origin[k] + static_cast<float>(i % 32) * step[k];
  }
  return positions;
}

void BM_HashEncodingForward(benchmark::State& state) {
  const HashGrid grid{HashGridConfig{}};
  const std::vector<float> table = uniform_values(grid.parameter_count(), -1e-4f, 1e-4f, 2);
  const std::vector<float> positions = ray_samples(kSamples);
  std::vector<float> features(kSamples * static_cast<std::size_t>(grid.output_width()));
  for (auto _ : state) grid.forward(table.data(), positions.data(), kSamples, features.data());
  state.counters["Msamples/s"] = benchmark::Counter(static_cast<double>(kSamples) * state.iterations() / 1e6, benchmark::Counter::kIsRate);
}
BENCHMARK(BM_HashEncodingForward)->Unit(benchmark::kMillisecond)->UseRealTime();

void BM_HashEncodingBackward(benchmark::State& state) {
  const HashGrid grid{HashGridConfig{}};
  const std::vector<float> positions = ray_samples(kSamples);
  const std::vector<float> gradient = uniform_values(kSamples * static_cast<std::size_t>(grid.output_width()), -1.0f, 1.0f, 3);
  std::vector<float> table_gradient(grid.parameter_count(), 0.0f);
  for (auto _ : state) grid.backward(positions.data(), kSamples, gradient.data(), table_gradient.data());
  state.counters["Msamples/s"] = benchmark::Counter(static_cast<double>(kSamples) * state.iterations() / 1e6, benchmark::Counter::kIsRate);
}
BENCHMARK(BM_HashEncodingBackward)->Unit(benchmark::kMillisecond)->UseRealTime();

void BM_ColourNetwork_Hanzo(benchmark::State& state) {
  const Mlp network(MlpShape{32, 64, 2, 3});
  std::mt19937_64 random(4);
  std::vector<float> parameters(network.parameter_count()), gradient(network.parameter_count());
  network.initialize(parameters.data(), random);
  const std::vector<float> input = uniform_values(kSamples * 32, -1.0f, 1.0f, 5);
  const std::vector<float> output_gradient = uniform_values(kSamples * 3, -1.0f, 1.0f, 6);
  std::vector<float> output(kSamples * 3), activations(kSamples * network.activation_floats()), input_gradient(input.size());
  for (auto _ : state) {
    network.forward(parameters.data(), input.data(), kSamples, output.data(), activations.data());
    network.backward(parameters.data(), input.data(), activations.data(), kSamples, output_gradient.data(), gradient.data(), input_gradient.data());
  }
  state.counters["Msamples/s"] = benchmark::Counter(static_cast<double>(kSamples) * state.iterations() / 1e6, benchmark::Counter::kIsRate);
}
BENCHMARK(BM_ColourNetwork_Hanzo)->Unit(benchmark::kMillisecond)->UseRealTime();

void BM_ColourNetwork_Libtorch(benchmark::State& state) {
  torch::manual_seed(4);
  std::vector<torch::Tensor> weights = {torch::randn({32, 64}) * 0.2, torch::randn({64, 64}) * 0.15, torch::randn({64, 3}) * 0.2};
  for (torch::Tensor& weight : weights) weight.set_requires_grad(true);
  const torch::Tensor input = torch::rand({static_cast<int64_t>(kSamples), 32}) * 2 - 1;
  const torch::Tensor output_gradient = torch::rand({static_cast<int64_t>(kSamples), 3}) * 2 - 1;
  for (auto _ : state) {
    torch::Tensor x = input.clone().set_requires_grad(true);
    const torch::Tensor output = torch::relu(torch::relu(x.mm(weights[0])).mm(weights[1])).mm(weights[2]);
    output.backward(output_gradient);
    benchmark::DoNotOptimize(x.grad().data_ptr<float>());
  }
  state.counters["Msamples/s"] = benchmark::Counter(static_cast<double>(kSamples) * state.iterations() / 1e6, benchmark::Counter::kIsRate);
}
BENCHMARK(BM_ColourNetwork_Libtorch)->Unit(benchmark::kMillisecond)->UseRealTime();

// `count` Gaussians in a 2-unit cube seen from 4 units away, as a trained lego holds (40,000).
GaussianCloud splat_scene(int count) {
  GaussianCloud cloud;
  cloud.sh_degree = 3;
  std::mt19937_64 random(7);
  std::uniform_real_distribution<float> uniform(-1.0f, 1.0f);
  for (int i = 0; i < count; ++i) {
    cloud.add(Eigen::Vector3f(uniform(random), uniform(random), uniform(random)), Eigen::Vector3f::Constant(std::log(0.01f)), Eigen::Vector4f(1, 0, 0, 0),
              logit(0.8f), Eigen::Vector3f(uniform(random), uniform(random), uniform(random)));
  }
  return cloud;
}

// The lego's field of view (fx = 1.39 x the width) at width x height.
SplatCamera splat_camera(int width, int height) {
  SplatCamera camera;
  camera.width = width;
  camera.height = height;
  camera.fx = camera.fy = 1.3875 * width;
  camera.cx = 0.5 * (width - 1);
  camera.cy = 0.5 * (height - 1);
  camera.t_camera_world = Eigen::Vector3d(0.0, 0.0, 4.0);
  return camera;
}

// Renders per second on the CPU; args: width, height, Gaussians.
void BM_SplatRender_Cpu(benchmark::State& state) {
  const GaussianCloud cloud = splat_scene(static_cast<int>(state.range(2)));
  const SplatCamera camera = splat_camera(static_cast<int>(state.range(0)), static_cast<int>(state.range(1)));
  for (auto _ : state) benchmark::DoNotOptimize(render_splats(cloud, camera, RasterizerConfig{}).image.data());
  state.counters["views/s"] = benchmark::Counter(static_cast<double>(state.iterations()), benchmark::Counter::kIsRate);
}
BENCHMARK(BM_SplatRender_Cpu)->Args({400, 400, 40000})->Args({1920, 1080, 40000})->Unit(benchmark::kMillisecond)->UseRealTime();

// The same on a CUDA device (the cloud uploaded once; each view's image, depth and alpha
// downloaded); an error row without a device.
// A CUDA rasterizer holding the benchmark's scene (args: width, height, Gaussians); none (the
// row skipped with the reason) without a device.
std::optional<CudaSplatRasterizer> rasterizer_with_scene(benchmark::State& state) {
  auto gpu = CudaSplatRasterizer::create();
  if (!gpu) {
    state.SkipWithError(gpu.error().message.c_str());
    return std::nullopt;
  }
  if (hanzo::fusion::Status uploaded = gpu->upload(splat_scene(static_cast<int>(state.range(2)))); !uploaded) {
    state.SkipWithError(uploaded.error().message.c_str());
    return std::nullopt;
  }
  return std::move(gpu).value();
}

void BM_SplatRender_Cuda(benchmark::State& state) {
  std::optional<CudaSplatRasterizer> gpu = rasterizer_with_scene(state);
  if (!gpu) return;
  const SplatCamera camera = splat_camera(static_cast<int>(state.range(0)), static_cast<int>(state.range(1)));
  for (auto _ : state) {
    auto render = gpu->render(camera, RasterizerConfig{});
    if (!render) {
      state.SkipWithError(render.error().message.c_str());
      return;
    }
    benchmark::DoNotOptimize(render->image.data());
  }
  state.counters["views/s"] = benchmark::Counter(static_cast<double>(state.iterations()), benchmark::Counter::kIsRate);
  state.SetLabel(gpu->device_name());
}
BENCHMARK(BM_SplatRender_Cuda)->Args({400, 400, 40000})->Args({1920, 1080, 40000})->Args({1920, 1080, 1000000})->Unit(benchmark::kMillisecond)->UseRealTime();

// Views for display on a CUDA device (render_view: the RGB image alone downloaded, buffers reused).
void BM_SplatView_Cuda(benchmark::State& state) {
  std::optional<CudaSplatRasterizer> gpu = rasterizer_with_scene(state);
  if (!gpu) return;
  const SplatCamera camera = splat_camera(static_cast<int>(state.range(0)), static_cast<int>(state.range(1)));
  SplatView view;
  for (auto _ : state) {
    if (hanzo::fusion::Status rendered = gpu->render_view(camera, RasterizerConfig{}, view); !rendered) {
      state.SkipWithError(rendered.error().message.c_str());
      return;
    }
    benchmark::DoNotOptimize(view.image.data());
  }
  state.counters["views/s"] = benchmark::Counter(static_cast<double>(state.iterations()), benchmark::Counter::kIsRate);
  state.SetLabel(gpu->device_name());
}
BENCHMARK(BM_SplatView_Cuda)->Args({400, 400, 40000})->Args({1920, 1080, 40000})->Args({1920, 1080, 1000000})->Unit(benchmark::kMillisecond)->UseRealTime();

// One training step's render and backward at 400 x 400 on the CPU and on a CUDA device.
void BM_SplatStep400_Cpu(benchmark::State& state) {
  const GaussianCloud cloud = splat_scene(40000);
  const SplatCamera camera = splat_camera(400, 400);
  GaussianGradients gradients;
  gradients.resize_like(cloud);
  const std::vector<float> loss_gradient(3 * 400 * 400, 1e-6f);
  for (auto _ : state) {
    const SplatRender render = render_splats(cloud, camera, RasterizerConfig{});
    render_splats_backward(cloud, camera, RasterizerConfig{}, render, loss_gradient, gradients);
  }
  state.counters["steps/s"] = benchmark::Counter(static_cast<double>(state.iterations()), benchmark::Counter::kIsRate);
}
BENCHMARK(BM_SplatStep400_Cpu)->Unit(benchmark::kMillisecond)->UseRealTime();

void BM_SplatStep400_Cuda(benchmark::State& state) {
  auto gpu = CudaSplatRasterizer::create();
  if (!gpu) {
    state.SkipWithError(gpu.error().message.c_str());
    return;
  }
  const GaussianCloud cloud = splat_scene(40000);
  const SplatCamera camera = splat_camera(400, 400);
  GaussianGradients gradients;
  gradients.resize_like(cloud);
  const std::vector<float> loss_gradient(3 * 400 * 400, 1e-6f);
  for (auto _ : state) {  // as the trainer does: the cloud uploaded every step
    const bool ok = gpu->upload(cloud) && gpu->render(camera, RasterizerConfig{}) && gpu->backward(loss_gradient, gradients);
    if (!ok) {
      state.SkipWithError("the CUDA step failed");
      return;
    }
  }
  state.counters["steps/s"] = benchmark::Counter(static_cast<double>(state.iterations()), benchmark::Counter::kIsRate);
  state.SetLabel(gpu->device_name());
}
BENCHMARK(BM_SplatStep400_Cuda)->Unit(benchmark::kMillisecond)->UseRealTime();

}  // namespace

BENCHMARK_MAIN();
