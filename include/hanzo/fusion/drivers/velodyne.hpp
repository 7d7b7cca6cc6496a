#pragma once
// Velodyne LiDARs (VLP-16, VLP-32C, HDL-32E, HDL-64E, VLS-128): UDP data packets into one
// PointCloudMessage per rotation, with per-point times and rings.
//
// Data packet (1206 bytes, port 2368): 12 blocks of 100 bytes (flag 0xEEFF, 0xDDFF, 0xCCFF or
// 0xBBFF: lasers 0-31, 32-63, 64-95, 96-127 of the block; azimuth in 0.01 degree; 32 returns
// of distance (2 mm units) and intensity), the time of the first firing in microseconds past the
// hour, the return mode (0x37 strongest, 0x38 last, 0x39 dual) and the product id. A VLP-16
// block holds two firing sequences of its 16 lasers. Position packets (512 bytes, port 8308:
// the GPS's $GPRMC) are counted and not decoded into points.
//
// Geometry, per return of laser l at azimuth a (VeloView's and the ROS driver's model; angles
// of the calibration, metres):
//   d = raw distance x distance_resolution + distance_correction
//   xy = d cos(v_l) - vertical_offset_l sin(v_l),   b = a - rotational_correction_l
//   x' = xy sin(b) - horizontal_offset_l cos(b),     y' = xy cos(b) + horizontal_offset_l sin(b)
//   z = d sin(v_l) + vertical_offset_l cos(v_l)
// (x', y' in the sensor's own axes: y' toward azimuth 0), output in the LiDAR frame of this
// project (x forward = azimuth 0, y left, z up): (x, y, z) = (y', -x', z). Returns of distance
// 0 (no echo) are left out.
// HDL-64E two-point distance corrections (its manual's calibration at two distances per axis, as
// VeloView and the ROS driver apply them), for lasers with two_point_correction: with x', y' from
// the model above, r = raw distance x distance_resolution,
//   c_x = (distance_correction - distance_correction_x) (|x'| - 2.4) / (25.04 - 2.4) + distance_correction_x
//   c_y = (distance_correction - distance_correction_y) (|y'| - 1.93) / (25.04 - 1.93) + distance_correction_y
// x' is computed again with d = r + c_x, and y' and z with d = r + c_y.
//
// Azimuths: each laser's azimuth moves toward the next firing's by its firing time within the
// block (per_laser_azimuth, as VeloView and the ROS driver do), rounded to the packets' 0.01
// degree as both do; the last block of a packet takes the advance of the one before it. Off:
// the block's azimuth (a VLP-16's second sequence half-way to the next block's). The HDL-64E and
// VLS-128 keep their blocks' azimuths.
//
// Times: the packet's microseconds past the hour, in the hour of the capture time nearest to
// it, plus each laser's firing offset (VLP-16: 55.296 us per sequence, 2.304 us per laser;
// HDL-32E: 46.08 us per block, 1.152 us per laser; VLP-32C: 55.296 us per block, 2.304 us per
// laser pair; HDL-64E: 48 us per upper/lower block pair and VLS-128: 53.3 us per four blocks, the
// lasers of a firing at its time).
//
// Frames: a rotation ends where the azimuth wraps (passes cut_angle_deg, default 0, the
// azimuth a frame starts at); a rotation's first frame may be partial. Dual-return packets give
// both returns (a second return equal to the first is left out).
//
// Failures: packets of another size, without block flags or of a laser layout other than the
// calibration's are counted (malformed) and skipped.

#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "hanzo/fusion/core/result.hpp"
#include "hanzo/fusion/core/time.hpp"
#include "hanzo/fusion/drivers/rotation_frame.hpp"
#include "hanzo/fusion/msgs/sensor_messages.hpp"

namespace hanzo::fusion::drivers {

enum class VelodyneModel { kVlp16, kVlp32c, kHdl32e, kHdl64e, kVls128 };
/// "VLP-16", "VLP-32C", "HDL-32E", "HDL-64E", "VLS-128" (case and dashes ignored).
Result<VelodyneModel> parse_velodyne_model(const std::string& name);
int laser_count(VelodyneModel model);

struct VelodyneLaser {
  double vertical_angle = 0.0;         ///< rad
  double rotational_correction = 0.0;  ///< rad
  double distance_correction = 0.0;    ///< m (at 25.04 m)
  double vertical_offset = 0.0;        ///< m
  double horizontal_offset = 0.0;      ///< m
  /// HDL-64E: distance corrections measured at 2.4 m along x and 1.93 m along y (m).
  bool two_point_correction = false;
  double distance_correction_x = 0.0;
  double distance_correction_y = 0.0;
};

struct VelodyneCalibration {
  std::vector<VelodyneLaser> lasers;  ///< by laser id
  double distance_resolution = 0.002;  ///< m per raw distance unit
};

/// A calibration file: VeloView's / Velodyne's XML (db.xml: `enabled_` lasers, `px` entries with
/// angles in degrees and offsets in cm) or the ROS driver's YAML (`lasers:` with angles in
/// radians and offsets in m, `distance_resolution`). Fails naming the file and what is missing.
/// Two-point corrections: a YAML laser's `two_pt_correction_available`; in XML every laser of a
/// 64-laser file (the HDL-64E's; other models' files carry the fields unused).
Result<VelodyneCalibration> load_velodyne_calibration(const std::string& path);
/// The nominal calibration of a model (elevation angles of its data sheet, no offsets).
VelodyneCalibration nominal_velodyne_calibration(VelodyneModel model);

struct VelodyneDecoderConfig {
  VelodyneModel model = VelodyneModel::kVlp16;
  double cut_angle_deg = 0.0;     ///< azimuth where one rotation ends and the next begins
  bool per_laser_azimuth = true;  ///< each laser's azimuth at its firing time (else the block's)
  std::string frame_id = "velodyne";
};

struct VelodyneStatistics {
  uint64_t packets = 0;           ///< data packets decoded
  uint64_t position_packets = 0;  ///< GPS position packets (port 8308 size)
  uint64_t malformed = 0;
  uint64_t frames = 0;
  uint64_t points = 0;
  std::string first_error;
};

class VelodyneDecoder {
 public:
  /// Fails when the calibration's laser count is not the model's.
  static Result<VelodyneDecoder> create(VelodyneCalibration calibration, VelodyneDecoderConfig config);

  /// One UDP payload received at `capture_time` (the capture's clock: gives the hour of the
  /// packet's own time). Completed rotations are appended to `frames`.
  void add_packet(std::string_view payload, Timestamp capture_time, std::vector<msgs::PointCloudMessage>& frames);
  /// The last (partial) rotation, if it has points.
  void flush(std::vector<msgs::PointCloudMessage>& frames);
  const VelodyneStatistics& statistics() const { return statistics_; }

 private:
  struct Trig {
    double cos_vertical, sin_vertical, cos_rotation, sin_rotation;
  };
  VelodyneDecoder(VelodyneCalibration calibration, VelodyneDecoderConfig config);
  void malformed(const std::string& what);
  void emit(std::vector<msgs::PointCloudMessage>& frames);
  void count(std::size_t emitted_points);  ///< statistics of a rotation emitted (0: none)
  void add_return(int laser, double azimuth_deg, uint16_t raw_distance, uint8_t intensity, Timestamp time);
  /// Firing offset (s) of channel `channel` (0-31) of block `block` (0-11).
  double firing_offset(int block, int channel) const;

  VelodyneCalibration calibration_;
  VelodyneDecoderConfig config_;
  std::vector<Trig> trig_;
  std::vector<uint32_t> ring_;  // per laser: its rank by elevation (0 the lowest)
  VelodyneStatistics statistics_;
  RotationFrame rotation_;
};

}  // namespace hanzo::fusion::drivers
