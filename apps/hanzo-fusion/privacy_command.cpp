// hanzo-fusion privacy blur IN OUT: faces and licence plates in an image file, every image of a
// folder, or every camera image of a sensor log (MCAP) blurred or blacked out
// (privacy/privacy_filter.hpp), with the regions reported.

#include <filesystem>
#include <memory>
#include <string>
#include <vector>

#include <fmt/format.h>
#include <opencv2/imgcodecs.hpp>

#include "commands.hpp"
#include "image_input.hpp"
#include "hanzo/fusion/crypto/file_encryption.hpp"
#include "hanzo/fusion/io/image_file_check.hpp"
#include "hanzo/fusion/privacy/log_redaction.hpp"

namespace hanzo::fusion::app {
namespace {

struct PrivacyOptions {
  std::string input;
  std::string output;
  std::string redaction = "blur";
  bool no_faces = false;
  bool no_plates = false;
  std::string face_model;
  double score_threshold = privacy::PrivacyFilterConfig{}.face_score_threshold;
  std::string image_compression = "png";  // logs: how the written log stores images
};

bool is_log_file(const std::filesystem::path& path) { return path.extension() == ".mcap"; }
// A sensor log to read: .mcap, or any file encrypted at rest (logs are what is encrypted).
bool is_input_log(const std::filesystem::path& path) { return is_log_file(path) || crypto::is_encrypted_file(path.string()); }

// A sensor log (privacy/log_redaction.hpp).
int redact_log_file(const Output& output, nlohmann::json result, privacy::PrivacyFilter& filter, const PrivacyOptions& options) {
  const std::optional<io::ImageCompression> compression = io::image_compression_from_string(options.image_compression);
  if (!compression) return report_failure(output, result, fmt::format("--image-compression: unknown '{}' (none, png, jpeg)", options.image_compression));
  io::SensorLogWriterConfig writer_config;
  writer_config.image_compression = *compression;
  Result<privacy::LogRedactionSummary> summary = privacy::redact_log(filter, options.input, options.output, writer_config);
  if (!summary) return report_failure(output, result, summary.error().message);
  const auto counts_json = [](const privacy::TopicRedactionCounts& c) {
    return nlohmann::json{{"images", c.images}, {"redacted_images", c.redacted_images}, {"faces", c.faces}, {"licence_plates", c.licence_plates}};
  };
  result["ok"] = true;
  result["redaction"] = options.redaction;
  result["messages"] = summary->messages;
  result.update(counts_json(summary->total));
  if (summary->input_warning) result["input_warning"] = *summary->input_warning;
  result["topics"] = nlohmann::json::object();
  for (const auto& [topic, counts] : summary->by_topic) result["topics"][topic] = counts_json(counts);
  const privacy::TopicRedactionCounts& total = summary->total;
  return report_success(output, result,
                        fmt::format("{} -> {}: {} messages, {} camera images, {} with regions {}: {} face(s), {} licence plate(s)\n",
                                    options.input, options.output, summary->messages, total.images, total.redacted_images,
                                    options.redaction == "blur" ? "blurred" : "blacked out", total.faces, total.licence_plates) +
                            (summary->input_warning ? fmt::format("warning: {}\n", *summary->input_warning) : std::string()));
}


// One image: read, redact, write (the output's extension picks its format). Nothing is written
// when any step fails.
Result<nlohmann::json> redact_file(privacy::PrivacyFilter& filter, const std::filesystem::path& input, const std::filesystem::path& output) {
  if (!cv::haveImageWriter(output.string())) {
    return Error(fmt::format("{}: no image format for the extension '{}' (png, jpg, bmp, tif...)", output.string(), output.extension().string()));
  }
  // A decoder fills what a cut-off file lacks: a face in the missing part would be written as
  // it is, so an incomplete file is refused.
  cv::Mat image;
  HANZO_ASSIGN_OR_RETURN(image, read_image_input(input.string(), cv::IMREAD_COLOR));
  std::vector<privacy::RedactedRegion> regions;
  HANZO_ASSIGN_OR_RETURN(regions, with_context(filter.apply(image), input.string()));
  bool written = false;
  try {
    written = cv::imwrite(output.string(), image);
  } catch (const cv::Exception& error) {
    return Error(fmt::format("{}: cannot write: {}", output.string(), error.msg));
  }
  if (!written) return Error(fmt::format("{}: cannot write (unknown image extension or unwritable folder)", output.string()));
  nlohmann::json boxes = nlohmann::json::array();
  privacy::TopicRedactionCounts counts;
  privacy::count_regions(regions, counts);
  for (const privacy::RedactedRegion& region : regions) {
    boxes.push_back({{"kind", region.kind}, {"x", region.box.x}, {"y", region.box.y}, {"width", region.box.width},
                     {"height", region.box.height}, {"score", region.score}});
  }
  return nlohmann::json{{"input", input.string()}, {"output", output.string()}, {"width", image.cols}, {"height", image.rows},
                        {"faces", counts.faces}, {"licence_plates", counts.licence_plates}, {"regions", boxes}};
}

int run_blur(const Output& output, const PrivacyOptions& options) {
  nlohmann::json result = {{"input", options.input}, {"output", options.output}};
  privacy::PrivacyFilterConfig config;
  Result<privacy::Redaction> redaction = privacy::parse_redaction(options.redaction);
  if (!redaction) return report_failure(output, result, "--redaction: " + redaction.error().message);
  config.redaction = *redaction;
  config.faces = !options.no_faces;
  config.licence_plates = !options.no_plates;
  config.face_model_path = options.face_model;
  config.face_score_threshold = options.score_threshold;
  Result<std::unique_ptr<privacy::PrivacyFilter>> filter = privacy::PrivacyFilter::create(config);
  if (!filter) return report_failure(output, result, filter.error().message);
  result["face_detector"] = (*filter)->face_detector();

  if (is_input_log(options.input)) {
    if (!std::filesystem::is_regular_file(options.input)) return report_failure(output, result, fmt::format("{}: no such file", options.input));
    if (!is_log_file(options.output)) return report_failure(output, result, fmt::format("{}: a sensor log is written to a .mcap file", options.output));
    return redact_log_file(output, result, **filter, options);
  }
  std::vector<std::pair<std::filesystem::path, std::filesystem::path>> jobs;
  std::error_code error;
  if (std::filesystem::is_directory(options.input, error)) {
    for (const auto& entry : std::filesystem::directory_iterator(options.input)) {
      if (entry.is_regular_file() && io::has_image_extension(entry.path().string())) jobs.emplace_back(entry.path(), std::filesystem::path(options.output) / entry.path().filename());
    }
    std::sort(jobs.begin(), jobs.end());
    if (jobs.empty()) return report_failure(output, result, fmt::format("{}: no image files in the folder", options.input));
    std::filesystem::create_directories(options.output, error);  // only once there is something to write
    if (error) return report_failure(output, result, fmt::format("cannot create {}: {}", options.output, error.message()));
  } else if (std::filesystem::is_regular_file(options.input, error)) {
    jobs.emplace_back(options.input, options.output);
  } else {
    return report_failure(output, result, fmt::format("{}: no such file or folder", options.input));
  }

  nlohmann::json images = nlohmann::json::array();
  int faces = 0, plates = 0;
  std::string text;
  for (const auto& [input, destination] : jobs) {
    Result<nlohmann::json> done = redact_file(**filter, input, destination);
    if (!done) return report_failure(output, result, done.error().message);
    faces += (*done)["faces"].get<int>();
    plates += (*done)["licence_plates"].get<int>();
    text += fmt::format("{} -> {}: {} face(s), {} licence plate(s) {}\n", input.string(), destination.string(), (*done)["faces"].get<int>(),
                        (*done)["licence_plates"].get<int>(), options.redaction == "blur" ? "blurred" : "blacked out");
    images.push_back(std::move(done).value());
  }
  result["ok"] = true;
  result["redaction"] = options.redaction;
  result["faces"] = faces;
  result["licence_plates"] = plates;
  result["images"] = images;
  return report_success(output, result, text);
}

}  // namespace

void add_privacy_command(CLI::App& app, const Output& output, Command& run) {
  CLI::App* privacy_command = app.add_subcommand("privacy", "Privacy filter for camera images (faces, licence plates)");
  privacy_command->require_subcommand(1);
  auto options = std::make_shared<PrivacyOptions>();
  CLI::App* blur = privacy_command->add_subcommand("blur", "Blur (or black out) faces and licence plates in an image, a folder of images or a sensor log");
  blur->add_option("IN", options->input, "Image file, folder of image files, or sensor log (.mcap)")->required();
  blur->add_option("OUT", options->output, "Output image file (its extension picks the format), folder, or sensor log (.mcap)")->required();
  blur->add_option("--image-compression", options->image_compression, "Sensor logs: how the output stores images: png (default), jpeg or none");
  blur->add_option("--redaction", options->redaction, "blur (default) or black")->check(CLI::IsMember({"blur", "black"}));
  blur->add_flag("--no-faces", options->no_faces, "Do not look for faces");
  blur->add_flag("--no-plates", options->no_plates, "Do not look for licence plates");
  blur->add_option("--face-model", options->face_model, "YuNet ONNX model (default: face_detection_yunet.onnx in $HANZO_FUSION_MODELS; without it OpenCV's Haar cascade)");
  blur->add_option("--score-threshold", options->score_threshold, "Face score threshold in [0, 1]")->check(CLI::Range(0.0, 1.0));
  blur->callback([&output, &run, options] { run = [&output, options] { return run_blur(output, *options); }; });
}

}  // namespace hanzo::fusion::app
