// The privacy filter's face detector (YuNet through cv::dnn) against OpenCV's Haar frontal-face
// cascade (Debian's opencv-data), the detector most pipelines reach for: time per image on the
// test photos and a KITTI street frame, and the faces each finds (counters: found / expected on
// the photos, false faces on 78 KITTI frames).

#include <algorithm>
#include <filesystem>
#include <string>
#include <vector>

#include <benchmark/benchmark.h>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <opencv2/objdetect.hpp>

#include "hanzo/fusion/privacy/privacy_filter.hpp"

namespace {

using namespace hanzo::fusion;

struct Photo {
  std::string file;
  int faces;
};
const std::vector<Photo> kPhotos{{"obama.jpg", 1}, {"two_people.jpg", 2}, {"obama_and_biden.jpg", 3}, {"kit_with_rose.jpg", 2}, {"alex-lacamoire.png", 1}};
const std::string kFaceCascade = "/usr/share/opencv4/haarcascades/haarcascade_frontalface_default.xml";

std::vector<cv::Mat> load(const std::vector<std::string>& paths) {
  std::vector<cv::Mat> images;
  for (const std::string& path : paths) images.push_back(cv::imread(path));
  return images;
}

std::vector<std::string> photo_paths() {
  std::vector<std::string> paths;
  for (const Photo& photo : kPhotos) paths.push_back(std::string(HANZO_DATA_DIR) + "/privacy_faces/" + photo.file);
  return paths;
}

std::vector<std::string> street_paths() {
  std::vector<std::string> paths;
  for (const auto& entry : std::filesystem::directory_iterator(std::string(HANZO_DATA_DIR) + "/kitti_raw_0052/image_02")) {
    paths.push_back(entry.path().string());
  }
  std::sort(paths.begin(), paths.end());
  return paths;
}

// Faces found per image by each detector.
std::vector<int> yunet_faces(privacy::PrivacyFilter& filter, const std::vector<cv::Mat>& images) {
  std::vector<int> counts;
  for (const cv::Mat& image : images) counts.push_back(static_cast<int>(filter.detect(image).value().size()));
  return counts;
}

std::vector<int> haar_faces(cv::CascadeClassifier& cascade, const std::vector<cv::Mat>& images) {
  std::vector<int> counts;
  for (const cv::Mat& image : images) {
    cv::Mat grey;
    cv::cvtColor(image, grey, cv::COLOR_BGR2GRAY);
    cv::equalizeHist(grey, grey);
    std::vector<cv::Rect> faces;
    cascade.detectMultiScale(grey, faces, 1.1, 3, 0, cv::Size(24, 24));
    counts.push_back(static_cast<int>(faces.size()));
  }
  return counts;
}

void report(benchmark::State& state, const std::vector<int>& photos, const std::vector<int>& street) {
  int found = 0, extra = 0, expected = 0;
  for (std::size_t i = 0; i < kPhotos.size(); ++i) {
    found += std::min(photos[i], kPhotos[i].faces);
    extra += std::max(0, photos[i] - kPhotos[i].faces);
    expected += kPhotos[i].faces;
  }
  state.counters["photo_faces_found"] = found;
  state.counters["photo_faces_expected"] = expected;
  state.counters["photo_extra"] = extra;
  int street_faces = 0;
  for (const int count : street) street_faces += count;
  state.counters["street_false_faces"] = street_faces;
}

void BM_YunetPhotos(benchmark::State& state) {
  privacy::PrivacyFilterConfig config;
  config.licence_plates = false;
  config.face_model_path = std::string(HANZO_MODELS_DIR) + "/yunet/face_detection_yunet.onnx";
  auto filter = privacy::PrivacyFilter::create(config).value();
  const std::vector<cv::Mat> photos = load(photo_paths());
  for (auto _ : state) benchmark::DoNotOptimize(yunet_faces(*filter, photos));
  report(state, yunet_faces(*filter, photos), yunet_faces(*filter, load(street_paths())));
  state.SetItemsProcessed(state.iterations() * static_cast<int64_t>(photos.size()));
}
BENCHMARK(BM_YunetPhotos)->Unit(benchmark::kMillisecond)->Iterations(3);

void BM_HaarCascadePhotos(benchmark::State& state) {
  cv::CascadeClassifier cascade(kFaceCascade);
  const std::vector<cv::Mat> photos = load(photo_paths());
  for (auto _ : state) benchmark::DoNotOptimize(haar_faces(cascade, photos));
  report(state, haar_faces(cascade, photos), haar_faces(cascade, load(street_paths())));
  state.SetItemsProcessed(state.iterations() * static_cast<int64_t>(photos.size()));
}
BENCHMARK(BM_HaarCascadePhotos)->Unit(benchmark::kMillisecond)->Iterations(3);

// One KITTI frame (1242 x 375) through the whole filter (faces and plates).
void BM_PrivacyFilterStreetFrame(benchmark::State& state) {
  auto filter = privacy::PrivacyFilter::create({}).value();
  const cv::Mat frame = cv::imread(street_paths().front());
  for (auto _ : state) {
    cv::Mat image = frame.clone();
    benchmark::DoNotOptimize(filter->apply(image));
  }
}
BENCHMARK(BM_PrivacyFilterStreetFrame)->Unit(benchmark::kMillisecond);

}  // namespace

BENCHMARK_MAIN();
