#pragma once
// Vocabulary: a bag-of-binary-words vocabulary tree for ORB descriptors (Galvez-Lopez and
// Tardos 2012, "Bags of Binary Words for Fast Place Recognition in Image Sequences", the DBoW2
// scheme).
//
//   training: the descriptors of many images are clustered hierarchically: `branching` clusters
//     per node by k-majority (k-means++ seeding with Hamming distances, each centre the bitwise
//     majority of its members, paper section III), `levels` deep; the leaves are the words.
//     Each word is weighted by its inverse document frequency idf = ln(N / n_i) (N training
//     images, n_i of them containing the word; eq. 2);
//   transform: a descriptor descends the tree to the nearest child at every level (Hamming) and
//     lands on a word; an image becomes a bag-of-words vector v (word -> tf-idf weight, term
//     frequency = occurrences / features), normalized to unit L1 norm, and a feature vector
//     (the tree node `direct_index_levels_up` above the leaves -> the image's keypoints under it:
//     the direct index that restricts descriptor matching to features sharing a node);
//   score: s(v1, v2) = 1 - 0.5 | v1 - v2 |_1 in [0, 1] (eq. 3), 1 for the same bag of words.
//
// File format (little-endian): "HZVOCAB\0", u32 version (1), u32 branching, u32 levels,
// u32 node count, u32 training images, then per node (root first, parents before children):
// u32 parent index (the root: 0xffffffff), 32 descriptor bytes, f64 idf weight (leaves; 0
// for inner nodes); a u32 crc32 of everything before it ends the file. load() refuses another
// magic or version, counts that do not add up, a parent after its child, non-finite weights,
// trailing bytes and a checksum mismatch, each with a message naming what is wrong.

#include <cstdint>
#include <map>
#include <string>
#include <vector>

#include <opencv2/core.hpp>

#include "hanzo/fusion/core/result.hpp"

namespace hanzo::fusion::vision {

struct VocabularyConfig {
  /// Children per node and depth: 10^4 = 10,000 words at most, enough for the rooms, streets
  /// and halls of one session (DBoW2's ORB-SLAM vocabulary has 10^6 words for city scale).
  int branching = 10;
  int levels = 4;
  /// k-majority rounds per node (stops earlier when no descriptor changes cluster).
  int max_iterations = 10;
  /// Seed of the k-means++ seeding (training is deterministic for a seed).
  uint64_t seed = 1;
};

/// Checks every field; the error names the first field out of range.
Status validate(const VocabularyConfig& config);

/// Word id -> weight, sorted by word, unit L1 norm.
using BowVector = std::map<uint32_t, double>;
/// Node id -> keypoint indices (ascending) of the image under that node.
using FeatureVector = std::map<uint32_t, std::vector<int>>;

struct VocabularyTrainingSummary {
  int images = 0;
  int descriptors = 0;
  int words = 0;
  int iterations = 0;  ///< k-majority rounds over all nodes
};

class Vocabulary {
 public:
  /// Trains on the descriptors of each image (one cv::Mat per image, CV_8U rows of 32 bytes;
  /// empty images are skipped). Fails on another descriptor layout, an invalid configuration or
  /// fewer descriptors than `branching`.
  static Result<Vocabulary> train(const std::vector<cv::Mat>& image_descriptors, const VocabularyConfig& config = {},
                                  VocabularyTrainingSummary* summary = nullptr);
  /// Reads a vocabulary file (see the format above).
  static Result<Vocabulary> load(const std::string& path);
  /// The default vocabulary shipped with the project (models/orb_vocabulary.hzvoc, trained by
  /// `hanzo-fusion vision vocabulary`, see docs/vision.md), found by find_model_file():
  /// $HANZO_FUSION_MODELS, the installed share/hanzo-fusion/models folder, the source tree's models/.
  static Result<Vocabulary> load_default();
  /// Writes the file durably through a temporary name.
  Status save(const std::string& path) const;

  /// The word of one 32-byte descriptor; `node` (optional) receives its ancestor
  /// `levels_up` levels above the leaf (0: the word's own node).
  uint32_t word_of(const unsigned char* descriptor, int levels_up = 0, uint32_t* node = nullptr) const;
  /// The bag of words of an image's descriptors (CV_8U rows of 32 bytes) and, when
  /// `features` is given, its direct index at `direct_index_levels_up` above the leaves
  /// (clamped to the tree's depth). An empty descriptor matrix gives an empty vector.
  BowVector transform(const cv::Mat& descriptors, FeatureVector* features = nullptr, int direct_index_levels_up = 2) const;
  /// s(a, b) = 1 - 0.5 |a - b|_1 (both unit L1 norm): 1 for equal vectors, 0 for disjoint ones.
  static double score(const BowVector& a, const BowVector& b);

  int words() const { return static_cast<int>(words_.size()); }
  int branching() const { return branching_; }
  int levels() const { return levels_; }
  int training_images() const { return training_images_; }
  double idf(uint32_t word) const { return nodes_[words_.at(word)].weight; }

 private:
  struct Node {
    uint32_t parent = 0xffffffffu;
    std::vector<uint32_t> children;
    unsigned char descriptor[32] = {};
    double weight = 0.0;
    int32_t word = -1;  // leaves
  };
  Vocabulary() = default;
  void index_words();
  uint32_t leaf_of(const unsigned char* descriptor) const;

  int branching_ = 0;
  int levels_ = 0;
  int training_images_ = 0;
  std::vector<Node> nodes_;
  std::vector<uint32_t> words_;  // word id -> node index
};

}  // namespace hanzo::fusion::vision
