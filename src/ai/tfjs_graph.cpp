#include "tfjs_graph.hpp"

#include <algorithm>
#include <filesystem>
#include <fstream>
#include <functional>
#include <iterator>
#include <set>

#include <fmt/format.h>
#include <nlohmann/json.hpp>

namespace hanzo::fusion::ai {
namespace {

using Json = nlohmann::json;
namespace F = torch::nn::functional;

const std::set<std::string>& supported_operations() {
  static const std::set<std::string> operations = {"Const",   "Placeholder", "Identity", "Pad",       "PadV2",     "Transpose",
                                                   "Reshape", "ConcatV2",    "SplitV",   "SparseToDense", "Add", "AddV2",
                                                   "Sub",     "Mul",         "LeakyRelu", "Relu",      "Sigmoid",   "Conv2D",
                                                   "MaxPool", "ResizeBilinear"};
  return operations;
}

std::string base64_decode(const std::string& text) {
  static const std::string alphabet = "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
  std::string bytes;
  uint32_t bits = 0;
  int count = 0;
  for (const char c : text) {
    const std::size_t value = alphabet.find(c);
    if (value == std::string::npos) break;  // '=' padding ends it
    bits = (bits << 6U) | static_cast<uint32_t>(value);
    count += 6;
    if (count >= 8) {
      count -= 8;
      bytes.push_back(static_cast<char>((bits >> static_cast<uint32_t>(count)) & 0xFFU));
    }
  }
  return bytes;
}

TfjsGraph::Node parse_node(const Json& json) {
  TfjsGraph::Node node;
  node.name = json.at("name").get<std::string>();
  node.op = json.at("op").get<std::string>();
  for (const Json& input : json.value("input", Json::array())) {
    const std::string name = input.get<std::string>();
    if (!name.starts_with("^")) node.inputs.push_back(name);  // control dependencies order nothing here
  }
  const Json attributes = json.value("attr", Json::object());
  for (const auto& [key, attribute] : attributes.items()) {
    if (attribute.contains("list") && attribute["list"].contains("i")) {
      std::vector<int64_t>& values = node.int_lists[key];
      for (const Json& value : attribute["list"]["i"]) values.push_back(std::stoll(value.get<std::string>()));
    } else if (attribute.contains("s")) {
      node.strings[key] = base64_decode(attribute["s"].get<std::string>());
    } else if (attribute.contains("f")) {
      node.numbers[key] = attribute["f"].get<double>();
    } else if (attribute.contains("b")) {
      node.flags[key] = attribute["b"].get<bool>();
    }
  }
  return node;
}

// One weight of the manifest from its bytes: float32 / int32 as stored, quantized ones restored.
Result<torch::Tensor> decode_weight(const Json& weight, const char* bytes, std::size_t available, std::size_t& used) {
  std::vector<int64_t> shape = weight.at("shape").get<std::vector<int64_t>>();
  int64_t count = 1;
  for (const int64_t size : shape) count *= size;
  const std::string dtype = weight.at("dtype").get<std::string>();
  std::string stored = dtype;
  if (weight.contains("quantization")) stored = weight["quantization"].at("dtype").get<std::string>();
  const std::map<std::string, std::pair<std::size_t, torch::ScalarType>> kinds = {
      {"float32", {4, torch::kFloat}}, {"int32", {4, torch::kInt}}, {"float16", {2, torch::kHalf}}, {"uint8", {1, torch::kByte}}, {"uint16", {2, torch::kInt16}}};
  const auto kind = kinds.find(stored);
  if (kind == kinds.end()) return Error(fmt::format("weight {}: stored as {}, which this reader does not know", weight.at("name").get<std::string>(), stored));
  used = kind->second.first * static_cast<std::size_t>(count);
  if (used > available) return Error(fmt::format("weight {}: needs {} bytes, the shards have {} left", weight.at("name").get<std::string>(), used, available));
  torch::Tensor tensor = torch::empty({count}, kind->second.second);
  std::memcpy(tensor.data_ptr(), bytes, used);
  if (stored == "uint16") tensor = tensor.to(torch::kInt).bitwise_and(0xFFFF);
  if (stored == "uint8" || stored == "uint16") {
    const Json& quantization = weight["quantization"];
    tensor = tensor.to(torch::kFloat) * quantization.at("scale").get<float>() + quantization.at("min").get<float>();
  }
  tensor = dtype == "int32" ? tensor.to(torch::kLong) : tensor.to(torch::kFloat);
  return tensor.reshape(shape);
}

// TensorFlow's SAME padding along one axis: (before, after).
std::pair<int64_t, int64_t> same_padding(int64_t size, int64_t kernel, int64_t stride, int64_t dilation) {
  const int64_t extent = (kernel - 1) * dilation + 1;
  const int64_t output = (size + stride - 1) / stride;
  const int64_t total = std::max<int64_t>(0, (output - 1) * stride + extent - size);
  return {total / 2, total - total / 2};
}

// NHWC -> NCHW with TensorFlow's padding applied.
torch::Tensor to_nchw_padded(const torch::Tensor& nhwc, const TfjsGraph::Node& node, int64_t kernel_h, int64_t kernel_w, double pad_value) {
  torch::Tensor nchw = nhwc.permute({0, 3, 1, 2});
  const std::string padding = node.strings.count("padding") != 0 ? node.strings.at("padding") : "VALID";
  if (padding != "SAME") return nchw;
  const std::vector<int64_t>& strides = node.int_lists.at("strides");
  const std::vector<int64_t> dilations = node.int_lists.count("dilations") != 0 ? node.int_lists.at("dilations") : std::vector<int64_t>{1, 1, 1, 1};
  const auto [top, bottom] = same_padding(nchw.size(2), kernel_h, strides[1], dilations[1]);
  const auto [left, right] = same_padding(nchw.size(3), kernel_w, strides[2], dilations[2]);
  return F::pad(nchw, F::PadFuncOptions({left, right, top, bottom}).value(pad_value));
}

std::vector<int64_t> as_vector(const torch::Tensor& tensor) {
  const torch::Tensor values = tensor.to(torch::kLong).contiguous().flatten();
  return {values.data_ptr<int64_t>(), values.data_ptr<int64_t>() + values.numel()};
}

int64_t axis_of(const torch::Tensor& axis, int64_t rank) {
  const int64_t value = axis.item<int64_t>();
  return value < 0 ? value + rank : value;
}

std::vector<torch::Tensor> evaluate(const TfjsGraph::Node& node, const std::vector<torch::Tensor>& in) {
  const std::string& op = node.op;
  if (op == "Identity") return {in.at(0)};
  if (op == "Pad" || op == "PadV2") {
    const std::vector<int64_t> pairs = as_vector(in.at(1));  // (before, after) per axis, outermost first
    std::vector<int64_t> torch_order;
    for (std::size_t axis = pairs.size() / 2; axis-- > 0;) {
      torch_order.push_back(pairs[2 * axis]);
      torch_order.push_back(pairs[2 * axis + 1]);
    }
    const double value = op == "PadV2" ? in.at(2).item<double>() : 0.0;
    return {F::pad(in.at(0), F::PadFuncOptions(torch_order).value(value))};
  }
  if (op == "Transpose") return {in.at(0).permute(as_vector(in.at(1))).contiguous()};
  if (op == "Reshape") return {in.at(0).reshape(as_vector(in.at(1)))};
  if (op == "ConcatV2") {
    const std::vector<torch::Tensor> parts(in.begin(), in.end() - 1);
    return {torch::cat(parts, axis_of(in.back(), parts.at(0).dim()))};
  }
  if (op == "SplitV") return torch::split_with_sizes(in.at(0), as_vector(in.at(1)), axis_of(in.at(2), in.at(0).dim()));
  if (op == "SparseToDense") {
    torch::Tensor dense = torch::full(as_vector(in.at(1)), in.at(3).item<double>(), in.at(2).scalar_type());
    const int64_t count = in.at(0).dim() == 0 ? 1 : in.at(0).size(0);
    const torch::Tensor indices = in.at(0).to(torch::kLong).reshape({count, in.at(0).dim() == 2 ? in.at(0).size(1) : 1});
    for (int64_t k = 0; k < count; ++k) {
      torch::Tensor cell = dense;
      const std::vector<int64_t> index = as_vector(indices[k]);
      for (std::size_t axis = 0; axis + 1 < index.size(); ++axis) cell = cell[index[axis]];
      cell[index.back()] = in.at(2).dim() == 0 ? in.at(2) : in.at(2)[k];
    }
    return {dense};
  }
  if (op == "Add" || op == "AddV2") return {in.at(0) + in.at(1)};
  if (op == "Sub") return {in.at(0) - in.at(1)};
  if (op == "Mul") return {in.at(0) * in.at(1)};
  if (op == "LeakyRelu") return {F::leaky_relu(in.at(0), F::LeakyReLUFuncOptions().negative_slope(node.numbers.at("alpha")))};
  if (op == "Relu") return {torch::relu(in.at(0))};
  if (op == "Sigmoid") return {torch::sigmoid(in.at(0))};
  if (op == "Conv2D") {
    const torch::Tensor& filter = in.at(1);  // HWIO
    const std::vector<int64_t>& strides = node.int_lists.at("strides");
    const std::vector<int64_t> dilations = node.int_lists.count("dilations") != 0 ? node.int_lists.at("dilations") : std::vector<int64_t>{1, 1, 1, 1};
    const torch::Tensor image = to_nchw_padded(in.at(0), node, filter.size(0), filter.size(1), 0.0);
    const int64_t groups = image.size(1) / filter.size(2);
    const torch::Tensor output = torch::conv2d(image, filter.permute({3, 2, 0, 1}).contiguous(), torch::Tensor(), at::IntArrayRef{strides[1], strides[2]},
                                               at::IntArrayRef{0, 0}, at::IntArrayRef{dilations[1], dilations[2]}, groups);
    return {output.permute({0, 2, 3, 1}).contiguous()};
  }
  if (op == "MaxPool") {
    const std::vector<int64_t>& kernel = node.int_lists.at("ksize");
    const std::vector<int64_t>& strides = node.int_lists.at("strides");
    const torch::Tensor image = to_nchw_padded(in.at(0), node, kernel[1], kernel[2], -std::numeric_limits<double>::infinity());
    return {torch::max_pool2d(image, {kernel[1], kernel[2]}, {strides[1], strides[2]}).permute({0, 2, 3, 1}).contiguous()};
  }
  if (op == "ResizeBilinear") {
    const std::vector<int64_t> size = as_vector(in.at(1));
    const bool align_corners = node.flags.count("align_corners") != 0 && node.flags.at("align_corners");
    const bool half_pixel = node.flags.count("half_pixel_centers") != 0 && node.flags.at("half_pixel_centers");
    if (!align_corners && !half_pixel) throw std::runtime_error("ResizeBilinear without half-pixel centres or aligned corners is not supported");
    const torch::Tensor nchw = in.at(0).permute({0, 3, 1, 2});
    const torch::Tensor output =
        F::interpolate(nchw, F::InterpolateFuncOptions().size(size).mode(torch::kBilinear).align_corners(align_corners));
    return {output.permute({0, 2, 3, 1}).contiguous()};
  }
  throw std::runtime_error("operation " + op + " is not supported");
}

std::pair<std::string, std::size_t> split_output(const std::string& name) {
  const std::size_t colon = name.rfind(':');
  if (colon == std::string::npos) return {name, 0};
  return {name.substr(0, colon), static_cast<std::size_t>(std::stoul(name.substr(colon + 1)))};
}

}  // namespace

Result<TfjsGraph> TfjsGraph::read(const std::string& path) {
  std::ifstream file(path);
  if (!file) return Error(fmt::format("{}: cannot open the model", path));
  Json json;
  try {
    json = Json::parse(file);
  } catch (const Json::exception& error) {
    return Error(fmt::format("{}: not JSON: {}", path, error.what()));
  }
  if (json.value("format", "") != "graph-model" || !json.contains("modelTopology") || !json.contains("weightsManifest")) {
    return Error(fmt::format("{}: not a TensorFlow.js graph model (format graph-model with modelTopology and weightsManifest)", path));
  }
  TfjsGraph graph;
  graph.path_ = path;
  const std::filesystem::path folder = std::filesystem::path(path).parent_path();
  try {
    for (const Json& group : json["weightsManifest"]) {
      std::string bytes;
      for (const Json& shard : group.at("paths")) {
        const std::filesystem::path shard_path = folder / shard.get<std::string>();
        std::ifstream shard_file(shard_path, std::ios::binary);
        if (!shard_file) return Error(fmt::format("{}: cannot open the weight shard {}", path, shard_path.string()));
        bytes.append(std::istreambuf_iterator<char>(shard_file), std::istreambuf_iterator<char>());
      }
      std::size_t offset = 0;
      for (const Json& weight : group.at("weights")) {
        std::size_t used = 0;
        Result<torch::Tensor> tensor = decode_weight(weight, bytes.data() + offset, bytes.size() - offset, used);
        if (!tensor) return Error(fmt::format("{}: {}", path, tensor.error().message));
        graph.constants_[weight.at("name").get<std::string>()] = std::move(tensor).value();
        offset += used;
      }
    }
    std::map<std::string, Node> pending;
    for (const Json& node_json : json["modelTopology"].at("node")) {
      Node node = parse_node(node_json);
      if (supported_operations().count(node.op) == 0) return Error(fmt::format("{}: node {}: operation {} is not supported", path, node.name, node.op));
      if (node.op == "Const" && graph.constants_.count(node.name) == 0) {
        return Error(fmt::format("{}: constant {} is not in the weights manifest", path, node.name));
      }
      if (node.op == "Placeholder") {
        std::vector<int64_t>& shape = graph.inputs_[node.name];
        const Json dimensions = node_json.at("attr").at("shape").at("shape").value("dim", Json::array());
        for (const Json& dimension : dimensions) shape.push_back(std::stoll(dimension.value("size", "-1")));
      }
      pending.emplace(node.name, std::move(node));
    }
    // Depth-first topological order.
    std::set<std::string> done;
    std::set<std::string> visiting;
    std::function<Status(const std::string&)> visit = [&](const std::string& name) -> Status {
      if (done.count(name) != 0) return {};
      const auto node = pending.find(name);
      if (node == pending.end()) return Error(fmt::format("{}: no node defines {}", path, name));
      if (!visiting.insert(name).second) return Error(fmt::format("{}: the graph has a cycle through {}", path, name));
      for (const std::string& input : node->second.inputs) HANZO_RETURN_IF_ERROR(visit(split_output(input).first));
      visiting.erase(name);
      done.insert(name);
      graph.nodes_.push_back(node->second);
      return {};
    };
    for (const auto& [name, node] : pending) HANZO_RETURN_IF_ERROR(visit(name));
  } catch (const std::exception& error) {
    return Error(fmt::format("{}: malformed graph model: {}", path, error.what()));
  }
  return graph;
}

Result<std::map<std::string, torch::Tensor>> TfjsGraph::run(const std::map<std::string, torch::Tensor>& inputs, const std::vector<std::string>& outputs) const {
  std::map<std::string, std::vector<torch::Tensor>> values;
  for (const auto& [name, shape] : inputs_) {
    const auto input = inputs.find(name);
    if (input == inputs.end()) return Error(fmt::format("{}: input {} not given", path_, name));
    if (input->second.dim() != static_cast<int64_t>(shape.size())) {
      return Error(fmt::format("{}: input {} has {} dimensions, the model takes {}", path_, name, input->second.dim(), shape.size()));
    }
    values[name] = {input->second};
  }
  const auto value_of = [&values](const std::string& reference) -> const torch::Tensor& {
    const auto [name, index] = split_output(reference);
    return values.at(name).at(index);
  };
  torch::NoGradGuard no_gradients;
  for (const Node& node : nodes_) {
    if (node.op == "Placeholder") continue;
    if (node.op == "Const") {
      values[node.name] = {constants_.at(node.name)};
      continue;
    }
    try {
      std::vector<torch::Tensor> operands;
      operands.reserve(node.inputs.size());
      for (const std::string& input : node.inputs) operands.push_back(value_of(input));
      values[node.name] = evaluate(node, operands);
    } catch (const std::exception& error) {
      std::string message = error.what();
      message = message.substr(0, message.find('\n'));
      return Error(fmt::format("{}: node {} ({}): {}", path_, node.name, node.op, message));
    }
  }
  std::map<std::string, torch::Tensor> results;
  for (const std::string& output : outputs) {
    const auto [name, index] = split_output(output);
    const auto value = values.find(name);
    if (value == values.end() || index >= value->second.size()) return Error(fmt::format("{}: the graph has no output {}", path_, output));
    results[output] = value->second[index];
  }
  return results;
}

}  // namespace hanzo::fusion::ai
