#pragma once
// The visual frontends' keypoint detector and descriptor from the configuration
// (config::FeatureSelection): ORB, or a learned model of the AI module (ai::LearnedFeatureExtractor,
// built with HANZO_FUSION_AI). The one place the pipeline and the command line turn a feature
// type's name into an extractor.
//
// Failure: an unknown type, a model path given to ORB, a learned type in a build without the AI
// module (the error names the CMake option and the package), or a learned model whose weights
// cannot be found or read (the error names the path or the folders looked in). `field` (the
// configuration key or command-line option) prefixes every error.

#include <memory>
#include <string>

#include "hanzo/fusion/config/fusion_config.hpp"
#include "hanzo/fusion/core/result.hpp"
#include "hanzo/fusion/vision/feature_extractor.hpp"

namespace hanzo::fusion::pipeline {

/// Whether this build has the learned feature extractors.
bool learned_features_available();

/// ORB with at most `max_features` keypoints (its other settings as `orb`), or the learned model
/// with at most `max_features` keypoints (its other settings the model's defaults).
Result<std::shared_ptr<const vision::FeatureExtractor>> make_feature_extractor(const config::FeatureSelection& features, int max_features,
                                                                                const std::string& field,
                                                                                vision::OrbExtractorConfig orb = {});

}  // namespace hanzo::fusion::pipeline
