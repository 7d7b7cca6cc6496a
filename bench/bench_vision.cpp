// Visual features against OpenCV's own ORB + BFMatcher, one thread each (cv::setNumThreads(1)):
// ORB extraction of 1000 keypoints on a 640 x 480 EuRoC frame, brute-force matching of 1000 x
// 1000 descriptors, and whole image-pair matching with the correct matches and precision at
// 3 px (counters) on the graf pair and on wide-baseline pairs made from graf1 (40 and 70 degrees
// of viewpoint change, tests/vision/graf_pairs.hpp); monocular visual odometry's time per frame;
// place recognition with the default vocabulary: a keyframe's bag of words (2000 descriptors),
// a query against 510 keyframes, and training a vocabulary on 51 images (no bag-of-words
// library for binary descriptors is packaged: DBoW2/3 are not, and OpenCV's BOWKMeansTrainer
// clusters float descriptors only).

#include <chrono>
#include <filesystem>
#include <string>

#include <benchmark/benchmark.h>
#include <opencv2/calib3d.hpp>
#include <opencv2/core/utility.hpp>
#include <opencv2/features2d.hpp>
#include <opencv2/imgcodecs.hpp>

#include "hanzo/fusion/vision/correspondence_filter.hpp"
#include "hanzo/fusion/vision/image_pair_matcher.hpp"
#include "hanzo/fusion/vision/place_database.hpp"
#include "hanzo/fusion/vision/visual_odometry.hpp"
#include "euroc_frame.hpp"
#include "vision/graf_pairs.hpp"

namespace {

using namespace hanzo::fusion::vision;
using testing::GrafPair;

using hanzo::fusion::bench::euroc_frame;

void BM_OrbExtract_Hanzo(benchmark::State& state) {
  const cv::Mat image = euroc_frame();
  const OrbExtractor extractor;
  std::size_t keypoints = 0;
  for (auto _ : state) keypoints = extractor.extract(image).value().size();
  state.counters["keypoints"] = static_cast<double>(keypoints);
}
BENCHMARK(BM_OrbExtract_Hanzo)->Unit(benchmark::kMillisecond);

void BM_OrbExtract_OpenCV(benchmark::State& state) {
  const cv::Mat image = euroc_frame();
  cv::Ptr<cv::ORB> orb = cv::ORB::create(1000);
  std::vector<cv::KeyPoint> keypoints;
  cv::Mat descriptors;
  for (auto _ : state) orb->detectAndCompute(image, cv::noArray(), keypoints, descriptors);
  state.counters["keypoints"] = static_cast<double>(keypoints.size());
}
BENCHMARK(BM_OrbExtract_OpenCV)->Unit(benchmark::kMillisecond);

void BM_MatchDescriptors_Hanzo(benchmark::State& state) {
  const GrafPair pair = testing::graf_pair();
  const ImageFeatures features1 = OrbExtractor().extract(pair.image1).value(), features2 = OrbExtractor().extract(pair.image2).value();
  std::size_t matches = 0;
  for (auto _ : state) matches = match_descriptors(features1.descriptors, features2.descriptors).size();
  state.counters["matches"] = static_cast<double>(matches);
}
BENCHMARK(BM_MatchDescriptors_Hanzo)->Unit(benchmark::kMillisecond);

// knnMatch (k = 2) with the 0.8 ratio test, no mutual check (it would need a second pass).
void BM_MatchDescriptors_OpenCV(benchmark::State& state) {
  const GrafPair pair = testing::graf_pair();
  const ImageFeatures features1 = OrbExtractor().extract(pair.image1).value(), features2 = OrbExtractor().extract(pair.image2).value();
  cv::BFMatcher matcher(cv::NORM_HAMMING);
  std::size_t matches = 0;
  for (auto _ : state) {
    std::vector<std::vector<cv::DMatch>> knn;
    matcher.knnMatch(features1.descriptors, features2.descriptors, knn, 2);
    matches = 0;
    for (const auto& pair_matches : knn) matches += pair_matches.size() == 2 && pair_matches[0].distance < 0.8f * pair_matches[1].distance;
  }
  state.counters["matches"] = static_cast<double>(matches);
}
BENCHMARK(BM_MatchDescriptors_OpenCV)->Unit(benchmark::kMillisecond);

GrafPair pair_for(int degrees) { return degrees == 0 ? testing::graf_pair() : testing::wide_baseline_pair(degrees); }

void report(benchmark::State& state, const std::vector<PointMatch>& matches, const GrafPair& pair) {
  const int correct = count_correct_matches(matches, pair.homography, 3.0);
  state.counters["matches"] = static_cast<double>(matches.size());
  state.counters["correct"] = correct;
  state.counters["precision"] = matches.empty() ? 0.0 : static_cast<double>(correct) / static_cast<double>(matches.size());
}

// Argument: viewpoint change in degrees (0 = the real graf1 -> graf2 pair).
void BM_PairMatch_Hanzo(benchmark::State& state) {
  const GrafPair pair = pair_for(static_cast<int>(state.range(0)));
  std::vector<PointMatch> matches;
  bool affine_views = false;
  for (auto _ : state) {
    ImagePairMatches result = match_image_pair(pair.image1, pair.image2).value();
    matches = std::move(result.matches);
    affine_views = result.affine_views_used;
  }
  report(state, matches, pair);
  state.counters["affine_views"] = affine_views;
}
BENCHMARK(BM_PairMatch_Hanzo)->Arg(0)->Arg(40)->Arg(70)->Unit(benchmark::kMillisecond);

// The putative matches and the geometry from them, no affine views and no guided matching
// (putative_only): ratio test (0.8) + RANSAC against the learned correspondence filter + RANSAC
// (argument 1), at equal features; counters: the putative matches' precision and recall among
// the mutual nearest neighbours' correct ones, and the verified matches.
void BM_PutativeFilter(benchmark::State& state) {
  const GrafPair pair = pair_for(40);
  const bool learned = state.range(0) == 1;
  const OrbExtractor extractor;
  const ImageFeatures features1 = extractor.extract(pair.image1).value(), features2 = extractor.extract(pair.image2).value();
  const CorrespondenceFilter filter = CorrespondenceFilter::load_default().value();
  DescriptorMatcherConfig mutual_only;
  mutual_only.ratio = 1.0;
  auto correct_of = [&](const std::vector<FeatureMatch>& matches) {
    std::vector<PointMatch> points;
    for (const FeatureMatch& m : matches) {
      points.push_back({features1.keypoints[static_cast<std::size_t>(m.query)].pt, features2.keypoints[static_cast<std::size_t>(m.train)].pt, m.distance, m.query, m.train});
    }
    return count_correct_matches(points, pair.homography, 3.0);
  };
  std::vector<FeatureMatch> putative;
  cv::Mat homography;
  for (auto _ : state) {
    putative = learned ? filter.filter(match_descriptors(features1.descriptors, features2.descriptors, mutual_only), features1, features2)
                       : match_descriptors(features1.descriptors, features2.descriptors);
    std::vector<cv::Point2f> points1, points2;
    for (const FeatureMatch& m : putative) {
      points1.push_back(features1.keypoints[static_cast<std::size_t>(m.query)].pt);
      points2.push_back(features2.keypoints[static_cast<std::size_t>(m.train)].pt);
    }
    homography = cv::findHomography(points1, points2, cv::USAC_MAGSAC, 3.0, cv::noArray(), 10000, 0.9999);
  }
  const int correct = correct_of(putative);
  const int reachable = correct_of(match_descriptors(features1.descriptors, features2.descriptors, mutual_only));
  state.counters["putative"] = static_cast<double>(putative.size());
  state.counters["precision"] = putative.empty() ? 0.0 : static_cast<double>(correct) / static_cast<double>(putative.size());
  state.counters["recall"] = reachable == 0 ? 0.0 : static_cast<double>(correct) / reachable;
  state.counters["geometry"] = homography.empty() ? 0 : 1;
}
BENCHMARK(BM_PutativeFilter)->Arg(0)->Arg(1)->Unit(benchmark::kMillisecond);

// OpenCV ORB (1000) + BFMatcher with a plain 0.8 ratio test.
void BM_PairMatch_OpenCV(benchmark::State& state) {
  const GrafPair pair = pair_for(static_cast<int>(state.range(0)));
  cv::Ptr<cv::ORB> orb = cv::ORB::create(1000);
  std::vector<PointMatch> matches;
  for (auto _ : state) {
    std::vector<cv::KeyPoint> keypoints1, keypoints2;
    cv::Mat descriptors1, descriptors2;
    orb->detectAndCompute(pair.image1, cv::noArray(), keypoints1, descriptors1);
    orb->detectAndCompute(pair.image2, cv::noArray(), keypoints2, descriptors2);
    std::vector<std::vector<cv::DMatch>> knn;
    cv::BFMatcher(cv::NORM_HAMMING).knnMatch(descriptors1, descriptors2, knn, 2);
    matches.clear();
    for (const auto& candidates : knn) {
      if (candidates.size() == 2 && candidates[0].distance < 0.8f * candidates[1].distance) {
        matches.push_back({keypoints1[static_cast<std::size_t>(candidates[0].queryIdx)].pt, keypoints2[static_cast<std::size_t>(candidates[0].trainIdx)].pt, 0});
      }
    }
  }
  report(state, matches, pair);
}
BENCHMARK(BM_PairMatch_OpenCV)->Arg(0)->Arg(40)->Arg(70)->Unit(benchmark::kMillisecond);

// Monocular visual odometry over KITTI odometry 06's first 51 frames (1226 x 370, 2000 ORB
// features; a keyframe and a local bundle adjustment nearly every frame at 11 m/s), the
// keyframes' local mapping inline (0) or on its own thread (1): wall time per frame, and
// counters for the tracking thread's own work per frame (time in track() less the waits for
// the mapping) and the mapping's time per keyframe. No peer library on the machine runs visual
// odometry.
void BM_VisualOdometryKitti06Mono(benchmark::State& state) {
  const std::string folder = std::string(HANZO_DATA_DIR) + "/kitti_odometry_06_first51";
  std::vector<cv::Mat> images;
  for (int i = 0; i < 51; ++i) images.push_back(cv::imread(cv::format("%s/image_l/%06d.png", folder.c_str(), i), cv::IMREAD_GRAYSCALE));
  hanzo::fusion::PinholeCamera camera;
  camera.fx = camera.fy = 707.0912;
  camera.cx = 601.8873;
  camera.cy = 183.1104;
  VisualOdometryConfig config;
  config.local_mapping_thread = state.range(0) != 0;
  double tracking_seconds = 0.0, mapping_seconds = 0.0, loop_seconds = 0.0;
  int keyframes = 0, frames = 0;
  for (auto _ : state) {
    auto odometry = VisualOdometry::create(camera, images.front().size(), config).value();
    double in_track = 0.0;
    for (std::size_t i = 0; i < images.size(); ++i) {
      const auto start = std::chrono::steady_clock::now();
      benchmark::DoNotOptimize(odometry->track(0.1 * static_cast<double>(i), images[i]));
      in_track += std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    }
    const VisualOdometrySummary summary = odometry->summary();  // waits for the last mapping
    tracking_seconds += in_track - summary.mapping_wait_seconds;
    mapping_seconds += summary.mapping_seconds;
    loop_seconds += summary.loop_seconds;
    keyframes += summary.keyframes;
    frames += static_cast<int>(images.size());
  }
  state.SetItemsProcessed(state.iterations() * static_cast<int64_t>(images.size()));  // frames per second (wall clock)
  state.counters["keyframes"] = static_cast<double>(keyframes) / static_cast<double>(state.iterations());
  state.counters["tracking_ms"] = 1000.0 * tracking_seconds / frames;
  state.counters["mapping_ms"] = 1000.0 * mapping_seconds / keyframes;
  state.counters["loop_ms"] = 1000.0 * loop_seconds / keyframes;
}
BENCHMARK(BM_VisualOdometryKitti06Mono)->Arg(0)->Arg(1)->Unit(benchmark::kMillisecond)->Iterations(2)->UseRealTime();

std::vector<cv::Mat> kitti06_descriptors(int features) {
  OrbExtractorConfig config;
  config.max_features = features;
  const OrbExtractor extractor(config);
  std::vector<cv::Mat> descriptors;
  for (int i = 0; i < 51; ++i) {
    const cv::Mat image = cv::imread(cv::format("%s/kitti_odometry_06_first51/image_l/%06d.png", HANZO_DATA_DIR, i), cv::IMREAD_GRAYSCALE);
    descriptors.push_back(extractor.extract(image).value().descriptors);
  }
  return descriptors;
}

void BM_BagOfWordsTransform(benchmark::State& state) {
  const Vocabulary vocabulary = Vocabulary::load_default().value();
  const cv::Mat descriptors = kitti06_descriptors(2000).front();
  FeatureVector features;
  for (auto _ : state) benchmark::DoNotOptimize(vocabulary.transform(descriptors, &features));
  state.counters["descriptors"] = descriptors.rows;
}
BENCHMARK(BM_BagOfWordsTransform)->Unit(benchmark::kMillisecond);

void BM_PlaceQuery510Keyframes(benchmark::State& state) {
  auto vocabulary = std::make_shared<const Vocabulary>(Vocabulary::load_default().value());
  std::vector<BowVector> bows;
  for (const cv::Mat& descriptors : kitti06_descriptors(2000)) bows.push_back(vocabulary->transform(descriptors));
  PlaceDatabase database(vocabulary);
  for (int copy = 0; copy < 10; ++copy) {
    for (const BowVector& bow : bows) database.add(bow);
  }
  for (auto _ : state) benchmark::DoNotOptimize(database.query(bows[25], 3));
  state.counters["entries"] = database.size();
}
BENCHMARK(BM_PlaceQuery510Keyframes)->Unit(benchmark::kMillisecond);

void BM_VocabularyTraining51Images(benchmark::State& state) {
  const std::vector<cv::Mat> descriptors = kitti06_descriptors(1000);
  int words = 0;
  for (auto _ : state) words = Vocabulary::train(descriptors).value().words();
  state.counters["words"] = words;
}
BENCHMARK(BM_VocabularyTraining51Images)->Unit(benchmark::kMillisecond)->Iterations(1);

}  // namespace

int main(int argc, char** argv) {
  cv::setNumThreads(1);
  benchmark::Initialize(&argc, argv);
  benchmark::RunSpecifiedBenchmarks();
  benchmark::Shutdown();
  return 0;
}
