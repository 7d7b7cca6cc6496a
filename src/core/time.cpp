#include "hanzo/fusion/core/time.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <ctime>

#include <fmt/format.h>

namespace hanzo::fusion {

namespace {

// The seconds an int64 count of nanoseconds holds (about 292 years), kept a little inside so the
// rounding below cannot overflow. NaN maps to 0.
double representable_seconds(double seconds) {
  constexpr double kLimit = 9.2e9;
  if (std::isnan(seconds)) return 0.0;
  return std::clamp(seconds, -kLimit, kLimit);
}

}  // namespace

Duration Duration::from_seconds(double seconds) {
  return Duration(static_cast<int64_t>(std::llround(representable_seconds(seconds) * 1e9)));
}

Timestamp Timestamp::wall_clock_now() {
  return Timestamp(
      std::chrono::duration_cast<std::chrono::nanoseconds>(std::chrono::system_clock::now().time_since_epoch()).count());
}

Timestamp Timestamp::from_seconds(double seconds_since_epoch) {
  // Split into whole and fractional seconds first so the nanoseconds keep full precision.
  const double seconds = representable_seconds(seconds_since_epoch);
  const double whole = std::floor(seconds);
  const auto fraction_ns = static_cast<int64_t>(std::llround((seconds - whole) * 1e9));
  return Timestamp(static_cast<int64_t>(whole) * 1'000'000'000 + fraction_ns);
}

std::string Timestamp::to_iso8601() const {
  int64_t seconds = ns_ / 1'000'000'000;
  int64_t fraction = ns_ % 1'000'000'000;
  if (fraction < 0) {  // floor division for times before the epoch
    fraction += 1'000'000'000;
    seconds -= 1;
  }
  const auto time = static_cast<std::time_t>(seconds);
  std::tm utc{};
  gmtime_r(&time, &utc);
  return fmt::format("{:04}-{:02}-{:02}T{:02}:{:02}:{:02}.{:09}Z", utc.tm_year + 1900, utc.tm_mon + 1,
                     utc.tm_mday, utc.tm_hour, utc.tm_min, utc.tm_sec, fraction);
}

}  // namespace hanzo::fusion
