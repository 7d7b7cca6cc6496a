// The KITTI odometry layout of export_dataset (hanzo/fusion/io/dataset_export.hpp).

#include <cstring>
#include <filesystem>
#include <string>

#include <fmt/format.h>

#include "dataset_layouts.hpp"

namespace hanzo::fusion::io::dataset {
namespace {

// The 12 numbers of the row-major 3x4 [R | t], as KITTI writes them.
std::string row_major_3x4(const Eigen::Matrix<double, 3, 4>& matrix) {
  std::string line;
  for (int r = 0; r < 3; ++r) {
    for (int c = 0; c < 4; ++c) line += fmt::format("{}{:.12e}", line.empty() ? "" : " ", matrix(r, c));
  }
  return line;
}

class KittiWriter final : public DatasetLayoutWriter {
 public:
  KittiWriter(const std::string& out_dir, std::vector<LayoutSensor> sensors, std::vector<LayoutFrame> frames)
      : sequence_(out_dir + "/sequences/00"), poses_path_(out_dir + "/poses/00.txt"), sensors_(std::move(sensors)), frames_(std::move(frames)) {
    int cameras = 0;
    bool lidar_named = false;
    for (std::size_t s = 0; s < sensors_.size(); ++s) {
      std::string folder;
      if (sensors_[s].is_camera) {
        folder = fmt::format("image_{}", cameras);
        if (cameras++ == 0) camera0_ = s;
      } else {
        folder = lidar_named ? "velodyne_" + sensors_[s].name : "velodyne";
        if (!lidar_named) lidar_ = s;
        lidar_named = true;
      }
      folders_.push_back(sequence_ + "/" + folder);
    }
    if (!camera0_) camera0_ = lidar_;
  }

  Status write_cloud(std::size_t frame, std::size_t sensor, Timestamp, const SE3&, const LayoutCloud& cloud) override {
    HANZO_RETURN_IF_ERROR(make_folder(folders_[sensor]));
    std::string bytes(cloud.points.size() * 4 * sizeof(float), '\0');
    auto* out = reinterpret_cast<float*>(bytes.data());
    for (std::size_t i = 0; i < cloud.points.size(); ++i) {
      out[4 * i] = cloud.points[i].x();
      out[4 * i + 1] = cloud.points[i].y();
      out[4 * i + 2] = cloud.points[i].z();
      out[4 * i + 3] = cloud.intensities.empty() ? 0.0F : cloud.intensities[i];
    }
    return write_file(fmt::format("{}/{:06d}.bin", folders_[sensor], frame), bytes);
  }

  Status write_image(std::size_t frame, std::size_t sensor, Timestamp, const SE3&, const msgs::ImageMessage& image) override {
    HANZO_RETURN_IF_ERROR(make_folder(folders_[sensor]));
    std::string png;
    HANZO_ASSIGN_OR_RETURN(png, encode_image(image, false, 0));
    return write_file(fmt::format("{}/{:06d}.png", folders_[sensor], frame), png);
  }

  Status finish() override {
    HANZO_RETURN_IF_ERROR(make_folder(sequence_));
    HANZO_RETURN_IF_ERROR(make_folder(std::filesystem::path(poses_path_).parent_path().string()));
    const SE3& T_body_camera0 = sensors_[*camera0_].T_body_sensor;
    std::string calib;
    int camera = 0;
    for (const LayoutSensor& sensor : sensors_) {
      if (!sensor.is_camera) continue;
      Eigen::Matrix3d K = Eigen::Matrix3d::Identity();
      K(0, 0) = sensor.intrinsics.fx;
      K(1, 1) = sensor.intrinsics.fy;
      K(0, 2) = sensor.intrinsics.cx;
      K(1, 2) = sensor.intrinsics.cy;
      const Eigen::Matrix4d T_camera_camera0 = (sensor.T_body_sensor.inverse() * T_body_camera0).matrix();
      calib += fmt::format("P{}: {}\n", camera++, row_major_3x4(K * T_camera_camera0.topRows<3>()));
    }
    if (lidar_) calib += fmt::format("Tr: {}\n", row_major_3x4((T_body_camera0.inverse() * sensors_[*lidar_].T_body_sensor).matrix().topRows<3>()));
    HANZO_RETURN_IF_ERROR(write_file(sequence_ + "/calib.txt", calib));
    std::string times, stamps, poses;
    const SE3 T_first_world = (frames_.front().T_world_body * T_body_camera0).inverse();
    for (const LayoutFrame& frame : frames_) {
      times += fmt::format("{:.6e}\n", (frame.time - frames_.front().time).seconds());
      stamps += fmt::format("{}\n", frame.time.nanoseconds());
      poses += row_major_3x4((T_first_world * frame.T_world_body * T_body_camera0).matrix().topRows<3>()) + "\n";
    }
    HANZO_RETURN_IF_ERROR(write_file(sequence_ + "/times.txt", times));
    HANZO_RETURN_IF_ERROR(write_file(sequence_ + "/timestamps_ns.txt", stamps));
    return write_file(poses_path_, poses);
  }

 private:
  static Status make_folder(const std::string& path) {
    std::error_code error;
    std::filesystem::create_directories(path, error);
    if (error) return Error(fmt::format("{}: cannot create the folder ({})", path, error.message()));
    return ok_status();
  }

  std::string sequence_;
  std::string poses_path_;
  std::vector<LayoutSensor> sensors_;
  std::vector<LayoutFrame> frames_;
  std::vector<std::string> folders_;  // per sensor
  std::optional<std::size_t> camera0_;
  std::optional<std::size_t> lidar_;
};

}  // namespace

std::unique_ptr<DatasetLayoutWriter> make_kitti_writer(const std::string& out_dir, std::vector<LayoutSensor> sensors,
                                                       std::vector<LayoutFrame> frames) {
  return std::make_unique<KittiWriter>(out_dir, std::move(sensors), std::move(frames));
}

}  // namespace hanzo::fusion::io::dataset
