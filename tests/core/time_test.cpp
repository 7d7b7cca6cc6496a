#include "hanzo/fusion/core/time.hpp"

#include <cmath>

#include <gtest/gtest.h>

namespace hanzo::fusion {
namespace {

TEST(Time, ArithmeticIsExactInNanoseconds) {
  const Timestamp t = Timestamp::from_nanoseconds(1'700'000'000'123'456'789);
  const Duration d = Duration::from_milliseconds(5);
  EXPECT_EQ((t + d).nanoseconds(), 1'700'000'000'128'456'789);
  EXPECT_EQ(((t + d) - t).nanoseconds(), 5'000'000);
  EXPECT_EQ((t - d).nanoseconds(), 1'700'000'000'118'456'789);
  EXPECT_LT(t, t + Duration::from_nanoseconds(1));
  EXPECT_EQ(Duration::from_seconds(-0.005).nanoseconds(), -5'000'000);
  EXPECT_DOUBLE_EQ(Duration::from_microseconds(2500).seconds(), 0.0025);
}

TEST(Time, FromSecondsKeepsNanosecondsOfTodaysEpoch) {
  // 1403636579.763555584 s (a EuRoC timestamp) survives within double's resolution (~0.24 us).
  const Timestamp t = Timestamp::from_seconds(1403636579.763555584);
  EXPECT_NEAR(static_cast<double>(t.nanoseconds() - 1403636579763555584), 0.0, 250.0);
  EXPECT_TRUE(Timestamp().is_zero());
}

TEST(Time, SecondsBeyondInt64NanosecondsSaturate) {
  EXPECT_GT(Timestamp::from_seconds(1e300).nanoseconds(), 9'000'000'000'000'000'000);
  EXPECT_LT(Duration::from_seconds(-1e300).nanoseconds(), -9'000'000'000'000'000'000);
  EXPECT_EQ(Duration::from_seconds(std::nan("")).nanoseconds(), 0);
}

TEST(Time, Iso8601) {
  EXPECT_EQ(Timestamp::from_nanoseconds(0).to_iso8601(), "1970-01-01T00:00:00.000000000Z");
  EXPECT_EQ(Timestamp::from_nanoseconds(1'771'842'930'000'000'001).to_iso8601(), "2026-02-23T10:35:30.000000001Z");
  EXPECT_EQ(Timestamp::from_nanoseconds(-1).to_iso8601(), "1969-12-31T23:59:59.999999999Z");
}

}  // namespace
}  // namespace hanzo::fusion
