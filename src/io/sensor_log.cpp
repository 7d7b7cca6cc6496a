#include "hanzo/fusion/io/sensor_log.hpp"

#include <cmath>
#include <set>
#include <type_traits>

#include <fmt/format.h>
#include <google/protobuf/descriptor.h>
#include <google/protobuf/descriptor.pb.h>

#include "foxglove_convert.hpp"
#include "image_compression.hpp"
#include "hanzo/fusion/msgs/convert.hpp"
#include "hanzo/fusion/msgs/validate.hpp"
#include "hanzo/fusion/v1/estimates.pb.h"
#include "hanzo/fusion/v1/sensors.pb.h"

namespace hanzo::fusion::io {
namespace {

void add_file_with_dependencies(const google::protobuf::FileDescriptor* file, std::set<std::string>& seen,
                                google::protobuf::FileDescriptorSet& set) {
  if (!seen.insert(file->name()).second) return;
  for (int i = 0; i < file->dependency_count(); ++i) add_file_with_dependencies(file->dependency(i), seen, set);
  file->CopyTo(set.add_file());
}

// Decodes a payload of the hanzo.fusion.v1 message `V1` into the engine struct (from_proto validates).
template <typename V1>
Result<LogEntry> decode(const mcap::MessageView& view) {
  V1 proto;
  if (!proto.ParseFromArray(view.data.data(), static_cast<int>(view.data.size()))) {
    return Error(fmt::format("{} at {} ns: payload is not a valid {}", view.channel->topic, view.log_time,
                             V1::descriptor()->full_name()));
  }
  std::string stored_format, stored_file;
  if constexpr (std::is_same_v<V1, v1::ImageMessage>) {
    if (!proto.compression().empty() && proto.encoding() != "depth16") {
      stored_format = proto.compression();
      stored_file = proto.data();
    }
    if (Status decoded = decompress_image(proto); !decoded) {
      return Error(fmt::format("{} at {} ns: {}", view.channel->topic, view.log_time, decoded.error().message), decoded.error().field);
    }
  }
  auto message = msgs::from_proto(proto);
  if (!message) return Error(fmt::format("{} at {} ns: {}", view.channel->topic, view.log_time, message.error().message));
  LogEntry entry;
  entry.topic = view.channel->topic;
  entry.log_time = Timestamp::from_nanoseconds(static_cast<int64_t>(view.log_time));
  entry.message = std::move(*message);
  entry.stored_image_format = std::move(stored_format);
  entry.stored_image_file = std::move(stored_file);
  return entry;
}

}  // namespace

std::optional<ImageCompression> image_compression_from_string(std::string_view name) {
  if (name == "none") return ImageCompression::kNone;
  if (name == "png") return ImageCompression::kPng;
  if (name == "jpeg") return ImageCompression::kJpeg;
  return std::nullopt;
}

std::string file_descriptor_set(const google::protobuf::Descriptor& descriptor) {
  google::protobuf::FileDescriptorSet set;
  std::set<std::string> seen;
  add_file_with_dependencies(descriptor.file(), seen, set);
  return set.SerializeAsString();
}

Result<std::unique_ptr<SensorLogWriter>> SensorLogWriter::open(const std::string& path) {
  return open(path, SensorLogWriterConfig{});
}

Result<std::unique_ptr<SensorLogWriter>> SensorLogWriter::open(const std::string& path, const SensorLogWriterConfig& config) {
  if (config.foxglove_channels && config.foxglove_topic_suffix.empty()) {
    return Error("sensor log: foxglove_topic_suffix must not be empty (mirrors would share the topics they mirror)");
  }
  if (!(std::isfinite(config.point_resolution) && config.point_resolution >= 0)) {
    return Error(fmt::format("sensor log: point_resolution {} m: expected 0 (exact) or a positive number", config.point_resolution));
  }
  if (config.jpeg_quality < 1 || config.jpeg_quality > 100) {
    return Error(fmt::format("sensor log: jpeg_quality {}: expected 1..100", config.jpeg_quality));
  }
  std::unique_ptr<mcap::McapWriter> writer;
  HANZO_ASSIGN_OR_RETURN(writer, mcap::McapWriter::open(path, config.mcap));
  HANZO_RETURN_IF_ERROR(writer->add_metadata({"hanzo-fusion", {{"log_format", "hanzo.fusion.v1 sensor log"}, {"log_format_version", "1"}}}));
  return std::unique_ptr<SensorLogWriter>(new SensorLogWriter(std::move(writer), config));
}

Status SensorLogWriter::write_proto(const std::string& topic, const google::protobuf::Message& message, Timestamp log_time,
                                    const std::map<std::string, std::string>& channel_metadata) {
  if (log_time.nanoseconds() < 0) return Error(fmt::format("{}: negative log time {} ns", topic, log_time.nanoseconds()));
  auto channel = channel_by_topic_.find(topic);
  if (channel == channel_by_topic_.end()) {
    const google::protobuf::Descriptor& descriptor = *message.GetDescriptor();
    uint16_t schema_id = 0;
    HANZO_ASSIGN_OR_RETURN(schema_id, mcap_->add_schema(descriptor.full_name(), "protobuf", file_descriptor_set(descriptor)));
    uint16_t channel_id = 0;
    HANZO_ASSIGN_OR_RETURN(channel_id, mcap_->add_channel(schema_id, topic, "protobuf", channel_metadata));
    channel = channel_by_topic_.emplace(topic, channel_id).first;
  }
  serialize_buffer_.clear();
  if (!message.SerializeToString(&serialize_buffer_)) return Error(fmt::format("{}: cannot serialize the message", topic));
  const auto time = static_cast<uint64_t>(log_time.nanoseconds());
  return mcap_->write(channel->second, time, time, serialize_buffer_);
}

Status SensorLogWriter::write(const std::string& topic, const msgs::SensorMessage& message, const std::string& sensor_name) {
  if (config_.image_filter) {
    if (const auto* image = std::get_if<msgs::ImageMessage>(&message)) {
      msgs::ImageMessage filtered = *image;
      if (Status passed = config_.image_filter(filtered); !passed) return Error(fmt::format("{}: {}", topic, passed.error().message));
      return write_message(topic, msgs::SensorMessage(std::move(filtered)), sensor_name);
    }
  }
  return write_message(topic, message, sensor_name);
}

Status SensorLogWriter::write_message(const std::string& topic, const msgs::SensorMessage& message, const std::string& sensor_name) {
  return std::visit(
      [&](const auto& typed) -> Status {
        if (Status valid = msgs::validate(typed); !valid) return Error(fmt::format("{}: {}", topic, valid.error().message), valid.error().field);
        const std::string sensor = sensor_name.empty() ? (topic.starts_with('/') ? topic.substr(1) : topic) : sensor_name;
        const std::map<std::string, std::string> metadata = {{"sensor", sensor},
                                                             {"modality", std::string(msgs::modality_name(message))}};
        using Message = std::decay_t<decltype(typed)>;
        if constexpr (std::is_same_v<Message, msgs::PointCloudMessage>) {
          // Packed (or quantized) points and fixed-width time offsets instead of a Point3
          // message and a varint time per point.
          v1::PointCloudMessage sweep;
          msgs::to_proto(typed, &sweep, config_.point_resolution > 0 ? msgs::PointEncoding::kQuantized : msgs::PointEncoding::kPacked,
                         config_.point_resolution);
          HANZO_RETURN_IF_ERROR(write_proto(topic, sweep, typed.timestamp, metadata));
        } else if constexpr (std::is_same_v<Message, msgs::ImageMessage>) {
          const v1::ImageMessage image = compressed_image(typed, config_.image_compression, config_.jpeg_quality);
          HANZO_RETURN_IF_ERROR(write_proto(topic, image, typed.timestamp, metadata));
          if (config_.foxglove_channels && !image.compression().empty()) {
            return write_mirror(topic, foxglove_mirror::compressed_image(image, sensor).get(), typed.timestamp);  // no second copy of the pixels
          }
        } else {
          HANZO_RETURN_IF_ERROR(write_proto(topic, msgs::to_proto(typed), typed.timestamp, metadata));
        }
        if (!config_.foxglove_channels) return ok_status();
        return write_mirror(topic, foxglove_mirror::to_foxglove(message, sensor).get(), typed.timestamp);
      },
      message);
}

Status SensorLogWriter::write(const std::string& topic, const msgs::PoseEstimate& pose) {
  if (Status valid = msgs::validate(pose); !valid) return Error(fmt::format("{}: {}", topic, valid.error().message), valid.error().field);
  HANZO_RETURN_IF_ERROR(write_proto(topic, msgs::to_proto(pose), pose.timestamp, {{"modality", "pose_estimate"}}));
  if (!config_.foxglove_channels) return ok_status();
  return write_mirror(topic, foxglove_mirror::to_foxglove(pose).get(), pose.timestamp);
}

Status SensorLogWriter::write_mirror(const std::string& topic, const google::protobuf::Message* mirror, Timestamp time) {
  if (mirror == nullptr) return ok_status();
  return write_proto(topic + config_.foxglove_topic_suffix, *mirror, time, {{"mirror_of", topic}});
}

Result<std::unique_ptr<SensorLogReader>> SensorLogReader::open(const std::string& path, const mcap::ReadOptions& options) {
  std::unique_ptr<SensorLogReader> reader(new SensorLogReader());
  HANZO_ASSIGN_OR_RETURN(reader->mcap_, mcap::McapReader::open(path));
  reader->iterator_ = std::make_unique<mcap::MessageIterator>(reader->mcap_->messages(options));
  return reader;
}

Result<bool> SensorLogReader::next(LogEntry& entry) {
  mcap::MessageView view;
  while (true) {
    Result<bool> more = iterator_->next(view);
    if (!more) {
      if (corrupted_chunks_++ == 0) first_chunk_error_ = more.error().message;
      return more.error();
    }
    if (!*more) return false;
    ++records_read_;
    last_log_time_ = Timestamp::from_nanoseconds(static_cast<int64_t>(view.log_time));
    const std::string type = view.schema != nullptr && view.schema->encoding == "protobuf" ? view.schema->name : "";
    Result<LogEntry> decoded = Error("");
    if (type == v1::ImuMessage::descriptor()->full_name()) decoded = decode<v1::ImuMessage>(view);
    else if (type == v1::PointCloudMessage::descriptor()->full_name()) decoded = decode<v1::PointCloudMessage>(view);
    else if (type == v1::ImageMessage::descriptor()->full_name()) decoded = decode<v1::ImageMessage>(view);
    else if (type == v1::GnssMessage::descriptor()->full_name()) decoded = decode<v1::GnssMessage>(view);
    else if (type == v1::WheelOdometryMessage::descriptor()->full_name()) decoded = decode<v1::WheelOdometryMessage>(view);
    else if (type == v1::RadarMessage::descriptor()->full_name()) decoded = decode<v1::RadarMessage>(view);
    else if (type == v1::RangeMessage::descriptor()->full_name()) decoded = decode<v1::RangeMessage>(view);
    else if (type == v1::DetectionsMessage::descriptor()->full_name()) decoded = decode<v1::DetectionsMessage>(view);
    else if (type == v1::PoseEstimate::descriptor()->full_name()) decoded = decode<v1::PoseEstimate>(view);
    else {
      ++skipped_;
      continue;
    }
    if (!decoded) return decoded.error();
    entry = std::move(*decoded);
    return true;
  }
}

Status SensorLogReader::complete() const {
  if (mcap_->warning()) return Error(*mcap_->warning());
  if (corrupted_chunks_ > 0) {
    return Error(fmt::format("{} corrupted chunk{} skipped, their messages lost (first: {})", corrupted_chunks_, corrupted_chunks_ == 1 ? "" : "s",
                             first_chunk_error_));
  }
  return ok_status();
}

}  // namespace hanzo::fusion::io
