// VladModel: global descriptors of float local descriptors. Synthetic places (each 60 of a pool
// of 300 appearance prototypes, as real places share kinds of corners and textures; an image of
// a place sees most of them with noise, under a "lighting" that perturbs every descriptor the
// same way) are told apart after training on other places of the same pool;
// the model file round-trips exactly and bad files and inputs are refused by name.

#include <cstdio>
#include <filesystem>
#include <fstream>
#include <random>

#include <gtest/gtest.h>

#include "hanzo/fusion/vision/vlad.hpp"

namespace hanzo::fusion::vision {
namespace {

constexpr int kSize = 32;

cv::Mat unit_rows(cv::Mat rows) {
  for (int r = 0; r < rows.rows; ++r) cv::normalize(rows.row(r), rows.row(r));
  return rows;
}

// The appearance prototypes: 300 random unit descriptors.
cv::Mat prototype_pool(std::mt19937& random) {
  cv::Mat pool(300, kSize, CV_32FC1);
  std::normal_distribution<float> normal(0.0F, 1.0F);
  for (int r = 0; r < pool.rows; ++r) {
    for (int c = 0; c < kSize; ++c) pool.at<float>(r, c) = normal(random);
  }
  return unit_rows(pool);
}

// A place: 60 prototypes of the pool.
cv::Mat place(const cv::Mat& pool, std::mt19937& random) {
  std::uniform_int_distribution<int> pick(0, pool.rows - 1);
  cv::Mat prototypes;
  for (int i = 0; i < 60; ++i) prototypes.push_back(pool.row(pick(random)));
  return prototypes;
}

// An image of the place: 80 % of its prototypes, each with noise, all shifted by `lighting`.
cv::Mat image_of(const cv::Mat& prototypes, const cv::Mat& lighting, std::mt19937& random) {
  std::normal_distribution<float> noise(0.0F, 0.05F);
  std::bernoulli_distribution seen(0.8);
  cv::Mat rows;
  for (int r = 0; r < prototypes.rows; ++r) {
    if (!seen(random)) continue;
    cv::Mat row = prototypes.row(r) + lighting;
    for (int c = 0; c < kSize; ++c) row.at<float>(0, c) += noise(random);
    rows.push_back(row);
  }
  return unit_rows(rows);
}

TEST(Vlad, TellsPlacesApartAcrossALightingChangeAndRoundTripsItsFile) {
  std::mt19937 random(3);
  const cv::Mat pool = prototype_pool(random);
  std::normal_distribution<float> normal(0.0F, 0.05F);
  auto lighting = [&] {
    cv::Mat shift(1, kSize, CV_32FC1);
    for (int c = 0; c < kSize; ++c) shift.at<float>(0, c) = normal(random);
    return shift;
  };
  // Training: 40 other places, 3 images each under random lighting.
  std::vector<cv::Mat> training;
  for (int p = 0; p < 40; ++p) {
    const cv::Mat prototypes = place(pool, random);
    for (int i = 0; i < 3; ++i) training.push_back(image_of(prototypes, lighting(), random));
  }
  VladConfig config;
  config.clusters = 16;
  config.dimensions = 64;
  const VladModel model = VladModel::train(training, "synthetic", config).value();
  EXPECT_EQ(model.training_images(), 120);
  EXPECT_EQ(model.dimensions(), 64);

  // 20 new places: database by day, queries at dusk; recall@1 of the nearest by similarity.
  const cv::Mat day = lighting(), dusk = lighting();
  std::vector<Eigen::VectorXf> database, queries;
  for (int p = 0; p < 20; ++p) {
    const cv::Mat prototypes = place(pool, random);
    database.push_back(model.describe(image_of(prototypes, day, random)).value());
    queries.push_back(model.describe(image_of(prototypes, dusk, random)).value());
  }
  int found = 0;
  for (std::size_t q = 0; q < queries.size(); ++q) {
    std::size_t best = 0;
    for (std::size_t d = 1; d < database.size(); ++d) {
      if (VladModel::similarity(queries[q], database[d]) > VladModel::similarity(queries[q], database[best])) best = d;
    }
    found += best == q;
    EXPECT_NEAR(queries[q].norm(), 1.0F, 1e-5F);
  }
  EXPECT_GE(found, 19);

  const std::string path = (std::filesystem::temp_directory_path() / "hanzo_vlad_test.hzvlad").string();
  ASSERT_TRUE(model.save(path));
  const VladModel loaded = VladModel::load(path).value();
  EXPECT_EQ(loaded.extractor_name(), "synthetic");
  const cv::Mat probe = training.front();
  EXPECT_EQ(loaded.describe(probe).value(), model.describe(probe).value());  // bit for bit

  // Corrupted and cut files, wrong descriptors.
  std::string bytes;
  {
    std::ifstream in(path, std::ios::binary);
    bytes.assign(std::istreambuf_iterator<char>(in), {});
  }
  const auto write = [&](const std::string& content) {
    std::ofstream out(path, std::ios::binary | std::ios::trunc);
    out << content;
  };
  std::string flipped = bytes;
  flipped[bytes.size() / 2] ^= 0x10;
  write(flipped);
  EXPECT_NE(VladModel::load(path).error().message.find("checksum mismatch"), std::string::npos);
  write(bytes.substr(0, bytes.size() - 100));
  EXPECT_NE(VladModel::load(path).error().message.find("truncated"), std::string::npos);
  write("HZVOCAB");
  EXPECT_NE(VladModel::load(path).error().message.find("not a hanzo-fusion VLAD model"), std::string::npos);
  std::filesystem::remove(path);
  EXPECT_NE(model.describe(cv::Mat(10, 32, CV_8UC1, cv::Scalar(1))).error().message.find("float (learned) descriptors"), std::string::npos);
  EXPECT_NE(model.describe(cv::Mat(10, 64, CV_32FC1, cv::Scalar(1))).error().message.find("the model's are 32"), std::string::npos);
  EXPECT_EQ(model.describe(cv::Mat()).value().norm(), 0.0F);  // no descriptors: similar to nothing
  EXPECT_NE(VladModel::train({training.begin(), training.begin() + 10}, "synthetic", config).error().message.find("need at least 65"),
            std::string::npos);
}

}  // namespace
}  // namespace hanzo::fusion::vision
