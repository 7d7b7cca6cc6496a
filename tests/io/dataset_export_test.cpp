// export_dataset: a synthetic drive (a body turning while it accelerates, a LiDAR sweeping
// known world points with per-point times and a time offset, a distorted camera seeing bright
// dots at known world points) written as a sensor log, exported in both layouts, and read back:
// every exported point, moved into the world with the exported poses and calibration, lands on
// its world point; the camera's dots land where the pinhole intrinsics put them.

#include <algorithm>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <random>
#include <sstream>

#include <unistd.h>

#include <fmt/format.h>
#include <gtest/gtest.h>
#include <nlohmann/json.hpp>
#include <opencv2/imgcodecs.hpp>

#include "hanzo/fusion/io/dataset_export.hpp"
#include "hanzo/fusion/io/kitti_import.hpp"
#include "hanzo/fusion/io/sensor_log.hpp"

namespace hanzo::fusion::io {
namespace {

namespace fs = std::filesystem;
using nlohmann::json;

const Timestamp kStart = Timestamp::from_seconds(1700000000.0);
constexpr double kDuration = 2.0;                  // s of trajectory
const Duration kLidarOffset = Duration::from_milliseconds(2);  // t_body = t_lidar + 2 ms

SE3 body_at(double t) {  // accelerating along x while turning
  return {SO3::from_axis_angle(Eigen::Vector3d::UnitZ(), 0.5 * t), Eigen::Vector3d(2.0 * t + 0.5 * t * t, 0.3 * t * t, 0.05 * t)};
}
const SE3 kT_body_lidar(SO3::from_axis_angle(Eigen::Vector3d::UnitZ(), 0.3), Eigen::Vector3d(0.5, 0.1, 1.0));
// Camera looking along body x (z forward, x right, y down).
const SE3 kT_body_camera(SO3::from_matrix((Eigen::Matrix3d() << 0, 0, 1, -1, 0, 0, 0, -1, 0).finished()), Eigen::Vector3d(0.6, 0.0, 0.8));

PinholeCamera camera_model() {
  PinholeCamera camera;
  camera.fx = camera.fy = 200.0;
  camera.cx = 160.0;
  camera.cy = 120.0;
  camera.distortion = PinholeCamera::Distortion::kRadtan;
  camera.coefficients = {-0.25, 0.06, 0.001, -0.001, 0.0};
  return camera;
}

struct Scene {
  fs::path dir;
  std::vector<Eigen::Vector3d> world_points;   // seen by the LiDAR
  std::vector<Eigen::Vector3d> camera_points;  // drawn as dots by the camera
  Trajectory trajectory;
  calib::Calibration calibration;
  std::string log;
};

Scene make_scene(const std::string& name, bool drop_one_image = false) {
  Scene scene;
  scene.dir = fs::temp_directory_path() / fmt::format("hanzo_dataset_export_{}_{}", ::getpid(), name);
  fs::remove_all(scene.dir);
  fs::create_directories(scene.dir);
  std::mt19937 random(3);
  std::uniform_real_distribution<double> coordinate(-15.0, 15.0);
  for (int i = 0; i < 400; ++i) scene.world_points.emplace_back(coordinate(random), coordinate(random), 0.5 * coordinate(random));
  for (int i = 0; i < 60; ++i) {  // a ring 15 m around the start, 6 deg apart, at two heights: always some in view
    const double angle = i * M_PI / 30.0;
    for (const double height : {0.0, 2.0}) scene.camera_points.emplace_back(15.0 * std::cos(angle), 15.0 * std::sin(angle), height);
  }
  for (int k = 0; k <= 200; ++k) {  // 100 Hz
    scene.trajectory.timestamps.push_back(kStart + Duration::from_milliseconds(10 * k));
    scene.trajectory.poses.push_back(body_at(0.01 * k).matrix());
  }
  scene.calibration.sensors.push_back(calib::SensorCalibration::from_transform("lidar", kT_body_lidar, kLidarOffset));
  calib::SensorCalibration camera = calib::SensorCalibration::from_transform("camera_front", kT_body_camera);
  camera.camera = calib::CameraCalibration{{200.0, 200.0, 160.0, 120.0, 320, 240}, {msgs::DistortionType::kRadtan, {-0.25, 0.06, 0.001, -0.001}}};
  scene.calibration.sensors.push_back(camera);

  scene.log = (scene.dir / "sensors.mcap").string();
  auto writer = SensorLogWriter::open(scene.log);
  EXPECT_TRUE(writer.ok());
  const PinholeCamera model = camera_model();
  std::vector<std::pair<Timestamp, msgs::SensorMessage>> messages;
  for (int k = 0; k < 22; ++k) {  // 10 Hz; the last two after the trajectory ends
    msgs::PointCloudMessage sweep;
    sweep.timestamp = kStart + Duration::from_milliseconds(100 * k);
    for (std::size_t i = 0; i < scene.world_points.size(); ++i) {
      const Timestamp point_time = sweep.timestamp + Duration::from_microseconds(static_cast<int64_t>(i) * 240);  // 96 ms sweep
      const SE3 T_world_lidar = body_at((point_time + kLidarOffset - kStart).seconds()) * kT_body_lidar;
      sweep.points.push_back((T_world_lidar.inverse() * scene.world_points[i]).cast<float>());
      sweep.point_timestamps.push_back(point_time);
      sweep.intensities.push_back(static_cast<float>(i % 100) / 100.0F);
      sweep.ring_ids.push_back(static_cast<uint32_t>(i % 16));
    }
    messages.emplace_back(sweep.timestamp, sweep);
  }
  for (int k = 0; k < 40; ++k) {  // 20 Hz, 7 ms after the sweeps
    if (drop_one_image && (k == 10 || k == 11)) continue;  // the frame at 0.5 s has no image within 20 ms
    msgs::ImageMessage image;
    image.timestamp = kStart + Duration::from_milliseconds(50 * k + 7);
    image.width = 320;
    image.height = 240;
    image.encoding = msgs::ImageEncoding::kMono8;
    image.data.assign(320 * 240, 0);
    const SE3 T_camera_world = (body_at((image.timestamp - kStart).seconds()) * kT_body_camera).inverse();
    for (const Eigen::Vector3d& point : scene.camera_points) {
      const std::optional<Eigen::Vector2d> pixel = model.project(T_camera_world * point);
      if (!pixel) continue;
      for (int dv = -2; dv <= 2; ++dv) {
        for (int du = -2; du <= 2; ++du) {
          const int u = static_cast<int>(std::lround(pixel->x())) + du, v = static_cast<int>(std::lround(pixel->y())) + dv;
          if (u >= 0 && u < 320 && v >= 0 && v < 240) image.data[static_cast<std::size_t>(v * 320 + u)] = 255;
        }
      }
    }
    messages.emplace_back(image.timestamp, image);
  }
  std::sort(messages.begin(), messages.end(), [](const auto& a, const auto& b) { return a.first < b.first; });
  for (const auto& [time, message] : messages) {
    const bool cloud = std::holds_alternative<msgs::PointCloudMessage>(message);
    EXPECT_TRUE((*writer)->write(cloud ? "/lidar" : "/camera", message, cloud ? "lidar" : "camera_front").ok());
  }
  EXPECT_TRUE((*writer)->close().ok());
  return scene;
}

DatasetExportConfig config_for(DatasetLayout layout) {
  DatasetExportConfig config;
  config.layout = layout;
  config.sensors = {{"lidar", "/lidar", false}, {"camera_front", "/camera", true}};
  config.max_time_difference_s = 0.02;
  return config;
}

std::string read_text(const fs::path& path) {
  std::ifstream file(path, std::ios::binary);
  std::stringstream text;
  text << file.rdbuf();
  return text.str();
}

std::vector<float> read_floats(const fs::path& path) {
  const std::string bytes = read_text(path);
  std::vector<float> values(bytes.size() / sizeof(float));
  std::memcpy(values.data(), bytes.data(), values.size() * sizeof(float));
  return values;
}

Eigen::Matrix4d matrix_3x4(const std::string& line) {
  std::istringstream numbers(line);
  Eigen::Matrix4d matrix = Eigen::Matrix4d::Identity();
  for (int r = 0; r < 3; ++r) {
    for (int c = 0; c < 4; ++c) numbers >> matrix(r, c);
  }
  return matrix;
}

// The dots of an undistorted image: bright pixels near where the pinhole model puts each point.
void expect_dots_where_the_pinhole_puts_them(const cv::Mat& image, const SE3& T_world_camera, const std::vector<Eigen::Vector3d>& points,
                                             const Eigen::Matrix<double, 3, 4>& projection) {
  int checked = 0;
  for (const Eigen::Vector3d& point : points) {
    const Eigen::Vector3d in_camera0 = T_world_camera.inverse() * point;
    const Eigen::Vector3d pixel = projection * in_camera0.homogeneous();
    const double u = pixel.x() / pixel.z(), v = pixel.y() / pixel.z();
    if (pixel.z() <= 0 || u < 5 || v < 5 || u > 314 || v > 234) continue;
    // The centroid of the bright pixels within 5 px.
    double sum_u = 0, sum_v = 0, weight = 0;
    for (int dv = -5; dv <= 5; ++dv) {
      for (int du = -5; du <= 5; ++du) {
        const int x = static_cast<int>(std::lround(u)) + du, y = static_cast<int>(std::lround(v)) + dv;
        if (x < 0 || y < 0 || x >= image.cols || y >= image.rows) continue;
        const double value = image.at<uint8_t>(y, x);
        sum_u += value * x;
        sum_v += value * y;
        weight += value;
      }
    }
    ASSERT_GT(weight, 0.0) << "no dot near (" << u << ", " << v << ")";
    EXPECT_NEAR(sum_u / weight, u, 1.0);
    EXPECT_NEAR(sum_v / weight, v, 1.0);
    ++checked;
  }
  EXPECT_GE(checked, 3);
}

TEST(DatasetExport, KittiLayoutPutsEveryPointBackOnTheWorld) {
  const Scene scene = make_scene("kitti");
  const fs::path out = scene.dir / "kitti";
  auto summary = export_dataset(scene.log, scene.trajectory, scene.calibration, out.string(), config_for(DatasetLayout::kKittiOdometry));
  ASSERT_TRUE(summary.ok()) << summary.error().message;
  EXPECT_EQ(summary->reference_messages, 22u);
  EXPECT_EQ(summary->outside_trajectory, 2u);  // the sweeps after the trajectory
  EXPECT_EQ(summary->frames, 20u);
  EXPECT_EQ(summary->deskewed_sweeps, 20u);
  EXPECT_EQ(summary->undistorted_images, 20u);

  const fs::path sequence = out / "sequences" / "00";
  std::istringstream calib(read_text(sequence / "calib.txt"));
  std::string line;
  std::getline(calib, line);
  ASSERT_EQ(line.rfind("P0: ", 0), 0u);
  const Eigen::Matrix<double, 3, 4> P0 = matrix_3x4(line.substr(4)).topRows<3>();
  std::getline(calib, line);
  ASSERT_EQ(line.rfind("Tr: ", 0), 0u);
  const Eigen::Matrix4d Tr = matrix_3x4(line.substr(4));
  EXPECT_TRUE(Tr.isApprox((kT_body_camera.inverse() * kT_body_lidar).matrix(), 1e-9));
  std::istringstream poses(read_text(out / "poses" / "00.txt"));
  std::istringstream times(read_text(sequence / "times.txt"));
  for (int frame = 0; frame < 20; ++frame) {
    ASSERT_TRUE(std::getline(poses, line));
    const Eigen::Matrix4d pose = matrix_3x4(line);
    double time = 0;
    times >> time;
    EXPECT_NEAR(time, 0.1 * frame, 1e-6);
    // World of the first frame's camera 0: the first sweep at 0.002 s body time.
    const Eigen::Matrix4d T_world_camera0 = (body_at(kLidarOffset.seconds()) * kT_body_camera).matrix() * pose;
    const std::vector<float> values = read_floats(sequence / "velodyne" / fmt::format("{:06d}.bin", frame));
    ASSERT_EQ(values.size(), scene.world_points.size() * 4);
    double worst = 0;
    for (std::size_t i = 0; i < scene.world_points.size(); ++i) {
      const Eigen::Vector4d p(values[4 * i], values[4 * i + 1], values[4 * i + 2], 1.0);
      worst = std::max(worst, ((T_world_camera0 * Tr * p).head<3>() - scene.world_points[i]).norm());
      EXPECT_FLOAT_EQ(values[4 * i + 3], static_cast<float>(i % 100) / 100.0F);
    }
    EXPECT_LT(worst, 2e-3) << "frame " << frame;  // float32 coordinates at 20 m, SE3 interpolation at 100 Hz
    const cv::Mat image = cv::imread((sequence / "image_0" / fmt::format("{:06d}.png", frame)).string(), cv::IMREAD_UNCHANGED);
    ASSERT_EQ(image.type(), CV_8UC1);
    // The image is the one 7 ms after the sweep: its camera pose, not the frame's.
    const SE3 T_world_camera = body_at(0.1 * frame + 0.007) * kT_body_camera;
    expect_dots_where_the_pinhole_puts_them(image, T_world_camera, scene.camera_points, P0);
  }

  // The KITTI importer reads the export back: the same sweeps, and ground truth (in the LiDAR
  // frame) that is the true motion of the LiDAR between the frames' times.
  auto reimported_log = SensorLogWriter::open((scene.dir / "reimported.mcap").string());
  ASSERT_TRUE(reimported_log.ok());
  KittiImportConfig import_config;
  import_config.poses_path = (out / "poses" / "00.txt").string();
  auto reimported = import_kitti(sequence.string(), **reimported_log, import_config);
  ASSERT_TRUE(reimported.ok()) << reimported.error().message;
  EXPECT_EQ(reimported->frames, 20u);
  EXPECT_EQ(reimported->images, 20u);
  // ... at the log's own times (timestamps_ns.txt), not times.txt's relative ones moved to 2001.
  EXPECT_TRUE(reimported->absolute_times);
  std::istringstream stamps(read_text(sequence / "timestamps_ns.txt"));
  int64_t first_ns = 0;
  stamps >> first_ns;
  ASSERT_FALSE(reimported->ground_truth.timestamps.empty());
  EXPECT_EQ(reimported->ground_truth.timestamps.front().nanoseconds(), first_ns);
  EXPECT_EQ(reimported->points, 20u * scene.world_points.size());
  const SE3 T_lidar0_world = (body_at(kLidarOffset.seconds()) * kT_body_lidar).inverse();
  for (int frame = 0; frame < 20; ++frame) {
    const SE3 truth = T_lidar0_world * body_at(0.1 * frame + kLidarOffset.seconds()) * kT_body_lidar;
    // The trajectory is sampled at 100 Hz and interpolated on SE3: ~1e-5 from the analytic motion.
    EXPECT_LT((reimported->ground_truth.poses[static_cast<std::size_t>(frame)] - truth.matrix()).cwiseAbs().maxCoeff(), 1e-4) << frame;
  }
  fs::remove_all(scene.dir);
}

// Real images and poses: KITTI odometry 06 (the first 51 frames of the left camera) as a log,
// exported with the official poses as the trajectory, gives back KITTI's own files: the same
// pixels, P0, times and poses.
TEST(DatasetExport, KittiSequence06ComesBackAsKittiHadIt) {
  const fs::path data = fs::path(HANZO_DATA_DIR) / "kitti_odometry_06_first51";
  const fs::path dir = fs::temp_directory_path() / fmt::format("hanzo_dataset_export_{}_kitti06", ::getpid());
  fs::remove_all(dir);
  fs::create_directories(dir);
  const double origin = 1.3e9;  // the benchmark's times start at 0
  auto ground_truth = read_trajectory((data / "gt_cam0.tum").string(), TrajectoryFormat::kTum);
  ASSERT_TRUE(ground_truth.ok()) << ground_truth.error().message;
  for (Timestamp& time : ground_truth->timestamps) time = time + Duration::from_seconds(origin);
  std::istringstream calib_text(read_text(data / "calib.txt"));
  std::string first_line;
  std::getline(calib_text, first_line);
  const Eigen::Matrix4d P_left = matrix_3x4(first_line);
  calib::Calibration calibration;
  calib::SensorCalibration camera = calib::SensorCalibration::from_transform("cam0", SE3());  // the body is camera 0
  camera.camera = calib::CameraCalibration{{P_left(0, 0), P_left(1, 1), P_left(0, 2), P_left(1, 2), 0, 0}, {}};  // size: as the images come
  calibration.sensors.push_back(camera);
  {
    auto writer = SensorLogWriter::open((dir / "kitti06.mcap").string());
    ASSERT_TRUE(writer.ok());
    for (std::size_t frame = 0; frame < ground_truth->size(); ++frame) {
      const cv::Mat gray = cv::imread((data / "image_l" / fmt::format("{:06d}.png", frame)).string(), cv::IMREAD_UNCHANGED);
      ASSERT_EQ(gray.type(), CV_8UC1);
      msgs::ImageMessage image;
      image.timestamp = ground_truth->timestamps[frame];
      image.width = static_cast<uint32_t>(gray.cols);
      image.height = static_cast<uint32_t>(gray.rows);
      image.data.assign(gray.data, gray.data + gray.total());
      ASSERT_TRUE((*writer)->write("/cam0", image, "cam0").ok());
    }
    ASSERT_TRUE((*writer)->close().ok());
  }
  DatasetExportConfig config;
  config.sensors = {{"cam0", "/cam0", true}};
  const fs::path out = dir / "out";
  auto summary = export_dataset((dir / "kitti06.mcap").string(), *ground_truth, calibration, out.string(), config);
  ASSERT_TRUE(summary.ok()) << summary.error().message;
  EXPECT_EQ(summary->frames, 51u);
  EXPECT_EQ(summary->undistorted_images, 0u);  // rectified already
  const fs::path sequence = out / "sequences" / "00";
  std::istringstream calib(read_text(sequence / "calib.txt"));
  std::string line;
  std::getline(calib, line);
  ASSERT_EQ(line.rfind("P0: ", 0), 0u);
  EXPECT_TRUE(matrix_3x4(line.substr(4)).isApprox(P_left, 1e-12));
  std::istringstream poses(read_text(out / "poses" / "00.txt"));
  std::istringstream exported_times(read_text(sequence / "times.txt"));
  std::istringstream kitti_times(read_text(data / "times_from_pyslam_kitti06.txt"));
  for (std::size_t frame = 0; frame < 51; ++frame) {
    ASSERT_TRUE(std::getline(poses, line));
    EXPECT_TRUE(matrix_3x4(line).isApprox(ground_truth->poses[frame], 1e-8)) << frame;
    double exported = 0, kitti = 0;
    exported_times >> exported;
    kitti_times >> kitti;
    EXPECT_NEAR(exported, kitti, 1e-6);
    const cv::Mat original = cv::imread((data / "image_l" / fmt::format("{:06d}.png", frame)).string(), cv::IMREAD_UNCHANGED);
    const cv::Mat written = cv::imread((sequence / "image_0" / fmt::format("{:06d}.png", frame)).string(), cv::IMREAD_UNCHANGED);
    ASSERT_EQ(written.type(), original.type());
    EXPECT_EQ(cv::norm(original, written, cv::NORM_INF), 0.0) << frame;
  }
  fs::remove_all(dir);
}

TEST(DatasetExport, UndeskewedSweepsAreSmeared) {
  const Scene scene = make_scene("no_deskew");
  DatasetExportConfig config = config_for(DatasetLayout::kKittiOdometry);
  config.deskew = false;
  auto summary = export_dataset(scene.log, scene.trajectory, scene.calibration, (scene.dir / "out").string(), config);
  ASSERT_TRUE(summary.ok()) << summary.error().message;
  EXPECT_EQ(summary->deskewed_sweeps, 0u);
  const std::vector<float> values = read_floats(scene.dir / "out" / "sequences" / "00" / "velodyne" / "000005.bin");
  const SE3 T_world_lidar = body_at(0.5 + kLidarOffset.seconds()) * kT_body_lidar;
  double worst = 0;
  for (std::size_t i = 0; i < scene.world_points.size(); ++i) {
    const Eigen::Vector3d p(values[4 * i], values[4 * i + 1], values[4 * i + 2]);
    worst = std::max(worst, (T_world_lidar * p - scene.world_points[i]).norm());
  }
  EXPECT_GT(worst, 0.1);  // ~100 ms of 2.5 m/s and 0.5 rad/s
  fs::remove_all(scene.dir);
}

TEST(DatasetExport, NuscenesTablesLinkEverything) {
  const Scene scene = make_scene("nuscenes", /*drop_one_image=*/true);
  const fs::path out = scene.dir / "nuscenes";
  DatasetExportConfig config = config_for(DatasetLayout::kNuscenes);
  auto summary = export_dataset(scene.log, scene.trajectory, scene.calibration, out.string(), config);
  ASSERT_TRUE(summary.ok()) << summary.error().message;
  EXPECT_EQ(summary->missing_sensor, 1u);  // the frame at 0.5 s: no image within 20 ms
  EXPECT_EQ(summary->frames, 19u);

  const auto table = [&](const std::string& name) { return json::parse(read_text(out / "v1.0-hanzo" / (name + ".json"))); };
  const json samples = table("sample"), data = table("sample_data"), ego = table("ego_pose"), calibrated = table("calibrated_sensor"),
             sensors = table("sensor"), scenes = table("scene");
  ASSERT_EQ(samples.size(), 19u);
  ASSERT_EQ(data.size(), 38u);
  ASSERT_EQ(scenes.size(), 1u);
  EXPECT_EQ(scenes[0]["nbr_samples"], 19);
  EXPECT_EQ(scenes[0]["first_sample_token"], samples.front()["token"]);
  std::map<std::string, json> by_token;
  for (const json* t : {&samples, &data, &ego, &calibrated, &sensors}) {
    for (const json& row : *t) by_token[row["token"].get<std::string>() + (t == &ego ? "/ego" : "")] = row;
  }
  EXPECT_EQ(table("sample_annotation"), json::array());
  int lidar_files = 0;
  for (const json& row : data) {
    ASSERT_TRUE(by_token.count(row["sample_token"].get<std::string>()));
    ASSERT_TRUE(by_token.count(row["ego_pose_token"].get<std::string>() + "/ego"));
    const json& calibration = by_token.at(row["calibrated_sensor_token"].get<std::string>());
    const json& sensor = by_token.at(calibration["sensor_token"].get<std::string>());
    if (!row["next"].get<std::string>().empty()) {
      EXPECT_EQ(by_token.at(row["next"].get<std::string>())["prev"], row["token"]);
    }
    ASSERT_TRUE(fs::exists(out / row["filename"].get<std::string>())) << row["filename"];
    if (sensor["modality"] != "lidar") {
      EXPECT_EQ(row["fileformat"], "jpg");
      EXPECT_EQ(calibration["camera_intrinsic"][0][0], 200.0);
      continue;
    }
    ++lidar_files;
    const json& pose = by_token.at(row["ego_pose_token"].get<std::string>() + "/ego");
    const auto se3 = [](const json& rotation, const json& translation) {
      return SE3(SO3::from_wxyz(Eigen::Vector4d(rotation[0], rotation[1], rotation[2], rotation[3])),
                 Eigen::Vector3d(translation[0], translation[1], translation[2]));
    };
    const SE3 T_world_lidar = se3(pose["rotation"], pose["translation"]) * se3(calibration["rotation"], calibration["translation"]);
    const std::vector<float> values = read_floats(out / row["filename"].get<std::string>());
    ASSERT_EQ(values.size(), scene.world_points.size() * 5);
    double worst = 0;
    for (std::size_t i = 0; i < scene.world_points.size(); ++i) {
      worst = std::max(worst, (T_world_lidar * Eigen::Vector3d(values[5 * i], values[5 * i + 1], values[5 * i + 2]) - scene.world_points[i]).norm());
      EXPECT_FLOAT_EQ(values[5 * i + 4], static_cast<float>(i % 16));
    }
    EXPECT_LT(worst, 2e-3);
  }
  EXPECT_EQ(lidar_files, 19);

  // Exporting again gives the same tables, token for token; --keep-incomplete keeps the frame.
  config.require_all_sensors = false;
  auto again = export_dataset(scene.log, scene.trajectory, scene.calibration, (scene.dir / "again").string(), config);
  ASSERT_TRUE(again.ok()) << again.error().message;
  EXPECT_EQ(again->frames, 20u);
  EXPECT_EQ(json::parse(read_text(scene.dir / "again" / "v1.0-hanzo" / "calibrated_sensor.json")), calibrated);
  fs::remove_all(scene.dir);
}

TEST(DatasetExport, BadInputIsRefusedBeforeWriting) {
  const Scene scene = make_scene("bad");
  const std::string out = (scene.dir / "out").string();
  DatasetExportConfig config = config_for(DatasetLayout::kKittiOdometry);

  calib::Calibration no_camera = scene.calibration;
  no_camera.sensors.pop_back();
  auto refused = export_dataset(scene.log, scene.trajectory, no_camera, out, config);
  ASSERT_FALSE(refused.ok());
  EXPECT_NE(refused.error().message.find("camera_front_to_body"), std::string::npos) << refused.error().message;
  EXPECT_FALSE(fs::exists(out));

  config.reference_sensor = "radar";
  refused = export_dataset(scene.log, scene.trajectory, scene.calibration, out, config);
  ASSERT_FALSE(refused.ok());
  EXPECT_NE(refused.error().message.find("radar"), std::string::npos);
  config.reference_sensor.clear();

  Trajectory later = scene.trajectory;
  for (Timestamp& time : later.timestamps) time = time + Duration::from_seconds(100.0);
  refused = export_dataset(scene.log, later, scene.calibration, out, config);
  ASSERT_FALSE(refused.ok());
  EXPECT_NE(refused.error().message.find("outside the trajectory"), std::string::npos) << refused.error().message;
  EXPECT_FALSE(fs::exists(out));

  config.sensors[1].topic = "/lidar";  // a topic given twice
  EXPECT_FALSE(export_dataset(scene.log, scene.trajectory, scene.calibration, out, config).ok());
  config.sensors[1] = {"camera_front", "/lidar_wrong", true};
  config.sensors[0] = {"lidar", "/camera", false};  // images where a LiDAR is expected
  refused = export_dataset(scene.log, scene.trajectory, scene.calibration, out, config);
  ASSERT_FALSE(refused.ok());
  EXPECT_NE(refused.error().message.find("not point clouds"), std::string::npos) << refused.error().message;

  // An existing, non-empty folder is left as it was.
  fs::create_directories(out);
  std::ofstream(out + "/keep.txt") << "mine";
  refused = export_dataset(scene.log, scene.trajectory, scene.calibration, out, config_for(DatasetLayout::kKittiOdometry));
  ASSERT_FALSE(refused.ok());
  EXPECT_NE(refused.error().message.find("not empty"), std::string::npos);
  EXPECT_EQ(read_text(out + "/keep.txt"), "mine");
  EXPECT_EQ(std::distance(fs::directory_iterator(out), fs::directory_iterator()), 1);
  fs::remove_all(scene.dir);
}

}  // namespace
}  // namespace hanzo::fusion::io
