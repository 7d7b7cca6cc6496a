#include "hanzo/fusion/neural/view_dataset.hpp"
#include "view_images.hpp"

#include <chrono>
#include <cmath>
#include <filesystem>
#include <fstream>

#include <fmt/format.h>
#include <nlohmann/json.hpp>
#include <opencv2/calib3d.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "hanzo/fusion/core/files.hpp"

namespace hanzo::fusion::neural {

namespace {

using Json = nlohmann::json;

// A finite number under `key` of `object`, else the fallback (nullopt: required).
Result<double> number(const Json& object, const std::string& key, std::optional<double> fallback, const std::string& where) {
  const auto found = object.find(key);
  if (found == object.end()) {
    if (fallback) return *fallback;
    return Error(fmt::format("{}: no '{}'", where, key), key);
  }
  if (!found->is_number() || !std::isfinite(found->get<double>())) return Error(fmt::format("{}: '{}' must be a finite number", where, key), key);
  return found->get<double>();
}

struct Intrinsics {
  std::optional<double> fl_x, fl_y, cx, cy, w, h, angle_x, angle_y;
  double k1 = 0, k2 = 0, p1 = 0, p2 = 0, k3 = 0;
};

Status read_intrinsics(const Json& object, Intrinsics& intrinsics, const std::string& where) {
  for (auto [key, slot] : {std::pair{"fl_x", &intrinsics.fl_x}, {"fl_y", &intrinsics.fl_y}, {"cx", &intrinsics.cx}, {"cy", &intrinsics.cy},
                           {"w", &intrinsics.w}, {"h", &intrinsics.h}, {"camera_angle_x", &intrinsics.angle_x}, {"camera_angle_y", &intrinsics.angle_y}}) {
    if (!object.contains(key)) continue;
    double value = 0.0;
    HANZO_ASSIGN_OR_RETURN(value, number(object, key, std::nullopt, where));
    *slot = value;
  }
  for (auto [key, slot] : {std::pair{"k1", &intrinsics.k1}, {"k2", &intrinsics.k2}, {"p1", &intrinsics.p1}, {"p2", &intrinsics.p2}, {"k3", &intrinsics.k3}}) {
    HANZO_ASSIGN_OR_RETURN(*slot, number(object, key, *slot, where));
  }
  return ok_status();
}

}  // namespace

Status to_view_image(const cv::Mat& read, const ViewDatasetConfig& config, PosedView& view) {
  cv::Mat rgb, alpha;
  if (read.channels() == 4) {
    std::vector<cv::Mat> channels;
    cv::split(read, channels);
    channels[3].convertTo(alpha, CV_32F, 1.0 / 255.0);
    cv::merge(std::vector<cv::Mat>{channels[2], channels[1], channels[0]}, rgb);
  } else if (read.channels() == 3) {
    cv::cvtColor(read, rgb, cv::COLOR_BGR2RGB);
  } else {
    cv::cvtColor(read, rgb, cv::COLOR_GRAY2RGB);
  }
  cv::Mat rgb_float;
  rgb.convertTo(rgb_float, CV_32FC3, 1.0 / 255.0);
  if (!alpha.empty()) {
    for (int y = 0; y < rgb_float.rows; ++y) {
      for (int x = 0; x < rgb_float.cols; ++x) {
        const float a = alpha.at<float>(y, x);
        cv::Vec3f& pixel = rgb_float.at<cv::Vec3f>(y, x);
        for (int c = 0; c < 3; ++c) pixel[c] = pixel[c] * a + config.background[c] * (1.0f - a);
      }
    }
  }
  if (config.downscale > 1) {
    const cv::Size size(rgb_float.cols / config.downscale, rgb_float.rows / config.downscale);
    cv::resize(rgb_float, rgb_float, size, 0, 0, cv::INTER_AREA);
    if (!alpha.empty()) cv::resize(alpha, alpha, size, 0, 0, cv::INTER_AREA);
  }
  view.image.width = rgb_float.cols;
  view.image.height = rgb_float.rows;
  view.image.pixels.assign(reinterpret_cast<const float*>(rgb_float.data), reinterpret_cast<const float*>(rgb_float.data) + 3 * rgb_float.total());
  if (!alpha.empty()) view.mask.assign(reinterpret_cast<const float*>(alpha.data), reinterpret_cast<const float*>(alpha.data) + alpha.total());
  return ok_status();
}

void set_scene_extent(ViewDataset& dataset) {
  // The point nearest to every optical axis: sum (I - d d^T) x = sum (I - d d^T) c.
  Eigen::Matrix3d a = Eigen::Matrix3d::Zero();
  Eigen::Vector3d b = Eigen::Vector3d::Zero();
  for (const PosedView& view : dataset.views) {
    const Eigen::Vector3d d = view.camera.R_camera_world.row(2).transpose();
    const Eigen::Matrix3d projector = Eigen::Matrix3d::Identity() - d * d.transpose();
    a += projector;
    b += projector * view.camera.centre_world();
  }
  Eigen::Vector3d mean_centre = Eigen::Vector3d::Zero();
  for (const PosedView& view : dataset.views) mean_centre += view.camera.centre_world() / static_cast<double>(dataset.views.size());
  const Eigen::FullPivLU<Eigen::Matrix3d> lu(a);
  dataset.scene_centre = lu.rank() == 3 ? Eigen::Vector3d(lu.solve(b)) : mean_centre;
  double distance = 0.0;
  for (const PosedView& view : dataset.views) distance += (view.camera.centre_world() - dataset.scene_centre).norm() / static_cast<double>(dataset.views.size());
  dataset.camera_distance = std::max(distance, 1e-6);
}

Result<ViewDataset> load_transforms(const std::string& path, const ViewDatasetConfig& config) {
  if (config.downscale < 1 || config.every < 1 || config.skip_every < 0 || config.only_every < 0) {
    return Error("ViewDatasetConfig: downscale and every must be >= 1, skip_every and only_every >= 0");
  }
  std::string text;
  HANZO_ASSIGN_OR_RETURN(text, read_file(path));
  Json root;
  try {
    root = Json::parse(text);
  } catch (const Json::exception& error) {
    return Error(fmt::format("{}: not JSON ({})", path, error.what()));
  }
  if (!root.is_object()) return Error(fmt::format("{}: not a JSON object", path));
  Intrinsics shared;
  HANZO_RETURN_IF_ERROR(read_intrinsics(root, shared, path));
  const auto frames = root.find("frames");
  if (frames == root.end() || !frames->is_array() || frames->empty()) return Error(fmt::format("{}: no frames", path), "frames");
  const std::filesystem::path folder = std::filesystem::path(path).parent_path();
  ViewDataset dataset;
  int kept = 0;
  for (std::size_t f = 0; f < frames->size(); ++f) {
    if (static_cast<int>(f) % config.every != 0) continue;
    const int position = kept++;
    if (config.skip_every > 0 && position % config.skip_every == 0) continue;
    if (config.only_every > 0 && position % config.only_every != 0) continue;
    const Json& frame = (*frames)[f];
    const std::string where = fmt::format("{}: frames[{}]", path, f);
    if (!frame.is_object() || !frame.contains("file_path") || !frame["file_path"].is_string()) return Error(fmt::format("{}: no file_path", where), "file_path");
    Intrinsics intrinsics = shared;
    HANZO_RETURN_IF_ERROR(read_intrinsics(frame, intrinsics, where));
    const auto matrix = frame.find("transform_matrix");
    if (matrix == frame.end() || !matrix->is_array() || matrix->size() < 3) return Error(fmt::format("{}: no 4 x 4 transform_matrix", where), "transform_matrix");
    Eigen::Matrix4d c2w = Eigen::Matrix4d::Identity();
    for (int r = 0; r < 3; ++r) {
      const Json& row = (*matrix)[static_cast<std::size_t>(r)];
      if (!row.is_array() || row.size() != 4) return Error(fmt::format("{}: transform_matrix row {} is not 4 numbers", where, r), "transform_matrix");
      for (int c = 0; c < 4; ++c) {
        if (!row[static_cast<std::size_t>(c)].is_number() || !std::isfinite(row[static_cast<std::size_t>(c)].get<double>())) {
          return Error(fmt::format("{}: transform_matrix[{}][{}] is not a finite number", where, r, c), "transform_matrix");
        }
        c2w(r, c) = row[static_cast<std::size_t>(c)].get<double>();
      }
    }
    PosedView view;
    view.name = frame["file_path"].get<std::string>();
    std::filesystem::path image_path = folder / view.name;
    if (!image_path.has_extension()) image_path += ".png";
    cv::Mat read;
    if (config.load_images || !intrinsics.w || !intrinsics.h) {
      read = cv::imread(image_path.string(), cv::IMREAD_UNCHANGED);
      if (read.empty()) return Error(fmt::format("{}: cannot read image {}", where, image_path.string()), "file_path");
      if (read.depth() != CV_8U) return Error(fmt::format("{}: {} is not an 8-bit image", where, image_path.string()), "file_path");
      if ((intrinsics.w && static_cast<int>(*intrinsics.w) != read.cols) || (intrinsics.h && static_cast<int>(*intrinsics.h) != read.rows)) {
        return Error(fmt::format("{}: {} is {} x {} pixels, the file says {} x {}", where, image_path.string(), read.cols, read.rows, intrinsics.w.value_or(0),
                                 intrinsics.h.value_or(0)));
      }
    }
    const double width = intrinsics.w.value_or(read.cols), height = intrinsics.h.value_or(read.rows);
    if (!intrinsics.fl_x && !intrinsics.angle_x) return Error(fmt::format("{}: neither fl_x nor camera_angle_x", where), "camera_angle_x");
    const double fx = intrinsics.fl_x ? *intrinsics.fl_x : 0.5 * width / std::tan(0.5 * *intrinsics.angle_x);
    const double fy = intrinsics.fl_y ? *intrinsics.fl_y : intrinsics.angle_y && !intrinsics.fl_x ? 0.5 * height / std::tan(0.5 * *intrinsics.angle_y) : fx;
    if (!(fx > 0.0 && fy > 0.0 && width > 0.0 && height > 0.0)) return Error(fmt::format("{}: focal lengths and size must be positive", where));
    // Pixel centres at integer coordinates (OpenCV): the file's cx (centres at +0.5) - 0.5.
    const double cx = intrinsics.cx.value_or(0.5 * width) - 0.5, cy = intrinsics.cy.value_or(0.5 * height) - 0.5;
    const bool distorted = intrinsics.k1 != 0 || intrinsics.k2 != 0 || intrinsics.p1 != 0 || intrinsics.p2 != 0 || intrinsics.k3 != 0;
    if (!read.empty() && config.load_images) {
      if (distorted) {
        const cv::Matx33d k(fx, 0, cx, 0, fy, cy, 0, 0, 1);
        const cv::Mat distortion = (cv::Mat_<double>(1, 5) << intrinsics.k1, intrinsics.k2, intrinsics.p1, intrinsics.p2, intrinsics.k3);
        cv::Mat undistorted;
        cv::undistort(read, undistorted, k, distortion, k);
        read = undistorted;
      }
      HANZO_RETURN_IF_ERROR(to_view_image(read, config, view));
    }
    const double s = static_cast<double>(config.downscale);
    view.camera.width = static_cast<int>(width) / config.downscale;
    view.camera.height = static_cast<int>(height) / config.downscale;
    view.camera.fx = fx / s;
    view.camera.fy = fy / s;
    view.camera.cx = (cx + 0.5) / s - 0.5;
    view.camera.cy = (cy + 0.5) / s - 0.5;
    // OpenGL camera (x right, y up, z back) to the optical frame (x right, y down, z forward).
    const Eigen::Matrix3d R_world_camera = c2w.topLeftCorner<3, 3>() * Eigen::Vector3d(1.0, -1.0, -1.0).asDiagonal();
    view.camera.R_camera_world = R_world_camera.transpose();
    view.camera.t_camera_world = -R_world_camera.transpose() * c2w.topRightCorner<3, 1>();
    dataset.views.push_back(std::move(view));
  }
  if (dataset.views.empty()) return Error(fmt::format("{}: no frames left after the selection", path), "frames");
  HANZO_ASSIGN_OR_RETURN(dataset.aabb_scale, number(root, "aabb_scale", 0.0, path));
  if (dataset.aabb_scale < 0.0) return Error(fmt::format("{}: 'aabb_scale' must be positive", path), "aabb_scale");
  set_scene_extent(dataset);
  return dataset;
}

Status save_transforms(const std::string& path, const std::vector<PosedView>& views, const std::vector<std::string>& file_paths) {
  Json frames = Json::array();
  for (std::size_t i = 0; i < views.size(); ++i) {
    const SplatCamera& camera = views[i].camera;
    const Eigen::Matrix3d R_world_camera = camera.R_camera_world.transpose();
    Eigen::Matrix4d c2w = Eigen::Matrix4d::Identity();
    c2w.topLeftCorner<3, 3>() = R_world_camera * Eigen::Vector3d(1.0, -1.0, -1.0).asDiagonal();
    c2w.topRightCorner<3, 1>() = camera.centre_world();
    Json matrix = Json::array();
    for (int r = 0; r < 4; ++r) matrix.push_back({c2w(r, 0), c2w(r, 1), c2w(r, 2), c2w(r, 3)});
    frames.push_back({{"file_path", file_paths[i]}, {"transform_matrix", matrix}, {"fl_x", camera.fx}, {"fl_y", camera.fy}, {"cx", camera.cx + 0.5},
                      {"cy", camera.cy + 0.5}, {"w", camera.width}, {"h", camera.height}});
  }
  return write_file_durably(path, Json{{"frames", frames}}.dump(2) + "\n");
}

std::vector<PosedView> downscaled(const std::vector<PosedView>& views, int factor) {
  std::vector<PosedView> out;
  for (const PosedView& view : views) {
    PosedView small;
    small.name = view.name;
    small.camera = view.camera;
    small.camera.width = view.camera.width / factor;
    small.camera.height = view.camera.height / factor;
    small.camera.fx /= factor;
    small.camera.fy /= factor;
    small.camera.cx = (view.camera.cx + 0.5) / factor - 0.5;
    small.camera.cy = (view.camera.cy + 0.5) / factor - 0.5;
    const cv::Size size(small.camera.width, small.camera.height);
    if (!view.image.pixels.empty()) {
      const cv::Mat image(view.image.height, view.image.width, CV_32FC3, const_cast<float*>(view.image.pixels.data()));
      cv::Mat resized;
      cv::resize(image, resized, size, 0, 0, cv::INTER_AREA);
      small.image.width = resized.cols;
      small.image.height = resized.rows;
      small.image.pixels.assign(reinterpret_cast<const float*>(resized.data), reinterpret_cast<const float*>(resized.data) + 3 * resized.total());
    }
    if (!view.mask.empty()) {
      const cv::Mat mask(view.image.height, view.image.width, CV_32FC1, const_cast<float*>(view.mask.data()));
      cv::Mat resized;
      cv::resize(mask, resized, size, 0, 0, cv::INTER_AREA);
      small.mask.assign(reinterpret_cast<const float*>(resized.data), reinterpret_cast<const float*>(resized.data) + resized.total());
    }
    out.push_back(std::move(small));
  }
  return out;
}

EvaluationSummary score_views(const std::vector<PosedView>& views, const std::function<std::vector<float>(const SplatCamera&)>& render) {
  EvaluationSummary summary;
  double seconds = 0.0;
  for (const PosedView& view : views) {
    if (view.image.pixels.empty()) continue;
    const auto start = std::chrono::steady_clock::now();
    const std::vector<float> image = render(view.camera);
    seconds += std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    ViewScore score{view.name, psnr(image, view.image.pixels), ssim(image, view.image.pixels, view.camera.width, view.camera.height)};
    summary.mean_psnr += score.psnr;
    summary.mean_ssim += score.ssim;
    summary.views.push_back(std::move(score));
  }
  if (!summary.views.empty()) {
    const auto count = static_cast<double>(summary.views.size());
    summary.mean_psnr /= count;
    summary.mean_ssim /= count;
    summary.seconds_per_view = seconds / count;
  }
  return summary;
}

}  // namespace hanzo::fusion::neural
