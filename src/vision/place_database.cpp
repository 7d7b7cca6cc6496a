#include "hanzo/fusion/vision/place_database.hpp"

#include <algorithm>
#include <cmath>

namespace hanzo::fusion::vision {

PlaceDatabase::PlaceDatabase(std::shared_ptr<const Vocabulary> vocabulary)
    : vocabulary_(std::move(vocabulary)), inverted_(static_cast<std::size_t>(vocabulary_->words())) {}

int PlaceDatabase::add(BowVector bow, FeatureVector features) {
  const int entry = size();
  for (const auto& [word, weight] : bow) {
    if (word < inverted_.size()) inverted_[word].push_back({entry, weight});
  }
  entries_.push_back({std::move(bow), std::move(features)});
  return entry;
}

std::vector<PlaceMatch> PlaceDatabase::query(const BowVector& bow, int max_results, int before, double min_score) const {
  const int limit = before < 0 ? size() : std::min(before, size());
  std::vector<double> shared(static_cast<std::size_t>(limit), 0.0);
  std::vector<char> touched(static_cast<std::size_t>(limit), 0);
  for (const auto& [word, weight] : bow) {
    if (word >= inverted_.size()) continue;
    for (const Posting& posting : inverted_[word]) {
      if (posting.entry >= limit) break;  // postings ascend by entry
      shared[static_cast<std::size_t>(posting.entry)] += std::abs(weight) + std::abs(posting.weight) - std::abs(weight - posting.weight);
      touched[static_cast<std::size_t>(posting.entry)] = 1;
    }
  }
  std::vector<PlaceMatch> matches;
  for (int entry = 0; entry < limit; ++entry) {
    if (!touched[static_cast<std::size_t>(entry)]) continue;
    const double score = std::clamp(0.5 * shared[static_cast<std::size_t>(entry)], 0.0, 1.0);
    if (score >= min_score) matches.push_back({entry, score});
  }
  const auto keep = std::min<std::size_t>(matches.size(), static_cast<std::size_t>(std::max(max_results, 0)));
  std::partial_sort(matches.begin(), matches.begin() + static_cast<std::ptrdiff_t>(keep), matches.end(),
                    [](const PlaceMatch& a, const PlaceMatch& b) { return a.score > b.score || (a.score == b.score && a.entry < b.entry); });
  matches.resize(keep);
  return matches;
}

}  // namespace hanzo::fusion::vision
