#include "hanzo/fusion/ai/learned_features.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <thread>

#include <ATen/Parallel.h>
#include <c10/core/InferenceMode.h>
#include <fmt/format.h>
#include <opencv2/imgproc.hpp>

#include "hanzo/fusion/core/files.hpp"
#include "learned_network.hpp"

namespace hanzo::fusion::ai {
namespace {

constexpr std::array<std::pair<LearnedModel, std::string_view>, 8> kNames = {{{LearnedModel::kAlikedT16, "aliked-t16"},
                                                                             {LearnedModel::kAlikedN16, "aliked-n16"},
                                                                             {LearnedModel::kAlikedN16Rot, "aliked-n16rot"},
                                                                             {LearnedModel::kAlikedN32, "aliked-n32"},
                                                                             {LearnedModel::kAlikeT, "alike-t"},
                                                                             {LearnedModel::kAlikeS, "alike-s"},
                                                                             {LearnedModel::kAlikeN, "alike-n"},
                                                                             {LearnedModel::kAlikeL, "alike-l"}}};

bool is_aliked(LearnedModel model) {
  return model == LearnedModel::kAlikedT16 || model == LearnedModel::kAlikedN16 || model == LearnedModel::kAlikedN16Rot ||
         model == LearnedModel::kAlikedN32;
}

}  // namespace

std::string_view to_string(LearnedModel model) {
  for (const auto& [value, name] : kNames) {
    if (value == model) return name;
  }
  return "unknown";
}

std::optional<LearnedModel> learned_model_from_name(std::string_view name) {
  for (const auto& [value, model_name] : kNames) {
    if (model_name == name) return value;
  }
  return std::nullopt;
}

const std::vector<LearnedModel>& all_learned_models() {
  static const std::vector<LearnedModel> kAll = [] {
    std::vector<LearnedModel> all;
    for (const auto& [value, name] : kNames) all.push_back(value);
    return all;
  }();
  return kAll;
}

Result<std::string> find_learned_model(LearnedModel model, const std::string& path) {
  if (!path.empty()) {
    if (!std::filesystem::is_regular_file(path)) return Error(fmt::format("{}: no such model file ({})", path, to_string(model)));
    return path;
  }
  const std::string file = std::string(to_string(model)) + ".pth";
  Result<std::string> found = find_model_file(file, "", "");
  if (!found) {
    return Error(fmt::format("{}: give the {} weights' path (the `model` key, --model) or put {} in ${}", found.error().message, to_string(model),
                             file, kModelsEnvironment));
  }
  return found;
}

Status validate(const LearnedFeatureConfig& config) {
  if (config.max_keypoints < 1) return Error(fmt::format("max_keypoints: {} (expected >= 1)", config.max_keypoints), "max_keypoints");
  if (config.nms_radius < 1 || config.nms_radius > 8) return Error(fmt::format("nms_radius: {} (expected 1..8)", config.nms_radius), "nms_radius");
  if (!(config.score_threshold < 1.0F)) return Error(fmt::format("score_threshold: {} (expected < 1)", config.score_threshold), "score_threshold");
  if (config.threads < 0) return Error(fmt::format("threads: {} (expected >= 0)", config.threads), "threads");
  return ok_status();
}

LearnedFeatureExtractor::LearnedFeatureExtractor(LearnedFeatureConfig config, std::string model_path, std::unique_ptr<Network> network)
    : config_(std::move(config)), model_path_(std::move(model_path)), network_(std::move(network)) {}

LearnedFeatureExtractor::~LearnedFeatureExtractor() = default;

Result<std::unique_ptr<LearnedFeatureExtractor>> LearnedFeatureExtractor::load(const LearnedFeatureConfig& config) {
  HANZO_RETURN_IF_ERROR(validate(config));
  std::string path;
  HANZO_ASSIGN_OR_RETURN(path, find_learned_model(config.model, config.model_path));
  StateDict state;
  HANZO_ASSIGN_OR_RETURN(state, read_state_dict(path));
  std::unique_ptr<Network> network;
  HANZO_ASSIGN_OR_RETURN(network, is_aliked(config.model) ? make_aliked_network(config.model, state, path)
                                                          : make_alike_network(config.model, state, path));
  at::set_num_threads(config.threads > 0 ? config.threads : static_cast<int>(std::max(1U, std::thread::hardware_concurrency())));
  return std::unique_ptr<LearnedFeatureExtractor>(new LearnedFeatureExtractor(config, std::move(path), std::move(network)));
}

int LearnedFeatureExtractor::descriptor_size() const { return network_->descriptor_size(); }

Result<vision::ImageFeatures> LearnedFeatureExtractor::extract(const cv::Mat& image, const cv::Mat& mask) const {
  LearnedFeatureMaps maps;
  HANZO_ASSIGN_OR_RETURN(maps, extract_with_maps(image, mask));
  return std::move(maps.features);
}

Result<LearnedFeatureMaps> LearnedFeatureExtractor::extract_with_maps(const cv::Mat& image, const cv::Mat& mask) const {
  if (image.empty()) return Error("empty image");
  if (image.depth() != CV_8U || (image.channels() != 1 && image.channels() != 3 && image.channels() != 4)) {
    return Error("expected an 8-bit grey, BGR or BGRA image");
  }
  if (image.cols < 64 || image.rows < 64) return Error(fmt::format("{} x {} pixels: the networks need at least 64 x 64", image.cols, image.rows));
  if (!mask.empty() && (mask.size() != image.size() || mask.type() != CV_8UC1)) return Error("mask: expected CV_8UC1 of the image's size");
  cv::Mat rgb;
  if (image.channels() == 1) cv::cvtColor(image, rgb, cv::COLOR_GRAY2RGB);
  else if (image.channels() == 3) cv::cvtColor(image, rgb, cv::COLOR_BGR2RGB);
  else cv::cvtColor(image, rgb, cv::COLOR_BGRA2RGB);
  cv::Mat scaled;
  rgb.convertTo(scaled, CV_32FC3, 1.0 / 255.0);

  c10::InferenceMode inference;
  const at::Tensor input = at::from_blob(scaled.data, {1, scaled.rows, scaled.cols, 3}, at::kFloat).permute({0, 3, 1, 2}).contiguous();
  const DenseMaps maps = network_->dense(input);
  auto [keypoints, scores] = detect_keypoints(maps.score_map, config_);
  if (!mask.empty() && keypoints.size(0) > 0) {  // keep the keypoints on non-zero mask pixels
    const float scale_x = static_cast<float>(image.cols - 1) / 2.0F, scale_y = static_cast<float>(image.rows - 1) / 2.0F;
    std::vector<int64_t> kept;
    const auto points = keypoints.accessor<float, 2>();
    for (int64_t i = 0; i < keypoints.size(0); ++i) {
      const int u = static_cast<int>(std::lround((points[i][0] + 1.0F) * scale_x)), v = static_cast<int>(std::lround((points[i][1] + 1.0F) * scale_y));
      if (mask.at<uint8_t>(std::clamp(v, 0, image.rows - 1), std::clamp(u, 0, image.cols - 1)) != 0) kept.push_back(i);
    }
    const at::Tensor index = at::tensor(kept, at::kLong);
    keypoints = keypoints.index_select(0, index);
    scores = scores.index_select(0, index);
  }
  const at::Tensor descriptors = network_->describe(maps, keypoints, config_.subpixel).contiguous();

  LearnedFeatureMaps out;
  out.score_map = cv::Mat(image.rows, image.cols, CV_32FC1);
  std::memcpy(out.score_map.data, maps.score_map.contiguous().data_ptr<float>(), sizeof(float) * static_cast<std::size_t>(image.rows * image.cols));
  vision::ImageFeatures& features = out.features;
  features.image_size = image.size();
  const int64_t count = keypoints.size(0);
  const auto points = keypoints.accessor<float, 2>();
  const auto score = scores.accessor<float, 1>();
  const float size = static_cast<float>(2 * config_.nms_radius + 1);
  for (int64_t i = 0; i < count; ++i) {
    const float u = (points[i][0] + 1.0F) / 2.0F * static_cast<float>(image.cols - 1);
    const float v = (points[i][1] + 1.0F) / 2.0F * static_cast<float>(image.rows - 1);
    features.keypoints.emplace_back(cv::Point2f(u, v), size, -1.0F, score[i], 0);
  }
  features.descriptors = cv::Mat(static_cast<int>(count), network_->descriptor_size(), CV_32FC1);
  if (count > 0) std::memcpy(features.descriptors.data, descriptors.data_ptr<float>(), sizeof(float) * static_cast<std::size_t>(descriptors.numel()));
  return out;
}

}  // namespace hanzo::fusion::ai
