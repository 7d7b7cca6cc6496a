// Bag-of-words vocabulary and place database (vision/vocabulary.hpp, vision/place_database.hpp):
// file round trips and refusals, and place recognition on real street images the vocabulary
// was not trained on.

#include <filesystem>
#include <fstream>
#include <string>

#include <gtest/gtest.h>
#include <opencv2/imgcodecs.hpp>

#include "hanzo/fusion/core/files.hpp"
#include "hanzo/fusion/vision/orb_extractor.hpp"
#include "hanzo/fusion/vision/place_database.hpp"
#include "hanzo/fusion/vision/vocabulary.hpp"

namespace hanzo::fusion::vision {
namespace {

const std::string kData = HANZO_DATA_DIR;

std::vector<std::string> images_in(const std::string& folder, int step) {
  std::vector<std::string> paths;
  for (const auto& entry : std::filesystem::directory_iterator(folder)) {
    if (entry.path().extension() == ".png") paths.push_back(entry.path().string());
  }
  std::sort(paths.begin(), paths.end());
  std::vector<std::string> kept;
  for (std::size_t i = 0; i < paths.size(); i += static_cast<std::size_t>(step)) kept.push_back(paths[i]);
  return kept;
}

cv::Mat descriptors_of(const std::string& path) {
  const cv::Mat image = cv::imread(path, cv::IMREAD_GRAYSCALE);
  EXPECT_FALSE(image.empty()) << path;
  return OrbExtractor().extract(image).value().descriptors;
}

// A vocabulary from the EuRoC room, the KITTI raw street and the calibration boards: the
// KITTI odometry 06 images below are not among them.
const Vocabulary& training_vocabulary() {
  static const Vocabulary vocabulary = [] {
    std::vector<cv::Mat> descriptors;
    for (const std::string& folder : {kData + "/euroc_v101_micro/mav0/cam0/data", kData + "/kitti_raw_0052/image_02", kData + "/camera_calib_opencv_stereo"}) {
      for (const std::string& path : images_in(folder, 4)) descriptors.push_back(descriptors_of(path));
    }
    return Vocabulary::train(descriptors).value();
  }();
  return vocabulary;
}

std::string temporary_path(const std::string& name) { return (std::filesystem::temp_directory_path() / ("hanzo_vocabulary_test_" + name)).string(); }

TEST(Vocabulary, TrainsATreeAndRoundTripsThroughItsFileExactly) {
  const Vocabulary& vocabulary = training_vocabulary();
  EXPECT_GT(vocabulary.words(), 5000);
  EXPECT_LE(vocabulary.words(), 10000);
  const std::string path = temporary_path("round_trip.hzvoc");
  ASSERT_TRUE(vocabulary.save(path));
  const Vocabulary loaded = Vocabulary::load(path).value();
  EXPECT_EQ(loaded.words(), vocabulary.words());
  EXPECT_EQ(loaded.training_images(), vocabulary.training_images());
  const cv::Mat descriptors = descriptors_of(kData + "/kitti_odometry_06_first51/image_l/000000.png");
  FeatureVector features, loaded_features;
  const BowVector bow = vocabulary.transform(descriptors, &features);
  EXPECT_EQ(loaded.transform(descriptors, &loaded_features), bow);
  EXPECT_EQ(loaded_features, features);
  double norm = 0.0;
  for (const auto& entry : bow) norm += entry.second;
  EXPECT_NEAR(norm, 1.0, 1e-9);
  EXPECT_DOUBLE_EQ(Vocabulary::score(bow, bow), 1.0);
  uint32_t unused_word = 0;
  while (bow.count(unused_word)) ++unused_word;
  EXPECT_NEAR(Vocabulary::score(bow, BowVector{{unused_word, 1.0}}), 0.0, 1e-12);
  std::size_t indexed = 0;
  for (const auto& entry : features) indexed += entry.second.size();
  EXPECT_EQ(indexed, static_cast<std::size_t>(descriptors.rows));
  std::filesystem::remove(path);
}

TEST(Vocabulary, RefusesCorruptedTruncatedAndUnknownFiles) {
  const std::string path = temporary_path("good.hzvoc");
  ASSERT_TRUE(training_vocabulary().save(path));
  const std::string bytes = read_file(path).value();
  const std::string bad = temporary_path("bad.hzvoc");
  auto load_with = [&](std::string content) {
    EXPECT_TRUE(write_file_durably(bad, content));
    Result<Vocabulary> loaded = Vocabulary::load(bad);
    EXPECT_FALSE(loaded);
    return loaded ? std::string() : loaded.error().message;
  };
  std::string flipped = bytes;
  flipped[bytes.size() / 2] ^= 0x10;
  EXPECT_NE(load_with(flipped).find("checksum mismatch"), std::string::npos);
  EXPECT_NE(load_with(bytes.substr(0, bytes.size() - 100)).find("truncated"), std::string::npos);
  EXPECT_NE(load_with(bytes + "extra").find("trailing bytes"), std::string::npos);
  std::string versioned = bytes;
  versioned[8] = 7;
  EXPECT_NE(load_with(versioned).find("version 7 is not supported"), std::string::npos);
  EXPECT_NE(load_with("not a vocabulary at all, just some text to fill the header").find("magic"), std::string::npos);
  EXPECT_NE(load_with("").find("too short"), std::string::npos);
  EXPECT_NE(Vocabulary::load(temporary_path("missing.hzvoc")).error().message.find("cannot open"), std::string::npos);
  std::filesystem::remove(path);
  std::filesystem::remove(bad);
}

TEST(Vocabulary, RefusesBadTrainingInput) {
  EXPECT_FALSE(Vocabulary::train({cv::Mat(10, 16, CV_8UC1, cv::Scalar(0))}));  // not 32-byte rows
  EXPECT_FALSE(Vocabulary::train({cv::Mat(10, 32, CV_32FC1, cv::Scalar(0))}));
  EXPECT_FALSE(Vocabulary::train({cv::Mat(3, 32, CV_8UC1, cv::Scalar(0))}));  // fewer than branching
  VocabularyConfig config;
  config.levels = 0;
  EXPECT_FALSE(Vocabulary::train({cv::Mat(100, 32, CV_8UC1, cv::Scalar(1))}, config));
  // Identical descriptors: one cluster, still a usable vocabulary.
  Result<Vocabulary> same = Vocabulary::train({cv::Mat(100, 32, CV_8UC1, cv::Scalar(1))});
  ASSERT_TRUE(same) << same.error().message;
  EXPECT_GE(same->words(), 1);
}

// KITTI odometry 06 (real street, driving straight 60 m): each odd frame queried against the
// even frames finds a neighbour along the road first, with a vocabulary trained elsewhere.
TEST(PlaceDatabase, RecognizesStreetPlacesWithAVocabularyTrainedElsewhere) {
  auto vocabulary = std::make_shared<const Vocabulary>(training_vocabulary());
  const std::vector<std::string> frames = images_in(kData + "/kitti_odometry_06_first51/image_l", 1);
  ASSERT_EQ(frames.size(), 51u);
  PlaceDatabase database(vocabulary);
  std::vector<BowVector> odd;
  for (std::size_t i = 0; i < frames.size(); ++i) {
    const BowVector bow = vocabulary->transform(descriptors_of(frames[i]));
    if (i % 2 == 0) database.add(bow);
    else odd.push_back(bow);
  }
  int neighbours_first = 0;
  for (std::size_t q = 0; q < odd.size(); ++q) {
    const std::vector<PlaceMatch> matches = database.query(odd[q], 3);
    ASSERT_EQ(matches.size(), 3u);
    EXPECT_GE(matches[0].score, matches[1].score);
    // The database's score is the vocabulary's L1 score.
    EXPECT_NEAR(matches[0].score, Vocabulary::score(odd[q], database.bow(matches[0].entry)), 1e-9);
    const int frame = 2 * static_cast<int>(q) + 1, found = 2 * matches[0].entry;
    neighbours_first += std::abs(found - frame) == 1;
  }
  EXPECT_GE(neighbours_first, 23) << "of " << odd.size();
  // Restricting the query to earlier entries.
  for (const PlaceMatch& match : database.query(odd.back(), 10, 5)) EXPECT_LT(match.entry, 5);
}

TEST(Vocabulary, TheDefaultVocabularyShipsWithTheProject) {
  Result<Vocabulary> vocabulary = Vocabulary::load_default();
  ASSERT_TRUE(vocabulary) << vocabulary.error().message;
  EXPECT_GT(vocabulary->words(), 5000);
  EXPECT_EQ(vocabulary->branching(), 10);
  EXPECT_EQ(vocabulary->levels(), 4);
}

}  // namespace
}  // namespace hanzo::fusion::vision
