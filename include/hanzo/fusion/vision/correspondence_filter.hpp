#pragma once
// CorrespondenceFilter: a learned classifier of putative matches (inlier or outlier), the role of
// a learned matcher such as SuperGlue, whose weights are not licensed for this project. The
// network is the context-normalization network of Yi et al., "Learning to Find Good
// Correspondences", CVPR 2018 (sec. 3): every match passes through the same per-match layers;
// context normalization (each channel normalized over all matches of the image pair, eq. 4) is
// how a match sees the others' geometry. Here:
//   input (6 per match, correspondence_inputs()) -> linear (width)
//   -> blocks x [linear, context norm, batch norm, ReLU, linear, context norm, batch norm, ReLU, + input]
//   -> linear (1): the logit of the match being an inlier.
// Batch normalization is stored folded (per-channel scale and shift).
//
// Weights: this project's own, trained by models/trained/train_correspondence_filter.py on
// synthetic homographies of the simulator's camera images (`make train-correspondence-filter`),
// stored as JSON (models/trained/correspondence_filter.json; load_default() finds it through
// find_model_file()). Failure: a missing or malformed file, or one whose sizes disagree.

#include <memory>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "hanzo/fusion/core/result.hpp"
#include "hanzo/fusion/vision/feature_matcher.hpp"

namespace hanzo::fusion::vision {

/// The network's inputs of one match, as training sees them: both points centred on their
/// image and divided by half its larger side (about -1..1), the descriptor distance over its
/// kind's range (Hamming / 256, Euclidean of unit vectors / 2), and the ratio to the runner-up
/// (1 without one).
std::vector<float> correspondence_inputs(const FeatureMatch& match, const ImageFeatures& features1, const ImageFeatures& features2);
inline constexpr int kCorrespondenceInputs = 6;

class CorrespondenceFilter {
 public:
  static Result<CorrespondenceFilter> load(const std::string& path);
  /// The project's trained filter.
  static Result<CorrespondenceFilter> load_default();

  /// Inlier probabilities in (0, 1) of `matches` between `features1` and `features2`, in their
  /// order. Fewer than 2 matches: 0.5 each (no context).
  std::vector<float> inlier_probabilities(const std::vector<FeatureMatch>& matches, const ImageFeatures& features1,
                                          const ImageFeatures& features2) const;
  /// The matches whose probability is at least `threshold`, in their order.
  std::vector<FeatureMatch> filter(const std::vector<FeatureMatch>& matches, const ImageFeatures& features1, const ImageFeatures& features2,
                                   double threshold = 0.5) const;

 private:
  struct Layer {
    Eigen::MatrixXf weight;  // outputs x inputs
    Eigen::VectorXf bias;
  };
  struct Block {
    Layer first, second;
    Eigen::VectorXf scale1, shift1, scale2, shift2;  // folded batch norm after each context norm
  };
  Layer input_, output_;
  std::vector<Block> blocks_;
};

}  // namespace hanzo::fusion::vision
