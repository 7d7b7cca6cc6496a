// Learned features in the visual frontends: the visual odometry with ALIKED on KITTI odometry 06
// (real images, ground truth) against ORB on the same frames, the visual-inertial tracker with a
// learned detector, and the landmark map with float descriptors through a FusionMap file.

#include <cmath>
#include <cstdio>

#include <gtest/gtest.h>

#include "hanzo/fusion/ai/learned_features.hpp"
#include "hanzo/fusion/eval/pose_error.hpp"
#include "hanzo/fusion/maps/fusion_map_file.hpp"
#include "hanzo/fusion/vision/feature_tracker.hpp"
#include "hanzo/fusion/vision/map_relocalizer.hpp"
#include "vision/odometry_sequences.hpp"

namespace hanzo::fusion::ai {
namespace {

const std::string kModels = HANZO_MODELS_DIR;

std::shared_ptr<const vision::FeatureExtractor> aliked_t16() {
  LearnedFeatureConfig config;
  config.model = LearnedModel::kAlikedT16;
  config.model_path = kModels + "/aliked/aliked-t16.pth";
  config.max_keypoints = 2000;
  return LearnedFeatureExtractor::load(config).value();
}

double sim3_ape(const vision::sequences::Sequence& sequence, const io::Trajectory& estimate) {
  const io::Trajectory reference = vision::sequences::at_times(sequence.ground_truth, estimate);
  eval::ApeConfig config;
  config.alignment = eval::Alignment::kSim3;
  return eval::compute_ape(reference, estimate, config).value().statistics.rmse;
}

// KITTI 06, frames 0-50 (60 m): ALIKED tracks every frame and is no worse than ORB.
TEST(LearnedOdometry, AlikedOnKittiOdometry06IsNoWorseThanOrb) {
  const vision::sequences::Sequence sequence = vision::sequences::kitti_odometry_06();
  const vision::sequences::RunResult orb = vision::sequences::run(sequence);
  vision::VisualOdometryConfig config;
  config.extractor = aliked_t16();
  const vision::sequences::RunResult learned = vision::sequences::run(sequence, config);
  const double orb_rmse = sim3_ape(sequence, orb.estimate), learned_rmse = sim3_ape(sequence, learned.estimate);
  std::printf("KITTI 06 (Sim3 APE RMSE): ORB %.3f m (%d landmarks), aliked-t16 %.3f m (%d landmarks, %.0f ms per frame)\n", orb_rmse,
              orb.summary.landmarks, learned_rmse, learned.summary.landmarks, 1000.0 * learned.summary.feature_seconds / learned.summary.feature_frames);
  EXPECT_EQ(learned.summary.tracked_frames, 51);
  EXPECT_EQ(learned.summary.features, "aliked-t16");
  EXPECT_FALSE(learned.summary.loop_closure_enabled);  // no place model given: the bag of words is of binary descriptors
  // Both are 0.04-0.05 m over 60 m here; the learned runs' spread over settings (0.036 m to
  // 0.052 m for max_float_descriptor_distance 0.7 to 1.2) is larger than the gap to ORB.
  EXPECT_LE(learned_rmse, orb_rmse * 1.2);
  EXPECT_LT(learned_rmse, 0.01 * sequence.ground_truth.path_length());
}

// Learned place recognition: the shipped VLAD model is for aliked-t16's descriptors; another
// extractor's are refused by name.
TEST(LearnedOdometry, LoopClosureUsesTheVladModelOfItsFeatures) {
  const auto model = std::make_shared<const vision::VladModel>(vision::VladModel::load_default("aliked-t16").value());
  const PinholeCamera camera = vision::sequences::kitti_odometry_06().camera;
  vision::VisualOdometryConfig config;
  config.extractor = aliked_t16();
  config.place_model = model;
  const auto odometry = vision::VisualOdometry::create(camera, {1226, 370}, config).value();
  EXPECT_TRUE(odometry->summary().loop_closure_enabled);
  EXPECT_EQ(odometry->summary().place_recognition, "learned");
  LearnedFeatureConfig alike;
  alike.model = LearnedModel::kAlikeT;
  alike.model_path = kModels + "/alike/alike-t.pth";
  config.extractor = LearnedFeatureExtractor::load(alike).value();
  const auto refused = vision::VisualOdometry::create(camera, {1226, 370}, config);
  ASSERT_FALSE(refused);
  EXPECT_EQ(refused.error().field, "place_model");
  EXPECT_NE(refused.error().message.find("trained on aliked-t16 descriptors, the features are alike-t's"), std::string::npos);
  EXPECT_FALSE(vision::VladModel::load_default("alike-t"));  // none shipped
}

// The landmark layer of a learned map carries the float descriptors and survives a map file
// exactly; relocalization with the map's features (candidates by VLAD, or by matched landmarks)
// places a later frame the map never saw where the odometry tracked it; ORB features are refused.
TEST(LearnedOdometry, LandmarkLayerKeepsFloatDescriptorsThroughAMapFile) {
  vision::sequences::Sequence sequence = vision::sequences::kitti_odometry_06();
  vision::VisualOdometryConfig config;
  config.extractor = aliked_t16();
  auto odometry = vision::VisualOdometry::create(sequence.camera, {1226, 370}, config).value();
  constexpr std::size_t kMapped = 12, kQuery = 15;  // frames in the map; the frame placed in it
  msgs::FusionMap map;
  map.map_id = "learned";
  SE3 T_world_query;  // the odometry's pose of the query frame (the world: the first camera's frame)
  for (std::size_t i = 0; i <= kQuery; ++i) {
    if (i == kMapped) map.visual_landmarks = odometry->landmark_layer("cam0");
    const Result<vision::VisualOdometryFrame> frame = odometry->track(sequence.times[i], cv::imread(sequence.images[i]));
    ASSERT_TRUE(frame) << i;
    if (i == kQuery) {
      ASSERT_EQ(frame->state, vision::TrackingState::kTracking);
      T_world_query = frame->T_world_camera;
    }
  }
  const msgs::VisualLandmarkLayer& layer = *map.visual_landmarks;
  ASSERT_GT(layer.positions.size(), 100u);
  EXPECT_EQ(layer.descriptor_type, "aliked-t16");
  EXPECT_EQ(layer.float_descriptor_size, 64u);
  EXPECT_EQ(layer.float_descriptors.size(), 64 * layer.positions.size());
  EXPECT_TRUE(layer.descriptors.empty());
  maps::FusionMapFileConfig small_chunks;  // the landmarks split over several chunks
  small_chunks.chunk_bytes = 16 << 10;
  const Result<std::string> bytes = maps::serialize_fusion_map(map, small_chunks);
  ASSERT_TRUE(bytes) << bytes.error().message;
  const msgs::FusionMap loaded = maps::parse_fusion_map(*bytes).value();
  ASSERT_TRUE(loaded.visual_landmarks);
  EXPECT_EQ(loaded.visual_landmarks->descriptor_type, "aliked-t16");
  EXPECT_EQ(loaded.visual_landmarks->float_descriptors, layer.float_descriptors);
  EXPECT_EQ(loaded.visual_landmarks->positions, layer.positions);

  const Result<vision::MapRelocalizer> orb = vision::MapRelocalizer::create(*loaded.visual_landmarks, sequence.camera);
  ASSERT_FALSE(orb);
  EXPECT_NE(orb.error().message.find("carry aliked-t16 descriptors, the image's features are orb's"), std::string::npos) << orb.error().message;

  const double travelled = T_world_query.translation().norm();
  const cv::Mat query = cv::imread(sequence.images[kQuery]);
  for (const bool learned_place_recognition : {true, false}) {
    vision::MapRelocalizerConfig relocalization;
    relocalization.extractor = aliked_t16();
    relocalization.learned_place_recognition = learned_place_recognition;
    const auto relocalizer = vision::MapRelocalizer::create(*loaded.visual_landmarks, sequence.camera, relocalization);
    ASSERT_TRUE(relocalizer) << relocalizer.error().message;
    const Result<vision::MapRelocalization> placed = relocalizer->relocalize(query);
    ASSERT_TRUE(placed) << placed.error().message;
    EXPECT_EQ(placed->place_recognition, learned_place_recognition ? "learned" : "matches");
    const SE3 error = T_world_query.inverse() * placed->T_world_camera;
    std::printf("relocalized frame %zu (%s): %d inliers, %.3f of %.3f map units travelled, %.2f deg\n", kQuery, placed->place_recognition.c_str(),
                placed->inliers, error.translation().norm(), travelled, error.rotation().log().norm() * 180.0 / M_PI);
    EXPECT_GE(placed->inliers, 50);
    EXPECT_LT(error.translation().norm(), 0.03 * travelled);
    EXPECT_LT(error.rotation().log().norm(), 0.5 * M_PI / 180.0);
  }
}

// The visual-inertial tracker takes its new features from a learned detector: they are the
// detector's keypoints, spread over the grid, and are followed by optical flow.
TEST(LearnedOdometry, TrackerDetectsWithALearnedDetector) {
  const vision::sequences::Sequence sequence = vision::sequences::kitti_odometry_06();
  vision::FeatureTrackerConfig config;
  config.detector = aliked_t16();
  auto tracker = vision::FeatureTracker::create(sequence.camera, {1226, 370}, config).value();
  const cv::Mat first = cv::imread(sequence.images[0], cv::IMREAD_GRAYSCALE);
  const vision::TrackedFrame detected = tracker->track(first).value();
  EXPECT_EQ(detected.new_features, config.max_features);
  const vision::ImageFeatures keypoints = config.detector->extract(first).value();
  for (const vision::FeatureObservation& observation : detected.observations) {
    const Eigen::Vector2d pixel = sequence.camera.project(observation.normalized.homogeneous()).value();
    bool on_keypoint = false;
    for (const cv::KeyPoint& keypoint : keypoints.keypoints) on_keypoint = on_keypoint || std::hypot(keypoint.pt.x - pixel.x(), keypoint.pt.y - pixel.y()) < 1.0;
    EXPECT_TRUE(on_keypoint) << pixel.transpose();
  }
  // Followed into the next images about as well as Shi-Tomasi's corners.
  auto classical = vision::FeatureTracker::create(sequence.camera, {1226, 370}).value();
  ASSERT_TRUE(classical->track(first));
  for (int i = 1; i <= 3; ++i) {
    const cv::Mat image = cv::imread(sequence.images[static_cast<std::size_t>(i)], cv::IMREAD_GRAYSCALE);
    const int learned_tracked = tracker->track(image).value().tracked, classical_tracked = classical->track(image).value().tracked;
    std::printf("frame %d: %d tracked (aliked-t16 detections), %d (Shi-Tomasi)\n", i, learned_tracked, classical_tracked);
    EXPECT_GE(learned_tracked, classical_tracked * 8 / 10);
  }
}

}  // namespace
}  // namespace hanzo::fusion::ai
