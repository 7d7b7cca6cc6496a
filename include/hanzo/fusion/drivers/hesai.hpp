#pragma once
// Hesai Pandar40P LiDAR: UDP data packets into one PointCloudMessage per rotation, with
// per-point times and rings.
//
// Data packet (1262 bytes, or 1266 with the UDP sequence number appended; port 2368 by
// default): 10 blocks of 124 bytes (flag 0xFFEE, azimuth in 0.01 degree, 40 returns of distance
// (4 mm units, little-endian) and reflectivity), then a 22-byte tail: 5 reserved bytes, the
// high-temperature flag, 2 reserved bytes, the motor speed, the microseconds within the second
// (uint32), the return mode (0x37 strongest, 0x38 last, 0x39 dual: blocks in pairs of the same
// firing), a factory byte and the UTC date and time to the second (year - 2000, month, day,
// hour, minute, second).
//
// Geometry, per return of channel c in a block at azimuth a (Hesai's model; the angle
// correction file's elevation e_c and azimuth offset o_c, degrees):
//   d = raw distance x 0.004 m,  b = a + o_c
//   sensor axes (y' toward azimuth 0, x' to its right): x' = d cos(e_c) sin(b), y' = d cos(e_c) cos(b),
//   z = d sin(e_c); output in the LiDAR frame of this project (x forward = azimuth 0, y left,
//   z up): (x, y, z) = (y', -x', z). Returns of distance 0 (no echo) are left out.
//
// Times (the Pandar40P manual's firing sequence): the packet's time is the tail's UTC second
// plus its microseconds; block k (0-9) fired 28.58 + 55.56 x (9 - k) us before it (dual return:
// the pair k / 2 at 28.58 + 55.56 x (4 - k / 2) us), and channel c at the firetime correction
// file's offset from its block (-42.22 .. -3.62 us on the unit of the test data; 0 without the
// file). A sensor without time synchronization counts its own clock from 2017 or an arbitrary
// date: with time_source kAuto the packet's time is used when it lies within
// max_clock_offset_s of the capture's clock, else the capture time (the packet's arrival) takes
// its place (counted: capture_clock_packets).
//
// Frames: a rotation ends where the azimuth wraps past cut_angle_deg (RotationFrame); a
// rotation's first frame may be partial. Rings by elevation (0 the lowest channel).
//
// Failures: packets of another size or without block flags are counted (malformed) and
// skipped; calibration files that do not list 40 channels are refused by name.
#include <cstdint>
#include <string>
#include <string_view>
#include <vector>

#include "hanzo/fusion/core/result.hpp"
#include "hanzo/fusion/core/time.hpp"
#include "hanzo/fusion/drivers/rotation_frame.hpp"
#include "hanzo/fusion/msgs/sensor_messages.hpp"

namespace hanzo::fusion::drivers {

inline constexpr int kHesaiPandar40Channels = 40;

struct HesaiChannel {
  double elevation = 0.0;       ///< rad
  double azimuth_offset = 0.0;  ///< rad, added to the block's azimuth
  double firetime = 0.0;        ///< s from the block's time (negative: before it)
};

struct HesaiCalibration {
  std::vector<HesaiChannel> channels;  ///< channel 1 .. 40 at index 0 .. 39
};

/// The angle correction CSV ("Channel,Elevation,Azimuth", degrees) and, when given (non-empty
/// path), the firetime correction CSV ("Channel,fire time(us)"). Fails naming the file and the
/// line that is wrong or the channels missing.
Result<HesaiCalibration> load_hesai_calibration(const std::string& angle_file, const std::string& firetime_file);

enum class HesaiTimeSource {
  kAuto,     ///< the packet's time when within max_clock_offset_s of the capture clock, else the capture time
  kPacket,   ///< always the packet's own UTC time
  kCapture,  ///< always the capture time of the packet (its arrival)
};

struct HesaiDecoderConfig {
  double cut_angle_deg = 0.0;  ///< azimuth where one rotation ends and the next begins
  HesaiTimeSource time_source = HesaiTimeSource::kAuto;
  double max_clock_offset_s = 10.0;
  std::string frame_id = "hesai";
};

struct HesaiStatistics {
  uint64_t packets = 0;    ///< data packets decoded
  uint64_t malformed = 0;
  uint64_t frames = 0;
  uint64_t points = 0;
  uint64_t capture_clock_packets = 0;  ///< packets timed by the capture clock (kAuto, kCapture)
  std::string first_error;
};

class HesaiDecoder {
 public:
  /// Fails when the calibration does not have 40 channels.
  static Result<HesaiDecoder> create(HesaiCalibration calibration, HesaiDecoderConfig config = {});

  /// One UDP payload received at `capture_time`. Completed rotations are appended to `frames`.
  void add_packet(std::string_view payload, Timestamp capture_time, std::vector<msgs::PointCloudMessage>& frames);
  /// The last (partial) rotation, if it has points.
  void flush(std::vector<msgs::PointCloudMessage>& frames);
  const HesaiStatistics& statistics() const { return statistics_; }

 private:
  HesaiDecoder(HesaiCalibration calibration, HesaiDecoderConfig config);
  void malformed(const std::string& what);
  void count(std::size_t emitted_points);

  struct Trig {
    double cos_elevation, sin_elevation, cos_offset, sin_offset;
  };
  HesaiCalibration calibration_;
  HesaiDecoderConfig config_;
  std::vector<Trig> trig_;  // per channel
  std::vector<uint32_t> ring_;  // per channel: its rank by elevation (0 the lowest)
  HesaiStatistics statistics_;
  RotationFrame rotation_;
};

}  // namespace hanzo::fusion::drivers
