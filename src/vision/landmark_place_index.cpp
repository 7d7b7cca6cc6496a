#include "hanzo/fusion/vision/landmark_place_index.hpp"

#include <algorithm>

#include <fmt/format.h>
#include <spdlog/spdlog.h>

#include "hanzo/fusion/vision/feature_matcher.hpp"

namespace hanzo::fusion::vision {

namespace {
// Learned descriptors matched for the "matches" ranking (as the relocalizer's candidates).
constexpr double kMaxFloatDistance = 1.0;
constexpr double kFloatRatio = 0.9;
}  // namespace

Result<cv::Mat> landmark_descriptors(const msgs::VisualLandmarkLayer& map) {
  const auto count = static_cast<int>(map.positions.size());
  if (map.descriptor_type == "orb") {
    if (map.descriptors.size() != map.positions.size()) {
      return Error(fmt::format("visual landmark map: {} descriptors for {} landmarks", map.descriptors.size(), map.positions.size()));
    }
    cv::Mat rows(count, 32, CV_8UC1);
    for (std::size_t i = 0; i < map.descriptors.size(); ++i) std::copy(map.descriptors[i].begin(), map.descriptors[i].end(), rows.ptr<uint8_t>(static_cast<int>(i)));
    return rows;
  }
  if (map.float_descriptor_size == 0 || map.float_descriptors.size() != map.float_descriptor_size * map.positions.size()) {
    return Error(fmt::format("visual landmark map: {} float descriptors of {} for {} landmarks", map.float_descriptors.size(), map.float_descriptor_size,
                             map.positions.size()));
  }
  cv::Mat rows(count, static_cast<int>(map.float_descriptor_size), CV_32FC1);
  if (count > 0) std::copy(map.float_descriptors.begin(), map.float_descriptors.end(), rows.ptr<float>(0));
  return rows;
}

Result<LandmarkPlaceIndex> LandmarkPlaceIndex::create(const msgs::VisualLandmarkLayer& map, const LandmarkPlaceIndexConfig& config) {
  LandmarkPlaceIndex index;
  HANZO_ASSIGN_OR_RETURN(index.descriptors_, landmark_descriptors(map));
  for (const msgs::VisualKeyframe& keyframe : map.keyframes) {
    for (uint32_t landmark : keyframe.landmarks) {
      if (landmark >= map.positions.size()) return Error(fmt::format("visual landmark map: a keyframe sees landmark {} of {}", landmark, map.positions.size()));
    }
    index.keyframe_landmarks_.push_back(keyframe.landmarks);
  }
  if (map.descriptor_type == "orb") {
    index.method_ = "bow";
    index.vocabulary_ = config.vocabulary;
    if (!index.vocabulary_) {
      Result<Vocabulary> loaded = Vocabulary::load_default();
      if (!loaded) return loaded.error();
      index.vocabulary_ = std::make_shared<const Vocabulary>(std::move(*loaded));
    }
    for (std::size_t k = 0; k < map.keyframes.size(); ++k) index.keyframe_words_.push_back(index.vocabulary_->transform(index.keyframe_descriptors(k)));
    return index;
  }
  index.place_model_ = config.learned_place_recognition ? config.place_model : nullptr;
  if (!index.place_model_ && config.learned_place_recognition) {
    if (Result<VladModel> loaded = VladModel::load_default(map.descriptor_type)) {
      index.place_model_ = std::make_shared<const VladModel>(std::move(*loaded));
    } else {
      spdlog::info("place recognition: no VLAD model for {} ({}); keyframes ranked by matched landmarks", map.descriptor_type, loaded.error().message);
    }
  }
  if (index.place_model_ && index.place_model_->extractor_name() != map.descriptor_type) {
    return Error(fmt::format("place model: trained on {} descriptors, the map's are {}", index.place_model_->extractor_name(), map.descriptor_type));
  }
  index.method_ = index.place_model_ ? "learned" : "matches";
  if (index.place_model_) {
    for (std::size_t k = 0; k < map.keyframes.size(); ++k) {
      Result<Eigen::VectorXf> described = index.place_model_->describe(index.keyframe_descriptors(k));
      if (!described) return Error("visual landmark map: " + described.error().message);
      index.keyframe_vlad_.push_back(std::move(*described));
    }
  }
  return index;
}

cv::Mat LandmarkPlaceIndex::keyframe_descriptors(std::size_t keyframe) const {
  cv::Mat seen;
  for (uint32_t landmark : keyframe_landmarks_.at(keyframe)) seen.push_back(descriptors_.row(static_cast<int>(landmark)));
  return seen;
}

std::vector<PlaceCandidate> LandmarkPlaceIndex::rank(const cv::Mat& descriptors, int count) const {
  std::vector<PlaceCandidate> ranked;
  if (descriptors.empty()) return ranked;
  if (method_ == "bow") {
    const BowVector words = vocabulary_->transform(descriptors);
    for (std::size_t k = 0; k < keyframe_words_.size(); ++k) ranked.push_back({Vocabulary::score(words, keyframe_words_[k]), static_cast<int>(k)});
  } else if (method_ == "learned") {
    const Result<Eigen::VectorXf> query = place_model_->describe(descriptors);
    if (!query) return {};
    for (std::size_t k = 0; k < keyframe_vlad_.size(); ++k) ranked.push_back({VladModel::similarity(*query, keyframe_vlad_[k]), static_cast<int>(k)});
  } else {
    DescriptorMatcherConfig matcher;
    matcher.float_ratio = kFloatRatio;
    matcher.max_float_distance = kMaxFloatDistance;
    std::vector<char> matched(static_cast<std::size_t>(descriptors_.rows), 0);
    for (const FeatureMatch& match : match_descriptors(descriptors_, descriptors, matcher)) matched[static_cast<std::size_t>(match.query)] = 1;
    for (std::size_t k = 0; k < keyframe_landmarks_.size(); ++k) {
      const std::vector<uint32_t>& seen = keyframe_landmarks_[k];
      const auto hits = std::count_if(seen.begin(), seen.end(), [&](uint32_t landmark) { return matched[landmark] != 0; });
      ranked.push_back({seen.empty() ? 0.0 : static_cast<double>(hits) / static_cast<double>(seen.size()), static_cast<int>(k)});
    }
  }
  std::stable_sort(ranked.begin(), ranked.end(), [](const PlaceCandidate& a, const PlaceCandidate& b) { return a.score > b.score; });
  ranked.resize(std::min<std::size_t>(ranked.size(), static_cast<std::size_t>(std::max(0, count))));
  return ranked;
}

}  // namespace hanzo::fusion::vision
