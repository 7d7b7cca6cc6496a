#pragma once
// Ouster LiDARs (OS-0, OS-1, OS-2; 32 to 128 beams): lidar packets into one PointCloudMessage
// per frame (a full rotation), IMU packets into ImuMessages, with the sensor's metadata JSON.
//
// Metadata (as `ouster-cli` / the sensor's HTTP API write it): the flat layout of firmware 2.x
// (beam_altitude_angles, beam_azimuth_angles, data_format, lidar_origin_to_beam_origin_mm,
// lidar_to_sensor_transform, imu_to_sensor_transform), the nested layout of newer firmware
// (beam_intrinsics, lidar_data_format, lidar_intrinsics, imu_intrinsics, config_params) and the
// reduced legacy file (angles and lidar_mode only: 16 columns per packet, the OS-1's default
// transforms and beam offset of 12.163 mm).
//
// Lidar packet profiles: LEGACY (per column: time ns, measurement id, frame id, encoder count;
// per pixel 12 bytes: range (20 bits, mm), signal, reflectivity, near-IR; status word
// 0xFFFFFFFF when valid) and the profiles with a 32-byte packet header (its frame id at byte 2)
// and footer, per column time, measurement id and status (bit 0 valid), and per pixel:
//   RNG19_RFL8_SIG16_NIR16 (12 bytes: range 19 bits mm, reflectivity at byte 4),
//   RNG19_RFL8_SIG16_NIR16_ZONE16 (the same, a zone mask after),
//   RNG19_RFL8_SIG16_NIR16_DUAL and FIVE_WORD_PIXEL (16 / 20 bytes: range, reflectivity at byte 3;
//     second range at byte 4, its reflectivity at byte 7),
//   RNG15_RFL8_NIR8 (4 bytes: range 15 bits in 8 mm units, reflectivity at byte 2),
//   RNG15_RFL8_NIR8_ZONE16 (8 bytes, the same first 4) and RNG15_RFL8_NIR8_DUAL (8 bytes: the
//     second return's range and reflectivity at bytes 4 and 6).
// A second return becomes a point of its own (one equal to the first is left out). Other profiles
// (the FUSA header, window fields) are refused by create().
//
// IMU packet profiles: LEGACY (48 bytes: one sample, g and deg/s) and ACCEL32_GYRO32_NMEA (the
// 32-byte header, a 100-byte NMEA block, imu_measurements_per_packet samples of 36 bytes: time ns,
// measurement id, status (bit 0 valid), acceleration x, y, z in m/s^2 and angular velocity in
// rad/s as floats; the footer). Zone monitoring packets (680 bytes) are counted, not decoded.
// Points (the ouster-sdk's model): for measurement id m of W columns and beam b,
//   encoder angle e = 2 pi (1 - m / W), azimuth a = e - beam_azimuth_b, elevation p = beam_altitude_b
//   direction d = (cos a cos p, sin a cos p, sin p), n = lidar_origin_to_beam_origin
//   point (lidar frame, mm) = range d + (n cos e - n d_x, n sin e - n d_y, -n d_z)
// then lidar_to_sensor_transform (its translation in mm), output in metres in the sensor frame.
// Pixels of range 0 (no return) are left out; the intensity is the reflectivity / 255 (LEGACY:
// its calibrated reflectivity clamped to 255). Rings are the beams ranked by elevation.
//
// Times: each column's own time. Sensor clocks that run from power-on (not PTP or GPS, more than
// a day from the capture time) are placed at the capture time of the stream's first packet.
//
// Frames: a frame ends when a packet of another frame id arrives (or at flush()); it is complete
// when every column of the column window came. Columns with an invalid status are left out.
// Malformed packets (a size that is neither the lidar nor the IMU packet's) are counted.

#include <array>
#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "hanzo/fusion/core/result.hpp"
#include "hanzo/fusion/core/time.hpp"
#include "hanzo/fusion/msgs/sensor_messages.hpp"

namespace hanzo::fusion::drivers {

struct OusterMetadata {
  std::string product;     ///< e.g. "OS-1-32-G" (empty when the file does not say)
  std::string lidar_mode;  ///< "1024x10", ...
  std::string udp_profile_lidar = "LEGACY";
  std::string udp_profile_imu = "LEGACY";
  int imu_measurements_per_packet = 0;  ///< ACCEL32_GYRO32_NMEA: samples per IMU packet
  int pixels_per_column = 0;   ///< beams
  int columns_per_frame = 0;   ///< W
  int columns_per_packet = 16;
  std::array<int, 2> column_window{0, 0};  ///< first and last column measured (inclusive)
  std::vector<double> beam_altitude_deg, beam_azimuth_deg;
  double lidar_origin_to_beam_origin_mm = 12.163;
  Eigen::Matrix4d lidar_to_sensor = Eigen::Matrix4d::Identity();  ///< translation in mm
  Eigen::Matrix4d imu_to_sensor = Eigen::Matrix4d::Identity();    ///< translation in mm
};

/// Reads a metadata JSON file of any of the three layouts; fails naming the missing field.
Result<OusterMetadata> load_ouster_metadata(const std::string& path);
Result<OusterMetadata> parse_ouster_metadata(const std::string& json_text);

/// One decoded frame: the cloud and the frame's range image (pixels_per_column x
/// columns_per_frame, row-major, staggered as measured, mm; 0 where nothing returned or no
/// column came) for inspection.
struct OusterFrame {
  msgs::PointCloudMessage cloud;
  std::vector<uint32_t> range_mm;
  uint16_t frame_id = 0;
  int columns = 0;        ///< valid columns received
  bool complete = false;  ///< every column of the column window came
};

struct OusterStatistics {
  uint64_t lidar_packets = 0;
  uint64_t imu_packets = 0;
  uint64_t malformed = 0;
  uint64_t zone_packets = 0;        ///< zone monitoring packets (not decoded)
  uint64_t invalid_columns = 0;
  uint64_t invalid_imu_samples = 0;
  uint64_t frames = 0;
  uint64_t incomplete_frames = 0;
  std::string first_error;
};

/// Where a lidar profile's pixel fields lie (from the pixel's first byte, little-endian); a
/// second return when second_range_bits > 0.
struct OusterPixelLayout {
  std::size_t bytes = 12;
  int range_bits = 20, range_shift = 0;  ///< range (mm) = the field << range_shift
  int reflectivity_byte = 4;
  int second_range_bit = 0, second_range_bits = 0, second_reflectivity_byte = 0;
};

/// The layout of a lidar profile named as in the metadata; nullopt for one not decoded.
std::optional<OusterPixelLayout> ouster_pixel_layout(const std::string& profile);

class OusterDecoder {
 public:
  /// Fails for a lidar or IMU packet profile not listed above, or metadata whose beam lists do
  /// not match pixels_per_column.
  static Result<OusterDecoder> create(OusterMetadata metadata, std::string frame_id = "lidar");

  /// One UDP payload of the lidar or IMU port, received at `capture_time`. Completed frames and
  /// IMU samples are appended.
  void add_packet(std::string_view payload, Timestamp capture_time, std::vector<OusterFrame>& frames, std::vector<msgs::ImuMessage>& imu);
  void flush(std::vector<OusterFrame>& frames);
  const OusterStatistics& statistics() const { return statistics_; }
  const OusterMetadata& metadata() const { return metadata_; }
  std::size_t lidar_packet_bytes() const;
  std::size_t imu_packet_bytes() const;


 private:
  explicit OusterDecoder(OusterMetadata metadata, std::string frame_id);
  void malformed(const std::string& what);
  void emit(std::vector<OusterFrame>& frames);
  Timestamp sensor_time(uint64_t nanoseconds, Timestamp capture_time);
  void add_column(uint64_t time_ns, uint16_t measurement_id, const uint8_t* pixels, Timestamp capture_time);
  void add_point(OusterFrame& frame, std::size_t index, uint32_t range_mm, float intensity, uint32_t ring, Timestamp time);
  void add_imu_packet(const uint8_t* data, Timestamp capture_time, std::vector<msgs::ImuMessage>& imu);

  OusterMetadata metadata_;
  std::string frame_id_;
  bool legacy_ = true;
  OusterPixelLayout layout_;
  std::vector<Eigen::Vector3d> direction_, offset_mm_;  // per (beam, measurement id): W x H
  std::vector<uint32_t> ring_;
  Eigen::Matrix3d rotation_;                            // lidar to sensor
  Eigen::Vector3d translation_mm_;
  OusterStatistics statistics_;
  std::optional<OusterFrame> frame_;
  std::vector<bool> seen_;          // columns of the current frame
  std::optional<int64_t> clock_offset_ns_;  // capture time - sensor time, for power-on clocks
};

}  // namespace hanzo::fusion::drivers
