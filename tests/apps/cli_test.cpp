// Runs the real hanzo-fusion program: exit codes, text and --json output, one-line errors.

#include <sys/wait.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <iterator>
#include <numbers>
#include <set>
#include <string>
#include <thread>
#include <tuple>

#include <fmt/format.h>
#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "hanzo/fusion/calib/calibration.hpp"
#include "hanzo/fusion/io/sensor_log.hpp"
#include "hanzo/fusion/io/trajectory.hpp"
#include <nlohmann/json.hpp>
#include <opencv2/imgcodecs.hpp>

namespace {

using ::testing::HasSubstr;
using ::testing::Not;

struct CliRun {
  int exit_code = -1;
  std::string out;
  std::string err;
};

// `tag` names the stderr file of a run made while another runs (from another thread).
CliRun run(const std::string& arguments, const std::string& tag = "") {
  const std::filesystem::path err_path = std::filesystem::temp_directory_path() / fmt::format("hanzo_cli_test_{}{}.err", ::getpid(), tag);
  const std::string command = fmt::format("{} {} 2>{}", HANZO_FUSION_CLI, arguments, err_path.string());
  CliRun result;
  FILE* pipe = ::popen(command.c_str(), "r");
  if (!pipe) return result;
  std::array<char, 4096> buffer{};
  size_t n = 0;
  while ((n = std::fread(buffer.data(), 1, buffer.size(), pipe)) > 0) result.out.append(buffer.data(), n);
  const int status = ::pclose(pipe);
  result.exit_code = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  std::ifstream err(err_path);
  result.err.assign(std::istreambuf_iterator<char>(err), {});
  std::filesystem::remove(err_path);
  return result;
}

std::string file_bytes(const std::filesystem::path& path) {
  std::ifstream file(path, std::ios::binary);
  return {std::istreambuf_iterator<char>(file), std::istreambuf_iterator<char>()};
}

std::string write_temp(const std::string& name, const std::string& text) {
  const std::filesystem::path path = std::filesystem::temp_directory_path() / name;
  std::ofstream(path) << text;
  return path.string();
}

TEST(Cli, VersionAndHelp) {
  const CliRun version = run("--version");
  EXPECT_EQ(version.exit_code, 0);
  EXPECT_THAT(version.out, HasSubstr("hanzo-fusion 0."));
  const CliRun help = run("--help");
  EXPECT_EQ(help.exit_code, 0);
  EXPECT_THAT(help.out, HasSubstr("config"));
  EXPECT_THAT(help.out, HasSubstr("calib"));
}

TEST(Cli, ConfigCheckPrintsSummary) {
  const CliRun result = run("config check examples/fusion.yaml");
  EXPECT_EQ(result.exit_code, 0) << result.err;
  EXPECT_THAT(result.out, HasSubstr("valid fusion configuration"));
  EXPECT_THAT(result.out, HasSubstr("velodyne_vlp16"));
  EXPECT_EQ(result.err, "");
}

TEST(Cli, ConfigCheckJsonIsOneObject) {
  for (const char* arguments : {"--json config check examples/fusion.yaml", "config check examples/fusion.yaml --json"}) {
    const CliRun result = run(arguments);
    ASSERT_EQ(result.exit_code, 0) << result.err;
    const nlohmann::json json = nlohmann::json::parse(result.out);  // throws (fails) unless exactly one JSON value
    EXPECT_TRUE(json.is_object());
    EXPECT_EQ(json["ok"], true);
    EXPECT_EQ(json["config"]["frontend"]["type"], "ekf");
    EXPECT_EQ(json["config"]["sensors"].size(), 6U);
    EXPECT_EQ(json["config"]["sensors"][1]["rate_hz"], 10.0);
  }
}

TEST(Cli, CalibCheckTextAndJson) {
  const CliRun text = run("calib check examples/calibration.yaml");
  EXPECT_EQ(text.exit_code, 0) << text.err;
  EXPECT_THAT(text.out, HasSubstr("3 sensor(s)"));
  EXPECT_THAT(text.out, HasSubstr("equidistant"));
  const CliRun json_run = run("calib check --json examples/calibration.yaml");
  ASSERT_EQ(json_run.exit_code, 0);
  const nlohmann::json json = nlohmann::json::parse(json_run.out);
  EXPECT_EQ(json["calibration"]["sensors"][1]["sensor"], "lidar");
  EXPECT_EQ(json["calibration"]["sensors"][1]["time_offset_ns"], -5000000);
  EXPECT_NEAR(json["calibration"]["sensors"][1]["rotation_angle_deg"].get<double>(), 90.0, 0.1);
  EXPECT_EQ(json["calibration"]["sensors"][2]["intrinsics"]["distortion_model"], "equidistant");
}

TEST(Cli, BadFileFailsWithOneLineReason) {
  const std::string path = write_temp("hanzo_cli_bad_calibration.yaml", "calibration:\n  lidar_to_body:\n    rotation: [0.707, 0.0, 0.707]\n");
  const CliRun text = run("calib check " + path);
  EXPECT_EQ(text.exit_code, 1);
  EXPECT_EQ(text.out, "");
  EXPECT_EQ(text.err, "hanzo-fusion: " + path + ":3: lidar_to_body.rotation: expected 4 numbers (w, x, y, z), got 3\n");
  const CliRun json_run = run("--json calib check " + path);
  EXPECT_EQ(json_run.exit_code, 1);
  const nlohmann::json json = nlohmann::json::parse(json_run.out);
  EXPECT_EQ(json["ok"], false);
  EXPECT_THAT(json["error"].get<std::string>(), HasSubstr("expected 4 numbers"));
  EXPECT_EQ(std::count(json_run.err.begin(), json_run.err.end(), '\n'), 1);
  std::filesystem::remove(path);
}

TEST(Cli, MissingFileAndUsageErrors) {
  const CliRun missing = run("config check /nonexistent/fusion.yaml");
  EXPECT_EQ(missing.exit_code, 1);
  EXPECT_EQ(missing.err, "hanzo-fusion: /nonexistent/fusion.yaml: cannot open file (No such file or directory)\n");
  const CliRun usage = run("config check");
  EXPECT_NE(usage.exit_code, 0);
  EXPECT_THAT(usage.err, HasSubstr("FILE"));
  const CliRun unknown = run("frobnicate");
  EXPECT_NE(unknown.exit_code, 0);
  EXPECT_THAT(unknown.err, HasSubstr("hanzo-fusion:"));
  // A misspelt option or command is named with the closest valid spelling (exit 2), before any
  // other complaint about the line.
  const std::pair<const char*, const char*> misspelt[] = {
      {"run --config examples/data/fusion.yaml --calibraton c.yaml", "unknown option '--calibraton' for 'run'; did you mean '--calibration'?"},
      {"map build --log a.mcap --height-band -0.3 1.0 --resoluton 0.1", "did you mean '--resolution'?"},
      {"map exprt", "unknown command 'exprt' for 'map'; did you mean 'export'?"},
      {"rn --config x", "did you mean 'run'?"},
      {"run --jsn", "did you mean '--json'?"}};
  for (const auto& [line, expected] : misspelt) {
    const CliRun wrong = run(line);
    EXPECT_EQ(wrong.exit_code, 2) << line;
    EXPECT_THAT(wrong.err, HasSubstr(expected)) << line;
  }
}

const std::string kEvo = std::string(HANZO_DATA_DIR) + "/trajectory_eval_evo/";

TEST(Cli, EvalApeReproducesEvoAndWritesPlots) {
  const std::filesystem::path plots = std::filesystem::temp_directory_path() / fmt::format("hanzo_cli_plots_{}", ::getpid());
  const CliRun ape = run(fmt::format("eval ape {0}KITTI_00_gt.txt {0}KITTI_00_ORB.txt --format kitti --align se3 --plot {1} --json",
                                     kEvo, plots.string()));
  ASSERT_EQ(ape.exit_code, 0) << ape.err;
  const nlohmann::json json = nlohmann::json::parse(ape.out);
  EXPECT_NEAR(json["statistics"]["rmse"].get<double>(), 1.3034497145650266, 1.3e-6);
  EXPECT_EQ(json["statistics"]["count"], 4541);
  EXPECT_EQ(json["alignment"]["method"], "se3");
  ASSERT_EQ(json["plots"].size(), 2u);
  for (const auto& plot : json["plots"]) EXPECT_GT(std::filesystem::file_size(plot.get<std::string>()), 1000u);
  std::filesystem::remove_all(plots);

  const CliRun text = run(fmt::format("eval rpe {0}KITTI_00_gt.txt {0}KITTI_00_ORB.txt --format kitti -d 10 -u m", kEvo));
  ASSERT_EQ(text.exit_code, 0);
  EXPECT_THAT(text.out, HasSubstr("rmse\t0.226261"));
  EXPECT_THAT(text.out, HasSubstr("pairs\t353"));
}

TEST(Cli, EvalKittiMetricOfOrbSlam2) {
  // ORB-SLAM2 (Mur-Artal & Tardos 2017, Table 3) reports 0.70 % and 0.25 deg/100 m on KITTI 00.
  const CliRun kitti = run(fmt::format("eval kitti {0}KITTI_00_gt.txt {0}KITTI_00_ORB.txt --format kitti --json", kEvo));
  ASSERT_EQ(kitti.exit_code, 0) << kitti.err;
  const nlohmann::json json = nlohmann::json::parse(kitti.out);
  EXPECT_NEAR(json["translation_error_percent"].get<double>(), 0.70, 0.005);
  EXPECT_NEAR(json["rotation_error_deg_per_100m"].get<double>(), 0.25, 0.005);
}

TEST(Cli, EvalRejectsBadInputWithOneLine) {
  const CliRun mismatch = run(fmt::format("eval ape {0}KITTI_00_gt.txt {0}fr2_desk_ORB.txt --format kitti", kEvo));
  EXPECT_EQ(mismatch.exit_code, 1);
  EXPECT_THAT(mismatch.err, HasSubstr("expected 12 numbers for a kitti pose"));
  EXPECT_EQ(std::count(mismatch.err.begin(), mismatch.err.end(), '\n'), 1);
  const CliRun relation = run(fmt::format("eval ape {0}fr2_desk_ORB.txt {0}fr2_desk_ORB.txt -r speed", kEvo));
  EXPECT_EQ(relation.exit_code, 1);
  EXPECT_THAT(relation.err, HasSubstr("unknown pose relation 'speed'"));
  const CliRun offset = run(fmt::format("eval ape {0}fr2_desk_ORB.txt {0}fr2_desk_ORB.txt --t-offset 100 --json", kEvo));
  EXPECT_EQ(offset.exit_code, 1);
  EXPECT_EQ(nlohmann::json::parse(offset.out)["ok"], false);
  EXPECT_THAT(offset.err, HasSubstr("no matching timestamps"));
}

}  // namespace

namespace {

TEST(Cli, ImportCsvThenLogInfoAndExportRoundTrip) {
  const std::filesystem::path dir = std::filesystem::temp_directory_path() / fmt::format("hanzo_cli_log_{}", ::getpid());
  std::filesystem::create_directories(dir);
  const std::string log = (dir / "sample.mcap").string();
  const CliRun imported = run(fmt::format(
      "import csv examples/data/imu.csv examples/data/gnss.csv examples/data/wheels.csv --topic wheels=/base/wheels --out {} --json", log));
  ASSERT_EQ(imported.exit_code, 0) << imported.err;
  EXPECT_EQ(nlohmann::json::parse(imported.out)["messages"], 3103);

  const CliRun info = run(fmt::format("log info {} --verify --json", log));
  ASSERT_EQ(info.exit_code, 0) << info.err;
  const nlohmann::json json = nlohmann::json::parse(info.out);
  EXPECT_EQ(json["messages"], 3103 + 101);  // + the Foxglove mirror of the 101 GNSS fixes
  EXPECT_NEAR(json["duration_s"].get<double>(), 20.0, 1e-9);
  ASSERT_EQ(json["channels"].size(), 4u);
  EXPECT_EQ(json["channels"][2]["topic"], "/gnss/foxglove");
  EXPECT_EQ(json["channels"][0]["topic"], "/base/wheels");
  EXPECT_NEAR(json["channels"][0]["rate_hz"].get<double>(), 50.0, 1e-9);
  EXPECT_EQ(json["channels"][3]["schema"], "hanzo.fusion.v1.ImuMessage");
  EXPECT_NEAR(json["channels"][3]["max_gap_s"].get<double>(), 0.01, 1e-12);
  EXPECT_EQ(json["verified"]["data_section_crc_checked"], true);

  // Export reproduces the imported CSV exactly (shortest round-trip numbers on both sides).
  for (const char* name : {"imu", "gnss"}) {
    const std::string csv = (dir / (std::string(name) + ".csv")).string();
    const CliRun exported = run(fmt::format("log export {} --topic /{} --out {}", log, name, csv));
    ASSERT_EQ(exported.exit_code, 0) << exported.err;
    std::ifstream original(fmt::format("examples/data/{}.csv", name));
    std::ifstream again(csv);
    std::string a, b;
    std::size_t line = 0;
    while (std::getline(original, a) && std::getline(again, b)) {
      ++line;
      if (std::string(name) == "gnss") {  // the sample writes 9 decimals and "10.000"; compare values
        EXPECT_EQ(a.substr(0, 19), b.substr(0, 19)) << line;
      } else {
        ASSERT_EQ(a, b) << name << " line " << line;
      }
    }
    EXPECT_EQ(line, std::string(name) == "imu" ? 2002u : 102u);
  }
  const CliRun missing_topic = run(fmt::format("log export {} --topic /lidar", log));
  EXPECT_EQ(missing_topic.exit_code, 1);
  EXPECT_THAT(missing_topic.err, HasSubstr("no topic '/lidar' (topics: /base/wheels, /gnss, /gnss/foxglove, /imu)"));
  const CliRun mirror = run(fmt::format("log export {} --topic /gnss/foxglove", log));
  EXPECT_NE(mirror.exit_code, 0);
  EXPECT_THAT(mirror.err, ::testing::HasSubstr("does not carry hanzo.fusion.v1 messages"));
  std::filesystem::remove_all(dir);
}

TEST(Cli, ImportKittiWritesLogGroundTruthAndCalibration) {
  const std::filesystem::path root = std::filesystem::temp_directory_path() / fmt::format("hanzo_cli_kitti_{}", ::getpid());
  const std::filesystem::path sequence = root / "sequences" / "03";
  std::filesystem::create_directories(sequence / "velodyne");
  std::filesystem::create_directories(root / "poses");
  std::ofstream(sequence / "times.txt") << "0.0\n0.1\n";
  std::ofstream(sequence / "calib.txt") << "P0: 700 0 600 0 0 700 180 0 0 0 1 0\nTr: 0 -1 0 0 0 0 -1 0 1 0 0 0\n";
  std::ofstream(root / "poses" / "03.txt") << "1 0 0 0 0 1 0 0 0 0 1 0\n1 0 0 0 0 1 0 0 0 0 1 1.5\n";
  for (int i = 0; i < 2; ++i) {
    const float point[4] = {5.0F, 0.0F, 0.0F, 0.5F};
    std::ofstream(sequence / "velodyne" / fmt::format("{:06d}.bin", i), std::ios::binary).write(reinterpret_cast<const char*>(point), 16);
  }
  const std::string log = (root / "kitti.mcap").string();
  const CliRun imported = run(fmt::format("import kitti {} --out {} --ground-truth {}/gt.tum --calibration {}/calib.yaml --json",
                                          sequence.string(), log, root.string(), root.string()));
  ASSERT_EQ(imported.exit_code, 0) << imported.err;
  const nlohmann::json json = nlohmann::json::parse(imported.out);
  EXPECT_EQ(json["scans"], 2);
  EXPECT_EQ(json["points"], 2);
  std::ifstream ground_truth(root / "gt.tum");
  std::string line, last;
  while (std::getline(ground_truth, line)) last = line;
  // 1.5 m along the camera's z axis is 1.5 m forward (x) in the LiDAR frame.
  EXPECT_EQ(last, "1000000000.1 1.5 0.0 0.0 0.0 0.0 0.0 1.0");
  std::ifstream calibration(root / "calib.yaml");
  const std::string yaml((std::istreambuf_iterator<char>(calibration)), std::istreambuf_iterator<char>());
  EXPECT_THAT(yaml, HasSubstr("lidar_to_body"));
  const CliRun info = run(fmt::format("log info {} --json", log));
  ASSERT_EQ(info.exit_code, 0) << info.err;
  EXPECT_EQ(nlohmann::json::parse(info.out)["channels"].size(), 2u);  // /lidar and /lidar/foxglove

  const CliRun missing = run(fmt::format("import kitti {} --out {}", (root / "nowhere").string(), log));
  EXPECT_EQ(missing.exit_code, 1);
  EXPECT_THAT(missing.err, HasSubstr("nowhere: not a directory (expected a KITTI sequence folder)"));
  std::filesystem::remove_all(root);
}

// A real receiver's NMEA log (u-blox NEO-M9N, 60 s with GST) into a sensor log: one fix per
// epoch on /gnss with the GST's covariance; a file without NMEA and GGA without a date are
// refused with the reason, and --date supplies the date.
TEST(Cli, ImportNmeaReceiverLog) {
  const std::filesystem::path dir = std::filesystem::temp_directory_path() / fmt::format("hanzo_cli_nmea_{}", ::getpid());
  std::filesystem::create_directories(dir);
  const std::string receiver = std::string(HANZO_DATA_DIR) + "/drivers/gnss_nmea_gpsd/ublox-neo-m9n-nmea.log";
  const CliRun imported = run(fmt::format("import nmea {} --out {}/gnss.mcap --json", receiver, dir.string()));
  ASSERT_EQ(imported.exit_code, 0) << imported.err;
  const nlohmann::json result = nlohmann::json::parse(imported.out);
  EXPECT_EQ(result["fixes"], 61);
  EXPECT_EQ(result["gst_covariances"], 61);
  EXPECT_EQ(result["checksum_errors"], 0);
  const CliRun info = run(fmt::format("log info {}/gnss.mcap --json", dir.string()));
  ASSERT_EQ(info.exit_code, 0) << info.err;
  EXPECT_THAT(info.out, HasSubstr("\"/gnss\""));

  const CliRun not_nmea = run(fmt::format("import nmea README.md --out {}/x.mcap", dir.string()));
  EXPECT_EQ(not_nmea.exit_code, 1);
  EXPECT_THAT(not_nmea.err, HasSubstr("README.md: no NMEA sentence"));
  std::ofstream(dir / "gga.nmea") << "$GPGGA,120000.00,4807.038,N,01131.000,E,1,08,0.9,545.4,M,46.9,M,,*67\r\n";
  const CliRun undated = run(fmt::format("import nmea {0}/gga.nmea --out {0}/y.mcap", dir.string()));
  EXPECT_EQ(undated.exit_code, 1);
  EXPECT_THAT(undated.err, HasSubstr("give --date YYYY-MM-DD"));
  EXPECT_EQ(std::count(undated.err.begin(), undated.err.end(), '\n'), 1);
  EXPECT_FALSE(std::filesystem::exists(dir / "y.mcap"));
  const CliRun dated = run(fmt::format("import nmea {0}/gga.nmea --out {0}/y.mcap --date 2024-05-01 --json", dir.string()));
  ASSERT_EQ(dated.exit_code, 0) << dated.err;
  EXPECT_EQ(nlohmann::json::parse(dated.out)["fixes"], 1);
  const CliRun missing = run(fmt::format("import nmea {} --out {}/z.mcap", (dir / "gga.nmea").string() + "x", dir.string()));
  EXPECT_EQ(missing.exit_code, 1);
  EXPECT_THAT(missing.err, HasSubstr("gga.nmeax"));
  std::filesystem::remove_all(dir);
}

// A Hesai Pandar40P capture (pcapng, port 2369) into a sensor log with the unit's corrections;
// the default port finds nothing and says which ports the capture has.
TEST(Cli, ImportHesaiPacketCapture) {
  const std::filesystem::path dir = std::filesystem::temp_directory_path() / fmt::format("hanzo_cli_hesai_{}", ::getpid());
  std::filesystem::create_directories(dir);
  const std::string folder = std::string(HANZO_DATA_DIR) + "/drivers/hesai_pandar40p_velocity_report/";
  const std::string common = fmt::format("import pcap {0}lidar_20Hz.pcapng --driver hesai --calibration {0}calib/Pandar40P_Angle_Correction_File.csv", folder);
  const CliRun imported = run(fmt::format("{} --firetime {}calib/Pandar40P_Firetime_Correction_File.csv --port 2369 --out {}/lidar.mcap --json", common,
                                          folder, dir.string()));
  ASSERT_EQ(imported.exit_code, 0) << imported.err;
  const nlohmann::json result = nlohmann::json::parse(imported.out);
  EXPECT_EQ(result["frames"], 3);
  EXPECT_EQ(result["packets"], 200);
  EXPECT_EQ(result["malformed_packets"], 0);
  EXPECT_EQ(result["capture_clock_packets"], 200);
  const CliRun info = run(fmt::format("log info {}/lidar.mcap --json", dir.string()));
  ASSERT_EQ(info.exit_code, 0) << info.err;
  EXPECT_THAT(info.out, HasSubstr("\"/lidar\""));

  const CliRun wrong_port = run(fmt::format("{} --out {}/x.mcap", common, dir.string()));
  EXPECT_EQ(wrong_port.exit_code, 1);
  EXPECT_THAT(wrong_port.err, HasSubstr("0 datagrams to port 2368"));
  EXPECT_THAT(wrong_port.err, HasSubstr("other ports: 2369 (200 datagrams)"));
  EXPECT_EQ(std::count(wrong_port.err.begin(), wrong_port.err.end(), '\n'), 1);
  const CliRun no_calibration = run(fmt::format("import pcap {}lidar_20Hz.pcapng --driver hesai --out {}/x.mcap", folder, dir.string()));
  EXPECT_EQ(no_calibration.exit_code, 1);
  EXPECT_THAT(no_calibration.err, HasSubstr("--calibration"));
  EXPECT_FALSE(std::filesystem::exists(dir / "x.mcap"));
  std::filesystem::remove_all(dir);
}

// Live input: a Velodyne's packets sent over loopback UDP at the recorded pace (`send`) and read
// by `drive` give the rotations the capture file gives (`import pcap`); a silent sensor fails
// the run by name, keeping the log; a configuration without drivers is refused.
// The messages of one type on `topic` of a sensor log, in log order.
template <typename Message>
std::vector<Message> messages_of(const std::string& path, const std::string& topic) {
  namespace hf = hanzo::fusion;
  std::vector<Message> messages;
  auto reader = hf::io::SensorLogReader::open(path);
  if (!reader) return messages;
  hf::io::LogEntry entry;
  while (true) {
    hf::Result<bool> more = (*reader)->next(entry);
    if (!more || !*more) break;
    if (entry.topic != topic) continue;
    if (const auto* message = std::get_if<hf::msgs::SensorMessage>(&entry.message)) {
      if (const auto* typed = std::get_if<Message>(message)) messages.push_back(*typed);
    }
  }
  return messages;
}

std::vector<hanzo::fusion::msgs::PointCloudMessage> clouds_of(const std::string& path, const std::string& topic) {
  return messages_of<hanzo::fusion::msgs::PointCloudMessage>(path, topic);
}

TEST(Cli, DriveRecordsAVelodyneStreamAsItsCaptureDecodes) {
  const std::filesystem::path dir = std::filesystem::temp_directory_path() / fmt::format("hanzo_cli_drive_{}", ::getpid());
  std::filesystem::create_directories(dir);
  const std::string veloview = std::string(HANZO_DATA_DIR) + "/drivers/velodyne_veloview/";
  const int port = 20000 + ::getpid() % 20000;
  std::ofstream(dir / "fusion.yaml") << fmt::format(
      "fusion:\n  sensors:\n    lidar:\n      modality: lidar\n      topic: /lidar\n      rate: 20\n      driver:\n        type: velodyne\n"
      "        source: udp://127.0.0.1:{}\n        model: VLP-16\n        calibration: {}calib/VLP-16.xml\n",
      port, veloview);
  CliRun drive;
  std::thread driver([&] {
    drive = run(fmt::format("drive --config {0}/fusion.yaml --record {0}/live.mcap --out {0}/live --duration 5 --json", dir.string()), "_drive");
  });
  std::this_thread::sleep_for(std::chrono::seconds(1));
  const CliRun sent = run(fmt::format("send {}vlp-16-test-90deg-1-50-frames.pcap --port {} --json", veloview, port));
  driver.join();
  ASSERT_EQ(sent.exit_code, 0) << sent.err;
  EXPECT_EQ(nlohmann::json::parse(sent.out)["sent"], 2269);
  EXPECT_GT(nlohmann::json::parse(sent.out)["seconds"].get<double>(), 2.4) << "the recorded pace";
  ASSERT_EQ(drive.exit_code, 0) << drive.err;
  const nlohmann::json lidar = nlohmann::json::parse(drive.out)["sensors"]["lidar"];
  EXPECT_EQ(lidar["malformed"], 0);
  EXPECT_EQ(lidar["topic"], "/lidar");
  ASSERT_EQ(run(fmt::format("import pcap {0}vlp-16-test-90deg-1-50-frames.pcap --driver velodyne --model VLP-16 --calibration {0}calib/VLP-16.xml "
                            "--out {1}/file.mcap", veloview, dir.string())).exit_code, 0);
  const auto live = clouds_of((dir / "live.mcap").string(), "/lidar");
  const auto file = clouds_of((dir / "file.mcap").string(), "/lidar");
  ASSERT_EQ(file.size(), 52U);
  // Loopback UDP may drop a datagram on a loaded machine: every rotation that came whole is
  // the file's, point for point.
  std::size_t identical = 0;
  for (std::size_t i = 0; i < std::min(live.size(), file.size()); ++i) identical += live[i].points == file[i].points && live[i].ring_ids == file[i].ring_ids;
  std::printf("drive: %zu of %zu rotations identical to the capture's decode (%d datagrams read)\n", identical, file.size(), lidar["reads"].get<int>());
  EXPECT_GE(identical, file.size() - 2);
  // Fused live as `run` fuses the file: the same poses (the live clock's hour aside: a Velodyne
  // packet carries its time past the hour, the hour comes from the receiving clock).
  const nlohmann::json fused = nlohmann::json::parse(drive.out);
  EXPECT_GT(fused["poses"].get<int>(), 40);
  ASSERT_EQ(run(fmt::format("run --config {0}/fusion.yaml --log {0}/file.mcap --out {0}/file_run", dir.string())).exit_code, 0);
  namespace hio = hanzo::fusion::io;
  const hio::Trajectory live_poses = hio::read_trajectory((dir / "live" / "trajectory.tum").string(), hio::TrajectoryFormat::kTum).value();
  const hio::Trajectory file_poses = hio::read_trajectory((dir / "file_run" / "trajectory.tum").string(), hio::TrajectoryFormat::kTum).value();
  if (identical == file.size()) {
    ASSERT_EQ(live_poses.size(), file_poses.size());
    for (std::size_t i = 0; i < live_poses.size(); ++i) EXPECT_LT((live_poses.poses[i] - file_poses.poses[i]).norm(), 1e-6) << i;
  }

  // A sensor that sends nothing: the run fails naming it; the log is kept.
  std::ofstream(dir / "silent.yaml") << fmt::format(
      "fusion:\n  sensors:\n    gnss:\n      rate: 5\n      driver:\n        type: nmea\n        source: udp://127.0.0.1:{}\n", port + 1);
  const CliRun silent = run(fmt::format("drive --config {0}/silent.yaml --record {0}/silent.mcap --duration 1", dir.string()));
  EXPECT_EQ(silent.exit_code, 1);
  EXPECT_THAT(silent.err, HasSubstr("no messages from gnss"));
  EXPECT_TRUE(std::filesystem::exists(dir / "silent.mcap"));
  std::ofstream(dir / "plain.yaml") << "fusion:\n  sensors:\n    imu:\n      rate: 100\n";
  const CliRun plain = run(fmt::format("drive --config {0}/plain.yaml --record {0}/x.mcap", dir.string()));
  EXPECT_EQ(plain.exit_code, 1);
  EXPECT_THAT(plain.err, HasSubstr("no sensor has a driver"));
  std::ofstream(dir / "mismatch.yaml") << "fusion:\n  sensors:\n    imu:\n      rate: 100\n      driver:\n        type: velodyne\n        source: udp://:2368\n";
  const CliRun mismatch = run(fmt::format("drive --config {0}/mismatch.yaml --record {0}/x.mcap", dir.string()));
  EXPECT_EQ(mismatch.exit_code, 1);
  EXPECT_THAT(mismatch.err, HasSubstr("a velodyne driver delivers lidar data (this sensor is imu)"));
  std::filesystem::remove_all(dir);
}

// An Ouster's two ports live: the lidar port (driver ouster) and the IMU port (ouster_imu) sent
// at their recorded ports and pace; the frame and the 11 IMU samples are the file's decode.
TEST(Cli, DriveReadsAnOustersLidarAndImuPorts) {
  const std::filesystem::path dir = std::filesystem::temp_directory_path() / fmt::format("hanzo_cli_drive_ouster_{}", ::getpid());
  std::filesystem::create_directories(dir);
  const std::string pcaps = std::string(HANZO_DATA_DIR) + "/drivers/ouster_sdk_pcaps/";
  const std::string metadata = pcaps + "OS-1-64_sensor_config_reduced.json";
  std::ofstream(dir / "fusion.yaml") << fmt::format(
      "fusion:\n  sensors:\n    lidar:\n      modality: lidar\n      topic: /lidar\n      rate: 10\n"
      "      driver: {{type: ouster, source: \"udp://127.0.0.1:7502\", metadata: {0}}}\n"
      "    imu:\n      modality: imu\n      topic: /imu\n      rate: 100\n"
      "      driver: {{type: ouster_imu, source: \"udp://127.0.0.1:7503\", metadata: {0}}}\n",
      metadata);
  CliRun drive;
  std::thread driver([&] { drive = run(fmt::format("drive --config {0}/fusion.yaml --record {0}/live.mcap --duration 3 --json", dir.string()), "_ouster"); });
  std::this_thread::sleep_for(std::chrono::seconds(1));
  const CliRun sent = run(fmt::format("send {}OS-1-64_1024x10_fw20.pcap --json", pcaps));  // to the recorded ports 7502 and 7503
  driver.join();
  ASSERT_EQ(sent.exit_code, 0) << sent.err;
  ASSERT_EQ(drive.exit_code, 0) << drive.err;
  ASSERT_EQ(run(fmt::format("import pcap {}OS-1-64_1024x10_fw20.pcap --driver ouster --metadata {} --out {}/file.mcap", pcaps, metadata, dir.string())).exit_code, 0);
  const auto imu_of = [](const std::string& path) { return messages_of<hanzo::fusion::msgs::ImuMessage>(path, "/imu"); };
  const auto live = imu_of((dir / "live.mcap").string());
  const auto file = imu_of((dir / "file.mcap").string());
  ASSERT_EQ(file.size(), 11U);
  ASSERT_EQ(live.size(), file.size());
  for (std::size_t i = 0; i < live.size(); ++i) {
    EXPECT_EQ(live[i].linear_acceleration, file[i].linear_acceleration) << i;
    EXPECT_EQ(live[i].angular_velocity, file[i].angular_velocity) << i;
  }
  EXPECT_EQ(clouds_of((dir / "live.mcap").string(), "/lidar").size(), 1U);
  std::filesystem::remove_all(dir);
}

// An Xsens MTi-G-710's serial stream into a sensor log: IMU on /imu, its receiver's fixes on
// /gnss; a file without Xsens frames is refused.
TEST(Cli, ImportXsensImuStream) {
  const std::filesystem::path dir = std::filesystem::temp_directory_path() / fmt::format("hanzo_cli_xsens_{}", ::getpid());
  std::filesystem::create_directories(dir);
  const std::string stream = std::string(HANZO_DATA_DIR) + "/drivers/imu_xsens_mti_g710/testdata/3/output.bin";
  const CliRun imported = run(fmt::format("import xsens {} --out {}/imu.mcap --json", stream, dir.string()));
  ASSERT_EQ(imported.exit_code, 0) << imported.err;
  const nlohmann::json result = nlohmann::json::parse(imported.out);
  EXPECT_EQ(result["imu_messages"], 96);
  EXPECT_EQ(result["gnss_fixes"], 4);
  EXPECT_EQ(result["checksum_errors"], 0);
  EXPECT_EQ(result["device_clock"], 0);
  const CliRun info = run(fmt::format("log info {}/imu.mcap --json", dir.string()));
  ASSERT_EQ(info.exit_code, 0) << info.err;
  EXPECT_THAT(info.out, HasSubstr("\"/imu\""));
  EXPECT_THAT(info.out, HasSubstr("\"/gnss\""));
  const CliRun renamed = run(fmt::format("import xsens {} --out {}/renamed.mcap --topic /imu=/xsens/imu --json", stream, dir.string()));
  ASSERT_EQ(renamed.exit_code, 0) << renamed.err;
  EXPECT_EQ(nlohmann::json::parse(renamed.out)["topics"][0], "/xsens/imu");

  const CliRun not_xsens = run(fmt::format("import xsens README.md --out {}/x.mcap", dir.string()));
  EXPECT_EQ(not_xsens.exit_code, 1);
  EXPECT_THAT(not_xsens.err, HasSubstr("README.md: no Xsens frame"));
  EXPECT_EQ(std::count(not_xsens.err.begin(), not_xsens.err.end(), '\n'), 1);
  EXPECT_FALSE(std::filesystem::exists(dir / "x.mcap"));
  std::filesystem::remove_all(dir);
}

// A Velodyne VLP-16's packet capture into a sensor log: one cloud per rotation on /lidar with
// per-point times; an Ouster's frame and IMU packets; an unknown driver, a missing model or
// metadata and a file that is no capture are refused.
TEST(Cli, ImportVelodynePacketCapture) {
  const std::filesystem::path dir = std::filesystem::temp_directory_path() / fmt::format("hanzo_cli_pcap_{}", ::getpid());
  std::filesystem::create_directories(dir);
  const std::string veloview = std::string(HANZO_DATA_DIR) + "/drivers/velodyne_veloview/";
  const CliRun imported = run(fmt::format("import pcap {0}vlp-16-test-90deg-1-50-frames.pcap --driver velodyne --model VLP-16 "
                                          "--calibration {0}calib/VLP-16.xml --out {1}/lidar.mcap --json",
                                          veloview, dir.string()));
  ASSERT_EQ(imported.exit_code, 0) << imported.err;
  const nlohmann::json result = nlohmann::json::parse(imported.out);
  EXPECT_EQ(result["frames"], 52);
  EXPECT_EQ(result["packets"], 1902);
  EXPECT_EQ(result["position_packets"], 367);
  EXPECT_EQ(result["malformed_packets"], 0);
  const CliRun info = run(fmt::format("log info {}/lidar.mcap --json", dir.string()));
  ASSERT_EQ(info.exit_code, 0) << info.err;
  EXPECT_THAT(info.out, HasSubstr("\"/lidar\""));

  const CliRun unknown = run(fmt::format("import pcap {}vlp-16-test-90deg-1-50-frames.pcap --driver robosense --model VLP-16 --out {}/x.mcap", veloview, dir.string()));
  EXPECT_EQ(unknown.exit_code, 1);
  EXPECT_THAT(unknown.err, HasSubstr("--driver 'robosense'"));
  // An Ouster with its metadata: the frame on /lidar, its IMU packets on /imu; without metadata refused.
  const std::string ouster = std::string(HANZO_DATA_DIR) + "/drivers/ouster_sdk_pcaps/";
  const CliRun os1 = run(fmt::format("import pcap {0}OS-1-64_1024x10_fw20.pcap --driver ouster --metadata {0}OS-1-64_sensor_config_reduced.json "
                                     "--out {1}/os1.mcap --json",
                                     ouster, dir.string()));
  ASSERT_EQ(os1.exit_code, 0) << os1.err;
  const nlohmann::json os1_result = nlohmann::json::parse(os1.out);
  EXPECT_EQ(os1_result["frames"], 1);
  EXPECT_EQ(os1_result["incomplete_frames"], 0);
  EXPECT_EQ(os1_result["imu_samples"], 11);
  const CliRun no_metadata = run(fmt::format("import pcap {0}OS-1-64_1024x10_fw20.pcap --driver ouster --out {1}/x.mcap", ouster, dir.string()));
  EXPECT_EQ(no_metadata.exit_code, 1);
  EXPECT_THAT(no_metadata.err, HasSubstr("--metadata"));
  const CliRun no_model = run(fmt::format("import pcap {}vlp-16-test-90deg-1-50-frames.pcap --driver velodyne --out {}/x.mcap", veloview, dir.string()));
  EXPECT_EQ(no_model.exit_code, 1);
  EXPECT_THAT(no_model.err, HasSubstr("--model"));
  const CliRun not_capture = run(fmt::format("import pcap README.md --driver velodyne --model VLP-16 --out {}/x.mcap", dir.string()));
  EXPECT_EQ(not_capture.exit_code, 1);
  EXPECT_THAT(not_capture.err, HasSubstr("not a packet capture"));
  EXPECT_FALSE(std::filesystem::exists(dir / "x.mcap"));
  std::filesystem::remove_all(dir);
}

TEST(Cli, ImportRejectsBadCsvAndLeavesNoLog) {
  const std::filesystem::path dir = std::filesystem::temp_directory_path() / fmt::format("hanzo_cli_bad_{}", ::getpid());
  std::filesystem::create_directories(dir);
  const std::string csv = (dir / "imu.csv").string();
  std::ofstream(csv) << "timestamp_ns,ax,ay,az,wx,wy,wz\n100,0,0,9.8,0,0,0\n100,0,0,9.8,0,0,0\n";
  const std::string log = (dir / "out.mcap").string();
  const CliRun duplicate = run(fmt::format("import csv {} --out {}", csv, log));
  EXPECT_EQ(duplicate.exit_code, 1);
  EXPECT_THAT(duplicate.err, HasSubstr("imu.csv:3: timestamp 100 ns is not after the previous line's 100 ns"));
  EXPECT_FALSE(std::filesystem::exists(log));
  std::ofstream(csv) << "timestamp_ns,ax,ay,az,wx,wy,wz\n100,0,0,nan,0,0,0\n";
  const CliRun nan = run(fmt::format("import csv {} --out {}", csv, log));
  EXPECT_EQ(nan.exit_code, 1);
  EXPECT_THAT(nan.err, HasSubstr("imu.csv:2: "));
  EXPECT_THAT(nan.err, HasSubstr("linear_acceleration.z"));
  std::ofstream(csv) << "time,x\n1,2\n";
  EXPECT_THAT(run(fmt::format("import csv {} --out {}", csv, log)).err, HasSubstr("unknown CSV header 'time,x'"));
  const CliRun not_mcap = run(fmt::format("log info {}", csv));
  EXPECT_EQ(not_mcap.exit_code, 1);
  EXPECT_THAT(not_mcap.err, HasSubstr("not an MCAP file"));
  std::filesystem::remove_all(dir);
}

}  // namespace

namespace {

TEST(Cli, ImportRosbagTest2) {
  const std::string bag = std::string(HANZO_DATA_DIR) + "/robot_localization/test2.bag";
  const std::string log = (std::filesystem::temp_directory_path() / fmt::format("hanzo_cli_bag_{}.mcap", ::getpid())).string();
  const CliRun without_separation = run(fmt::format("import rosbag {} --out {}", bag, log));
  EXPECT_EQ(without_separation.exit_code, 1);
  EXPECT_THAT(without_separation.err, HasSubstr("--wheel-separation"));
  EXPECT_FALSE(std::filesystem::exists(log));
  EXPECT_FALSE(std::filesystem::exists(log + ".partial"));

  const CliRun imported = run(fmt::format(
      "import rosbag {} --out {} --wheel-separation 0.37 --topic /imu/data=/imu --topic /jackal_velocity_controller/odom=/wheels --json",
      bag, log));
  ASSERT_EQ(imported.exit_code, 0) << imported.err;
  const nlohmann::json json = nlohmann::json::parse(imported.out);
  EXPECT_EQ(json["messages"], 6121);
  EXPECT_EQ(json["bag"]["compressions"]["bz2"], json["bag"]["chunks"]);
  const CliRun info = run(fmt::format("log info {} --json", log));
  const nlohmann::json summary = nlohmann::json::parse(info.out);
  EXPECT_EQ(summary["channels"][0]["topic"], "/imu");
  EXPECT_EQ(summary["channels"][0]["messages"], 3061);
  EXPECT_EQ(summary["channels"][1]["topic"], "/wheels");
  EXPECT_EQ(summary["channels"][1]["messages"], 3060);
  EXPECT_NEAR(summary["duration_s"].get<double>(), 61.2, 0.01);
  std::filesystem::remove(log);
}

// The ROS 2 sample bag (examples/rosbag2_sample: written by Foxglove's libraries with
// tests/conformance/rosbag2_write.mjs): every sensor type, the calibration from /tf_static.
TEST(Cli, ImportRos2BagWithCalibration) {
  const std::filesystem::path dir = std::filesystem::temp_directory_path() / fmt::format("hanzo_cli_ros2_{}", ::getpid());
  std::filesystem::create_directories(dir);
  const std::string log = (dir / "bag.mcap").string(), calibration = (dir / "calibration.yaml").string();
  const CliRun without_separation = run(fmt::format("import ros2bag examples/rosbag2_sample --out {}", log));
  EXPECT_EQ(without_separation.exit_code, 1);
  EXPECT_THAT(without_separation.err, HasSubstr("--wheel-separation"));
  EXPECT_FALSE(std::filesystem::exists(log));
  const CliRun missing = run(fmt::format("import ros2bag {} --out {}", (dir / "nope").string(), log));
  EXPECT_EQ(missing.exit_code, 1);
  EXPECT_THAT(missing.err, HasSubstr("no such file or folder"));

  const CliRun imported = run(fmt::format(
      "import ros2bag examples/rosbag2_sample --out {} --wheel-separation 0.5 --calibration {} --json", log, calibration));
  ASSERT_EQ(imported.exit_code, 0) << imported.err;
  const nlohmann::json json = nlohmann::json::parse(imported.out);
  EXPECT_EQ(json["bag"]["storage"], "mcap");
  EXPECT_EQ(json["bag"]["messages"], 95);
  EXPECT_EQ(json["messages"], 92);  // all but /tf_static, CameraInfo and a std_msgs/String
  EXPECT_EQ(json["skipped_topics"]["/chatter"], "std_msgs/msg/String");
  EXPECT_EQ(json["body_frame"], "base_link");
  EXPECT_EQ(json["calibration_sensors"], 9);
  const auto loaded = hanzo::fusion::calib::load_calibration(calibration);
  ASSERT_TRUE(loaded.ok()) << loaded.error().message;
  ASSERT_NE(loaded->find("imu"), nullptr);
  EXPECT_EQ(loaded->find("imu")->translation, Eigen::Vector3d(0.1, 0.0, 0.2));
  ASSERT_TRUE(loaded->find("camera") && loaded->find("camera")->camera.has_value());
  const CliRun info = run(fmt::format("log info {} --json", log));
  const nlohmann::json summary = nlohmann::json::parse(info.out);
  std::map<std::string, int> messages;
  for (const auto& channel : summary["channels"]) messages[channel["topic"]] = channel["messages"];
  EXPECT_EQ(messages["/imu"], 50);
  EXPECT_EQ(messages["/ouster"], 3);
  EXPECT_EQ(messages["/camera"], 3);
  EXPECT_EQ(messages["/wheel"], 10);
  std::filesystem::remove_all(dir);
}

TEST(Cli, SimWritesLogGroundTruthCalibrationAndConfig) {
  const std::filesystem::path dir = std::filesystem::temp_directory_path() / fmt::format("hanzo_cli_sim_{}", ::getpid());
  std::filesystem::remove_all(dir);
  const CliRun simulated = run(fmt::format("sim examples/scenarios/warehouse_robot.yaml --out {} --duration 1 --json", dir.string()));
  ASSERT_EQ(simulated.exit_code, 0) << simulated.err;
  const nlohmann::json json = nlohmann::json::parse(simulated.out);
  EXPECT_EQ(json["name"], "warehouse_robot");
  EXPECT_EQ(json["ground_truth_poses"], 201);
  ASSERT_EQ(json["sensors"].size(), 4u);
  EXPECT_EQ(json["sensors"][0]["messages"], 201);  // IMU at 200 Hz
  EXPECT_EQ(json["sensors"][1]["messages"], 10);   // LiDAR sweeps that end by 1 s
  EXPECT_EQ(json["sensors"][2]["messages"], 16);   // camera at 15 Hz

  const CliRun info = run(fmt::format("log info {} --verify --json", (dir / "sensors.mcap").string()));
  ASSERT_EQ(info.exit_code, 0) << info.err;
  const nlohmann::json log = nlohmann::json::parse(info.out);
  std::set<std::string> topics;
  for (const auto& channel : log["channels"]) topics.insert(channel["topic"].get<std::string>());
  for (const char* topic : {"/sensors/imu", "/sensors/lidar", "/sensors/camera_front", "/sensors/wheels", "/ground_truth"}) {
    EXPECT_TRUE(topics.count(topic)) << topic;
  }
  EXPECT_FALSE(topics.count("/sensors/lidar/foxglove")) << "Foxglove mirrors are opt-in (--foxglove)";
  EXPECT_EQ(run(fmt::format("calib check {}", (dir / "calibration.yaml").string())).exit_code, 0);
  EXPECT_EQ(run(fmt::format("config check {}", (dir / "fusion.yaml").string())).exit_code, 0);
  std::ifstream truth(dir / "ground_truth.tum");
  std::size_t lines = 0;
  for (std::string line; std::getline(truth, line);) lines += line.empty() || line[0] == '#' ? 0 : 1;
  EXPECT_EQ(lines, 201u);
  EXPECT_TRUE(std::filesystem::exists(dir / "imu_biases.csv"));

  const CliRun bad = run(fmt::format("sim {} --out {}", write_temp("bad_scenario.yaml", "scenario: {name: x}\n"), dir.string()));
  EXPECT_EQ(bad.exit_code, 1);
  EXPECT_THAT(bad.err, HasSubstr("trajectory: missing"));
  EXPECT_EQ(std::count(bad.err.begin(), bad.err.end(), '\n'), 1);
  const CliRun negative = run(fmt::format("sim examples/scenarios/drone.yaml --out {} --duration -3", dir.string()));
  EXPECT_EQ(negative.exit_code, 1);
  EXPECT_THAT(negative.err, HasSubstr("--duration: expected seconds > 0, got -3"));
  std::filesystem::remove_all(dir);
}

}  // namespace

TEST(Cli, RunReplaysTheSampleAndScoresItAgainstGroundTruth) {
  const std::filesystem::path dir = std::filesystem::temp_directory_path() / fmt::format("hanzo_cli_run_{}", ::getpid());
  std::filesystem::remove_all(dir);
  std::filesystem::create_directories(dir);
  const std::string log = (dir / "sample.mcap").string();
  ASSERT_EQ(run(fmt::format("import csv examples/data/imu.csv examples/data/gnss.csv examples/data/wheels.csv --out {}", log)).exit_code, 0);
  const CliRun replay = run(fmt::format("run --config examples/data/fusion.yaml --log {} --out {} --gt examples/data/ground_truth.tum --json",
                                        log, (dir / "run").string()));
  ASSERT_EQ(replay.exit_code, 0) << replay.err;
  const nlohmann::json json = nlohmann::json::parse(replay.out);
  EXPECT_EQ(json["summary"]["filter"], "ekf");
  EXPECT_EQ(json["summary"]["poses"], 1901);  // 100 Hz IMU after 1 s of alignment
  EXPECT_EQ(json["summary"]["sensors"][1]["name"], "gnss");
  EXPECT_EQ(json["summary"]["sensors"][1]["fused"], 96);
  // The sample's wheels are perfect and its speed and turn rate constant: the wheels' heading
  // drift (estimated because their yaw rate is fused) cannot be told from the gyro bias, which
  // costs 0.05 m against a filter told the wheels are exact (0.13 m).
  EXPECT_LT(json["evaluation"]["ape_se3_aligned_rmse_m"].get<double>(), 0.2);
  EXPECT_LT(json["evaluation"]["rpe_1m_rmse_m"].get<double>(), 0.06);
  EXPECT_NEAR(json["summary"]["wheel_speed_scale"]["value"].get<double>(), 1.0, 3.0 * json["summary"]["wheel_speed_scale"]["sigma"].get<double>());
  EXPECT_NEAR(json["summary"]["gyro_yaw_scale"]["value"].get<double>(), 1.0, 3.0 * json["summary"]["gyro_yaw_scale"]["sigma"].get<double>());
  EXPECT_NEAR(json["summary"]["wheel_heading_drift"]["value"].get<double>(), 0.0,
              3.0 * json["summary"]["wheel_heading_drift"]["sigma"].get<double>());
  // One spelling per concept in every command: --ground-truth / --calibration, with --gt / --calib.
  const CliRun spelled = run(fmt::format("run --config examples/data/fusion.yaml --log {} --out {} --ground-truth examples/data/ground_truth.tum --json",
                                         log, (dir / "run_spelled").string()));
  ASSERT_EQ(spelled.exit_code, 0) << spelled.err;
  EXPECT_EQ(nlohmann::json::parse(spelled.out)["evaluation"]["ape_rmse_m"], json["evaluation"]["ape_rmse_m"]);
  for (const char* command : {"run", "lidar-odometry", "import", "stream", "map build"}) {
    const CliRun help = run(fmt::format("{} --help", command));
    EXPECT_THAT(help.out, HasSubstr("--calibration,--calib")) << command;
  }
  EXPECT_EQ(json["summary"]["keyframes"], 19);  // 1 Hz after alignment
  for (const char* file : {"trajectory.tum", "trajectory_optimized.tum", "poses.csv", "innovations.csv", "keyframes.csv", "summary.json",
                           "trajectory.svg", "covariance.svg"}) {
    EXPECT_TRUE(std::filesystem::exists(dir / "run" / file)) << file;
  }
  // Bad input: a configuration without sensors, a missing log; one line on stderr, exit 1.
  const std::string no_sensors = write_temp("no_sensors.yaml", "fusion:\n  sensors: {}\n");
  const CliRun refused = run(fmt::format("run --config {} --log {} --out {}", no_sensors, log, (dir / "bad").string()));
  EXPECT_EQ(refused.exit_code, 1);
  EXPECT_THAT(refused.err, HasSubstr("no sensors"));
  EXPECT_EQ(std::count(refused.err.begin(), refused.err.end(), '\n'), 1);
  const CliRun missing = run(fmt::format("run --config examples/data/fusion.yaml --log {} --out {}", (dir / "none.mcap").string(),
                                         (dir / "bad").string()));
  EXPECT_EQ(missing.exit_code, 1);
  EXPECT_THAT(missing.err, HasSubstr("none.mcap"));
  // A configuration none of whose topics is in the log fuses nothing: refused, naming both.
  const std::string other_topics = write_temp("other_topics.yaml", "fusion:\n  sensors:\n    imu:\n      topic: /other/imu\n      rate: 100\n");
  const CliRun unmatched = run(fmt::format("run --config {} --log {} --out {}", other_topics, log, (dir / "bad").string()));
  EXPECT_EQ(unmatched.exit_code, 1);
  EXPECT_THAT(unmatched.err, HasSubstr("has none of the configured sensors' topics (/other/imu); its topics: /gnss, /imu, /wheels"));
  // A calibration that leaves sensors out: refused, naming the entry to add.
  const std::string imu_only = write_temp("imu_only_calibration.yaml", "calibration:\n  imu_to_body: identity\n");
  const CliRun uncalibrated = run(fmt::format("run --config examples/data/fusion.yaml --calib {} --log {} --out {}", imu_only, log,
                                              (dir / "bad").string()));
  EXPECT_EQ(uncalibrated.exit_code, 1);
  EXPECT_THAT(uncalibrated.err, HasSubstr("no 'gnss_to_body' entry for sensor 'gnss'"));
  // A corrupted log: what could be read is replayed and written, and the run fails unless the
  // user accepts a partial log.
  std::string bytes = file_bytes(log);
  for (std::size_t i = 0; i < 4; ++i) bytes[bytes.size() / 2 + i] = static_cast<char>(0xA5);
  const std::string corrupted = (dir / "corrupted.mcap").string();
  std::ofstream(corrupted, std::ios::binary) << bytes;
  const CliRun partial = run(fmt::format("run --config examples/data/fusion.yaml --log {} --out {}", corrupted, (dir / "partial").string()));
  EXPECT_EQ(partial.exit_code, 1);
  EXPECT_THAT(partial.err, HasSubstr("partial log: 1 corrupted chunk skipped"));
  EXPECT_THAT(partial.err, HasSubstr("--allow-partial"));
  std::ifstream summary_file(dir / "partial" / "summary.json");
  ASSERT_TRUE(summary_file.good());
  const nlohmann::json partial_summary = nlohmann::json::parse(summary_file);
  EXPECT_EQ(partial_summary["ok"], false);
  EXPECT_EQ(partial_summary["partial"], true);
  const CliRun accepted = run(fmt::format("run --config examples/data/fusion.yaml --log {} --out {} --allow-partial --json", corrupted,
                                          (dir / "accepted").string()));
  EXPECT_EQ(accepted.exit_code, 0) << accepted.err;
  const nlohmann::json accepted_json = nlohmann::json::parse(accepted.out);
  EXPECT_EQ(accepted_json["partial"], true);
  EXPECT_THAT(accepted_json["incomplete"].get<std::string>(), HasSubstr("corrupted chunk"));
  // The other readers of a log say so too: exporting a cut-off log fails naming what was lost.
  const std::string whole = file_bytes(log), cut = (dir / "cut.mcap").string();
  std::ofstream(cut, std::ios::binary) << whole.substr(0, whole.size() * 2 / 3);
  const CliRun cut_export = run(fmt::format("log export {} --topic /imu --out {}", cut, (dir / "imu.csv").string()));
  EXPECT_EQ(cut_export.exit_code, 1);
  EXPECT_THAT(cut_export.err, HasSubstr("file is truncated"));
  const CliRun cut_run = run(fmt::format("run --config examples/data/fusion.yaml --log {} --out {}", cut, (dir / "cut_run").string()));
  EXPECT_EQ(cut_run.exit_code, 1);
  EXPECT_THAT(cut_run.err, HasSubstr("partial log: "));
  EXPECT_THAT(cut_run.err, HasSubstr("file is truncated"));
  std::filesystem::remove_all(dir);
}

// The whole pipeline through `run` (IMU + wheels + LiDAR in the simulated warehouse): the real-time
// and the optimized trajectory, the map; the same log twice, on one and on two threads, gives
// the same files byte for byte (replay mode: no background work, no wall clock).
// A camera-only configuration (the simulated drone's stereo pair, no IMU) runs through `run`:
// the cameras' visual odometry is the whole estimate.
TEST(Cli, RunTracksACameraOnlyConfigurationWithVisualOdometry) {
  const std::filesystem::path dir = std::filesystem::temp_directory_path() / fmt::format("hanzo_cli_run_cameras_{}", ::getpid());
  std::filesystem::remove_all(dir);
  const CliRun simulated = run(fmt::format("sim examples/scenarios/drone.yaml --out {} --duration 5 --sensors camera_left,camera_right "
                                           "--threads 0 --no-foxglove",
                                           (dir / "sim").string()));
  ASSERT_EQ(simulated.exit_code, 0) << simulated.err;
  const CliRun replayed = run(fmt::format("run --config {0}/fusion.yaml --calib {0}/calibration.yaml --log {0}/sensors.mcap --out {1} "
                                          "--gt {0}/ground_truth.tum --json",
                                          (dir / "sim").string(), (dir / "run").string()));
  ASSERT_EQ(replayed.exit_code, 0) << replayed.err;
  EXPECT_EQ(replayed.err, "");  // no sensor warnings: the right camera is heard through the pairs
  const nlohmann::json json = nlohmann::json::parse(replayed.out);
  EXPECT_EQ(json["mapping"]["camera_frames_tracked"], 51);  // 10 Hz over 5 s, both ends
  EXPECT_EQ(json["mapping"]["camera_frames_lost"], 0);
  EXPECT_EQ(json["mapping"]["visual_scale_free"], false);
  EXPECT_GT(json["mapping"]["camera_mapping_ms"].get<double>(), 0.0);  // the keyframes' local mapping was timed
  EXPECT_LT(json["evaluation"]["ape_se3_aligned_rmse_m"].get<double>(), 0.1);  // 4.9 m flown; measured 0.047 m
  // Each camera's images add up (a pair's outcomes shown on both cameras).
  for (const auto& camera : json["summary"]["sensors"]) {
    int accounted = camera["fused"].get<int>();
    for (const auto& [reason, count] : camera["rejected"].items()) accounted += count.get<int>();
    EXPECT_EQ(accounted, camera["received"].get<int>()) << camera.dump();
  }

  // The run's map carries the odometry's landmarks, and a camera image is placed in it.
  using namespace hanzo::fusion;
  const std::string map = (dir / "run" / "map.fmap").string();
  const CliRun info = run(fmt::format("map info {} --json", map));
  ASSERT_EQ(info.exit_code, 0) << info.err;
  EXPECT_GT(nlohmann::json::parse(info.out)["layers"]["visual_landmarks"]["landmarks"].get<int>(), 500);
  const CliRun exported = run(fmt::format("log export {}/sensors.mcap --topic /sensors/camera_left --format png --out {} --json", (dir / "sim").string(),
                                          (dir / "left").string()));
  ASSERT_EQ(exported.exit_code, 0) << exported.err;
  EXPECT_EQ(nlohmann::json::parse(exported.out)["messages"], 51);
  std::vector<std::string> images;
  for (const auto& file : std::filesystem::directory_iterator(dir / "left")) images.push_back(file.path().string());
  std::sort(images.begin(), images.end());
  ASSERT_EQ(images.size(), 51u);
  const std::string image_path = images[39];
  const Timestamp image_time = Timestamp::from_nanoseconds(std::stoll(std::filesystem::path(image_path).stem().string()));
  const CliRun not_images = run(fmt::format("log export {}/sensors.mcap --topic /sensors/camera_left --format png", (dir / "sim").string()));
  EXPECT_EQ(not_images.exit_code, 1);
  EXPECT_THAT(not_images.err, HasSubstr("needs --out FOLDER"));
  const CliRun placed = run(fmt::format("vision relocalize {} {} --calib {}/calibration.yaml --json", map, image_path, (dir / "sim").string()));
  ASSERT_EQ(placed.exit_code, 0) << placed.err;
  const nlohmann::json pose = nlohmann::json::parse(placed.out);
  EXPECT_GE(pose["inliers"].get<int>(), 30);
  const io::Trajectory trajectory = io::read_trajectory((dir / "run" / "trajectory.tum").string(), io::TrajectoryFormat::kTum).value();
  const auto& position = pose["T_world_body"]["position"];
  double nearest = 1e9;
  for (std::size_t i = 0; i < trajectory.size(); ++i) {
    if (std::abs((trajectory.timestamps[i] - image_time).seconds()) > 0.01) continue;
    nearest = std::min(nearest, (trajectory.position(i) - Eigen::Vector3d(position[0].get<double>(), position[1].get<double>(), position[2].get<double>())).norm());
  }
  EXPECT_LT(nearest, 0.1);
  const CliRun wrong_size = run(fmt::format("vision relocalize {} {}/graf1.png --calib {}/calibration.yaml", map,
                                            std::string(HANZO_DATA_DIR) + "/feature_matching_graf", (dir / "sim").string()));
  EXPECT_EQ(wrong_size.exit_code, 1);
  EXPECT_THAT(wrong_size.err, HasSubstr("is calibrated for 640 x 480"));
  std::filesystem::remove_all(dir);
}

TEST(Cli, RunMapsWithTheWholePipelineAndReplaysBitIdenticallyOnAnyThreadCount) {
  const std::filesystem::path dir = std::filesystem::temp_directory_path() / fmt::format("hanzo_cli_run_lidar_{}", ::getpid());
  std::filesystem::remove_all(dir);
  const CliRun simulated = run(fmt::format("sim examples/scenarios/warehouse_robot.yaml --out {} --duration 25 --sensors imu,lidar,wheels "
                                           "--threads 0 --no-foxglove",
                                           (dir / "sim").string()));
  ASSERT_EQ(simulated.exit_code, 0) << simulated.err;
  const auto replay = [&](int threads) {
    const std::filesystem::path out = dir / fmt::format("run{}", threads);
    const CliRun replayed = run(fmt::format("run --config {0}/fusion.yaml --calib {0}/calibration.yaml --log {0}/sensors.mcap --out {1} "
                                            "--gt {0}/ground_truth.tum --threads {2} --json",
                                            (dir / "sim").string(), out.string(), threads));
    EXPECT_EQ(replayed.exit_code, 0) << replayed.err;
    // Every sensor publishes at its rate: none is reported silent (the LiDAR's sweeps, heard
    // before their registration gives a pose, and the wheels withheld while they slip).
    EXPECT_THAT(replayed.err, ::testing::Not(HasSubstr("timed out"))) << replayed.err;
    return nlohmann::json::parse(replayed.out.empty() ? "{}" : replayed.out);
  };
  const nlohmann::json one = replay(1);
  const nlohmann::json two = replay(2);
  ASSERT_TRUE(one.contains("mapping")) << one.dump();
  EXPECT_EQ(one["mode"], "replay");
  EXPECT_GT(one["mapping"]["scans_registered"].get<int>(), 200);
  EXPECT_GT(one["mapping"]["map_keyframes"].get<int>(), 5);
  EXPECT_GT(one["mapping"]["graph_keyframes"].get<int>(), 15);
  for (const char* key : {"evaluation", "evaluation_tracking", "evaluation_optimized"}) {
    ASSERT_TRUE(one[key].contains("ape_se3_aligned_rmse_m")) << one[key].dump();
    EXPECT_LT(one[key]["ape_se3_aligned_rmse_m"].get<double>(), 0.1) << key;
  }
  for (const char* file : {"trajectory.tum", "trajectory_optimized.tum", "map.fmap", "map.png", "map_points.png", "keyframes.csv", "poses.csv"}) {
    const std::string first = file_bytes(dir / "run1" / file);
    EXPECT_FALSE(first.empty()) << file;
    EXPECT_TRUE(first == file_bytes(dir / "run2" / file)) << file << " differs between --threads 1 and --threads 2";
  }
  // The run's poses (with covariances) and map as a ROS 2 bag.
  const CliRun exported = run(fmt::format("export ros2bag --out {} --poses {} --map {} --json", (dir / "ros2").string(),
                                          (dir / "run1" / "poses.csv").string(), (dir / "run1" / "map.fmap").string()));
  ASSERT_EQ(exported.exit_code, 0) << exported.err;
  const nlohmann::json bag = nlohmann::json::parse(exported.out);
  EXPECT_EQ(bag["topics"]["/trajectory"], 1);
  EXPECT_EQ(bag["topics"]["/map/points"], 1);
  EXPECT_EQ(bag["topics"]["/map/occupancy"], 1);
  EXPECT_GT(bag["topics"]["/pose"].get<int>(), 100);
  EXPECT_TRUE(std::filesystem::exists(dir / "ros2" / "metadata.yaml"));
  // The sweeps with the optimized poses as training data, in both layouts.
  for (const std::string layout : {"kitti", "nuscenes"}) {
    const CliRun dataset = run(fmt::format("export dataset {0}/sensors.mcap --trajectory {1}/trajectory_optimized.tum --calib {0}/calibration.yaml "
                                           "--out {2} --layout {3} --json",
                                           (dir / "sim").string(), (dir / "run1").string(), (dir / layout).string(), layout));
    ASSERT_EQ(dataset.exit_code, 0) << dataset.err;
    const nlohmann::json summary = nlohmann::json::parse(dataset.out);
    EXPECT_EQ(summary["reference_messages"], 250);
    EXPECT_GT(summary["frames"].get<int>(), 230);  // the sweeps before the IMU aligned have no pose
    EXPECT_EQ(summary["frames"].get<int>() + summary["left_out_outside_trajectory"].get<int>(), 250);
    EXPECT_EQ(summary["deskewed_sweeps"], summary["frames"]);
    EXPECT_EQ(summary["files_by_sensor"]["lidar"], summary["frames"]);
  }
  EXPECT_TRUE(std::filesystem::exists(dir / "kitti" / "poses" / "00.txt"));
  EXPECT_TRUE(std::filesystem::exists(dir / "nuscenes" / "v1.0-hanzo" / "sample_data.json"));
  std::filesystem::remove_all(dir);
}

// A simulated robot (IMU, LiDAR with per-point times, wheels) through ROS 2: exported
// with each LiDAR driver's point layout, imported back and run, it is estimated as from the
// original log (wheel odometry travels as twists and is re-integrated, LiDAR times as the
// drivers store them).
// --lidar-labels: a SemanticKITTI .label file per sweep, one label per point of the sweep in the
// log, the class table beside them; the cars and people that drive and walk have instances.
TEST(Cli, SimWritesPerPointLidarLabels) {
  const std::filesystem::path dir = std::filesystem::temp_directory_path() / fmt::format("hanzo_cli_sim_labels_{}", ::getpid());
  std::filesystem::remove_all(dir);
  const CliRun simulated =
      run(fmt::format("sim examples/scenarios/urban_traffic.yaml --out {} --duration 3 --sensors lidar --lidar-labels --json", dir.string()));
  ASSERT_EQ(simulated.exit_code, 0) << simulated.err;
  const nlohmann::json json = nlohmann::json::parse(simulated.out);
  ASSERT_EQ(json["sensors"].size(), 1u);
  const std::size_t sweeps = json["sensors"][0]["messages"], points = json["sensors"][0]["elements"];
  std::size_t labelled = 0, on_movers = 0, files = 0;
  std::set<uint32_t> classes, instances;
  for (const auto& entry : std::filesystem::directory_iterator(dir / "lidar_labels" / "lidar")) {
    ++files;
    std::ifstream file(entry.path(), std::ios::binary);
    uint32_t label = 0;
    while (file.read(reinterpret_cast<char*>(&label), sizeof(label))) {
      ++labelled;
      classes.insert(label & 0xFFFFU);
      if ((label >> 16U) != 0) {
        ++on_movers;
        instances.insert(label >> 16U);
      }
    }
  }
  EXPECT_EQ(files, sweeps);
  EXPECT_EQ(labelled, points);
  EXPECT_GT(on_movers, 100u);
  EXPECT_GE(instances.size(), 2u);
  std::ifstream table(dir / "lidar_labels" / "classes.yaml");
  const std::string text((std::istreambuf_iterator<char>(table)), std::istreambuf_iterator<char>());
  for (const char* line : {"0: unlabelled", "1: ground", "car", "person"}) EXPECT_NE(text.find(line), std::string::npos) << line;
  EXPECT_GE(classes.size(), 3u);
  std::filesystem::remove_all(dir);
}

TEST(Cli, SimulatedLogThroughRos2BagsOfEachLidarLayoutRunsLikeTheOriginal) {
  const std::filesystem::path dir = std::filesystem::temp_directory_path() / fmt::format("hanzo_cli_ros2_trip_{}", ::getpid());
  std::filesystem::remove_all(dir);
  const std::string sim = (dir / "sim").string();
  ASSERT_EQ(run(fmt::format("sim examples/scenarios/warehouse_robot.yaml --out {} --duration 20 --no-foxglove --sensors imu,lidar,wheels",
                sim)).exit_code, 0);
  auto run_log = [&](const std::string& log, const std::string& out) {
    const CliRun ran = run(fmt::format("run --config {0}/fusion.yaml --calib {0}/calibration.yaml --log {1} --out {2} --gt {0}/ground_truth.tum --json",
                                       sim, log, out));
    EXPECT_EQ(ran.exit_code, 0) << ran.err;
    return nlohmann::json::parse(ran.out.empty() ? "{}" : ran.out);
  };
  // 20 s: the robot has turned, so the SE3 alignment is determined.
  const nlohmann::json direct = run_log(sim + "/sensors.mcap", (dir / "direct").string());
  ASSERT_TRUE(direct.contains("evaluation") && direct["evaluation"]["ape_se3_aligned_rmse_m"].is_number()) << direct.dump();
  const double direct_ape = direct["evaluation"]["ape_se3_aligned_rmse_m"];
  for (const std::string layout : {"velodyne", "ouster", "livox", "hesai"}) {
    SCOPED_TRACE(layout);
    const std::string bag = (dir / layout).string(), log = bag + ".mcap";
    const CliRun exported = run(fmt::format("export ros2bag --log {}/sensors.mcap --lidar-layout {} --out {} --json", sim, layout, bag));
    ASSERT_EQ(exported.exit_code, 0) << exported.err;
    EXPECT_GT(nlohmann::json::parse(exported.out)["left_out"]["/ground_truth"].get<int>(), 0);  // estimates have no sensor type
    // The bag records the log's topic and sensor names and the wheel separation: imported as it
    // is, it gives back the same log. Topic maps and a separation given by hand still apply.
    std::string options;
    if (layout != "velodyne") {
      options = " --wheel-separation 0.5";
      for (const char* topic : {"/sensors/imu", "/sensors/lidar", "/sensors/wheels"}) options += fmt::format(" --topic {0}={0}", topic);
    }
    const CliRun imported = run(fmt::format("import ros2bag {} --out {}{} --json", bag, log, options));
    ASSERT_EQ(imported.exit_code, 0) << imported.err;
    const nlohmann::json import_report = nlohmann::json::parse(imported.out);  // kept: the loop reads into it
    for (const auto& topic : import_report["topics"]) EXPECT_EQ(topic["rejected"], 0) << topic.dump();
    if (layout == "velodyne") {
      std::set<std::string> topics;
      for (const auto& topic : import_report["topics"]) topics.insert(topic["topic"].get<std::string>());
      EXPECT_EQ(topics, (std::set<std::string>{"/sensors/imu", "/sensors/lidar", "/sensors/wheels"}));
    }
    const nlohmann::json replayed = run_log(log, bag + "_run");
    ASSERT_TRUE(replayed.contains("evaluation") && replayed["evaluation"]["ape_se3_aligned_rmse_m"].is_number()) << replayed.dump();
    EXPECT_NEAR(replayed["evaluation"]["ape_se3_aligned_rmse_m"].get<double>(), direct_ape, 0.002);
    EXPECT_EQ(replayed["mapping"]["scans_registered"], direct["mapping"]["scans_registered"]);
  }
  std::filesystem::remove_all(dir);
}

// A camera with a detector and a segmenter through a ROS 2 bag: the log's DetectionsMessages go
// out as vision_msgs/Detection2DArray, label images and LabelInfo, and come back the same.
TEST(Cli, DetectionsAndSegmentationThroughRos2ComeBackTheSame) {
  const std::filesystem::path dir = std::filesystem::temp_directory_path() / fmt::format("hanzo_cli_ros2_vision_{}", ::getpid());
  std::filesystem::remove_all(dir);
  std::filesystem::create_directories(dir);
  std::ifstream in("examples/scenarios/warehouse_segmented.yaml");
  std::string scenario((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  const std::string segmenter = "      segmentation: true";
  ASSERT_NE(scenario.find(segmenter), std::string::npos);
  scenario.replace(scenario.find(segmenter), segmenter.size(), "      detections: boxes\n" + segmenter);
  std::ofstream((dir / "scenario.yaml").string()) << scenario;
  const std::string sim = (dir / "sim").string(), bag = (dir / "bag").string(), back = (dir / "back.mcap").string();
  ASSERT_EQ(run(fmt::format("sim {}/scenario.yaml --out {} --duration 8 --no-foxglove --sensors camera_front", dir.string(), sim)).exit_code, 0);
  const CliRun exported = run(fmt::format("export ros2bag --log {}/sensors.mcap --out {} --json", sim, bag));
  ASSERT_EQ(exported.exit_code, 0) << exported.err;
  const nlohmann::json topics = nlohmann::json::parse(exported.out)["topics"];
  EXPECT_EQ(topics["/sensors/camera_front/detections"], topics["/sensors/camera_front"]);
  EXPECT_EQ(topics["/sensors/camera_front/segmentation"], topics["/sensors/camera_front"]);
  EXPECT_EQ(topics["/sensors/camera_front/label_info"], 1);
  const CliRun imported = run(fmt::format("import ros2bag {} --out {} --json", bag, back));
  ASSERT_EQ(imported.exit_code, 0) << imported.err;
  for (const auto& topic : nlohmann::json::parse(imported.out)["topics"]) EXPECT_EQ(topic["rejected"], 0) << topic.dump();

  namespace hf = hanzo::fusion;
  const auto original = messages_of<hf::msgs::DetectionsMessage>(sim + "/sensors.mcap", "/sensors/camera_front/detections");
  const auto returned = messages_of<hf::msgs::DetectionsMessage>(back, "/sensors/camera_front/detections");
  ASSERT_EQ(returned.size(), original.size());
  std::size_t boxes = 0;
  for (std::size_t i = 0; i < original.size(); ++i) {
    EXPECT_EQ(returned[i].timestamp, original[i].timestamp) << i;
    EXPECT_EQ(returned[i].image_width, original[i].image_width);
    EXPECT_EQ(returned[i].segmentation, original[i].segmentation) << i;
    EXPECT_EQ(returned[i].segmentation_classes, original[i].segmentation_classes) << i;
    ASSERT_EQ(returned[i].detections.size(), original[i].detections.size()) << i;
    for (std::size_t k = 0; k < original[i].detections.size(); ++k, ++boxes) {
      const hf::msgs::Detection2D &a = returned[i].detections[k], &b = original[i].detections[k];
      EXPECT_EQ(a.class_name, b.class_name);
      EXPECT_EQ(a.score, b.score);
      EXPECT_EQ(a.track_id, b.track_id);
      EXPECT_EQ(std::make_tuple(a.x_min, a.y_min, a.x_max, a.y_max), std::make_tuple(b.x_min, b.y_min, b.x_max, b.y_max)) << i << " " << k;
    }
  }
  EXPECT_GT(boxes, 10u) << "people walk through the camera's view";
  std::filesystem::remove_all(dir);
}

// A stereo camera drone (IMU + two cameras) through a ROS 2 bag (sqlite3 storage): images as
// sensor_msgs/CompressedImage, the calibration as /tf_static and CameraInfo. Imported back, the calibration is the original
// and the run (visual-inertial) gives the same trajectory.
TEST(Cli, StereoCameraBagThroughRos2CarriesItsCalibrationAndRunsLikeTheOriginal) {
  const std::filesystem::path dir = std::filesystem::temp_directory_path() / fmt::format("hanzo_cli_ros2_camera_{}", ::getpid());
  std::filesystem::remove_all(dir);
  const std::string sim = (dir / "sim").string(), bag = (dir / "bag").string();
  ASSERT_EQ(run(fmt::format("sim examples/scenarios/drone.yaml --out {} --duration 10 --no-foxglove", sim)).exit_code, 0);
  const CliRun exported = run(fmt::format("export ros2bag --log {0}/sensors.mcap --calib {0}/calibration.yaml --storage sqlite3 --out {1} --json",
                                          sim, bag));
  ASSERT_EQ(exported.exit_code, 0) << exported.err;
  const nlohmann::json topics = nlohmann::json::parse(exported.out)["topics"];
  EXPECT_EQ(topics["/tf_static"], 1);
  EXPECT_EQ(topics["/sensors/camera_left/camera_info"], topics["/sensors/camera_left"]);
  // The log's JPEG images go out unchanged as CompressedImage: the bag is about the log's size
  // (as raw Images it is several times larger).
  std::uintmax_t bag_bytes = 0;
  for (const auto& file : std::filesystem::recursive_directory_iterator(bag)) {
    if (file.is_regular_file()) bag_bytes += file.file_size();
  }
  EXPECT_LT(static_cast<double>(bag_bytes), 1.5 * static_cast<double>(std::filesystem::file_size(sim + "/sensors.mcap")));
  const CliRun imported = run(fmt::format("import ros2bag {0} --out {1}/back.mcap --calibration {1}/back_calibration.yaml --json", bag,
                                          dir.string()));
  ASSERT_EQ(imported.exit_code, 0) << imported.err;
  auto original = hanzo::fusion::calib::load_calibration(sim + "/calibration.yaml");
  auto back = hanzo::fusion::calib::load_calibration((dir / "back_calibration.yaml").string());
  ASSERT_TRUE(original.ok() && back.ok());
  for (const hanzo::fusion::calib::SensorCalibration& sensor : original->sensors) {
    const hanzo::fusion::calib::SensorCalibration* found = back->find(sensor.sensor);
    ASSERT_NE(found, nullptr) << sensor.sensor;
    EXPECT_TRUE(found->T_body_sensor().matrix().isApprox(sensor.T_body_sensor().matrix(), 1e-12)) << sensor.sensor;
    ASSERT_EQ(found->camera.has_value(), sensor.camera.has_value()) << sensor.sensor;
    if (sensor.camera) {
      EXPECT_EQ(found->camera->intrinsics.fx, sensor.camera->intrinsics.fx);
      EXPECT_EQ(found->camera->intrinsics.cx, sensor.camera->intrinsics.cx);
      EXPECT_EQ(found->camera->distortion.coefficients, sensor.camera->distortion.coefficients);  // the exported calibration itself
    }
    EXPECT_EQ(found->time_offset, sensor.time_offset) << sensor.sensor;
  }
  // The bag keeps the log's topics: the original configuration reads the imported log.
  auto run_log = [&](const std::string& config_path, const std::string& calibration, const std::string& log, const std::string& out) {
    const CliRun ran = run(fmt::format("run --config {} --calib {} --log {} --out {} --gt {}/ground_truth.tum --json", config_path, calibration,
                                       log, out, sim));
    EXPECT_EQ(ran.exit_code, 0) << ran.err;
    return nlohmann::json::parse(ran.out.empty() ? "{}" : ran.out);
  };
  const nlohmann::json direct = run_log(sim + "/fusion.yaml", sim + "/calibration.yaml", sim + "/sensors.mcap", (dir / "direct").string());
  const nlohmann::json replayed = run_log(sim + "/fusion.yaml", (dir / "back_calibration.yaml").string(),
                                          (dir / "back.mcap").string(), (dir / "back_run").string());
  ASSERT_TRUE(direct.contains("evaluation") && replayed.contains("evaluation")) << replayed.dump();
  EXPECT_GT(replayed["mapping"]["camera_frames_tracked"].get<int>(), 90);
  EXPECT_EQ(replayed["mapping"]["camera_frames_tracked"], direct["mapping"]["camera_frames_tracked"]);
  EXPECT_NEAR(replayed["evaluation"]["ape_se3_aligned_rmse_m"].get<double>(), direct["evaluation"]["ape_se3_aligned_rmse_m"].get<double>(), 1e-3);
  std::filesystem::remove_all(dir);
}

TEST(Cli, ExportRos2BagRefusesBadInputAndLeavesNothingBehind) {
  const std::filesystem::path dir = std::filesystem::temp_directory_path() / fmt::format("hanzo_cli_export_{}", ::getpid());
  std::filesystem::remove_all(dir);
  const CliRun exported = run(fmt::format("export ros2bag --out {} --trajectory examples/data/ground_truth.tum --json", dir.string()));
  ASSERT_EQ(exported.exit_code, 0) << exported.err;
  const nlohmann::json json = nlohmann::json::parse(exported.out);
  EXPECT_EQ(json["topics"]["/trajectory"], 1);
  EXPECT_GT(json["topics"]["/pose"].get<int>(), 10);
  const CliRun again = run(fmt::format("export ros2bag --out {} --trajectory examples/data/ground_truth.tum", dir.string()));
  EXPECT_EQ(again.exit_code, 1);
  EXPECT_THAT(again.err, HasSubstr("exists"));
  EXPECT_TRUE(std::filesystem::exists(dir / "metadata.yaml"));  // the first bag is untouched
  const std::string other = dir.string() + "_2";
  const CliRun nothing = run(fmt::format("export ros2bag --out {}", other));
  EXPECT_EQ(nothing.exit_code, 1);
  EXPECT_THAT(nothing.err, HasSubstr("nothing to export"));
  const CliRun not_poses = run(fmt::format("export ros2bag --out {} --poses examples/data/ground_truth.tum", other));
  EXPECT_EQ(not_poses.exit_code, 1);
  EXPECT_THAT(not_poses.err, HasSubstr("no column 'timestamp_ns'"));
  const CliRun no_map = run(fmt::format("export ros2bag --out {} --map {}/missing.fmap", other, dir.string()));
  EXPECT_EQ(no_map.exit_code, 1);
  EXPECT_FALSE(std::filesystem::exists(other));
  std::filesystem::remove_all(dir);
}

// Learned place recognition's commands refuse what they cannot use, in one line, writing nothing.
TEST(Cli, VisionVladAndPlaceRecallRefuseBadInputWithOneLine) {
  const std::string graf = std::string(HANZO_DATA_DIR) + "/feature_matching_graf";
  const std::string out = (std::filesystem::temp_directory_path() / "hanzo_cli_orb.hzvlad").string();
  const CliRun orb = run(fmt::format("vision vlad {0}/graf1.png {0}/graf2.png --detector orb --out {1}", graf, out));
  EXPECT_EQ(orb.exit_code, 1);
  EXPECT_THAT(orb.err, HasSubstr("VLAD aggregates learned (float) descriptors"));
  EXPECT_EQ(std::count(orb.err.begin(), orb.err.end(), '\n'), 1);
  EXPECT_FALSE(std::filesystem::exists(out));
  const CliRun not_model = run(fmt::format("vision place-recall --database day.mcap --database-poses day.tum --queries dusk.mcap --query-poses dusk.tum --vlad {} --json",
                                           write_temp("not_a_model.hzvlad", "HZVOCAB")));
  EXPECT_EQ(not_model.exit_code, 1);
  EXPECT_THAT(not_model.err, HasSubstr("not a hanzo-fusion VLAD model"));
  EXPECT_EQ(nlohmann::json::parse(not_model.out)["ok"], false);
}

TEST(Cli, FeaturesMatchReportsCorrectMatchesAgainstAHomographyAndRefusesBadInput) {
  const std::string graf = std::string(HANZO_DATA_DIR) + "/feature_matching_graf";
  const CliRun matched = run(fmt::format("features match {0}/graf1.png {0}/graf2.png --homography {0}/H_graf1_to_graf2_halfres.txt --json", graf));
  ASSERT_EQ(matched.exit_code, 0) << matched.err;
  const nlohmann::json json = nlohmann::json::parse(matched.out);
  EXPECT_EQ(json["keypoints1"], 1000);
  EXPECT_EQ(json["geometry"]["model"], "homography");
  EXPECT_GE(json["ground_truth"]["correct"].get<int>(), 300);
  EXPECT_GE(json["ground_truth"]["precision"].get<double>(), 0.9);
  const CliRun text = run(fmt::format("features match {0}/graf1.png {0}/graf2.png --no-affine-views", graf));
  ASSERT_EQ(text.exit_code, 0) << text.err;
  EXPECT_THAT(text.out, HasSubstr("verified matches"));
  const CliRun missing = run(fmt::format("features match {0}/graf1.png {0}/graf9.png", graf));
  EXPECT_EQ(missing.exit_code, 1);
  EXPECT_THAT(missing.err, HasSubstr("graf9.png: no such file"));
  EXPECT_EQ(std::count(missing.err.begin(), missing.err.end(), '\n'), 1);
  const CliRun short_matrix = run(fmt::format("features match {0}/graf1.png {0}/graf2.png --homography {1}", graf, write_temp("h.txt", "1 0 0\n0 1 0\n")));
  EXPECT_EQ(short_matrix.exit_code, 1);
  EXPECT_THAT(short_matrix.err, HasSubstr("expected 9 numbers"));
  const CliRun not_image = run(fmt::format("features match {0}/graf1.png {1}", graf, write_temp("text.png", "not a picture")));
  EXPECT_EQ(not_image.exit_code, 1);
  EXPECT_THAT(not_image.err, HasSubstr("not an image OpenCV can read"));
  // A cut-off PNG: the program's one line, not libpng's.
  std::ifstream whole(graf + "/graf2.png", std::ios::binary);
  const std::string bytes((std::istreambuf_iterator<char>(whole)), std::istreambuf_iterator<char>());
  const CliRun truncated = run(fmt::format("features match {0}/graf1.png {1}", graf, write_temp("cut.png", bytes.substr(0, bytes.size() / 2))));
  EXPECT_EQ(truncated.exit_code, 1);
  EXPECT_THAT(truncated.err, HasSubstr("truncated PNG"));
  EXPECT_THAT(truncated.err, Not(HasSubstr("libpng")));
}

// A vocabulary trained on the EuRoC room and the calibration boards finds the KITTI street
// frame next to the one queried (a vocabulary file round trip through the commands).
TEST(Cli, VisionVocabularyTrainsAndVisionQueryRanksPlacesAndBothRefuseBadInput) {
  const std::string data = HANZO_DATA_DIR;
  const std::filesystem::path vocabulary = std::filesystem::temp_directory_path() / fmt::format("hanzo_cli_vocabulary_{}.hzvoc", ::getpid());
  const CliRun trained = run(fmt::format("vision vocabulary {0}/euroc_v101_micro/mav0/cam0/data {0}/camera_calib_opencv_stereo --step 4 --out {1} --json", data,
                                         vocabulary.string()));
  ASSERT_EQ(trained.exit_code, 0) << trained.err;
  const nlohmann::json json = nlohmann::json::parse(trained.out);
  EXPECT_GT(json["words"].get<int>(), 1000);
  EXPECT_EQ(json["images"], 24 + 7);
  const std::string street = data + "/kitti_odometry_06_first51/image_l";
  const CliRun queried = run(fmt::format("vision query {0}/000020.png {0}/000010.png {0}/000019.png {0}/000040.png {1}/euroc_v101_micro/mav0/cam1/data/1403715273262142976.png "
                                         "--vocabulary {2} --top 2 --json", street, data, vocabulary.string()));
  ASSERT_EQ(queried.exit_code, 0) << queried.err;
  const nlohmann::json ranked = nlohmann::json::parse(queried.out)["matches"];
  ASSERT_EQ(ranked.size(), 2u);
  EXPECT_THAT(ranked[0]["image"].get<std::string>(), HasSubstr("000019.png"));
  const CliRun with_default = run(fmt::format("vision query {0}/000020.png {0}/000019.png {0}/000040.png", street));
  ASSERT_EQ(with_default.exit_code, 0) << with_default.err;
  EXPECT_THAT(with_default.out, HasSubstr("000019.png"));

  const CliRun empty_folder = run(fmt::format("vision vocabulary {} --out {}", std::filesystem::temp_directory_path().string() + "/hanzo_no_such_folder", vocabulary.string()));
  EXPECT_EQ(empty_folder.exit_code, 1);
  EXPECT_THAT(empty_folder.err, HasSubstr("no such file or folder"));
  const CliRun corrupt = run(fmt::format("vision query {0}/000020.png {0}/000019.png --vocabulary {1}", street, write_temp("bad.hzvoc", "HZVOCAB garbage")));
  EXPECT_EQ(corrupt.exit_code, 1);
  EXPECT_THAT(corrupt.err, HasSubstr("bad.hzvoc"));
  EXPECT_EQ(std::count(corrupt.err.begin(), corrupt.err.end(), '\n'), 1);
  const CliRun not_image = run(fmt::format("vision query {} {}/000019.png", write_temp("text.png", "not a picture"), street));
  EXPECT_EQ(not_image.exit_code, 1);
  EXPECT_THAT(not_image.err, HasSubstr("not an image OpenCV can read"));
  std::filesystem::remove(vocabulary);
}

// A plain folder of real images (KITTI 06's left camera, 51 frames, 60 m) through `import images`
// and a camera-only `run`: monocular visual SLAM, scored with a Sim3 alignment (its lengths are
// in units of the first baseline).
TEST(Cli, ImageFolderImportRunsAsCameraOnlyVisualSlam) {
  const std::filesystem::path dir = std::filesystem::temp_directory_path() / fmt::format("hanzo_cli_images_{}", ::getpid());
  std::filesystem::remove_all(dir);
  std::filesystem::create_directories(dir);
  const std::string data = std::string(HANZO_DATA_DIR) + "/kitti_odometry_06_first51";
  const std::string log = (dir / "street.mcap").string(), calibration = (dir / "calibration.yaml").string();
  const CliRun imported = run(fmt::format("import images {0}/image_l --times {0}/times_from_pyslam_kitti06.txt --intrinsics 707.0912,707.0912,601.8873,183.1104 "
                                          "--calibration {1} --out {2} --json", data, calibration, log));
  ASSERT_EQ(imported.exit_code, 0) << imported.err;
  const nlohmann::json report = nlohmann::json::parse(imported.out);
  EXPECT_EQ(report["images"], 51);
  EXPECT_EQ(report["time_source"], "times file");
  EXPECT_EQ(report["width"], 1226);
  const std::string config = write_temp("hanzo_cli_camera_only.yaml", "fusion:\n  sensors:\n    cam0:\n      topic: /cam0\n      modality: camera\n      rate: 10\n");
  const CliRun slam = run(fmt::format("run --config {} --calibration {} --log {} --out {} --gt {}/gt_cam0.tum --json", config, calibration, log,
                                      (dir / "run").string(), data));
  ASSERT_EQ(slam.exit_code, 0) << slam.err;
  const nlohmann::json slam_json = nlohmann::json::parse(slam.out);
  const nlohmann::json mapping = slam_json["mapping"];
  EXPECT_GE(mapping["camera_frames_tracked"].get<int>(), 45);
  EXPECT_EQ(mapping["visual_scale_free"], true);
  // A pose for every image: the camera, the only sensor, is not gated (the motion model alone
  // refused the poses of the car speeding up), and the first image, the monocular map's origin,
  // is posed when the map is made from it and a later one.
  const nlohmann::json& camera = slam_json["summary"]["sensors"][0];
  EXPECT_EQ(camera["received"], 51);
  EXPECT_EQ(camera["fused"], 51) << camera.dump();
  EXPECT_TRUE(camera["rejected"].empty()) << camera.dump();
  std::ifstream trajectory(dir / "run" / "trajectory.tum");
  int poses = 0;
  for (std::string line; std::getline(trajectory, line);) poses += !line.empty() && line[0] != '#';
  EXPECT_EQ(poses, 51);
  // The importer's relative times (origin 1e9 s) are paired with the ground truth's (from 0).
  const nlohmann::json& evaluation = slam_json["evaluation"];
  ASSERT_FALSE(evaluation.contains("undefined")) << evaluation.dump();
  EXPECT_THAT(evaluation["time_pairing"].get<std::string>(), HasSubstr("origin taken off"));
  EXPECT_GE(evaluation["pairs"].get<int>(), 30);
  // eval pairs them too, without --t-offset, and says how.
  const CliRun ape = run(fmt::format("eval ape {}/gt_cam0.tum {} --align sim3 --json", data, (dir / "run" / "trajectory.tum").string()));
  ASSERT_EQ(ape.exit_code, 0) << ape.err;
  const nlohmann::json ape_json = nlohmann::json::parse(ape.out);
  EXPECT_EQ(ape_json["estimate_time_offset_s"], -1e9);
  EXPECT_THAT(ape_json["time_pairing"].get<std::string>(), HasSubstr("importers' origin"));
  const double rmse = ape_json["statistics"]["rmse"].get<double>();
  std::printf("KITTI 06 image folder, camera-only run: Sim3-aligned APE %.3f m over 60 m\n", rmse);
  EXPECT_LT(rmse, 0.3);  // 0.5 % of the path, over every frame

  // Bad input: stereo folders without a baseline for the calibration; intrinsics of the wrong count.
  const CliRun no_baseline = run(fmt::format("import images {0}/image_l {0}/image_l --times {0}/times_from_pyslam_kitti06.txt --intrinsics 707,707,601,183 "
                                             "--calibration {1} --out {2}", data, calibration, (dir / "stereo.mcap").string()));
  EXPECT_EQ(no_baseline.exit_code, 1);
  EXPECT_THAT(no_baseline.err, HasSubstr("baseline"));
  const CliRun three = run(fmt::format("import images {}/image_l --rate 10 --intrinsics 707,707,601 --out {}", data, (dir / "x.mcap").string()));
  EXPECT_EQ(three.exit_code, 1);
  EXPECT_THAT(three.err, HasSubstr("--intrinsics: 3 numbers"));
  const CliRun zero_origin = run(fmt::format("import images {0}/image_l --times {0}/times_from_pyslam_kitti06.txt --time-origin 0 --out {1}", data,
                                             (dir / "zero.mcap").string()));
  EXPECT_EQ(zero_origin.exit_code, 1);
  EXPECT_THAT(zero_origin.err, HasSubstr("--time-origin 0: relative times need an origin after 0"));
  EXPECT_FALSE(std::filesystem::exists(dir / "zero.mcap"));
  std::filesystem::remove_all(dir);
}

TEST(Cli, PrivacyBlurRedactsFacesOfAnImageOrAFolderAndRefusesBadInput) {
  const std::filesystem::path dir = std::filesystem::temp_directory_path() / fmt::format("hanzo_cli_privacy_{}", ::getpid());
  std::filesystem::remove_all(dir);
  std::filesystem::create_directories(dir);
  const CliRun one = run(fmt::format("privacy blur {}/privacy_faces/two_people.jpg {} --json", HANZO_DATA_DIR, (dir / "two.png").string()));
  ASSERT_EQ(one.exit_code, 0) << one.err;
  const nlohmann::json json = nlohmann::json::parse(one.out);
  EXPECT_EQ(json["faces"], 2);
  EXPECT_EQ(json["redaction"], "blur");
  ASSERT_EQ(json["images"].size(), 1U);
  EXPECT_EQ(json["images"][0]["regions"].size(), 2U);
  EXPECT_TRUE(std::filesystem::exists(dir / "two.png"));
  const CliRun folder = run(fmt::format("privacy blur {}/privacy_faces {} --redaction black --no-plates --json", HANZO_DATA_DIR,
                                        (dir / "all").string()));
  ASSERT_EQ(folder.exit_code, 0) << folder.err;
  const nlohmann::json all = nlohmann::json::parse(folder.out);
  EXPECT_EQ(all["images"].size(), 5U);
  EXPECT_EQ(all["faces"], 9);  // 1 + 2 + 3 + 2 + 1
  EXPECT_EQ(all["licence_plates"], 0);
  const CliRun missing = run(fmt::format("privacy blur {} {}", (dir / "none.jpg").string(), (dir / "out.png").string()));
  EXPECT_EQ(missing.exit_code, 1);
  EXPECT_THAT(missing.err, HasSubstr("none.jpg: no such file or folder"));
  const CliRun not_image = run(fmt::format("privacy blur {} {}", write_temp("text.jpg", "not a picture"), (dir / "out.png").string()));
  EXPECT_EQ(not_image.exit_code, 1);
  EXPECT_THAT(not_image.err, HasSubstr("not an image OpenCV can read"));
  EXPECT_EQ(std::count(not_image.err.begin(), not_image.err.end(), '\n'), 1);
  EXPECT_FALSE(std::filesystem::exists(dir / "out.png"));
  // Without YuNet's file (the repository does not ship it), faces are searched with OpenCV's
  // Haar cascade, with a warning naming where the file was looked for; a file that is no ONNX
  // network is refused on one line naming it.
  EXPECT_EQ(json["face_detector"], "yunet");
  const char* models = std::getenv("HANZO_FUSION_MODELS");
  const std::string shared_models = models != nullptr ? models : "";
  ::setenv("HANZO_FUSION_MODELS", "/nonexistent-models", 1);
  const CliRun fallback = run(fmt::format("privacy blur {}/privacy_faces/two_people.jpg {} --json", HANZO_DATA_DIR, (dir / "fallback.png").string()));
  ::setenv("HANZO_FUSION_MODELS", shared_models.c_str(), 1);
  EXPECT_EQ(fallback.exit_code, 0) << fallback.err;
  EXPECT_THAT(fallback.err, HasSubstr("face_detection_yunet.onnx not found (looked in HANZO_FUSION_MODELS=/nonexistent-models"));
  EXPECT_THAT(fallback.err, HasSubstr("Haar cascade"));
  const nlohmann::json fallback_json = nlohmann::json::parse(fallback.out);
  EXPECT_EQ(fallback_json["face_detector"], "haar_cascade");
  EXPECT_GE(fallback_json["faces"].get<int>(), 2);  // both faces of the photo
  const CliRun bad_model = run(fmt::format("privacy blur {}/privacy_faces/two_people.jpg {} --face-model {}", HANZO_DATA_DIR,
                                           (dir / "bad_model.png").string(), write_temp("bad_model.onnx", "not a network")));
  EXPECT_EQ(bad_model.exit_code, 1);
  EXPECT_THAT(bad_model.err, HasSubstr("bad_model.onnx': not an ONNX network"));
  EXPECT_EQ(std::count(bad_model.err.begin(), bad_model.err.end(), '\n'), 1) << bad_model.err;
  // A cut-off JPEG decodes with its missing part grey (libjpeg only prints a warning): a face
  // there would be written unblurred, so the file is refused.
  const std::string whole_photo = file_bytes(fmt::format("{}/privacy_faces/two_people.jpg", HANZO_DATA_DIR));
  std::ofstream((dir / "cut.jpg").string(), std::ios::binary) << whole_photo.substr(0, whole_photo.size() * 3 / 5);
  const CliRun cut = run(fmt::format("privacy blur {} {}", (dir / "cut.jpg").string(), (dir / "out.png").string()));
  EXPECT_EQ(cut.exit_code, 1);
  EXPECT_THAT(cut.err, HasSubstr("cut.jpg: truncated JPEG"));
  EXPECT_FALSE(std::filesystem::exists(dir / "out.png"));
  // A sensor log: its camera images pass the filter, the rest is copied.
  ASSERT_EQ(run(fmt::format("sim examples/scenarios/camera_checkerboard.yaml --out {} --duration 1 --no-foxglove", (dir / "sim").string())).exit_code, 0);
  const CliRun log = run(fmt::format("privacy blur {} {} --json", (dir / "sim" / "sensors.mcap").string(), (dir / "blurred.mcap").string()));
  ASSERT_EQ(log.exit_code, 0) << log.err;
  const nlohmann::json redacted = nlohmann::json::parse(log.out);
  EXPECT_EQ(redacted["images"], 6);  // 5 Hz for 1 s, both ends
  EXPECT_EQ(redacted["faces"], 0);
  EXPECT_EQ(redacted["messages"], 107);
  const CliRun info = run(fmt::format("log info {} --json", (dir / "blurred.mcap").string()));
  ASSERT_EQ(info.exit_code, 0) << info.err;
  EXPECT_EQ(nlohmann::json::parse(info.out)["messages"], 107);
  // `import --privacy`: a TUM RGB-D folder whose colour frames are the face photos; the faces are
  // blurred before the log is written.
  std::filesystem::create_directories(dir / "tum" / "rgb");
  std::ofstream list(dir / "tum" / "rgb.txt");
  list << "# timestamp filename\n";
  for (const auto& [i, photo] : std::vector<std::pair<int, std::string>>{{0, "two_people.jpg"}, {1, "obama.jpg"}}) {
    std::filesystem::copy_file(fmt::format("{}/privacy_faces/{}", HANZO_DATA_DIR, photo), dir / "tum" / "rgb" / fmt::format("{}.jpg", i));
    list << fmt::format("{}.0 rgb/{}.jpg\n", 1700000000 + i, i);
  }
  list.close();
  const CliRun imported = run(fmt::format("import tum-rgbd {} --out {} --privacy blur --json", (dir / "tum").string(), (dir / "tum.mcap").string()));
  ASSERT_EQ(imported.exit_code, 0) << imported.err;
  const nlohmann::json privacy = nlohmann::json::parse(imported.out)["privacy"];
  EXPECT_EQ(privacy["images"], 2);
  EXPECT_EQ(privacy["faces"], 3);
  EXPECT_EQ(privacy["redaction"], "blur");
  // Nothing with a face is left in the log.
  const CliRun again = run(fmt::format("privacy blur {} {} --json", (dir / "tum.mcap").string(), (dir / "again.mcap").string()));
  ASSERT_EQ(again.exit_code, 0) << again.err;
  EXPECT_EQ(nlohmann::json::parse(again.out)["faces"], 0);
  const CliRun wrong_output = run(fmt::format("privacy blur {} {}", (dir / "sim" / "sensors.mcap").string(), (dir / "out.png").string()));
  EXPECT_EQ(wrong_output.exit_code, 1);
  EXPECT_THAT(wrong_output.err, HasSubstr("a sensor log is written to a .mcap file"));
  std::filesystem::remove_all(dir);
}

TEST(Cli, CryptoEncryptsAndDecryptsWithKeyFilesOrTheEnvironment) {
  const std::filesystem::path dir = std::filesystem::temp_directory_path() / fmt::format("hanzo_cli_crypto_{}", ::getpid());
  std::filesystem::remove_all(dir);
  std::filesystem::create_directories(dir);
  const std::string key = (dir / "a.key").string(), other = (dir / "b.key").string();
  const CliRun made = run(fmt::format("crypto keygen {} --json", key));
  ASSERT_EQ(made.exit_code, 0) << made.err;
  const std::string key_id = nlohmann::json::parse(made.out)["key_id"];
  EXPECT_EQ(key_id.size(), 16U);
  EXPECT_EQ(run(fmt::format("crypto keygen {}", key)).exit_code, 1);  // never overwritten
  ASSERT_EQ(run(fmt::format("crypto keygen {}", other)).exit_code, 0);
  const std::string plain = write_temp("plain.yaml", "fusion:\n  frontend: {type: ekf}\n");
  const std::string sealed = (dir / "plain.enc").string(), opened = (dir / "opened.yaml").string();
  const CliRun encrypted = run(fmt::format("crypto encrypt {} {} --key {} --json", plain, sealed, key));
  ASSERT_EQ(encrypted.exit_code, 0) << encrypted.err;
  EXPECT_EQ(nlohmann::json::parse(encrypted.out)["key_id"], key_id);
  const CliRun wrong = run(fmt::format("crypto decrypt {} {} --key {}", sealed, opened, other));
  EXPECT_EQ(wrong.exit_code, 1);
  EXPECT_THAT(wrong.err, HasSubstr(fmt::format("encrypted with key {}, which is not among the keys given", key_id)));
  EXPECT_FALSE(std::filesystem::exists(opened));
  // During a rotation every key in use is given; the file names its own.
  const CliRun decrypted = run(fmt::format("crypto decrypt {} {} --key {} --key {} --json", sealed, opened, other, key));
  ASSERT_EQ(decrypted.exit_code, 0) << decrypted.err;
  std::ifstream a(plain), b(opened);
  EXPECT_EQ(std::string(std::istreambuf_iterator<char>(a), {}), std::string(std::istreambuf_iterator<char>(b), {}));
  std::filesystem::resize_file(sealed, std::filesystem::file_size(sealed) - 1);
  const CliRun cut = run(fmt::format("crypto decrypt {} {} --key {}", sealed, (dir / "cut.yaml").string(), key));
  EXPECT_EQ(cut.exit_code, 1);
  EXPECT_THAT(cut.err, HasSubstr("truncated"));
  EXPECT_FALSE(std::filesystem::exists(dir / "cut.yaml"));
  // An encrypted sensor log reads like the plain one with the key in the environment.
  ASSERT_EQ(run(fmt::format("sim examples/scenarios/camera_checkerboard.yaml --out {} --duration 1 --no-foxglove", (dir / "sim").string())).exit_code, 0);
  const std::string log = (dir / "sim" / "sensors.mcap").string(), sealed_log = (dir / "sensors.mcap.enc").string();
  ASSERT_EQ(run(fmt::format("crypto encrypt {} {} --key {}", log, sealed_log, key)).exit_code, 0);
  std::ifstream key_file(key);
  const std::string key_hex((std::istreambuf_iterator<char>(key_file)), {});
  ::setenv("HANZO_ENCRYPTION_KEY", key_hex.substr(0, 64).c_str(), 1);
  const CliRun info = run(fmt::format("log info {} --json", sealed_log));
  ASSERT_EQ(info.exit_code, 0) << info.err;
  EXPECT_EQ(nlohmann::json::parse(info.out)["messages"], 107);
  const CliRun redacted = run(fmt::format("privacy blur {} {} --json", sealed_log, (dir / "redacted.mcap").string()));
  ASSERT_EQ(redacted.exit_code, 0) << redacted.err;
  EXPECT_EQ(nlohmann::json::parse(redacted.out)["images"], 6);
  ::unsetenv("HANZO_ENCRYPTION_KEY");
  const CliRun locked = run(fmt::format("log info {}", sealed_log));
  EXPECT_EQ(locked.exit_code, 1);
  EXPECT_THAT(locked.err, HasSubstr("the file is encrypted; set HANZO_ENCRYPTION_KEY to its key"));
  const CliRun no_key = run(fmt::format("crypto encrypt {} {}", plain, (dir / "x.enc").string()));
  EXPECT_EQ(no_key.exit_code, 1);
  EXPECT_THAT(no_key.err, HasSubstr("HANZO_ENCRYPTION_KEY is not set"));
  std::filesystem::remove_all(dir);
}

TEST(Cli, GraphOptimizeReachesSeSyncOptimumOnIntel) {
  const std::filesystem::path out = std::filesystem::temp_directory_path() / fmt::format("hanzo_cli_graph_{}.g2o", ::getpid());
  const CliRun optimized = run(fmt::format(
      "graph optimize {}/pose_graph/se_sync/intel.g2o --out {} --objective chordal --initialize chordal --json", HANZO_DATA_DIR, out.string()));
  ASSERT_EQ(optimized.exit_code, 0) << optimized.err;
  const nlohmann::json json = nlohmann::json::parse(optimized.out);
  EXPECT_EQ(json["poses"], 1728);
  EXPECT_EQ(json["edges"], 2512);
  EXPECT_EQ(json["initialize"], "chordal");
  EXPECT_NEAR(json["se_sync_objective"]["final"].get<double>(), 52.3482, 0.05);
  EXPECT_GT(json["g2o_chi2"]["initial"].get<double>(), json["g2o_chi2"]["final"].get<double>());
  // The written poses are the certified ones, and the output says what they minimize.
  EXPECT_EQ(json["written_poses_minimize"], "se_sync_chordal");
  EXPECT_TRUE(json["certified"].get<bool>());
  EXPECT_EQ(json["certificate"]["about"], "the written poses");
  // Geodesic poses are not SE-Sync's optimum: the certificate is about the optimum near them.
  const CliRun geodesic = run(fmt::format("graph optimize {}/pose_graph/se_sync/intel.g2o --out {} --json", HANZO_DATA_DIR, out.string()));
  ASSERT_EQ(geodesic.exit_code, 0) << geodesic.err;
  const nlohmann::json geodesic_json = nlohmann::json::parse(geodesic.out);
  EXPECT_EQ(geodesic_json["written_poses_minimize"], "g2o_geodesic");
  EXPECT_FALSE(geodesic_json["certified"].get<bool>());
  EXPECT_TRUE(geodesic_json["certificate"]["certified"].get<bool>());
  EXPECT_THAT(geodesic_json["certificate"]["about"].get<std::string>(), HasSubstr("not written"));
  EXPECT_TRUE(std::filesystem::exists(out));
  std::filesystem::remove(out);
  const CliRun bad = run(fmt::format("graph optimize {} --out {}", write_temp("bad.g2o", "VERTEX_SE2 0 0 0\n"), out.string()));
  EXPECT_EQ(bad.exit_code, 1);
  EXPECT_THAT(bad.err, HasSubstr("bad.g2o:1: VERTEX_SE2: expected 4 numbers, got 3"));
  EXPECT_EQ(std::count(bad.err.begin(), bad.err.end(), '\n'), 1);
  const CliRun bad_initialize =
      run(fmt::format("graph optimize {}/pose_graph/se_sync/intel.g2o --out {} --initialize guess", HANZO_DATA_DIR, out.string()));
  EXPECT_EQ(bad_initialize.exit_code, 1);
  EXPECT_THAT(bad_initialize.err, HasSubstr("--initialize: expected best, file or chordal, got 'guess'"));

  // The default optimizes from the file's vertices and from the chordal start and keeps the
  // lower cost: a file whose vertices are a trap (headings scrambled) still ends at the optimum.
  std::ifstream original(fmt::format("{}/pose_graph/se_sync/intel.g2o", HANZO_DATA_DIR));
  std::string scrambled;
  int vertex = 0;
  for (std::string line; std::getline(original, line);) {
    if (line.starts_with("VERTEX_SE2")) {
      std::istringstream fields(line);
      std::string tag;
      double id = 0, x = 0, y = 0, theta = 0;
      fields >> tag >> id >> x >> y >> theta;
      line = fmt::format("VERTEX_SE2 {} {} {} {}", id, x, y, theta + 2.5 * std::sin(1.7 * vertex++));
    }
    scrambled += line + "\n";
  }
  const std::string trap = write_temp("intel_scrambled.g2o", scrambled);
  const CliRun from_file = run(fmt::format("graph optimize {} --out {} --objective chordal --initialize file --json", trap, out.string()));
  const CliRun best = run(fmt::format("graph optimize {} --out {} --objective chordal --json", trap, out.string()));
  ASSERT_EQ(best.exit_code, 0) << best.err;
  const nlohmann::json best_json = nlohmann::json::parse(best.out);
  EXPECT_EQ(best_json["initialize"], "best");
  EXPECT_EQ(best_json["started_from"], "chordal");
  EXPECT_NEAR(best_json["se_sync_objective"]["final"].get<double>(), 52.3482, 0.05);
  EXPECT_GT(nlohmann::json::parse(from_file.out)["se_sync_objective"]["final"].get<double>(), 60.0);
  // The certificate (SE-Sync's verification) tells the two apart: the optimum is certified, the
  // local minimum the file's start ends in is not.
  EXPECT_TRUE(best_json["certified"].get<bool>());
  EXPECT_GE(best_json["certificate"]["min_eigenvalue"].get<double>(), -1e-6);
  const nlohmann::json trapped = nlohmann::json::parse(from_file.out);
  EXPECT_FALSE(trapped["certified"].get<bool>());
  EXPECT_LT(trapped["certificate"]["min_eigenvalue"].get<double>(), -1.0);
  const CliRun uncertified = run(fmt::format("graph optimize {} --out {} --no-certificate --json", trap, out.string()));
  ASSERT_EQ(uncertified.exit_code, 0) << uncertified.err;
  EXPECT_FALSE(nlohmann::json::parse(uncertified.out).contains("certified"));
  std::filesystem::remove(out);
}

TEST(Cli, GraphOptimizeIncrementallyEndsAtTheOptimum) {
  const std::filesystem::path out = std::filesystem::temp_directory_path() / fmt::format("hanzo_cli_incremental_{}.g2o", ::getpid());
  const std::string input = fmt::format("{}/pose_graph/se_sync/intel.g2o", HANZO_DATA_DIR);
  const CliRun optimized = run(fmt::format("graph optimize {} --out {} --objective chordal --incremental --json", input, out.string()));  // from the file
  ASSERT_EQ(optimized.exit_code, 0) << optimized.err;
  const nlohmann::json json = nlohmann::json::parse(optimized.out);
  EXPECT_EQ(json["incremental"]["updates"], 1728);
  EXPECT_GT(json["incremental"]["update_ms"]["p99"].get<double>(), 0.0);
  EXPECT_NEAR(json["se_sync_objective"]["final"].get<double>(), 52.3482, 0.05);
  std::filesystem::remove(out);
  const CliRun refused = run(fmt::format("graph optimize {} --out {} --incremental --initialize chordal", input, out.string()));
  EXPECT_EQ(refused.exit_code, 1);
  EXPECT_THAT(refused.err, HasSubstr("--incremental"));
}

TEST(Cli, Slam2dMatchesScansAndWritesTrajectoryMapAndPlot) {
  const std::filesystem::path folder = std::filesystem::temp_directory_path() / fmt::format("hanzo_cli_slam2d_{}", ::getpid());
  std::filesystem::create_directories(folder);
  const std::string log = fmt::format("{}/laser2d_carmen/intel-corrected.log.gz", HANZO_DATA_DIR);
  // Scan-to-map odometry only (the loop-closing run is tests/pipeline/planar_laser_slam_test.cpp).
  const CliRun slam = run(fmt::format("slam2d {} --scale-error 0.05 --heading-drift 2 --no-loop-closure --trajectory {}/slam.tum --map {}/map.yaml --plot {} --json",
                                      log, folder.string(), folder.string(), folder.string()));
  ASSERT_EQ(slam.exit_code, 0) << slam.err;
  const nlohmann::json json = nlohmann::json::parse(slam.out);
  EXPECT_EQ(json["scans"], 906);
  EXPECT_EQ(json["loop_closures"], 0);
  EXPECT_GT(json["ape_rmse_m"]["odometry"].get<double>(), 5.0);
  EXPECT_LT(json["ape_rmse_m"]["slam"].get<double>(), 1.0);
  EXPECT_GT(json["scan_ms"]["p99"].get<double>(), 0.0);
  for (const char* file : {"slam.tum", "map.yaml", "map.pgm", "slam2d_trajectory.svg"}) EXPECT_TRUE(std::filesystem::exists(folder / file)) << file;

  const CliRun missing = run(fmt::format("slam2d {}/none.log", folder.string()));
  EXPECT_EQ(missing.exit_code, 1);
  EXPECT_THAT(missing.err, HasSubstr("none.log: cannot open file"));
  const CliRun bad_scale = run(fmt::format("slam2d {} --scale-error -2", log));
  EXPECT_EQ(bad_scale.exit_code, 1);
  EXPECT_THAT(bad_scale.err, HasSubstr("--scale-error"));
  const CliRun no_scans = run(fmt::format("slam2d {}", write_temp("odometry_only.log", "ODOM 0 0 0 0 0 0 1.0 host 1.0\n")));
  EXPECT_EQ(no_scans.exit_code, 1);
  EXPECT_EQ(std::count(no_scans.err.begin(), no_scans.err.end(), '\n'), 1);
  std::filesystem::remove_all(folder);
}

// A CARMEN log whose times are useless (all the same) still maps: the times are rebuilt with a
// warning; an evaluation that cannot be computed (the robot never moved: the alignment is
// degenerate) is reported as undefined, and the trajectory and map are written all the same.
TEST(Cli, Slam2dWritesItsResultsWhenTimesOrTheEvaluationAreBroken) {
  const std::filesystem::path dir = std::filesystem::temp_directory_path() / fmt::format("hanzo_cli_slam2d_{}", ::getpid());
  std::filesystem::remove_all(dir);
  std::filesystem::create_directories(dir);
  std::string ranges;
  for (int beam = 0; beam < 180; ++beam) ranges += fmt::format(" {:.3f}", 2.0 + 0.5 * std::cos(beam * M_PI / 45.0));
  std::ofstream log(dir / "standing.log");
  for (int scan = 0; scan < 6; ++scan) log << "FLASER 180" << ranges << " 0 0 0 0 0 0 1.13486e+09 host 1.13486e+09\n";
  log.close();
  const CliRun mapped = run(fmt::format("slam2d {} --trajectory {} --map {} --json", (dir / "standing.log").string(),
                                        (dir / "standing.tum").string(), (dir / "standing.yaml").string()));
  ASSERT_EQ(mapped.exit_code, 0) << mapped.err;
  const nlohmann::json json = nlohmann::json::parse(mapped.out);
  EXPECT_EQ(json["scans"], 6);
  EXPECT_THAT(json["warnings"][0].get<std::string>(), HasSubstr("times rebuilt from line order"));
  EXPECT_TRUE(json["ape_rmse_m"].contains("undefined")) << json["ape_rmse_m"];
  EXPECT_TRUE(std::filesystem::exists(dir / "standing.tum"));
  EXPECT_TRUE(std::filesystem::exists(dir / "standing.pgm"));
  std::filesystem::remove_all(dir);
}

TEST(Cli, RegisterRecoversTheReferenceOfTheRealPair) {
  const std::string dir = fmt::format("{}/lidar_small_gicp", HANZO_DATA_DIR);
  for (const char* method : {"gicp", "ndt"}) {
    const CliRun registered = run(fmt::format("register {}/source.ply {}/251370668.pcd --method {} --json", dir, dir, method));
    ASSERT_EQ(registered.exit_code, 0) << registered.err;
    const nlohmann::json json = nlohmann::json::parse(registered.out);
    EXPECT_TRUE(json["converged"].get<bool>());
    // small_gicp's reference translation (0.4889, 0.1212, -0.0253).
    EXPECT_NEAR(json["translation"][0].get<double>(), 0.4889, 0.03) << method;
    EXPECT_NEAR(json["translation"][1].get<double>(), 0.1212, 0.03) << method;
    EXPECT_NEAR(json["translation"][2].get<double>(), -0.0253, 0.03) << method;
    EXPECT_LT(json["rotation_deg"].get<double>(), 0.716 + 1.0);
    EXPECT_GT(json["fitness"].get<double>(), 0.8);
  }
  const CliRun bad_method = run(fmt::format("register {0}/source.ply {0}/target.ply --method sift", dir));
  EXPECT_EQ(bad_method.exit_code, 1);
  EXPECT_THAT(bad_method.err, HasSubstr("--method: expected icp, icp-plane, gicp or ndt, got 'sift'"));
  const CliRun far = run(fmt::format("register {0}/source.ply {0}/target.ply --init 100,0,0,0,0,0", dir));
  EXPECT_EQ(far.exit_code, 1);
  EXPECT_THAT(far.err, HasSubstr("initial guess"));
  EXPECT_EQ(std::count(far.err.begin(), far.err.end(), '\n'), 1);
  // Not converged within the iterations allowed: exit 1, still one JSON object saying so.
  const CliRun unconverged = run(fmt::format("register {0}/source.ply {0}/251370668.pcd --max-iterations 1 --json", dir));
  EXPECT_EQ(unconverged.exit_code, 1);
  const nlohmann::json refused = nlohmann::json::parse(unconverged.out);
  EXPECT_FALSE(refused["ok"].get<bool>());
  EXPECT_FALSE(refused["converged"].get<bool>());
  EXPECT_THAT(refused["error"].get<std::string>(), HasSubstr("did not converge in 1 iterations"));
  EXPECT_EQ(std::count(unconverged.err.begin(), unconverged.err.end(), '\n'), 1);
}

TEST(Cli, CloudFilterWritesEachStep) {
  const auto out = std::filesystem::temp_directory_path() / "hanzo_cli_filtered.ply";
  const CliRun filtered = run(fmt::format("cloud filter {}/lidar_small_gicp/source.ply --out {} --voxel 0.1 --sor 10,0.5 --ground --json",
                                          HANZO_DATA_DIR, out.string()));
  ASSERT_EQ(filtered.exit_code, 0) << filtered.err;
  const nlohmann::json json = nlohmann::json::parse(filtered.out);
  ASSERT_EQ(json["steps"].size(), 4u);
  EXPECT_EQ(json["steps"][0]["points"], 69792);
  EXPECT_TRUE(json["steps"][3]["found"].get<bool>());
  EXPECT_GT(json["steps"][3]["plane"][2].get<double>(), 0.95);  // the floor is level in this scan
  EXPECT_LT(json["points"].get<int>(), json["steps"][1]["points"].get<int>());
  EXPECT_TRUE(std::filesystem::exists(out));
  const CliRun bad = run(fmt::format("cloud filter {}/lidar_small_gicp/source.ply --out {} --sor 10", HANZO_DATA_DIR, out.string()));
  EXPECT_EQ(bad.exit_code, 1);
  EXPECT_THAT(bad.err, HasSubstr("--sor: expected K,R"));
  std::filesystem::remove(out);
}

// `map localize` on small_gicp's real outdoor pair: the target scan as the map, the source scan
// found within 10 cm / 1 deg of the reference transform around a guess 0.5 m / 5 deg off.
TEST(Cli, MapLocalizeFindsTheRealScanInTheOtherScansMap) {
  const std::filesystem::path dir = std::filesystem::temp_directory_path() / fmt::format("hanzo_cli_localize_{}", ::getpid());
  std::filesystem::remove_all(dir);
  std::filesystem::create_directories(dir);
  const std::string pair = std::string(HANZO_DATA_DIR) + "/lidar_small_gicp";
  const std::string map = (dir / "target.fmap").string();
  const CliRun imported = run(fmt::format("map import {}/target.ply --out {} --voxel 0.2", pair, map));
  ASSERT_EQ(imported.exit_code, 0) << imported.err;
  const CliRun found = run(fmt::format("map localize {} {}/source.ply --guess 1.0 0 0 5 --window 3 --json", map, pair));
  ASSERT_EQ(found.exit_code, 0) << found.err;
  const nlohmann::json result = nlohmann::json::parse(found.out);
  // Reference (T_target_source.txt): translation 0.489 0.121 -0.025, yaw -0.70 deg.
  EXPECT_NEAR(result["position"][0].get<double>(), 0.489, 0.1);
  EXPECT_NEAR(result["position"][1].get<double>(), 0.121, 0.1);
  EXPECT_NEAR(result["yaw_deg"].get<double>(), -0.70, 1.0);
  EXPECT_EQ(result["global_search"], false);
  // A map without a point layer, and a missing scan, are refused with the reason.
  const CliRun no_points = run(fmt::format("map localize {} {}/source.ply", (dir / "missing.fmap").string(), pair));
  EXPECT_NE(no_points.exit_code, 0);
  EXPECT_THAT(no_points.err, HasSubstr("missing.fmap"));
  const CliRun no_scan = run(fmt::format("map localize {} {}/no-such-scan.ply", map, pair));
  EXPECT_NE(no_scan.exit_code, 0);
  std::filesystem::remove_all(dir);
}

// `map merge` on the same real pair: the source scan's map joins the target's within 5 cm and
// 1 degree of the reference transform, without a guess; one map alone is refused.
TEST(Cli, MapMergeJoinsTheRealScansMapsWithoutAGuess) {
  const std::filesystem::path dir = std::filesystem::temp_directory_path() / fmt::format("hanzo_cli_merge_{}", ::getpid());
  std::filesystem::remove_all(dir);
  std::filesystem::create_directories(dir);
  const std::string pair = std::string(HANZO_DATA_DIR) + "/lidar_small_gicp";
  const std::string target = (dir / "target.fmap").string(), source = (dir / "source.fmap").string();
  ASSERT_EQ(run(fmt::format("map import {}/target.ply --out {} --voxel 0.2", pair, target)).exit_code, 0);
  ASSERT_EQ(run(fmt::format("map import {}/source.ply --out {} --voxel 0.2", pair, source)).exit_code, 0);
  const CliRun merged = run(fmt::format("map merge {} {} --out {} --json", target, source, (dir / "merged.fmap").string()));
  ASSERT_EQ(merged.exit_code, 0) << merged.err;
  const nlohmann::json result = nlohmann::json::parse(merged.out);
  const nlohmann::json& joined = result["joined"][0];
  // Reference (T_target_source.txt): translation 0.489 0.121 -0.025, yaw -0.70 deg.
  EXPECT_NEAR(joined["translation"][0].get<double>(), 0.489, 0.05);
  EXPECT_NEAR(joined["translation"][1].get<double>(), 0.121, 0.05);
  EXPECT_NEAR(joined["yaw_deg"].get<double>(), -0.70, 1.0);
  EXPECT_GE(joined["agreeing"].get<int>(), 2);
  const CliRun info = run(fmt::format("map info {} --json", (dir / "merged.fmap").string()));
  ASSERT_EQ(info.exit_code, 0) << info.err;
  EXPECT_EQ(nlohmann::json::parse(info.out)["layers"]["points"]["count"], result["points"]);
  const CliRun alone = run(fmt::format("map merge {} --out {}", target, (dir / "alone.fmap").string()));
  EXPECT_NE(alone.exit_code, 0);
  EXPECT_THAT(alone.err, HasSubstr("two or more maps"));
  EXPECT_FALSE(std::filesystem::exists(dir / "alone.fmap"));
  std::filesystem::remove_all(dir);
}

// `map merge` of two camera-only runs of the simulated drone (stereo, different noise): the
// second joins by its visual keyframes' landmarks; the merged map holds both maps' landmarks and
// keyframes, each keyframe with its source.
TEST(Cli, MapMergeJoinsCameraSessionsByTheirLandmarks) {
  const std::filesystem::path dir = std::filesystem::temp_directory_path() / fmt::format("hanzo_cli_camera_merge_{}", ::getpid());
  std::filesystem::remove_all(dir);
  std::filesystem::create_directories(dir);
  std::vector<std::string> maps;
  std::size_t landmarks = 0;
  for (int seed : {1, 2}) {
    const std::string sim = (dir / fmt::format("sim{}", seed)).string(), out = (dir / fmt::format("run{}", seed)).string();
    ASSERT_EQ(run(fmt::format("sim examples/scenarios/drone.yaml --out {} --duration 4 --seed {} --sensors camera_left,camera_right --no-foxglove", sim, seed)).exit_code, 0);
    const CliRun ran = run(fmt::format("run --config {0}/fusion.yaml --calib {0}/calibration.yaml --log {0}/sensors.mcap --out {1}", sim, out));
    ASSERT_EQ(ran.exit_code, 0) << ran.err;
    maps.push_back(out + "/map.fmap");
    const CliRun info = run(fmt::format("map info {} --json", maps.back()));
    ASSERT_EQ(info.exit_code, 0) << info.err;
    landmarks += nlohmann::json::parse(info.out)["layers"]["visual_landmarks"]["landmarks"].get<std::size_t>();
  }
  const std::string merged_path = (dir / "merged.fmap").string();
  const CliRun merged = run(fmt::format("map merge {} {} --out {} --json", maps[0], maps[1], merged_path));
  ASSERT_EQ(merged.exit_code, 0) << merged.err;
  const nlohmann::json result = nlohmann::json::parse(merged.out);
  EXPECT_EQ(result["method"], "keyframe_graph");
  EXPECT_GE(result["joined"][0]["loops"].get<int>(), 3);
  EXPECT_EQ(result["joined"][0]["scale"].get<double>(), 1.0) << "stereo maps are metric";
  // Both flights start at the same place in the same world frame: the join is near identity.
  const std::vector<double> translation = result["joined"][0]["translation"].get<std::vector<double>>();
  EXPECT_LT(std::hypot(translation[0], translation[1], translation[2]), 0.5);
  EXPECT_LT(std::abs(result["joined"][0]["yaw_deg"].get<double>()), 2.0);
  EXPECT_EQ(result["landmarks"].get<std::size_t>(), landmarks);
  const CliRun info = run(fmt::format("map info {} --json", merged_path));
  ASSERT_EQ(info.exit_code, 0) << info.err;
  const nlohmann::json described = nlohmann::json::parse(info.out);
  const nlohmann::json& layer = described["layers"]["visual_landmarks"];
  EXPECT_EQ(layer["sources"], nlohmann::json(maps));
  EXPECT_EQ(layer["keyframes"], result["keyframes"]);
  std::filesystem::remove_all(dir);
}

TEST(Cli, MapBuildInfoExportStoreDiffRedact) {
  const std::filesystem::path dir = std::filesystem::temp_directory_path() / fmt::format("hanzo_cli_map_{}", ::getpid());
  std::filesystem::remove_all(dir);
  std::filesystem::create_directories(dir);
  const std::string log = (dir / "intel.mcap").string();
  const std::string poses = (dir / "intel.tum").string();
  const CliRun imported = run(fmt::format("import carmen {}/laser2d_carmen/intel-corrected.log.gz --out {} --ground-truth {} --no-foxglove",
                                          HANZO_DATA_DIR, log, poses));
  ASSERT_EQ(imported.exit_code, 0) << imported.err;

  const std::string map = (dir / "intel.fmap").string();
  const CliRun built = run(fmt::format("map build --log {} --trajectory {} --topic /laser --resolution 0.05 --points-voxel 0.05 "
                                       "--map-id intel-lab --out {} --json", log, poses, map));
  ASSERT_EQ(built.exit_code, 0) << built.err;
  const nlohmann::json build_json = nlohmann::json::parse(built.out);
  EXPECT_EQ(build_json["scans"], 906);
  EXPECT_EQ(build_json["map_id"], "intel-lab");
  EXPECT_GT(build_json["layers"]["occupancy"]["occupied_cells"].get<int>(), 10000);
  EXPECT_EQ(build_json["inputs"].size(), 2u);
  EXPECT_EQ(build_json["inputs"][0]["sha256"].get<std::string>().size(), 64u);

  const CliRun info = run(fmt::format("map info {}", map));
  ASSERT_EQ(info.exit_code, 0) << info.err;
  EXPECT_THAT(info.out, HasSubstr("map intel-lab version 1"));
  EXPECT_THAT(info.out, HasSubstr("cells of 0.05 m"));

  for (const std::string format : {"png", "pgm", "ply"}) {
    const std::string out = (dir / ("intel_export." + std::string(format == "pgm" ? "yaml" : format))).string();
    const CliRun exported = run(fmt::format("map export {} --format {} --out {} --json", map, format, out));
    ASSERT_EQ(exported.exit_code, 0) << format << ": " << exported.err;
    const nlohmann::json export_report = nlohmann::json::parse(exported.out);  // kept: the loop reads into it
    for (const auto& file : export_report["files"]) EXPECT_TRUE(std::filesystem::exists(file.get<std::string>()));
  }
  // --out map.pgm keeps the name as given (the YAML goes beside it).
  const CliRun pgm = run(fmt::format("map export {} --out {} --json", map, (dir / "named.pgm").string()));
  ASSERT_EQ(pgm.exit_code, 0) << pgm.err;
  EXPECT_EQ(nlohmann::json::parse(pgm.out)["files"], nlohmann::json::array({(dir / "named.yaml").string(), (dir / "named.pgm").string()}));
  EXPECT_TRUE(std::filesystem::exists(dir / "named.pgm"));
  EXPECT_FALSE(std::filesystem::exists(dir / "named.pgm.pgm"));

  // Versions: the built map, then a redacted copy saved as version 2.
  const std::string store = (dir / "store").string();
  ASSERT_EQ(run(fmt::format("map save {} --store {}", map, store)).exit_code, 0);
  const std::string redacted = (dir / "redacted.fmap").string();
  const CliRun redact = run(fmt::format("map redact {} --out {} --drop-labels --resolution 0.5 --json", map, redacted));
  ASSERT_EQ(redact.exit_code, 0) << redact.err;
  EXPECT_EQ(nlohmann::json::parse(redact.out)["layers"]["occupancy"]["resolution"], 0.5);
  ASSERT_EQ(run(fmt::format("map save {} --store {}", redacted, store)).exit_code, 0);
  const CliRun versions = run(fmt::format("map versions --store {} --json", store));
  ASSERT_EQ(versions.exit_code, 0) << versions.err;
  const nlohmann::json versions_json = nlohmann::json::parse(versions.out);
  ASSERT_EQ(versions_json["maps"][0]["versions"].size(), 2u);
  EXPECT_EQ(versions_json["maps"][0]["versions"][0]["parent_version"], 0);  // built, never stored before
  EXPECT_EQ(versions_json["maps"][0]["versions"][1]["parent_version"], 1);
  const std::string first = (dir / "v1.fmap").string();
  ASSERT_EQ(run(fmt::format("map checkout intel-lab --store {} --version 1 --out {}", store, first)).exit_code, 0);

  // Same map against itself: no change; against the redacted one: resolutions differ.
  const CliRun same = run(fmt::format("map diff {} {} --json", first, map));
  ASSERT_EQ(same.exit_code, 0) << same.err;
  EXPECT_EQ(nlohmann::json::parse(same.out)["occupancy"]["became_occupied"], 0);
  const CliRun mismatch = run(fmt::format("map diff {} {}", map, redacted));
  EXPECT_EQ(mismatch.exit_code, 1);
  EXPECT_THAT(mismatch.err, HasSubstr("resolutions differ"));

  // Bad input: a file that is not a map, an export the map cannot give.
  const std::string junk = write_temp("hanzo_cli_junk.fmap", "not a map");
  const CliRun bad = run(fmt::format("map info {}", junk));
  EXPECT_EQ(bad.exit_code, 1);
  EXPECT_THAT(bad.err, HasSubstr("not a FusionMap file"));
  const CliRun no_points = run(fmt::format("map export {} --format pcd --out {}", redacted, (dir / "x.pcd").string()));
  EXPECT_EQ(no_points.exit_code, 0) << no_points.err;  // the redacted map keeps a (coarser) point layer
  std::filesystem::remove(junk);
  std::filesystem::remove_all(dir);
}

namespace {

// The documented calibration walk (docs/calibration.md): simulate, run LiDAR-only odometry (the
// LiDAR's own poses: no calibration given), calibrate lidar_to_body against the ground truth and
// against the IMU. Truth: the scenario's mount, R_body_lidar wxyz (0.701057, -0.092296, 0.092296,
// 0.701057), t (0.05, -0.03, 0.25), no clock offset.
TEST(Cli, CalibMotionRecoversTheLidarMountOfTheCalibrationWalk) {
  const std::filesystem::path dir = std::filesystem::temp_directory_path() / fmt::format("hanzo_cli_calib_{}", ::getpid());
  std::filesystem::remove_all(dir);
  const std::string d = dir.string();
  ASSERT_EQ(run(fmt::format("sim examples/scenarios/calibration_walk.yaml --out {} --duration 40", d)).exit_code, 0);
  const CliRun odometry = run(fmt::format("lidar-odometry {}/sensors.mcap --trajectory {}/lidar.tum", d, d));
  ASSERT_EQ(odometry.exit_code, 0) << odometry.err;

  const auto rotation_error_deg = [](const nlohmann::json& result) {
    const std::array<double, 4> truth = {0.701057, -0.092296, 0.092296, 0.701057};
    double dot = 0.0;
    for (int i = 0; i < 4; ++i) dot += truth[i] * result["rotation_wxyz"][i].get<double>();
    return 2.0 * std::acos(std::min(1.0, std::abs(dot))) * 180.0 / M_PI;
  };
  std::filesystem::copy_file(dir / "calibration.yaml", dir / "result.yaml");
  const CliRun with_truth = run(fmt::format("calib motion --sensor lidar --sensor-poses {}/lidar.tum --body-poses {}/ground_truth.tum "
                                            "--out {}/result.yaml --json", d, d, d));
  ASSERT_EQ(with_truth.exit_code, 0) << with_truth.err;
  const nlohmann::json result = nlohmann::json::parse(with_truth.out);
  EXPECT_LT(rotation_error_deg(result), 0.5);  // measured 0.19 (LiDAR odometry's own error)
  const std::array<double, 3> truth_translation = {0.05, -0.03, 0.25};
  double squared = 0.0;
  for (int i = 0; i < 3; ++i) squared += std::pow(result["translation"][i].get<double>() - truth_translation[i], 2);
  EXPECT_LT(std::sqrt(squared), 0.08);  // measured 0.046
  EXPECT_LT(std::abs(result["time_offset_ns"].get<double>()), 2e6);  // measured 0.5 ms
  EXPECT_TRUE(result["unobservable_translation_axis"].is_null());
  // --out replaced lidar_to_body and kept the IMU's entry.
  const CliRun check = run(fmt::format("calib check {}/result.yaml --json", d));
  ASSERT_EQ(check.exit_code, 0) << check.err;
  const nlohmann::json sensors = nlohmann::json::parse(check.out)["calibration"]["sensors"];
  ASSERT_EQ(sensors.size(), 2u);
  EXPECT_EQ(sensors[1]["sensor"], "lidar");
  EXPECT_EQ(sensors[1]["translation"], result["translation"]);

  const CliRun with_imu = run(fmt::format("calib motion --sensor lidar --sensor-poses {}/lidar.tum --imu-log {}/sensors.mcap --json", d, d));
  ASSERT_EQ(with_imu.exit_code, 0) << with_imu.err;
  const nlohmann::json gyro_result = nlohmann::json::parse(with_imu.out);
  EXPECT_LT(rotation_error_deg(gyro_result), 0.5);
  EXPECT_FALSE(gyro_result["translation_estimated"].get<bool>());
  EXPECT_NEAR(gyro_result["gyro_bias"][1].get<double>(), -0.002, 0.0005);  // the scenario's initial gyro bias

  const CliRun neither = run(fmt::format("calib motion --sensor lidar --sensor-poses {}/lidar.tum", d));
  EXPECT_EQ(neither.exit_code, 1);
  EXPECT_THAT(neither.err, HasSubstr("--body-poses FILE or --imu-log LOG"));
  const CliRun missing = run(fmt::format("calib motion --sensor lidar --sensor-poses {}/nothing.tum --body-poses {}/ground_truth.tum", d, d));
  EXPECT_EQ(missing.exit_code, 1);
  EXPECT_EQ(std::count(missing.err.begin(), missing.err.end(), '\n'), 1);
  std::filesystem::remove_all(dir);
}

// calib stereo on OpenCV's sample pairs: the rig into a calibration file whose right camera is
// the left's mount times the solved pose; uneven pairs refused in one line.
TEST(Cli, CalibStereoWritesBothCamerasOfOpenCvsSamplePairs) {
  const std::filesystem::path dir = std::filesystem::temp_directory_path() / fmt::format("hanzo_cli_stereo_{}", ::getpid());
  std::filesystem::create_directories(dir);
  const std::string folder = std::string(HANZO_DATA_DIR) + "/camera_calib_opencv_stereo/";
  std::string left, right;
  for (const int number : {1, 2, 3, 4, 5, 6, 7, 8, 9, 11, 12, 13, 14}) {
    left += fmt::format(" {}left{:02}.jpg", folder, number);
    right += fmt::format(" {}right{:02}.jpg", folder, number);
  }
  // A mount for the left camera already in the file: kept, and the right one placed from it.
  std::ofstream(dir / "rig.yaml") << "calibration:\n  left_to_body:\n    rotation: [1.0, 0.0, 0.0, 0.0]\n    translation: [0.1, 0.0, 0.5]\n";
  const CliRun solved = run(fmt::format("calib stereo --left{} --right{} --board 9x6 --square 0.025 --out {}/rig.yaml --json", left, right, dir.string()));
  ASSERT_EQ(solved.exit_code, 0) << solved.err;
  const nlohmann::json result = nlohmann::json::parse(solved.out);
  EXPECT_EQ(result["pairs_used"], 13);
  EXPECT_NEAR(result["baseline"].get<double>(), 3.33 * 0.025, 0.002);
  EXPECT_LT(result["epipolar_error_px"].get<double>(), 0.3);
  const hanzo::fusion::calib::Calibration rig = hanzo::fusion::calib::load_calibration((dir / "rig.yaml").string()).value();
  ASSERT_NE(rig.find("right"), nullptr);
  ASSERT_TRUE(rig.find("right")->camera.has_value());
  const Eigen::Vector3d right_position = rig.find("right")->T_body_sensor().translation();
  EXPECT_NEAR(right_position.x(), 0.1 + result["T_left_right"]["position"][0].get<double>(), 1e-9);
  EXPECT_NEAR(right_position.z(), 0.5 + result["T_left_right"]["position"][2].get<double>(), 1e-9);
  const CliRun uneven = run(fmt::format("calib stereo --left{} --right {}right01.jpg --board 9x6", left, folder));
  EXPECT_EQ(uneven.exit_code, 1);
  EXPECT_THAT(uneven.err, HasSubstr("13 left and 1 right images"));
  EXPECT_EQ(std::count(uneven.err.begin(), uneven.err.end(), '\n'), 1);
  std::filesystem::remove_all(dir);
}

TEST(Cli, CalibCameraRecoversTheLensOfTheCheckerboardScenario) {
  const std::filesystem::path dir = std::filesystem::temp_directory_path() / fmt::format("hanzo_cli_calib_camera_{}", ::getpid());
  std::filesystem::remove_all(dir);
  const std::string d = dir.string();
  ASSERT_EQ(run(fmt::format("sim examples/scenarios/camera_checkerboard.yaml --out {}", d)).exit_code, 0);
  // The scenario's calibration.yaml holds the true lens: calibrate into a file with the mount only.
  const CliRun calibrated = run(fmt::format("calib camera {}/sensors.mcap --board 8x6 --square 0.08 --out {}/result.yaml --json", d, d));
  ASSERT_EQ(calibrated.exit_code, 0) << calibrated.err;
  const nlohmann::json result = nlohmann::json::parse(calibrated.out);
  EXPECT_EQ(result["views_found"], 60);  // the whole board in every image
  EXPECT_LT(result["rms_px"].get<double>(), 0.25);  // measured 0.146
  // Measured: fx -0.44, fy -0.46, cx -0.55, cy -0.19 px; k1 -0.28332 (truth -0.28341).
  EXPECT_NEAR(result["intrinsics"]["fx"].get<double>(), 458.654, 1.5);
  EXPECT_NEAR(result["intrinsics"]["fy"].get<double>(), 457.296, 1.5);
  EXPECT_NEAR(result["intrinsics"]["cx"].get<double>(), 367.215, 1.5);
  EXPECT_NEAR(result["intrinsics"]["cy"].get<double>(), 248.375, 1.5);
  EXPECT_NEAR(result["distortion_coeffs"][0].get<double>(), -0.28340811, 0.005);
  const CliRun check = run(fmt::format("calib check {}/result.yaml --json", d));
  ASSERT_EQ(check.exit_code, 0) << check.err;
  const nlohmann::json sensors = nlohmann::json::parse(check.out)["calibration"]["sensors"];
  ASSERT_EQ(sensors.size(), 1u);
  EXPECT_EQ(sensors[0]["sensor"], "camera");
  EXPECT_NEAR(sensors[0]["intrinsics"]["fx"].get<double>(), result["intrinsics"]["fx"].get<double>(), 1e-9);

  // (A board of other dimensions is refused by calib's own test: the search takes seconds per image.)
  const CliRun no_images = run(fmt::format("calib camera {}/sensors.mcap --topic /nothing", d));
  EXPECT_EQ(no_images.exit_code, 1);
  EXPECT_THAT(no_images.err, HasSubstr("no images on /nothing"));
  EXPECT_EQ(std::count(no_images.err.begin(), no_images.err.end(), '\n'), 1);
  EXPECT_THAT(run(fmt::format("calib camera {}/sensors.mcap --board nine", d)).err, HasSubstr("COLUMNSxROWS"));
  EXPECT_THAT(run(fmt::format("calib camera {}/sensors.mcap --board 99999999999x6", d)).err, HasSubstr("COLUMNSxROWS"));  // beyond an int
  EXPECT_THAT(run(fmt::format("calib camera {}/sensors.mcap --board 8x", d)).err, HasSubstr("COLUMNSxROWS"));
  EXPECT_THAT(run(fmt::format("calib camera {}/sensors.mcap --model pinhole", d)).err, HasSubstr("radtan or equidistant"));
  std::filesystem::remove_all(dir);
}

// calib camera-lidar on the first five stations of the board scenario: lidar_to_body written next
// to the camera's true mount lands within 1 cm / 0.5 deg of the LiDAR's; a wrong board size is
// not certified (exit 1, nothing written); bad options get one line.
TEST(Cli, CalibCameraLidarWritesTheLidarMountFromBoardStations) {
  const std::filesystem::path dir = std::filesystem::temp_directory_path() / fmt::format("hanzo_cli_calib_camera_lidar_{}", ::getpid());
  std::filesystem::remove_all(dir);
  const std::string d = dir.string();
  ASSERT_EQ(run(fmt::format("sim examples/scenarios/camera_lidar_board.yaml --out {} --duration 12", d)).exit_code, 0);
  const auto truth = hanzo::fusion::calib::load_calibration(d + "/calibration.yaml");
  ASSERT_TRUE(truth);
  const CliRun calibrated = run(fmt::format("calib camera-lidar {0}/sensors.mcap --calibration {0}/calibration.yaml --board 8x6 --square 0.10 "
                                            "--board-size 1.1x0.9 --out {0}/result.yaml --json",
                                            d));
  ASSERT_EQ(calibrated.exit_code, 0) << calibrated.err;
  const nlohmann::json result = nlohmann::json::parse(calibrated.out);
  EXPECT_TRUE(result["certified"].get<bool>());
  EXPECT_EQ(result["stations"], 5);
  EXPECT_EQ(result["views"].size(), result["scans_used"].get<std::size_t>());
  const auto written = hanzo::fusion::calib::load_calibration(d + "/result.yaml");
  ASSERT_TRUE(written) << written.error().message;
  ASSERT_NE(written->find("lidar"), nullptr);
  const hanzo::fusion::SE3 error = truth->find("lidar")->T_body_sensor().inverse() * written->find("lidar")->T_body_sensor();
  EXPECT_LT(error.translation().norm(), 0.01);
  EXPECT_LT(error.rotation().angle(), 0.5 * std::numbers::pi / 180.0);

  const CliRun wrong_size = run(fmt::format("calib camera-lidar {0}/sensors.mcap --calibration {0}/calibration.yaml --out {0}/wrong.yaml", d));
  EXPECT_EQ(wrong_size.exit_code, 1);
  EXPECT_THAT(wrong_size.err, HasSubstr("not certified: the LiDAR sees the board's edges"));
  EXPECT_THAT(wrong_size.err, HasSubstr("wrong.yaml not written"));
  EXPECT_EQ(std::count(wrong_size.err.begin(), wrong_size.err.end(), '\n'), 1);
  EXPECT_FALSE(std::filesystem::exists(dir / "wrong.yaml"));
  EXPECT_THAT(run(fmt::format("calib camera-lidar {}/sensors.mcap --board-size 1.1", d)).err, HasSubstr("WIDTHxHEIGHT"));
  EXPECT_THAT(run(fmt::format("calib camera-lidar {}/sensors.mcap --initial-guess", d)).err, HasSubstr("--calibration needs both"));
  EXPECT_THAT(run(fmt::format("calib camera-lidar {}/sensors.mcap --lidar-topic /nothing", d)).err, HasSubstr("no point clouds on /nothing"));
  std::filesystem::remove_all(dir);
}

// Gaussian splats from the command line (AI builds): the lego renders at an eighth of their size,
// every 4th frame held back and scored; render writes one PNG (and depth) per frame of a poses
// file in its order and scores them; a poses file that names no images still renders; bad
// input gets one line.
TEST(Cli, ReconstructSplatsAndRenderThemAtAPosesFile) {
  if (run("reconstruct --help").exit_code != 0) GTEST_SKIP() << "built without HANZO_FUSION_AI";
  const std::filesystem::path dir = std::filesystem::temp_directory_path() / fmt::format("hanzo_cli_splats_{}", ::getpid());
  std::filesystem::remove_all(dir);
  const std::string lego = std::string(HANZO_DATA_DIR) + "/nerf_lego_400";
  const CliRun trained = run(fmt::format("reconstruct splats {}/transforms_train.json --out {}/splats --downscale 8 --iterations 300 "
                                         "--initial-gaussians 5000 --hold-every 4 --json",
                                         lego, dir.string()));
  ASSERT_EQ(trained.exit_code, 0) << trained.err;
  const nlohmann::json result = nlohmann::json::parse(trained.out);
  EXPECT_EQ(result["train_views"], 75);
  EXPECT_EQ(result["eval"]["views"], 25);
  EXPECT_EQ(result["iterations"], 300);
  EXPECT_GT(result["eval"]["psnr"].get<double>(), 18.0);
  EXPECT_TRUE(std::filesystem::exists(dir / "splats" / "reconstruction.json"));
  EXPECT_THAT(trained.err, HasSubstr("step 300/300"));  // progress on stderr

  const CliRun rendered = run(fmt::format("render {}/splats --poses {}/transforms_val.json --out {}/views --downscale 8 --depth --json", dir.string(), lego,
                                          dir.string()));
  ASSERT_EQ(rendered.exit_code, 0) << rendered.err;
  const nlohmann::json views = nlohmann::json::parse(rendered.out);
  EXPECT_EQ(views["views"], 25);
  EXPECT_EQ(views["files"][24]["frame"], "./val/r_96");
  EXPECT_GT(views["eval"]["psnr"].get<double>(), 18.0);
  const cv::Mat first = cv::imread((dir / "views" / "0000.png").string());
  EXPECT_EQ(first.cols, 50);
  EXPECT_EQ(cv::imread((dir / "views" / "0024_depth.png").string(), cv::IMREAD_UNCHANGED).type(), CV_16UC1);
  EXPECT_EQ(views["device"], "cpu");

  // --device auto renders on a CUDA device when there is one, else the CPU: the same scores;
  // --device cuda without a device is refused with the reason.
  const CliRun automatic = run(fmt::format("render {}/splats --poses {}/transforms_val.json --out {}/auto --downscale 8 --device auto --json", dir.string(),
                                           lego, dir.string()));
  ASSERT_EQ(automatic.exit_code, 0) << automatic.err;
  const nlohmann::json auto_views = nlohmann::json::parse(automatic.out);
  EXPECT_NEAR(auto_views["eval"]["psnr"].get<double>(), views["eval"]["psnr"].get<double>(), 0.01);
  const CliRun cuda = run(fmt::format("render {}/splats --poses {}/transforms_val.json --out {}/cuda --downscale 8 --device cuda", dir.string(), lego,
                                      dir.string()));
  if (auto_views["device"] == "cpu") {
    EXPECT_EQ(cuda.exit_code, 1);
    EXPECT_THAT(cuda.err, HasSubstr("--device cuda: "));
    EXPECT_EQ(std::count(cuda.err.begin(), cuda.err.end(), '\n'), 1);
  } else {
    EXPECT_EQ(cuda.exit_code, 0) << cuda.err;
  }
  const CliRun bad_device = run(fmt::format("render {}/splats --poses {}/transforms_val.json --out {}/x --device gpu", dir.string(), lego, dir.string()));
  EXPECT_EQ(bad_device.exit_code, 1);
  EXPECT_THAT(bad_device.err, HasSubstr("unknown device 'gpu'"));

  // Poses without images (a camera path): rendered, not scored.
  std::ofstream(dir / "path.json") << R"({"camera_angle_x": 0.69, "w": 400, "h": 400, "frames": [{"file_path": "none", "transform_matrix": )"
                                   << R"([[1,0,0,0],[0,0,-1,-4],[0,1,0,0],[0,0,0,1]]}]})";
  const CliRun path = run(fmt::format("render {}/splats --poses {}/path.json --out {}/path --json", dir.string(), dir.string(), dir.string()));
  ASSERT_EQ(path.exit_code, 0) << path.err;
  EXPECT_FALSE(nlohmann::json::parse(path.out).contains("eval"));
  EXPECT_EQ(cv::imread((dir / "path" / "0000.png").string()).cols, 400);

  const CliRun missing = run(fmt::format("reconstruct splats {}/nothing.json --out {}/x", dir.string(), dir.string()));
  EXPECT_EQ(missing.exit_code, 1);
  EXPECT_THAT(missing.err, HasSubstr("nothing.json"));
  EXPECT_EQ(std::count(missing.err.begin(), missing.err.end(), '\n'), 1);
  const CliRun not_splats = run(fmt::format("render {}/transforms_val.json --poses {}/transforms_val.json --out {}/y", lego, lego, dir.string()));
  EXPECT_EQ(not_splats.exit_code, 1);
  EXPECT_THAT(not_splats.err, HasSubstr("not a PLY file"));
  std::filesystem::remove_all(dir);
}

// Splats from a session's own data (AI builds): the simulated phone's camera images at the poses
// of a trajectory through the calibration's camera, every 4th view held back and scored; a
// trajectory that misses the log, a calibration without a camera and a wrong topic are refused.
TEST(Cli, ReconstructSplatsFromASensorLogAndATrajectory) {
  if (run("reconstruct --help").exit_code != 0) GTEST_SKIP() << "built without HANZO_FUSION_AI";
  const std::filesystem::path dir = std::filesystem::temp_directory_path() / fmt::format("hanzo_cli_log_splats_{}", ::getpid());
  std::filesystem::remove_all(dir);
  const std::string d = dir.string();
  ASSERT_EQ(run(fmt::format("sim examples/scenarios/ar_handheld.yaml --out {} --duration 8 --sensors camera --no-foxglove", d)).exit_code, 0);
  const CliRun trained = run(fmt::format("reconstruct splats --log {0}/sensors.mcap --trajectory {0}/ground_truth.tum --calibration {0}/calibration.yaml "
                                         "--out {0}/splats --downscale 4 --iterations 600 --initial-gaussians 5000 --hold-every 4 --json",
                                         d));
  ASSERT_EQ(trained.exit_code, 0) << trained.err;
  const nlohmann::json result = nlohmann::json::parse(trained.out);
  EXPECT_EQ(result["source"]["topic"], "/sensors/camera");
  EXPECT_EQ(result["source"]["images"], 121);  // 15 Hz over 8 s
  EXPECT_EQ(result["source"]["without_pose"], 0);
  const int views = result["train_views"].get<int>() + result["eval"]["views"].get<int>();
  EXPECT_GT(views, 30);  // kept every 10 cm or 5 degrees of the walk: 41
  EXPECT_LT(views, 121);
  EXPECT_EQ(result["eval"]["views"], views / 4);
  EXPECT_EQ(result["resolution"][0], 160);
  EXPECT_GT(result["eval"]["psnr"].get<double>(), 18.5);  // measured 20.1

  std::ofstream(dir / "late.tum") << "1000 0 0 0 0 0 0 1\n1001 1 0 0 0 0 0 1\n";
  const CliRun outside = run(fmt::format("reconstruct nerf --log {0}/sensors.mcap --trajectory {0}/late.tum --calibration {0}/calibration.yaml --out {0}/x", d));
  EXPECT_EQ(outside.exit_code, 1);
  EXPECT_THAT(outside.err, HasSubstr("inside"));
  EXPECT_EQ(std::count(outside.err.begin(), outside.err.end(), '\n'), 1);
  const CliRun topic = run(fmt::format(
      "reconstruct splats --log {0}/sensors.mcap --trajectory {0}/ground_truth.tum --calibration {0}/calibration.yaml --topic /nothing --out {0}/x", d));
  EXPECT_EQ(topic.exit_code, 1);
  EXPECT_THAT(topic.err, HasSubstr("no images on /nothing (image topics: /sensors/camera)"));
  const CliRun both = run(fmt::format("reconstruct splats {0}/a.json --log {0}/sensors.mcap --out {0}/x", d));
  EXPECT_EQ(both.exit_code, 1);
  EXPECT_THAT(both.err, HasSubstr("either TRANSFORMS or --log"));
  std::filesystem::remove_all(dir);
}

// A hash-grid NeRF from the command line (AI builds): the lego at an eighth of its size for a few
// steps, every 4th frame held back and scored; render finds nerf.hznerf in the folder.
TEST(Cli, ReconstructNerfAndRenderIt) {
  if (run("reconstruct --help").exit_code != 0) GTEST_SKIP() << "built without HANZO_FUSION_AI";
  const std::filesystem::path dir = std::filesystem::temp_directory_path() / fmt::format("hanzo_cli_nerf_{}", ::getpid());
  std::filesystem::remove_all(dir);
  const std::string lego = std::string(HANZO_DATA_DIR) + "/nerf_lego_400";
  const CliRun trained = run(fmt::format("reconstruct nerf {}/transforms_train.json --out {}/nerf --downscale 8 --iterations 80 "
                                         "--samples-per-step 16384 --hold-every 4 --json",
                                         lego, dir.string()));
  ASSERT_EQ(trained.exit_code, 0) << trained.err;
  const nlohmann::json result = nlohmann::json::parse(trained.out);
  EXPECT_EQ(result["train_views"], 75);
  EXPECT_EQ(result["eval"]["views"], 25);
  EXPECT_EQ(result["iterations"], 80);
  EXPECT_GT(result["eval"]["psnr"].get<double>(), 17.0);
  EXPECT_NEAR(result["box"]["half_size"].get<double>(), 1.51, 0.05);
  EXPECT_THAT(trained.err, HasSubstr("step 80/80"));

  const CliRun rendered = run(fmt::format("render {}/nerf --poses {}/transforms_val.json --out {}/views --downscale 8 --depth --json", dir.string(), lego,
                                          dir.string()));
  ASSERT_EQ(rendered.exit_code, 0) << rendered.err;
  const nlohmann::json views = nlohmann::json::parse(rendered.out);
  EXPECT_EQ(views["kind"], "nerf");
  EXPECT_EQ(views["views"], 25);
  EXPECT_GT(views["eval"]["psnr"].get<double>(), 17.0);
  EXPECT_EQ(cv::imread((dir / "views" / "0003.png").string()).cols, 50);
  EXPECT_EQ(cv::imread((dir / "views" / "0003_depth.png").string(), cv::IMREAD_UNCHANGED).type(), CV_16UC1);

  std::ofstream(dir / "nerf" / "nerf.hznerf", std::ios::trunc) << "HZNERF1\n{";
  const CliRun broken = run(fmt::format("render {}/nerf --poses {}/transforms_val.json --out {}/x", dir.string(), lego, dir.string()));
  EXPECT_EQ(broken.exit_code, 1);
  EXPECT_THAT(broken.err, HasSubstr("nerf.hznerf"));
  EXPECT_EQ(std::count(broken.err.begin(), broken.err.end(), '\n'), 1);
  std::filesystem::remove_all(dir);
}

// Splats and a NeRF as layers of one FusionMap (AI builds): each reconstruct --map makes the
// map's next version and keeps the other layers; map info reports them with their training;
// render draws the map's layers exactly as the folders' files; surfaces (rendered depth fused
// into a TSDF, the NeRF's density meshed) join the map; a missing layer is refused.
TEST(Cli, ReconstructionsBecomeLayersOfAFusionMap) {
  if (run("reconstruct --help").exit_code != 0) GTEST_SKIP() << "built without HANZO_FUSION_AI";
  const std::filesystem::path dir = std::filesystem::temp_directory_path() / fmt::format("hanzo_cli_neural_map_{}", ::getpid());
  std::filesystem::remove_all(dir);
  const std::string d = dir.string();
  const std::string lego = std::string(HANZO_DATA_DIR) + "/nerf_lego_400";
  const CliRun splats = run(fmt::format("reconstruct splats {0}/transforms_train.json --out {1}/splats --downscale 8 --iterations 100 "
                                        "--initial-gaussians 2000 --hold-every 4 --map {1}/scene.fmap --json",
                                        lego, d));
  ASSERT_EQ(splats.exit_code, 0) << splats.err;
  const nlohmann::json trained = nlohmann::json::parse(splats.out);
  EXPECT_EQ(trained["map"]["version"], 1);
  EXPECT_EQ(trained["map"]["layer"], "gaussian_splats");
  std::filesystem::copy_file(dir / "scene.fmap", dir / "splats_only.fmap");
  const CliRun nerf = run(fmt::format("reconstruct nerf {0}/transforms_train.json --out {1}/nerf --downscale 8 --iterations 20 "
                                      "--samples-per-step 8192 --map {1}/scene.fmap --json",
                                      lego, d));
  ASSERT_EQ(nerf.exit_code, 0) << nerf.err;
  EXPECT_EQ(nlohmann::json::parse(nerf.out)["map"]["version"], 2);
  EXPECT_EQ(nlohmann::json::parse(nerf.out)["map"]["map_id"], trained["map"]["map_id"]);

  const CliRun info = run(fmt::format("map info {}/scene.fmap --json", d));
  ASSERT_EQ(info.exit_code, 0) << info.err;
  const nlohmann::json layers = nlohmann::json::parse(info.out)["layers"];
  EXPECT_EQ(layers["gaussian_splats"]["gaussians"], trained["gaussians"]);
  EXPECT_EQ(layers["gaussian_splats"]["trained"]["views"], 75);
  EXPECT_EQ(layers["gaussian_splats"]["trained"]["evaluated_views"], 25);
  EXPECT_EQ(layers["gaussian_splats"]["trained"]["psnr_db"], trained["eval"]["psnr"]);
  EXPECT_EQ(layers["neural_field"]["bytes"], nlohmann::json::parse(nerf.out)["model_bytes"]);
  EXPECT_EQ(layers["neural_field"]["trained"]["iterations"], 20);
  EXPECT_THAT(run(fmt::format("map info {}/scene.fmap", d)).out, HasSubstr("gaussian splats: "));

  // The map's layers render exactly as the folders' files (two of the held-out views: a NeRF
  // renders a view in about a second on the CPU).
  nlohmann::json two_views = nlohmann::json::parse(std::ifstream(lego + "/transforms_val.json"));
  two_views["frames"] = {two_views["frames"][0], two_views["frames"][13]};
  for (nlohmann::json& frame : two_views["frames"]) frame["file_path"] = lego + "/" + frame["file_path"].get<std::string>();
  std::ofstream(dir / "two_views.json") << two_views.dump();
  for (const auto& [layer, folder] : {std::pair<std::string, std::string>{"splats", "splats"}, {"nerf", "nerf"}}) {
    const CliRun from_map = run(fmt::format("render {0}/scene.fmap --layer {1} --poses {0}/two_views.json --out {0}/map_{1} --downscale 8 --json", d, layer));
    ASSERT_EQ(from_map.exit_code, 0) << from_map.err;
    EXPECT_EQ(nlohmann::json::parse(from_map.out)["kind"], layer);
    ASSERT_EQ(run(fmt::format("render {0}/{1} --poses {0}/two_views.json --out {0}/folder_{1} --downscale 8", d, folder)).exit_code, 0);
    for (const char* view : {"0000.png", "0001.png"}) {
      const cv::Mat a = cv::imread((dir / ("map_" + layer) / view).string());
      const cv::Mat b = cv::imread((dir / ("folder_" + layer) / view).string());
      ASSERT_FALSE(a.empty());
      EXPECT_EQ(cv::norm(a, b, cv::NORM_INF), 0.0) << layer << " " << view;
    }
  }
  // Surfaces: the splats' rendered depth fused into a TSDF, stored as the map's mesh and tsdf
  // layers; the NeRF's density meshed; splats without cameras have no surface to give.
  const CliRun fused = run(fmt::format("reconstruct surface {0}/scene.fmap --poses {1}/transforms_val.json --downscale 8 --out {0}/surface "
                                       "--map {0}/scene.fmap --json", d, lego));
  ASSERT_EQ(fused.exit_code, 0) << fused.err;
  const nlohmann::json surface = nlohmann::json::parse(fused.out);
  EXPECT_EQ(surface["kind"], "splats");
  EXPECT_EQ(surface["depth_fusion"]["views"], 25);
  EXPECT_GT(surface["depth_fusion"]["triangles"].get<int>(), 100);
  EXPECT_EQ(surface["map"]["version"], 3);
  const nlohmann::json with_mesh = nlohmann::json::parse(run(fmt::format("map info {}/scene.fmap --json", d)).out)["layers"];
  EXPECT_EQ(with_mesh["mesh"]["triangles"], surface["depth_fusion"]["triangles"]);
  EXPECT_TRUE(with_mesh.contains("tsdf"));
  EXPECT_TRUE(with_mesh.contains("gaussian_splats"));
  const CliRun density = run(fmt::format("reconstruct surface {0}/nerf --resolution 64 --out {0}/nerf_surface --json", d));
  ASSERT_EQ(density.exit_code, 0) << density.err;
  EXPECT_TRUE(std::filesystem::exists(dir / "nerf_surface" / "surface.ply"));
  const CliRun no_surface = run(fmt::format("reconstruct surface {0}/splats_only.fmap --out {0}/x", d));
  EXPECT_EQ(no_surface.exit_code, 1);
  EXPECT_THAT(no_surface.err, HasSubstr("give --poses"));

  const CliRun missing = run(fmt::format("render {0}/splats_only.fmap --layer nerf --poses {1}/transforms_val.json --out {0}/x", d, lego));
  EXPECT_EQ(missing.exit_code, 1);
  EXPECT_THAT(missing.err, HasSubstr("no neural_field layer"));
  EXPECT_EQ(std::count(missing.err.begin(), missing.err.end(), '\n'), 1);
  const CliRun not_a_map = run(fmt::format("render {0}/splats --layer nerf --poses {1}/transforms_val.json --out {0}/x", d, lego));
  EXPECT_EQ(not_a_map.exit_code, 1);
  EXPECT_THAT(not_a_map.err, HasSubstr("--layer applies to a FusionMap"));
  std::filesystem::remove_all(dir);
}

}  // namespace
