// Sensor-log (MCAP) throughput for a LiDAR-heavy log: 10 Hz scans of 120k points (with
// intensity, ring and per-point time) plus a 200 Hz IMU, written and read with each chunk
// compression, compared with `cat` of the same bytes (the disk/page-cache ceiling). Also reads
// a multi-GB log and reports the peak memory of reading it.
//
// Counters: bytes_per_second (file bytes), items_per_second (messages), ratio (file / raw payload).
// Also the wire encodings of one of those scans as the gRPC streams send it (encode: to_proto +
// serialize; decode: parse + from_proto, the server's side): the spec's Point3 messages with
// absolute point_timestamps, packed_points with absolute times, packed_points with
// point_time_offsets_ns (what `hanzo-fusion stream` sends). Counter: wire_bytes.
// And ROS 2: one of those scans as a sensor_msgs/PointCloud2 in CDR, in each LiDAR driver's
// layout, encoded (export ros2bag) and decoded (import ros2bag), next to PCL's
// fromPCLPointCloud2 of the same bytes into PointXYZI (x, y, z, intensity only).

#include <unistd.h>

#include <cstdlib>
#include <cstring>
#include <fstream>
#include <filesystem>
#include <random>

#include <benchmark/benchmark.h>
#include <fmt/format.h>

#include "hanzo/fusion/io/dataset_export.hpp"
#include "hanzo/fusion/io/mcap.hpp"
#include "hanzo/fusion/io/ros2_bag_writer.hpp"
#include "hanzo/fusion/io/ros_conversion.hpp"
#include "hanzo/fusion/io/sensor_log.hpp"
#include "hanzo/fusion/msgs/convert.hpp"
#include "hanzo/fusion/v1/sensors.pb.h"
#include "io_peers.hpp"

namespace {

using namespace hanzo::fusion;

constexpr int kScans = 20;  // 2 s of a 10 Hz LiDAR
constexpr std::size_t kPointsPerScan = 120'000;
const Timestamp kStart = Timestamp::from_nanoseconds(1'700'000'000'000'000'000);

// A spinning-LiDAR-like scan: 16 rings, ranges 2-60 m with a smooth structure, time across the sweep.
msgs::PointCloudMessage make_scan(int index, std::mt19937& rng) {
  std::normal_distribution<float> noise(0.0F, 0.02F);
  msgs::PointCloudMessage scan;
  scan.timestamp = kStart + Duration::from_milliseconds(100 * index);
  scan.frame_id = "lidar";
  scan.points.reserve(kPointsPerScan);
  for (std::size_t i = 0; i < kPointsPerScan; ++i) {
    const auto ring = static_cast<uint32_t>(i % 16);
    const float azimuth = 2.0F * 3.14159265F * static_cast<float>(i / 16) / (kPointsPerScan / 16.0F);
    const float elevation = (static_cast<float>(ring) - 7.5F) * 0.035F;
    const float range = 10.0F + 8.0F * std::sin(3.0F * azimuth) + noise(rng);
    scan.points.emplace_back(range * std::cos(elevation) * std::cos(azimuth), range * std::cos(elevation) * std::sin(azimuth),
                             range * std::sin(elevation));
    scan.intensities.push_back(0.5F + 0.4F * std::cos(azimuth * 7.0F));
    scan.ring_ids.push_back(ring);
    scan.point_timestamps.push_back(scan.timestamp + Duration::from_nanoseconds(static_cast<int64_t>(i) * 100'000'000 / kPointsPerScan));
  }
  return scan;
}

struct Workload {
  std::vector<msgs::PointCloudMessage> scans;
  std::vector<msgs::ImuMessage> imu;
};

const Workload& workload() {
  static const Workload w = [] {
    Workload out;
    std::mt19937 rng(1);
    for (int i = 0; i < kScans; ++i) out.scans.push_back(make_scan(i, rng));
    for (int i = 0; i < kScans * 20; ++i) {
      msgs::ImuMessage imu;
      imu.timestamp = kStart + Duration::from_milliseconds(5 * i);
      imu.linear_acceleration = {0.1, 0.0, 9.81};
      imu.angular_velocity = {0.0, 0.0, 0.1};
      out.imu.push_back(imu);
    }
    return out;
  }();
  return w;
}

std::string log_path(const std::string& name) {
  return (std::filesystem::temp_directory_path() / fmt::format("hanzo_bench_io_{}.mcap", name)).string();
}

// Writes the workload in time order; returns the number of messages.
std::size_t write_log(const std::string& path, io::mcap::Compression compression, bool foxglove_mirror = false) {
  io::SensorLogWriterConfig config;
  config.mcap.compression = compression;
  config.foxglove_channels = foxglove_mirror;  // off: the log itself; BM_SensorLogWriteFoxgloveMirror measures the mirror
  auto writer = io::SensorLogWriter::open(path, config);
  if (!writer) throw std::runtime_error(writer.error().message);
  const Workload& w = workload();
  std::size_t imu_index = 0;
  for (const auto& scan : w.scans) {
    while (imu_index < w.imu.size() && w.imu[imu_index].timestamp < scan.timestamp) {
      (void)(*writer)->write("/imu", w.imu[imu_index++]);
    }
    (void)(*writer)->write("/lidar", scan);
  }
  while (imu_index < w.imu.size()) (void)(*writer)->write("/imu", w.imu[imu_index++]);
  (void)(*writer)->close();
  return w.scans.size() + w.imu.size();
}

io::mcap::Compression compression_of(int64_t index) { return static_cast<io::mcap::Compression>(index); }
std::string compression_label(io::mcap::Compression compression) {
  return compression == io::mcap::Compression::kNone ? "none" : io::mcap::compression_name(compression);
}

// Writes the workload `state` times and reports file size and throughput.
void measure_write(benchmark::State& state, io::mcap::Compression compression, bool foxglove_mirror, const std::string& label) {
  const std::string path = log_path(fmt::format("write_{}_{}", static_cast<int>(compression), foxglove_mirror));
  workload();
  std::size_t messages = 0;
  for (auto _ : state) messages += write_log(path, compression, foxglove_mirror);
  const auto bytes = std::filesystem::file_size(path);
  state.SetBytesProcessed(static_cast<int64_t>(bytes) * state.iterations());
  state.SetItemsProcessed(static_cast<int64_t>(messages));
  state.SetLabel(label);
  state.counters["file_MB"] = static_cast<double>(bytes) / 1e6;
  std::filesystem::remove(path);
}

void BM_SensorLogWrite(benchmark::State& state) {
  const auto compression = compression_of(state.range(0));
  measure_write(state, compression, false, compression_label(compression));
}

// The default import setting: every scan also written as foxglove.PointCloud (zstd).
void BM_SensorLogWriteFoxgloveMirror(benchmark::State& state) {
  measure_write(state, io::mcap::Compression::kZstd, true, "zstd + foxglove mirror");
}

// The container alone: pre-serialized payloads through McapWriter (chunking, compression, CRCs,
// indexes); the difference to BM_SensorLogWrite is protobuf serialization.
void BM_McapWriteSerialized(benchmark::State& state) {
  const auto compression = compression_of(state.range(0));
  const std::string path = log_path(fmt::format("raw_{}", state.range(0)));
  std::vector<std::pair<uint64_t, std::string>> payloads;
  for (const auto& scan : workload().scans) {
    payloads.emplace_back(scan.timestamp.nanoseconds(), msgs::to_proto(scan).SerializeAsString());
  }
  for (auto _ : state) {
    io::mcap::McapWriterConfig config;
    config.compression = compression;
    auto writer = io::mcap::McapWriter::open(path, config);
    const uint16_t channel = *(*writer)->add_channel(0, "/lidar", "protobuf");
    for (const auto& [time, payload] : payloads) (void)(*writer)->write(channel, time, time, payload);
    (void)(*writer)->close();
  }
  const auto bytes = std::filesystem::file_size(path);
  state.SetBytesProcessed(static_cast<int64_t>(bytes) * state.iterations());
  state.SetItemsProcessed(static_cast<int64_t>(payloads.size()) * state.iterations());
  state.SetLabel(compression_label(compression));
  state.counters["file_MB"] = static_cast<double>(bytes) / 1e6;
  std::filesystem::remove(path);
}

// Raw MCAP iteration (decompress + merge, no protobuf decoding).
void BM_McapRead(benchmark::State& state) {
  const auto compression = compression_of(state.range(0));
  const std::string path = log_path(fmt::format("read_{}", state.range(0)));
  write_log(path, compression);
  std::size_t messages = 0;
  for (auto _ : state) {
    auto reader = io::mcap::McapReader::open(path);
    io::mcap::MessageIterator it = (*reader)->messages();
    io::mcap::MessageView view;
    while (*it.next(view)) {
      benchmark::DoNotOptimize(view.data.data());
      ++messages;
    }
  }
  state.SetBytesProcessed(static_cast<int64_t>(std::filesystem::file_size(path)) * state.iterations());
  state.SetItemsProcessed(static_cast<int64_t>(messages));
  state.SetLabel(compression_label(compression));
  std::filesystem::remove(path);
}

// Full decoding into engine messages (protobuf parse + validation).
void BM_SensorLogReadDecoded(benchmark::State& state) {
  const auto compression = compression_of(state.range(0));
  const std::string path = log_path(fmt::format("decode_{}", state.range(0)));
  write_log(path, compression);
  std::size_t messages = 0;
  for (auto _ : state) {
    auto reader = io::SensorLogReader::open(path);
    io::LogEntry entry;
    while (*(*reader)->next(entry)) ++messages;
  }
  state.SetBytesProcessed(static_cast<int64_t>(std::filesystem::file_size(path)) * state.iterations());
  state.SetItemsProcessed(static_cast<int64_t>(messages));
  state.SetLabel(compression_label(compression));
  std::filesystem::remove(path);
}

// export_dataset of the workload's sweeps (with per-point times: deskewed) into the KITTI (0)
// or nuScenes-like (1) layout; BM_SensorLogReadDecoded/0 is the floor of each of its two passes.
void BM_DatasetExport(benchmark::State& state) {
  const std::string path = log_path("dataset");
  write_log(path, io::mcap::Compression::kZstd);
  io::Trajectory trajectory;  // 100 Hz, 1 m/s along x, over the whole workload
  for (int i = 0; i <= kScans * 10 + 10; ++i) {
    trajectory.timestamps.push_back(kStart + Duration::from_milliseconds(10 * i));
    io::PoseMatrix pose = io::PoseMatrix::Identity();
    pose(0, 3) = 0.01 * i;
    trajectory.poses.push_back(pose);
  }
  calib::Calibration calibration;
  calibration.sensors.push_back(calib::SensorCalibration::from_transform("lidar", SE3()));
  io::DatasetExportConfig config;
  config.layout = state.range(0) == 0 ? io::DatasetLayout::kKittiOdometry : io::DatasetLayout::kNuscenes;
  config.sensors = {{"lidar", "/lidar", false}};
  const std::string out = log_path("dataset_out");
  uint64_t frames = 0, bytes = 0;
  for (auto _ : state) {
    std::filesystem::remove_all(out);
    auto summary = io::export_dataset(path, trajectory, calibration, out, config);
    if (!summary) {
      state.SkipWithError(summary.error().message.c_str());
      break;
    }
    frames += summary->frames;
    bytes = summary->bytes_written;
  }
  state.SetItemsProcessed(static_cast<int64_t>(frames));
  state.SetLabel(state.range(0) == 0 ? "kitti" : "nuscenes");
  state.counters["written_MB"] = static_cast<double>(bytes) / 1e6;
  std::filesystem::remove_all(out);
  std::filesystem::remove(path);
}

// Peer: `cat` of the same (uncompressed) log into /dev/null.
void BM_CatSameBytes(benchmark::State& state) {
  const std::string path = log_path("cat");
  write_log(path, io::mcap::Compression::kNone);
  const std::string command = fmt::format("cat {} > /dev/null", path);
  for (auto _ : state) {
    if (std::system(command.c_str()) != 0) state.SkipWithError("cat failed");
  }
  state.SetBytesProcessed(static_cast<int64_t>(std::filesystem::file_size(path)) * state.iterations());
  state.SetLabel("cat");
  std::filesystem::remove(path);
}

// Current resident memory (MB) from /proc/self/statm.
double rss_mb() {
  std::ifstream statm("/proc/self/statm");
  long pages_total = 0, pages_resident = 0;
  statm >> pages_total >> pages_resident;
  return static_cast<double>(pages_resident) * static_cast<double>(::sysconf(_SC_PAGESIZE)) / 1e6;
}

// Reads a log of HANZO_BENCH_LARGE_LOG_GB (default 2) GB of scans and reports how much the
// resident memory grew at most while reading it: it must stay near one chunk, not the file size.
void BM_ReadMultiGigabyteLog(benchmark::State& state) {
  const double gigabytes = std::getenv("HANZO_BENCH_LARGE_LOG_GB") ? std::atof(std::getenv("HANZO_BENCH_LARGE_LOG_GB")) : 2.0;
  const std::string path = log_path("large");
  {
    io::mcap::McapWriterConfig config;
    config.compression = io::mcap::Compression::kNone;
    auto writer = io::mcap::McapWriter::open(path, config);
    const uint16_t channel = *(*writer)->add_channel(0, "/lidar", "protobuf");
    const std::string payload = msgs::to_proto(workload().scans[0]).SerializeAsString();
    const auto count = static_cast<std::size_t>(gigabytes * 1e9 / static_cast<double>(payload.size()));
    for (std::size_t i = 0; i < count; ++i) (void)(*writer)->write(channel, 1'000'000'000ULL + i * 100'000'000ULL, 0, payload);
    (void)(*writer)->close();
  }
  const double rss_before = rss_mb();
  double rss_peak = rss_before;
  std::size_t messages = 0;
  for (auto _ : state) {
    auto reader = io::mcap::McapReader::open(path);
    io::mcap::MessageIterator it = (*reader)->messages();
    io::mcap::MessageView view;
    while (*it.next(view)) {
      if (++messages % 16 == 0) rss_peak = std::max(rss_peak, rss_mb());
    }
  }
  state.counters["file_GB"] = static_cast<double>(std::filesystem::file_size(path)) / 1e9;
  state.counters["rss_before_MB"] = rss_before;
  state.counters["rss_peak_MB"] = rss_peak;
  state.SetBytesProcessed(static_cast<int64_t>(std::filesystem::file_size(path)) * state.iterations());
  state.SetItemsProcessed(static_cast<int64_t>(messages));
  std::filesystem::remove(path);
}

// 0: Point3 + point_timestamps (the spec), 1: packed_points + point_timestamps, 2: packed_points
// + point_time_offsets_ns.
v1::PointCloudMessage wire_scan(int encoding) {
  const msgs::PointCloudMessage& scan = workload().scans.front();
  v1::PointCloudMessage out;
  msgs::to_proto(scan, &out, encoding == 0 ? msgs::PointEncoding::kPoint3 : msgs::PointEncoding::kPacked);
  if (encoding == 1) {
    out.clear_point_time_offsets_ns();
    for (Timestamp time : scan.point_timestamps) out.add_point_timestamps(static_cast<uint64_t>(time.nanoseconds()));
  }
  return out;
}

const char* wire_name(int encoding) {
  static const char* names[] = {"point3+timestamps", "packed+timestamps", "packed+offsets"};
  return names[encoding];
}

void BM_PointCloudWireEncode(benchmark::State& state) {
  const int encoding = static_cast<int>(state.range(0));
  const msgs::PointCloudMessage& scan = workload().scans.front();
  v1::PointCloudMessage message;
  std::string bytes;
  for (auto _ : state) {
    if (encoding == 1) {
      message = wire_scan(1);  // not a to_proto mode: built as encoding 1 is on the wire
    } else {
      msgs::to_proto(scan, &message, encoding == 0 ? msgs::PointEncoding::kPoint3 : msgs::PointEncoding::kPacked);
    }
    message.SerializeToString(&bytes);
    benchmark::DoNotOptimize(bytes.data());
  }
  state.SetLabel(wire_name(encoding));
  state.counters["wire_bytes"] = static_cast<double>(bytes.size());
  state.counters["points"] = static_cast<double>(scan.points.size());
}

void BM_PointCloudWireDecode(benchmark::State& state) {
  const int encoding = static_cast<int>(state.range(0));
  const std::string bytes = wire_scan(encoding).SerializeAsString();
  v1::PointCloudMessage message;
  for (auto _ : state) {
    if (!message.ParseFromString(bytes)) state.SkipWithError("parse failed");
    Result<msgs::PointCloudMessage> decoded = msgs::from_proto(message);
    if (!decoded) state.SkipWithError(decoded.error().message.c_str());
    benchmark::DoNotOptimize(decoded);
  }
  state.SetLabel(wire_name(encoding));
  state.counters["wire_bytes"] = static_cast<double>(bytes.size());
}

const char* kLayoutNames[] = {"plain", "velodyne", "ouster", "livox", "hesai"};

const msgs::PointCloudMessage& ros_scan() {
  static const msgs::PointCloudMessage scan = [] {
    std::mt19937 rng(7);
    return make_scan(0, rng);
  }();
  return scan;
}

void BM_Ros2PointCloudEncode(benchmark::State& state) {
  const auto layout = static_cast<io::ros2::LidarLayout>(state.range(0));
  std::string cdr;
  for (auto _ : state) {
    cdr = io::ros2::point_cloud_cdr(ros_scan(), layout);
    benchmark::DoNotOptimize(cdr.data());
  }
  state.SetLabel(kLayoutNames[state.range(0)]);
  state.counters["bytes"] = static_cast<double>(cdr.size());
  state.counters["points"] = static_cast<double>(ros_scan().points.size());
}

void BM_Ros2PointCloudDecode(benchmark::State& state) {
  const auto layout = static_cast<io::ros2::LidarLayout>(state.range(0));
  const std::string cdr = io::ros2::point_cloud_cdr(ros_scan(), layout);
  for (auto _ : state) {
    Result<msgs::PointCloudMessage> cloud = io::ros::point_cloud_from_ros(cdr, io::ros::Serialization::kCdr);
    if (!cloud) state.SkipWithError(cloud.error().message.c_str());
    benchmark::DoNotOptimize(cloud);
  }
  state.SetLabel(kLayoutNames[state.range(0)]);
  state.counters["points"] = static_cast<double>(ros_scan().points.size());
}

// The peer: PCL's conversion of the Velodyne layout's bytes (x, y, z, intensity, ring, time).
void BM_Ros2PointCloudDecodePcl(benchmark::State& state) {
  const msgs::PointCloudMessage& scan = ros_scan();
  const uint32_t point_step = 22;
  std::vector<uint8_t> data(point_step * scan.points.size());
  for (std::size_t i = 0; i < scan.points.size(); ++i) {
    std::memcpy(data.data() + i * point_step, scan.points[i].data(), 12);
    std::memcpy(data.data() + i * point_step + 12, &scan.intensities[i], 4);
  }
  const std::vector<bench::Cloud2Field> fields = {{"x", 0, 7}, {"y", 4, 7}, {"z", 8, 7}, {"intensity", 12, 7}, {"ring", 16, 4}, {"time", 18, 7}};
  for (auto _ : state) {
    benchmark::DoNotOptimize(bench::pcl_points_from_cloud2(fields, point_step, static_cast<uint32_t>(scan.points.size()), data));
  }
  state.SetLabel("PCL 1.13 fromPCLPointCloud2 -> PointXYZI");
  state.counters["points"] = static_cast<double>(scan.points.size());
}

}  // namespace

// Wall-clock time everywhere (cat runs in a child process). The multi-GB read runs first, while
// the process is still small, so its peak memory is easy to read.
BENCHMARK(BM_ReadMultiGigabyteLog)->Unit(benchmark::kMillisecond)->Iterations(1)->UseRealTime();
BENCHMARK(BM_SensorLogWrite)->DenseRange(0, 2)->Unit(benchmark::kMillisecond)->Iterations(3)->UseRealTime();
BENCHMARK(BM_SensorLogWriteFoxgloveMirror)->Unit(benchmark::kMillisecond)->Iterations(3)->UseRealTime();
BENCHMARK(BM_McapWriteSerialized)->DenseRange(0, 2)->Unit(benchmark::kMillisecond)->Iterations(3)->UseRealTime();
BENCHMARK(BM_McapRead)->DenseRange(0, 2)->Unit(benchmark::kMillisecond)->Iterations(5)->UseRealTime();
BENCHMARK(BM_SensorLogReadDecoded)->DenseRange(0, 2)->Unit(benchmark::kMillisecond)->Iterations(3)->UseRealTime();
BENCHMARK(BM_DatasetExport)->DenseRange(0, 1)->Unit(benchmark::kMillisecond)->Iterations(3)->UseRealTime();
BENCHMARK(BM_CatSameBytes)->Unit(benchmark::kMillisecond)->Iterations(5)->UseRealTime();
BENCHMARK(BM_PointCloudWireEncode)->DenseRange(0, 2)->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK(BM_PointCloudWireDecode)->DenseRange(0, 2)->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK(BM_Ros2PointCloudEncode)->DenseRange(1, 4)->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK(BM_Ros2PointCloudDecode)->DenseRange(1, 4)->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK(BM_Ros2PointCloudDecodePcl)->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK_MAIN();
