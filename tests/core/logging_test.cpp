#include "hanzo/fusion/core/logging.hpp"

#include <gtest/gtest.h>
#include <spdlog/sinks/ostream_sink.h>

#include <sstream>

namespace hanzo::fusion {
namespace {

TEST(Logging, SilentByDefaultAndRoutedToTheInstalledLogger) {
  testing::internal::CaptureStdout();
  testing::internal::CaptureStderr();
  logger()->error("must not appear anywhere");
  EXPECT_EQ(testing::internal::GetCapturedStdout(), "");
  EXPECT_EQ(testing::internal::GetCapturedStderr(), "");

  std::ostringstream captured;
  auto sink = std::make_shared<spdlog::sinks::ostream_sink_mt>(captured);
  set_logger(std::make_shared<spdlog::logger>("test", sink));
  logger()->warn("calibration {} normalized", "lidar");
  logger()->flush();
  EXPECT_NE(captured.str().find("calibration lidar normalized"), std::string::npos);

  set_logger(nullptr);  // back to silent
  logger()->error("silent again");
  EXPECT_EQ(captured.str().find("silent again"), std::string::npos);
}

}  // namespace
}  // namespace hanzo::fusion
