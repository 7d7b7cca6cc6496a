// hanzo-fusion vision vlad INPUTS... --out M: trains a VLAD place-recognition model (cluster
// centres and whitened projection, vision/vlad.hpp) on the learned descriptors of images.
// hanzo-fusion vision place-recall: recall@1 / @5 of place recognition by bag of words (ORB) and
// by VLAD (learned) in one run, database images against query images of the same places taken
// at another time (another lighting, season), each placed by its ground-truth trajectory.
// INPUTS are sensor logs (.mcap: every --every-th image of --topic, default the first image
// topic) or image files and folders.

#include <algorithm>
#include <chrono>
#include <filesystem>
#include <memory>
#include <string>
#include <vector>

#include <fmt/format.h>
#include <opencv2/calib3d.hpp>
#include <opencv2/imgcodecs.hpp>

#include "commands.hpp"
#include "image_input.hpp"
#include "hanzo/fusion/io/sensor_log.hpp"
#include "hanzo/fusion/io/trajectory.hpp"
#include "hanzo/fusion/pipeline/feature_extractors.hpp"
#include "hanzo/fusion/vision/feature_matcher.hpp"
#include "hanzo/fusion/vision/image_message.hpp"
#include "hanzo/fusion/vision/place_database.hpp"
#include "hanzo/fusion/vision/vlad.hpp"
#include "hanzo/fusion/vision/vocabulary.hpp"

namespace hanzo::fusion::app {
namespace {

struct VladOptions {
  std::vector<std::string> inputs;
  std::string out;
  std::string detector = "aliked-t16";
  std::string model;
  std::string topic;
  int every = 5;
  int max_features = 1000;
  int clusters = vision::VladConfig{}.clusters;
  int dimensions = vision::VladConfig{}.dimensions;
};

struct PlaceRecallOptions {
  std::string database, database_poses, queries, query_poses;
  std::string vlad;        // the VLAD model (its detector is the one it was trained on)
  std::string model;       // the detector's weights (default: found in $HANZO_FUSION_MODELS)
  std::string vocabulary;  // empty: the default bag-of-words vocabulary
  std::string topic;
  int every = 5;
  int max_features = 1000;
  double radius = 10.0;
};

struct PlaceImage {
  std::string source;  // "log.mcap@12.300" or the image file
  Timestamp time;      // log images only
  cv::Mat grey;
};

// Every `every`-th image of the log's `topic` (the first image topic when empty), as grey.
Result<std::vector<PlaceImage>> read_log_images(const std::string& path, std::string topic, int every) {
  auto reader = io::SensorLogReader::open(path);
  if (!reader) return reader.error();
  std::vector<PlaceImage> images;
  io::LogEntry entry;
  int seen = 0;
  while (true) {
    Result<bool> more = (*reader)->next(entry);
    if (!more) return Error(fmt::format("{}: {}", path, more.error().message));
    if (!*more) break;
    const auto* sensor_message = std::get_if<msgs::SensorMessage>(&entry.message);
    const auto* image = sensor_message ? std::get_if<msgs::ImageMessage>(sensor_message) : nullptr;
    if (image == nullptr || image->encoding == msgs::ImageEncoding::kDepth16 || image->encoding == msgs::ImageEncoding::kDepth32f) continue;
    if (topic.empty()) topic = entry.topic;
    if (entry.topic != topic || seen++ % every != 0) continue;
    Result<cv::Mat> grey = vision::grey_image(*image);
    if (!grey) return Error(fmt::format("{}: {} at {:.3f} s: {}", path, topic, image->timestamp.seconds(), grey.error().message));
    images.push_back({fmt::format("{}@{:.3f}", path, image->timestamp.seconds()), image->timestamp, std::move(grey).value()});
  }
  if (images.empty()) return Error(fmt::format("{}: no images{}", path, topic.empty() ? "" : " on " + topic));
  return images;
}

// The images of every input: logs (.mcap) as read_log_images, image files and folders read whole.
Result<std::vector<PlaceImage>> read_inputs(const std::vector<std::string>& inputs, const std::string& topic, int every) {
  std::vector<PlaceImage> images;
  for (const std::string& input : inputs) {
    if (std::filesystem::path(input).extension() == ".mcap") {
      Result<std::vector<PlaceImage>> from_log = read_log_images(input, topic, every);
      if (!from_log) return from_log.error();
      std::move(from_log->begin(), from_log->end(), std::back_inserter(images));
      continue;
    }
    Result<std::vector<std::string>> files = collect_images({input}, every);
    if (!files) return files.error();
    for (const std::string& file : *files) {
      Result<cv::Mat> grey = read_image_input(file, cv::IMREAD_GRAYSCALE);
      if (!grey) return grey.error();
      images.push_back({file, Timestamp(), std::move(grey).value()});
    }
  }
  return images;
}

Result<std::vector<vision::ImageFeatures>> extract_all(const std::vector<PlaceImage>& images, const vision::FeatureExtractor& extractor, double* seconds) {
  std::vector<vision::ImageFeatures> all;
  const auto start = std::chrono::steady_clock::now();
  for (const PlaceImage& image : images) {
    Result<vision::ImageFeatures> features = extractor.extract(image.grey);
    if (!features) return Error(fmt::format("{}: {}", image.source, features.error().message));
    all.push_back(std::move(features).value());
  }
  *seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return all;
}

// Geometric verification of a candidate: the mutual nearest-neighbour matches of the two images
// that a RANSAC fundamental matrix (3 px) keeps.
int verified_matches(const vision::ImageFeatures& a, const vision::ImageFeatures& b) {
  vision::DescriptorMatcherConfig mutual_only;
  mutual_only.ratio = mutual_only.float_ratio = 1.0;
  std::vector<cv::Point2f> points_a, points_b;
  for (const vision::FeatureMatch& match : vision::match_descriptors(a.descriptors, b.descriptors, mutual_only)) {
    points_a.push_back(a.keypoints[static_cast<std::size_t>(match.query)].pt);
    points_b.push_back(b.keypoints[static_cast<std::size_t>(match.train)].pt);
  }
  if (points_a.size() < 8) return 0;
  std::vector<uchar> inliers;
  cv::findFundamentalMat(points_a, points_b, cv::FM_RANSAC, 3.0, 0.999, inliers);
  return static_cast<int>(std::count(inliers.begin(), inliers.end(), 1));
}

// The candidates re-ranked by verified matches (the global ranking breaks ties).
std::vector<int> rerank(std::vector<int> candidates, const vision::ImageFeatures& query, const std::vector<vision::ImageFeatures>& database) {
  std::vector<std::pair<int, int>> scored;  // (-verified, rank)
  for (std::size_t rank = 0; rank < candidates.size(); ++rank) {
    scored.emplace_back(-verified_matches(query, database[static_cast<std::size_t>(candidates[rank])]), static_cast<int>(rank));
  }
  std::sort(scored.begin(), scored.end());
  std::vector<int> reranked;
  for (const auto& [verified, rank] : scored) reranked.push_back(candidates[static_cast<std::size_t>(rank)]);
  return reranked;
}

int run_vlad(const Output& output, const VladOptions& options) {
  nlohmann::json result = {{"out", options.out}, {"detector", options.detector}};
  Result<std::shared_ptr<const vision::FeatureExtractor>> extractor =
      pipeline::make_feature_extractor({options.detector, options.model}, options.max_features, "--detector");
  if (!extractor) return report_failure(output, result, extractor.error().message);
  if ((*extractor)->descriptor_type() != CV_32FC1) return report_failure(output, result, "--detector orb: VLAD aggregates learned (float) descriptors; ORB's place recognition is the bag of words (vision vocabulary)");
  Result<std::vector<PlaceImage>> images = read_inputs(options.inputs, options.topic, options.every);
  if (!images) return report_failure(output, result, images.error().message);
  double seconds = 0.0;
  Result<std::vector<vision::ImageFeatures>> features = extract_all(*images, **extractor, &seconds);
  if (!features) return report_failure(output, result, features.error().message);
  std::vector<cv::Mat> descriptors;
  for (const vision::ImageFeatures& image : *features) descriptors.push_back(image.descriptors);
  vision::VladConfig config;
  config.clusters = options.clusters;
  config.dimensions = options.dimensions;
  Result<vision::VladModel> model = vision::VladModel::train(descriptors, (*extractor)->name(), config);
  if (!model) return report_failure(output, result, model.error().message);
  if (Status saved = model->save(options.out); !saved) return report_failure(output, result, saved.error().message);
  result["ok"] = true;
  result["images"] = model->training_images();
  result["clusters"] = model->clusters();
  result["dimensions"] = model->dimensions();
  return report_success(output, result,
                        fmt::format("{}: VLAD of {} {} descriptors ({} clusters, projected to {} dimensions) trained on {} images\n", options.out,
                                    model->descriptor_size(), model->extractor_name(), model->clusters(), model->dimensions(), model->training_images()));
}

// Each image's position from the trajectory: the pose nearest in time within 0.1 s; images
// without one are dropped (counted).
std::vector<Eigen::Vector3d> place_images(std::vector<PlaceImage>& images, const io::Trajectory& trajectory, int* dropped) {
  std::vector<Eigen::Vector3d> positions;
  std::vector<PlaceImage> kept;
  for (PlaceImage& image : images) {
    const auto after = std::lower_bound(trajectory.timestamps.begin(), trajectory.timestamps.end(), image.time);
    std::optional<std::size_t> nearest;
    for (auto it : {after, after == trajectory.timestamps.begin() ? after : after - 1}) {
      if (it == trajectory.timestamps.end() || std::abs((*it - image.time).seconds()) > 0.1) continue;
      const auto index = static_cast<std::size_t>(it - trajectory.timestamps.begin());
      if (!nearest || std::abs((*it - image.time).seconds()) < std::abs((trajectory.timestamps[*nearest] - image.time).seconds())) nearest = index;
    }
    if (!nearest) {
      ++*dropped;
      continue;
    }
    positions.push_back(trajectory.poses[*nearest].block<3, 1>(0, 3));
    kept.push_back(std::move(image));
  }
  images = std::move(kept);
  return positions;
}

struct Recall {
  int queries = 0;
  int at_1 = 0;
  int at_5 = 0;
  double seconds_per_image = 0.0;
  nlohmann::json json() const {
    return {{"queries", queries}, {"recall_at_1", queries > 0 ? static_cast<double>(at_1) / queries : 0.0},
            {"recall_at_5", queries > 0 ? static_cast<double>(at_5) / queries : 0.0}, {"ms_per_image", 1000.0 * seconds_per_image}};
  }
};

// Recall of a ranking: a query counts when it has a database image within `radius`; it is found
// at k when one of its k best-ranked database images is within `radius`.
void count(Recall& recall, const std::vector<int>& ranked, const Eigen::Vector3d& query, const std::vector<Eigen::Vector3d>& database, double radius) {
  ++recall.queries;
  for (std::size_t k = 0; k < std::min<std::size_t>(5, ranked.size()); ++k) {
    if ((database[static_cast<std::size_t>(ranked[k])] - query).norm() > radius) continue;
    if (k == 0) ++recall.at_1;
    ++recall.at_5;
    break;
  }
}

int run_place_recall(const Output& output, const PlaceRecallOptions& options) {
  nlohmann::json result = {{"database", options.database}, {"queries", options.queries}, {"radius_m", options.radius}};
  Result<vision::VladModel> vlad = vision::VladModel::load(options.vlad);
  if (!vlad) return report_failure(output, result, vlad.error().message);
  Result<std::shared_ptr<const vision::FeatureExtractor>> learned =
      pipeline::make_feature_extractor({vlad->extractor_name(), options.model}, options.max_features, "--vlad's detector");
  if (!learned) return report_failure(output, result, learned.error().message);
  Result<vision::Vocabulary> vocabulary = options.vocabulary.empty() ? vision::Vocabulary::load_default() : vision::Vocabulary::load(options.vocabulary);
  if (!vocabulary) return report_failure(output, result, vocabulary.error().message);
  auto shared_vocabulary = std::make_shared<const vision::Vocabulary>(std::move(vocabulary).value());
  Result<std::shared_ptr<const vision::FeatureExtractor>> orb = pipeline::make_feature_extractor({"orb", ""}, 2 * options.max_features, "orb");
  if (!orb) return report_failure(output, result, orb.error().message);

  struct Side {
    std::vector<PlaceImage> images;
    std::vector<Eigen::Vector3d> positions;
    std::vector<vision::ImageFeatures> orb, learned;
  };
  Side sides[2];
  int dropped = 0;
  double orb_seconds = 0.0, learned_seconds = 0.0;
  for (int s = 0; s < 2; ++s) {
    const std::string& log = s == 0 ? options.database : options.queries;
    const std::string& poses = s == 0 ? options.database_poses : options.query_poses;
    Result<std::vector<PlaceImage>> images = read_log_images(log, options.topic, options.every);
    if (!images) return report_failure(output, result, images.error().message);
    Result<io::Trajectory> trajectory = io::read_trajectory(poses, io::TrajectoryFormat::kTum);
    if (!trajectory) return report_failure(output, result, trajectory.error().message);
    sides[s].images = std::move(images).value();
    sides[s].positions = place_images(sides[s].images, *trajectory, &dropped);
    double seconds = 0.0;
    Result<std::vector<vision::ImageFeatures>> described = extract_all(sides[s].images, **orb, &seconds);
    if (!described) return report_failure(output, result, described.error().message);
    sides[s].orb = std::move(described).value();
    orb_seconds += seconds;
    described = extract_all(sides[s].images, **learned, &seconds);
    if (!described) return report_failure(output, result, described.error().message);
    sides[s].learned = std::move(described).value();
    learned_seconds += seconds;
  }
  const Side& database = sides[0];
  const Side& queries = sides[1];
  if (database.images.empty() || queries.images.empty()) return report_failure(output, result, "no images with a ground-truth pose on one side");

  // Bag of words (ORB) and VLAD (learned), each ranking the whole database per query.
  vision::PlaceDatabase places(shared_vocabulary);
  std::vector<Eigen::VectorXf> database_vlad;
  const auto describe_start = std::chrono::steady_clock::now();
  for (std::size_t i = 0; i < database.images.size(); ++i) {
    places.add(shared_vocabulary->transform(database.orb[i].descriptors));
    database_vlad.push_back(vlad->describe(database.learned[i].descriptors).value());
  }
  Recall bow, learned_recall, bow_verified, learned_verified;
  int without_match = 0;
  for (std::size_t q = 0; q < queries.images.size(); ++q) {
    const bool has_match = std::any_of(database.positions.begin(), database.positions.end(),
                                       [&](const Eigen::Vector3d& p) { return (p - queries.positions[q]).norm() <= options.radius; });
    if (!has_match) {
      ++without_match;
      continue;
    }
    std::vector<int> ranked;
    for (const vision::PlaceMatch& match : places.query(shared_vocabulary->transform(queries.orb[q].descriptors), 5)) ranked.push_back(match.entry);
    count(bow, ranked, queries.positions[q], database.positions, options.radius);
    count(bow_verified, rerank(ranked, queries.orb[q], database.orb), queries.positions[q], database.positions, options.radius);
    const Eigen::VectorXf query = vlad->describe(queries.learned[q].descriptors).value();
    std::vector<std::pair<float, int>> scored;
    for (std::size_t d = 0; d < database_vlad.size(); ++d) scored.emplace_back(-vision::VladModel::similarity(query, database_vlad[d]), static_cast<int>(d));
    std::partial_sort(scored.begin(), scored.begin() + std::min<std::ptrdiff_t>(5, static_cast<std::ptrdiff_t>(scored.size())), scored.end());
    ranked.clear();
    for (std::size_t k = 0; k < std::min<std::size_t>(5, scored.size()); ++k) ranked.push_back(scored[k].second);
    count(learned_recall, ranked, queries.positions[q], database.positions, options.radius);
    count(learned_verified, rerank(ranked, queries.learned[q], database.learned), queries.positions[q], database.positions, options.radius);
  }
  const double aggregation = std::chrono::duration<double>(std::chrono::steady_clock::now() - describe_start).count();
  const double images = static_cast<double>(database.images.size() + queries.images.size());
  bow.seconds_per_image = bow_verified.seconds_per_image = orb_seconds / images;
  learned_recall.seconds_per_image = learned_verified.seconds_per_image = learned_seconds / images;
  result["ok"] = true;
  result["database_images"] = database.images.size();
  result["query_images"] = queries.images.size();
  result["queries_without_a_database_image_in_radius"] = without_match;
  result["images_without_ground_truth"] = dropped;
  result["bow"] = bow.json();
  result["bow"]["features"] = "orb";
  result["learned"] = learned_recall.json();
  result["learned"]["features"] = vlad->extractor_name();
  result["bow_verified"] = bow_verified.json();
  result["learned_verified"] = learned_verified.json();
  result["ranking_seconds"] = aggregation;
  std::string text = fmt::format("{} queries against {} database images (radius {} m; {} queries without a database image that near, {} images without ground truth):\n",
                                 bow.queries, database.images.size(), options.radius, without_match, dropped);
  for (const auto& [name, recall] : {std::pair<std::string, const Recall*>{"bag of words (orb)", &bow},
                                     {"  + verified top 5", &bow_verified},
                                     {fmt::format("VLAD ({})", vlad->extractor_name()), &learned_recall},
                                     {"  + verified top 5", &learned_verified}}) {
    const nlohmann::json j = recall->json();
    text += fmt::format("  {:<22} recall@1 {:.3f}  recall@5 {:.3f}  features {:.1f} ms per image\n", name, j["recall_at_1"].get<double>(),
                        j["recall_at_5"].get<double>(), j["ms_per_image"].get<double>());
  }
  return report_success(output, result, text);
}

}  // namespace

void add_vision_place_commands(CLI::App& vision_app, const Output& output, Command& run) {
  auto train = std::make_shared<VladOptions>();
  CLI::App* vlad = vision_app.add_subcommand("vlad", "Train a VLAD place-recognition model on the learned descriptors of images");
  vlad->add_option("INPUTS", train->inputs, "Sensor logs (.mcap) or image files and folders")->required();
  vlad->add_option("--out", train->out, "Model file to write")->required();
  vlad->add_option("--detector", train->detector, "Learned detector: aliked-t16, aliked-n16, ..., alike-t, ...");
  vlad->add_option("--model", train->model, "The detector's weights (.pth; default: found in $HANZO_FUSION_MODELS)");
  vlad->add_option("--topic", train->topic, "Logs: the image topic (default: the first)");
  vlad->add_option("--every", train->every, "Every N-th image of a log or folder")->check(CLI::Range(1, 100000));
  vlad->add_option("--max-features", train->max_features, "Keypoints per image")->check(CLI::Range(10, 100000));
  vlad->add_option("--clusters", train->clusters, "Cluster centres")->check(CLI::Range(2, 1024));
  vlad->add_option("--dimensions", train->dimensions, "Dimensions of the projected descriptor")->check(CLI::Range(1, 65536));
  vlad->callback([&output, &run, train] { run = [&output, train] { return run_vlad(output, *train); }; });

  auto recall = std::make_shared<PlaceRecallOptions>();
  CLI::App* recall_app = vision_app.add_subcommand("place-recall", "Recall of bag-of-words and learned (VLAD) place recognition: queries against a database");
  recall_app->add_option("--database", recall->database, "Sensor log of the database images")->required();
  recall_app->add_option("--database-poses", recall->database_poses, "Its ground truth (TUM)")->required();
  recall_app->add_option("--queries", recall->queries, "Sensor log of the query images (the same places at another time)")->required();
  recall_app->add_option("--query-poses", recall->query_poses, "Its ground truth (TUM)")->required();
  recall_app->add_option("--vlad", recall->vlad, "VLAD model (vision vlad)")->required();
  recall_app->add_option("--model", recall->model, "The VLAD detector's weights (.pth; default: found in $HANZO_FUSION_MODELS)");
  recall_app->add_option("--vocabulary", recall->vocabulary, "Bag-of-words vocabulary (default: the one shipped in models/)");
  recall_app->add_option("--topic", recall->topic, "The image topic (default: the first)");
  recall_app->add_option("--every", recall->every, "Every N-th image of each log")->check(CLI::Range(1, 100000));
  recall_app->add_option("--max-features", recall->max_features, "Learned keypoints per image (ORB: twice as many)")->check(CLI::Range(10, 100000));
  recall_app->add_option("--radius", recall->radius, "Metres: a database image this near the query is the same place")->check(CLI::PositiveNumber);
  recall_app->callback([&output, &run, recall] { run = [&output, recall] { return run_place_recall(output, *recall); }; });
}

}  // namespace hanzo::fusion::app
