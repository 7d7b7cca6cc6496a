// hanzo-fusion features match IMG1 IMG2: ORB features of two images matched and verified by a
// robust geometry (vision/image_pair_matcher.hpp); with a ground-truth homography, the correct
// matches and the precision at a pixel threshold.

#include <cmath>
#include <filesystem>
#include <fstream>
#include <memory>
#include <string>

#include <fmt/format.h>
#include <opencv2/features2d.hpp>
#include <opencv2/imgcodecs.hpp>

#include "commands.hpp"
#include "image_input.hpp"
#include "hanzo/fusion/pipeline/feature_extractors.hpp"
#include "hanzo/fusion/vision/correspondence_filter.hpp"
#include "hanzo/fusion/vision/image_pair_matcher.hpp"

namespace hanzo::fusion::app {
namespace {

struct MatchOptions {
  std::string image1;
  std::string image2;
  std::string homography;  // ground truth, 3x3 row-major text
  std::string geometry = "auto";
  std::string draw;
  int max_features = vision::OrbExtractorConfig{}.max_features;
  double threshold_px = 3.0;
  bool no_affine_views = false;
  std::string detector = "orb";
  std::string model;  // learned detectors: the weights (.pth)
  std::string matcher = "ratio";
  std::string filter_model;  // --matcher learned: the filter's weights (default: the trained one)
  std::string putative_out;  // training data of the correspondence filter
};

// The mutual nearest neighbours of the pair (no ratio test: what the correspondence filter
// classifies) as rows of the filter's inputs, with a label when the true homography is known
// (1: within threshold_px of it). The data `make train-correspondence-filter` learns from.
Status write_putative_matches(const std::string& path, const vision::ImagePairMatches& matched, const vision::ImagePairMatcherConfig& config,
                              const std::optional<cv::Matx33d>& truth, double threshold_px) {
  vision::DescriptorMatcherConfig mutual_only = config.descriptors;
  mutual_only.ratio = 1.0;
  mutual_only.float_ratio = 1.0;
  std::ofstream out(path);
  if (!out) return Error(fmt::format("--putative-out {}: cannot write", path));
  out << "image_1_x,image_1_y,image_2_x,image_2_y,distance,ratio,correct\n";
  for (const vision::FeatureMatch& match : vision::match_descriptors(matched.features1.descriptors, matched.features2.descriptors, mutual_only)) {
    for (const float value : vision::correspondence_inputs(match, matched.features1, matched.features2)) out << fmt::format("{},", value);
    if (truth) {
      const vision::PointMatch point{matched.features1.keypoints[static_cast<std::size_t>(match.query)].pt,
                                     matched.features2.keypoints[static_cast<std::size_t>(match.train)].pt, match.distance, match.query, match.train};
      out << vision::count_correct_matches({point}, *truth, threshold_px);
    }
    out << "\n";
  }
  if (!out) return Error(fmt::format("--putative-out {}: write failed", path));
  return ok_status();
}

// The detector named by --detector: null for ORB (the matcher's own), else a learned one.
Result<std::shared_ptr<const vision::FeatureExtractor>> make_detector(const MatchOptions& options) {
  if (options.detector == "orb") {
    if (!options.model.empty()) return Error("--model: ORB takes no model (give --detector aliked-t16, ...)");
    return std::shared_ptr<const vision::FeatureExtractor>();
  }
  return pipeline::make_feature_extractor({options.detector, options.model}, options.max_features, "--detector");
}

// Nine numbers, row-major, image-1 pixels to image-2 pixels (the Oxford data sets' format).
Result<cv::Matx33d> read_homography(const std::string& path) {
  std::ifstream file(path);
  if (!file) return Error(fmt::format("{}: cannot open", path));
  cv::Matx33d homography;
  for (int i = 0; i < 9; ++i) {
    if (!(file >> homography.val[i])) return Error(fmt::format("{}: expected 9 numbers (a 3x3 homography, row-major), read {}", path, i));
    if (!std::isfinite(homography.val[i])) return Error(fmt::format("{}: value {} is not finite", path, i + 1));
  }
  std::string extra;
  if (file >> extra) return Error(fmt::format("{}: more than 9 numbers ('{}' after the matrix)", path, extra));
  if (std::abs(cv::determinant(homography)) < 1e-12) return Error(fmt::format("{}: the homography is singular", path));
  return homography;
}

nlohmann::json matrix_json(const cv::Matx33d& matrix) {
  nlohmann::json rows = nlohmann::json::array();
  for (int r = 0; r < 3; ++r) rows.push_back({matrix(r, 0), matrix(r, 1), matrix(r, 2)});
  return rows;
}

int run_match(const Output& output, const MatchOptions& options) {
  nlohmann::json result = {{"image1", options.image1}, {"image2", options.image2}};
  Result<cv::Mat> image1 = read_image_input(options.image1, cv::IMREAD_COLOR);
  if (!image1) return report_failure(output, result, image1.error().message);
  Result<cv::Mat> image2 = read_image_input(options.image2, cv::IMREAD_COLOR);
  if (!image2) return report_failure(output, result, image2.error().message);
  std::optional<cv::Matx33d> truth;
  if (!options.homography.empty()) {
    Result<cv::Matx33d> read = read_homography(options.homography);
    if (!read) return report_failure(output, result, "--homography: " + read.error().message);
    truth = *read;
  }
  Result<std::shared_ptr<const vision::FeatureExtractor>> detector = make_detector(options);
  if (!detector) return report_failure(output, result, detector.error().message);
  result["detector"] = options.detector;
  vision::ImagePairMatcherConfig config;
  config.features.max_features = options.max_features;
  config.ransac_threshold_px = options.threshold_px;
  config.geometry = options.geometry == "homography"    ? vision::PairGeometry::kHomography
                    : options.geometry == "fundamental" ? vision::PairGeometry::kFundamental
                                                        : vision::PairGeometry::kAuto;
  if (options.no_affine_views || *detector) config.view_tilts.clear();  // learned features need no simulated views
  result["matcher"] = options.matcher;
  if (options.matcher == "learned") {
    Result<vision::CorrespondenceFilter> filter = options.filter_model.empty() ? vision::CorrespondenceFilter::load_default()
                                                                                : vision::CorrespondenceFilter::load(options.filter_model);
    if (!filter) return report_failure(output, result, filter.error().message);
    config.putative_filter = std::make_shared<const vision::CorrespondenceFilter>(std::move(filter).value());
  } else if (!options.filter_model.empty()) {
    return report_failure(output, result, "--filter-model: give --matcher learned too");
  }
  Result<vision::ImagePairMatches> matched = vision::match_image_pair(*image1, *image2, config, detector->get());
  if (!matched) return report_failure(output, result, matched.error().message);

  result["ok"] = true;
  result["keypoints1"] = matched->features1.size();
  result["keypoints2"] = matched->features2.size();
  result["putative_matches"] = matched->putative.size();
  result["matches"] = matched->matches.size();
  result["geometry_found"] = matched->geometry_found;
  result["affine_views_used"] = matched->affine_views_used;
  std::string text = fmt::format("{} -> {}: {} / {} keypoints, {} putative matches, {} {}\n", options.image1, options.image2,
                                 matched->features1.size(), matched->features2.size(), matched->putative.size(), matched->matches.size(),
                                 matched->geometry_found ? "verified matches (putative, affine-view and guided matches that fit the geometry)"
                                                         : "matches (no geometry found: unverified)");
  if (matched->geometry_found) {
    const char* model = matched->model == vision::GeometryModel::kHomography ? "homography" : "fundamental";
    result["geometry"] = {{"model", model}, {"matrix", matrix_json(matched->geometry)}};
    text += fmt::format("geometry: {}{}\n", model, matched->affine_views_used ? " (found with affine views: wide baseline)" : "");
  }
  if (truth) {
    const int correct = vision::count_correct_matches(matched->matches, *truth, options.threshold_px);
    const double precision = matched->matches.empty() ? 0.0 : static_cast<double>(correct) / static_cast<double>(matched->matches.size());
    result["ground_truth"] = {{"correct", correct}, {"precision", precision}, {"threshold_px", options.threshold_px}};
    text += fmt::format("ground truth: {} correct within {} px, precision {:.1f} %\n", correct, options.threshold_px, 100.0 * precision);
  }
  if (!options.putative_out.empty()) {
    if (Status written = write_putative_matches(options.putative_out, *matched, config, truth, options.threshold_px); !written) {
      return report_failure(output, result, written.error().message);
    }
    result["putative_out"] = options.putative_out;
  }
  if (!options.draw.empty()) {
    std::vector<cv::KeyPoint> points1, points2;
    std::vector<cv::DMatch> lines;
    for (const vision::PointMatch& match : matched->matches) {
      lines.emplace_back(static_cast<int>(points1.size()), static_cast<int>(points2.size()), static_cast<float>(match.distance));
      points1.emplace_back(match.point1, 7.0f);
      points2.emplace_back(match.point2, 7.0f);
    }
    cv::Mat canvas;
    cv::drawMatches(*image1, points1, *image2, points2, lines, canvas);
    bool written = false;
    try {
      written = cv::imwrite(options.draw, canvas);
    } catch (const cv::Exception& error) {
      return report_failure(output, result, fmt::format("--draw {}: cannot write: {}", options.draw, error.msg));
    }
    if (!written) return report_failure(output, result, fmt::format("--draw {}: cannot write (unknown image extension or unwritable folder)", options.draw));
    result["drawing"] = options.draw;
  }
  return report_success(output, result, text);
}

}  // namespace

void add_features_command(CLI::App& app, const Output& output, Command& run) {
  CLI::App* features = app.add_subcommand("features", "Image features: ORB or learned (ALIKED, ALIKE) extraction and matching");
  features->require_subcommand(1);
  auto options = std::make_shared<MatchOptions>();
  CLI::App* match = features->add_subcommand("match", "Match two images (ORB or learned features, ratio + mutual test, robust geometry, guided matching)");
  match->add_option("IMG1", options->image1, "First image")->required();
  match->add_option("IMG2", options->image2, "Second image")->required();
  match->add_option("--homography", options->homography,
                    "Ground-truth homography IMG1 -> IMG2 (9 numbers, row-major): report correct matches and precision");
  match->add_option("--detector", options->detector,
                    "Keypoints and descriptors: orb (default) or a learned model: aliked-t16, aliked-n16, aliked-n16rot, aliked-n32, "
                    "alike-t, alike-s, alike-n, alike-l (its weights from --model or $HANZO_FUSION_MODELS)")
      ->capture_default_str();
  match->add_option("--model", options->model, "Learned detectors: the model file (.pth)");
  match->add_option("--max-features", options->max_features, "Keypoints per image (at most)")->check(CLI::Range(1, 100000));
  match->add_option("--matcher", options->matcher,
                    "Putative matches: ratio (Lowe's ratio test, default) or learned (the trained correspondence filter on the mutual "
                    "nearest neighbours)")
      ->check(CLI::IsMember({"ratio", "learned"}))
      ->capture_default_str();
  match->add_option("--filter-model", options->filter_model, "--matcher learned: the filter's weights (default: models/trained/correspondence_filter.json)");
  match->add_option("--putative-out", options->putative_out,
                    "Write the mutual nearest neighbours as the correspondence filter's inputs (CSV; a `correct` label with --homography)");
  match->add_option("--threshold", options->threshold_px, "Pixels: geometry verification and ground-truth check")->check(CLI::Range(0.1, 100.0));
  match->add_option("--geometry", options->geometry, "auto (default), homography or fundamental")
      ->check(CLI::IsMember({"auto", "homography", "fundamental"}));
  match->add_flag("--no-affine-views", options->no_affine_views, "Do not simulate affine views when the first geometry is weak (ORB; learned detectors never do)");
  match->add_option("--draw", options->draw, "Write an image of the matches (its extension picks the format)");
  match->callback([&output, &run, options] { run = [&output, options] { return run_match(output, *options); }; });
}

}  // namespace hanzo::fusion::app
