// The splat rasterizer's CUDA schedule (the arithmetic is splat_kernels.hpp, shared with the CPU):
//  forward:  one thread per Gaussian projects it and counts the tiles it touches; an inclusive
//            scan gives each Gaussian its slots; every (tile, Gaussian) pair gets the key
//            tile << 32 | depth bits (positive floats order as their bits) and a stable radix
//            sort orders the pairs by tile, then depth, then Gaussian index, as the CPU's sort
//            does; one 16 x 16 block per tile blends its pixels front to back, the tile's
//            Gaussians read through shared memory in batches of 256.
//  backward: the same blocks walk each pixel's contributors back to front and add the pair
//            gradients per Gaussian with atomics (so the sums' rounding depends on the schedule);
//            one thread per Gaussian takes them through the projection to its parameters.
#include <cuda_runtime.h>

#include <algorithm>
#include <cub/device/device_radix_sort.cuh>
#include <cub/device/device_scan.cuh>

#include "splat_device.hpp"

namespace hanzo::fusion::neural::cuda {

namespace {

constexpr int kBlock = kernels::kTileSize * kernels::kTileSize;
constexpr int kLinearBlock = 256;

#define HANZO_CUDA_TRY(call, step)                                                  \
  do {                                                                              \
    const cudaError_t status_ = (call);                                             \
    if (status_ != cudaSuccess) return std::string(step) + ": " + cudaGetErrorString(status_); \
  } while (0)

/// Device memory that grows to the largest size asked for and is reused.
template <typename T>
struct Buffer {
  T* data = nullptr;
  std::size_t capacity = 0;
  cudaError_t reserve(std::size_t count) {
    if (count <= capacity && data != nullptr) return cudaSuccess;
    release();
    const cudaError_t status = cudaMalloc(&data, std::max<std::size_t>(count, 1) * sizeof(T));
    if (status == cudaSuccess) capacity = std::max<std::size_t>(count, 1);
    return status;
  }
  void release() {
    if (data != nullptr) cudaFree(data);
    data = nullptr;
    capacity = 0;
  }
};

int blocks_for(int count) { return (count + kLinearBlock - 1) / kLinearBlock; }

__global__ void project_kernel(int count, const float* position, const float* log_scale, const float* rotation, const float* opacity_logit,
                               const float* sh, int sh_floats, ForwardSettings settings, kernels::Projection* projections, uint32_t* tiles_touched) {
  const int i = blockIdx.x * blockDim.x + threadIdx.x;
  if (i >= count) return;
  kernels::Projection projection{};
  uint32_t touched = 0;
  if (kernels::project_gaussian(position + 3 * i, log_scale + 3 * i, rotation + 4 * i, opacity_logit[i], sh + static_cast<std::size_t>(i) * sh_floats,
                                settings.degree, settings.camera, settings.near, settings.low_pass, projection)) {
    touched = static_cast<uint32_t>((projection.rect[2] - projection.rect[0]) * (projection.rect[3] - projection.rect[1]));
  } else {
    projection.radius = 0;
  }
  projections[i] = projection;
  tiles_touched[i] = touched;
}

__global__ void duplicate_kernel(int count, const kernels::Projection* projections, const uint32_t* inclusive_offsets, int tiles_x, uint64_t* keys,
                                 uint32_t* values) {
  const int i = blockIdx.x * blockDim.x + threadIdx.x;
  if (i >= count || projections[i].radius == 0) return;
  const kernels::Projection& projection = projections[i];
  uint32_t slot = i == 0 ? 0u : inclusive_offsets[i - 1];
  const uint64_t depth_bits = __float_as_uint(projection.depth);
  for (int ty = projection.rect[1]; ty < projection.rect[3]; ++ty) {
    for (int tx = projection.rect[0]; tx < projection.rect[2]; ++tx) {
      keys[slot] = (static_cast<uint64_t>(ty * tiles_x + tx) << 32) | depth_bits;
      values[slot] = static_cast<uint32_t>(i);
      ++slot;
    }
  }
}

__global__ void ranges_kernel(int pairs, const uint64_t* keys, uint2* ranges) {
  const int k = blockIdx.x * blockDim.x + threadIdx.x;
  if (k >= pairs) return;
  const auto tile = static_cast<uint32_t>(keys[k] >> 32);
  if (k == 0 || static_cast<uint32_t>(keys[k - 1] >> 32) != tile) ranges[tile].x = static_cast<uint32_t>(k);
  if (k == pairs - 1 || static_cast<uint32_t>(keys[k + 1] >> 32) != tile) ranges[tile].y = static_cast<uint32_t>(k + 1);
}

__device__ kernels::TileSplat tile_splat_of(const kernels::Projection& p) {
  return kernels::make_tile_splat(p.mean, p.extent, p.conic, p.opacity, p.colour, p.depth);
}

__global__ void blend_kernel(ForwardSettings settings, const uint2* ranges, const uint32_t* values, const kernels::Projection* projections, float* image,
                             float* depth_out, float* alpha_out, float* final_transmittance, uint32_t* contributors) {
  __shared__ kernels::TileSplat batch[kBlock];
  const kernels::CameraParams& camera = settings.camera;
  const int x = static_cast<int>(blockIdx.x) * kernels::kTileSize + static_cast<int>(threadIdx.x);
  const int y = static_cast<int>(blockIdx.y) * kernels::kTileSize + static_cast<int>(threadIdx.y);
  const int thread = static_cast<int>(threadIdx.y) * kernels::kTileSize + static_cast<int>(threadIdx.x);
  const bool inside = x < camera.width && y < camera.height;
  const uint2 range = ranges[blockIdx.y * camera.tiles_x + blockIdx.x];
  bool done = !inside;
  float transmittance = 1.0f, depth = 0.0f, colour[3] = {0.0f, 0.0f, 0.0f};
  uint32_t walked = 0;
  for (uint32_t base = range.x; base < range.y; base += kBlock) {
    if (__syncthreads_count(done) == kBlock) break;
    if (base + thread < range.y) batch[thread] = tile_splat_of(projections[values[base + thread]]);
    __syncthreads();
    const uint32_t size = min(static_cast<uint32_t>(kBlock), range.y - base);
    for (uint32_t j = 0; !done && j < size; ++j) {
      float dx, dy, gaussian, alpha;
      if (!kernels::evaluate_splat(batch[j], static_cast<float>(x), static_cast<float>(y), dx, dy, gaussian, alpha)) continue;
      const float next = transmittance * (1.0f - alpha);
      if (next < kernels::kMinTransmittance) {
        done = true;
        break;
      }
      for (int c = 0; c < 3; ++c) colour[c] += batch[j].colour[c] * (alpha * transmittance);
      depth += batch[j].depth * alpha * transmittance;
      transmittance = next;
      walked = base - range.x + j + 1;
    }
  }
  if (!inside) return;
  const int pixel = y * camera.width + x;
  for (int c = 0; c < 3; ++c) image[3 * pixel + c] = colour[c] + transmittance * settings.background[c];
  const float alpha = 1.0f - transmittance;
  alpha_out[pixel] = alpha;
  depth_out[pixel] = settings.normalize_depth && alpha > 1e-6f ? depth / alpha : depth;
  final_transmittance[pixel] = transmittance;
  contributors[pixel] = walked;
}

__global__ void pixel_backward_kernel(ForwardSettings settings, const uint2* ranges, const uint32_t* values, const kernels::Projection* projections,
                                      const float* final_transmittance, const uint32_t* contributors, const float* loss_gradient,
                                      float* pair_gradients) {
  __shared__ kernels::TileSplat batch[kBlock];
  __shared__ uint32_t ids[kBlock];
  const kernels::CameraParams& camera = settings.camera;
  const int x = static_cast<int>(blockIdx.x) * kernels::kTileSize + static_cast<int>(threadIdx.x);
  const int y = static_cast<int>(blockIdx.y) * kernels::kTileSize + static_cast<int>(threadIdx.y);
  const int thread = static_cast<int>(threadIdx.y) * kernels::kTileSize + static_cast<int>(threadIdx.x);
  const bool inside = x < camera.width && y < camera.height;
  const int pixel = inside ? y * camera.width + x : 0;
  const uint2 range = ranges[blockIdx.y * camera.tiles_x + blockIdx.x];
  const int last = inside ? static_cast<int>(contributors[pixel]) : 0;  // list positions [0, last) were walked
  const float zero[3] = {0.0f, 0.0f, 0.0f};
  kernels::PixelBackward walk(inside ? loss_gradient + 3 * pixel : zero, inside ? final_transmittance[pixel] : 1.0f, settings.background);
  const int count = static_cast<int>(range.y - range.x);
  for (int batch_end = count; batch_end > 0; batch_end -= kBlock) {
    const int batch_begin = max(0, batch_end - kBlock);
    __syncthreads();
    if (batch_begin + thread < batch_end) {
      const uint32_t id = values[range.x + static_cast<uint32_t>(batch_begin + thread)];
      ids[thread] = id;
      batch[thread] = tile_splat_of(projections[id]);
    }
    __syncthreads();
    for (int j = min(batch_end, last) - 1; j >= batch_begin; --j) {
      const kernels::TileSplat& splat = batch[j - batch_begin];
      float dx, dy, gaussian, alpha;
      if (!kernels::evaluate_splat(splat, static_cast<float>(x), static_cast<float>(y), dx, dy, gaussian, alpha)) continue;
      float pair[kernels::kPairGradients];
      walk.step(splat, dx, dy, gaussian, alpha, pair);
      float* target = pair_gradients + static_cast<std::size_t>(ids[j - batch_begin]) * kernels::kPairGradients;
      for (int k = 0; k < kernels::kPairGradients; ++k) {
        if (pair[k] != 0.0f) atomicAdd(target + k, pair[k]);
      }
    }
  }
}

__global__ void gaussian_backward_kernel(int count, const float* position, const float* log_scale, const float* rotation, const float* sh, int sh_floats,
                                         int degree, kernels::CameraParams camera, const kernels::Projection* projections, const float* pair_gradients,
                                         BackwardOutputs gradients) {
  const int i = blockIdx.x * blockDim.x + threadIdx.x;
  if (i >= count || projections[i].radius == 0) return;
  const std::size_t sh_offset = static_cast<std::size_t>(i) * sh_floats;
  const kernels::GaussianGradientOut out{gradients.position + 3 * i, gradients.log_scale + 3 * i, gradients.rotation + 4 * i, gradients.opacity_logit + i,
                                         gradients.sh + sh_offset};
  gradients.screen_gradient_norm[i] = kernels::gaussian_backward(position + 3 * i, log_scale + 3 * i, rotation + 4 * i, sh + sh_offset, degree, camera,
                                                                 projections[i], pair_gradients + static_cast<std::size_t>(i) * kernels::kPairGradients, out);
}

}  // namespace

struct DeviceState {
  int device = 0;
  int count = 0, sh_floats = 0;
  Buffer<float> position, log_scale, rotation, opacity_logit, sh;
  // The last forward pass.
  ForwardSettings settings{};
  bool has_forward = false;
  int pairs = 0;
  Buffer<kernels::Projection> projections;
  Buffer<uint32_t> tiles_touched, offsets, values, values_sorted, contributors;
  Buffer<uint64_t> keys, keys_sorted;
  Buffer<uint2> ranges;
  Buffer<unsigned char> scratch;
  Buffer<float> image, depth, alpha, final_transmittance;
  // Backward.
  Buffer<float> loss_gradient, pair_gradients, gradient_position, gradient_log_scale, gradient_rotation, gradient_opacity, gradient_sh, screen_norm;

  void release_all() {
    for (Buffer<float>* buffer : {&position, &log_scale, &rotation, &opacity_logit, &sh, &image, &depth, &alpha, &final_transmittance, &loss_gradient,
                                  &pair_gradients, &gradient_position, &gradient_log_scale, &gradient_rotation, &gradient_opacity, &gradient_sh, &screen_norm}) {
      buffer->release();
    }
    for (Buffer<uint32_t>* buffer : {&tiles_touched, &offsets, &values, &values_sorted, &contributors}) buffer->release();
    projections.release();
    keys.release();
    keys_sorted.release();
    ranges.release();
    scratch.release();
  }
};

std::string device_count(int& count) {
  count = 0;
  const cudaError_t status = cudaGetDeviceCount(&count);
  if (status != cudaSuccess) {
    count = 0;
    return std::string("no CUDA device: ") + cudaGetErrorString(status);
  }
  return {};
}

std::string create_state(int device, DeviceState*& state, std::string& device_name) {
  state = nullptr;
  HANZO_CUDA_TRY(cudaSetDevice(device), "selecting the device");
  cudaDeviceProp properties{};
  HANZO_CUDA_TRY(cudaGetDeviceProperties(&properties, device), "reading the device's properties");
  device_name = properties.name;
  state = new DeviceState();
  state->device = device;
  return {};
}

void destroy_state(DeviceState* state) {
  if (state == nullptr) return;
  cudaSetDevice(state->device);
  state->release_all();
  delete state;
}

namespace {
template <typename T>
std::string upload(Buffer<T>& buffer, const T* host, std::size_t count, const char* what) {
  HANZO_CUDA_TRY(buffer.reserve(count), what);
  if (count > 0) HANZO_CUDA_TRY(cudaMemcpy(buffer.data, host, count * sizeof(T), cudaMemcpyHostToDevice), what);
  return {};
}

template <typename T>
std::string download(T* host, const Buffer<T>& buffer, std::size_t count, const char* what) {
  if (host != nullptr && count > 0) HANZO_CUDA_TRY(cudaMemcpy(host, buffer.data, count * sizeof(T), cudaMemcpyDeviceToHost), what);
  return {};
}
}  // namespace

std::string upload_cloud(DeviceState* state, int count, int sh_floats, const float* position, const float* log_scale, const float* rotation,
                         const float* opacity_logit, const float* sh) {
  HANZO_CUDA_TRY(cudaSetDevice(state->device), "selecting the device");
  const auto n = static_cast<std::size_t>(count);
  std::string error;
  if (!(error = upload(state->position, position, 3 * n, "uploading positions")).empty()) return error;
  if (!(error = upload(state->log_scale, log_scale, 3 * n, "uploading scales")).empty()) return error;
  if (!(error = upload(state->rotation, rotation, 4 * n, "uploading rotations")).empty()) return error;
  if (!(error = upload(state->opacity_logit, opacity_logit, n, "uploading opacities")).empty()) return error;
  if (!(error = upload(state->sh, sh, n * static_cast<std::size_t>(sh_floats), "uploading colours")).empty()) return error;
  state->count = count;
  state->sh_floats = sh_floats;
  state->has_forward = false;
  return {};
}

std::string forward(DeviceState* state, const ForwardSettings& settings, const ForwardOutputs& outputs) {
  HANZO_CUDA_TRY(cudaSetDevice(state->device), "selecting the device");
  const kernels::CameraParams& camera = settings.camera;
  const int n = state->count;
  const int tile_count = camera.tiles_x * camera.tiles_y;
  const auto pixels = static_cast<std::size_t>(camera.width) * static_cast<std::size_t>(camera.height);
  state->has_forward = false;
  HANZO_CUDA_TRY(state->projections.reserve(static_cast<std::size_t>(n)), "allocating projections");
  HANZO_CUDA_TRY(state->tiles_touched.reserve(static_cast<std::size_t>(n)), "allocating tile counts");
  HANZO_CUDA_TRY(state->offsets.reserve(static_cast<std::size_t>(n)), "allocating tile offsets");
  HANZO_CUDA_TRY(state->ranges.reserve(static_cast<std::size_t>(tile_count)), "allocating tile ranges");
  for (Buffer<float>* buffer : {&state->depth, &state->alpha, &state->final_transmittance}) HANZO_CUDA_TRY(buffer->reserve(pixels), "allocating images");
  HANZO_CUDA_TRY(state->image.reserve(3 * pixels), "allocating images");
  HANZO_CUDA_TRY(state->contributors.reserve(pixels), "allocating images");
  HANZO_CUDA_TRY(cudaMemset(state->ranges.data, 0, static_cast<std::size_t>(tile_count) * sizeof(uint2)), "clearing tile ranges");

  // 1. Project, count tiles, give each Gaussian its slots.
  uint32_t pairs = 0;
  if (n > 0) {
    project_kernel<<<blocks_for(n), kLinearBlock>>>(n, state->position.data, state->log_scale.data, state->rotation.data, state->opacity_logit.data,
                                                    state->sh.data, state->sh_floats, settings, state->projections.data, state->tiles_touched.data);
    HANZO_CUDA_TRY(cudaGetLastError(), "projecting");
    std::size_t scan_bytes = 0;
    HANZO_CUDA_TRY(cub::DeviceScan::InclusiveSum(nullptr, scan_bytes, state->tiles_touched.data, state->offsets.data, n), "sizing the scan");
    HANZO_CUDA_TRY(state->scratch.reserve(scan_bytes), "allocating the scan");
    HANZO_CUDA_TRY(cub::DeviceScan::InclusiveSum(state->scratch.data, scan_bytes, state->tiles_touched.data, state->offsets.data, n), "scanning tile counts");
    HANZO_CUDA_TRY(cudaMemcpy(&pairs, state->offsets.data + (n - 1), sizeof(uint32_t), cudaMemcpyDeviceToHost), "reading the pair count");
  }

  // 2. Pairs sorted by tile, depth, index; each tile's range.
  if (pairs > 0) {
    HANZO_CUDA_TRY(state->keys.reserve(pairs), "allocating pairs");
    HANZO_CUDA_TRY(state->keys_sorted.reserve(pairs), "allocating pairs");
    HANZO_CUDA_TRY(state->values.reserve(pairs), "allocating pairs");
    HANZO_CUDA_TRY(state->values_sorted.reserve(pairs), "allocating pairs");
    duplicate_kernel<<<blocks_for(n), kLinearBlock>>>(n, state->projections.data, state->offsets.data, camera.tiles_x, state->keys.data, state->values.data);
    HANZO_CUDA_TRY(cudaGetLastError(), "listing tile pairs");
    int tile_bits = 1;
    while ((1 << tile_bits) < tile_count + 1) ++tile_bits;
    std::size_t sort_bytes = 0;
    const auto pair_count = static_cast<int>(pairs);
    HANZO_CUDA_TRY(cub::DeviceRadixSort::SortPairs(nullptr, sort_bytes, state->keys.data, state->keys_sorted.data, state->values.data,
                                                   state->values_sorted.data, pair_count, 0, 32 + tile_bits),
                   "sizing the sort");
    HANZO_CUDA_TRY(state->scratch.reserve(sort_bytes), "allocating the sort");
    HANZO_CUDA_TRY(cub::DeviceRadixSort::SortPairs(state->scratch.data, sort_bytes, state->keys.data, state->keys_sorted.data, state->values.data,
                                                   state->values_sorted.data, pair_count, 0, 32 + tile_bits),
                   "sorting tile pairs");
    ranges_kernel<<<blocks_for(pair_count), kLinearBlock>>>(pair_count, state->keys_sorted.data, state->ranges.data);
    HANZO_CUDA_TRY(cudaGetLastError(), "finding tile ranges");
  }

  // 3. Blend.
  if (pixels > 0) {
    const dim3 grid(static_cast<unsigned>(camera.tiles_x), static_cast<unsigned>(camera.tiles_y));
    const dim3 block(kernels::kTileSize, kernels::kTileSize);
    blend_kernel<<<grid, block>>>(settings, state->ranges.data, state->values_sorted.data, state->projections.data, state->image.data, state->depth.data,
                                  state->alpha.data, state->final_transmittance.data, state->contributors.data);
    HANZO_CUDA_TRY(cudaGetLastError(), "blending");
  }
  HANZO_CUDA_TRY(cudaDeviceSynchronize(), "rendering");

  std::string error;
  if (!(error = download(outputs.image, state->image, 3 * pixels, "downloading the image")).empty()) return error;
  if (!(error = download(outputs.depth, state->depth, pixels, "downloading the depth")).empty()) return error;
  if (!(error = download(outputs.alpha, state->alpha, pixels, "downloading the alpha")).empty()) return error;
  if (!(error = download(outputs.final_transmittance, state->final_transmittance, pixels, "downloading the transmittance")).empty()) return error;
  if (!(error = download(outputs.contributors, state->contributors, pixels, "downloading the contributors")).empty()) return error;
  if (!(error = download(outputs.projections, state->projections, static_cast<std::size_t>(n), "downloading the projections")).empty()) return error;
  state->settings = settings;
  state->pairs = static_cast<int>(pairs);
  state->has_forward = true;
  return {};
}

std::string backward(DeviceState* state, const float* loss_gradient_image, const BackwardOutputs& outputs) {
  if (!state->has_forward) return "backward without a forward pass of the uploaded cloud";
  HANZO_CUDA_TRY(cudaSetDevice(state->device), "selecting the device");
  const ForwardSettings& settings = state->settings;
  const kernels::CameraParams& camera = settings.camera;
  const auto n = static_cast<std::size_t>(state->count);
  const auto pixels = static_cast<std::size_t>(camera.width) * static_cast<std::size_t>(camera.height);
  const auto sh_total = n * static_cast<std::size_t>(state->sh_floats);
  std::string error;
  if (!(error = upload(state->loss_gradient, loss_gradient_image, 3 * pixels, "uploading dL/dimage")).empty()) return error;
  const std::pair<Buffer<float>*, std::size_t> zeroed[] = {{&state->pair_gradients, n * kernels::kPairGradients},
                                                           {&state->gradient_position, 3 * n},
                                                           {&state->gradient_log_scale, 3 * n},
                                                           {&state->gradient_rotation, 4 * n},
                                                           {&state->gradient_opacity, n},
                                                           {&state->gradient_sh, sh_total},
                                                           {&state->screen_norm, n}};
  for (const auto& [buffer, size] : zeroed) {
    HANZO_CUDA_TRY(buffer->reserve(size), "allocating gradients");
    HANZO_CUDA_TRY(cudaMemset(buffer->data, 0, std::max<std::size_t>(size, 1) * sizeof(float)), "clearing gradients");
  }
  if (pixels > 0) {
    const dim3 grid(static_cast<unsigned>(camera.tiles_x), static_cast<unsigned>(camera.tiles_y));
    const dim3 block(kernels::kTileSize, kernels::kTileSize);
    pixel_backward_kernel<<<grid, block>>>(settings, state->ranges.data, state->values_sorted.data, state->projections.data,
                                           state->final_transmittance.data, state->contributors.data, state->loss_gradient.data,
                                           state->pair_gradients.data);
    HANZO_CUDA_TRY(cudaGetLastError(), "pixel gradients");
  }
  if (n > 0) {
    const BackwardOutputs device_gradients{state->gradient_position.data, state->gradient_log_scale.data, state->gradient_rotation.data,
                                           state->gradient_opacity.data,  state->gradient_sh.data,        state->screen_norm.data};
    gaussian_backward_kernel<<<blocks_for(static_cast<int>(n)), kLinearBlock>>>(
        static_cast<int>(n), state->position.data, state->log_scale.data, state->rotation.data, state->sh.data, state->sh_floats, settings.degree, camera,
        state->projections.data, state->pair_gradients.data, device_gradients);
    HANZO_CUDA_TRY(cudaGetLastError(), "Gaussian gradients");
  }
  HANZO_CUDA_TRY(cudaDeviceSynchronize(), "back-propagating");
  if (!(error = download(outputs.position, state->gradient_position, 3 * n, "downloading gradients")).empty()) return error;
  if (!(error = download(outputs.log_scale, state->gradient_log_scale, 3 * n, "downloading gradients")).empty()) return error;
  if (!(error = download(outputs.rotation, state->gradient_rotation, 4 * n, "downloading gradients")).empty()) return error;
  if (!(error = download(outputs.opacity_logit, state->gradient_opacity, n, "downloading gradients")).empty()) return error;
  if (!(error = download(outputs.sh, state->gradient_sh, sh_total, "downloading gradients")).empty()) return error;
  return download(outputs.screen_gradient_norm, state->screen_norm, n, "downloading gradients");
}

}  // namespace hanzo::fusion::neural::cuda
