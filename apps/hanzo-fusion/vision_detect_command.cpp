// hanzo-fusion vision detect IMAGES... [--model nanodet.json]: the object detector of
// fusion.vision.detector (pipeline/camera_detector.hpp) on image files: each object's class,
// score and box; with --draw, the images with their boxes.

#include <filesystem>
#include <map>
#include <memory>
#include <string>
#include <vector>

#include <fmt/format.h>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "commands.hpp"
#include "image_input.hpp"
#include "hanzo/fusion/pipeline/camera_detector.hpp"

namespace hanzo::fusion::app {
namespace {

struct DetectOptions {
  std::vector<std::string> inputs;
  std::string model;
  double score_threshold = config::DetectorSelection{}.score_threshold;
  std::vector<std::string> classes;  // empty: every class
  std::string draw;                  // a folder for the annotated images
};

int run_detect(const Output& output, const DetectOptions& options) {
  nlohmann::json result = {{"command", "vision detect"}};
  std::vector<std::string> images;
  if (Result<std::vector<std::string>> found = collect_images(options.inputs, 1); found) {
    images = std::move(found).value();
  } else {
    return report_failure(output, result, found.error().message);
  }
  config::DetectorSelection selection;
  selection.type = "nanodet";
  selection.model = options.model;
  selection.score_threshold = options.score_threshold;
  Result<std::unique_ptr<pipeline::CameraDetector>> detector = pipeline::CameraDetector::make(selection, "--model");
  if (!detector) return report_failure(output, result, detector.error().message);
  result["model"] = (*detector)->model_path();
  if (!options.draw.empty()) {
    std::error_code error;
    std::filesystem::create_directories(options.draw, error);
    if (error) return report_failure(output, result, fmt::format("--draw {}: cannot create the folder: {}", options.draw, error.message()));
  }
  const auto wanted = [&options](const std::string& name) {
    return options.classes.empty() || std::find(options.classes.begin(), options.classes.end(), name) != options.classes.end();
  };
  nlohmann::json per_image = nlohmann::json::array();
  std::map<std::string, int> class_counts;
  std::string text;
  std::size_t total = 0;
  for (const std::string& path : images) {
    cv::Mat image;
    if (Result<cv::Mat> read = read_image_input(path, cv::IMREAD_COLOR); read) {
      image = std::move(read).value();
    } else {
      return report_failure(output, result, read.error().message);
    }
    Result<std::vector<msgs::Detection2D>> found = (*detector)->detect(image);
    if (!found) return report_failure(output, result, fmt::format("{}: {}", path, found.error().message));
    nlohmann::json boxes = nlohmann::json::array();
    std::vector<std::string> names;
    for (const msgs::Detection2D& detection : *found) {
      if (!wanted(detection.class_name)) continue;
      boxes.push_back({{"class", detection.class_name},
                       {"score", detection.score},
                       {"box", {detection.x_min, detection.y_min, detection.x_max, detection.y_max}}});
      ++class_counts[detection.class_name];
      names.push_back(fmt::format("{} {:.2f}", detection.class_name, detection.score));
      if (!options.draw.empty()) {
        const cv::Rect box(cv::Point(static_cast<int>(detection.x_min), static_cast<int>(detection.y_min)),
                           cv::Point(static_cast<int>(detection.x_max), static_cast<int>(detection.y_max)));
        cv::rectangle(image, box, cv::Scalar(0, 255, 0), 2);
        cv::putText(image, names.back(), box.tl() + cv::Point(2, 14), cv::FONT_HERSHEY_SIMPLEX, 0.5, cv::Scalar(0, 255, 0), 1);
      }
    }
    total += boxes.size();
    per_image.push_back({{"image", path}, {"width", image.cols}, {"height", image.rows}, {"detections", boxes}});
    text += fmt::format("{}: {} object(s){}{}\n", path, boxes.size(), names.empty() ? "" : ": ", fmt::join(names, ", "));
    if (!options.draw.empty()) {
      const std::string drawn = (std::filesystem::path(options.draw) / std::filesystem::path(path).filename()).replace_extension(".png").string();
      if (!cv::imwrite(drawn, image)) return report_failure(output, result, fmt::format("--draw: cannot write {}", drawn));
    }
  }
  result["images"] = per_image;
  result["detections"] = total;
  result["class_counts"] = class_counts;
  text += fmt::format("{} object(s) in {} image(s)", total, images.size());
  for (const auto& [name, count] : class_counts) text += fmt::format(", {} {}", count, name);
  return report_success(output, result, text);
}

}  // namespace

void add_vision_detect_command(CLI::App& vision_app, const Output& output, Command& run) {
  auto options = std::make_shared<DetectOptions>();
  CLI::App* detect = vision_app.add_subcommand("detect", "Detect objects (people, vehicles: 80 COCO classes) in images with NanoDet");
  detect->add_option("IMAGES", options->inputs, "Image files or folders (searched recursively)")->required();
  detect->add_option("--model", options->model, "The detector's nanodet.json (default: found in $HANZO_FUSION_MODELS)");
  detect->add_option("--score-threshold", options->score_threshold, "Report objects scored above this")->check(CLI::Range(0.01, 0.99));
  detect->add_option("--classes", options->classes, "Report only these classes (e.g. --classes person car)");
  detect->add_option("--draw", options->draw, "Write each image with its boxes (PNG) into this folder");
  detect->callback([&output, &run, options] { run = [&output, options] { return run_detect(output, *options); }; });
}

}  // namespace hanzo::fusion::app
