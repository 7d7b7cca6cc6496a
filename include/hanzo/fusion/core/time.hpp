#pragma once
// Time in hanzo-fusion: int64 nanoseconds. A Timestamp counts from the Unix epoch (UTC); a
// Duration is a signed difference of two timestamps. int64 nanoseconds cover +-292 years, so
// arithmetic on real timestamps never overflows; conversion to seconds (double) is for
// display and for algorithms that need dt, never for storage.

#include <compare>
#include <cstdint>
#include <string>

namespace hanzo::fusion {

class Duration {
 public:
  constexpr Duration() = default;
  static constexpr Duration from_nanoseconds(int64_t ns) { return Duration(ns); }
  static constexpr Duration from_microseconds(int64_t us) { return Duration(us * 1'000); }
  static constexpr Duration from_milliseconds(int64_t ms) { return Duration(ms * 1'000'000); }
  /// Rounds to the nearest nanosecond.
  static Duration from_seconds(double seconds);

  constexpr int64_t nanoseconds() const { return ns_; }
  constexpr double seconds() const { return static_cast<double>(ns_) * 1e-9; }

  constexpr Duration operator+(Duration other) const { return Duration(ns_ + other.ns_); }
  constexpr Duration operator-(Duration other) const { return Duration(ns_ - other.ns_); }
  constexpr Duration operator-() const { return Duration(-ns_); }
  constexpr Duration operator*(int64_t factor) const { return Duration(ns_ * factor); }
  constexpr Duration& operator+=(Duration other) { ns_ += other.ns_; return *this; }
  constexpr Duration& operator-=(Duration other) { ns_ -= other.ns_; return *this; }
  constexpr auto operator<=>(const Duration&) const = default;

 private:
  constexpr explicit Duration(int64_t ns) : ns_(ns) {}
  int64_t ns_ = 0;
};

class Timestamp {
 public:
  constexpr Timestamp() = default;
  static constexpr Timestamp from_nanoseconds(int64_t ns_since_epoch) { return Timestamp(ns_since_epoch); }
  /// Rounds to the nearest nanosecond (a double holds ~0.2 us resolution at today's epoch
  /// seconds, so prefer nanoseconds when reading files that have them).
  static Timestamp from_seconds(double seconds_since_epoch);
  /// The system's wall clock (for creation times of files and maps, never for sensor data).
  static Timestamp wall_clock_now();

  constexpr int64_t nanoseconds() const { return ns_; }
  constexpr double seconds() const { return static_cast<double>(ns_) * 1e-9; }
  /// The zero timestamp is never a valid sensor time; messages carrying it are rejected.
  constexpr bool is_zero() const { return ns_ == 0; }

  constexpr Timestamp operator+(Duration d) const { return Timestamp(ns_ + d.nanoseconds()); }
  constexpr Timestamp operator-(Duration d) const { return Timestamp(ns_ - d.nanoseconds()); }
  constexpr Duration operator-(Timestamp other) const { return Duration::from_nanoseconds(ns_ - other.ns_); }
  constexpr Timestamp& operator+=(Duration d) { ns_ += d.nanoseconds(); return *this; }
  constexpr auto operator<=>(const Timestamp&) const = default;

  /// "2026-02-23T10:15:30.123456789Z" (UTC, always 9 fractional digits).
  std::string to_iso8601() const;

 private:
  constexpr explicit Timestamp(int64_t ns) : ns_(ns) {}
  int64_t ns_ = 0;
};

}  // namespace hanzo::fusion
