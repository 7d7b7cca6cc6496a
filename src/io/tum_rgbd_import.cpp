#include "hanzo/fusion/io/tum_rgbd_import.hpp"

#include <algorithm>
#include <tuple>
#include <filesystem>
#include <sstream>

#include <fmt/format.h>

#include "hanzo/fusion/core/files.hpp"
#include "image_files.hpp"
#include "text_lines.hpp"

namespace hanzo::fusion::io {
namespace {

namespace fs = std::filesystem;

struct ListEntry {
  Timestamp time;
  std::string file;
};

Result<std::vector<ListEntry>> read_list(const fs::path& path, TumRgbdImportReport& report) {
  std::string text;
  HANZO_ASSIGN_OR_RETURN(text, read_file(path.string()));
  std::vector<ListEntry> entries;
  std::istringstream lines(text);
  std::string line;
  for (std::size_t line_number = 1; std::getline(lines, line); ++line_number) {
    const std::vector<std::string> fields = split_fields(line);
    if (fields.empty() || fields[0][0] == '#') continue;
    const std::string where = fmt::format("{}:{}", path.string(), line_number);
    if (fields.size() != 2) return Error(fmt::format("{}: {} fields (expected: timestamp filename)", where, fields.size()));
    auto time = parse_seconds(fields[0]);
    if (!time) return Error(fmt::format("{}: {}", where, time.error().message));
    if (!entries.empty() && *time <= entries.back().time) {
      if (report.rejected++ == 0) report.first_rejection = fmt::format("{}: time {} s does not increase", where, fields[0]);
      continue;
    }
    entries.push_back({*time, fields[1]});
  }
  return entries;
}

// The Kinect calibrations TUM published (ROS default intrinsics for fr3, whose images are undistorted).
std::optional<calib::CameraCalibration> kinect_of(const std::string& folder_name, std::string& model) {
  using msgs::DistortionType;
  struct Known {
    const char* name;
    calib::CameraCalibration camera;
  };
  static const Known known[] = {
      {"freiburg1", {{517.3, 516.5, 318.6, 255.3, 640, 480}, {DistortionType::kRadtan, {0.2624, -0.9531, -0.0054, 0.0026, 1.1633}}}},
      {"freiburg2", {{520.9, 521.0, 325.1, 249.7, 640, 480}, {DistortionType::kRadtan, {0.2312, -0.7849, -0.0033, -0.0001, 0.9172}}}},
      {"freiburg3", {{535.4, 539.2, 320.1, 247.6, 640, 480}, {DistortionType::kNone, {}}}},
  };
  for (const Known& candidate : known) {
    if (folder_name.find(candidate.name) != std::string::npos) {
      model = candidate.name;
      return candidate.camera;
    }
  }
  return std::nullopt;
}

// Each depth entry stamped with the nearest colour entry's time within max_offset, one-to-one
// (pairs taken nearest first); the others counted and left out. In time order.
std::vector<ListEntry> paired_with_colour(const std::vector<ListEntry>& depth, const std::vector<ListEntry>& rgb, double max_offset,
                                          TumRgbdImportReport& report) {
  std::vector<std::tuple<double, std::size_t, std::size_t>> candidates;  // (|dt|, depth, rgb)
  for (std::size_t d = 0; d < depth.size(); ++d) {
    const auto after = std::lower_bound(rgb.begin(), rgb.end(), depth[d].time, [](const ListEntry& e, Timestamp t) { return e.time < t; });
    for (auto it : {after, after == rgb.begin() ? rgb.end() : std::prev(after)}) {
      if (it == rgb.end()) continue;
      const double offset = std::abs((it->time - depth[d].time).seconds());
      if (offset <= max_offset) candidates.emplace_back(offset, d, static_cast<std::size_t>(it - rgb.begin()));
    }
  }
  std::sort(candidates.begin(), candidates.end());
  std::vector<bool> depth_used(depth.size(), false), rgb_used(rgb.size(), false);
  std::vector<ListEntry> paired;
  for (const auto& [offset, d, r] : candidates) {
    if (depth_used[d] || rgb_used[r]) continue;
    depth_used[d] = rgb_used[r] = true;
    paired.push_back({rgb[r].time, depth[d].file});
  }
  report.depth_unpaired = depth.size() - paired.size();
  std::sort(paired.begin(), paired.end(), [](const ListEntry& a, const ListEntry& b) { return a.time < b.time; });
  return paired;
}

}  // namespace

Result<TumRgbdImportReport> import_tum_rgbd(const std::string& dir, SensorLogWriter& writer, const TumRgbdImportConfig& config) {
  const fs::path root = fs::path(dir).lexically_normal();
  if (!fs::is_regular_file(root / "rgb.txt")) return Error(fmt::format("{}: no rgb.txt (expected a TUM RGB-D sequence folder)", dir));
  TumRgbdImportReport report;
  std::vector<ListEntry> rgb, depth;
  HANZO_ASSIGN_OR_RETURN(rgb, read_list(root / "rgb.txt", report));
  if (config.import_depth && fs::is_regular_file(root / "depth.txt")) HANZO_ASSIGN_OR_RETURN(depth, read_list(root / "depth.txt", report));
  if (fs::is_regular_file(root / "groundtruth.txt")) {
    HANZO_ASSIGN_OR_RETURN(report.ground_truth, read_trajectory((root / "groundtruth.txt").string(), TrajectoryFormat::kTum));
  }

  if (config.max_depth_offset > 0.0 && !depth.empty()) depth = paired_with_colour(depth, rgb, config.max_depth_offset, report);
  std::optional<calib::CameraCalibration> camera = config.camera;
  if (camera) {
    report.camera_model = "config";
  } else {
    const std::string name = (root.has_filename() ? root : root.parent_path()).filename().string();
    camera = kinect_of(name, report.camera_model);
  }
  for (const std::string* topic : {&config.rgb_topic, &config.depth_topic}) {
    if (topic == &config.depth_topic && depth.empty()) continue;
    calib::SensorCalibration sensor = calib::SensorCalibration::from_transform(topic->substr(1), SE3());
    sensor.camera = camera;
    report.calibration.sensors.push_back(sensor);
  }

  // Merge both lists in time order; images are read only when written.
  std::size_t r = 0, d = 0;
  while (r < rgb.size() || d < depth.size()) {
    const bool take_rgb = d == depth.size() || (r < rgb.size() && rgb[r].time <= depth[d].time);
    const ListEntry& entry = take_rgb ? rgb[r++] : depth[d++];
    const std::string& topic = take_rgb ? config.rgb_topic : config.depth_topic;
    const std::string path = (root / entry.file).string();
    msgs::ImageMessage image;
    HANZO_ASSIGN_OR_RETURN(image, read_image_file(path, entry.time, topic.substr(1), 0.2));  // 5000 per metre -> mm
    const bool expected = take_rgb ? image.encoding == msgs::ImageEncoding::kRgb8 || image.encoding == msgs::ImageEncoding::kMono8
                                   : image.encoding == msgs::ImageEncoding::kDepth16;
    if (!expected) return Error(fmt::format("{}: expected a {} image", path, take_rgb ? "colour" : "16-bit depth"));
    if (camera) {
      image.intrinsics = camera->intrinsics;
      image.intrinsics->width = image.width;
      image.intrinsics->height = image.height;
      if (camera->distortion.type != msgs::DistortionType::kNone) image.distortion = camera->distortion;
    }
    HANZO_RETURN_IF_ERROR(with_context(writer.write(topic, image), path));
    ++(take_rgb ? report.rgb_images : report.depth_images);
  }
  return report;
}

}  // namespace hanzo::fusion::io
