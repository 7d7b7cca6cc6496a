#pragma once
// UTC calendar dates of GNSS receivers and IMUs into days since the Unix epoch (no leap seconds:
// UTC as POSIX counts it).

#include <cstdint>

namespace hanzo::fusion::drivers {

// Days from 1970-01-01 to a proleptic Gregorian date (the civil-from-days inverse: shift the
// year to start in March so that the leap day is last, count 400-year eras).
inline int64_t days_from_civil(int64_t year, int month, int day) {
  year -= month <= 2 ? 1 : 0;
  const int64_t era = (year >= 0 ? year : year - 399) / 400;
  const auto year_of_era = static_cast<int64_t>(year - era * 400);
  const int64_t day_of_year = (153 * (month + (month > 2 ? -3 : 9)) + 2) / 5 + day - 1;
  const int64_t day_of_era = year_of_era * 365 + year_of_era / 4 - year_of_era / 100 + day_of_year;
  return era * 146097 + day_of_era - 719468;
}

/// Dates a receiver can report (GPS time began in 1980).
inline bool valid_date(int64_t year, int month, int day) {
  return year >= 1980 && year <= 2200 && month >= 1 && month <= 12 && day >= 1 && day <= 31;
}

}  // namespace hanzo::fusion::drivers
