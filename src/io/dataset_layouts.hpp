#pragma once
// The two file layouts of export_dataset (hanzo/fusion/io/dataset_export.hpp), internal to io:
// export_dataset picks the frames, moves and undistorts the data, and hands each frame's
// sensor data to a DatasetLayoutWriter, in log order (frames interleave). finish() writes what
// needs every frame (poses, times, tables).

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "hanzo/fusion/core/se3.hpp"
#include "hanzo/fusion/io/dataset_export.hpp"
#include "hanzo/fusion/msgs/sensor_messages.hpp"

namespace hanzo::fusion::io::dataset {

/// A sensor as the layouts need it.
struct LayoutSensor {
  std::string name;
  bool is_camera = false;
  SE3 T_body_sensor;
  msgs::CameraIntrinsics intrinsics;  ///< cameras: of the undistorted images written
};

/// One exported frame (frames are numbered 0.. in time order).
struct LayoutFrame {
  Timestamp time;     ///< the reference sensor's message time (body clock)
  SE3 T_world_body;   ///< at `time`
};

/// A sweep in the sensor frame at its message time (deskewed when per-point times allowed).
struct LayoutCloud {
  std::vector<Eigen::Vector3f> points;
  std::vector<float> intensities;  ///< empty, or one per point in [0, 1]
  std::vector<uint32_t> rings;     ///< empty, or one per point
};

class DatasetLayoutWriter {
 public:
  virtual ~DatasetLayoutWriter() = default;
  /// `time` is the message's time on the body clock, `T_world_body` the pose then.
  virtual Status write_cloud(std::size_t frame, std::size_t sensor, Timestamp time, const SE3& T_world_body, const LayoutCloud& cloud) = 0;
  virtual Status write_image(std::size_t frame, std::size_t sensor, Timestamp time, const SE3& T_world_body,
                             const msgs::ImageMessage& image) = 0;
  virtual Status finish() = 0;
  uint64_t bytes_written() const { return bytes_written_; }

 protected:
  Status write_file(const std::string& path, const std::string& bytes);
  uint64_t bytes_written_ = 0;
};

/// `out_dir` exists and is empty; frames are in time order.
std::unique_ptr<DatasetLayoutWriter> make_kitti_writer(const std::string& out_dir, std::vector<LayoutSensor> sensors,
                                                       std::vector<LayoutFrame> frames);
std::unique_ptr<DatasetLayoutWriter> make_nuscenes_writer(const std::string& out_dir, std::vector<LayoutSensor> sensors,
                                                          std::vector<LayoutFrame> frames, const DatasetExportConfig& config);

/// PNG (lossless) or JPEG bytes of an image; colour written as colour, depth16 as 16-bit PNG.
/// Fails for depth32f under JPEG.
Result<std::string> encode_image(const msgs::ImageMessage& image, bool jpeg, int jpeg_quality);

}  // namespace hanzo::fusion::io::dataset
