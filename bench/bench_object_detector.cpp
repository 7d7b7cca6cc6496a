// The object detector (NanoDet on the TensorFlow.js graph reader, ai/object_detector.hpp) against
// the person detectors OpenCV ships (the HOG + linear SVM pedestrian detector of Dalal & Triggs,
// and the Haar full-body cascade of Debian's opencv-data): time per image on the privacy
// filter's photos and on KITTI raw 0052's street frames; counters: people found / expected and
// extra on the photos, false people and vehicles on the 78 street frames (no pedestrian there);
// the street's visual odometry with the detector's boxes masked.

#include <algorithm>
#include <filesystem>
#include <functional>
#include <memory>
#include <string>
#include <vector>

#include <benchmark/benchmark.h>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <opencv2/objdetect.hpp>

#include "hanzo/fusion/ai/object_detector.hpp"
#include "hanzo/fusion/eval/pose_error.hpp"
#include "hanzo/fusion/pipeline/dynamic_mask.hpp"
#include "vision/odometry_sequences.hpp"

namespace {

using namespace hanzo::fusion;

struct Photo {
  std::string file;
  int people;
};
// Counted by eye, people at the photos' edges included.
const std::vector<Photo> kPhotos{{"obama.jpg", 1}, {"two_people.jpg", 2}, {"obama_and_biden.jpg", 3}, {"kit_with_rose.jpg", 3}, {"alex-lacamoire.png", 1}};
const std::string kFullBodyCascade = "/usr/share/opencv4/haarcascades/haarcascade_fullbody.xml";

std::vector<cv::Mat> photos() {
  std::vector<cv::Mat> images;
  for (const Photo& photo : kPhotos) images.push_back(cv::imread(std::string(HANZO_DATA_DIR) + "/privacy_faces/" + photo.file));
  return images;
}

std::vector<cv::Mat> street() {
  std::vector<std::string> paths;
  for (const auto& entry : std::filesystem::directory_iterator(std::string(HANZO_DATA_DIR) + "/kitti_raw_0052/image_02")) paths.push_back(entry.path());
  std::sort(paths.begin(), paths.end());
  std::vector<cv::Mat> images;
  for (const std::string& path : paths) images.push_back(cv::imread(path));
  return images;
}

struct Counts {
  int people = 0;
  int vehicles = 0;
};
using Detect = std::function<Counts(const cv::Mat&)>;

void run(benchmark::State& state, const Detect& detect, bool on_street) {
  const std::vector<cv::Mat> timed = on_street ? street() : photos();
  for (auto _ : state) {
    for (const cv::Mat& image : timed) benchmark::DoNotOptimize(detect(image));
  }
  state.SetItemsProcessed(state.iterations() * static_cast<int64_t>(timed.size()));
  if (on_street) {
    int people = 0, vehicles = 0;
    for (const cv::Mat& image : timed) {
      const Counts counts = detect(image);
      people += counts.people;
      vehicles += counts.vehicles;
    }
    state.counters["street_false_people"] = people;
    state.counters["street_vehicles"] = vehicles;
    return;
  }
  int found = 0, extra = 0, expected = 0;
  for (std::size_t i = 0; i < kPhotos.size(); ++i) {
    const int people = detect(timed[i]).people;
    found += std::min(people, kPhotos[i].people);
    extra += std::max(0, people - kPhotos[i].people);
    expected += kPhotos[i].people;
  }
  state.counters["photo_people_found"] = found;
  state.counters["photo_people_expected"] = expected;
  state.counters["photo_extra"] = extra;
}

Detect nanodet(int max_tiles) {
  ai::ObjectDetectorConfig config;
  config.model_path = std::string(HANZO_SOURCE_DIR) + "/tests/models/nanodet/nanodet.json";
  config.max_tiles = max_tiles;
  std::shared_ptr<ai::ObjectDetector> detector = ai::ObjectDetector::load(config).value();
  return [detector](const cv::Mat& image) {
    Counts counts;
    const std::vector<msgs::Detection2D> found = detector->detect(image).value();
    for (const msgs::Detection2D& d : found) {
      counts.people += d.class_name == "person" ? 1 : 0;
      counts.vehicles += d.class_name == "car" || d.class_name == "truck" || d.class_name == "bus" ? 1 : 0;
    }
    return counts;
  };
}

Detect hog() {
  auto descriptor = std::make_shared<cv::HOGDescriptor>();
  descriptor->setSVMDetector(cv::HOGDescriptor::getDefaultPeopleDetector());
  return [descriptor](const cv::Mat& image) {
    std::vector<cv::Rect> found;
    descriptor->detectMultiScale(image, found, 0.0, cv::Size(8, 8), cv::Size(), 1.05, 2.0);
    return Counts{static_cast<int>(found.size()), 0};
  };
}

Detect full_body_cascade() {
  auto cascade = std::make_shared<cv::CascadeClassifier>(kFullBodyCascade);
  return [cascade](const cv::Mat& image) {
    cv::Mat grey;
    cv::cvtColor(image, grey, cv::COLOR_BGR2GRAY);
    std::vector<cv::Rect> found;
    cascade->detectMultiScale(grey, found, 1.1, 3, 0, cv::Size(24, 48));
    return Counts{static_cast<int>(found.size()), 0};
  };
}

void BM_NanoDetPhotos(benchmark::State& state) { run(state, nanodet(4), false); }
void BM_NanoDetStreet(benchmark::State& state) { run(state, nanodet(4), true); }
void BM_NanoDetStreetNoTiles(benchmark::State& state) { run(state, nanodet(1), true); }
void BM_OpenCvHogPhotos(benchmark::State& state) { run(state, hog(), false); }
void BM_OpenCvHogStreet(benchmark::State& state) { run(state, hog(), true); }
void BM_OpenCvFullBodyCascadePhotos(benchmark::State& state) { run(state, full_body_cascade(), false); }
void BM_OpenCvFullBodyCascadeStreet(benchmark::State& state) { run(state, full_body_cascade(), true); }
// KITTI raw 0052's monocular visual odometry with every box of the moving classes masked (the
// Session's default classes) and unmasked: counters Sim3-aligned APE (m) and tracked frames.
void BM_KittiRaw0052OdometryMaskedByNanoDet(benchmark::State& state) {
  ai::ObjectDetectorConfig detector_config;
  detector_config.model_path = std::string(HANZO_SOURCE_DIR) + "/tests/models/nanodet/nanodet.json";
  const std::unique_ptr<ai::ObjectDetector> detector = ai::ObjectDetector::load(detector_config).value();
  const vision::sequences::Sequence sequence = vision::sequences::kitti_raw_0052();
  const config::DynamicObjectsConfig classes;
  double masked_share = 0.0;
  const auto mask_of = [&](const cv::Mat& image) {
    msgs::DetectionsMessage detections;
    detections.image_width = static_cast<uint32_t>(image.cols);
    detections.image_height = static_cast<uint32_t>(image.rows);
    detections.detections = detector->detect(image).value();
    const pipeline::DynamicMask mask = pipeline::dynamic_mask(detections, image.size(), classes).value();
    masked_share += mask.masked_share;
    return vision::StaticMask{mask.static_mask};
  };
  const auto ape = [&](const io::Trajectory& estimate) {
    eval::ApeConfig config;
    config.alignment = eval::Alignment::kSim3;
    return eval::compute_ape(vision::sequences::at_times(sequence.ground_truth, estimate), estimate, config).value().statistics.rmse;
  };
  for (auto _ : state) {
    const vision::sequences::RunResult plain = vision::sequences::run(sequence);
    const vision::sequences::RunResult masked = vision::sequences::run(sequence, {}, mask_of);
    state.counters["ape_unmasked_m"] = ape(plain.estimate);
    state.counters["ape_masked_m"] = ape(masked.estimate);
    state.counters["frames_unmasked"] = static_cast<double>(plain.estimate.size());
    state.counters["frames_masked"] = static_cast<double>(masked.estimate.size());
    state.counters["masked_share"] = masked_share / static_cast<double>(sequence.images.size());
  }
}

BENCHMARK(BM_NanoDetPhotos)->Unit(benchmark::kMillisecond)->Iterations(2);
BENCHMARK(BM_NanoDetStreet)->Unit(benchmark::kMillisecond)->Iterations(1);
BENCHMARK(BM_NanoDetStreetNoTiles)->Unit(benchmark::kMillisecond)->Iterations(1);
BENCHMARK(BM_OpenCvHogPhotos)->Unit(benchmark::kMillisecond)->Iterations(2);
BENCHMARK(BM_OpenCvHogStreet)->Unit(benchmark::kMillisecond)->Iterations(1);
BENCHMARK(BM_OpenCvFullBodyCascadePhotos)->Unit(benchmark::kMillisecond)->Iterations(2);
BENCHMARK(BM_OpenCvFullBodyCascadeStreet)->Unit(benchmark::kMillisecond)->Iterations(1);
BENCHMARK(BM_KittiRaw0052OdometryMaskedByNanoDet)->Unit(benchmark::kMillisecond)->Iterations(1);

}  // namespace

BENCHMARK_MAIN();
