#include "hanzo/fusion/io/carmen_import.hpp"

#include <filesystem>
#include <fstream>

#include <unistd.h>

#include <fmt/format.h>
#include <gmock/gmock.h>
#include <gtest/gtest.h>

namespace hanzo::fusion::io {
namespace {

using ::testing::HasSubstr;

// Per-process names: ctest runs the tests of this file in parallel processes.
std::string temp(const std::string& name) {
  return (std::filesystem::temp_directory_path() / ("hanzo_carmen_" + std::to_string(::getpid()) + "_" + name)).string();
}

struct Imported {
  CarmenImportReport report;
  std::vector<msgs::PointCloudMessage> scans;
  std::vector<msgs::WheelOdometryMessage> wheels;
};

Result<Imported> import_file(const std::string& path, double wheel_separation) {
  const std::string log = temp("out.mcap");
  Imported out;
  {
    std::unique_ptr<SensorLogWriter> writer;
    HANZO_ASSIGN_OR_RETURN(writer, SensorLogWriter::open(log));
    CarmenImportConfig config;
    config.wheel_separation = wheel_separation;
    HANZO_ASSIGN_OR_RETURN(out.report, import_carmen(path, *writer, config));
    HANZO_RETURN_IF_ERROR(writer->close());
  }
  std::unique_ptr<SensorLogReader> reader;
  HANZO_ASSIGN_OR_RETURN(reader, SensorLogReader::open(log));
  LogEntry entry;
  while (*reader->next(entry)) {
    const auto& message = std::get<msgs::SensorMessage>(entry.message);
    if (entry.topic == "/laser") out.scans.push_back(std::get<msgs::PointCloudMessage>(message));
    if (entry.topic == "/odom") out.wheels.push_back(std::get<msgs::WheelOdometryMessage>(message));
  }
  std::filesystem::remove(log);
  return out;
}

TEST(CarmenImport, Freiburg079ScansAndPoses) {
  const std::string path = std::string(HANZO_DATA_DIR) + "/laser2d_carmen/freiburg-079-corrected.log.gz";
  auto imported = import_file(path, 0.0);
  ASSERT_TRUE(imported.ok()) << imported.error().message;
  EXPECT_EQ(imported->report.scans, 4791u);  // SOURCE.md
  EXPECT_EQ(imported->scans.size(), 4791u);
  EXPECT_EQ(imported->report.scan_poses.size(), 4791u);
  EXPECT_EQ(imported->report.odometry, 0u);  // no wheel separation: ODOM left out
  EXPECT_TRUE(imported->wheels.empty());
  // 360 beams over 180 deg: every point lies at its beam's bearing, -90 deg + i * 0.5 deg.
  for (const auto& scan : imported->scans) {
    ASSERT_LE(scan.points.size(), 360u);
    for (const auto& p : scan.points) {
      ASSERT_EQ(p.z(), 0.0F);
      ASSERT_LT(p.head<2>().norm(), 80.0F);
      const double beam = (std::atan2(p.y(), p.x()) + M_PI / 2) / (M_PI / 360);
      ASSERT_NEAR(beam, std::round(beam), 1e-3);
    }
  }
}

TEST(CarmenImport, IntelOdometryWithBrokenTimesIsFiltered) {
  const std::string path = std::string(HANZO_DATA_DIR) + "/laser2d_carmen/intel-corrected.log.gz";
  auto imported = import_file(path, 0.5);
  ASSERT_TRUE(imported.ok()) << imported.error().message;
  // 910 FLASER lines, 4 of them stamped before the previous scan.
  EXPECT_EQ(imported->report.scans, 906u);
  EXPECT_GT(imported->report.odometry, 9000u);
  EXPECT_THAT(imported->report.first_rejection, HasSubstr("does not increase"));
  for (std::size_t i = 1; i < imported->wheels.size(); ++i) {
    ASSERT_GT(imported->wheels[i].timestamp, imported->wheels[i - 1].timestamp);
  }
}

TEST(CarmenImport, OdometryBecomesWheelDistancesAndTimeZeroReanchors) {
  const std::string path = temp("small.log");
  std::ofstream(path) << "# comment\nPARAM robot_x 1\n"
                         "ODOM 0 0 0 0 0 0 1 host 1\n"
                         "ODOM 1 0 0 0 0 0 2 host 2\n"
                         "ODOM 1 0 0.5 0 0 0 3 host 3\n"
                         "FLASER 4 1.0 2.0 81.83 3.0 1 0 0.5 1 0 0.5 3.5 host 3.5\n"
                         "ODOM 5 5 0.5 0 0 0 0 host 0\n"
                         "ODOM 4 5 0.5 0 0 0 4 host 4\n";
  auto imported = import_file(path, 0.5);
  ASSERT_TRUE(imported.ok()) << imported.error().message;
  ASSERT_EQ(imported->wheels.size(), 4u);
  EXPECT_DOUBLE_EQ(imported->wheels[1].left_distance, 1.0);
  EXPECT_DOUBLE_EQ(imported->wheels[2].left_distance, 1.0 - 0.5 * 0.25);
  EXPECT_DOUBLE_EQ(imported->wheels[2].right_distance, 1.0 + 0.5 * 0.25);
  // Re-anchored at (5, 5, 0.5), then 1 m backwards (x decreases while heading is 0.5 rad).
  EXPECT_DOUBLE_EQ(imported->wheels[3].left_distance, 1.0 - 0.125 - 1.0);
  ASSERT_EQ(imported->scans.size(), 1u);
  ASSERT_EQ(imported->scans[0].points.size(), 3u);  // the 81.83 max-range reading is dropped
  EXPECT_NEAR(imported->scans[0].points[0].y(), -1.0F, 1e-6);       // first beam at -90 deg
  EXPECT_NEAR(imported->scans[0].points[2].x(), 3.0 * std::cos(M_PI / 4), 1e-6);  // beam 3 at +45 deg
  EXPECT_EQ(imported->report.scan_poses.timestamps[0].nanoseconds(), 3'500'000'000);
  std::filesystem::remove(path);
}

TEST(CarmenImport, MalformedLinesNameFileAndLine) {
  const std::string path = temp("bad.log");
  std::ofstream(path) << "ODOM 0 0 0 0 0 0 1 host 1\nFLASER 4 1.0 2.0\n";
  auto imported = import_file(path, 0.5);
  ASSERT_FALSE(imported.ok());
  EXPECT_THAT(imported.error().message, HasSubstr("bad.log:2: FLASER with 4 beams needs 15 fields, has 4"));
  std::ofstream(path) << "ODOM 0 0 x 0 0 0 1 host 1\n";
  EXPECT_THAT(import_file(path, 0.5).error().message, HasSubstr("bad.log:1: field 4 'x' is not a finite number"));
  std::ofstream(path) << "NEFF 3\n";
  EXPECT_THAT(import_file(path, 0.5).error().message, HasSubstr("no FLASER or ODOM lines"));
  EXPECT_THAT(import_file("/nonexistent/missing.log", 0.5).error().message, HasSubstr("cannot open file"));
  std::filesystem::remove(path);
}

// Scans that all carry one time (the ODOM lines' are fine): their times are rebuilt between the
// ODOM lines around them, in line order; nothing is dropped and the report says why.
TEST(CarmenImport, DuplicateScanTimesAreRebuiltFromTheOdometryLines) {
  const std::string path = temp("duplicate_scans.log");
  std::ofstream(path) << "ODOM 0 0 0 0 0 0 10.0 host 10.0\n"
                         "FLASER 4 1.0 2.0 3.0 1.5 0 0 0 0 0 0 7.0 host 7.0\n"
                         "FLASER 4 1.0 2.0 3.0 1.5 0.1 0 0 0.1 0 0 7.0 host 7.0\n"
                         "ODOM 0.2 0 0 0 0 0 10.3 host 10.3\n"
                         "FLASER 4 1.0 2.0 3.0 1.5 0.2 0 0 0.2 0 0 7.0 host 7.0\n"
                         "FLASER 4 1.0 2.0 3.0 1.5 0.3 0 0 0.3 0 0 7.0 host 7.0\n"
                         "FLASER 4 1.0 2.0 3.0 1.5 0.4 0 0 0.4 0 0 7.0 host 7.0\n"
                         "ODOM 0.4 0 0 0 0 0 10.7 host 10.7\n";
  auto imported = import_file(path, 0.5);
  ASSERT_TRUE(imported.ok()) << imported.error().message;
  EXPECT_TRUE(imported->report.timestamps_reconstructed);
  EXPECT_THAT(imported->report.timestamp_warning, HasSubstr("scan times: 4 of 4 times do not increase"));
  EXPECT_THAT(imported->report.timestamp_warning, HasSubstr("rebuilt from the ODOM lines' times"));
  ASSERT_EQ(imported->scans.size(), 5u);
  const double expected[] = {10.1, 10.2, 10.4, 10.5, 10.6};
  for (std::size_t i = 0; i < 5; ++i) EXPECT_NEAR(imported->scans[i].timestamp.seconds(), expected[i], 1e-6) << i;
  EXPECT_EQ(imported->wheels.size(), 3u);
  EXPECT_EQ(imported->report.rejected, 0u);
}

// The Intel log written as a logger printing 6 significant digits would: every time reads
// 1.13486e+09. Scans and odometry are rebuilt from the line order at the nominal scan rate;
// every scan comes through, in order, with its logged pose.
TEST(CarmenImport, TimesPrintedWithSixDigitsAreRebuiltFromTheLineOrder) {
  const std::string original = std::string(HANZO_DATA_DIR) + "/laser2d_carmen/intel-corrected.log.gz";
  const std::string path = temp("six_digits.log");
  {
    CarmenImportConfig config;
    config.wheel_separation = 0.5;
    const CarmenLog log = read_carmen(original, config).value();
    EXPECT_FALSE(log.report.timestamps_reconstructed);
    std::ofstream out(path);
    for (const msgs::PointCloudMessage& scan : log.scans) {
      out << "FLASER 2 1.0 2.0 0 0 0 0 0 0 " << fmt::format("{:.6g} host {:.6g}\n", 1134860000.0 + (scan.timestamp.seconds() - 30.0),
                                                               1134860000.0 + (scan.timestamp.seconds() - 30.0));
      out << "ODOM 0 0 0 0 0 0 " << fmt::format("{:.6g} host 0\n", 1134860000.0 + scan.timestamp.seconds());
    }
  }
  auto imported = import_file(path, 0.5);
  ASSERT_TRUE(imported.ok()) << imported.error().message;
  EXPECT_THAT(imported->report.timestamp_warning, HasSubstr("(written to 10000 s)"));
  EXPECT_THAT(imported->report.timestamp_warning, HasSubstr("line order at the nominal 5 Hz scan rate"));
  EXPECT_EQ(imported->scans.size(), 906u);
  EXPECT_EQ(imported->wheels.size(), 906u);
  EXPECT_NEAR((imported->scans.back().timestamp - imported->scans.front().timestamp).seconds(), 905 * 0.2, 1e-6);
  for (std::size_t i = 1; i < imported->scans.size(); ++i) ASSERT_LT(imported->wheels[i - 1].timestamp, imported->scans[i].timestamp);
}

}  // namespace
}  // namespace hanzo::fusion::io
