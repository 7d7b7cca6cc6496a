// The ROS 2 bag importer against bags written by Foxglove's libraries (tests/conformance/
// rosbag2_write.mjs: CDR by @foxglove/rosmsg2-serialization, MCAP by @mcap/core, SQLite by
// sql.js): every value written comes back, in both storages, plain and zstd-compressed (per
// message and per file), and broken bags are refused naming what is wrong.

#include <sqlite3.h>
#include <unistd.h>
#include <zstd.h>

#include <filesystem>
#include <fstream>
#include <map>
#include <sstream>

#include <fmt/format.h>
#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "hanzo/fusion/io/ros2_bag.hpp"
#include "hanzo/fusion/io/rosbag_import.hpp"
#include "hanzo/fusion/msgs/validate.hpp"
#include "node_runner.hpp"

namespace hanzo::fusion::io {
namespace {

namespace fs = std::filesystem;
using ::testing::HasSubstr;

constexpr double kWheelSeparation = 0.5;

fs::path temp_path(const std::string& name) { return fs::temp_directory_path() / fmt::format("hanzo_rosbag2_{}_{}", name, ::getpid()); }

std::string read_file(const fs::path& path) {
  std::ifstream in(path, std::ios::binary);
  std::stringstream buffer;
  buffer << in.rdbuf();
  return buffer.str();
}

void write_file(const fs::path& path, const std::string& data) {
  std::ofstream out(path, std::ios::binary);
  out << data;
}

std::string zstd_compress(const std::string& data) {
  std::string out(ZSTD_compressBound(data.size()), '\0');
  out.resize(ZSTD_compress(out.data(), out.size(), data.data(), data.size(), 3));
  return out;
}

// Writes a bag with node (rosbag2_write.mjs or another writer); returns what was written.
nlohmann::json write_bag(const fs::path& dir, const std::string& storage, const std::string& script = "rosbag2_write.mjs") {
  fs::remove_all(dir);
  return test::run_node(script, dir.string() + " " + storage);
}

struct Imported {
  RosbagImportReport report;
  std::map<std::string, std::vector<msgs::SensorMessage>> by_topic;  // log topic -> messages
};

Result<Imported> import(const std::string& bag, RosbagImportConfig config = {}) {
  const fs::path log = temp_path("import.mcap");
  Imported imported;
  {
    auto writer = SensorLogWriter::open(log.string());
    if (!writer) return writer.error();
    if (!config.wheel_separation) config.wheel_separation = kWheelSeparation;
    auto report = import_rosbag2(bag, **writer, config);
    if (!report) return report.error();
    imported.report = *report;
    if (Status closed = (*writer)->close(); !closed) return closed.error();
  }
  auto reader = SensorLogReader::open(log.string());
  if (!reader) return reader.error();
  LogEntry entry;
  while (*(*reader)->next(entry)) imported.by_topic[entry.topic].push_back(std::get<msgs::SensorMessage>(entry.message));
  fs::remove(log);
  return imported;
}

template <typename Message>
std::vector<Message> messages_of(const Imported& imported, const std::string& topic) {
  std::vector<Message> out;
  const auto it = imported.by_topic.find(topic);
  if (it == imported.by_topic.end()) return out;
  for (const auto& m : it->second) out.push_back(std::get<Message>(m));
  return out;
}

int64_t ns(const nlohmann::json& text) { return std::stoll(text.get<std::string>()); }

// Every value rosbag2_write.mjs wrote, as the importer must have turned it into messages.
void expect_matches(const Imported& imported, const nlohmann::json& written) {
  const auto& topics = written["topics"];
  const RosbagImportReport& report = imported.report;
  EXPECT_EQ(report.messages, written["messages"].get<uint64_t>());
  EXPECT_EQ(report.skipped_topics.at("/chatter"), "std_msgs/msg/String");
  EXPECT_EQ(report.calibration_topics.at("/tf_static"), 1u);
  EXPECT_EQ(report.calibration_topics.at("/camera/camera_info"), 1u);
  for (const TopicImportReport& topic : report.topics) EXPECT_EQ(topic.rejected, 0u) << topic.ros_topic << ": " << topic.first_rejection;

  const auto imu = messages_of<msgs::ImuMessage>(imported, "/imu");
  const auto& imu_ref = topics["/imu/data"]["messages"];
  ASSERT_EQ(imu.size(), imu_ref.size());
  for (std::size_t i = 0; i < imu.size(); ++i) {
    EXPECT_EQ(imu[i].timestamp.nanoseconds(), ns(imu_ref[i]["stamp"])) << i;  // header stamps, not record times
    EXPECT_EQ(imu[i].frame_id, "imu_link");
    for (int k = 0; k < 3; ++k) {
      EXPECT_EQ(imu[i].angular_velocity[k], imu_ref[i]["angular_velocity"][k].get<double>()) << i;
      EXPECT_EQ(imu[i].linear_acceleration[k], imu_ref[i]["linear_acceleration"][k].get<double>()) << i;
    }
    ASSERT_TRUE(imu[i].orientation.has_value());
    EXPECT_DOUBLE_EQ(imu[i].orientation->z(), imu_ref[i]["orientation_z"].get<double>());
    ASSERT_TRUE(imu[i].gyroscope_covariance.has_value());
    EXPECT_EQ((*imu[i].gyroscope_covariance)(1, 1), 1e-4);
    EXPECT_FALSE(imu[i].acceleration_covariance.has_value());  // all zero: unknown
  }

  const auto fixes = messages_of<msgs::GnssMessage>(imported, "/gps");
  const auto& fix_ref = topics["/gps/fix"]["messages"];
  ASSERT_EQ(fixes.size(), fix_ref.size());
  for (std::size_t i = 0; i < fixes.size(); ++i) {
    EXPECT_EQ(fixes[i].timestamp.nanoseconds(), ns(fix_ref[i]["stamp"]));
    EXPECT_EQ(fixes[i].latitude, fix_ref[i]["lla"][0].get<double>());
    EXPECT_EQ(fixes[i].longitude, fix_ref[i]["lla"][1].get<double>());
    EXPECT_EQ(fixes[i].altitude, fix_ref[i]["lla"][2].get<double>());
    EXPECT_EQ(fixes[i].fix_type, fix_ref[i]["fix"].get<bool>() ? msgs::GnssFixType::kFix3d : msgs::GnssFixType::kNoFix);
    ASSERT_TRUE(fixes[i].position_covariance.has_value());
    EXPECT_EQ((*fixes[i].position_covariance)(2, 2), 1.0);
  }

  // Each driver's layout: points, rings and per-point times (relative or absolute, s or ns).
  for (const auto& [ros_topic, log_topic] : std::map<std::string, std::string>{
           {"/velodyne_points", "/velodyne_points"}, {"/ouster/points", "/ouster"}, {"/livox/lidar", "/lidar"}, {"/hesai/pandar", "/pandar"}}) {
    SCOPED_TRACE(ros_topic);
    const auto clouds = messages_of<msgs::PointCloudMessage>(imported, log_topic);
    const auto& cloud_ref = topics[ros_topic]["messages"];
    ASSERT_EQ(clouds.size(), cloud_ref.size());
    for (std::size_t c = 0; c < clouds.size(); ++c) {
      EXPECT_EQ(clouds[c].timestamp.nanoseconds(), ns(cloud_ref[c]["stamp"]));
      const auto& points = cloud_ref[c]["points"];
      ASSERT_EQ(clouds[c].points.size(), points.size());
      ASSERT_EQ(clouds[c].point_timestamps.size(), points.size());
      ASSERT_EQ(clouds[c].ring_ids.size(), points.size());
      ASSERT_EQ(clouds[c].intensities.size(), points.size());
      for (std::size_t k = 0; k < points.size(); ++k) {
        for (int a = 0; a < 3; ++a) EXPECT_EQ(clouds[c].points[k][a], points[k]["xyz"][a].get<float>()) << k;
        EXPECT_EQ(clouds[c].point_timestamps[k].nanoseconds(), ns(points[k]["time"])) << k;
        EXPECT_EQ(clouds[c].ring_ids[k], points[k]["ring"].get<uint32_t>()) << k;
      }
    }
  }

  const auto images = messages_of<msgs::ImageMessage>(imported, "/camera");
  const auto& image_ref = topics["/camera/image_raw"]["messages"];
  ASSERT_EQ(images.size(), image_ref.size());
  for (std::size_t i = 0; i < images.size(); ++i) {
    EXPECT_EQ(images[i].timestamp.nanoseconds(), ns(image_ref[i]["stamp"]));
    EXPECT_EQ(images[i].encoding, msgs::ImageEncoding::kMono8);
    EXPECT_EQ(images[i].data, image_ref[i]["pixels"].get<std::vector<uint8_t>>());  // row padding removed
  }
  const auto compressed = messages_of<msgs::ImageMessage>(imported, "/camera_image_raw_compressed");
  const auto& compressed_ref = topics["/camera/image_raw/compressed"]["messages"];
  ASSERT_EQ(compressed.size(), compressed_ref.size());
  for (std::size_t i = 0; i < compressed.size(); ++i) {
    EXPECT_EQ(compressed[i].timestamp.nanoseconds(), ns(compressed_ref[i]["stamp"]));
    ASSERT_EQ(compressed[i].encoding, msgs::ImageEncoding::kBgr8);
    const auto rgb = compressed_ref[i]["rgb"].get<std::vector<uint8_t>>();
    ASSERT_EQ(compressed[i].data.size(), rgb.size());
    for (std::size_t p = 0; p < rgb.size(); p += 3) {  // PNG is lossless: exact, in BGR order
      ASSERT_EQ(compressed[i].data[p], rgb[p + 2]);
      ASSERT_EQ(compressed[i].data[p + 1], rgb[p + 1]);
      ASSERT_EQ(compressed[i].data[p + 2], rgb[p]);
    }
  }

  // Odometry and TwistStamped: trapezoid integrals of the twists written.
  for (const auto& [ros_topic, log_topic] : std::map<std::string, std::string>{{"/odom", "/odom"}, {"/wheel/twist", "/wheel"}}) {
    SCOPED_TRACE(ros_topic);
    const auto wheels = messages_of<msgs::WheelOdometryMessage>(imported, log_topic);
    const auto& ref = topics[ros_topic]["messages"];
    ASSERT_EQ(wheels.size(), ref.size());
    double left = 0.0, right = 0.0;
    for (std::size_t i = 0; i < wheels.size(); ++i) {
      EXPECT_EQ(wheels[i].timestamp.nanoseconds(), ns(ref[i]["stamp"]));
      if (i > 0) {
        const double dt = static_cast<double>(ns(ref[i]["stamp"]) - ns(ref[i - 1]["stamp"])) * 1e-9;
        const double half = kWheelSeparation / 2.0;
        const double v0 = ref[i - 1]["v"], w0 = ref[i - 1]["w"], v1 = ref[i]["v"], w1 = ref[i]["w"];
        left += 0.5 * ((v0 - w0 * half) + (v1 - w1 * half)) * dt;
        right += 0.5 * ((v0 + w0 * half) + (v1 + w1 * half)) * dt;
      }
      EXPECT_NEAR(wheels[i].left_distance, left, 1e-12);
      EXPECT_NEAR(wheels[i].right_distance, right, 1e-12);
    }
  }

  // Calibration: /tf_static composed into T_body_sensor, the camera's CameraInfo intrinsics.
  EXPECT_EQ(report.body_frame, "base_link");
  const calib::Calibration& calibration = report.calibration;
  std::map<std::string, SE3> T_base_frame;
  for (const auto& t : topics["/tf_static"]["messages"][0]["transforms"]) {
    const auto& q = t["rotation_wxyz"];
    const SE3 T_parent_child(SO3::from_quaternion_normalized(Eigen::Quaterniond(q[0], q[1], q[2], q[3])),
                             Eigen::Vector3d(t["translation"][0], t["translation"][1], t["translation"][2]));
    const std::string parent = t["parent"];
    T_base_frame[t["child"]] = (parent == "base_link" ? SE3() : T_base_frame.at(parent)) * T_parent_child;
  }
  for (const auto& [sensor, frame] : std::map<std::string, std::string>{{"imu", "imu_link"},
                                                                         {"velodyne_points", "velodyne"},
                                                                         {"ouster", "os_sensor"},
                                                                         {"lidar", "livox_frame"},
                                                                         {"gps", "gps"},
                                                                         {"camera", "camera_optical_frame"}}) {
    const calib::SensorCalibration* entry = calibration.find(sensor);
    ASSERT_NE(entry, nullptr) << sensor;
    const SE3 error = entry->T_body_sensor().inverse() * T_base_frame.at(frame);
    EXPECT_LT(error.translation().norm(), 1e-12) << sensor;
    EXPECT_LT(error.rotation().log().norm(), 1e-9) << sensor;
  }
  EXPECT_EQ(calibration.find("pandar"), nullptr);  // hesai_lidar is in no transform: left out, said so
  ASSERT_FALSE(report.calibration_notes.empty());
  EXPECT_THAT(report.calibration_notes[0], HasSubstr("hesai_lidar"));
  const calib::SensorCalibration* camera = calibration.find("camera");
  ASSERT_TRUE(camera && camera->camera);
  EXPECT_EQ(camera->camera->intrinsics.fx, 30.5);
  EXPECT_EQ(camera->camera->intrinsics.cy, 12.1);
  EXPECT_EQ(camera->camera->intrinsics.width, 32u);
  EXPECT_EQ(camera->camera->distortion.type, msgs::DistortionType::kRadtan);
  EXPECT_EQ(camera->camera->distortion.coefficients, (std::vector<double>{-0.28, 0.07, 0.0002, -0.0001, 0.0}));
  EXPECT_TRUE(calib::validate(calibration).ok());
}

class Rosbag2Conformance : public ::testing::TestWithParam<std::string> {};

TEST_P(Rosbag2Conformance, EveryValueWrittenComesBack) {
  const fs::path dir = temp_path(GetParam());
  const nlohmann::json written = write_bag(dir, GetParam());
  ASSERT_FALSE(written.is_null());
  {
    SCOPED_TRACE("bag folder");
    auto imported = import(dir.string());
    ASSERT_TRUE(imported.ok()) << imported.error().message;
    EXPECT_EQ(imported->report.storage, GetParam());
    expect_matches(*imported, written);
  }
  {
    SCOPED_TRACE("storage file alone");
    auto imported = import((dir / written["file"].get<std::string>()).string());
    ASSERT_TRUE(imported.ok()) << imported.error().message;
    expect_matches(*imported, written);
  }
  {
    SCOPED_TRACE("folder without metadata.yaml (a cut-off recording)");
    fs::remove(dir / "metadata.yaml");
    auto imported = import(dir.string());
    ASSERT_TRUE(imported.ok()) << imported.error().message;
    expect_matches(*imported, written);
  }
  fs::remove_all(dir);
}

INSTANTIATE_TEST_SUITE_P(Storages, Rosbag2Conformance, ::testing::Values("mcap", "sqlite3"));

// A ROS 2 vision pipeline's output (rosbag2_vision_write.mjs): Detection2DArray boxes and a
// half-resolution label image on separate topics become one DetectionsMessage per camera image
// on the camera's detections topic, class ids named by the LabelInfo, the rear camera's
// detector found by its frame, a box wholly outside the image refused.
class Rosbag2Vision : public ::testing::TestWithParam<std::string> {};

TEST_P(Rosbag2Vision, DetectionsAndLabelImagesBecomeEachImagesDetections) {
  const fs::path dir = temp_path("vision_" + GetParam());
  const nlohmann::json written = write_bag(dir, GetParam(), "rosbag2_vision_write.mjs");
  ASSERT_FALSE(written.is_null());
  auto imported = import(dir.string());
  ASSERT_TRUE(imported.ok()) << imported.error().message;
  const RosbagImportReport& report = imported->report;
  EXPECT_EQ(report.calibration_topics.at("/camera/label_info"), 1u);
  EXPECT_EQ(report.skipped_topics.at("/chatter"), "std_msgs/msg/String");
  std::map<std::string, TopicImportReport> topics;
  for (const TopicImportReport& topic : report.topics) topics[topic.ros_topic] = topic;
  EXPECT_EQ(topics.at("/camera/detections").topic, "/camera/detections");
  EXPECT_EQ(topics.at("/camera/detections").imported, 4u);
  EXPECT_EQ(topics.at("/camera/segmentation").topic, "/camera/detections");
  EXPECT_EQ(topics.at("/camera/segmentation").imported, 5u);
  EXPECT_EQ(topics.at("/yolo/detections").topic, "/rear/detections");
  EXPECT_EQ(topics.at("/yolo/detections").imported, 4u);
  EXPECT_EQ(topics.at("/yolo/detections").rejected, 1u);
  EXPECT_THAT(topics.at("/yolo/detections").first_rejection, HasSubstr("outside the 64 x 48 image"));
  for (const std::string topic : {"/camera/detections", "/camera/segmentation"}) EXPECT_EQ(topics.at(topic).rejected, 0u) << topic;
  for (const calib::SensorCalibration& sensor : report.calibration.sensors) EXPECT_THAT(sensor.sensor, ::testing::Not(HasSubstr("detections")));

  for (const auto& [topic, images] : written["expected"].items()) {
    SCOPED_TRACE(topic);
    const auto detections = messages_of<msgs::DetectionsMessage>(*imported, topic);
    ASSERT_EQ(detections.size(), images.size());
    for (std::size_t i = 0; i < detections.size(); ++i) {
      const msgs::DetectionsMessage& message = detections[i];
      const nlohmann::json& image = images[i];
      EXPECT_EQ(message.timestamp.nanoseconds(), ns(image["stamp"])) << i;
      EXPECT_EQ(message.image_width, 64u);
      EXPECT_EQ(message.image_height, 48u);
      ASSERT_EQ(message.detections.size(), image["boxes"].size()) << i;
      for (std::size_t k = 0; k < message.detections.size(); ++k) {
        const msgs::Detection2D& box = message.detections[k];
        const nlohmann::json& expected = image["boxes"][k];
        EXPECT_EQ(box.class_name, expected["class_name"].get<std::string>()) << i << " " << k;
        EXPECT_FLOAT_EQ(box.score, expected["score"].get<float>());
        EXPECT_NEAR(box.x_min, expected["box"][0].get<double>(), 1e-4) << i << " " << k;
        EXPECT_NEAR(box.y_min, expected["box"][1].get<double>(), 1e-4) << i << " " << k;
        EXPECT_NEAR(box.x_max, expected["box"][2].get<double>(), 1e-4) << i << " " << k;
        EXPECT_NEAR(box.y_max, expected["box"][3].get<double>(), 1e-4) << i << " " << k;
        EXPECT_EQ(box.track_id, expected["track_id"].get<int64_t>()) << i << " " << k;
      }
      if (!image.contains("segmentation")) {
        EXPECT_TRUE(message.segmentation.empty());
        continue;
      }
      EXPECT_EQ(message.segmentation_classes, image["classes"].get<std::vector<std::string>>());
      EXPECT_EQ(message.segmentation, image["segmentation"].get<std::vector<uint8_t>>()) << i;
      EXPECT_TRUE(msgs::validate(message).ok());
    }
  }
  {
    SCOPED_TRACE("a detector's topic mapped to a camera's detections");
    RosbagImportConfig config;
    config.topic_map = {{"/camera/image_raw", "/front"}, {"/yolo/detections", "/front/detections"}};
    auto mapped = import(dir.string(), config);
    ASSERT_TRUE(mapped.ok()) << mapped.error().message;
    EXPECT_EQ(messages_of<msgs::DetectionsMessage>(*mapped, "/front/detections").size(), 4u);
    config.topic_map["/yolo/detections"] = "/rear/detections";  // not imported: no camera /rear in the log
    auto refused = import(dir.string(), config);
    ASSERT_FALSE(refused.ok());
    EXPECT_THAT(refused.error().message, HasSubstr("topic '/yolo/detections' is a detector's output: map it to the detections of a camera"));
  }
  fs::remove_all(dir);
}

INSTANTIATE_TEST_SUITE_P(Storages, Rosbag2Vision, ::testing::Values("mcap", "sqlite3"));

// rosbag2's zstd compression: per message (the SQLite rows compressed) and per file.
TEST(Rosbag2Compression, MessageAndFileModesReadTheSameValues) {
  const fs::path dir = temp_path("zstd");
  const nlohmann::json written = write_bag(dir, "sqlite3");
  ASSERT_FALSE(written.is_null());
  const std::string file = written["file"];
  const std::string metadata = read_file(dir / "metadata.yaml");
  auto with_compression = [&](const std::string& mode, const std::string& stored_file) {
    std::string text = metadata;
    text.replace(text.find("compression_format: \"\""), 22, "compression_format: zstd");
    text.replace(text.find("compression_mode: \"\""), 20, "compression_mode: " + mode);
    for (std::size_t at; (at = text.find("- " + file + "\n")) != std::string::npos;) text.replace(at, file.size() + 3, "- " + stored_file + "\n");
    for (std::size_t at; (at = text.find("path: " + file + "\n")) != std::string::npos;) text.replace(at, file.size() + 7, "path: " + stored_file + "\n");
    write_file(dir / "metadata.yaml", text);
  };

  // MESSAGE: every row's data compressed in place.
  {
    const fs::path copy = dir / "message_mode.db3";
    fs::copy_file(dir / file, copy);
    sqlite3* db = nullptr;
    ASSERT_EQ(sqlite3_open(copy.c_str(), &db), SQLITE_OK);
    std::vector<std::pair<int64_t, std::string>> rows;
    sqlite3_stmt* select = nullptr;
    sqlite3_prepare_v2(db, "SELECT id, data FROM messages", -1, &select, nullptr);
    while (sqlite3_step(select) == SQLITE_ROW) {
      rows.emplace_back(sqlite3_column_int64(select, 0),
                        std::string(static_cast<const char*>(sqlite3_column_blob(select, 1)), sqlite3_column_bytes(select, 1)));
    }
    sqlite3_finalize(select);
    for (const auto& [id, data] : rows) {
      const std::string compressed = zstd_compress(data);
      sqlite3_stmt* update = nullptr;
      sqlite3_prepare_v2(db, "UPDATE messages SET data = ? WHERE id = ?", -1, &update, nullptr);
      sqlite3_bind_blob(update, 1, compressed.data(), static_cast<int>(compressed.size()), SQLITE_TRANSIENT);
      sqlite3_bind_int64(update, 2, id);
      ASSERT_EQ(sqlite3_step(update), SQLITE_DONE);
      sqlite3_finalize(update);
    }
    sqlite3_close(db);
    fs::remove(dir / file);
    with_compression("MESSAGE", copy.filename().string());
    SCOPED_TRACE("MESSAGE");
    auto imported = import(dir.string());
    ASSERT_TRUE(imported.ok()) << imported.error().message;
    expect_matches(*imported, written);
  }
  // FILE: the whole database compressed; the temporary decompressed copy is removed afterwards.
  {
    const std::string compressed_file = "file_mode.db3.zstd";
    fs::remove_all(dir / "plain");
    ASSERT_EQ(write_bag(dir / "plain", "sqlite3").is_null(), false);
    write_file(dir / compressed_file, zstd_compress(read_file(dir / "plain" / "plain_0.db3")));
    with_compression("FILE", compressed_file);
    const auto temporaries = [] {
      int count = 0;
      for (const auto& entry : fs::directory_iterator(fs::temp_directory_path())) {
        count += entry.path().filename().string().rfind(fmt::format("hanzo_rosbag2_{}_", ::getpid()), 0) == 0;
      }
      return count;
    };
    const int before = temporaries();
    SCOPED_TRACE("FILE");
    auto imported = import(dir.string());
    ASSERT_TRUE(imported.ok()) << imported.error().message;
    expect_matches(*imported, written);
    EXPECT_EQ(temporaries(), before);

    // A truncated compressed file is refused, naming it.
    const std::string whole = read_file(dir / compressed_file);
    write_file(dir / compressed_file, whole.substr(0, whole.size() / 2));
    auto truncated = import(dir.string());
    ASSERT_FALSE(truncated.ok());
    EXPECT_THAT(truncated.error().message, HasSubstr(compressed_file));
    EXPECT_THAT(truncated.error().message, HasSubstr("truncated"));
  }
  fs::remove_all(dir);
}

// Real data: robot_localization's test2.bag (Jackal IMU + wheel odometry, 61 s) converted to a
// ROS 2 bag by Foxglove's libraries (ros1_to_ros2.mjs) imports into exactly the log the ROS 1
// bag gives; the ROS 2 bag stores by arrival, in which 163 odometry stamps go back.
TEST(Rosbag2RealData, RobotLocalizationBagAsRos2ImportsLikeTheRos1Bag) {
  const std::string ros1_bag = std::string(HANZO_DATA_DIR) + "/robot_localization/test2.bag";
  const fs::path dir = temp_path("test2");
  fs::remove_all(dir);
  const nlohmann::json converted = test::run_node("ros1_to_ros2.mjs", ros1_bag + " " + dir.string() + " sqlite3");
  ASSERT_FALSE(converted.is_null());
  EXPECT_EQ(converted["topics"]["/imu/data"], 3061);
  RosbagImportConfig config;
  config.topic_map = {{"/imu/data", "/imu"}, {"/jackal_velocity_controller/odom", "/wheels"}};
  auto ros2 = import(dir.string(), config);
  ASSERT_TRUE(ros2.ok()) << ros2.error().message;

  const fs::path log = temp_path("test2_ros1.mcap");
  {
    auto writer = SensorLogWriter::open(log.string());
    ASSERT_TRUE(writer.ok());
    config.wheel_separation = kWheelSeparation;
    ASSERT_TRUE(import_rosbag(ros1_bag, **writer, config).ok());
    ASSERT_TRUE((*writer)->close().ok());
  }
  auto reader = SensorLogReader::open(log.string());
  ASSERT_TRUE(reader.ok());
  std::map<std::string, std::vector<msgs::SensorMessage>> ros1;
  LogEntry entry;
  while (*(*reader)->next(entry)) ros1[entry.topic].push_back(std::get<msgs::SensorMessage>(entry.message));
  for (const TopicImportReport& topic : ros2->report.topics) EXPECT_EQ(topic.rejected, 0u) << topic.first_rejection;
  ASSERT_EQ(ros2->by_topic.at("/imu").size(), 3061u);
  ASSERT_EQ(ros2->by_topic.at("/wheels").size(), 3060u);
  const auto imu1 = messages_of<msgs::ImuMessage>(*ros2, "/imu");
  const auto wheels2 = messages_of<msgs::WheelOdometryMessage>(*ros2, "/wheels");
  ASSERT_EQ(ros1.at("/imu").size(), imu1.size());
  ASSERT_EQ(ros1.at("/wheels").size(), wheels2.size());
  for (std::size_t i = 0; i < imu1.size(); ++i) {
    const auto& a = std::get<msgs::ImuMessage>(ros1.at("/imu")[i]);
    ASSERT_EQ(a.timestamp, imu1[i].timestamp) << i;
    ASSERT_EQ(a.frame_id, imu1[i].frame_id) << i;
    ASSERT_EQ(a.angular_velocity, imu1[i].angular_velocity) << i;
    ASSERT_EQ(a.linear_acceleration, imu1[i].linear_acceleration) << i;
    ASSERT_EQ(a.orientation->coeffs(), imu1[i].orientation->coeffs()) << i;
  }
  for (std::size_t i = 0; i < wheels2.size(); ++i) {
    const auto& a = std::get<msgs::WheelOdometryMessage>(ros1.at("/wheels")[i]);
    ASSERT_EQ(a.timestamp, wheels2[i].timestamp) << i;
    ASSERT_EQ(a.left_distance, wheels2[i].left_distance) << i;
    ASSERT_EQ(a.right_distance, wheels2[i].right_distance) << i;
  }
  fs::remove(log);
  fs::remove_all(dir);
}

TEST(Rosbag2Errors, BrokenBagsAreRefusedNamingTheProblem) {
  const fs::path dir = temp_path("errors");
  const nlohmann::json written = write_bag(dir, "sqlite3");
  ASSERT_FALSE(written.is_null());
  const std::string file = written["file"];
  const std::string metadata = read_file(dir / "metadata.yaml");
  auto error_of = [&](RosbagImportConfig config = {}) {
    auto imported = import(dir.string(), std::move(config));
    return imported.ok() ? std::string("(imported)") : imported.error().message;
  };
  auto mapping = [](const std::string& ros_topic) {
    RosbagImportConfig config;
    config.topic_map = {{ros_topic, "/x"}};
    return config;
  };

  EXPECT_THAT(error_of(mapping("/nope")), HasSubstr("the bag has no topic '/nope'"));
  EXPECT_THAT(error_of(mapping("/chatter")), HasSubstr("std_msgs/msg/String, which cannot be imported"));
  RosbagImportConfig no_separation;
  no_separation.wheel_separation = 0.0;
  no_separation.topic_map = {{"/odom", "/odom"}};
  EXPECT_THAT(error_of(no_separation), HasSubstr("--wheel-separation"));

  // A topic map imports only what it names, under its names; the calibration is still read.
  RosbagImportConfig mapped;
  mapped.topic_map = {{"/imu/data", "/sensors/imu"}};
  auto only_imu = import(dir.string(), mapped);
  ASSERT_TRUE(only_imu.ok()) << only_imu.error().message;
  ASSERT_EQ(only_imu->by_topic.size(), 1u);
  EXPECT_EQ(only_imu->by_topic.at("/sensors/imu").size(), 50u);
  ASSERT_NE(only_imu->report.calibration.find("sensors/imu"), nullptr);
  EXPECT_EQ(only_imu->report.calibration.find("sensors/imu")->translation, Eigen::Vector3d(0.1, 0, 0.2));

  write_file(dir / "metadata.yaml", metadata.substr(0, metadata.find("storage_identifier")) + "storage_identifier: leveldb\n");
  EXPECT_THAT(error_of(), HasSubstr("relative_file_paths lists no storage file"));
  std::string unknown_storage = metadata;
  unknown_storage.replace(unknown_storage.find("storage_identifier: sqlite3"), 27, "storage_identifier: leveldb");
  write_file(dir / "metadata.yaml", unknown_storage);
  EXPECT_THAT(error_of(), HasSubstr("storage_identifier 'leveldb' is not supported"));
  write_file(dir / "metadata.yaml", "rosbag2_bagfile_information: [unclosed");
  EXPECT_THAT(error_of(), HasSubstr("metadata.yaml"));
  write_file(dir / "metadata.yaml", metadata);

  // A storage file that is not SQLite, or SQLite without rosbag2's tables; nothing is half-imported.
  const std::string database = read_file(dir / file);
  write_file(dir / file, "not a database at all, just text that is long enough to be a file header....");
  EXPECT_THAT(error_of(), HasSubstr(file));
  sqlite3* db = nullptr;
  fs::remove(dir / file);
  ASSERT_EQ(sqlite3_open((dir / file).c_str(), &db), SQLITE_OK);
  sqlite3_exec(db, "CREATE TABLE topics(id INTEGER, name TEXT, type TEXT, serialization_format TEXT)", nullptr, nullptr, nullptr);
  sqlite3_close(db);
  EXPECT_THAT(error_of(), HasSubstr("not a rosbag2 SQLite database (no table 'messages')"));
  fs::remove(dir / file);
  EXPECT_THAT(error_of(), HasSubstr("storage file " + file + " does not exist"));
  write_file(dir / file, database);

  // Damaged messages are counted per topic and left out; the rest imports.
  ASSERT_EQ(sqlite3_open((dir / file).c_str(), &db), SQLITE_OK);
  sqlite3_exec(db, "UPDATE messages SET data = substr(data, 1, 20) WHERE topic_id = (SELECT id FROM topics WHERE name = '/imu/data') "
                   "AND id % 5 = 0", nullptr, nullptr, nullptr);
  const int damaged = sqlite3_changes(db);
  sqlite3_close(db);
  ASSERT_GT(damaged, 0);
  auto partly = import(dir.string());
  ASSERT_TRUE(partly.ok()) << partly.error().message;
  for (const TopicImportReport& topic : partly->report.topics) {
    if (topic.ros_topic != "/imu/data") continue;
    EXPECT_EQ(topic.rejected, static_cast<uint64_t>(damaged));
    EXPECT_EQ(topic.imported, 50u - static_cast<uint64_t>(damaged));
    EXPECT_THAT(topic.first_rejection, HasSubstr("sensor_msgs/Imu: truncated"));
  }
  EXPECT_THAT(import(temp_path("missing").string()).error().message, HasSubstr("no such file or folder"));
  fs::remove_all(dir);
}

}  // namespace
}  // namespace hanzo::fusion::io
