// The trained correspondence filter (models/trained/correspondence_filter.json): on pairs it was
// not trained on (the real graf images, graf1 from 40 degrees), the matches it keeps are more
// precise than the ratio test's and it keeps more of the correct ones; bad files are refused.
#include <unistd.h>

#include <filesystem>
#include <fstream>

#include <fmt/format.h>
#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "hanzo/fusion/vision/correspondence_filter.hpp"
#include "hanzo/fusion/vision/image_pair_matcher.hpp"
#include "vision/graf_pairs.hpp"

namespace hanzo::fusion::vision {
namespace {

using ::testing::HasSubstr;

struct Counts {
  int kept = 0, correct = 0;
};

// Matches among `matches` within 3 px of the true homography.
int correct_of(const std::vector<FeatureMatch>& matches, const ImageFeatures& features1, const ImageFeatures& features2, const cv::Matx33d& truth) {
  std::vector<PointMatch> points;
  for (const FeatureMatch& match : matches) {
    points.push_back({features1.keypoints[static_cast<std::size_t>(match.query)].pt, features2.keypoints[static_cast<std::size_t>(match.train)].pt,
                      match.distance, match.query, match.train});
  }
  return count_correct_matches(points, truth, 3.0);
}

TEST(CorrespondenceFilter, KeepsMoreCorrectMatchesMorePreciselyThanTheRatioTest) {
  auto filter = CorrespondenceFilter::load_default();
  ASSERT_TRUE(filter.ok()) << filter.error().message;
  for (const double degrees : {0.0, 40.0}) {
    SCOPED_TRACE(degrees);
    const testing::GrafPair pair = degrees == 0.0 ? testing::graf_pair() : testing::wide_baseline_pair(degrees);
    const OrbExtractor extractor;
    const ImageFeatures features1 = extractor.extract(pair.image1).value(), features2 = extractor.extract(pair.image2).value();
    DescriptorMatcherConfig mutual_only;
    mutual_only.ratio = 1.0;
    const std::vector<FeatureMatch> putative = match_descriptors(features1.descriptors, features2.descriptors, mutual_only);
    const std::vector<FeatureMatch> ratio = match_descriptors(features1.descriptors, features2.descriptors);  // 0.8
    const std::vector<FeatureMatch> learned = filter->filter(putative, features1, features2);
    const int all_correct = correct_of(putative, features1, features2, pair.homography);
    const int ratio_correct = correct_of(ratio, features1, features2, pair.homography);
    const int learned_correct = correct_of(learned, features1, features2, pair.homography);
    const double ratio_precision = static_cast<double>(ratio_correct) / static_cast<double>(std::max<std::size_t>(ratio.size(), 1));
    const double learned_precision = static_cast<double>(learned_correct) / static_cast<double>(std::max<std::size_t>(learned.size(), 1));
    std::printf("%s: %zu mutual matches, %d correct; ratio test keeps %zu (precision %.3f, recall %.3f), the filter %zu (precision %.3f, recall %.3f)\n",
                degrees == 0.0 ? "graf1-graf2" : "40 degrees", putative.size(), all_correct, ratio.size(), ratio_precision,
                static_cast<double>(ratio_correct) / all_correct, learned.size(), learned_precision, static_cast<double>(learned_correct) / all_correct);
    EXPECT_GT(learned_correct, ratio_correct);
    EXPECT_GE(learned_precision, ratio_precision);
  }
}

TEST(CorrespondenceFilter, RefusesFilesThatAreNotItsWeights) {
  const std::filesystem::path dir = std::filesystem::temp_directory_path() / fmt::format("hanzo_filter_{}", ::getpid());
  std::filesystem::create_directories(dir);
  EXPECT_THAT(CorrespondenceFilter::load((dir / "missing.json").string()).error().message, HasSubstr("cannot open"));
  std::ofstream(dir / "text.json") << "not json";
  EXPECT_THAT(CorrespondenceFilter::load((dir / "text.json").string()).error().message, HasSubstr("not JSON"));
  std::ofstream(dir / "other.json") << R"({"architecture": "mlp"})";
  EXPECT_THAT(CorrespondenceFilter::load((dir / "other.json").string()).error().message, HasSubstr("not a correspondence filter"));
  std::ofstream(dir / "short.json") << R"({"architecture": "cn-net", "width": 4, "blocks": 0, "layers": {"input.weight": [1, 2], "input.bias": [0, 0, 0, 0]}})";
  EXPECT_THAT(CorrespondenceFilter::load((dir / "short.json").string()).error().message, HasSubstr("'input.weight' holds 2 values, expected 4 x 6"));
  std::filesystem::remove_all(dir);
}

}  // namespace
}  // namespace hanzo::fusion::vision
