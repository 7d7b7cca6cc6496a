// The privacy filter on real photos (../shared/data/privacy_faces, faces counted by eye) and real
// street images (KITTI raw 2011_09_26_drive_0052: cars with German plates, no faces close enough).
#include <algorithm>
#include <filesystem>
#include <string>

#include <gtest/gtest.h>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "hanzo/fusion/privacy/privacy_filter.hpp"

namespace hanzo::fusion::privacy {
namespace {

const std::string kFaces = std::string(HANZO_DATA_DIR) + "/privacy_faces/";

std::unique_ptr<PrivacyFilter> make_filter(PrivacyFilterConfig config = {}) {
  auto filter = PrivacyFilter::create(config);
  EXPECT_TRUE(filter.ok()) << (filter.ok() ? "" : filter.error().message);
  return filter ? std::move(filter).value() : nullptr;
}

int count(const std::vector<RedactedRegion>& regions, const std::string& kind) {
  return static_cast<int>(std::count_if(regions.begin(), regions.end(), [&](const RedactedRegion& r) { return r.kind == kind; }));
}

bool covers(const std::vector<RedactedRegion>& regions, const cv::Point& point) {
  return std::any_of(regions.begin(), regions.end(), [&](const RedactedRegion& r) { return r.box.contains(point); });
}

TEST(PrivacyFilter, FindsEveryFaceOfTheTestPhotos) {
  auto filter = make_filter();
  ASSERT_NE(filter, nullptr);
  // SOURCE.md counts the faces; obama_and_biden.jpg shows a third, a girl's face cut by the
  // bottom edge (at about (1700, 1130)), which counts too.
  const std::vector<std::pair<std::string, int>> photos{
      {"obama.jpg", 1}, {"two_people.jpg", 2}, {"obama_and_biden.jpg", 3}, {"kit_with_rose.jpg", 2}, {"alex-lacamoire.png", 1}};
  for (const auto& [file, faces] : photos) {
    const cv::Mat image = cv::imread(kFaces + file);
    ASSERT_FALSE(image.empty()) << file;
    auto regions = filter->detect(image);
    ASSERT_TRUE(regions.ok()) << regions.error().message;
    EXPECT_EQ(count(*regions, "face"), faces) << file;
    EXPECT_EQ(count(*regions, "licence_plate"), 0) << file;
  }
  const cv::Mat both = cv::imread(kFaces + "obama_and_biden.jpg");
  auto regions = filter->detect(both);
  ASSERT_TRUE(regions.ok());
  EXPECT_TRUE(covers(*regions, {1230, 480}));  // Biden
  EXPECT_TRUE(covers(*regions, {840, 520}));   // Obama
  EXPECT_TRUE(covers(*regions, {1700, 1130}));
}

TEST(PrivacyFilter, FindsFacesDownTo24PixelsAndInGreyImages) {
  auto filter = make_filter();
  ASSERT_NE(filter, nullptr);
  const cv::Mat image = cv::imread(kFaces + "two_people.jpg");
  ASSERT_FALSE(image.empty());
  // The faces are about 150 px wide: scaled to 24, 32 and 64 px.
  for (const double face_width : {24.0, 32.0, 64.0}) {
    cv::Mat small;
    cv::resize(image, small, cv::Size(), face_width / 150.0, face_width / 150.0, cv::INTER_AREA);
    auto regions = filter->detect(small);
    ASSERT_TRUE(regions.ok());
    EXPECT_EQ(count(*regions, "face"), 2) << face_width << " px faces in a " << small.cols << " x " << small.rows << " image";
  }
  cv::Mat grey;
  cv::cvtColor(image, grey, cv::COLOR_BGR2GRAY);
  auto regions = filter->detect(grey);
  ASSERT_TRUE(regions.ok());
  EXPECT_EQ(count(*regions, "face"), 2);
}

TEST(PrivacyFilter, FindsLicencePlatesAndNoFacesInStreetImages) {
  auto filter = make_filter();
  ASSERT_NE(filter, nullptr);
  const std::string folder = std::string(HANZO_DATA_DIR) + "/kitti_raw_0052/image_02/";
  // Frame 50: the car ahead (plate "KA JS 6312" at about (660, 318)) and a truck's plate at the
  // left edge (about (70, 332)).
  const cv::Mat frame = cv::imread(folder + "0000000050.png");
  ASSERT_FALSE(frame.empty());
  auto regions = filter->detect(frame);
  ASSERT_TRUE(regions.ok());
  EXPECT_TRUE(covers(*regions, {660, 318}));
  EXPECT_TRUE(covers(*regions, {70, 332}));
  int faces = 0, frames = 0;
  for (const auto& entry : std::filesystem::directory_iterator(folder)) {
    const cv::Mat image = cv::imread(entry.path().string());
    if (image.empty()) continue;
    auto found = filter->detect(image);
    ASSERT_TRUE(found.ok());
    faces += count(*found, "face");
    ++frames;
  }
  EXPECT_GT(frames, 50);
  EXPECT_EQ(faces, 0);
}

TEST(PrivacyFilter, BlursOrBlacksOutOnlyTheRegions) {
  const cv::Mat original = cv::imread(kFaces + "obama.jpg");
  ASSERT_FALSE(original.empty());
  for (const Redaction redaction : {Redaction::kBlur, Redaction::kBlackOut}) {
    PrivacyFilterConfig config;
    config.redaction = redaction;
    auto filter = make_filter(config);
    ASSERT_NE(filter, nullptr);
    cv::Mat image = original.clone();
    auto regions = filter->apply(image);
    ASSERT_TRUE(regions.ok());
    ASSERT_EQ(regions->size(), 1U);
    const cv::Rect face = regions->front().box;
    // Inside the face: black, or blurred (the detail, the Laplacian's spread, gone).
    const auto detail = [](const cv::Mat& pixels) {
      cv::Mat grey, laplacian;
      cv::cvtColor(pixels, grey, cv::COLOR_BGR2GRAY);
      cv::Laplacian(grey, laplacian, CV_64F);
      cv::Scalar mean, deviation;
      cv::meanStdDev(laplacian, mean, deviation);
      return deviation[0];
    };
    if (redaction == Redaction::kBlackOut) {
      EXPECT_EQ(cv::countNonZero(image(face).reshape(1)), 0);
    } else {
      EXPECT_LT(detail(image(face)), 0.1 * detail(original(face)));
    }
    // Outside the enlarged region nothing changed.
    cv::Mat changed;
    cv::absdiff(image, original, changed);
    cv::Mat mask = cv::Mat::ones(image.size(), CV_8U);
    const int dx = face.width / 10 + 1, dy = face.height / 10 + 1;
    mask(cv::Rect(face.x - dx, face.y - dy, face.width + 2 * dx, face.height + 2 * dy) & cv::Rect(0, 0, image.cols, image.rows)).setTo(0);
    std::vector<cv::Mat> channels;
    cv::split(changed, channels);
    const cv::Mat outside = mask * 255;
    for (const cv::Mat& channel : channels) EXPECT_EQ(cv::countNonZero(channel & outside), 0) << to_string(redaction);
  }
}

TEST(PrivacyFilter, RefusesBadInputWithAReason) {
  auto filter = make_filter();
  ASSERT_NE(filter, nullptr);
  cv::Mat empty;
  auto refused = filter->apply(empty);
  ASSERT_FALSE(refused.ok());
  EXPECT_NE(refused.error().message.find("empty"), std::string::npos);
  cv::Mat floating(100, 100, CV_32FC3, cv::Scalar::all(0.5));
  refused = filter->apply(floating);
  ASSERT_FALSE(refused.ok());
  EXPECT_NE(refused.error().message.find("8-bit"), std::string::npos);
  PrivacyFilterConfig config;
  config.face_model_path = "/nonexistent/yunet.onnx";
  auto missing = PrivacyFilter::create(config);
  ASSERT_FALSE(missing.ok());
  EXPECT_NE(missing.error().message.find("/nonexistent/yunet.onnx"), std::string::npos);
  config = {};
  config.face_score_threshold = 1.5;
  EXPECT_FALSE(PrivacyFilter::create(config).ok());
  EXPECT_FALSE(parse_redaction("pixelate").ok());
  EXPECT_EQ(parse_redaction("black").value(), Redaction::kBlackOut);
}

}  // namespace
}  // namespace hanzo::fusion::privacy
