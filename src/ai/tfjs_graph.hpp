#pragma once
// TfjsGraph: a TensorFlow.js graph model (`format: graph-model`: `<name>.json`, a TensorFlow
// GraphDef written as JSON with a weights manifest, and the binary weight shards it lists) read
// and run on libtorch, on the CPU.
//
// Tensors keep TensorFlow's layouts (images NHWC, filters HWIO); each operation is the libtorch
// one of the same meaning. Operations: Const (from the weight shards), Placeholder, Identity,
// Pad, PadV2, Transpose, Reshape, ConcatV2, SplitV, SparseToDense, Add, AddV2, Sub, Mul,
// LeakyRelu, Relu, Sigmoid, Conv2D (NHWC, VALID or SAME, grouped when the filter has fewer input
// channels than the image), MaxPool (NHWC) and ResizeBilinear (align_corners false, half-pixel
// centres or not). Weights: float32 and int32, and float16 / uint8 / uint16 quantized ones
// (restored to float32 as the manifest's quantization says).
//
// Failure (read): a missing or malformed file, a weight shard shorter than its manifest, an
// operation outside the list above, an input no node defines, a cycle. run(): an input missing or
// of another rank, an operation whose operands disagree (libtorch's message, with the node's
// name). Errors name the file or the node.

#include <map>
#include <string>
#include <vector>

#include <torch/torch.h>

#include "hanzo/fusion/core/result.hpp"

namespace hanzo::fusion::ai {

class TfjsGraph {
 public:
  /// `path`: the model's JSON; its shards are read from the same folder.
  static Result<TfjsGraph> read(const std::string& path);

  /// Runs the graph with `inputs` (placeholder name to tensor) and returns `outputs` (node
  /// names, "name" or "name:k" for a node's k-th output).
  Result<std::map<std::string, torch::Tensor>> run(const std::map<std::string, torch::Tensor>& inputs,
                                                   const std::vector<std::string>& outputs) const;

  /// Placeholder names and their declared shapes (-1 where free).
  const std::map<std::string, std::vector<int64_t>>& inputs() const { return inputs_; }
  const std::string& path() const { return path_; }

  struct Node {
    std::string name;
    std::string op;
    std::vector<std::string> inputs;  // "name" or "name:k"
    std::map<std::string, std::vector<int64_t>> int_lists;  // strides, ksize, dilations
    std::map<std::string, std::string> strings;              // padding, data_format
    std::map<std::string, double> numbers;                   // alpha
    std::map<std::string, bool> flags;                       // align_corners, half_pixel_centers
  };

 private:
  std::string path_;
  std::vector<Node> nodes_;  // in an order where every input comes first
  std::map<std::string, torch::Tensor> constants_;
  std::map<std::string, std::vector<int64_t>> inputs_;
};

}  // namespace hanzo::fusion::ai
