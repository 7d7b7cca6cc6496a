#pragma once
// NMEA-0183 GNSS receivers: sentences into GnssMessage fixes (NMEA 0183 v4.11, any talker: GP,
// GN, GL, GA, GB, ...).
//
// Bytes arrive in any split (a serial port, a TCP stream, a log file); everything between
// sentences (binary protocols interleaved on the same port, noise) is skipped and counted, and
// so is a "sentence" that is not printable or not opened by an address ("$GPGGA,", "$PUBX,"):
// a '$' inside binary data. A
// sentence runs from '$' to CR/LF, at most kMaxSentenceLength characters; its checksum "*HH"
// (XOR of the characters between '$' and '*') is verified when present.
//
// Fixes: one per epoch (a GGA sentence's UTC time), emitted once a sentence of a later epoch or
// flush() shows that the epoch is complete:
//   GGA  position (latitude, longitude, altitude above mean sea level + geoid separation = above
//        the WGS84 ellipsoid), fix quality, satellites used, HDOP. A GGA without the geoid
//        separation (some receivers leave it empty) keeps the altitude above mean sea level (no
//        geoid model is shipped) with unknown_geoid_sigma added to its vertical error.
//   RMC, ZDA  the UTC date (GGA carries the time of day only); a GGA before any date, and without
//        NmeaDecoderConfig::date, is counted (no_date) and left out
//   GST  the position's 1-sigma errors (latitude, longitude, altitude in metres): the fix's
//        covariance diag(lon^2, lat^2, alt^2) in ENU when the GST has the GGA's time (before or
//        after the GGA; a GST without positive errors is ignored)
//   GSA  the fix mode (2D) of the receiver
// Without a GST the covariance is (HDOP x the quality's user equivalent range error)^2 per
// horizontal axis and (vertical_factor x that)^2 vertically.
// Fix types by GGA quality: 0 no fix, 1 GPS / 3 PPS (FIX_3D, FIX_2D when the last GSA said 2D),
// 2 DGPS (FIX_3D), 4 RTK fixed, 5 RTK float; 6 (dead reckoning), 7 (manual) and 8 (simulation)
// are not measurements: NO_FIX. A GGA without a position is counted (no_position) and left out.
// VTG, GLL, GSV, TXT and proprietary sentences are read and ignored (other_sentences).
//
// Failures: none thrown; malformed sentences are counted by reason and the decoder goes on.

#include <cstdint>
#include <optional>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include <Eigen/Core>

#include "hanzo/fusion/core/result.hpp"
#include "hanzo/fusion/msgs/sensor_messages.hpp"

namespace hanzo::fusion::drivers {

inline constexpr std::size_t kMaxSentenceLength = 164;  ///< NMEA says 82; some receivers write longer

/// One sentence: "$GNGGA,..." is talker "GN", type "GGA", fields after the type.
struct NmeaSentence {
  std::string talker;  ///< two letters, or "P" + maker for proprietary sentences ("PUBX")
  std::string type;    ///< "GGA", "RMC", ...
  std::vector<std::string> fields;
  bool checksum_present = false;
};

/// Parses one sentence (leading '$' or '!', trailing CR/LF ignored); fails naming what is wrong
/// (no '$', a bad or mismatched checksum, a non-printable character, an empty address).
Result<NmeaSentence> parse_nmea_sentence(std::string_view line);

struct NmeaDecoderConfig {
  /// User equivalent range errors (m, 1 sigma per horizontal axis per unit of HDOP) for fixes
  /// without a GST, by GGA quality: autonomous, DGPS / SBAS, RTK float, RTK fixed.
  double uere_autonomous = 2.5;
  double uere_dgps = 1.0;
  double uere_rtk_float = 0.3;
  double uere_rtk_fixed = 0.02;
  double vertical_factor = 1.7;  ///< vertical sigma / horizontal sigma without a GST (typical VDOP / HDOP)
  /// Vertical sigma (m) added where the GGA gives no geoid separation: the geoid lies within
  /// about +-100 m of the ellipsoid (EGM96), 30 m RMS.
  double unknown_geoid_sigma = 30.0;
  /// The UTC date ("YYYY-MM-DD") of fixes before the stream's first RMC or ZDA; empty: such fixes
  /// are left out.
  std::string date;
};

struct NmeaStatistics {
  uint64_t sentences = 0;        ///< checksum-valid sentences read
  uint64_t fixes = 0;            ///< GnssMessages emitted
  uint64_t checksum_errors = 0;
  uint64_t malformed = 0;        ///< unparsable sentences or fields (too long, bad numbers)
  uint64_t no_position = 0;      ///< GGA without latitude / longitude
  uint64_t no_date = 0;          ///< GGA before any date
  uint64_t other_sentences = 0;  ///< sentences that carry nothing a fix uses
  uint64_t skipped_bytes = 0;    ///< bytes outside sentences
  uint64_t gst = 0;              ///< fixes whose covariance came from a GST
  uint64_t no_geoid_separation = 0;  ///< GGA without the geoid separation (altitude above mean sea level)
  std::string first_error;       ///< the first malformed or checksum error, for a one-line report
};

class NmeaDecoder {
 public:
  static Result<NmeaDecoder> create(NmeaDecoderConfig config = {});

  /// Decodes `bytes`; the fixes completed by them are appended to `fixes` in time order.
  void feed(std::string_view bytes, std::vector<msgs::GnssMessage>& fixes);
  /// The end of the stream: the last epoch's fix (if any) is appended.
  void flush(std::vector<msgs::GnssMessage>& fixes);
  const NmeaStatistics& statistics() const { return statistics_; }

 private:
  struct Pending {
    double time_of_day;  // s since UTC midnight
    msgs::GnssMessage fix;
    bool has_gst = false;
    bool unknown_geoid = false;
    double hdop_sigma = 0.0;  // the quality's horizontal sigma per unit of HDOP
  };
  explicit NmeaDecoder(NmeaDecoderConfig config) : config_(std::move(config)) {}
  void handle_line(std::string_view line, std::vector<msgs::GnssMessage>& fixes);
  void handle(const NmeaSentence& sentence, std::vector<msgs::GnssMessage>& fixes);
  void malformed(const std::string& what);
  /// The sentence being read ends without its line end (cut off, too long).
  void abandon_line(const std::string& why);
  /// Emits the pending fix when `time_of_day` is of a later epoch (or always, when none is given).
  void complete_epoch(std::optional<double> time_of_day, std::vector<msgs::GnssMessage>& fixes);

  NmeaDecoderConfig config_;
  NmeaStatistics statistics_;
  std::string line_;           // the sentence being read
  bool in_sentence_ = false;
  std::optional<int64_t> date_days_;       // days since 1970-01-01 of the last RMC / ZDA
  std::optional<double> date_time_of_day_;  // its time of day
  int gsa_mode_ = 0;                       // the last GSA's fix mode (1 none, 2 2D, 3 3D)
  std::optional<std::pair<double, Eigen::Vector3d>> gst_;  // a GST (time of day, ENU variances) before its epoch's GGA
  std::optional<Pending> pending_;
};

}  // namespace hanzo::fusion::drivers
