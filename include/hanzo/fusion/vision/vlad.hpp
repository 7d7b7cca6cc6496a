#pragma once
// VladModel: a global image descriptor aggregated from learned local descriptors (VLAD, Jégou et
// al. CVPR 2010, as NetVLAD's aggregation layer, Arandjelović et al. CVPR 2016, with hard
// assignment), for place recognition across lighting and season changes.
//
//   describe: every local descriptor x (unit rows, CV_32FC1 of `descriptor_size` floats) is
//     assigned to its nearest cluster centre c_k and the residuals are summed per cluster,
//     v_k = sum (x - c_k) (paper eq. 1); each v_k is L2-normalized (intra-normalization,
//     Arandjelović and Zisserman CVPR 2013) and the K x D vector L2-normalized; then
//     y = P (v - mean), the PCA projection with whitening (Jégou and Chum ECCV 2012), and y is
//     L2-normalized. The similarity of two images is the dot product of their y (cosine, -1..1).
//   train: the centres by k-means++ (cv::kmeans) on the training images' descriptors; the mean
//     and projection by PCA of the training images' VLAD vectors, each direction divided by
//     sqrt(eigenvalue + the mean eigenvalue / 10) (whitening, regularized so the weakest
//     directions do not dominate).
//
// File format (little-endian): "HZVLAD\0\0", u32 version (1), u32 name length, the extractor's
// name (the descriptors the model was trained on, e.g. "aliked-t16"), u32 clusters K, u32
// descriptor_size D, u32 output dimensions P, u32 training images, then f32 centres (K x D),
// mean (K D), projection (P x K D, row-major); a u32 crc32 of everything before it ends the file.
// load() refuses another magic or version, sizes that do not add up, non-finite values, trailing
// bytes and a checksum mismatch, each named.

#include <cstdint>
#include <string>
#include <vector>

#include <Eigen/Core>
#include <opencv2/core.hpp>

#include "hanzo/fusion/core/result.hpp"
#include "hanzo/fusion/vision/place_database.hpp"

namespace hanzo::fusion::vision {

struct VladConfig {
  /// Cluster centres K (VLAD has K x descriptor_size dimensions before the projection).
  int clusters = 32;
  /// Dimensions of the projected descriptor (at most the training images - 1 and K x D).
  int dimensions = 128;
  /// k-means rounds and restarts; the seed makes training deterministic.
  int kmeans_iterations = 30;
  int kmeans_attempts = 2;
  /// Training descriptors are subsampled to at most this many for k-means.
  int max_kmeans_descriptors = 200000;
  uint64_t seed = 1;
};

Status validate(const VladConfig& config);

class VladModel {
 public:
  /// Trains on the descriptors of each image (CV_32FC1, one row per keypoint, all of one width)
  /// of the extractor `extractor_name`. Fails on a bad configuration, binary or mixed
  /// descriptors, fewer than `dimensions` + 1 images with descriptors or fewer descriptors than
  /// clusters.
  static Result<VladModel> train(const std::vector<cv::Mat>& image_descriptors, const std::string& extractor_name, const VladConfig& config = {});
  static Result<VladModel> load(const std::string& path);
  /// The project's trained model for `extractor_name`'s descriptors: `vlad_<name>.hzvlad`
  /// found by find_model_file() ($HANZO_FUSION_MODELS, the installed models, models/trained).
  static Result<VladModel> load_default(const std::string& extractor_name);
  Status save(const std::string& path) const;

  /// The unit global descriptor of an image's descriptors (CV_32FC1 rows of descriptor_size());
  /// fails on another type or width. No descriptors: the zero vector (similar to nothing).
  Result<Eigen::VectorXf> describe(const cv::Mat& descriptors) const;
  /// Cosine similarity of two global descriptors.
  static float similarity(const Eigen::VectorXf& a, const Eigen::VectorXf& b) { return a.dot(b); }

  const std::string& extractor_name() const { return extractor_name_; }
  int clusters() const { return static_cast<int>(centres_.rows()); }
  int descriptor_size() const { return static_cast<int>(centres_.cols()); }
  int dimensions() const { return static_cast<int>(projection_.rows()); }
  int training_images() const { return training_images_; }

 private:
  using RowMatrix = Eigen::Matrix<float, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;
  Eigen::VectorXf aggregate(const cv::Mat& descriptors) const;  // the normalized K x D VLAD vector

  std::string extractor_name_;
  RowMatrix centres_;     // K x D
  Eigen::VectorXf mean_;  // K D
  RowMatrix projection_;  // P x K D
  int training_images_ = 0;
};

/// The `count` entries of `vectors` (global descriptors, entry = index) among [0, before) most
/// similar to `query` with a similarity of at least min_score, best first.
std::vector<PlaceMatch> rank_places(const std::vector<Eigen::VectorXf>& vectors, const Eigen::VectorXf& query, int count, int before, double min_score);

}  // namespace hanzo::fusion::vision
