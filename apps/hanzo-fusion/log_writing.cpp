#include "log_writing.hpp"

#include <filesystem>

#include <fmt/format.h>

namespace hanzo::fusion::app {

int write_log(const Output& output, nlohmann::json& result, const LogWriteOptions& options,
              const std::function<Status(io::SensorLogWriter&)>& fill) {
  auto compression = io::mcap::compression_from_name(options.compression);
  if (!compression) return report_failure(output, result, compression.error().message);
  io::SensorLogWriterConfig config;
  config.mcap.compression = *compression;
  config.foxglove_channels = options.foxglove_channels;
  const std::optional<io::ImageCompression> image_compression = io::image_compression_from_string(options.image_compression);
  if (!image_compression) {
    return report_failure(output, result, fmt::format("image compression '{}': expected none, png or jpeg", options.image_compression));
  }
  config.image_compression = *image_compression;
  config.jpeg_quality = options.jpeg_quality;
  config.point_resolution = options.point_resolution;
  if (const std::shared_ptr<ImageRedaction> redaction = options.redaction) {
    config.image_filter = [redaction](msgs::ImageMessage& image) -> Status {
      Result<std::vector<privacy::RedactedRegion>> regions = redaction->filter->apply(image);
      if (!regions) return regions.error();
      privacy::count_regions(*regions, redaction->counts);
      return ok_status();
    };
  }
  const std::string temporary = options.path + ".partial";
  auto writer = io::SensorLogWriter::open(temporary, config);
  if (!writer) return report_failure(output, result, writer.error().message);
  Status status = fill(**writer);
  if (status) status = (*writer)->close();
  if (!status) {
    (void)(*writer)->close();  // the partial file is removed anyway
    std::filesystem::remove(temporary);
    return report_failure(output, result, status.error().message);
  }
  std::error_code ec;
  std::filesystem::rename(temporary, options.path, ec);
  if (ec) return report_failure(output, result, fmt::format("{}: cannot move into place ({})", options.path, ec.message()));
  if (options.redaction) {
    const privacy::TopicRedactionCounts& counts = options.redaction->counts;
    result["privacy"] = {{"redaction", privacy::to_string(options.redaction->filter->config().redaction)},
                         {"face_detector", options.redaction->filter->face_detector()}, {"images", counts.images},
                         {"redacted_images", counts.redacted_images}, {"faces", counts.faces}, {"licence_plates", counts.licence_plates}};
  }
  return 0;
}

}  // namespace hanzo::fusion::app
