#include "hanzo/fusion/neural/mlp.hpp"

#include <algorithm>
#include <cmath>

#include <tbb/parallel_for.h>

#if defined(__x86_64__) && defined(__GNUC__) && !defined(__clang__)
#define HANZO_VECTOR_CLONES __attribute__((target_clones("arch=skylake-avx512", "arch=haswell", "default")))
#else
#define HANZO_VECTOR_CLONES
#endif

namespace hanzo::fusion::neural {

namespace {

// The kernels are templates on the width that their accumulators span (so that the compiler keeps
// them in vector registers: one load per multiply-add), inlined into clones per instruction set.
// Width 0: a run-time width (`n`).

// y[r][0..out) = x[r][0..in) W (W: [in][out]); ReLU on y when `relu`. Strides in floats.
template <int Out>
__attribute__((always_inline)) inline void multiply_kernel(const float* x, std::size_t x_stride, int in, const float* weights, int n, std::size_t rows,
                                                           float* y, std::size_t y_stride, bool relu) {
  const int out = Out > 0 ? Out : n;
  constexpr int kCapacity = Out > 0 ? Out : 1;
  for (std::size_t r = 0; r < rows; ++r) {
    const float* xr = x + r * x_stride;
    float* yr = y + r * y_stride;
    float fixed[kCapacity] = {};
    float* acc = Out > 0 ? fixed : yr;
    if (Out == 0) {
      for (int j = 0; j < out; ++j) acc[j] = 0.0f;
    }
    for (int i = 0; i < in; ++i) {
      const float xi = xr[i];
      const float* w = weights + static_cast<std::size_t>(i) * static_cast<std::size_t>(out);
      for (int j = 0; j < out; ++j) acc[j] += xi * w[j];
    }
    for (int j = 0; j < out; ++j) yr[j] = relu && acc[j] < 0.0f ? 0.0f : acc[j];
  }
}

// gradient[i][j] += sum_r x[r][i] g[r][j], rows in tiles so that a tile of g stays in cache while
// each gradient row accumulates in registers.
template <int Out>
__attribute__((always_inline)) inline void accumulate_outer_kernel(const float* x, std::size_t x_stride, int in, const float* g, int n, std::size_t rows,
                                                                   float* gradient) {
  const int out = Out > 0 ? Out : n;
  constexpr std::size_t kTile = 64;
  constexpr int kCapacity = Out > 0 ? Out : 1;
  for (std::size_t first = 0; first < rows; first += kTile) {
    const std::size_t last = std::min(rows, first + kTile);
    for (int i = 0; i < in; ++i) {
      float* row = gradient + static_cast<std::size_t>(i) * static_cast<std::size_t>(out);
      float fixed[kCapacity];
      float* acc = Out > 0 ? fixed : row;
      if (Out > 0) {
        for (int j = 0; j < out; ++j) acc[j] = row[j];
      }
      for (std::size_t r = first; r < last; ++r) {
        const float xi = x[r * x_stride + static_cast<std::size_t>(i)];
        const float* gr = g + r * static_cast<std::size_t>(out);
        for (int j = 0; j < out; ++j) acc[j] += xi * gr[j];
      }
      if (Out > 0) {
        for (int j = 0; j < out; ++j) row[j] = acc[j];
      }
    }
  }
}

// dx[r][i] = sum_j g[r][j] W[i][j] through W^T ([out][in]), times (a[r][i] > 0) when `relu_of`
// (the layer's input: the previous ReLU's output) is given.
template <int In>
__attribute__((always_inline)) inline void multiply_transposed_kernel(const float* g, int out, const float* weights_transposed, int n, std::size_t rows,
                                                                      float* dx, const float* relu_of, std::size_t relu_stride) {
  const int in = In > 0 ? In : n;
  constexpr int kCapacity = In > 0 ? In : 1;
  for (std::size_t r = 0; r < rows; ++r) {
    const float* gr = g + r * static_cast<std::size_t>(out);
    float* dr = dx + r * static_cast<std::size_t>(in);
    float fixed[kCapacity] = {};
    float* acc = In > 0 ? fixed : dr;
    if (In == 0) {
      for (int i = 0; i < in; ++i) acc[i] = 0.0f;
    }
    for (int j = 0; j < out; ++j) {
      const float gj = gr[j];
      const float* w = weights_transposed + static_cast<std::size_t>(j) * static_cast<std::size_t>(in);
      for (int i = 0; i < in; ++i) acc[i] += gj * w[i];
    }
    const float* a = relu_of != nullptr ? relu_of + r * relu_stride : nullptr;
    for (int i = 0; i < in; ++i) dr[i] = a != nullptr && !(a[i] > 0.0f) ? 0.0f : acc[i];
  }
}

#define HANZO_MLP_KERNEL(name, kernel, width, parameters, arguments) \
  HANZO_VECTOR_CLONES void name parameters { kernel<width> arguments; }

#define HANZO_MULTIPLY_PARAMETERS (const float* x, std::size_t x_stride, int in, const float* weights, int n, std::size_t rows, float* y, std::size_t y_stride, bool relu)
#define HANZO_MULTIPLY_ARGUMENTS (x, x_stride, in, weights, n, rows, y, y_stride, relu)
HANZO_MLP_KERNEL(multiply_64, multiply_kernel, 64, HANZO_MULTIPLY_PARAMETERS, HANZO_MULTIPLY_ARGUMENTS)
HANZO_MLP_KERNEL(multiply_16, multiply_kernel, 16, HANZO_MULTIPLY_PARAMETERS, HANZO_MULTIPLY_ARGUMENTS)
HANZO_MLP_KERNEL(multiply_any, multiply_kernel, 0, HANZO_MULTIPLY_PARAMETERS, HANZO_MULTIPLY_ARGUMENTS)

#define HANZO_OUTER_PARAMETERS (const float* x, std::size_t x_stride, int in, const float* g, int n, std::size_t rows, float* gradient)
#define HANZO_OUTER_ARGUMENTS (x, x_stride, in, g, n, rows, gradient)
HANZO_MLP_KERNEL(accumulate_outer_64, accumulate_outer_kernel, 64, HANZO_OUTER_PARAMETERS, HANZO_OUTER_ARGUMENTS)
HANZO_MLP_KERNEL(accumulate_outer_16, accumulate_outer_kernel, 16, HANZO_OUTER_PARAMETERS, HANZO_OUTER_ARGUMENTS)
HANZO_MLP_KERNEL(accumulate_outer_any, accumulate_outer_kernel, 0, HANZO_OUTER_PARAMETERS, HANZO_OUTER_ARGUMENTS)

#define HANZO_TRANSPOSED_PARAMETERS \
  (const float* g, int out, const float* weights_transposed, int n, std::size_t rows, float* dx, const float* relu_of, std::size_t relu_stride)
#define HANZO_TRANSPOSED_ARGUMENTS (g, out, weights_transposed, n, rows, dx, relu_of, relu_stride)
HANZO_MLP_KERNEL(multiply_transposed_64, multiply_transposed_kernel, 64, HANZO_TRANSPOSED_PARAMETERS, HANZO_TRANSPOSED_ARGUMENTS)
HANZO_MLP_KERNEL(multiply_transposed_32, multiply_transposed_kernel, 32, HANZO_TRANSPOSED_PARAMETERS, HANZO_TRANSPOSED_ARGUMENTS)
HANZO_MLP_KERNEL(multiply_transposed_any, multiply_transposed_kernel, 0, HANZO_TRANSPOSED_PARAMETERS, HANZO_TRANSPOSED_ARGUMENTS)

void multiply(const float* x, std::size_t x_stride, int in, const float* weights, int out, std::size_t rows, float* y, std::size_t y_stride, bool relu) {
  auto* kernel = out == 64 ? multiply_64 : out == 16 ? multiply_16 : multiply_any;
  kernel(x, x_stride, in, weights, out, rows, y, y_stride, relu);
}

void accumulate_outer(const float* x, std::size_t x_stride, int in, const float* g, int out, std::size_t rows, float* gradient) {
  auto* kernel = out == 64 ? accumulate_outer_64 : out == 16 ? accumulate_outer_16 : accumulate_outer_any;
  kernel(x, x_stride, in, g, out, rows, gradient);
}

void multiply_transposed(const float* g, int out, const float* weights_transposed, int in, std::size_t rows, float* dx, const float* relu_of,
                         std::size_t relu_stride) {
  auto* kernel = in == 64 ? multiply_transposed_64 : in == 32 ? multiply_transposed_32 : multiply_transposed_any;
  kernel(g, out, weights_transposed, in, rows, dx, relu_of, relu_stride);
}

}  // namespace

Status validate(const MlpShape& shape) {
  if (shape.inputs < 1 || shape.width < 1 || shape.outputs < 1 || shape.hidden_layers < 0) {
    return Error("MlpShape: inputs, width and outputs must be >= 1, hidden_layers >= 0");
  }
  if (shape.width > 4096 || shape.inputs > 4096 || shape.outputs > 4096 || shape.hidden_layers > 64) return Error("MlpShape: too large (4096 units, 64 layers at most)");
  return ok_status();
}

Mlp::Mlp(const MlpShape& shape) : shape_(shape) {
  offsets_.push_back(0);
  for (int layer = 0; layer <= shape.hidden_layers; ++layer) {
    offsets_.push_back(offsets_.back() + static_cast<std::size_t>(layer_inputs(layer)) * static_cast<std::size_t>(layer_outputs(layer)));
  }
}

void Mlp::initialize(float* parameters, std::mt19937_64& random) const {
  for (int layer = 0; layer <= shape_.hidden_layers; ++layer) {
    const double limit = std::sqrt(6.0 / static_cast<double>(layer_inputs(layer) + layer_outputs(layer)));
    std::uniform_real_distribution<float> uniform(static_cast<float>(-limit), static_cast<float>(limit));
    for (std::size_t i = offsets_[static_cast<std::size_t>(layer)]; i < offsets_[static_cast<std::size_t>(layer) + 1]; ++i) parameters[i] = uniform(random);
  }
}

void Mlp::forward(const float* parameters, const float* input, std::size_t count, float* output, float* activations) const {
  const std::size_t blocks = (count + kMlpBlockRows - 1) / kMlpBlockRows;
  const std::size_t kept = activation_floats();
  const auto width = static_cast<std::size_t>(shape_.width);
  tbb::parallel_for(std::size_t{0}, blocks, [&](std::size_t block) {
    const std::size_t first = block * kMlpBlockRows;
    const std::size_t rows = std::min(kMlpBlockRows, count - first);
    // Without `activations`, two scratch buffers take turns.
    std::vector<float> scratch(activations == nullptr ? 2 * rows * width : 0);
    const float* x = input + first * static_cast<std::size_t>(shape_.inputs);
    std::size_t x_stride = static_cast<std::size_t>(shape_.inputs);
    for (int layer = 0; layer <= shape_.hidden_layers; ++layer) {
      const float* weights = parameters + offsets_[static_cast<std::size_t>(layer)];
      if (layer == shape_.hidden_layers) {
        multiply(x, x_stride, layer_inputs(layer), weights, shape_.outputs, rows, output + first * static_cast<std::size_t>(shape_.outputs),
                 static_cast<std::size_t>(shape_.outputs), false);
        break;
      }
      float* y = activations != nullptr ? activations + first * kept + static_cast<std::size_t>(layer) * width : scratch.data() + static_cast<std::size_t>(layer % 2) * rows * width;
      const std::size_t y_stride = activations != nullptr ? kept : width;
      multiply(x, x_stride, layer_inputs(layer), weights, shape_.width, rows, y, y_stride, true);
      x = y;
      x_stride = y_stride;
    }
  });
}

void Mlp::backward(const float* parameters, const float* input, const float* activations, std::size_t count, const float* output_gradient,
                   float* parameter_gradient, float* input_gradient) const {
  const std::size_t blocks = (count + kMlpBlockRows - 1) / kMlpBlockRows;
  const std::size_t kept = activation_floats();
  const auto width = static_cast<std::size_t>(shape_.width);
  // W^T per layer ([outputs][inputs]) so that dL/dx runs along contiguous memory.
  std::vector<float> transposed(parameter_count());
  for (int layer = 0; layer <= shape_.hidden_layers; ++layer) {
    const int in = layer_inputs(layer), out = layer_outputs(layer);
    const std::size_t offset = offsets_[static_cast<std::size_t>(layer)];
    for (int i = 0; i < in; ++i) {
      for (int j = 0; j < out; ++j) {
        transposed[offset + static_cast<std::size_t>(j) * static_cast<std::size_t>(in) + static_cast<std::size_t>(i)] =
            parameters[offset + static_cast<std::size_t>(i) * static_cast<std::size_t>(out) + static_cast<std::size_t>(j)];
      }
    }
  }
  std::vector<std::vector<float>> block_gradients(blocks);
  tbb::parallel_for(std::size_t{0}, blocks, [&](std::size_t block) {
    const std::size_t first = block * kMlpBlockRows;
    const std::size_t rows = std::min(kMlpBlockRows, count - first);
    std::vector<float>& gradient = block_gradients[block];
    gradient.assign(parameter_count(), 0.0f);
    std::vector<float> g(output_gradient + first * static_cast<std::size_t>(shape_.outputs),
                         output_gradient + (first + rows) * static_cast<std::size_t>(shape_.outputs));
    std::vector<float> dx;
    for (int layer = shape_.hidden_layers; layer >= 0; --layer) {
      const int in = layer_inputs(layer), out = layer_outputs(layer);
      const float* x = layer == 0 ? input + first * static_cast<std::size_t>(shape_.inputs)
                                  : activations + first * kept + static_cast<std::size_t>(layer - 1) * width;
      const std::size_t x_stride = layer == 0 ? static_cast<std::size_t>(shape_.inputs) : kept;
      accumulate_outer(x, x_stride, in, g.data(), out, rows, gradient.data() + offsets_[static_cast<std::size_t>(layer)]);
      if (layer == 0 && input_gradient == nullptr) break;
      dx.resize(rows * static_cast<std::size_t>(in));
      multiply_transposed(g.data(), out, transposed.data() + offsets_[static_cast<std::size_t>(layer)], in, rows,
                          layer == 0 ? input_gradient + first * static_cast<std::size_t>(shape_.inputs) : dx.data(), layer == 0 ? nullptr : x, x_stride);
      if (layer > 0) g.swap(dx);
    }
  });
  // The blocks' sums in block order.
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, parameter_count(), 1024), [&](const tbb::blocked_range<std::size_t>& range) {
    for (std::size_t block = 0; block < blocks; ++block) {
      const float* gradient = block_gradients[block].data();
      for (std::size_t i = range.begin(); i != range.end(); ++i) parameter_gradient[i] += gradient[i];
    }
  });
}

}  // namespace hanzo::fusion::neural
