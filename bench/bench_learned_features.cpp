// Learned features (HANZO_FUSION_AI) beside ORB: extraction time of every ALIKED / ALIKE model on a
// 640 x 480 EuRoC frame next to the project's ORB and OpenCV's ORB (1000 keypoints each; the
// learned models keep up to 1000 of their best above the 0.2 score threshold), on the machine's
// cores (libtorch's threads; ORB is single-threaded); and image-pair matching of graf1 against
// graf1 seen from 40 degrees further round (tests/vision/graf_pairs.hpp), with correct matches at
// 3 px and precision as counters: learned features without simulated views, ORB with them.
// Weights from $HANZO_FUSION_MODELS, else ../shared/models. Its own process, apart from
// bench_vision: that one pins OpenCV to one thread, which slowed libtorch, sharing its OpenMP
// runtime, in the same process.

#include <cstdlib>
#include <filesystem>
#include <memory>
#include <string>

#include <benchmark/benchmark.h>
#include <opencv2/features2d.hpp>
#include <opencv2/imgcodecs.hpp>

#include "hanzo/fusion/ai/learned_features.hpp"
#include "hanzo/fusion/vision/image_pair_matcher.hpp"
#include "euroc_frame.hpp"
#include "vision/graf_pairs.hpp"

namespace {

using namespace hanzo::fusion;

using hanzo::fusion::bench::euroc_frame;

std::unique_ptr<ai::LearnedFeatureExtractor> learned(ai::LearnedModel model, int max_keypoints) {
  if (std::getenv("HANZO_FUSION_MODELS") == nullptr) ::setenv("HANZO_FUSION_MODELS", HANZO_MODELS_DIR, 1);
  ai::LearnedFeatureConfig config;
  config.model = model;
  config.max_keypoints = max_keypoints;
  auto extractor = ai::LearnedFeatureExtractor::load(config);
  if (!extractor) throw std::runtime_error(extractor.error().message);
  return std::move(extractor).value();
}

void BM_Extract_Learned(benchmark::State& state, ai::LearnedModel model) {
  const cv::Mat image = euroc_frame();
  const auto extractor = learned(model, 1000);
  std::size_t keypoints = 0;
  for (auto _ : state) keypoints = extractor->extract(image).value().size();
  state.counters["keypoints"] = static_cast<double>(keypoints);
}

void BM_Extract_OrbHanzo(benchmark::State& state) {
  const cv::Mat image = euroc_frame();
  const vision::OrbExtractor extractor;
  std::size_t keypoints = 0;
  for (auto _ : state) keypoints = extractor.extract(image).value().size();
  state.counters["keypoints"] = static_cast<double>(keypoints);
}
BENCHMARK(BM_Extract_OrbHanzo)->Unit(benchmark::kMillisecond);

void BM_Extract_OrbOpenCV(benchmark::State& state) {
  const cv::Mat image = euroc_frame();
  cv::Ptr<cv::ORB> orb = cv::ORB::create(1000);
  std::vector<cv::KeyPoint> keypoints;
  cv::Mat descriptors;
  for (auto _ : state) orb->detectAndCompute(image, cv::noArray(), keypoints, descriptors);
  state.counters["keypoints"] = static_cast<double>(keypoints.size());
}
BENCHMARK(BM_Extract_OrbOpenCV)->Unit(benchmark::kMillisecond);

void report_pair(benchmark::State& state, const vision::ImagePairMatches& matched, const cv::Matx33d& truth) {
  const int correct = vision::count_correct_matches(matched.matches, truth, 3.0);
  state.counters["correct"] = correct;
  state.counters["precision"] = matched.matches.empty() ? 0.0 : static_cast<double>(correct) / static_cast<double>(matched.matches.size());
}

void BM_MatchPair40Degrees_Learned(benchmark::State& state, ai::LearnedModel model) {
  const vision::testing::GrafPair pair = vision::testing::wide_baseline_pair(40.0);
  const auto extractor = learned(model, 2000);
  vision::ImagePairMatcherConfig config;
  config.view_tilts.clear();
  vision::ImagePairMatches matched;
  for (auto _ : state) matched = vision::match_image_pair(pair.image1, pair.image2, config, extractor.get()).value();
  report_pair(state, matched, pair.homography);
}

void BM_MatchPair40Degrees_OrbAffineViews(benchmark::State& state) {
  const vision::testing::GrafPair pair = vision::testing::wide_baseline_pair(40.0);
  vision::ImagePairMatches matched;
  for (auto _ : state) matched = vision::match_image_pair(pair.image1, pair.image2).value();
  report_pair(state, matched, pair.homography);
}
BENCHMARK(BM_MatchPair40Degrees_OrbAffineViews)->Unit(benchmark::kMillisecond);

const int kRegistered = [] {
  for (const ai::LearnedModel model : ai::all_learned_models()) {
    const std::string name(ai::to_string(model));
    benchmark::RegisterBenchmark(("BM_Extract_Learned/" + name).c_str(), BM_Extract_Learned, model)->Unit(benchmark::kMillisecond);
  }
  for (const ai::LearnedModel model : {ai::LearnedModel::kAlikedT16, ai::LearnedModel::kAlikedN16}) {
    const std::string name(ai::to_string(model));
    benchmark::RegisterBenchmark(("BM_MatchPair40Degrees_Learned/" + name).c_str(), BM_MatchPair40Degrees_Learned, model)->Unit(benchmark::kMillisecond);
  }
  return 0;
}();

}  // namespace

BENCHMARK_MAIN();
