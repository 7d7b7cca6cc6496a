// The nuScenes-like layout of export_dataset (hanzo/fusion/io/dataset_export.hpp): the
// devkit's table files (v1.0 schema) without annotations.

#include <algorithm>
#include <cctype>
#include <filesystem>
#include <map>
#include <string>

#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include "dataset_layouts.hpp"

namespace hanzo::fusion::io::dataset {
namespace {

using nlohmann::json;

// 32 hex digits from a text: two 64-bit FNV-1a hashes with different offsets.
std::string token(const std::string& text) {
  uint64_t a = 14695981039346656037ULL, b = 1099511628211ULL * 31;
  for (const unsigned char c : text) {
    a = (a ^ c) * 1099511628211ULL;
    b = (b ^ c) * 1099511628211ULL + 0x9E3779B97F4A7C15ULL;
  }
  return fmt::format("{:016x}{:016x}", a, b);
}

json vector_json(const Eigen::Vector3d& v) { return json::array({v.x(), v.y(), v.z()}); }
json rotation_json(const SE3& pose) {
  const Eigen::Quaterniond& q = pose.rotation().quaternion();
  return json::array({q.w(), q.x(), q.y(), q.z()});
}

std::string channel_of(const std::string& name) {
  std::string channel = name;
  std::transform(channel.begin(), channel.end(), channel.begin(), [](unsigned char c) { return static_cast<char>(std::toupper(c)); });
  return channel;
}

struct SampleData {
  std::size_t frame;
  std::size_t sensor;
  Timestamp time;
  SE3 T_world_body;
  std::string filename;
  std::string fileformat;
  uint32_t width = 0;
  uint32_t height = 0;
};

class NuscenesWriter final : public DatasetLayoutWriter {
 public:
  NuscenesWriter(const std::string& out_dir, std::vector<LayoutSensor> sensors, std::vector<LayoutFrame> frames, const DatasetExportConfig& config)
      : out_dir_(out_dir), sensors_(std::move(sensors)), frames_(std::move(frames)), config_(config) {}

  Status write_cloud(std::size_t frame, std::size_t sensor, Timestamp time, const SE3& T_world_body, const LayoutCloud& cloud) override {
    // x, y, z, intensity (0..255), ring: five float32 per point, as nuScenes' .pcd.bin.
    std::string bytes(cloud.points.size() * 5 * sizeof(float), '\0');
    auto* out = reinterpret_cast<float*>(bytes.data());
    for (std::size_t i = 0; i < cloud.points.size(); ++i) {
      out[5 * i] = cloud.points[i].x();
      out[5 * i + 1] = cloud.points[i].y();
      out[5 * i + 2] = cloud.points[i].z();
      out[5 * i + 3] = cloud.intensities.empty() ? 0.0F : cloud.intensities[i] * 255.0F;
      out[5 * i + 4] = cloud.rings.empty() ? 0.0F : static_cast<float>(cloud.rings[i]);
    }
    return add(SampleData{frame, sensor, time, T_world_body, file_name(sensor, time, "pcd.bin"), "pcd", 0, 0}, bytes);
  }

  Status write_image(std::size_t frame, std::size_t sensor, Timestamp time, const SE3& T_world_body, const msgs::ImageMessage& image) override {
    const bool depth = image.encoding == msgs::ImageEncoding::kDepth16 || image.encoding == msgs::ImageEncoding::kDepth32f;
    std::string bytes;
    HANZO_ASSIGN_OR_RETURN(bytes, encode_image(image, !depth, config_.jpeg_quality));
    const std::string format = depth ? "png" : "jpg";
    return add(SampleData{frame, sensor, time, T_world_body, file_name(sensor, time, format), format, image.width, image.height}, bytes);
  }

  Status finish() override {
    const std::string tables = out_dir_ + "/v1.0-hanzo";
    std::error_code error;
    std::filesystem::create_directories(tables, error);
    if (error) return Error(fmt::format("{}: cannot create the folder ({})", tables, error.message()));
    const std::string log_token = token("log/" + config_.scene_name);
    const std::string scene_token = token("scene/" + config_.scene_name);
    json sensor_table = json::array(), calibrated_table = json::array();
    for (const LayoutSensor& sensor : sensors_) {
      sensor_table.push_back({{"token", token("sensor/" + sensor.name)}, {"channel", channel_of(sensor.name)},
                              {"modality", sensor.is_camera ? "camera" : "lidar"}});
      json intrinsic = json::array();
      if (sensor.is_camera) {
        const msgs::CameraIntrinsics& k = sensor.intrinsics;
        intrinsic = json::array({json::array({k.fx, 0.0, k.cx}), json::array({0.0, k.fy, k.cy}), json::array({0.0, 0.0, 1.0})});
      }
      calibrated_table.push_back({{"token", token("calibrated_sensor/" + sensor.name)}, {"sensor_token", token("sensor/" + sensor.name)},
                                  {"translation", vector_json(sensor.T_body_sensor.translation())},
                                  {"rotation", rotation_json(sensor.T_body_sensor)}, {"camera_intrinsic", intrinsic}});
    }
    // Samples: the frames (a frame's reference message decides its token), linked in time order.
    std::vector<std::string> sample_tokens;
    for (const LayoutFrame& frame : frames_) sample_tokens.push_back(token(fmt::format("sample/{}/{}", config_.scene_name, frame.time.nanoseconds())));
    json sample_table = json::array();
    for (std::size_t i = 0; i < frames_.size(); ++i) {
      sample_table.push_back({{"token", sample_tokens[i]}, {"timestamp", frames_[i].time.nanoseconds() / 1000}, {"scene_token", scene_token},
                              {"prev", i > 0 ? sample_tokens[i - 1] : ""}, {"next", i + 1 < frames_.size() ? sample_tokens[i + 1] : ""}});
    }
    // Sample data and ego poses (sharing tokens, as nuScenes does), chained per sensor.
    std::sort(records_.begin(), records_.end(), [](const SampleData& a, const SampleData& b) {
      return std::tie(a.sensor, a.frame) < std::tie(b.sensor, b.frame);
    });
    const auto data_token = [&](const SampleData& d) { return token(fmt::format("sample_data/{}/{}/{}", sensors_[d.sensor].name, d.frame, d.time.nanoseconds())); };
    json data_table = json::array(), ego_table = json::array();
    for (std::size_t i = 0; i < records_.size(); ++i) {
      const SampleData& d = records_[i];
      const bool has_prev = i > 0 && records_[i - 1].sensor == d.sensor;
      const bool has_next = i + 1 < records_.size() && records_[i + 1].sensor == d.sensor;
      const std::string own = data_token(d);
      ego_table.push_back({{"token", own}, {"timestamp", d.time.nanoseconds() / 1000}, {"rotation", rotation_json(d.T_world_body)},
                           {"translation", vector_json(d.T_world_body.translation())}});
      data_table.push_back({{"token", own}, {"sample_token", sample_tokens[d.frame]}, {"ego_pose_token", own},
                            {"calibrated_sensor_token", token("calibrated_sensor/" + sensors_[d.sensor].name)},
                            {"timestamp", d.time.nanoseconds() / 1000}, {"fileformat", d.fileformat}, {"is_key_frame", true},
                            {"height", d.height}, {"width", d.width}, {"filename", d.filename},
                            {"prev", has_prev ? data_token(records_[i - 1]) : ""}, {"next", has_next ? data_token(records_[i + 1]) : ""}});
    }
    const json scene_table = json::array({{{"token", scene_token}, {"log_token", log_token}, {"nbr_samples", frames_.size()},
                                           {"first_sample_token", sample_tokens.front()}, {"last_sample_token", sample_tokens.back()},
                                           {"name", config_.scene_name}, {"description", "exported by hanzo-fusion export dataset"}}});
    const json log_table = json::array({{{"token", log_token}, {"logfile", config_.scene_name}, {"vehicle", ""},
                                         {"date_captured", ""}, {"location", ""}}});
    const std::map<std::string, const json*> written = {
        {"sensor", &sensor_table}, {"calibrated_sensor", &calibrated_table}, {"sample", &sample_table}, {"sample_data", &data_table},
        {"ego_pose", &ego_table},  {"scene", &scene_table},                  {"log", &log_table}};
    for (const auto& [name, table] : written) HANZO_RETURN_IF_ERROR(write_file(fmt::format("{}/{}.json", tables, name), table->dump(1)));
    for (const char* empty : {"category", "attribute", "visibility", "instance", "sample_annotation", "map"}) {
      HANZO_RETURN_IF_ERROR(write_file(fmt::format("{}/{}.json", tables, empty), "[]\n"));
    }
    return ok_status();
  }

 private:
  std::string file_name(std::size_t sensor, Timestamp time, const std::string& extension) const {
    const std::string channel = channel_of(sensors_[sensor].name);
    return fmt::format("samples/{}/{}__{}__{}.{}", channel, config_.scene_name, channel, time.nanoseconds() / 1000, extension);
  }

  Status add(SampleData data, const std::string& bytes) {
    const std::string path = out_dir_ + "/" + data.filename;
    std::error_code error;
    std::filesystem::create_directories(std::filesystem::path(path).parent_path(), error);
    if (error) return Error(fmt::format("{}: cannot create the folder ({})", path, error.message()));
    HANZO_RETURN_IF_ERROR(write_file(path, bytes));
    records_.push_back(std::move(data));
    return ok_status();
  }

  std::string out_dir_;
  std::vector<LayoutSensor> sensors_;
  std::vector<LayoutFrame> frames_;
  DatasetExportConfig config_;
  std::vector<SampleData> records_;
};

}  // namespace

std::unique_ptr<DatasetLayoutWriter> make_nuscenes_writer(const std::string& out_dir, std::vector<LayoutSensor> sensors,
                                                          std::vector<LayoutFrame> frames, const DatasetExportConfig& config) {
  return std::make_unique<NuscenesWriter>(out_dir, std::move(sensors), std::move(frames), config);
}

}  // namespace hanzo::fusion::io::dataset
