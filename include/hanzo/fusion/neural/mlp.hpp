#pragma once
// A small fully connected network for neural fields, evaluated on the CPU for many inputs at once
// (the "fully fused MLP" of tiny-cuda-nn, Mueller et al. 2021, on CPU cores): `hidden_layers`
// layers of `width` ReLU units between `inputs` and `outputs`, no biases, a linear output (the
// caller applies its own output activation). Layer l computes y = x W_l with W_l stored row-major
// as [inputs of l][outputs of l], the layers one after the other in one float array owned by the
// caller (so that any optimizer moves them).
//
// forward() and backward() split the rows into fixed blocks of kMlpBlockRows that run in
// parallel (TBB); backward() sums the blocks' weight gradients in block order, so that the
// result does not depend on the thread count or schedule. The inner loops are compiled for
// AVX-512, AVX2 and baseline x86-64 and picked at run time.

#include <cstddef>
#include <random>
#include <vector>

#include "hanzo/fusion/core/result.hpp"

namespace hanzo::fusion::neural {

inline constexpr std::size_t kMlpBlockRows = 1024;

struct MlpShape {
  int inputs = 32;
  int width = 64;
  int hidden_layers = 1;
  int outputs = 16;
};

Status validate(const MlpShape& shape);

class Mlp {
 public:
  explicit Mlp(const MlpShape& shape);  ///< the shape must be valid

  const MlpShape& shape() const { return shape_; }
  std::size_t parameter_count() const { return offsets_.back(); }
  /// Floats per row kept by forward() for backward(): every hidden layer's activations.
  std::size_t activation_floats() const { return static_cast<std::size_t>(shape_.hidden_layers) * static_cast<std::size_t>(shape_.width); }

  /// Xavier-uniform weights (Glorot and Bengio 2010) into `parameters` from `random`.
  void initialize(float* parameters, std::mt19937_64& random) const;

  /// output[count][outputs] from input[count][inputs]; with `activations`
  /// ([count][activation_floats()]) the hidden layers' outputs are kept for backward().
  void forward(const float* parameters, const float* input, std::size_t count, float* output, float* activations = nullptr) const;

  /// From dL/doutput: parameter_gradient += dL/dW (every layer), and dL/dinput when
  /// `input_gradient` is given. `input` and `activations` are forward()'s.
  void backward(const float* parameters, const float* input, const float* activations, std::size_t count, const float* output_gradient,
                float* parameter_gradient, float* input_gradient = nullptr) const;

 private:
  int layer_inputs(int layer) const { return layer == 0 ? shape_.inputs : shape_.width; }
  int layer_outputs(int layer) const { return layer == shape_.hidden_layers ? shape_.outputs : shape_.width; }

  MlpShape shape_;
  std::vector<std::size_t> offsets_;  ///< first float of each layer's matrix; back(): all
};

}  // namespace hanzo::fusion::neural
