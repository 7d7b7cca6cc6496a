#include "hanzo/fusion/pipeline/feature_extractors.hpp"

#include <string>

#include <fmt/format.h>

#ifdef HANZO_FUSION_WITH_AI
#include "hanzo/fusion/ai/learned_features.hpp"
#endif

namespace hanzo::fusion::pipeline {

bool learned_features_available() {
#ifdef HANZO_FUSION_WITH_AI
  return true;
#else
  return false;
#endif
}

Result<std::shared_ptr<const vision::FeatureExtractor>> make_feature_extractor(const config::FeatureSelection& features, int max_features,
                                                                                const std::string& field, vision::OrbExtractorConfig orb) {
  HANZO_RETURN_IF_ERROR(config::validate(features, field));
  if (!features.learned()) {
    orb.max_features = max_features;
    HANZO_RETURN_IF_ERROR(with_context(vision::validate(orb), field));
    return std::shared_ptr<const vision::FeatureExtractor>(std::make_shared<const vision::OrbFeatureExtractor>(orb));
  }
#ifdef HANZO_FUSION_WITH_AI
  ai::LearnedFeatureConfig learned;
  learned.model = ai::learned_model_from_name(features.type).value();  // validate() checked the name
  learned.model_path = features.model;
  learned.max_keypoints = max_features;
  Result<std::unique_ptr<ai::LearnedFeatureExtractor>> extractor = ai::LearnedFeatureExtractor::load(learned);
  if (!extractor) return Error(fmt::format("{}: {}", field, extractor.error().message), field);
  return std::shared_ptr<const vision::FeatureExtractor>(std::move(extractor).value());
#else
  return Error(fmt::format("{}: {}: this build has no learned features (built without HANZO_FUSION_AI; install libtorch-dev)", field, features.type),
               field);
#endif
}

}  // namespace hanzo::fusion::pipeline
