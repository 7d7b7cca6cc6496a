#pragma once
// PlaceDatabase: images (keyframes) as bag-of-words vectors of a Vocabulary with an inverted
// index (word -> the entries containing it and their weights), so that a query scores only the
// entries sharing a word with it (Galvez-Lopez and Tardos 2012, section IV). Each entry also
// keeps its feature vector (the direct index) for matching descriptors node by node.
//
// Scores are the vocabulary's L1 score s = 1 - 0.5 |a - b|_1, computed from the shared words
// alone: for unit-L1 vectors, |a - b|_1 = 2 - sum over shared words of (|a_i| + |b_i| - |a_i - b_i|).
// Use from one thread.

#include <cstdint>
#include <memory>
#include <vector>

#include "hanzo/fusion/vision/vocabulary.hpp"

namespace hanzo::fusion::vision {

struct PlaceMatch {
  int entry = -1;
  double score = 0.0;  ///< in [0, 1]
};

class PlaceDatabase {
 public:
  explicit PlaceDatabase(std::shared_ptr<const Vocabulary> vocabulary);

  /// Adds an image; returns its entry number (0, 1, ...).
  int add(BowVector bow, FeatureVector features = {});
  /// The `max_results` best entries by score (best first) among entries [0, before) (all when
  /// `before` is negative), leaving out entries that share no word or score under min_score.
  std::vector<PlaceMatch> query(const BowVector& bow, int max_results, int before = -1, double min_score = 0.0) const;

  int size() const { return static_cast<int>(entries_.size()); }
  const BowVector& bow(int entry) const { return entries_.at(static_cast<std::size_t>(entry)).bow; }
  const FeatureVector& features(int entry) const { return entries_.at(static_cast<std::size_t>(entry)).features; }
  const Vocabulary& vocabulary() const { return *vocabulary_; }

 private:
  struct Entry {
    BowVector bow;
    FeatureVector features;
  };
  struct Posting {
    int entry;
    double weight;
  };
  std::shared_ptr<const Vocabulary> vocabulary_;
  std::vector<Entry> entries_;
  std::vector<std::vector<Posting>> inverted_;  // word -> postings, ascending entry
};

}  // namespace hanzo::fusion::vision
