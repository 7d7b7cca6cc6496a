#pragma once
// Xsens MTi IMUs and GNSS/INS (MTi-1 .. MTi-G-710, MTi-680G): the MTData2 stream of the Xbus
// protocol (Xsens "MT Low Level Communication Protocol", document MT0101P) into ImuMessages and,
// with a GNSS receiver inside, GnssMessages.
//
// Framing: preamble 0xFA, bus identifier 0xFF, message identifier (0x36 = MTData2), length
// (one byte; 0xFF: two bytes follow, big-endian), payload, checksum (the bytes from the bus
// identifier through the checksum sum to 0 modulo 256). Bytes arrive in any split; a frame with
// a bad checksum is counted and the search for the next preamble goes on one byte after its
// start; other messages (acknowledgements, configuration) are counted and skipped.
//
// MTData2 payload: packets of a 16-bit data identifier (big-endian; bits 0-1 the number format:
// Float32, FP12.20, FP16.32, Float64; bits 2-3 the coordinate system: ENU, NED, NWU), a one-byte
// size and the data, big-endian. Decoded: PacketCounter, SampleTimeFine (10 kHz), UTCTime,
// StatusWord / StatusByte, Quaternion, EulerAngles (roll, pitch, yaw about x, y, z in degrees,
// R = Rz(yaw) Ry(pitch) Rx(roll)), Acceleration, FreeAcceleration, DeltaV, RateOfTurn, DeltaQ,
// MagneticField, LatLon, AltitudeEllipsoid, VelocityXYZ, GNSSPVTData (u-blox NAV-PVT's layout);
// other packets are counted and skipped.
//
// ImuMessage: specific force = Acceleration (m/s^2, sensor frame), else DeltaV / dt; angular
// velocity = RateOfTurn (rad/s), else DeltaQ's rotation vector / dt (dt: SampleTimeFine since the previous
// message with inertial data; the first such message of a stream without Acceleration /
// RateOfTurn is left out). Orientation R_world_sensor in ENU from Quaternion or EulerAngles (NED
// and NWU turned into ENU). A message without inertial data (GNSSPVTData alone) gives no
// ImuMessage.
// GnssMessage from GNSSPVTData with a 2D / 3D fix (fix types 2, 3; 4 GNSS + dead reckoning):
// latitude / longitude (1e-7 degree), height above the ellipsoid (mm), covariance
// diag(hAcc^2 / 2, hAcc^2 / 2, vAcc^2) (hAcc is u-blox's horizontal accuracy estimate, taken as
// the 2D root of the two axes' variances), satellites, HDOP (0.01). Its time: the PVT's own UTC
// date and time (year .. second + nano) when the validity flags say date and time are valid.
//
// Time of an ImuMessage: UTCTime when its flags say UTC is valid (bit 2); otherwise the last
// valid UTCTime plus the SampleTimeFine ticks since (wrapping at 2^32); with no UTC yet
// SampleTimeFine / 10 kHz since the device started, and statistics().device_clock counts those.
//
// Failures: none thrown; malformed packets are counted by reason and decoding goes on.

#include <cstdint>
#include <optional>
#include <span>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include <Eigen/Core>
#include <Eigen/Geometry>

#include "hanzo/fusion/core/result.hpp"
#include "hanzo/fusion/core/time.hpp"
#include "hanzo/fusion/msgs/sensor_messages.hpp"

namespace hanzo::fusion::drivers {

inline constexpr uint8_t kXsensMtData2 = 0x36;

enum class XsensCoordinates { kEnu, kNed, kNwu };

struct XsensUtcTime {
  uint32_t nanoseconds = 0;  ///< within the second
  uint16_t year = 0;
  uint8_t month = 0, day = 0, hour = 0, minute = 0, second = 0;
  uint8_t flags = 0;  ///< bit 0 valid time of week, bit 1 valid week number, bit 2 valid UTC
  bool valid() const { return (flags & 0x04) != 0; }
  /// Time since the Unix epoch; fails on a date or time out of range.
  Result<Timestamp> to_timestamp() const;
};

/// GNSSPVTData (0x7010, 94 bytes): u-blox NAV-PVT's fields, units as the receiver gives them.
struct XsensGnssPvt {
  uint32_t itow = 0;  ///< ms of the GPS week
  uint16_t year = 0;
  uint8_t month = 0, day = 0, hour = 0, minute = 0, second = 0;
  uint8_t valid = 0;  ///< bit 0 valid date, bit 1 valid time, bit 2 fully resolved
  uint32_t time_accuracy = 0;  ///< ns
  int32_t nano = 0;            ///< ns added to the second (may be negative)
  uint8_t fix_type = 0;        ///< 0 none, 1 dead reckoning, 2 2D, 3 3D, 4 GNSS + dead reckoning, 5 time only
  uint8_t flags = 0;           ///< bit 0 gnssFixOK
  uint8_t satellites = 0;
  int32_t longitude = 0, latitude = 0;          ///< 1e-7 degree
  int32_t height = 0, height_msl = 0;           ///< mm above the ellipsoid / mean sea level
  uint32_t horizontal_accuracy = 0, vertical_accuracy = 0;  ///< mm
  int32_t velocity_north = 0, velocity_east = 0, velocity_down = 0, ground_speed = 0;  ///< mm/s
  int32_t heading_of_motion = 0;  ///< 1e-5 degree
  uint32_t speed_accuracy = 0;    ///< mm/s
  uint32_t heading_accuracy = 0;  ///< 1e-5 degree
  int32_t heading_of_vehicle = 0; ///< 1e-5 degree
  uint16_t gdop = 0, pdop = 0, tdop = 0, vdop = 0, hdop = 0, ndop = 0, edop = 0;  ///< 0.01
};

/// One MTData2 message's packets (each present when the message carried it). Vectors in the
/// sensor frame except velocity (the coordinate system's axes); values converted from the number
/// format to double.
struct XsensMtData2 {
  std::optional<uint16_t> packet_counter;
  std::optional<uint32_t> sample_time_fine;  ///< 10 kHz ticks since the device started
  std::optional<XsensUtcTime> utc;
  std::optional<uint32_t> status;            ///< StatusWord, or StatusByte widened
  std::optional<Eigen::Vector3d> euler_degrees;   ///< roll, pitch, yaw
  std::optional<Eigen::Quaterniond> quaternion;   ///< the sensor's orientation in `coordinates`
  std::optional<Eigen::Vector3d> acceleration;    ///< m/s^2, specific force
  std::optional<Eigen::Vector3d> free_acceleration;  ///< m/s^2, gravity removed, in `coordinates`
  std::optional<Eigen::Vector3d> delta_v;         ///< m/s over the output interval
  std::optional<Eigen::Vector3d> rate_of_turn;    ///< rad/s
  std::optional<Eigen::Quaterniond> delta_q;      ///< rotation over the output interval
  std::optional<Eigen::Vector3d> magnetic_field;  ///< arbitrary units (normalized to the calibration)
  std::optional<Eigen::Vector2d> lat_lon;         ///< degrees
  std::optional<double> altitude_ellipsoid;       ///< m
  std::optional<Eigen::Vector3d> velocity;        ///< m/s in `coordinates`
  std::optional<XsensGnssPvt> gnss_pvt;
  XsensCoordinates coordinates = XsensCoordinates::kEnu;  ///< of the orientation / velocity packets
  uint32_t unknown_packets = 0;                   ///< packets skipped (identifiers not listed above)
};

/// Decodes one MTData2 payload (after the length byte(s), before the checksum); fails naming the
/// packet that runs past the payload or has the wrong size for its identifier.
Result<XsensMtData2> decode_mtdata2(std::span<const uint8_t> payload);

/// R_world_sensor in ENU from a message's Quaternion, else its EulerAngles, in its coordinates.
std::optional<Eigen::Quaterniond> xsens_orientation_enu(const XsensMtData2& message);

struct XsensStatistics {
  uint64_t messages = 0;         ///< checksum-valid frames read
  uint64_t mtdata2 = 0;          ///< of them MTData2
  uint64_t imu_messages = 0;     ///< ImuMessages emitted
  uint64_t gnss_fixes = 0;       ///< GnssMessages emitted
  uint64_t checksum_errors = 0;
  uint64_t malformed = 0;        ///< MTData2 payloads that did not decode, or with non-finite inertial values
  uint64_t other_messages = 0;   ///< frames of other message identifiers
  uint64_t skipped_bytes = 0;    ///< bytes outside frames
  uint64_t without_inertial = 0; ///< MTData2 messages without inertial data or time (or no interval yet for DeltaV / DeltaQ)
  uint64_t gnss_without_fix = 0; ///< GNSSPVTData without a 2D / 3D fix, a valid date and time, or a position in range
  uint64_t device_clock = 0;     ///< ImuMessages timed by SampleTimeFine alone (no valid UTC yet)
  uint64_t unknown_packets = 0;
  std::string first_error;       ///< the first checksum or decoding error, for a one-line report
};

struct XsensDecoderConfig {
  std::string frame_id = "imu";
};

class XsensDecoder {
 public:
  explicit XsensDecoder(XsensDecoderConfig config = {}) : config_(std::move(config)) {}

  /// Decodes `bytes`; complete frames' messages are appended in stream order, and every
  /// decoded MTData2 message to `decoded` when given (tools that need more than the standard
  /// messages).
  void feed(std::string_view bytes, std::vector<msgs::ImuMessage>& imu, std::vector<msgs::GnssMessage>& gnss,
            std::vector<XsensMtData2>* decoded = nullptr);
  const XsensStatistics& statistics() const { return statistics_; }
  /// Bytes held waiting for the rest of a frame (a cut-off stream leaves them here).
  std::size_t pending_bytes() const { return buffer_.size(); }

 private:
  void handle(const XsensMtData2& message, std::vector<msgs::ImuMessage>& imu, std::vector<msgs::GnssMessage>& gnss);
  std::optional<Timestamp> time_of(const XsensMtData2& message);
  void error(uint64_t& counter, const std::string& what);

  XsensDecoderConfig config_;
  XsensStatistics statistics_;
  std::string buffer_;
  std::optional<std::pair<Timestamp, uint32_t>> utc_anchor_;  // the last valid UTC and its SampleTimeFine
  std::optional<uint32_t> previous_inertial_fine_;            // SampleTimeFine of the last inertial message
};

}  // namespace hanzo::fusion::drivers
