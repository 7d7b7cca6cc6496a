#include "live_decoder.hpp"

#include <utility>

#include <fmt/format.h>

#include "hanzo/fusion/drivers/hesai.hpp"
#include "hanzo/fusion/drivers/nmea.hpp"
#include "hanzo/fusion/drivers/ouster.hpp"
#include "hanzo/fusion/drivers/velodyne.hpp"
#include "hanzo/fusion/drivers/xsens.hpp"

namespace hanzo::fusion::app {

namespace {

template <typename Message>
void append(std::vector<Message>& decoded, std::vector<msgs::SensorMessage>& messages) {
  for (Message& message : decoded) messages.emplace_back(std::move(message));
  decoded.clear();
}

// Decoders of rotations from packets: Velodyne, Hesai (the same interface).
template <typename Decoder>
class RotationDecoder : public LiveDecoder {
 public:
  explicit RotationDecoder(Decoder decoder) : decoder_(std::move(decoder)) {}
  void decode(const drivers::ReceivedBytes& received, std::vector<msgs::SensorMessage>& messages) override {
    decoder_.add_packet(received.bytes, received.time, frames_);
    append(frames_, messages);
  }
  void flush(std::vector<msgs::SensorMessage>& messages) override {
    decoder_.flush(frames_);
    append(frames_, messages);
  }
  LiveDecoderCounts counts() const override { return {decoder_.statistics().malformed, decoder_.statistics().first_error}; }

 private:
  Decoder decoder_;
  std::vector<msgs::PointCloudMessage> frames_;
};

// An Ouster's lidar port (frames) or IMU port (imu_port: its IMU samples); each port is a
// source of its own, the other port's packets are not this sensor's.
class OusterLive : public LiveDecoder {
 public:
  OusterLive(drivers::OusterDecoder decoder, bool imu_port) : decoder_(std::move(decoder)), imu_port_(imu_port) {}
  void decode(const drivers::ReceivedBytes& received, std::vector<msgs::SensorMessage>& messages) override {
    decoder_.add_packet(received.bytes, received.time, frames_, imu_);
    take(messages);
  }
  void flush(std::vector<msgs::SensorMessage>& messages) override {
    decoder_.flush(frames_);
    take(messages);
  }
  LiveDecoderCounts counts() const override { return {decoder_.statistics().malformed, decoder_.statistics().first_error}; }

 private:
  void take(std::vector<msgs::SensorMessage>& messages) {
    if (imu_port_) {
      append(imu_, messages);
    } else {
      for (drivers::OusterFrame& frame : frames_) messages.emplace_back(std::move(frame.cloud));
    }
    frames_.clear();
    imu_.clear();
  }
  drivers::OusterDecoder decoder_;
  bool imu_port_;
  std::vector<drivers::OusterFrame> frames_;
  std::vector<msgs::ImuMessage> imu_;
};

class NmeaLive : public LiveDecoder {
 public:
  explicit NmeaLive(drivers::NmeaDecoder decoder) : decoder_(std::move(decoder)) {}
  void decode(const drivers::ReceivedBytes& received, std::vector<msgs::SensorMessage>& messages) override {
    decoder_.feed(received.bytes, fixes_);
    append(fixes_, messages);
  }
  void flush(std::vector<msgs::SensorMessage>& messages) override {
    decoder_.flush(fixes_);
    append(fixes_, messages);
  }
  LiveDecoderCounts counts() const override {
    return {decoder_.statistics().malformed + decoder_.statistics().checksum_errors, decoder_.statistics().first_error};
  }

 private:
  drivers::NmeaDecoder decoder_;
  std::vector<msgs::GnssMessage> fixes_;
};

// An Xsens IMU: its IMU samples (a GNSS/INS's fixes belong to a gnss sensor of their own).
class XsensLive : public LiveDecoder {
 public:
  explicit XsensLive(drivers::XsensDecoderConfig config) : decoder_(std::move(config)) {}
  void decode(const drivers::ReceivedBytes& received, std::vector<msgs::SensorMessage>& messages) override {
    decoder_.feed(received.bytes, imu_, fixes_);
    append(imu_, messages);
    fixes_.clear();
  }
  void flush(std::vector<msgs::SensorMessage>&) override {}
  LiveDecoderCounts counts() const override {
    return {decoder_.statistics().malformed + decoder_.statistics().checksum_errors, decoder_.statistics().first_error};
  }

 private:
  drivers::XsensDecoder decoder_;
  std::vector<msgs::ImuMessage> imu_;
  std::vector<msgs::GnssMessage> fixes_;
};

}  // namespace

Result<std::unique_ptr<LiveDecoder>> make_live_decoder(const config::SensorConfig& sensor) {
  if (!sensor.driver) return Error(fmt::format("sensor {}: no driver configured", sensor.name));
  const config::SensorDriverConfig& driver = *sensor.driver;
  const auto failed = [&](const Error& error) { return Error(fmt::format("sensor {} ({}): {}", sensor.name, driver.type, error.message)); };
  if (driver.type == "velodyne") {
    Result<drivers::VelodyneModel> model = drivers::parse_velodyne_model(driver.model);
    if (!model) return failed(model.error());
    drivers::VelodyneCalibration calibration = drivers::nominal_velodyne_calibration(*model);
    if (!driver.calibration.empty()) {
      Result<drivers::VelodyneCalibration> loaded = drivers::load_velodyne_calibration(driver.calibration);
      if (!loaded) return failed(loaded.error());
      calibration = std::move(*loaded);
    }
    drivers::VelodyneDecoderConfig config;
    config.model = *model;
    config.frame_id = sensor.body_frame;
    Result<drivers::VelodyneDecoder> decoder = drivers::VelodyneDecoder::create(std::move(calibration), config);
    if (!decoder) return failed(decoder.error());
    return std::unique_ptr<LiveDecoder>(std::make_unique<RotationDecoder<drivers::VelodyneDecoder>>(std::move(*decoder)));
  }
  if (driver.type == "hesai") {
    Result<drivers::HesaiCalibration> calibration = drivers::load_hesai_calibration(driver.calibration, driver.firetime);
    if (!calibration) return failed(calibration.error());
    drivers::HesaiDecoderConfig config;
    config.frame_id = sensor.body_frame;
    Result<drivers::HesaiDecoder> decoder = drivers::HesaiDecoder::create(std::move(*calibration), config);
    if (!decoder) return failed(decoder.error());
    return std::unique_ptr<LiveDecoder>(std::make_unique<RotationDecoder<drivers::HesaiDecoder>>(std::move(*decoder)));
  }
  if (driver.type == "ouster" || driver.type == "ouster_imu") {
    Result<drivers::OusterMetadata> metadata = drivers::load_ouster_metadata(driver.metadata);
    if (!metadata) return failed(metadata.error());
    Result<drivers::OusterDecoder> decoder = drivers::OusterDecoder::create(*metadata, sensor.body_frame);
    if (!decoder) return failed(decoder.error());
    return std::unique_ptr<LiveDecoder>(std::make_unique<OusterLive>(std::move(*decoder), driver.type == "ouster_imu"));
  }
  if (driver.type == "nmea") {
    Result<drivers::NmeaDecoder> decoder = drivers::NmeaDecoder::create();
    if (!decoder) return failed(decoder.error());
    return std::unique_ptr<LiveDecoder>(std::make_unique<NmeaLive>(std::move(*decoder)));
  }
  if (driver.type == "xsens") {
    drivers::XsensDecoderConfig config;
    config.frame_id = sensor.body_frame;
    return std::unique_ptr<LiveDecoder>(std::make_unique<XsensLive>(config));
  }
  return Error(fmt::format("sensor {}: unknown driver type '{}'", sensor.name, driver.type));
}

}  // namespace hanzo::fusion::app
