// ImageQualityMonitor: dark, glare and motion-blurred images of a textured scene are told apart
// from good ones; a lasting change of scene becomes the norm; bad input and configuration are
// refused naming what is wrong.

#include <gtest/gtest.h>
#include <opencv2/imgproc.hpp>

#include "hanzo/fusion/vision/image_quality.hpp"

namespace hanzo::fusion::vision {
namespace {

// A textured scene: blobs of several sizes, grey levels 40-200, shifted by `shift` pixels.
cv::Mat scene(int shift, uint64_t seed = 3) {
  cv::Mat noise(480, 640 + 64, CV_8UC1);
  cv::RNG rng(seed);
  rng.fill(noise, cv::RNG::UNIFORM, 0, 256);
  cv::Mat coarse, fine, image;
  cv::GaussianBlur(noise, coarse, cv::Size(0, 0), 6.0);
  cv::GaussianBlur(noise, fine, cv::Size(0, 0), 1.2);
  cv::addWeighted(coarse, 2.0, fine, 0.6, -150.0, image);
  cv::normalize(image, image, 40, 200, cv::NORM_MINMAX);
  return image(cv::Rect(shift, 0, 640, 480)).clone();
}

ImageQualityMonitor warmed_up() {
  ImageQualityMonitor monitor = ImageQualityMonitor::create().value();
  for (int i = 0; i < 10; ++i) EXPECT_EQ(monitor.assess(scene(i)).value().condition, ImageCondition::kGood) << i;
  return monitor;
}

TEST(ImageQuality, TellsDarkGlareAndMotionBlurFromGoodImages) {
  ImageQualityMonitor monitor = warmed_up();
  cv::Mat dark;
  scene(10).convertTo(dark, CV_8UC1, 0.05);  // lights out: 5 % of the light
  const ImageQuality dark_quality = monitor.assess(dark).value();
  EXPECT_EQ(dark_quality.condition, ImageCondition::kDark);
  EXPECT_LT(dark_quality.mean_intensity, 10.0);

  cv::Mat glare = scene(11);
  cv::circle(glare, cv::Point(120, 90), 200, cv::Scalar(255), cv::FILLED);  // the sun in a corner
  const ImageQuality glare_quality = monitor.assess(glare).value();
  EXPECT_EQ(glare_quality.condition, ImageCondition::kGlare);
  EXPECT_GT(glare_quality.saturated_fraction, 0.15);

  cv::Mat blurred;
  cv::blur(scene(12), blurred, cv::Size(15, 1));  // 15 px of horizontal motion during the exposure
  EXPECT_EQ(monitor.assess(blurred).value().condition, ImageCondition::kMotionBlur);
  EXPECT_EQ(monitor.assess(scene(13)).value().condition, ImageCondition::kGood);  // sharp again

  // A uniformly darker but still visible scene is neither dark nor blurred.
  cv::Mat dimmer;
  scene(14).convertTo(dimmer, CV_8UC1, 0.4);
  EXPECT_EQ(monitor.assess(dimmer).value().condition, ImageCondition::kGood);
}

TEST(ImageQuality, ALastingSofterSceneBecomesTheNorm) {
  ImageQualityMonitor monitor = warmed_up();
  int blurred = 0;
  for (int i = 0; i < 40; ++i) {
    cv::Mat softer;
    cv::GaussianBlur(scene(20 + i, 9), softer, cv::Size(0, 0), 2.5);
    if (monitor.assess(softer).value().condition == ImageCondition::kMotionBlur) ++blurred;
  }
  EXPECT_GT(blurred, 0);   // at first a sudden drop
  EXPECT_LT(blurred, 20);  // then the new norm (half the 30-frame history)
}

TEST(ImageQuality, RefusesBadImagesAndConfiguration) {
  ImageQualityMonitor monitor = ImageQualityMonitor::create().value();
  EXPECT_FALSE(monitor.assess(cv::Mat()));
  EXPECT_FALSE(monitor.assess(cv::Mat(48, 64, CV_8UC3, cv::Scalar::all(100))));
  EXPECT_TRUE(monitor.assess(cv::Mat(48, 64, CV_8UC1, cv::Scalar::all(100))));

  ImageQualityConfig config;
  config.glare_saturated_fraction = 0.0;
  const auto refused = ImageQualityMonitor::create(config);
  ASSERT_FALSE(refused);
  EXPECT_NE(refused.error().message.find("glare_saturated_fraction"), std::string::npos);
  config = {};
  config.min_history_for_blur = 40;  // more than the 30-frame history
  EXPECT_FALSE(ImageQualityMonitor::create(config));
}

}  // namespace
}  // namespace hanzo::fusion::vision
