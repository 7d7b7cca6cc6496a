// Learned features (ALIKED, ALIKE) against an independent PyTorch run of the same weights
// (tests/ai/learned_features_reference.py: torch.nn modules loaded strictly, torchvision's
// deform_conv2d), the state_dict reader, and the errors of missing or wrong models.
#include <unistd.h>

#include <cstdio>
#include <filesystem>
#include <fstream>

#include <fmt/format.h>
#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <nlohmann/json.hpp>
#include <opencv2/imgcodecs.hpp>

#include "hanzo/fusion/ai/learned_features.hpp"
#include "hanzo/fusion/ai/state_dict.hpp"
#include "hanzo/fusion/vision/image_pair_matcher.hpp"
#include "vision/graf_pairs.hpp"

namespace hanzo::fusion::ai {
namespace {

using ::testing::HasSubstr;

const std::string kModels = HANZO_MODELS_DIR;
const std::string kGraf = std::string(HANZO_DATA_DIR) + "/feature_matching_graf";

std::string model_file(LearnedModel model) {
  const std::string name(to_string(model));
  return fmt::format("{}/{}/{}.pth", kModels, name.starts_with("aliked") ? "aliked" : "alike", name);
}

std::vector<float> read_floats(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  std::vector<float> values;
  float value = 0.0F;
  while (in.read(reinterpret_cast<char*>(&value), sizeof value)) values.push_back(value);
  return values;
}

struct Reference {
  int height = 0, width = 0, descriptor_size = 0;
  std::vector<float> score_map, keypoints, scores, descriptors;
};

Reference run_reference(LearnedModel model, const std::string& image, const std::string& extra = "") {
  const std::string prefix = (std::filesystem::temp_directory_path() / fmt::format("hanzo_ai_ref_{}_{}", ::getpid(), to_string(model))).string();
  const std::string command = fmt::format("/usr/bin/python3 tests/ai/learned_features_reference.py {} {} {} {} {}", to_string(model),
                                          model_file(model), image, prefix, extra);
  FILE* pipe = ::popen(command.c_str(), "r");
  std::string output;
  char buffer[4096];
  while (pipe != nullptr && std::fgets(buffer, sizeof buffer, pipe) != nullptr) output += buffer;
  const int status = pipe == nullptr ? -1 : ::pclose(pipe);
  Reference reference;
  EXPECT_EQ(status, 0) << command;
  if (status != 0) return reference;
  const nlohmann::json header = nlohmann::json::parse(output);
  reference.height = header["height"];
  reference.width = header["width"];
  reference.descriptor_size = header["descriptor_size"];
  reference.score_map = read_floats(prefix + ".score_map.f32");
  reference.keypoints = read_floats(prefix + ".keypoints.f32");
  reference.scores = read_floats(prefix + ".scores.f32");
  reference.descriptors = read_floats(prefix + ".descriptors.f32");
  for (const char* part : {"score_map", "keypoints", "scores", "descriptors"}) std::filesystem::remove(fmt::format("{}.{}.f32", prefix, part));
  return reference;
}

// The C++ outputs of `model` on graf1 (400 x 320, not a multiple of 32: padding is exercised)
// agree with PyTorch's: the score map to 1e-4 everywhere, the same keypoints, and their
// descriptors to 1e-4.
void expect_matches_pytorch(LearnedModel model, bool subpixel) {
  SCOPED_TRACE(std::string(to_string(model)));
  const std::string image_path = kGraf + "/graf1.png";
  const Reference reference = run_reference(model, image_path, subpixel ? "" : "--no-subpixel");
  ASSERT_GT(reference.height, 0);
  LearnedFeatureConfig config;
  config.model = model;
  config.model_path = model_file(model);
  config.subpixel = subpixel;
  auto extractor = LearnedFeatureExtractor::load(config);
  ASSERT_TRUE(extractor.ok()) << extractor.error().message;
  const cv::Mat image = cv::imread(image_path, cv::IMREAD_COLOR);
  auto maps = (*extractor)->extract_with_maps(image);
  ASSERT_TRUE(maps.ok()) << maps.error().message;
  ASSERT_EQ(maps->score_map.rows, reference.height);
  ASSERT_EQ(maps->score_map.cols, reference.width);
  double worst_score = 0.0;
  for (int i = 0; i < reference.height * reference.width; ++i) {
    worst_score = std::max(worst_score, static_cast<double>(std::abs(maps->score_map.ptr<float>()[i] - reference.score_map[static_cast<std::size_t>(i)])));
  }
  EXPECT_LT(worst_score, 1e-4);
  const vision::ImageFeatures& features = maps->features;
  const std::size_t count = reference.scores.size();
  ASSERT_GT(count, 100u);
  ASSERT_EQ(features.size(), count);
  ASSERT_EQ(features.descriptors.cols, reference.descriptor_size);
  double worst_position = 0.0, worst_keypoint_score = 0.0, worst_descriptor = 0.0;
  for (std::size_t i = 0; i < count; ++i) {
    const cv::KeyPoint& keypoint = features.keypoints[i];
    worst_position = std::max({worst_position, std::abs(static_cast<double>(keypoint.pt.x - reference.keypoints[2 * i])),
                               std::abs(static_cast<double>(keypoint.pt.y - reference.keypoints[2 * i + 1]))});
    worst_keypoint_score = std::max(worst_keypoint_score, static_cast<double>(std::abs(keypoint.response - reference.scores[i])));
    for (int d = 0; d < reference.descriptor_size; ++d) {
      const float expected = reference.descriptors[i * static_cast<std::size_t>(reference.descriptor_size) + static_cast<std::size_t>(d)];
      worst_descriptor = std::max(worst_descriptor, static_cast<double>(std::abs(features.descriptors.at<float>(static_cast<int>(i), d) - expected)));
    }
  }
  EXPECT_LT(worst_position, 1e-3);
  EXPECT_LT(worst_keypoint_score, 1e-4);
  EXPECT_LT(worst_descriptor, 1e-4);
  std::printf("%s: %zu keypoints, largest differences: score map %.2g, position %.2g px, descriptor %.2g\n", std::string(to_string(model)).c_str(),
              count, worst_score, worst_position, worst_descriptor);
}

TEST(LearnedFeatures, AlikedT16AgreesWithPyTorch) { expect_matches_pytorch(LearnedModel::kAlikedT16, true); }
TEST(LearnedFeatures, AlikedN32AgreesWithPyTorch) { expect_matches_pytorch(LearnedModel::kAlikedN32, true); }
TEST(LearnedFeatures, AlikeTAgreesWithPyTorch) { expect_matches_pytorch(LearnedModel::kAlikeT, true); }
TEST(LearnedFeatures, AlikeLAgreesWithPyTorchAtPixelPositions) { expect_matches_pytorch(LearnedModel::kAlikeL, false); }

TEST(StateDict, ReadsEveryTensorOfATorchSaveFile) {
  auto state = read_state_dict(model_file(LearnedModel::kAlikedT16));
  ASSERT_TRUE(state.ok()) << state.error().message;
  EXPECT_EQ(state->size(), 76u);
  const StateTensor& weights = state->at("desc_head.agg_weights");
  EXPECT_EQ(weights.shape, (std::vector<int64_t>{16, 64, 64}));
  EXPECT_EQ(weights.values.size(), 16u * 64u * 64u);
  EXPECT_EQ(state->at("block1.bn1.num_batches_tracked").shape, std::vector<int64_t>{});  // a scalar
}

TEST(StateDict, RefusesFilesThatAreNotStateDicts) {
  const std::filesystem::path dir = std::filesystem::temp_directory_path() / fmt::format("hanzo_ai_bad_{}", ::getpid());
  std::filesystem::create_directories(dir);
  std::ofstream(dir / "text.pth") << "not a model";
  EXPECT_THAT(read_state_dict((dir / "text.pth").string()).error().message, HasSubstr("not a zip archive"));
  EXPECT_THAT(read_state_dict((dir / "missing.pth").string()).error().message, HasSubstr("cannot open"));
  // A cut-off file: its directory is gone.
  std::ifstream whole(model_file(LearnedModel::kAlikeT), std::ios::binary);
  const std::string bytes((std::istreambuf_iterator<char>(whole)), std::istreambuf_iterator<char>());
  std::ofstream(dir / "cut.pth", std::ios::binary) << bytes.substr(0, bytes.size() / 2);
  EXPECT_FALSE(read_state_dict((dir / "cut.pth").string()).ok());
  std::filesystem::remove_all(dir);
}

TEST(LearnedFeatures, ModelsAreFoundOrRefusedWithTheirNames) {
  LearnedFeatureConfig config;
  config.model = LearnedModel::kAlikedN16;
  config.model_path = model_file(LearnedModel::kAlikeN);  // another architecture's weights (same widths)
  EXPECT_THAT(LearnedFeatureExtractor::load(config).error().message, HasSubstr("no tensor"));
  config.model_path = model_file(LearnedModel::kAlikedT16);  // the same family, another size
  EXPECT_THAT(LearnedFeatureExtractor::load(config).error().message, HasSubstr("another model size"));
  config.model_path = "/nonexistent/aliked-n16.pth";
  EXPECT_THAT(LearnedFeatureExtractor::load(config).error().message, HasSubstr("/nonexistent/aliked-n16.pth: no such model file"));
  config.model_path.clear();
  ::setenv("HANZO_FUSION_MODELS", kModels.c_str(), 1);
  auto found = find_learned_model(LearnedModel::kAlikedN16);
  ASSERT_TRUE(found.ok()) << found.error().message;
  EXPECT_EQ(std::filesystem::path(*found).filename(), "aliked-n16.pth");
  ::setenv("HANZO_FUSION_MODELS", "/nonexistent", 1);
  EXPECT_THAT(find_learned_model(LearnedModel::kAlikedN16).error().message, HasSubstr("aliked-n16.pth not found (looked in HANZO_FUSION_MODELS=/nonexistent"));
  ::unsetenv("HANZO_FUSION_MODELS");
  EXPECT_THAT(find_learned_model(LearnedModel::kAlikedN16).error().message, HasSubstr("HANZO_FUSION_MODELS"));
  EXPECT_EQ(learned_model_from_name("aliked-n16rot"), LearnedModel::kAlikedN16Rot);
  EXPECT_FALSE(learned_model_from_name("superpoint").has_value());
}

TEST(LearnedFeatures, RefusesImagesTheNetworksCannotTake) {
  LearnedFeatureConfig config;
  config.model_path = model_file(LearnedModel::kAlikedT16);
  auto extractor = LearnedFeatureExtractor::load(config);
  ASSERT_TRUE(extractor.ok()) << extractor.error().message;
  EXPECT_THAT((*extractor)->extract(cv::Mat()).error().message, HasSubstr("empty"));
  EXPECT_THAT((*extractor)->extract(cv::Mat(32, 200, CV_8UC1, cv::Scalar(0))).error().message, HasSubstr("at least 64 x 64"));
  EXPECT_THAT((*extractor)->extract(cv::Mat(100, 100, CV_32FC1, cv::Scalar(0))).error().message, HasSubstr("8-bit"));
  const cv::Mat image = cv::imread(kGraf + "/graf1.png", cv::IMREAD_GRAYSCALE);
  EXPECT_THAT((*extractor)->extract(image, cv::Mat(10, 10, CV_8UC1)).error().message, HasSubstr("mask"));
  // A mask keeps the keypoints of its non-zero half.
  cv::Mat left_half(image.size(), CV_8UC1, cv::Scalar(0));
  left_half.colRange(0, image.cols / 2).setTo(255);
  auto all = (*extractor)->extract(image);
  auto masked = (*extractor)->extract(image, left_half);
  ASSERT_TRUE(all.ok() && masked.ok());
  EXPECT_GT(masked->size(), 0u);
  EXPECT_LT(masked->size(), all->size());
  for (const cv::KeyPoint& keypoint : masked->keypoints) EXPECT_LT(keypoint.pt.x, image.cols / 2.0F + 0.5F);
  LearnedFeatureConfig bad = config;
  bad.max_keypoints = 0;
  EXPECT_THAT(LearnedFeatureExtractor::load(bad).error().message, HasSubstr("max_keypoints"));
}

// Image-pair matching with learned features and no simulated views: the graf pair (20 degrees)
// and graf1 seen from 40 and 60 degrees further round (known homographies).
TEST(LearnedFeatures, MatchWideBaselinePairsWithoutAffineViews) {
  for (const LearnedModel model : {LearnedModel::kAlikedT16, LearnedModel::kAlikedN16}) {
    LearnedFeatureConfig config;
    config.model = model;
    config.model_path = model_file(model);
    auto extractor = LearnedFeatureExtractor::load(config);
    ASSERT_TRUE(extractor.ok()) << extractor.error().message;
    vision::ImagePairMatcherConfig matcher;
    matcher.view_tilts.clear();
    for (const double degrees : {0.0, 40.0, 60.0}) {
      const vision::testing::GrafPair pair = degrees == 0.0 ? vision::testing::graf_pair() : vision::testing::wide_baseline_pair(degrees);
      auto matched = vision::match_image_pair(pair.image1, pair.image2, matcher, extractor->get());
      ASSERT_TRUE(matched.ok()) << matched.error().message;
      const int correct = vision::count_correct_matches(matched->matches, pair.homography, 3.0);
      const double precision = matched->matches.empty() ? 0.0 : static_cast<double>(correct) / static_cast<double>(matched->matches.size());
      std::printf("%s, %s: %d correct matches at 3 px, precision %.3f (%zu putative)\n", std::string(to_string(model)).c_str(),
                  degrees == 0.0 ? "graf1-graf2" : fmt::format("{:.0f} degrees", degrees).c_str(), correct, precision, matched->putative.size());
      EXPECT_TRUE(matched->geometry_found);
      EXPECT_GE(correct, 200);  // ORB needs simulated affine views for 258-278 at 40 degrees (docs/vision.md)
      EXPECT_GE(precision, 0.9);
    }
  }
}

}  // namespace
}  // namespace hanzo::fusion::ai
