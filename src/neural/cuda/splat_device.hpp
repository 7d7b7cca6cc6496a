#pragma once
// The CUDA half of CudaSplatRasterizer (splat_rasterizer_cuda.hpp), behind plain pointers so
// that neither Eigen nor CUDA crosses the boundary. Every function returns an empty string on
// success, else the CUDA error's text with the step that failed.

#include <cstdint>
#include <string>

#include "../splat_kernels.hpp"

namespace hanzo::fusion::neural::cuda {

struct DeviceState;  ///< device buffers of one rasterizer (grown as needed, reused)

/// CUDA devices present (0 when there is no driver or device; the reason in the return value).
std::string device_count(int& count);
std::string create_state(int device, DeviceState*& state, std::string& device_name);
void destroy_state(DeviceState* state);

/// The cloud's arrays (count Gaussians, sh_floats coefficients each) onto the device.
std::string upload_cloud(DeviceState* state, int count, int sh_floats, const float* position, const float* log_scale, const float* rotation,
                         const float* opacity_logit, const float* sh);

struct ForwardSettings {
  kernels::CameraParams camera;
  int degree;
  float near, low_pass;
  float background[3];
  bool normalize_depth;
};

/// Host arrays the forward pass fills: per pixel (image 3 floats a pixel) and per Gaussian. A null
/// array is not downloaded (a view for display needs the image alone).
struct ForwardOutputs {
  float* image;
  float* depth;
  float* alpha;
  float* final_transmittance;
  uint32_t* contributors;
  kernels::Projection* projections;  ///< radius 0: not drawn
};

/// Renders the uploaded cloud; the tile lists stay on the device for backward().
std::string forward(DeviceState* state, const ForwardSettings& settings, const ForwardOutputs& outputs);

/// Arrays the backward pass writes (the cloud's layout) and the per-Gaussian statistic.
struct BackwardOutputs {
  float* position;
  float* log_scale;
  float* rotation;
  float* opacity_logit;
  float* sh;
  float* screen_gradient_norm;
};

/// Gradients of the last forward() for dL/dimage (3 floats a pixel, host memory).
std::string backward(DeviceState* state, const float* loss_gradient_image, const BackwardOutputs& outputs);

}  // namespace hanzo::fusion::neural::cuda
