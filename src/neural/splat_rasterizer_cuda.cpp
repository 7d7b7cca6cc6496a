#include "hanzo/fusion/neural/splat_rasterizer_cuda.hpp"

#include <algorithm>

#include <fmt/format.h>

#if defined(HANZO_FUSION_WITH_CUDA)
#include "cuda/splat_device.hpp"
#endif

namespace hanzo::fusion::neural {

Result<SplatDevice> parse_splat_device(const std::string& text) {
  if (text == "cpu") return SplatDevice::kCpu;
  if (text == "cuda") return SplatDevice::kCuda;
  if (text == "auto") return SplatDevice::kAuto;
  return Error(fmt::format("unknown device '{}' (cpu, cuda or auto)", text), "device");
}

#if defined(HANZO_FUSION_WITH_CUDA)

struct CudaSplatRasterizer::State {
  cuda::DeviceState* device = nullptr;
  std::string name;
  int count = 0, sh_degree = 0;
  std::vector<uint8_t> drawn;  // per Gaussian of the last render
  bool backward_ready = false;  // the last render was render(), not render_view()
  ~State() { cuda::destroy_state(device); }
};

bool CudaSplatRasterizer::available(std::string* reason) {
  int count = 0;
  const std::string error = cuda::device_count(count);
  if (count > 0) return true;
  if (reason != nullptr) *reason = error.empty() ? "no CUDA device" : error;
  return false;
}

Result<CudaSplatRasterizer> CudaSplatRasterizer::create(int device) {
  int count = 0;
  std::string error = cuda::device_count(count);
  if (count == 0) return Error(error.empty() ? "no CUDA device" : error, "device");
  if (device < 0 || device >= count) return Error(fmt::format("CUDA device {} does not exist ({} present)", device, count), "device");
  auto state = std::make_unique<State>();
  error = cuda::create_state(device, state->device, state->name);
  if (!error.empty()) return Error(error, "device");
  return CudaSplatRasterizer(std::move(state));
}

Status CudaSplatRasterizer::upload(const GaussianCloud& cloud) {
  if (!cloud.consistent()) return Error("the cloud's arrays are inconsistent or not finite", "cloud");
  const std::string error = cuda::upload_cloud(state_->device, static_cast<int>(cloud.size()), cloud.sh_floats(), cloud.position.data(),
                                               cloud.log_scale.data(), cloud.rotation.data(), cloud.opacity_logit.data(), cloud.sh.data());
  if (!error.empty()) return Error(error, "device");
  state_->count = static_cast<int>(cloud.size());
  state_->sh_degree = cloud.sh_degree;
  state_->backward_ready = false;
  return ok_status();
}

namespace {
cuda::ForwardSettings forward_settings(const SplatCamera& camera, const RasterizerConfig& config, int sh_degree) {
  cuda::ForwardSettings settings{};
  settings.camera = camera_params(camera);
  settings.degree = std::clamp(config.active_sh_degree, 0, sh_degree);
  settings.near = static_cast<float>(config.near);
  settings.low_pass = static_cast<float>(config.low_pass);
  for (int c = 0; c < 3; ++c) settings.background[c] = config.background[c];
  settings.normalize_depth = config.normalize_depth;
  return settings;
}
}  // namespace

Result<SplatRender> CudaSplatRasterizer::render(const SplatCamera& camera, const RasterizerConfig& config) {
  const cuda::ForwardSettings settings = forward_settings(camera, config, state_->sh_degree);
  SplatRender out;
  out.width = camera.width;
  out.height = camera.height;
  out.tiles_x = settings.camera.tiles_x;
  out.tiles_y = settings.camera.tiles_y;
  const auto pixels = static_cast<std::size_t>(camera.width) * static_cast<std::size_t>(camera.height);
  const auto n = static_cast<std::size_t>(state_->count);
  out.image.resize(3 * pixels);
  out.depth.resize(pixels);
  out.alpha.resize(pixels);
  out.final_transmittance.resize(pixels);
  out.contributors.resize(pixels);
  std::vector<kernels::Projection> projections(n);
  const std::string error = cuda::forward(state_->device, settings,
                                          {out.image.data(), out.depth.data(), out.alpha.data(), out.final_transmittance.data(), out.contributors.data(),
                                           projections.data()});
  state_->backward_ready = error.empty();
  if (!error.empty()) return Error(error, "device");
  out.mean_2d.assign(n, Eigen::Vector2f::Zero());
  out.conic.assign(n, Eigen::Vector3f::Zero());
  out.colour.assign(n, Eigen::Vector3f::Zero());
  out.view_depth.assign(n, 0.0f);
  out.radius.assign(n, 0);
  out.extent.assign(n, Eigen::Vector2f::Zero());
  out.opacity.assign(n, 0.0f);
  out.colour_clamped.assign(n, 0);
  state_->drawn.assign(n, 0);
  for (std::size_t i = 0; i < n; ++i) {
    const kernels::Projection& projection = projections[i];
    if (projection.radius == 0) continue;
    state_->drawn[i] = 1;
    out.mean_2d[i] = Eigen::Vector2f(projection.mean[0], projection.mean[1]);
    out.conic[i] = Eigen::Vector3f(projection.conic[0], projection.conic[1], projection.conic[2]);
    out.colour[i] = Eigen::Vector3f(projection.colour[0], projection.colour[1], projection.colour[2]);
    out.view_depth[i] = projection.depth;
    out.radius[i] = projection.radius;
    out.extent[i] = Eigen::Vector2f(projection.extent[0], projection.extent[1]);
    out.opacity[i] = projection.opacity;
    out.colour_clamped[i] = static_cast<uint8_t>(projection.clamped);
  }
  return out;
}

Status CudaSplatRasterizer::render_view(const SplatCamera& camera, const RasterizerConfig& config, SplatView& view, bool with_depth_and_alpha) {
  const cuda::ForwardSettings settings = forward_settings(camera, config, state_->sh_degree);
  const auto pixels = static_cast<std::size_t>(camera.width) * static_cast<std::size_t>(camera.height);
  view.width = camera.width;
  view.height = camera.height;
  view.image.resize(3 * pixels);
  view.depth.resize(with_depth_and_alpha ? pixels : 0);
  view.alpha.resize(with_depth_and_alpha ? pixels : 0);
  state_->backward_ready = false;
  const std::string error = cuda::forward(state_->device, settings,
                                          {view.image.data(), with_depth_and_alpha ? view.depth.data() : nullptr,
                                           with_depth_and_alpha ? view.alpha.data() : nullptr, nullptr, nullptr, nullptr});
  if (!error.empty()) return Error(error, "device");
  return ok_status();
}

Status CudaSplatRasterizer::backward(const std::vector<float>& loss_gradient_image, GaussianGradients& gradients) {
  if (!state_->backward_ready) return Error("backward needs a render() of the uploaded cloud first (render_view keeps no per-Gaussian fields)", "device");
  const auto n = static_cast<std::size_t>(state_->count);
  const std::size_t sh_floats = 3 * static_cast<std::size_t>(sh_coefficients(state_->sh_degree));
  if (gradients.position.size() != 3 * n || gradients.sh.size() != n * sh_floats) return Error("the gradients are not sized like the uploaded cloud", "gradients");
  std::vector<float> position(3 * n), log_scale(3 * n), rotation(4 * n), opacity(n), sh(n * sh_floats), screen(n);
  const std::string error = cuda::backward(state_->device, loss_gradient_image.data(),
                                           {position.data(), log_scale.data(), rotation.data(), opacity.data(), sh.data(), screen.data()});
  if (!error.empty()) return Error(error, "device");
  const auto add = [](std::vector<float>& into, const std::vector<float>& values) {
    for (std::size_t k = 0; k < values.size(); ++k) into[k] += values[k];
  };
  add(gradients.position, position);
  add(gradients.log_scale, log_scale);
  add(gradients.rotation, rotation);
  add(gradients.opacity_logit, opacity);
  add(gradients.sh, sh);
  for (std::size_t i = 0; i < n && i < state_->drawn.size(); ++i) {
    if (state_->drawn[i] == 0) continue;
    gradients.screen_gradient_norm[i] += screen[i];
    gradients.visible_views[i] += 1;
  }
  return ok_status();
}

#else  // built without CUDA

struct CudaSplatRasterizer::State {
  std::string name;
};

bool CudaSplatRasterizer::available(std::string* reason) {
  if (reason != nullptr) *reason = "built without CUDA (HANZO_FUSION_CUDA off: no nvcc at configure time)";
  return false;
}

Result<CudaSplatRasterizer> CudaSplatRasterizer::create(int) {
  return Error("built without CUDA (HANZO_FUSION_CUDA off: no nvcc at configure time)", "device");
}

Status CudaSplatRasterizer::upload(const GaussianCloud&) { return Error("built without CUDA", "device"); }
Result<SplatRender> CudaSplatRasterizer::render(const SplatCamera&, const RasterizerConfig&) { return Error("built without CUDA", "device"); }
Status CudaSplatRasterizer::render_view(const SplatCamera&, const RasterizerConfig&, SplatView&, bool) { return Error("built without CUDA", "device"); }
Status CudaSplatRasterizer::backward(const std::vector<float>&, GaussianGradients&) { return Error("built without CUDA", "device"); }

#endif

CudaSplatRasterizer::CudaSplatRasterizer(std::unique_ptr<State> state) : state_(std::move(state)) {}
CudaSplatRasterizer::CudaSplatRasterizer(CudaSplatRasterizer&&) noexcept = default;
CudaSplatRasterizer& CudaSplatRasterizer::operator=(CudaSplatRasterizer&&) noexcept = default;
CudaSplatRasterizer::~CudaSplatRasterizer() = default;
const std::string& CudaSplatRasterizer::device_name() const { return state_->name; }

}  // namespace hanzo::fusion::neural
