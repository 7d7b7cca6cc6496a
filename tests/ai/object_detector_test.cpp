// The object detector (NanoDet on the TensorFlow.js graph reader): agreement with an independent
// PyTorch run, the people of the privacy filter's photos, the vehicles of a KITTI street (real
// images), refused models and images; the detector of fusion.vision.detector in a Session.

#include <algorithm>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <map>

#include <unistd.h>

#include <fmt/format.h>
#include <gtest/gtest.h>
#include <nlohmann/json.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "hanzo/fusion/ai/object_detector.hpp"
#include "hanzo/fusion/calib/calibration.hpp"
#include "hanzo/fusion/config/fusion_config.hpp"
#include "hanzo/fusion/pipeline/session.hpp"
#include "vision/odometry_sequences.hpp"

namespace hanzo::fusion::ai {
namespace {

// scripts/install-deps.sh fetches it (make test runs that first).
const std::string kNanodet = std::string(HANZO_SOURCE_DIR) + "/tests/models/nanodet/nanodet.json";
const std::string kPhotos = std::string(HANZO_DATA_DIR) + "/privacy_faces/";

const ObjectDetector& detector() {
  static const std::unique_ptr<ObjectDetector> loaded = [] {
    ObjectDetectorConfig config;
    config.model_path = kNanodet;
    Result<std::unique_ptr<ObjectDetector>> made = ObjectDetector::load(config);
    if (!made) throw std::runtime_error(made.error().message + " (scripts/install-deps.sh fetches the model)");
    return std::move(made).value();
  }();
  return *loaded;
}

std::vector<msgs::Detection2D> of_class(const std::vector<msgs::Detection2D>& detections, const std::string& name) {
  std::vector<msgs::Detection2D> kept;
  std::copy_if(detections.begin(), detections.end(), std::back_inserter(kept), [&name](const msgs::Detection2D& d) { return d.class_name == name; });
  return kept;
}

// Every person in the five photos (counted by eye: 1, 2 and one at the right edge, 1, 2 and a
// girl at the lower right, 2), each box around one of them.
TEST(ObjectDetector, FindsEveryPersonInThePhotos) {
  const std::map<std::string, std::size_t> people = {
      {"alex-lacamoire.png", 1}, {"kit_with_rose.jpg", 3}, {"obama.jpg", 1}, {"obama_and_biden.jpg", 3}, {"two_people.jpg", 2}};
  for (const auto& [file, count] : people) {
    const cv::Mat image = cv::imread(kPhotos + file, cv::IMREAD_COLOR);
    const std::vector<msgs::Detection2D> persons = of_class(detector().detect(image).value(), "person");
    EXPECT_EQ(persons.size(), count) << file;
    for (const msgs::Detection2D& person : persons) {
      EXPECT_GT(person.score, 0.35F);
      EXPECT_LE(person.x_max, image.cols - 1);
      EXPECT_GT(person.x_max - person.x_min, 0.05F * image.cols) << file;
    }
  }
  // two_people.jpg: one person in each half.
  const cv::Mat image = cv::imread(kPhotos + "two_people.jpg", cv::IMREAD_COLOR);
  std::vector<msgs::Detection2D> persons = of_class(detector().detect(image).value(), "person");
  ASSERT_EQ(persons.size(), 2U);
  std::sort(persons.begin(), persons.end(), [](const auto& a, const auto& b) { return a.x_min < b.x_min; });
  EXPECT_LT((persons[0].x_min + persons[0].x_max) / 2, image.cols / 2.0F);
  EXPECT_GT((persons[1].x_min + persons[1].x_max) / 2, image.cols / 2.0F);
}

// The TensorFlow.js graph reader, decoding and suppression agree with an independent PyTorch
// run of the same model (tests/ai/object_detector_reference.py) on 416 x 416 images (the
// network's input: no resize, no tiles): the same objects, scores to 1e-4, boxes to 0.05 px.
TEST(ObjectDetector, AgreesWithAnIndependentPyTorchRun) {
  const cv::Mat street = cv::imread(std::string(HANZO_DATA_DIR) + "/kitti_raw_0052/image_02/0000000060.png", cv::IMREAD_COLOR);
  const std::vector<cv::Mat> sources = {cv::imread(kPhotos + "obama_and_biden.jpg", cv::IMREAD_COLOR), street(cv::Rect(700, 0, 416, 375))};
  for (std::size_t k = 0; k < sources.size(); ++k) {
    cv::Mat image;
    cv::resize(sources[k], image, cv::Size(416, 416), 0, 0, cv::INTER_AREA);
    const std::string path = (std::filesystem::temp_directory_path() / fmt::format("hanzo_detector_ref_{}_{}.png", ::getpid(), k)).string();
    ASSERT_TRUE(cv::imwrite(path, image));
    const std::string command = fmt::format("/usr/bin/python3 tests/ai/object_detector_reference.py {} {}", kNanodet, path);
    FILE* pipe = ::popen(command.c_str(), "r");
    std::string output;
    char buffer[4096];
    while (pipe != nullptr && std::fgets(buffer, sizeof buffer, pipe) != nullptr) output += buffer;
    ASSERT_EQ(pipe == nullptr ? -1 : ::pclose(pipe), 0) << command;
    std::filesystem::remove(path);
    const nlohmann::json reference = nlohmann::json::parse(output);
    const std::vector<msgs::Detection2D> found = detector().detect(image).value();
    ASSERT_EQ(found.size(), reference.size()) << output;
    ASSERT_GE(found.size(), 2U);
    for (std::size_t i = 0; i < found.size(); ++i) {
      EXPECT_EQ(found[i].class_name, coco_class_names()[reference[i][0].get<std::size_t>()]);
      EXPECT_NEAR(found[i].score, reference[i][1].get<double>(), 1e-4);
      EXPECT_NEAR(found[i].x_min, reference[i][2].get<double>(), 0.05);
      EXPECT_NEAR(found[i].y_min, reference[i][3].get<double>(), 0.05);
      EXPECT_NEAR(found[i].x_max, reference[i][4].get<double>(), 0.05);
      EXPECT_NEAR(found[i].y_max, reference[i][5].get<double>(), 0.05);
    }
  }
}

// KITTI raw 0052: a street full of cars and trucks, no pedestrian on the road.
TEST(ObjectDetector, FindsTheVehiclesOfAKittiStreet) {
  const vision::sequences::Sequence sequence = vision::sequences::kitti_raw_0052();
  std::size_t frames_with_vehicles = 0, vehicles = 0, persons = 0;
  for (const std::string& path : sequence.images) {
    const std::vector<msgs::Detection2D> found = detector().detect(cv::imread(path, cv::IMREAD_COLOR)).value();
    std::size_t in_frame = 0;
    for (const msgs::Detection2D& d : found) {
      in_frame += d.class_name == "car" || d.class_name == "truck" || d.class_name == "bus" ? 1 : 0;
      persons += d.class_name == "person" ? 1 : 0;
    }
    vehicles += in_frame;
    frames_with_vehicles += in_frame >= 3 ? 1 : 0;
  }
  std::printf("KITTI raw 0052: %zu vehicles in %zu frames (%zu with 3 or more), %zu persons\n", vehicles, sequence.images.size(), frames_with_vehicles,
              persons);
  EXPECT_EQ(frames_with_vehicles, sequence.images.size());
}

// Refused models: each error names the file and what is wrong.
TEST(ObjectDetector, RefusesMissingTruncatedAndForeignModels) {
  const std::filesystem::path folder = std::filesystem::temp_directory_path() / "hanzo_object_detector_test";
  std::filesystem::remove_all(folder);
  std::filesystem::create_directories(folder);
  const auto load = [](const std::string& path) {
    ObjectDetectorConfig config;
    config.model_path = path;
    Result<std::unique_ptr<ObjectDetector>> made = ObjectDetector::load(config);
    EXPECT_FALSE(made);
    return made ? std::string() : made.error().message;
  };
  EXPECT_NE(load((folder / "none.json").string()).find("no such model file"), std::string::npos);
  // The weights cut short.
  std::filesystem::copy_file(kNanodet, folder / "nanodet.json");
  {
    std::ifstream full(std::filesystem::path(kNanodet).replace_extension(".bin"), std::ios::binary);
    std::string bytes((std::istreambuf_iterator<char>(full)), std::istreambuf_iterator<char>());
    std::ofstream(folder / "nanodet.bin", std::ios::binary).write(bytes.data(), static_cast<std::streamsize>(bytes.size() / 2));
  }
  const std::string truncated = load((folder / "nanodet.json").string());
  EXPECT_NE(truncated.find("the shards have"), std::string::npos) << truncated;
  // An operation the reader does not know, and JSON that is no graph model.
  {
    std::ifstream in(kNanodet);
    std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    const std::size_t at = text.find("\"op\": \"LeakyRelu\"") != std::string::npos ? text.find("\"op\": \"LeakyRelu\"") : text.find("\"op\":\"LeakyRelu\"");
    ASSERT_NE(at, std::string::npos);
    text.replace(text.find("LeakyRelu", at), 9, "Erf");
    std::ofstream(folder / "unknown_op.json") << text;
    std::filesystem::copy_file(std::filesystem::path(kNanodet).replace_extension(".bin"), folder / "nanodet.bin",
                               std::filesystem::copy_options::overwrite_existing);
  }
  const std::string unknown = load((folder / "unknown_op.json").string());
  EXPECT_NE(unknown.find("operation Erf is not supported"), std::string::npos) << unknown;
  std::ofstream(folder / "other.json") << R"({"format": "layers-model", "modelTopology": {}})";
  EXPECT_NE(load((folder / "other.json").string()).find("not a TensorFlow.js graph model"), std::string::npos);
  // A bad image.
  EXPECT_FALSE(detector().detect(cv::Mat()));
  EXPECT_FALSE(detector().detect(cv::Mat(100, 100, CV_32FC1, cv::Scalar(0.5))));
  std::filesystem::remove_all(folder);
}

// fusion.vision.detector in a Session: KITTI raw 0052's first 12 images through the monocular
// visual odometry, each detected, matched and masked; once a vision pipeline's output comes for
// the camera, the Session's detector stops running on it.
TEST(ObjectDetector, RunsInASessionOnACameraWithoutDetections) {
  const vision::sequences::Sequence sequence = vision::sequences::kitti_raw_0052();
  const config::FusionConfig fusion_config = config::parse_fusion_config(R"(fusion:
  vision:
    detector: {type: nanodet, model: )" + kNanodet + R"(}
  sensors:
    cam0: {modality: camera, topic: /cam0, rate: 10.0}
)", "test").value();
  const calib::Calibration calibration = calib::parse_calibration(R"(calibration:
  cam0_to_body:
    rotation: [1.0, 0.0, 0.0, 0.0]
    translation: [0.0, 0.0, 0.0]
    intrinsics: {fx: 721.5377, fy: 721.5377, cx: 609.5593, cy: 172.854, width: 1242, height: 375, distortion_model: none, distortion_coeffs: []}
)", "test").value();
  auto session = pipeline::Session::create(fusion_config, calibration).value();
  const auto image_message = [&](std::size_t i) {
    const cv::Mat image = cv::imread(sequence.images[i], cv::IMREAD_COLOR);
    msgs::ImageMessage message;
    message.timestamp = Timestamp::from_seconds(sequence.times[i]);
    message.frame_id = "cam0";
    message.width = static_cast<uint32_t>(image.cols);
    message.height = static_cast<uint32_t>(image.rows);
    message.encoding = msgs::ImageEncoding::kBgr8;
    message.data.assign(image.data, image.data + image.total() * image.elemSize());
    return message;
  };
  for (std::size_t i = 0; i < 12; ++i) ASSERT_TRUE(session->push("cam0", image_message(i)).ok());
  pipeline::MappingSummary summary = session->mapping_summary();
  std::printf("Session on KITTI raw 0052: %llu images detected (%.0f ms each), %llu masked, %llu moving objects, %.1f %% of a masked image\n",
              static_cast<unsigned long long>(summary.detections_computed), summary.detector_ms, static_cast<unsigned long long>(summary.images_masked),
              static_cast<unsigned long long>(summary.dynamic_objects_masked), 100.0 * summary.masked_image_share);
  EXPECT_EQ(summary.detections_computed, 12U);
  EXPECT_EQ(summary.detector_failures, 0U);
  EXPECT_EQ(summary.detections_matched, 12U);
  EXPECT_EQ(summary.images_masked, 12U);
  EXPECT_GE(summary.dynamic_objects_masked, 36U);  // three or more vehicles in every frame
  EXPECT_GT(summary.detector_ms, 0.0);
  // A vision pipeline's output for the next image: it is used, the Session's detector is not.
  msgs::DetectionsMessage pushed;
  pushed.timestamp = Timestamp::from_seconds(sequence.times[12]);
  pushed.image_width = 1242;
  pushed.image_height = 375;
  pushed.detections.push_back({"person", 0.9F, 100.0F, 100.0F, 200.0F, 300.0F, -1, 0, 0, {}});
  ASSERT_TRUE(session->push("cam0", pushed).ok());
  ASSERT_TRUE(session->push("cam0", image_message(12)).ok());
  summary = session->mapping_summary();
  EXPECT_EQ(summary.detections_computed, 12U);
  EXPECT_EQ(summary.detections_matched, 13U);
  EXPECT_EQ(summary.images_masked, 13U);
}

}  // namespace
}  // namespace hanzo::fusion::ai
