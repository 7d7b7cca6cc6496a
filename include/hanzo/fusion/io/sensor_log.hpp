#pragma once
// The hanzo-fusion sensor log: an MCAP file whose messages are hanzo.fusion.v1 protobuf
// messages (schema encoding "protobuf", the schema data a serialized FileDescriptorSet of the
// message's .proto file and its imports, message encoding "protobuf"), one channel per topic.
// Any MCAP tool with protobuf support (Foxglove, mcap CLI) can open it.
//
// Topics are free-form; the importers and the simulator use "/<sensor name>" (the name that
// joins the fusion configuration and the calibration, e.g. "/imu", "/lidar_front"), and put
// the sensor name and modality in the channel metadata ("sensor", "modality").
//
// A message's log time is its sensor timestamp (timestamp_ns): replaying a log in log-time
// order replays the sensors in the order they measured.
//
// Foxglove mirror channels: so that a log opens in Foxglove with nothing to convert, the
// writer by default also writes every pose estimate, point cloud, GNSS fix and image on
// "<topic>/foxglove" in Foxglove's own schema (foxglove.PoseInFrame, foxglove.PointCloud,
// foxglove.LocationFix, foxglove.RawImage, or foxglove.CompressedImage for images stored as
// PNG / JPEG; channel metadata "mirror_of" = the topic). This doubles the size of point-cloud
// and image data; SensorLogWriterConfig::foxglove_channels = false leaves the mirrors out.
// Readers of hanzo.fusion.v1 messages skip them.

#include <cstdint>
#include <functional>
#include <map>
#include <memory>
#include <optional>
#include <string>
#include <string_view>
#include <variant>

#include "hanzo/fusion/core/result.hpp"
#include "hanzo/fusion/core/time.hpp"
#include "hanzo/fusion/io/mcap.hpp"
#include "hanzo/fusion/msgs/estimate_messages.hpp"
#include "hanzo/fusion/msgs/sensor_messages.hpp"

namespace google::protobuf {
class Descriptor;
class Message;
}  // namespace google::protobuf

namespace hanzo::fusion::io {

/// A serialized google.protobuf.FileDescriptorSet holding the file that defines `descriptor`
/// and every file it imports (dependencies first), as MCAP's protobuf profile asks.
std::string file_descriptor_set(const google::protobuf::Descriptor& descriptor);

/// How a writer stores images: raw pixels, or PNG (lossless) / JPEG (lossy) files that the
/// reader decodes back to raw pixels. Encodings a format cannot hold stay raw (depth32f; depth16
/// under JPEG).
enum class ImageCompression { kNone, kPng, kJpeg };
/// "none", "png", "jpeg".
std::optional<ImageCompression> image_compression_from_string(std::string_view name);

struct SensorLogWriterConfig {
  mcap::McapWriterConfig mcap;                     ///< chunk size and compression
  bool foxglove_channels = true;                   ///< also write the Foxglove mirror channels
  std::string foxglove_topic_suffix = "/foxglove";  ///< mirror topic = topic + suffix
  ImageCompression image_compression = ImageCompression::kNone;
  int jpeg_quality = 90;                           ///< 1..100, with ImageCompression::kJpeg
  /// Point clouds: 0 stores the exact float coordinates (packed); > 0 stores them as multiples
  /// of this many meters (msgs::PointEncoding::kQuantized), a third of the size compressed.
  double point_resolution = 0.0;
  /// When set, every image passes through it (on a copy) before anything of it is written: the
  /// privacy filter of `import --privacy`. An error fails the write.
  std::function<Status(msgs::ImageMessage&)> image_filter;
};

class SensorLogWriter {
 public:
  static Result<std::unique_ptr<SensorLogWriter>> open(const std::string& path, const SensorLogWriterConfig& config);
  static Result<std::unique_ptr<SensorLogWriter>> open(const std::string& path);  ///< default configuration

  /// Validates the message (msgs::validate) and appends it on `topic` at its timestamp (and its
  /// Foxglove mirror, when configured). A message that fails validation is not written; the
  /// error names topic and field.
  /// `sensor_name` goes into the channel metadata when the topic is first used (default: the
  /// topic without its leading '/').
  Status write(const std::string& topic, const msgs::SensorMessage& message, const std::string& sensor_name = {});
  Status write(const std::string& topic, const msgs::PoseEstimate& pose);
  /// Any protobuf message at `log_time` (its schema is taken from its descriptor).
  Status write_proto(const std::string& topic, const google::protobuf::Message& message, Timestamp log_time,
                     const std::map<std::string, std::string>& channel_metadata = {});
  Status add_metadata(const mcap::Metadata& metadata) { return mcap_->add_metadata(metadata); }
  Status close() { return mcap_->close(); }
  const mcap::Statistics& statistics() const { return mcap_->statistics(); }

 private:
  SensorLogWriter(std::unique_ptr<mcap::McapWriter> writer, SensorLogWriterConfig config)
      : mcap_(std::move(writer)), config_(std::move(config)) {}
  Status write_mirror(const std::string& topic, const google::protobuf::Message* mirror, Timestamp time);
  Status write_message(const std::string& topic, const msgs::SensorMessage& message, const std::string& sensor_name);

  std::unique_ptr<mcap::McapWriter> mcap_;
  SensorLogWriterConfig config_;
  std::map<std::string, uint16_t> channel_by_topic_;
  std::string serialize_buffer_;
};

/// One decoded log message: a sensor message or a pose estimate.
struct LogEntry {
  std::string topic;
  Timestamp log_time;
  std::variant<msgs::SensorMessage, msgs::PoseEstimate> message;
  /// For an 8-bit image stored compressed: the stored file ("jpeg" or "png") as it is in the log,
  /// so a writer can pass it on without encoding it again; empty formats otherwise.
  std::string stored_image_format;
  std::string stored_image_file;
};

/// Reads a sensor log in log-time order, decoding the hanzo.fusion.v1 messages. Channels with
/// other schemas (e.g. Foxglove visualization channels) are skipped and counted.
class SensorLogReader {
 public:
  static Result<std::unique_ptr<SensorLogReader>> open(const std::string& path, const mcap::ReadOptions& options = {});

  /// true and fills `entry`; false at the end. A message that does not decode or fails
  /// validation returns an error naming topic and time; reading can continue with the next
  /// call. A corrupted chunk returns its error once (its messages are lost) and is counted in
  /// corrupted_chunks(); later calls go on with the rest of the file.
  Result<bool> next(LogEntry& entry);

  const mcap::McapReader& mcap() const { return *mcap_; }
  uint64_t skipped_messages() const { return skipped_; }
  /// Messages of any topic taken from the file so far (decoded, skipped or refused).
  uint64_t records_read() const { return records_read_; }
  /// Log time of the last message taken from the file.
  Timestamp last_log_time() const { return last_log_time_; }
  /// After the last message: fails when the file was not read whole (truncated after its last
  /// complete record, or corrupted chunks skipped), saying what was lost; ok otherwise. Readers
  /// that must not pass a partial log off as a whole one call it at the end.
  Status complete() const;
  /// Corrupted chunks met so far, and the first one's error ("" while none).
  uint64_t corrupted_chunks() const { return corrupted_chunks_; }
  const std::string& first_chunk_error() const { return first_chunk_error_; }

 private:
  SensorLogReader() = default;
  std::unique_ptr<mcap::McapReader> mcap_;
  std::unique_ptr<mcap::MessageIterator> iterator_;
  uint64_t skipped_ = 0;
  uint64_t records_read_ = 0;
  Timestamp last_log_time_;
  uint64_t corrupted_chunks_ = 0;
  std::string first_chunk_error_;
};

}  // namespace hanzo::fusion::io
