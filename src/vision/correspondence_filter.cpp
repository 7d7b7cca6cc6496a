#include "hanzo/fusion/vision/correspondence_filter.hpp"

#include <algorithm>
#include <cmath>
#include <fstream>

#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include "hanzo/fusion/core/files.hpp"

namespace hanzo::fusion::vision {
namespace {

constexpr float kContextEpsilon = 1e-3F;  // Yi et al.'s context normalization

float centred(float value, int extent, int larger_side) {
  return (value - 0.5F * static_cast<float>(extent - 1)) / (0.5F * static_cast<float>(larger_side));
}

Result<Eigen::MatrixXf> matrix(const nlohmann::json& json, const std::string& name, Eigen::Index rows, Eigen::Index columns) {
  if (!json.contains(name) || !json[name].is_array()) return Error(fmt::format("'{}' is missing", name));
  const nlohmann::json& values = json[name];
  if (static_cast<Eigen::Index>(values.size()) != rows * columns) {
    return Error(fmt::format("'{}' holds {} values, expected {} x {}", name, values.size(), rows, columns));
  }
  Eigen::MatrixXf out(rows, columns);
  for (Eigen::Index r = 0; r < rows; ++r) {
    for (Eigen::Index c = 0; c < columns; ++c) {
      const nlohmann::json& value = values[static_cast<std::size_t>(r * columns + c)];
      if (!value.is_number()) return Error(fmt::format("'{}' holds a value that is not a number", name));
      out(r, c) = value.get<float>();
    }
  }
  return out;
}

// Each row (channel) normalized over the columns (matches).
void context_normalize(Eigen::MatrixXf& x) {
  const Eigen::VectorXf mean = x.rowwise().mean();
  x.colwise() -= mean;
  const Eigen::VectorXf deviation = ((x.array().square().rowwise().mean()) + kContextEpsilon).sqrt();
  x.array().colwise() /= deviation.array();
}

}  // namespace

std::vector<float> correspondence_inputs(const FeatureMatch& match, const ImageFeatures& features1, const ImageFeatures& features2) {
  const cv::Point2f& p1 = features1.keypoints[static_cast<std::size_t>(match.query)].pt;
  const cv::Point2f& p2 = features2.keypoints[static_cast<std::size_t>(match.train)].pt;
  const cv::Size s1 = features1.image_size, s2 = features2.image_size;
  const int side1 = std::max({s1.width, s1.height, 1}), side2 = std::max({s2.width, s2.height, 1});
  const bool binary = features1.descriptors.type() == CV_8UC1;
  const float range = binary ? 256.0F : static_cast<float>(2.0 * kFloatDistanceScale);
  const float ratio = match.second_distance > 0 ? static_cast<float>(match.distance) / static_cast<float>(match.second_distance) : 1.0F;
  return {centred(p1.x, s1.width, side1), centred(p1.y, s1.height, side1), centred(p2.x, s2.width, side2), centred(p2.y, s2.height, side2),
          static_cast<float>(match.distance) / range, std::min(ratio, 1.0F)};
}

Result<CorrespondenceFilter> CorrespondenceFilter::load(const std::string& path) {
  std::ifstream in(path);
  if (!in) return Error(fmt::format("{}: cannot open the correspondence filter", path));
  nlohmann::json json;
  try {
    in >> json;
  } catch (const nlohmann::json::exception& error) {
    return Error(fmt::format("{}: not JSON ({})", path, error.what()));
  }
  auto context = [&](const Error& error) { return Error(fmt::format("{}: {}", path, error.message)); };
  if (json.value("architecture", "") != "cn-net" || !json.contains("width") || !json.contains("blocks")) {
    return Error(fmt::format("{}: not a correspondence filter (architecture cn-net with width and blocks)", path));
  }
  const Eigen::Index width = json["width"].get<int>();
  const nlohmann::json& layers = json["layers"];
  CorrespondenceFilter filter;
  auto layer = [&](const std::string& prefix, Eigen::Index outputs, Eigen::Index inputs) -> Result<Layer> {
    Layer out;
    HANZO_ASSIGN_OR_RETURN(out.weight, matrix(layers, prefix + ".weight", outputs, inputs));
    Eigen::MatrixXf bias;
    HANZO_ASSIGN_OR_RETURN(bias, matrix(layers, prefix + ".bias", outputs, 1));
    out.bias = bias.col(0);
    return out;
  };
  auto vector = [&](const std::string& name) -> Result<Eigen::VectorXf> {
    Eigen::MatrixXf values;
    HANZO_ASSIGN_OR_RETURN(values, matrix(layers, name, width, 1));
    return Eigen::VectorXf(values.col(0));
  };
  Result<Layer> input = layer("input", width, kCorrespondenceInputs);
  if (!input) return context(input.error());
  filter.input_ = std::move(input).value();
  for (int b = 0; b < json["blocks"].get<int>(); ++b) {
    Block block;
    const std::string name = fmt::format("block{}", b);
    Result<Layer> first = layer(name + ".first", width, width), second = layer(name + ".second", width, width);
    if (!first) return context(first.error());
    if (!second) return context(second.error());
    block.first = std::move(first).value();
    block.second = std::move(second).value();
    for (auto [target, part] : {std::pair{&block.scale1, ".scale1"}, {&block.shift1, ".shift1"}, {&block.scale2, ".scale2"}, {&block.shift2, ".shift2"}}) {
      Result<Eigen::VectorXf> values = vector(name + part);
      if (!values) return context(values.error());
      *target = std::move(values).value();
    }
    filter.blocks_.push_back(std::move(block));
  }
  Result<Layer> output = layer("output", 1, width);
  if (!output) return context(output.error());
  filter.output_ = std::move(output).value();
  return filter;
}

Result<CorrespondenceFilter> CorrespondenceFilter::load_default() {
  const Result<std::string> path = find_model_file("correspondence_filter.json", HANZO_INSTALLED_MODELS_DIR, HANZO_SOURCE_MODELS_DIR "/trained");
  if (!path) return Error(fmt::format("the trained correspondence filter: {}", path.error().message));
  return load(*path);
}

std::vector<float> CorrespondenceFilter::inlier_probabilities(const std::vector<FeatureMatch>& matches, const ImageFeatures& features1,
                                                              const ImageFeatures& features2) const {
  const auto count = static_cast<Eigen::Index>(matches.size());
  if (count < 2) return std::vector<float>(matches.size(), 0.5F);
  Eigen::MatrixXf inputs(kCorrespondenceInputs, count);
  for (Eigen::Index i = 0; i < count; ++i) {
    const std::vector<float> values = correspondence_inputs(matches[static_cast<std::size_t>(i)], features1, features2);
    for (int k = 0; k < kCorrespondenceInputs; ++k) inputs(k, i) = values[static_cast<std::size_t>(k)];
  }
  Eigen::MatrixXf x = (input_.weight * inputs).colwise() + input_.bias;
  for (const Block& block : blocks_) {
    Eigen::MatrixXf y = (block.first.weight * x).colwise() + block.first.bias;
    context_normalize(y);
    y = ((y.array().colwise() * block.scale1.array()).colwise() + block.shift1.array()).max(0.0F).matrix();
    y = (block.second.weight * y).colwise() + block.second.bias;
    context_normalize(y);
    y = ((y.array().colwise() * block.scale2.array()).colwise() + block.shift2.array()).max(0.0F).matrix();
    x += y;
  }
  const Eigen::RowVectorXf logits = (output_.weight * x).array() + output_.bias(0);
  std::vector<float> probabilities(matches.size());
  for (Eigen::Index i = 0; i < count; ++i) probabilities[static_cast<std::size_t>(i)] = 1.0F / (1.0F + std::exp(-logits(i)));
  return probabilities;
}

std::vector<FeatureMatch> CorrespondenceFilter::filter(const std::vector<FeatureMatch>& matches, const ImageFeatures& features1,
                                                       const ImageFeatures& features2, double threshold) const {
  const std::vector<float> probabilities = inlier_probabilities(matches, features1, features2);
  std::vector<FeatureMatch> kept;
  for (std::size_t i = 0; i < matches.size(); ++i) {
    if (probabilities[i] >= threshold) kept.push_back(matches[i]);
  }
  return kept;
}

}  // namespace hanzo::fusion::vision
