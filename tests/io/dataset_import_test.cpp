// The dataset importers (KITTI odometry, EuRoC/ASL, TUM RGB-D) on small folders laid out
// exactly like the published data sets: what lands in the log, the ground truth and the
// calibration, and the errors for malformed folders.

#include <cstring>
#include <filesystem>
#include <fstream>

#include <unistd.h>

#include <fmt/format.h>
#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <opencv2/imgcodecs.hpp>

#include "hanzo/fusion/io/euroc_import.hpp"
#include "hanzo/fusion/io/image_folder_import.hpp"
#include "hanzo/fusion/io/kitti_import.hpp"
#include "hanzo/fusion/io/tum_rgbd_import.hpp"

namespace hanzo::fusion::io {
namespace {

namespace fs = std::filesystem;
using ::testing::HasSubstr;

fs::path temp_dir(const std::string& name) {
  const fs::path dir = fs::temp_directory_path() / fmt::format("hanzo_dataset_{}_{}", ::getpid(), name);
  fs::remove_all(dir);
  fs::create_directories(dir);
  return dir;
}

void write_text(const fs::path& path, const std::string& text) {
  fs::create_directories(path.parent_path());
  std::ofstream(path) << text;
}

// Images at the data sets' real sizes (the principal points must lie inside them).
void write_gray(const fs::path& path, uint8_t value, int width, int height) {
  fs::create_directories(path.parent_path());
  ASSERT_TRUE(cv::imwrite(path.string(), cv::Mat(height, width, CV_8UC1, cv::Scalar(value))));
}

template <typename T>
Status status_of(const Result<T>& result) {
  if (!result) return result.error();
  return ok_status();
}

// Runs `import` into a fresh log and reads every hanzo.fusion.v1 message back.
template <typename Import>
Result<std::vector<LogEntry>> import_and_read(const fs::path& dir, Import import) {
  const std::string log = (dir / "out.mcap").string();
  {
    std::unique_ptr<SensorLogWriter> writer;
    HANZO_ASSIGN_OR_RETURN(writer, SensorLogWriter::open(log));
    HANZO_RETURN_IF_ERROR(import(*writer));
    HANZO_RETURN_IF_ERROR(writer->close());
  }
  std::unique_ptr<SensorLogReader> reader;
  HANZO_ASSIGN_OR_RETURN(reader, SensorLogReader::open(log));
  std::vector<LogEntry> entries;
  LogEntry entry;
  for (;;) {
    bool more = false;
    HANZO_ASSIGN_OR_RETURN(more, reader->next(entry));
    if (!more) return entries;
    entries.push_back(entry);
  }
}

// ---- KITTI ------------------------------------------------------------------------------

// Sequence 00's calibration.
constexpr const char* kKittiCalib =
    "P0: 7.188560000000e+02 0.000000000000e+00 6.071928000000e+02 0.000000000000e+00 0.000000000000e+00 "
    "7.188560000000e+02 1.852157000000e+02 0.000000000000e+00 0.000000000000e+00 0.000000000000e+00 "
    "1.000000000000e+00 0.000000000000e+00\n"
    "P1: 7.188560000000e+02 0.000000000000e+00 6.071928000000e+02 -3.861448000000e+02 0.000000000000e+00 "
    "7.188560000000e+02 1.852157000000e+02 0.000000000000e+00 0.000000000000e+00 0.000000000000e+00 "
    "1.000000000000e+00 0.000000000000e+00\n"
    "Tr: 4.276802385584e-04 -9.999672484946e-01 -8.084491683471e-03 -1.198459927713e-02 -7.210626507497e-03 "
    "8.081198471645e-03 -9.999413164504e-01 -5.403984729748e-02 9.999738645903e-01 4.859485810390e-04 "
    "-7.206933692422e-03 -2.921968648686e-01\n";

void write_bin(const fs::path& path, const std::vector<std::array<float, 4>>& points) {
  fs::create_directories(path.parent_path());
  std::ofstream out(path, std::ios::binary);
  for (const auto& point : points) out.write(reinterpret_cast<const char*>(point.data()), 16);
}

// sequences/07 with 3 frames (LiDAR, both gray cameras) and poses/07.txt: the camera drives
// i metres straight ahead (its z axis) by frame i.
fs::path make_kitti(const std::string& name) {
  const fs::path root = temp_dir(name);
  const fs::path sequence = root / "sequences" / "07";
  write_text(sequence / "times.txt", "0.000000e+00\n1.036240e-01\n2.072480e-01\n");
  write_text(sequence / "calib.txt", kKittiCalib);
  std::string poses;
  for (int i = 0; i < 3; ++i) {
    write_bin(sequence / "velodyne" / fmt::format("{:06d}.bin", i), {{10.0F + i, 1.0F, -1.5F, 0.25F}, {-3.0F, 4.0F, 0.5F, 0.0F}});
    write_gray(sequence / "image_0" / fmt::format("{:06d}.png", i), static_cast<uint8_t>(10 * i), 1241, 376);
    write_gray(sequence / "image_1" / fmt::format("{:06d}.png", i), static_cast<uint8_t>(10 * i + 1), 1241, 376);
    poses += fmt::format("1 0 0 0 0 1 0 0 0 0 1 {}\n", i);
  }
  write_text(root / "poses" / "07.txt", poses);
  return sequence;
}

TEST(KittiImport, FramesGroundTruthInTheLidarFrameAndCalibration) {
  const fs::path sequence = make_kitti("ok");
  KittiImportReport report;
  auto entries = import_and_read(sequence.parent_path().parent_path(), [&](SensorLogWriter& writer) -> Status {
    HANZO_ASSIGN_OR_RETURN(report, import_kitti(sequence.string(), writer, {}));
    return ok_status();
  });
  ASSERT_TRUE(entries.ok()) << entries.error().message;
  EXPECT_EQ(report.frames, 3u);
  EXPECT_EQ(report.scans, 3u);
  EXPECT_EQ(report.images, 6u);
  EXPECT_EQ(report.points, 6u);
  ASSERT_EQ(entries->size(), 9u);
  // Frame 1: LiDAR then both cameras, at time_origin + 0.103624 s exactly.
  const Timestamp t1 = Timestamp::from_nanoseconds(1'000'000'000'103'624'000);
  EXPECT_EQ((*entries)[3].topic, "/lidar");
  EXPECT_EQ((*entries)[3].log_time, t1);
  const auto& cloud = std::get<msgs::PointCloudMessage>(std::get<msgs::SensorMessage>((*entries)[3].message));
  EXPECT_EQ(cloud.points[0], Eigen::Vector3f(11.0F, 1.0F, -1.5F));
  EXPECT_EQ(cloud.intensities, (std::vector<float>{0.25F, 0.0F}));
  EXPECT_EQ((*entries)[5].topic, "/cam1");
  const auto& image = std::get<msgs::ImageMessage>(std::get<msgs::SensorMessage>((*entries)[5].message));
  EXPECT_EQ(image.encoding, msgs::ImageEncoding::kMono8);
  EXPECT_EQ(image.data[0], 11);
  EXPECT_DOUBLE_EQ(image.intrinsics->fx, 718.856);
  EXPECT_DOUBLE_EQ(image.intrinsics->cx, 607.1928);
  EXPECT_EQ(image.intrinsics->width, 1241u);

  // Driving 2 m along the camera's optical axis is driving 2 m forward (x) in the LiDAR frame.
  ASSERT_EQ(report.ground_truth.size(), 3u);
  EXPECT_EQ(report.ground_truth.timestamps[1], t1);
  const Eigen::Vector3d p2 = report.ground_truth.position(2);
  EXPECT_NEAR(p2.x(), 2.0, 1e-3);
  EXPECT_NEAR(p2.y(), 0.0, 2e-3);
  EXPECT_NEAR(p2.z(), 0.0, 2e-2);
  EXPECT_TRUE(report.ground_truth.poses[0].isIdentity(1e-9));

  // Calibration: the right camera sits the 0.537 m stereo baseline to the right (-y) of the left.
  ASSERT_EQ(report.calibration.sensors.size(), 3u);
  const SE3 left = report.calibration.find("cam0")->T_body_sensor();
  const SE3 right = report.calibration.find("cam1")->T_body_sensor();
  EXPECT_NEAR((right.translation() - left.translation()).norm(), 386.1448 / 718.856, 1e-6);
  EXPECT_NEAR(right.translation().y() - left.translation().y(), -386.1448 / 718.856, 1e-3);
  EXPECT_NEAR(left.translation().x(), 0.29, 0.01);  // sequence 00: cam0 is 0.29 m ahead of the Velodyne
  EXPECT_EQ(report.calibration.find("cam0")->camera->intrinsics.width, 1241u);
  EXPECT_TRUE(calib::validate(report.calibration).ok());
  fs::remove_all(sequence.parent_path().parent_path());
}

TEST(KittiImport, MalformedSequencesAreRejectedByName) {
  const fs::path sequence = make_kitti("bad");
  const fs::path root = sequence.parent_path().parent_path();
  auto run = [&](const KittiImportConfig& config = {}) {
    return import_and_read(root, [&](SensorLogWriter& writer) { return status_of(import_kitti(sequence.string(), writer, config)); });
  };
  {  // a .bin that is not whole points
    std::ofstream(sequence / "velodyne" / "000001.bin", std::ios::binary | std::ios::app) << 'x';
    auto result = run();
    ASSERT_FALSE(result.ok());
    EXPECT_THAT(result.error().message, HasSubstr("000001.bin: 33 bytes is not a whole number of points"));
  }
  {  // a frame too many
    write_bin(sequence / "velodyne" / "000001.bin", {{1, 2, 3, 0.5F}});
    write_bin(sequence / "velodyne" / "000003.bin", {{1, 2, 3, 0.5F}});
    auto result = run();
    ASSERT_FALSE(result.ok());
    EXPECT_THAT(result.error().message, HasSubstr("velodyne: 4 files for 3 frames in times.txt"));
    fs::remove(sequence / "velodyne" / "000003.bin");
  }
  {  // a poses file with a line too few
    write_text(root / "poses" / "07.txt", "1 0 0 0 0 1 0 0 0 0 1 0\n");
    auto result = run();
    ASSERT_FALSE(result.ok());
    EXPECT_THAT(result.error().message, HasSubstr("07.txt"));
  }
  {  // no calibration
    fs::remove(sequence / "calib.txt");
    auto result = run();
    ASSERT_FALSE(result.ok());
    EXPECT_THAT(result.error().message, HasSubstr("calib.txt: cannot open file"));
  }
  fs::remove_all(root);
}

// ---- EuRoC ------------------------------------------------------------------------------

constexpr const char* kEurocCamYaml = R"(# General sensor definitions.
sensor_type: camera
comment: VI-Sensor cam0 (MT9M034)

# Sensor extrinsics wrt. the body-frame.
T_BS:
  cols: 4
  rows: 4
  data: [0.0148655429818, -0.999880929698, 0.00414029679422, -0.0216401454975,
         0.999557249008, 0.0149672133247, 0.025715529948, -0.064676986768,
        -0.0257744366974, 0.00375618835797, 0.999660727178, 0.00981073058949,
         0.0, 0.0, 0.0, 1.0]

# Camera specific definitions.
rate_hz: 20
resolution: [752, 480]
camera_model: pinhole
intrinsics: [458.654, 457.296, 367.215, 248.375] #fu, fv, cu, cv
distortion_model: radial-tangential
distortion_coefficients: [-0.28340811, 0.07395907, 0.00019359, 1.76187114e-05]
)";

constexpr const char* kEurocImuYaml = R"(sensor_type: imu
comment: VI-Sensor IMU (ADIS16448)
T_BS:
  cols: 4
  rows: 4
  data: [1.0, 0.0, 0.0, 0.0,
         0.0, 1.0, 0.0, 0.0,
         0.0, 0.0, 1.0, 0.0,
         0.0, 0.0, 0.0, 1.0]
rate_hz: 200
gyroscope_noise_density: 1.6968e-04
gyroscope_random_walk: 1.9393e-05
accelerometer_noise_density: 2.0000e-3
accelerometer_random_walk: 3.0000e-3
)";

fs::path make_euroc(const std::string& name) {
  const fs::path root = temp_dir(name);
  const fs::path mav = root / "MH_01_easy" / "mav0";
  write_text(mav / "imu0" / "sensor.yaml", kEurocImuYaml);
  write_text(mav / "imu0" / "data.csv",
             "#timestamp [ns],w_RS_S_x [rad s^-1],w_RS_S_y [rad s^-1],w_RS_S_z [rad s^-1],a_RS_S_x [m s^-2],a_RS_S_y [m s^-2],"
             "a_RS_S_z [m s^-2]\r\n"
             "1403636579758555392,-0.099134701513277898,0.14730578886832138,0.02722713633111154,8.1476917083333333,"
             "-0.37592158333333331,-2.4026292499999999\r\n"
             "1403636579763555584,-0.099134701513277898,0.14032447186034408,0.029321531433504733,8.033280791666666,"
             "-0.40861041666666664,-2.4026292499999999\r\n"
             "1403636579763555584,0,0,0,0,0,9.81\r\n"
             "1403636579768555520,-0.098436569812480182,0.12775810124598494,0.037699111843077518,7.8861810416666662,"
             "-0.42495483333333334,-2.4271461249999998\r\n");
  write_text(mav / "cam0" / "sensor.yaml", kEurocCamYaml);
  write_text(mav / "cam0" / "data.csv",
             "#timestamp [ns],filename\n1403636579763555584,1403636579763555584.png\n1403636579813555456,1403636579813555456.png\n");
  write_gray(mav / "cam0" / "data" / "1403636579763555584.png", 100, 752, 480);
  write_gray(mav / "cam0" / "data" / "1403636579813555456.png", 101, 752, 480);
  write_text(mav / "state_groundtruth_estimate0" / "data.csv",
             "#timestamp, p_RS_R_x [m], p_RS_R_y [m], p_RS_R_z [m], q_RS_w [], q_RS_x [], q_RS_y [], q_RS_z [], v_RS_R_x [m s^-1], "
             "v_RS_R_y [m s^-1], v_RS_R_z [m s^-1], b_w_RS_S_x [rad s^-1], b_w_RS_S_y [rad s^-1], b_w_RS_S_z [rad s^-1], "
             "b_a_RS_S_x [m s^-2], b_a_RS_S_y [m s^-2], b_a_RS_S_z [m s^-2]\n"
             "1403636580838555648,4.688319,-1.786938,0.783338,0.534108,-0.153029,-0.827383,-0.082152,-0.027876,0.033207,0.800006,"
             "-0.003172,0.021267,0.078502,-0.025266,0.136696,0.075593\n"
             "1403636580843555328,4.688177,-1.786770,0.787350,0.534640,-0.152990,-0.826976,-0.082863,-0.029272,0.033992,0.804771,"
             "-0.003172,0.021267,0.078502,-0.025266,0.136696,0.075593\n");
  return root / "MH_01_easy";
}

TEST(EurocImport, ImuAndImagesInTimeOrderWithCalibrationAndGroundTruth) {
  const fs::path dir = make_euroc("ok");
  EurocImportReport report;
  auto entries = import_and_read(dir.parent_path(), [&](SensorLogWriter& writer) -> Status {
    HANZO_ASSIGN_OR_RETURN(report, import_euroc(dir.string(), writer, {}));
    return ok_status();
  });
  ASSERT_TRUE(entries.ok()) << entries.error().message;
  ASSERT_EQ(report.streams.size(), 2u);
  EXPECT_EQ(report.streams[0].messages, 3u);
  EXPECT_EQ(report.streams[0].rejected, 1u);  // the repeated time
  EXPECT_THAT(report.streams[0].first_rejection, HasSubstr("data.csv:4: time 1403636579763555584 ns does not increase"));
  EXPECT_EQ(report.streams[1].messages, 2u);
  std::vector<std::string> topics;
  for (const LogEntry& entry : *entries) topics.push_back(entry.topic);
  EXPECT_EQ(topics, (std::vector<std::string>{"/imu", "/imu", "/cam0", "/imu", "/cam0"}));

  const auto& imu = std::get<msgs::ImuMessage>(std::get<msgs::SensorMessage>((*entries)[0].message));
  EXPECT_EQ(imu.timestamp.nanoseconds(), 1403636579758555392);
  EXPECT_EQ(imu.angular_velocity.x(), -0.099134701513277898);
  EXPECT_EQ(imu.linear_acceleration.x(), 8.1476917083333333);
  EXPECT_DOUBLE_EQ((*imu.gyroscope_covariance)(0, 0), 1.6968e-04 * 1.6968e-04 * 200);
  EXPECT_DOUBLE_EQ((*imu.acceleration_covariance)(2, 2), 2.0e-3 * 2.0e-3 * 200);

  const auto& image = std::get<msgs::ImageMessage>(std::get<msgs::SensorMessage>((*entries)[2].message));
  EXPECT_EQ(image.data[0], 100);
  EXPECT_DOUBLE_EQ(image.intrinsics->fx, 458.654);
  EXPECT_EQ(image.distortion->type, msgs::DistortionType::kRadtan);
  EXPECT_DOUBLE_EQ(image.distortion->coefficients[3], 1.76187114e-05);

  const calib::SensorCalibration* camera = report.calibration.find("cam0");
  ASSERT_NE(camera, nullptr);
  EXPECT_NEAR(camera->T_body_sensor().translation().y(), -0.064676986768, 1e-12);
  EXPECT_EQ(camera->camera->intrinsics.width, 752u);
  EXPECT_TRUE(calib::validate(report.calibration).ok());
  ASSERT_EQ(report.ground_truth.size(), 2u);
  EXPECT_EQ(report.ground_truth.position(1).z(), 0.787350);
  fs::remove_all(dir.parent_path());
}

TEST(EurocImport, MalformedFoldersAreRejectedByName) {
  const fs::path dir = make_euroc("bad");
  auto run = [&] {
    return import_and_read(dir.parent_path(), [&](SensorLogWriter& writer) { return status_of(import_euroc(dir.string(), writer, {})); });
  };
  fs::remove(dir / "mav0" / "cam0" / "data" / "1403636579813555456.png");
  auto missing = run();
  ASSERT_FALSE(missing.ok());
  EXPECT_THAT(missing.error().message, HasSubstr("1403636579813555456.png: no such image file"));

  std::string yaml = kEurocCamYaml;
  yaml.replace(yaml.find("radial-tangential"), 17, "kannala-brandt");
  write_text(dir / "mav0" / "cam0" / "sensor.yaml", yaml);
  auto model = run();
  ASSERT_FALSE(model.ok());
  EXPECT_THAT(model.error().message, HasSubstr("sensor.yaml:19: distortion_model: unknown distortion model 'kannala-brandt'"));

  write_text(dir / "mav0" / "imu0" / "data.csv", "#timestamp\n1403636579758555392,1,2,3,4,5\n");
  auto short_row = run();
  ASSERT_FALSE(short_row.ok());
  EXPECT_THAT(short_row.error().message, HasSubstr("imu0/data.csv:2: 6 fields (expected 7)"));

  EXPECT_FALSE(run().ok());
  auto not_euroc = import_and_read(dir.parent_path(), [&](SensorLogWriter& writer) -> Status {
    return status_of(import_euroc(dir.parent_path().string(), writer, {}));
  });
  ASSERT_FALSE(not_euroc.ok());
  EXPECT_THAT(not_euroc.error().message, HasSubstr("no mav0/imu0 or mav0/cam0 folder"));
  fs::remove_all(dir.parent_path());
}

// ---- TUM RGB-D --------------------------------------------------------------------------

TEST(TumRgbdImport, ColourAndDepthMergedWithFreiburgIntrinsics) {
  const fs::path root = temp_dir("tum");
  const fs::path dir = root / "rgbd_dataset_freiburg1_xyz";
  const std::string header = "# color images\n# file: 'rgbd_dataset_freiburg1_xyz.bag'\n# timestamp filename\n";
  write_text(dir / "rgb.txt", header + "1305031102.175304 rgb/1305031102.175304.png\n1305031102.211214 rgb/1305031102.211214.png\n");
  write_text(dir / "depth.txt", header + "1305031102.160407 depth/1305031102.160407.png\n1305031102.194330 depth/1305031102.194330.png\n");
  write_text(dir / "groundtruth.txt", "# ground truth trajectory\n# timestamp tx ty tz qx qy qz qw\n"
                                      "1305031098.6659 1.3563 0.6305 1.6380 0.6132 0.5962 -0.3311 -0.3986\n"
                                      "1305031098.6758 1.3543 0.6306 1.6360 0.6129 0.5966 -0.3316 -0.3980\n");
  for (const char* stamp : {"1305031102.175304", "1305031102.211214"}) {
    cv::Mat colour(480, 640, CV_8UC3, cv::Scalar(255, 0, 0));  // blue, in OpenCV's BGR order
    fs::create_directories(dir / "rgb");
    ASSERT_TRUE(cv::imwrite((dir / "rgb" / fmt::format("{}.png", stamp)).string(), colour));
  }
  for (const char* stamp : {"1305031102.160407", "1305031102.194330"}) {
    cv::Mat depth(480, 640, CV_16UC1, cv::Scalar(5000));  // 1 m
    depth.at<uint16_t>(0, 1) = 0;                     // no measurement
    depth.at<uint16_t>(0, 2) = 5003;                  // 1.0006 m
    fs::create_directories(dir / "depth");
    ASSERT_TRUE(cv::imwrite((dir / "depth" / fmt::format("{}.png", stamp)).string(), depth));
  }
  TumRgbdImportReport report;
  TumRgbdImportConfig own_times;
  own_times.max_depth_offset = 0.0;  // the depth images' own times
  auto entries = import_and_read(root, [&](SensorLogWriter& writer) -> Status {
    HANZO_ASSIGN_OR_RETURN(report, import_tum_rgbd(dir.string(), writer, own_times));
    return ok_status();
  });
  ASSERT_TRUE(entries.ok()) << entries.error().message;
  EXPECT_EQ(report.camera_model, "freiburg1");
  EXPECT_EQ(report.rgb_images, 2u);
  EXPECT_EQ(report.depth_images, 2u);
  std::vector<std::string> topics;
  for (const LogEntry& entry : *entries) topics.push_back(entry.topic);
  EXPECT_EQ(topics, (std::vector<std::string>{"/depth", "/rgb", "/depth", "/rgb"}));
  const auto& depth = std::get<msgs::ImageMessage>(std::get<msgs::SensorMessage>((*entries)[0].message));
  EXPECT_EQ(depth.timestamp.nanoseconds(), 1305031102160407000);
  EXPECT_EQ(depth.encoding, msgs::ImageEncoding::kDepth16);
  uint16_t millimetres[3];
  std::memcpy(millimetres, depth.data.data(), sizeof millimetres);
  EXPECT_EQ(millimetres[0], 1000);
  EXPECT_EQ(millimetres[1], 0);
  EXPECT_EQ(millimetres[2], 1001);
  const auto& colour = std::get<msgs::ImageMessage>(std::get<msgs::SensorMessage>((*entries)[1].message));
  EXPECT_EQ(colour.encoding, msgs::ImageEncoding::kRgb8);
  EXPECT_EQ(colour.data[0], 0);    // red
  EXPECT_EQ(colour.data[2], 255);  // blue
  EXPECT_DOUBLE_EQ(colour.intrinsics->fx, 517.3);
  EXPECT_EQ(colour.distortion->coefficients.size(), 5u);
  EXPECT_EQ(report.ground_truth.size(), 2u);
  EXPECT_EQ(report.calibration.sensors.size(), 2u);
  EXPECT_TRUE(calib::validate(report.calibration).ok());

  // By default each depth image takes the time of the colour image it pairs with (nearest,
  // within 20 ms, one each), as an RGB-D odometry needs them; one 25 ms from any is left out.
  write_text(dir / "depth.txt", header + "1305031102.160407 depth/1305031102.160407.png\n1305031102.194330 depth/1305031102.194330.png\n"
                                         "1305031102.236300 depth/1305031102.194330.png\n");
  auto paired = import_and_read(root, [&](SensorLogWriter& writer) -> Status {
    HANZO_ASSIGN_OR_RETURN(report, import_tum_rgbd(dir.string(), writer, {}));
    return ok_status();
  });
  ASSERT_TRUE(paired.ok()) << paired.error().message;
  EXPECT_EQ(report.depth_images, 2u);
  EXPECT_EQ(report.depth_unpaired, 1u);
  std::vector<std::pair<std::string, int64_t>> stamped;
  for (const LogEntry& entry : *paired) {
    stamped.emplace_back(entry.topic, std::get<msgs::ImageMessage>(std::get<msgs::SensorMessage>(entry.message)).timestamp.nanoseconds());
  }
  EXPECT_EQ(stamped, (std::vector<std::pair<std::string, int64_t>>{{"/rgb", 1305031102175304000},
                                                                    {"/depth", 1305031102175304000},
                                                                    {"/rgb", 1305031102211214000},
                                                                    {"/depth", 1305031102211214000}}));

  write_text(dir / "rgb.txt", header + "1305031102.175304 rgb/1305031102.175304.png extra\n");
  auto bad = import_and_read(root, [&](SensorLogWriter& writer) -> Status { return status_of(import_tum_rgbd(dir.string(), writer, {})); });
  ASSERT_FALSE(bad.ok());
  EXPECT_THAT(bad.error().message, HasSubstr("rgb.txt:4: 3 fields (expected: timestamp filename)"));
  fs::remove_all(root);
}


// ---- Image folders ------------------------------------------------------------------------

// KITTI 06's real left images (1226 x 370) with the sequence's times.txt: the order, the times
// and the pixels as in the files, and the calibration from the given intrinsics.
TEST(ImageFolderImport, RealSequenceWithATimesFileAndIntrinsics) {
  const std::string folder = std::string(HANZO_DATA_DIR) + "/kitti_odometry_06_first51/image_l";
  const fs::path dir = temp_dir("images_kitti");
  ImageFolderImportConfig config;
  config.times_path = std::string(HANZO_DATA_DIR) + "/kitti_odometry_06_first51/times_from_pyslam_kitti06.txt";
  config.camera = calib::CameraCalibration{{707.0912, 707.0912, 601.8873, 183.1104, 0, 0}, {}};
  ImageFolderImportReport report;
  auto entries = import_and_read(dir, [&](SensorLogWriter& writer) -> Status {
    HANZO_ASSIGN_OR_RETURN(report, import_image_folders({folder}, writer, config));
    return ok_status();
  });
  ASSERT_TRUE(entries.ok()) << entries.error().message;
  EXPECT_EQ(report.images, 51u);
  EXPECT_EQ(report.rejected, 0u);
  EXPECT_EQ(report.time_source, "times file");
  EXPECT_EQ(report.width, 1226u);
  EXPECT_EQ(report.height, 370u);
  ASSERT_EQ(entries->size(), 51u);
  const auto& tenth = std::get<msgs::ImageMessage>(std::get<msgs::SensorMessage>((*entries)[10].message));
  EXPECT_EQ((*entries)[10].topic, "/cam0");
  EXPECT_EQ(tenth.timestamp, Timestamp::from_seconds(1e9) + Duration::from_nanoseconds(parse_seconds("1.038877e+00")->nanoseconds()));  // line 11
  EXPECT_EQ(tenth.encoding, msgs::ImageEncoding::kMono8);
  const cv::Mat file = cv::imread(folder + "/000010.png", cv::IMREAD_GRAYSCALE);
  ASSERT_EQ(tenth.data.size(), file.total());
  EXPECT_EQ(std::memcmp(tenth.data.data(), file.data, file.total()), 0);
  ASSERT_TRUE(tenth.intrinsics.has_value());
  EXPECT_EQ(tenth.intrinsics->width, 1226u);
  ASSERT_EQ(report.calibration.sensors.size(), 1u);
  EXPECT_EQ(report.calibration.sensors[0].sensor, "cam0");
  EXPECT_DOUBLE_EQ(report.calibration.sensors[0].camera->intrinsics.cx, 601.8873);
  fs::remove_all(dir);
}

// EuRoC's stereo folders: times from the nanosecond file names, pairs in order, the right camera
// one baseline along x.
TEST(ImageFolderImport, StereoFoldersTimedByTheirFileNames) {
  const std::string cam0 = std::string(HANZO_DATA_DIR) + "/euroc_v101_micro/mav0/cam0/data";
  const std::string cam1 = std::string(HANZO_DATA_DIR) + "/euroc_v101_micro/mav0/cam1/data";
  const fs::path dir = temp_dir("images_euroc");
  ImageFolderImportConfig config;
  config.camera = calib::CameraCalibration{{458.654, 457.296, 367.215, 248.375, 0, 0}, {msgs::DistortionType::kRadtan, {-0.28340811, 0.07395907, 0.00019359, 1.76187114e-05}}};
  EXPECT_THAT(status_of(import_image_folders({cam0, cam1}, *SensorLogWriter::open((dir / "x.mcap").string()).value(), config)).error().message,
              HasSubstr("baseline"));
  config.baseline = 0.110;
  ImageFolderImportReport report;
  auto entries = import_and_read(dir, [&](SensorLogWriter& writer) -> Status {
    HANZO_ASSIGN_OR_RETURN(report, import_image_folders({cam0, cam1}, writer, config));
    return ok_status();
  });
  ASSERT_TRUE(entries.ok()) << entries.error().message;
  EXPECT_EQ(report.time_source, "file names");
  EXPECT_EQ(report.images, 2u * 95u);
  ASSERT_EQ(entries->size(), 2u * 95u);
  const auto& first = std::get<msgs::ImageMessage>(std::get<msgs::SensorMessage>((*entries)[0].message));
  const auto& second = std::get<msgs::ImageMessage>(std::get<msgs::SensorMessage>((*entries)[1].message));
  EXPECT_EQ(first.timestamp, Timestamp::from_nanoseconds(1403715273262142976));
  EXPECT_EQ(second.timestamp, first.timestamp);
  EXPECT_NE((*entries)[0].topic, (*entries)[1].topic);
  ASSERT_TRUE(first.distortion.has_value());
  ASSERT_EQ(report.calibration.sensors.size(), 2u);
  EXPECT_EQ(report.calibration.sensors[1].sensor, "cam1");
  EXPECT_DOUBLE_EQ(report.calibration.sensors[1].translation.x(), 0.110);
  fs::remove_all(dir);
}

// Frames named frame1 .. frame12 at a frame rate, in number order; a corrupt file and an image
// of another size are left out and counted, the rest imported; what cannot be imported at all
// is an error naming why.
TEST(ImageFolderImport, NumberOrderRateAndBadFiles) {
  const fs::path dir = temp_dir("images_rate");
  for (int i = 1; i <= 12; ++i) write_gray(dir / "frames" / fmt::format("frame{}.png", i), static_cast<uint8_t>(10 * i), 64, 48);
  write_text(dir / "frames" / "frame5.png", "not an image");
  write_gray(dir / "frames" / "frame7.png", 70, 32, 48);
  write_text(dir / "frames" / "notes.txt", "not an image either");
  ImageFolderImportConfig config;
  const std::string frames = (dir / "frames").string();
  EXPECT_THAT(status_of(import_image_folders({frames}, *SensorLogWriter::open((dir / "x.mcap").string()).value(), config)).error().message,
              HasSubstr("times file or a frame rate"));
  config.rate_hz = 10.0;
  ImageFolderImportReport report;
  auto entries = import_and_read(dir, [&](SensorLogWriter& writer) -> Status {
    HANZO_ASSIGN_OR_RETURN(report, import_image_folders({frames}, writer, config));
    return ok_status();
  });
  ASSERT_TRUE(entries.ok()) << entries.error().message;
  EXPECT_EQ(report.images, 10u);
  EXPECT_EQ(report.rejected, 2u);
  EXPECT_THAT(report.first_rejection, HasSubstr("frame5.png"));
  ASSERT_EQ(entries->size(), 10u);
  std::vector<int> values;
  for (const LogEntry& entry : *entries) values.push_back(std::get<msgs::ImageMessage>(std::get<msgs::SensorMessage>(entry.message)).data[0]);
  EXPECT_EQ(values, (std::vector<int>{10, 20, 30, 40, 60, 80, 90, 100, 110, 120}));
  const auto& last = std::get<msgs::ImageMessage>(std::get<msgs::SensorMessage>(entries->back().message));
  EXPECT_EQ(last.timestamp, Timestamp::from_seconds(1e9) + Duration::from_milliseconds(1100));  // frame12: the 12th at 10 Hz

  // A times file of "TIME NAME" lines orders by its lines; one whose count differs is refused.
  write_text(dir / "named.txt", "# time name\n0.5 frame2.png\n0.6 frame1.png\n");
  write_gray(dir / "two" / "frame1.png", 1, 64, 48);
  write_gray(dir / "two" / "frame2.png", 2, 64, 48);
  config.times_path = (dir / "named.txt").string();
  auto named = import_and_read(dir, [&](SensorLogWriter& writer) -> Status {
    HANZO_ASSIGN_OR_RETURN(report, import_image_folders({(dir / "two").string()}, writer, config));
    return ok_status();
  });
  ASSERT_TRUE(named.ok()) << named.error().message;
  ASSERT_EQ(named->size(), 2u);
  EXPECT_EQ(std::get<msgs::ImageMessage>(std::get<msgs::SensorMessage>((*named)[0].message)).data[0], 2);
  write_text(dir / "short.txt", "0.1\n");
  config.times_path = (dir / "short.txt").string();
  EXPECT_THAT(status_of(import_image_folders({(dir / "two").string()}, *SensorLogWriter::open((dir / "y.mcap").string()).value(), config)).error().message,
              HasSubstr("1 times for 2 images"));
  fs::create_directories(dir / "empty");
  EXPECT_THAT(status_of(import_image_folders({(dir / "empty").string()}, *SensorLogWriter::open((dir / "z.mcap").string()).value(), config)).error().message,
              HasSubstr("no image files"));
  fs::remove_all(dir);
}

}  // namespace
}  // namespace hanzo::fusion::io
