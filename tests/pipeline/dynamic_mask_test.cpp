// The static mask a detector's boxes give the visual odometry (pipeline/dynamic_mask.hpp).

#include "hanzo/fusion/pipeline/dynamic_mask.hpp"

#include <gmock/gmock.h>
#include <gtest/gtest.h>

namespace hanzo::fusion::pipeline {
namespace {

using ::testing::HasSubstr;

msgs::Detection2D box(std::string class_name, float x_min, float y_min, float x_max, float y_max, float score = 0.9F) {
  msgs::Detection2D detection;
  detection.class_name = std::move(class_name);
  detection.score = score;
  detection.x_min = x_min;
  detection.y_min = y_min;
  detection.x_max = x_max;
  detection.y_max = y_max;
  return detection;
}

msgs::DetectionsMessage detections(std::vector<msgs::Detection2D> boxes) {
  msgs::DetectionsMessage message;
  message.timestamp = Timestamp::from_seconds(1.0);
  message.image_width = 64;
  message.image_height = 48;
  message.detections = std::move(boxes);
  return message;
}

// A person's box grown by the margin masks; a chair (not a moving class), a weak detection
// and nothing at all leave the image usable.
TEST(DynamicMask, MovingClassesBoxesGrownByTheMarginAreMasked) {
  config::DynamicObjectsConfig config;
  config.margin_px = 2.0;
  const DynamicMask mask = dynamic_mask(detections({box("Person", 10.0F, 5.0F, 19.0F, 14.0F), box("chair", 40.0F, 5.0F, 50.0F, 20.0F),
                                                    box("car", 30.0F, 30.0F, 40.0F, 40.0F, 0.1F)}),
                                        cv::Size(64, 48), config)
                               .value();
  ASSERT_FALSE(mask.static_mask.empty());
  EXPECT_EQ(mask.masked_objects, 1);
  // Pixels 8..21 x 3..16 (the box's 10..19 x 5..14 and 2 more on every side).
  EXPECT_EQ(cv::countNonZero(mask.static_mask == 0), 14 * 14);
  EXPECT_EQ(mask.static_mask.at<uint8_t>(3, 8), 0);
  EXPECT_EQ(mask.static_mask.at<uint8_t>(16, 21), 0);
  EXPECT_NE(mask.static_mask.at<uint8_t>(2, 8), 0);
  EXPECT_NE(mask.static_mask.at<uint8_t>(10, 45), 0);  // the chair
  EXPECT_NEAR(mask.masked_share, 196.0 / (64.0 * 48.0), 1e-12);
  EXPECT_TRUE(dynamic_mask(detections({box("chair", 1.0F, 1.0F, 5.0F, 5.0F)}), cv::Size(64, 48), config)->static_mask.empty());
  EXPECT_TRUE(dynamic_mask(detections({}), cv::Size(64, 48), config)->static_mask.empty());
  config.classes = {"chair"};
  EXPECT_EQ(dynamic_mask(detections({box("CHAIR", 1.0F, 1.0F, 5.0F, 5.0F)}), cv::Size(64, 48), config)->masked_objects, 1);
}

// An instance mask masks its own pixels (stretched over the box) dilated by the margin, not the
// whole box.
TEST(DynamicMask, AnInstanceMaskMasksItsPixelsOnly) {
  config::DynamicObjectsConfig config;
  config.margin_px = 0.0;
  msgs::Detection2D person = box("person", 10.0F, 10.0F, 13.0F, 11.0F);
  person.mask_width = 2;
  person.mask_height = 1;
  person.mask = {255, 0};  // the box's left half
  const DynamicMask mask = dynamic_mask(detections({person}), cv::Size(64, 48), config).value();
  EXPECT_EQ(cv::countNonZero(mask.static_mask == 0), 4);  // columns 10..11, rows 10..11
  EXPECT_EQ(mask.static_mask.at<uint8_t>(10, 11), 0);
  EXPECT_NE(mask.static_mask.at<uint8_t>(10, 12), 0);
  config.margin_px = 1.0;
  EXPECT_GT(cv::countNonZero(dynamic_mask(detections({person}), cv::Size(64, 48), config)->static_mask == 0), 4);
}

// A segmentation's region of a moving class masks (dilated by the margin); scattered pixels of
// that class (a segmenter's errors) do not.
TEST(DynamicMask, ASegmentedPersonMasksItsRegionButScatteredPixelsDoNot) {
  config::DynamicObjectsConfig config;
  config.margin_px = 1.0;
  msgs::DetectionsMessage message = detections({});
  message.segmentation_classes = {"floor", "person"};
  message.segmentation.assign(64 * 48, 0);
  for (int row = 20; row < 30; ++row) {
    for (int column = 10; column < 18; ++column) message.segmentation[static_cast<std::size_t>(row) * 64 + column] = 1;
  }
  for (const int pixel : {3 * 64 + 40, 40 * 64 + 50, 45 * 64 + 5}) message.segmentation[static_cast<std::size_t>(pixel)] = 1;
  const DynamicMask mask = dynamic_mask(message, cv::Size(64, 48), config).value();
  ASSERT_FALSE(mask.static_mask.empty());
  EXPECT_EQ(mask.masked_objects, 0);  // detections only
  EXPECT_EQ(mask.static_mask.at<uint8_t>(25, 14), 0);
  EXPECT_EQ(mask.static_mask.at<uint8_t>(25, 9), 0);  // the margin
  EXPECT_NE(mask.static_mask.at<uint8_t>(25, 20), 0);
  EXPECT_NE(mask.static_mask.at<uint8_t>(3, 40), 0);  // a lone pixel
  EXPECT_NE(mask.static_mask.at<uint8_t>(40, 50), 0);
  config.classes = {"car"};
  EXPECT_TRUE(dynamic_mask(message, cv::Size(64, 48), config)->static_mask.empty());
}

TEST(DynamicMask, DetectionsForAnotherImageSizeAreRefused) {
  EXPECT_THAT(dynamic_mask(detections({box("person", 1.0F, 1.0F, 5.0F, 5.0F)}), cv::Size(640, 480), {}).error().message,
              HasSubstr("detections for a 64 x 48 image, the camera's images are 640 x 480"));
}

}  // namespace
}  // namespace hanzo::fusion::pipeline
