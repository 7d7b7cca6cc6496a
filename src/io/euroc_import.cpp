#include "hanzo/fusion/io/euroc_import.hpp"

#include <algorithm>
#include <charconv>
#include <cmath>
#include <filesystem>
#include <sstream>

#include <fmt/format.h>

#include "hanzo/fusion/core/files.hpp"
#include "hanzo/fusion/core/yaml_value.hpp"
#include "image_files.hpp"
#include "text_lines.hpp"

namespace hanzo::fusion::io {
namespace {

namespace fs = std::filesystem;

struct Row {
  Timestamp time;
  std::vector<std::string> fields;  // after the timestamp
};

// data.csv: '#' header, then "timestamp_ns,field,...". Rows whose time does not increase are
// counted in `stream` and left out.
Result<std::vector<Row>> read_rows(const fs::path& path, std::size_t fields_after_time, EurocStreamReport& stream) {
  std::string text;
  HANZO_ASSIGN_OR_RETURN(text, read_file(path.string()));
  std::vector<Row> rows;
  std::istringstream lines(text);
  std::string line;
  for (std::size_t line_number = 1; std::getline(lines, line); ++line_number) {
    if (line.empty() || line[0] == '#' || line == "\r") continue;
    std::vector<std::string> fields = split_fields(line);
    const std::string where = fmt::format("{}:{}", path.string(), line_number);
    if (fields.size() != fields_after_time + 1) {
      return Error(fmt::format("{}: {} fields (expected {})", where, fields.size(), fields_after_time + 1));
    }
    int64_t ns = 0;
    const auto [end, error] = std::from_chars(fields[0].data(), fields[0].data() + fields[0].size(), ns);
    if (error != std::errc() || end != fields[0].data() + fields[0].size() || ns <= 0) {
      return Error(fmt::format("{}: timestamp '{}' is not a positive integer number of nanoseconds", where, fields[0]));
    }
    const Timestamp time = Timestamp::from_nanoseconds(ns);
    if (!rows.empty() && time <= rows.back().time) {
      if (stream.rejected++ == 0) stream.first_rejection = fmt::format("{}: time {} ns does not increase", where, ns);
      continue;
    }
    fields.erase(fields.begin());
    rows.push_back({time, std::move(fields)});
  }
  return rows;
}

Result<SE3> read_T_BS(const YamlValue& yaml) {
  const YamlValue T_BS = yaml["T_BS"];
  if (!T_BS.present()) return SE3();
  std::vector<double> data;
  HANZO_ASSIGN_OR_RETURN(data, T_BS["data"].as_doubles(16, "(row-major 4x4 T_BS)"));
  const Eigen::Matrix4d matrix = Eigen::Map<const Eigen::Matrix<double, 4, 4, Eigen::RowMajor>>(data.data());
  const Eigen::Matrix3d R = matrix.topLeftCorner<3, 3>();
  if ((R.transpose() * R - Eigen::Matrix3d::Identity()).norm() > 1e-3 || R.determinant() < 0) {
    return T_BS.error("T_BS: rotation block is not a rotation");
  }
  return SE3::from_matrix(matrix);
}

Result<calib::CameraCalibration> read_camera(const YamlValue& yaml) {
  calib::CameraCalibration camera;
  std::vector<double> k;
  HANZO_ASSIGN_OR_RETURN(k, yaml["intrinsics"].as_doubles(4, "(fu, fv, cu, cv)"));
  camera.intrinsics = {k[0], k[1], k[2], k[3], 0, 0};
  if (yaml["resolution"].present()) {
    std::vector<double> size;
    HANZO_ASSIGN_OR_RETURN(size, yaml["resolution"].as_doubles(2, "(width, height)"));
    camera.intrinsics.width = static_cast<uint32_t>(size[0]);
    camera.intrinsics.height = static_cast<uint32_t>(size[1]);
  }
  if (yaml["distortion_model"].present()) {
    std::string model;
    HANZO_ASSIGN_OR_RETURN(model, yaml["distortion_model"].as_string());
    if (model == "radial-tangential" || model == "radtan") {
      camera.distortion.type = msgs::DistortionType::kRadtan;
    } else if (model == "equidistant") {
      camera.distortion.type = msgs::DistortionType::kEquidistant;
    } else {
      return yaml["distortion_model"].error(fmt::format("unknown distortion model '{}' (radial-tangential, equidistant)", model));
    }
    HANZO_ASSIGN_OR_RETURN(camera.distortion.coefficients,
                           yaml["distortion_coefficients"].as_doubles(4, "(k1, k2, p1, p2 or k1..k4)"));
  }
  return camera;
}

// The IMU covariance per sample from a continuous-time noise density: sigma^2 = density^2 * rate.
Result<std::optional<Eigen::Matrix3d>> sample_covariance(const YamlValue& yaml, const char* density_key) {
  if (!yaml[density_key].present() || !yaml["rate_hz"].present()) return std::optional<Eigen::Matrix3d>();
  double density = 0, rate = 0;
  HANZO_ASSIGN_OR_RETURN(density, yaml[density_key].as_double());
  HANZO_ASSIGN_OR_RETURN(rate, yaml["rate_hz"].as_double());
  if (density <= 0 || rate <= 0) return yaml[density_key].error("noise density and rate_hz must be positive");
  return std::optional<Eigen::Matrix3d>(Eigen::Matrix3d::Identity() * density * density * rate);
}

Result<double> field(const Row& row, std::size_t i, const fs::path& path) {
  const auto value = parse_double(row.fields[i]);
  if (!value || !std::isfinite(*value)) {
    return Error(fmt::format("{}: row at {} ns: '{}' is not a finite number", path.string(), row.time.nanoseconds(), row.fields[i]));
  }
  return *value;
}

struct CameraStream {
  std::string name;  // cam0
  fs::path dir;
  std::size_t report_index = 0;  // into EurocImportReport::streams
  calib::CameraCalibration camera;
  std::vector<Row> rows;
};

}  // namespace

Result<calib::SensorCalibration> read_euroc_camera_calibration(const std::string& sensor_yaml_path, const std::string& sensor_name) {
  const Result<YamlValue> yaml = YamlValue::load_file(sensor_yaml_path);
  if (!yaml) return yaml.error();
  SE3 T_body_camera;
  HANZO_ASSIGN_OR_RETURN(T_body_camera, read_T_BS(*yaml));
  calib::SensorCalibration sensor = calib::SensorCalibration::from_transform(sensor_name, T_body_camera);
  HANZO_ASSIGN_OR_RETURN(sensor.camera, read_camera(*yaml));
  return sensor;
}

Result<EurocImportReport> import_euroc(const std::string& dir, SensorLogWriter& writer, const EurocImportConfig& config) {
  fs::path mav(dir);
  if (fs::is_directory(mav / "mav0")) mav /= "mav0";
  if (!fs::is_directory(mav / "imu0") && !fs::is_directory(mav / "cam0")) {
    return Error(fmt::format("{}: no mav0/imu0 or mav0/cam0 folder (expected an EuRoC/ASL dataset folder)", dir));
  }
  EurocImportReport report;

  // IMU.
  std::vector<Row> imu_rows;
  std::optional<Eigen::Matrix3d> gyro_covariance, accel_covariance;
  const fs::path imu_dir = mav / "imu0";
  if (fs::is_directory(imu_dir)) {
    report.streams.push_back({config.imu_topic, 0, 0, {}});
    HANZO_ASSIGN_OR_RETURN(imu_rows, read_rows(imu_dir / "data.csv", 6, report.streams.back()));
    SE3 T_body_imu;
    if (fs::is_regular_file(imu_dir / "sensor.yaml")) {
      const Result<YamlValue> yaml = YamlValue::load_file((imu_dir / "sensor.yaml").string());
      if (!yaml) return yaml.error();
      HANZO_ASSIGN_OR_RETURN(T_body_imu, read_T_BS(*yaml));
      HANZO_ASSIGN_OR_RETURN(gyro_covariance, sample_covariance(*yaml, "gyroscope_noise_density"));
      HANZO_ASSIGN_OR_RETURN(accel_covariance, sample_covariance(*yaml, "accelerometer_noise_density"));
    }
    report.calibration.sensors.push_back(calib::SensorCalibration::from_transform(config.imu_topic.substr(1), T_body_imu));
  }

  // Cameras: every camN folder with a data.csv, in name order.
  std::vector<CameraStream> cameras;
  if (config.import_images) {
    for (const auto& entry : fs::directory_iterator(mav)) {
      const std::string name = entry.path().filename().string();
      if (entry.is_directory() && name.starts_with("cam") && fs::is_regular_file(entry.path() / "data.csv")) {
        cameras.push_back({name, entry.path(), 0, {}, {}});
      }
    }
    std::sort(cameras.begin(), cameras.end(), [](const CameraStream& a, const CameraStream& b) { return a.name < b.name; });
    for (CameraStream& camera : cameras) {
      camera.report_index = report.streams.size();
      report.streams.push_back({"/" + camera.name, 0, 0, {}});
      HANZO_ASSIGN_OR_RETURN(camera.rows, read_rows(camera.dir / "data.csv", 1, report.streams.back()));
      if (fs::is_regular_file(camera.dir / "sensor.yaml")) {
        calib::SensorCalibration sensor;
        HANZO_ASSIGN_OR_RETURN(sensor, read_euroc_camera_calibration((camera.dir / "sensor.yaml").string(), camera.name));
        camera.camera = *sensor.camera;
        report.calibration.sensors.push_back(sensor);
      }
    }
  }

  // Ground truth.
  for (const char* source : {"state_groundtruth_estimate0", "vicon0"}) {
    const fs::path path = mav / source / "data.csv";
    if (!fs::is_regular_file(path)) continue;
    HANZO_ASSIGN_OR_RETURN(report.ground_truth, read_trajectory(path.string(), TrajectoryFormat::kEuroc));
    report.ground_truth_path = path.string();
    break;
  }

  // Everything in time order: (time, stream, row); stream 0 is the IMU, 1.. the cameras.
  struct Event {
    Timestamp time;
    std::size_t stream;
    std::size_t row;
  };
  std::vector<Event> events;
  for (std::size_t i = 0; i < imu_rows.size(); ++i) events.push_back({imu_rows[i].time, 0, i});
  for (std::size_t c = 0; c < cameras.size(); ++c) {
    for (std::size_t i = 0; i < cameras[c].rows.size(); ++i) events.push_back({cameras[c].rows[i].time, c + 1, i});
  }
  std::stable_sort(events.begin(), events.end(), [](const Event& a, const Event& b) { return a.time < b.time; });

  for (const Event& event : events) {
    if (event.stream == 0) {
      const Row& row = imu_rows[event.row];
      double v[6];
      for (std::size_t i = 0; i < 6; ++i) HANZO_ASSIGN_OR_RETURN(v[i], field(row, i, imu_dir / "data.csv"));
      msgs::ImuMessage imu;
      imu.timestamp = row.time;
      imu.frame_id = config.imu_topic.substr(1);
      imu.angular_velocity = {v[0], v[1], v[2]};
      imu.linear_acceleration = {v[3], v[4], v[5]};
      imu.gyroscope_covariance = gyro_covariance;
      imu.acceleration_covariance = accel_covariance;
      HANZO_RETURN_IF_ERROR(with_context(writer.write(config.imu_topic, imu), (imu_dir / "data.csv").string()));
      ++report.streams[0].messages;
      continue;
    }
    const CameraStream& camera = cameras[event.stream - 1];
    const Row& row = camera.rows[event.row];
    const std::string path = (camera.dir / "data" / row.fields[0]).string();
    msgs::ImageMessage image;
    HANZO_ASSIGN_OR_RETURN(image, read_image_file(path, row.time, camera.name));
    if (image.encoding != msgs::ImageEncoding::kMono8 && image.encoding != msgs::ImageEncoding::kRgb8) {
      return Error(fmt::format("{}: expected an 8-bit gray or colour image", path));
    }
    if (camera.camera.intrinsics.fx > 0) {
      image.intrinsics = camera.camera.intrinsics;
      image.intrinsics->width = image.width;
      image.intrinsics->height = image.height;
      if (camera.camera.distortion.type != msgs::DistortionType::kNone) image.distortion = camera.camera.distortion;
    }
    HANZO_RETURN_IF_ERROR(with_context(writer.write("/" + camera.name, image), path));
    ++report.streams[camera.report_index].messages;
  }
  return report;
}

}  // namespace hanzo::fusion::io
