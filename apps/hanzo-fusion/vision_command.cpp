// hanzo-fusion vision vocabulary IMAGES... --out V: trains a bag-of-words vocabulary on the ORB
// features of images (vision/vocabulary.hpp).
// hanzo-fusion vision query IMAGE IMAGES... [--vocabulary V]: ranks images by their
// bag-of-words similarity to IMAGE (place recognition; vision/place_database.hpp).
// hanzo-fusion vision relocalize MAP IMAGE --calib CALIB: places a camera image in a saved map's
// visual landmarks (vision/map_relocalizer.hpp), with the features the map was made with.
// IMAGES are image files or folders (their images, recursively, in name order).

#include <algorithm>
#include <filesystem>
#include <memory>
#include <string>
#include <vector>

#include <fmt/format.h>
#include <opencv2/imgcodecs.hpp>

#include "commands.hpp"
#include "image_input.hpp"
#include "hanzo/fusion/calib/calibration.hpp"
#include "hanzo/fusion/io/image_file_check.hpp"
#include "hanzo/fusion/maps/fusion_map_file.hpp"
#include "hanzo/fusion/pipeline/feature_extractors.hpp"
#include "hanzo/fusion/vision/map_relocalizer.hpp"
#include "hanzo/fusion/vision/orb_extractor.hpp"
#include "hanzo/fusion/vision/place_database.hpp"
#include "hanzo/fusion/vision/vocabulary.hpp"

namespace hanzo::fusion::app {
namespace {

struct VocabularyOptions {
  std::vector<std::string> inputs;
  std::string out;
  int branching = vision::VocabularyConfig{}.branching;
  int levels = vision::VocabularyConfig{}.levels;
  int max_features = vision::OrbExtractorConfig{}.max_features;
  int step = 1;
};

struct QueryOptions {
  std::string image;
  std::vector<std::string> inputs;
  std::string vocabulary;  // empty: the default vocabulary
  int max_features = vision::OrbExtractorConfig{}.max_features;
  int top = 5;
};

struct RelocalizeOptions {
  std::string map;
  std::string image;
  std::string calib;
  std::string camera;  // empty: the map's camera
  std::string model;        // learned maps: the detector's weights (empty: found by name)
  std::string place_model;  // learned maps: the VLAD model (empty: the shipped one for the features)
};

Result<cv::Mat> descriptors_of(const std::string& path, const vision::OrbExtractor& extractor) {
  cv::Mat image;
  HANZO_ASSIGN_OR_RETURN(image, read_image_input(path, cv::IMREAD_GRAYSCALE));
  Result<vision::ImageFeatures> features = extractor.extract(image);
  if (!features) return Error(fmt::format("{}: {}", path, features.error().message));
  return features->descriptors;
}

int run_vocabulary(const Output& output, const VocabularyOptions& options) {
  nlohmann::json result = {{"out", options.out}};
  Result<std::vector<std::string>> images = collect_images(options.inputs, options.step);
  if (!images) return report_failure(output, result, images.error().message);
  vision::OrbExtractorConfig features;
  features.max_features = options.max_features;
  const vision::OrbExtractor extractor(features);
  std::vector<cv::Mat> descriptors;
  for (const std::string& path : *images) {
    Result<cv::Mat> described = descriptors_of(path, extractor);
    if (!described) return report_failure(output, result, described.error().message);
    descriptors.push_back(*described);
  }
  vision::VocabularyConfig config;
  config.branching = options.branching;
  config.levels = options.levels;
  vision::VocabularyTrainingSummary summary;
  Result<vision::Vocabulary> vocabulary = vision::Vocabulary::train(descriptors, config, &summary);
  if (!vocabulary) return report_failure(output, result, vocabulary.error().message);
  if (Status saved = vocabulary->save(options.out); !saved) return report_failure(output, result, saved.error().message);
  result["ok"] = true;
  result["images"] = summary.images;
  result["descriptors"] = summary.descriptors;
  result["words"] = summary.words;
  result["branching"] = config.branching;
  result["levels"] = config.levels;
  return report_success(output, result,
                        fmt::format("{}: {} words (branching {}, {} levels) from {} descriptors of {} images\n", options.out, summary.words,
                                    config.branching, config.levels, summary.descriptors, summary.images));
}

int run_query(const Output& output, const QueryOptions& options) {
  nlohmann::json result = {{"image", options.image}};
  Result<vision::Vocabulary> loaded = options.vocabulary.empty() ? vision::Vocabulary::load_default() : vision::Vocabulary::load(options.vocabulary);
  if (!loaded) return report_failure(output, result, loaded.error().message);
  auto vocabulary = std::make_shared<const vision::Vocabulary>(std::move(*loaded));
  Result<std::vector<std::string>> images = collect_images(options.inputs, 1);
  if (!images) return report_failure(output, result, images.error().message);
  vision::OrbExtractorConfig features;
  features.max_features = options.max_features;
  const vision::OrbExtractor extractor(features);
  vision::PlaceDatabase database(vocabulary);
  for (const std::string& path : *images) {
    Result<cv::Mat> described = descriptors_of(path, extractor);
    if (!described) return report_failure(output, result, described.error().message);
    database.add(vocabulary->transform(*described));
  }
  Result<cv::Mat> query = descriptors_of(options.image, extractor);
  if (!query) return report_failure(output, result, query.error().message);
  nlohmann::json ranked = nlohmann::json::array();
  std::string text = fmt::format("{} against {} images ({} words):\n", options.image, images->size(), vocabulary->words());
  for (const vision::PlaceMatch& match : database.query(vocabulary->transform(*query), options.top)) {
    const std::string& path = (*images)[static_cast<std::size_t>(match.entry)];
    ranked.push_back({{"image", path}, {"score", match.score}});
    text += fmt::format("  {:.4f}  {}\n", match.score, path);
  }
  result["ok"] = true;
  result["matches"] = ranked;
  return report_success(output, result, text);
}

nlohmann::json pose_json(const SE3& pose) {
  const Eigen::Quaterniond& q = pose.rotation().quaternion();
  return {{"position", {pose.translation().x(), pose.translation().y(), pose.translation().z()}}, {"orientation_wxyz", {q.w(), q.x(), q.y(), q.z()}}};
}

int run_relocalize(const Output& output, const RelocalizeOptions& options) {
  nlohmann::json result = {{"map", options.map}, {"image", options.image}};
  Result<msgs::FusionMap> map = maps::read_fusion_map(options.map);
  if (!map) return report_failure(output, result, map.error().message);
  if (!map->visual_landmarks) return report_failure(output, result, fmt::format("{}: the map has no visual landmarks layer (made by a run with cameras)", options.map));
  const std::string camera = options.camera.empty() ? map->visual_landmarks->camera : options.camera;
  Result<calib::Calibration> calibration = calib::load_calibration(options.calib);
  if (!calibration) return report_failure(output, result, calibration.error().message);
  const calib::SensorCalibration* sensor = calibration->find(camera);
  if (sensor == nullptr || !sensor->camera) return report_failure(output, result, fmt::format("{}: no intrinsics for camera '{}'", options.calib, camera));
  Result<cv::Mat> read = read_image_input(options.image, cv::IMREAD_GRAYSCALE);
  if (!read) return report_failure(output, result, read.error().message);
  const cv::Mat& image = *read;
  if (image.cols != static_cast<int>(sensor->camera->intrinsics.width) || image.rows != static_cast<int>(sensor->camera->intrinsics.height)) {
    return report_failure(output, result, fmt::format("{}: {} x {} pixels, but camera '{}' is calibrated for {} x {}", options.image, image.cols, image.rows, camera,
                                                      sensor->camera->intrinsics.width, sensor->camera->intrinsics.height));
  }
  vision::MapRelocalizerConfig config;
  const std::string& features = map->visual_landmarks->descriptor_type;
  if (features != "orb") {
    Result<std::shared_ptr<const vision::FeatureExtractor>> extractor =
        pipeline::make_feature_extractor({features, options.model}, config.features.max_features, fmt::format("{} (the map's features)", options.map));
    if (!extractor) return report_failure(output, result, extractor.error().message);
    config.extractor = *extractor;
  }
  if (!options.place_model.empty()) {
    Result<vision::VladModel> model = vision::VladModel::load(options.place_model);
    if (!model) return report_failure(output, result, fmt::format("--place-model {}: {}", options.place_model, model.error().message));
    config.place_model = std::make_shared<const vision::VladModel>(std::move(*model));
  }
  Result<vision::MapRelocalizer> relocalizer = vision::MapRelocalizer::create(*map->visual_landmarks, sensor->camera->pinhole_camera(), config);
  if (!relocalizer) return report_failure(output, result, relocalizer.error().message);
  Result<vision::MapRelocalization> placed = relocalizer->relocalize(image);
  if (!placed) return report_failure(output, result, placed.error().message);
  const SE3 T_world_body = placed->T_world_camera * sensor->T_body_sensor().inverse();
  result["ok"] = true;
  result["camera"] = camera;
  result["T_world_camera"] = pose_json(placed->T_world_camera);
  result["T_world_body"] = pose_json(T_world_body);
  result["inliers"] = placed->inliers;
  result["keyframe"] = placed->keyframe;
  result["score"] = placed->score;
  result["features"] = features;
  result["place_recognition"] = placed->place_recognition;
  const Eigen::Vector3d& p = T_world_body.translation();
  return report_success(output, result,
                        fmt::format("{}: body at ({:.3f}, {:.3f}, {:.3f}) m in {} ({} inliers, near keyframe {})\n", options.image, p.x(), p.y(), p.z(),
                                    options.map, placed->inliers, placed->keyframe));
}

}  // namespace

void add_vision_command(CLI::App& app, const Output& output, Command& run) {
  CLI::App* vision_app = app.add_subcommand("vision", "Visual place recognition (bag-of-words vocabularies, learned VLAD models, queries, recall) and object detection");
  vision_app->require_subcommand(1);

  auto train = std::make_shared<VocabularyOptions>();
  CLI::App* vocabulary = vision_app->add_subcommand("vocabulary", "Train a bag-of-words vocabulary on the ORB features of images");
  vocabulary->add_option("IMAGES", train->inputs, "Image files or folders (searched recursively)")->required();
  vocabulary->add_option("--out", train->out, "Vocabulary file to write")->required();
  vocabulary->add_option("--branching", train->branching, "Children per tree node")->check(CLI::Range(2, 64));
  vocabulary->add_option("--levels", train->levels, "Tree depth (words: branching^levels at most)")->check(CLI::Range(1, 8));
  vocabulary->add_option("--max-features", train->max_features, "ORB keypoints per image")->check(CLI::Range(10, 100000));
  vocabulary->add_option("--step", train->step, "Use every N-th image of each folder")->check(CLI::Range(1, 100000));
  vocabulary->callback([&output, &run, train] { run = [&output, train] { return run_vocabulary(output, *train); }; });

  auto query = std::make_shared<QueryOptions>();
  CLI::App* query_app = vision_app->add_subcommand("query", "Rank images by bag-of-words similarity to one image (place recognition)");
  query_app->add_option("IMAGE", query->image, "The query image")->required();
  query_app->add_option("IMAGES", query->inputs, "Image files or folders to search (recursively)")->required();
  query_app->add_option("--vocabulary", query->vocabulary, "Vocabulary file (default: the one shipped in models/)");
  query_app->add_option("--max-features", query->max_features, "ORB keypoints per image")->check(CLI::Range(10, 100000));
  query_app->add_option("--top", query->top, "How many images to report")->check(CLI::Range(1, 100000));
  query_app->callback([&output, &run, query] { run = [&output, query] { return run_query(output, *query); }; });

  auto relocalize = std::make_shared<RelocalizeOptions>();
  CLI::App* relocalize_app = vision_app->add_subcommand("relocalize", "Place a camera image in a saved map's visual landmarks");
  relocalize_app->add_option("MAP", relocalize->map, "FusionMap file with a visual landmarks layer (from run with cameras)")->required();
  relocalize_app->add_option("IMAGE", relocalize->image, "The camera image")->required();
  relocalize_app->add_option("--calib", relocalize->calib, "Calibration YAML with the camera's intrinsics and extrinsics")->required();
  relocalize_app->add_option("--camera", relocalize->camera, "Camera sensor name (default: the map's)");
  relocalize_app->add_option("--model", relocalize->model, "A learned map's detector weights (.pth; default: found in $HANZO_FUSION_MODELS)");
  relocalize_app->add_option("--place-model", relocalize->place_model, "A learned map's VLAD model (.hzvlad; default: the one shipped for its features)");
  relocalize_app->callback([&output, &run, relocalize] { run = [&output, relocalize] { return run_relocalize(output, *relocalize); }; });

  add_vision_place_commands(*vision_app, output, run);
  add_vision_detect_command(*vision_app, output, run);
}

}  // namespace hanzo::fusion::app
