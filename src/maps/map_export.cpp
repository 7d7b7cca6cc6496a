#include "hanzo/fusion/maps/map_export.hpp"

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <limits>
#include <vector>

#include <fmt/format.h>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "hanzo/fusion/core/yaml_value.hpp"
#include "grid_image.hpp"
#include "layer_checks.hpp"

namespace hanzo::fusion::maps {
namespace {

constexpr float kUnknown = 0.5f;
constexpr uint8_t kOccupiedPixel = 0;
constexpr uint8_t kFreePixel = 254;
constexpr uint8_t kUnknownPixel = 205;

double yaw_of(const Eigen::Quaterniond& orientation) {
  const Eigen::Quaterniond q = orientation.normalized();
  return std::atan2(2.0 * (q.w() * q.z() + q.x() * q.y()), 1.0 - 2.0 * (q.y() * q.y() + q.z() * q.z()));
}

}  // namespace

msgs::OccupancyGridLayer flatten_occupancy(const msgs::OccupancyGridLayer& layer) {
  if (layer.size_z <= 1) return layer;
  msgs::OccupancyGridLayer flat = layer;
  flat.size_z = 1;
  flat.labels.clear();
  flat.classes.clear();
  const std::size_t plane = std::size_t{layer.size_x} * layer.size_y;
  flat.occupancy.assign(plane, kUnknown);
  for (uint32_t z = 0; z < layer.size_z; ++z) {
    for (std::size_t i = 0; i < plane; ++i) {
      const float value = layer.occupancy[z * plane + i];
      if (value == kUnknown) continue;
      float& column = flat.occupancy[i];
      column = column == kUnknown ? value : std::max(column, value);
    }
  }
  return flat;
}

Status write_ros_map(const std::string& yaml_path, const msgs::OccupancyGridLayer& layer, const RosMapConfig& config) {
  HANZO_RETURN_IF_ERROR(validate_layer(layer));
  if (layer.size_x == 0 || layer.size_y == 0) return Error{"ROS map: the occupancy grid is empty", "occupancy"};
  const msgs::OccupancyGridLayer flat = flatten_occupancy(layer);
  const std::filesystem::path image_path = std::filesystem::path(yaml_path).replace_extension(".pgm");

  std::string pgm = fmt::format("P5\n# hanzo-fusion occupancy grid, {} m/cell\n{} {}\n255\n", flat.resolution, flat.size_x, flat.size_y);
  const cv::Mat image = grid_image(flat, [&](float p) {
    if (p == kUnknown) return kUnknownPixel;
    if (p > config.occupied_threshold) return kOccupiedPixel;
    if (p < config.free_threshold) return kFreePixel;
    return kUnknownPixel;
  });
  pgm.append(reinterpret_cast<const char*>(image.data), image.total());
  HANZO_RETURN_IF_ERROR(yaml::write_file_atomically(image_path.string(), pgm));

  const std::string yaml = fmt::format(
      "image: {}\nmode: trinary\nresolution: {}\norigin: [{}, {}, {}]\nnegate: 0\noccupied_thresh: {}\nfree_thresh: {}\n",
      yaml::scalar(image_path.filename().string()), format_double(flat.resolution), format_double(flat.origin.position.x()),
      format_double(flat.origin.position.y()), format_double(yaw_of(flat.origin.orientation)),
      format_double(config.occupied_threshold), format_double(config.free_threshold));
  return yaml::write_file_atomically(yaml_path, yaml);
}

Result<msgs::OccupancyGridLayer> read_ros_map(const std::string& yaml_path) {
  const Result<YamlValue> loaded = YamlValue::load_file(yaml_path);
  if (!loaded) return loaded.error();
  const YamlValue& root = *loaded;
  HANZO_RETURN_IF_ERROR(root.check_keys({"image", "mode", "resolution", "origin", "negate", "occupied_thresh", "free_thresh"}));
  std::string image_name;
  HANZO_ASSIGN_OR_RETURN(image_name, root["image"].as_string());
  double resolution = 0.0;
  HANZO_ASSIGN_OR_RETURN(resolution, root["resolution"].as_double());
  if (!(resolution > 0.0)) return root["resolution"].error("must be a positive number of meters");
  std::vector<double> origin;
  HANZO_ASSIGN_OR_RETURN(origin, root["origin"].as_doubles(3, "(x, y, yaw)"));
  int64_t negate = 0;
  if (root["negate"].present()) HANZO_ASSIGN_OR_RETURN(negate, root["negate"].as_int64());
  double occupied_threshold = 0.65;
  double free_threshold = 0.196;
  if (root["occupied_thresh"].present()) HANZO_ASSIGN_OR_RETURN(occupied_threshold, root["occupied_thresh"].as_double());
  if (root["free_thresh"].present()) HANZO_ASSIGN_OR_RETURN(free_threshold, root["free_thresh"].as_double());
  if (!(free_threshold > 0.0 && free_threshold < occupied_threshold && occupied_threshold < 1.0)) {
    return root["free_thresh"].error("need 0 < free_thresh < occupied_thresh < 1");
  }
  std::string mode = "trinary";
  if (root["mode"].present()) HANZO_ASSIGN_OR_RETURN(mode, root["mode"].as_string());
  if (mode != "trinary" && mode != "scale" && mode != "raw") {
    return root["mode"].error(fmt::format("unknown mode '{}' (trinary, scale or raw)", mode));
  }

  std::filesystem::path image_path(image_name);
  if (image_path.is_relative()) image_path = std::filesystem::path(yaml_path).parent_path() / image_path;
  cv::Mat image;
  try {
    image = cv::imread(image_path.string(), cv::IMREAD_GRAYSCALE);
  } catch (const cv::Exception& error) {
    return Error{fmt::format("{}: cannot read the image ({})", image_path.string(), error.what())};
  }
  if (image.empty()) return Error{fmt::format("{}: cannot read the image (missing or not an image file)", image_path.string())};

  msgs::OccupancyGridLayer layer;
  layer.resolution = resolution;
  layer.size_x = static_cast<uint32_t>(image.cols);
  layer.size_y = static_cast<uint32_t>(image.rows);
  layer.size_z = 1;
  layer.origin.position = {origin[0], origin[1], 0.0};
  layer.origin.orientation = Eigen::Quaterniond(Eigen::AngleAxisd(origin[2], Eigen::Vector3d::UnitZ()));
  layer.occupancy.resize(image.total());
  for (int row = 0; row < image.rows; ++row) {
    const uint8_t* pixels = image.ptr<uint8_t>(row);
    const std::size_t y = static_cast<std::size_t>(image.rows - 1 - row);
    for (int x = 0; x < image.cols; ++x) {
      float& cell = layer.occupancy[y * layer.size_x + static_cast<std::size_t>(x)];
      if (mode == "raw") {
        cell = pixels[x] <= 100 ? static_cast<float>(pixels[x]) / 100.0f : kUnknown;
        continue;
      }
      const double p = negate != 0 ? pixels[x] / 255.0 : (255.0 - pixels[x]) / 255.0;
      const bool known = mode == "scale" || p > occupied_threshold || p < free_threshold;
      cell = known ? static_cast<float>(p) : kUnknown;
    }
  }
  return layer;
}

Status write_occupancy_png(const std::string& path, const msgs::OccupancyGridLayer& layer) {
  HANZO_RETURN_IF_ERROR(validate_layer(layer));
  if (layer.size_x == 0 || layer.size_y == 0) return Error{"occupancy PNG: the occupancy grid is empty", "occupancy"};
  const msgs::OccupancyGridLayer flat = flatten_occupancy(layer);
  const cv::Mat image = grid_image(flat, [](float p) {
    return p == kUnknown ? uint8_t{160} : static_cast<uint8_t>(std::lround(255.0 * (1.0 - p)));
  });
  return write_image(path, image, ".png");
}

Status write_points_png(const std::string& path, const msgs::PointLayer& layer, double pixel_size) {
  if (layer.points.empty()) return Error{"points PNG: the point layer is empty", "points"};
  Eigen::Vector3f low = Eigen::Vector3f::Constant(std::numeric_limits<float>::max());
  Eigen::Vector3f high = -low;
  for (const Eigen::Vector3f& point : layer.points) {
    if (!point.allFinite()) return Error{"points PNG: a point is not finite", "points"};
    low = low.cwiseMin(point);
    high = high.cwiseMax(point);
  }
  const double extent = std::max<double>({high.x() - low.x(), high.y() - low.y(), 1e-3});
  if (!(pixel_size > 0.0)) pixel_size = extent / 1600.0;
  const double width = std::ceil((high.x() - low.x()) / pixel_size) + 1;
  const double height = std::ceil((high.y() - low.y()) / pixel_size) + 1;
  if (width * height > 64e6) {
    return Error{fmt::format("points PNG: {} x {} pixels is too large; use a larger pixel size", width, height), "pixel_size"};
  }
  // Colour by height between the 2nd and 98th percentile (a few outliers do not wash it out).
  std::vector<float> heights;
  heights.reserve(layer.points.size());
  for (const Eigen::Vector3f& point : layer.points) heights.push_back(point.z());
  const auto percentile = [&](double fraction) {
    auto nth = heights.begin() + static_cast<std::ptrdiff_t>(fraction * static_cast<double>(heights.size() - 1));
    std::nth_element(heights.begin(), nth, heights.end());
    return *nth;
  };
  const float z_low = percentile(0.02);
  const float z_high = std::max(percentile(0.98), z_low + 1e-3f);

  cv::Mat top(static_cast<int>(height), static_cast<int>(width), CV_32FC1, cv::Scalar(-std::numeric_limits<float>::max()));
  for (const Eigen::Vector3f& point : layer.points) {
    const int column = static_cast<int>((point.x() - low.x()) / pixel_size);
    const int row = static_cast<int>(height) - 1 - static_cast<int>((point.y() - low.y()) / pixel_size);
    float& cell = top.at<float>(row, column);
    cell = std::max(cell, point.z());
  }
  cv::Mat levels(top.size(), CV_8UC1);
  cv::Mat empty(top.size(), CV_8UC1, cv::Scalar(0));
  for (int row = 0; row < top.rows; ++row) {
    for (int column = 0; column < top.cols; ++column) {
      const float z = top.at<float>(row, column);
      const bool has_point = z > -std::numeric_limits<float>::max();
      empty.at<uint8_t>(row, column) = has_point ? 0 : 255;
      levels.at<uint8_t>(row, column) =
          has_point ? static_cast<uint8_t>(std::clamp((z - z_low) / (z_high - z_low), 0.0f, 1.0f) * 255.0f) : 0;
    }
  }
  cv::Mat colored;
  cv::applyColorMap(levels, colored, cv::COLORMAP_TURBO);
  colored.setTo(cv::Scalar(255, 255, 255), empty);
  return write_image(path, colored, ".png");
}

Status write_mesh(const std::string& path, const msgs::MeshLayer& mesh) {
  if (mesh.triangle_indices.size() % 3 != 0) return Error{"mesh: triangle index count is not a multiple of 3", "triangle_indices"};
  for (uint32_t index : mesh.triangle_indices) {
    if (index >= mesh.vertices.size()) return Error{fmt::format("mesh: triangle index {} past {} vertices", index, mesh.vertices.size()), "triangle_indices"};
  }
  std::string extension = std::filesystem::path(path).extension().string();
  std::transform(extension.begin(), extension.end(), extension.begin(), [](unsigned char c) { return std::tolower(c); });
  const std::size_t triangles = mesh.triangle_indices.size() / 3;
  std::string out;
  if (extension == ".obj") {
    out = fmt::format("# hanzo-fusion mesh: {} vertices, {} triangles\n", mesh.vertices.size(), triangles);
    for (const Eigen::Vector3f& v : mesh.vertices) out += fmt::format("v {} {} {}\n", v.x(), v.y(), v.z());
    for (std::size_t t = 0; t < triangles; ++t) {
      out += fmt::format("f {} {} {}\n", mesh.triangle_indices[3 * t] + 1, mesh.triangle_indices[3 * t + 1] + 1, mesh.triangle_indices[3 * t + 2] + 1);
    }
  } else if (extension == ".ply") {
    out = fmt::format("ply\nformat binary_little_endian 1.0\ncomment hanzo-fusion mesh\nelement vertex {}\nproperty float x\n"
                      "property float y\nproperty float z\nelement face {}\nproperty list uchar int vertex_indices\nend_header\n",
                      mesh.vertices.size(), triangles);
    out.reserve(out.size() + mesh.vertices.size() * 12 + triangles * 13);
    for (const Eigen::Vector3f& v : mesh.vertices) out.append(reinterpret_cast<const char*>(v.data()), 3 * sizeof(float));
    for (std::size_t t = 0; t < triangles; ++t) {
      out.push_back(3);
      for (std::size_t k = 0; k < 3; ++k) {
        const int32_t index = static_cast<int32_t>(mesh.triangle_indices[3 * t + k]);
        out.append(reinterpret_cast<const char*>(&index), sizeof(index));
      }
    }
  } else {
    return Error{fmt::format("{}: mesh files are .ply or .obj", path)};
  }
  return yaml::write_file_atomically(path, out);
}

cloud::PointCloud to_point_cloud(const msgs::PointLayer& layer) {
  cloud::PointCloud cloud;
  cloud.positions = layer.points;
  cloud.intensities = layer.intensities;
  return cloud;
}

msgs::PointLayer to_point_layer(const cloud::PointCloud& cloud, double voxel_size) {
  msgs::PointLayer layer;
  layer.points = cloud.positions;
  layer.intensities = cloud.intensities;
  layer.voxel_size = voxel_size;
  return layer;
}

}  // namespace hanzo::fusion::maps
