// Sensor drivers' decoding speed on one core, from recordings held in memory (the decoders
// alone: no file or socket reads): a Velodyne VLP-16 capture (1902 data packets in 2.52 s,
// 754 packets/s recorded) and an HDL-32E capture (2702 in 1.49 s), and an NMEA-0183 receiver log
// (u-blox ZED-F9P with UBX binary in between, 655 epochs in 654 s), an Ouster OS-1-64 frame
// (the decoder is created per run: its 64 x 1024 direction table included), a Hesai Pandar40P
// capture (200 packets) and an Xsens MTi-G-710 stream (100 messages). `x real time`: recorded
// seconds decoded per second. No packaged peer decodes these on this machine (PCL's Velodyne
// grabbers need libpcap support, which Debian's PCL is built without).
#include <fstream>
#include <map>
#include <sstream>
#include <string>
#include <vector>

#include <benchmark/benchmark.h>

#include "hanzo/fusion/drivers/hesai.hpp"
#include "hanzo/fusion/drivers/nmea.hpp"
#include "hanzo/fusion/drivers/ouster.hpp"
#include "hanzo/fusion/drivers/pcap.hpp"
#include "hanzo/fusion/drivers/velodyne.hpp"
#include "hanzo/fusion/drivers/xsens.hpp"

namespace {

using namespace hanzo::fusion;

const std::string kDrivers = std::string(HANZO_DATA_DIR) + "/drivers/";

struct Capture {
  std::vector<drivers::UdpDatagram> datagrams;
  double seconds = 0.0;  // recorded span
};

std::string file_bytes(const std::string& file) {
  std::ifstream stream(kDrivers + file, std::ios::binary);
  std::ostringstream bytes;
  bytes << stream.rdbuf();
  return bytes.str();
}

const Capture& capture(const std::string& file) {
  static std::map<std::string, Capture> loaded;
  Capture& capture = loaded[file];
  if (capture.datagrams.empty()) {
    auto reader = drivers::PcapReader::open(kDrivers + file).value();
    while (auto datagram = reader.next().value()) capture.datagrams.push_back(std::move(*datagram));
    capture.seconds = (capture.datagrams.back().time - capture.datagrams.front().time).seconds();
  }
  return capture;
}

// Every packet of `recorded` through a fresh decoder (`make`: Velodyne, Hesai) per pass.
template <typename MakeDecoder>
void decode_rotations(benchmark::State& state, const Capture& recorded, const MakeDecoder& make) {
  std::size_t points = 0;
  for (auto _ : state) {
    auto decoder = make();
    std::vector<msgs::PointCloudMessage> frames;
    for (const drivers::UdpDatagram& datagram : recorded.datagrams) decoder.add_packet(datagram.payload, datagram.time, frames);
    decoder.flush(frames);
    points = decoder.statistics().points;
    benchmark::DoNotOptimize(frames.data());
  }
  state.counters["packets/s"] = benchmark::Counter(static_cast<double>(recorded.datagrams.size() * state.iterations()), benchmark::Counter::kIsRate);
  state.counters["points/s"] = benchmark::Counter(static_cast<double>(points * state.iterations()), benchmark::Counter::kIsRate);
  state.counters["x real time"] = benchmark::Counter(recorded.seconds * static_cast<double>(state.iterations()), benchmark::Counter::kIsRate);
}

void decode_velodyne(benchmark::State& state, const std::string& file, const std::string& calibration, drivers::VelodyneModel model) {
  drivers::VelodyneDecoderConfig config;
  config.model = model;
  const drivers::VelodyneCalibration lasers = drivers::load_velodyne_calibration(kDrivers + calibration).value();
  decode_rotations(state, capture(file), [&] { return drivers::VelodyneDecoder::create(lasers, config).value(); });
}

void BM_VelodyneVlp16(benchmark::State& state) {
  decode_velodyne(state, "velodyne_veloview/vlp-16-test-90deg-1-50-frames.pcap", "velodyne_veloview/calib/VLP-16.xml", drivers::VelodyneModel::kVlp16);
}
BENCHMARK(BM_VelodyneVlp16)->Unit(benchmark::kMillisecond)->UseRealTime();

void BM_VelodyneHdl32e(benchmark::State& state) {
  decode_velodyne(state, "velodyne_veloview/monterey-first-100-packets.pcap", "velodyne_veloview/calib/HDL-32.xml", drivers::VelodyneModel::kHdl32e);
}
BENCHMARK(BM_VelodyneHdl32e)->Unit(benchmark::kMillisecond)->UseRealTime();

// Ouster OS-1-64 (LEGACY, 1024 x 10: one frame of 64 packets and 11 IMU packets, 0.1 s).
void BM_OusterOs1_64(benchmark::State& state) {
  const Capture& recorded = capture("ouster_sdk_pcaps/OS-1-64_1024x10_fw20.pcap");
  const drivers::OusterMetadata metadata = drivers::load_ouster_metadata(kDrivers + "ouster_sdk_pcaps/OS-1-64_sensor_config_reduced.json").value();
  std::size_t points = 0;
  for (auto _ : state) {
    auto decoder = drivers::OusterDecoder::create(metadata).value();
    std::vector<drivers::OusterFrame> frames;
    std::vector<msgs::ImuMessage> imu;
    for (const drivers::UdpDatagram& datagram : recorded.datagrams) decoder.add_packet(datagram.payload, datagram.time, frames, imu);
    decoder.flush(frames);
    points = frames.empty() ? 0 : frames[0].cloud.points.size();
    benchmark::DoNotOptimize(frames.data());
  }
  // One frame of a 10 Hz sensor: 0.1 s recorded.
  state.counters["points/s"] = benchmark::Counter(static_cast<double>(points * state.iterations()), benchmark::Counter::kIsRate);
  state.counters["x real time"] = benchmark::Counter(0.1 * static_cast<double>(state.iterations()), benchmark::Counter::kIsRate);
}
BENCHMARK(BM_OusterOs1_64)->Unit(benchmark::kMillisecond)->UseRealTime();

// Hesai Pandar40P (200 packets, 0.11 s at 20 Hz, the unit's angle and firetime corrections).
void BM_HesaiPandar40p(benchmark::State& state) {
  const std::string calibration = kDrivers + "hesai_pandar40p_velocity_report/calib/Pandar40P_";
  const drivers::HesaiCalibration channels =
      drivers::load_hesai_calibration(calibration + "Angle_Correction_File.csv", calibration + "Firetime_Correction_File.csv").value();
  decode_rotations(state, capture("hesai_pandar40p_velocity_report/lidar_20Hz.pcapng"), [&] { return drivers::HesaiDecoder::create(channels).value(); });
}
BENCHMARK(BM_HesaiPandar40p)->Unit(benchmark::kMillisecond)->UseRealTime();

// Xsens MTi-G-710 (100 MTData2 messages at 100 Hz, 13 outputs in FP16.32, 0.95 s).
void BM_XsensMtData2(benchmark::State& state) {
  const std::string content = file_bytes("imu_xsens_mti_g710/testdata/3/output.bin");
  double seconds = 0.0;
  for (auto _ : state) {
    drivers::XsensDecoder decoder;
    std::vector<msgs::ImuMessage> imu;
    std::vector<msgs::GnssMessage> fixes;
    decoder.feed(content, imu, fixes);
    seconds = (imu.back().timestamp - imu.front().timestamp).seconds();
    benchmark::DoNotOptimize(imu.data());
  }
  state.counters["MB/s"] = benchmark::Counter(static_cast<double>(content.size() * state.iterations()) / 1e6, benchmark::Counter::kIsRate);
  state.counters["x real time"] = benchmark::Counter(seconds * static_cast<double>(state.iterations()), benchmark::Counter::kIsRate);
}
BENCHMARK(BM_XsensMtData2)->Unit(benchmark::kMicrosecond)->UseRealTime();

void BM_PcapRead(benchmark::State& state) {
  const std::string content = file_bytes("velodyne_veloview/monterey-first-100-packets.pcap");
  for (auto _ : state) {
    auto reader = drivers::PcapReader::from_bytes(content).value();
    std::size_t datagrams = 0;
    while (auto datagram = reader.next().value()) ++datagrams;
    benchmark::DoNotOptimize(datagrams);
  }
  state.counters["MB/s"] = benchmark::Counter(static_cast<double>(content.size() * state.iterations()) / 1e6, benchmark::Counter::kIsRate);
}
BENCHMARK(BM_PcapRead)->Unit(benchmark::kMillisecond)->UseRealTime();

void BM_NmeaZedF9p(benchmark::State& state) {
  const std::string content = file_bytes("gnss_nmea_gpsd/ublox-zed-f9p_hpg1.11.log");
  double seconds = 0.0;
  for (auto _ : state) {
    auto decoder = drivers::NmeaDecoder::create().value();
    std::vector<msgs::GnssMessage> fixes;
    decoder.feed(content, fixes);
    decoder.flush(fixes);
    seconds = (fixes.back().timestamp - fixes.front().timestamp).seconds();
    benchmark::DoNotOptimize(fixes.data());
  }
  state.counters["MB/s"] = benchmark::Counter(static_cast<double>(content.size() * state.iterations()) / 1e6, benchmark::Counter::kIsRate);
  state.counters["x real time"] = benchmark::Counter(seconds * static_cast<double>(state.iterations()), benchmark::Counter::kIsRate);
}
BENCHMARK(BM_NmeaZedF9p)->Unit(benchmark::kMillisecond)->UseRealTime();

}  // namespace

BENCHMARK_MAIN();
