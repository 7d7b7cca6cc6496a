#include "hanzo/fusion/io/image_folder_import.hpp"

#include <algorithm>
#include <cctype>
#include <filesystem>
#include <map>
#include <sstream>

#include <fmt/format.h>

#include "hanzo/fusion/core/files.hpp"
#include "hanzo/fusion/io/image_file_check.hpp"
#include "hanzo/fusion/io/trajectory.hpp"
#include "image_files.hpp"
#include "text_lines.hpp"

namespace hanzo::fusion::io {
namespace {

namespace fs = std::filesystem;

// Name order with digit runs compared as numbers: "frame9" < "frame10", "000009" < "000010".
bool natural_less(const std::string& a, const std::string& b) {
  std::size_t i = 0, j = 0;
  while (i < a.size() && j < b.size()) {
    if (std::isdigit(static_cast<unsigned char>(a[i])) && std::isdigit(static_cast<unsigned char>(b[j]))) {
      std::size_t end_a = i, end_b = j;
      while (end_a < a.size() && std::isdigit(static_cast<unsigned char>(a[end_a]))) ++end_a;
      while (end_b < b.size() && std::isdigit(static_cast<unsigned char>(b[end_b]))) ++end_b;
      std::string_view run_a(a.data() + i, end_a - i), run_b(b.data() + j, end_b - j);
      while (run_a.size() > 1 && run_a.front() == '0') run_a.remove_prefix(1);
      while (run_b.size() > 1 && run_b.front() == '0') run_b.remove_prefix(1);
      if (run_a.size() != run_b.size()) return run_a.size() < run_b.size();
      if (run_a != run_b) return run_a < run_b;
      i = end_a;
      j = end_b;
    } else {
      if (a[i] != b[j]) return a[i] < b[j];
      ++i;
      ++j;
    }
  }
  return a.size() - i < b.size() - j;
}

Result<std::vector<fs::path>> list_images(const std::string& folder) {
  std::error_code error;
  if (!fs::is_directory(folder, error)) return Error(fmt::format("{}: not a folder", folder));
  std::vector<fs::path> images;
  for (const fs::directory_entry& entry : fs::directory_iterator(folder, error)) {
    if (entry.is_regular_file() && has_image_extension(entry.path().string())) images.push_back(entry.path());
  }
  if (error) return Error(fmt::format("{}: {}", folder, error.message()));
  if (images.empty()) return Error(fmt::format("{}: no image files (png, jpg, bmp, tif, pgm, ppm, webp)", folder));
  std::sort(images.begin(), images.end(), [](const fs::path& a, const fs::path& b) { return natural_less(a.filename().string(), b.filename().string()); });
  return images;
}

// The time a file name stands for: >= 16 digits are nanoseconds, a decimal number seconds.
std::optional<Timestamp> time_of_name(const fs::path& path) {
  const std::string stem = path.stem().string();
  if (stem.empty()) return std::nullopt;
  const bool all_digits = std::all_of(stem.begin(), stem.end(), [](unsigned char c) { return std::isdigit(c); });
  if (all_digits && stem.size() >= 16 && stem.size() <= 19) return Timestamp::from_nanoseconds(std::stoll(stem));
  if (std::count(stem.begin(), stem.end(), '.') == 1 && stem.front() != '.' && stem.back() != '.' &&
      std::all_of(stem.begin(), stem.end(), [](unsigned char c) { return std::isdigit(c) || c == '.'; })) {
    if (Result<Timestamp> seconds = parse_seconds(stem)) return *seconds;
  }
  return std::nullopt;
}

Timestamp absolute(Timestamp time, double origin) {
  return time.seconds() < 1e8 ? Timestamp::from_seconds(origin) + Duration::from_nanoseconds(time.nanoseconds()) : time;
}

// Times from a times file; reorders `images` when the lines name the files.
Result<std::vector<Timestamp>> read_times(const std::string& path, std::vector<fs::path>& images, double origin) {
  std::string text;
  HANZO_ASSIGN_OR_RETURN(text, read_file(path));
  std::vector<Timestamp> times;
  std::vector<fs::path> named;
  std::map<std::string, fs::path> by_name;
  for (const fs::path& image : images) by_name[image.filename().string()] = image;
  std::istringstream lines(text);
  std::string line;
  for (std::size_t line_number = 1; std::getline(lines, line); ++line_number) {
    const std::vector<std::string> fields = split_fields(line);
    if (fields.empty() || fields[0][0] == '#') continue;
    const std::string where = fmt::format("{}:{}", path, line_number);
    if (fields.size() > 2) return Error(fmt::format("{}: {} fields (expected TIME or TIME NAME)", where, fields.size()));
    Result<Timestamp> time = parse_seconds(fields[0]);
    if (!time) return Error(fmt::format("{}: {}", where, time.error().message));
    if (fields.size() == 2) {
      const auto found = by_name.find(fs::path(fields[1]).filename().string());
      if (found == by_name.end()) return Error(fmt::format("{}: {} is not an image of the folder", where, fields[1]));
      named.push_back(found->second);
    } else if (!named.empty()) {
      return Error(fmt::format("{}: a time without a file name after lines with one", where));
    }
    times.push_back(absolute(*time, origin));
  }
  if (!named.empty()) {
    if (named.size() != times.size()) return Error(fmt::format("{}: a file name without a time", path));
    images = std::move(named);
  } else if (times.size() != images.size()) {
    return Error(fmt::format("{}: {} times for {} images", path, times.size(), images.size()));
  }
  return times;
}

}  // namespace

Result<ImageFolderImportReport> import_image_folders(const std::vector<std::string>& folders, SensorLogWriter& writer,
                                                     const ImageFolderImportConfig& config) {
  if (folders.empty() || folders.size() > 2) return Error(fmt::format("image folders: {} given (one, or two for a stereo pair)", folders.size()));
  if (config.topics.size() < folders.size()) return Error(fmt::format("image folders: {} topics for {} folders", config.topics.size(), folders.size()));
  if (folders.size() == 2 && !(config.baseline > 0.0) && config.camera) {
    return Error("image folders: a stereo pair needs its baseline (metres, > 0) for the calibration");
  }
  if (!(config.rate_hz >= 0.0) || !std::isfinite(config.rate_hz)) return Error(fmt::format("image folders: rate {} Hz (expected > 0)", config.rate_hz));
  std::vector<std::vector<fs::path>> images;
  for (const std::string& folder : folders) {
    std::vector<fs::path> listed;
    HANZO_ASSIGN_OR_RETURN(listed, list_images(folder));
    images.push_back(std::move(listed));
  }
  if (images.size() == 2 && images[0].size() != images[1].size()) {
    return Error(fmt::format("stereo folders: {} holds {} images, {} holds {}", folders[0], images[0].size(), folders[1], images[1].size()));
  }

  ImageFolderImportReport report;
  std::vector<Timestamp> times;
  if (!config.times_path.empty()) {
    HANZO_ASSIGN_OR_RETURN(times, read_times(config.times_path, images[0], config.time_origin));
    report.time_source = "times file";
  } else if (std::all_of(images[0].begin(), images[0].end(), [](const fs::path& path) { return time_of_name(path).has_value(); })) {
    for (const fs::path& path : images[0]) times.push_back(*time_of_name(path));
    report.time_source = "file names";
  } else if (config.rate_hz > 0.0) {
    for (std::size_t i = 0; i < images[0].size(); ++i) {
      times.push_back(Timestamp::from_seconds(config.time_origin) + Duration::from_seconds(static_cast<double>(i) / config.rate_hz));
    }
    report.time_source = "rate";
  } else {
    return Error(fmt::format("{}: the file names are not times; give a times file or a frame rate", folders[0]));
  }
  const Timestamp origin = Timestamp::from_seconds(config.time_origin);
  report.relative_times = report.time_source == "rate" || (report.time_source == "times file" && !times.empty() && times.front() >= origin &&
                                                          times.front() < origin + Duration::from_seconds(1e8));

  std::optional<msgs::CameraIntrinsics> intrinsics;
  if (config.camera) intrinsics = config.camera->intrinsics;
  const auto reject = [&](const std::string& reason) {
    if (report.rejected++ == 0) report.first_rejection = reason;
  };
  std::optional<Timestamp> last;
  for (std::size_t frame = 0; frame < times.size(); ++frame) {
    if (last && times[frame] <= *last) {
      reject(fmt::format("{}: time {} s does not increase", images[0][frame].string(), format_seconds(times[frame])));
      continue;
    }
    // Read every camera's image of the frame first: a stereo frame goes in whole or not at all.
    std::vector<msgs::ImageMessage> frame_images;
    for (std::size_t camera = 0; camera < images.size(); ++camera) {
      const std::string path = images[camera][frame].string();
      Result<msgs::ImageMessage> image = read_image_file(path, times[frame], config.topics[camera].substr(1));
      if (!image) {
        reject(image.error().message);
        break;
      }
      if (image->encoding != msgs::ImageEncoding::kMono8 && image->encoding != msgs::ImageEncoding::kRgb8) {
        reject(fmt::format("{}: a 16-bit image (expected 8-bit grey or colour)", path));
        break;
      }
      if (report.width == 0) {
        report.width = image->width;
        report.height = image->height;
      } else if (image->width != report.width || image->height != report.height) {
        reject(fmt::format("{}: {}x{} pixels (the folder's images are {}x{})", path, image->width, image->height, report.width, report.height));
        break;
      }
      if (intrinsics) {
        intrinsics->width = report.width;
        intrinsics->height = report.height;
        image->intrinsics = intrinsics;
        if (config.camera->distortion.type != msgs::DistortionType::kNone) image->distortion = config.camera->distortion;
      }
      frame_images.push_back(std::move(image).value());
    }
    if (frame_images.size() != images.size()) continue;
    for (std::size_t camera = 0; camera < images.size(); ++camera) {
      HANZO_RETURN_IF_ERROR(with_context(writer.write(config.topics[camera], frame_images[camera]), images[camera][frame].string()));
      ++report.images;
    }
    last = times[frame];
  }
  if (report.images == 0) return Error(fmt::format("{}: no image could be imported ({})", folders[0], report.first_rejection));
  if (config.camera) {
    for (std::size_t camera = 0; camera < images.size(); ++camera) {
      const SE3 T_body_camera(SO3(), Eigen::Vector3d(camera == 0 ? 0.0 : config.baseline, 0.0, 0.0));
      calib::SensorCalibration entry = calib::SensorCalibration::from_transform(config.topics[camera].substr(1), T_body_camera);
      entry.camera = calib::CameraCalibration{*intrinsics, config.camera->distortion};
      report.calibration.sensors.push_back(std::move(entry));
    }
  }
  return report;
}

}  // namespace hanzo::fusion::io
