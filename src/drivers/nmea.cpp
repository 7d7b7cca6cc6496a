#include "hanzo/fusion/drivers/nmea.hpp"

#include <algorithm>
#include <charconv>
#include <cmath>

#include <fmt/format.h>

#include "civil_time.hpp"

namespace hanzo::fusion::drivers {

namespace {

constexpr double kSecondsPerDay = 86400.0;

int hex_value(char c) {
  if (c >= '0' && c <= '9') return c - '0';
  if (c >= 'A' && c <= 'F') return c - 'A' + 10;
  if (c >= 'a' && c <= 'f') return c - 'a' + 10;
  return -1;
}

std::optional<double> parse_number(std::string_view text) {
  if (text.empty()) return std::nullopt;
  double value = 0.0;
  const auto [end, error] = std::from_chars(text.data(), text.data() + text.size(), value);
  if (error != std::errc() || end != text.data() + text.size() || !std::isfinite(value)) return std::nullopt;
  return value;
}

// hhmmss(.sss) to seconds of the day.
std::optional<double> parse_time_of_day(std::string_view text) {
  if (text.size() < 6) return std::nullopt;
  const std::optional<double> hours = parse_number(text.substr(0, 2)), minutes = parse_number(text.substr(2, 2)), seconds = parse_number(text.substr(4));
  if (!hours || !minutes || !seconds || *hours > 23 || *minutes > 59 || *seconds >= 61) return std::nullopt;
  return *hours * 3600.0 + *minutes * 60.0 + *seconds;
}

// ddmm.mmmm / dddmm.mmmm with a hemisphere letter to signed degrees.
std::optional<double> parse_angle(std::string_view value, std::string_view hemisphere, int degree_digits, char negative, char positive) {
  if (value.size() < static_cast<std::size_t>(degree_digits) + 2 || hemisphere.size() != 1) return std::nullopt;
  const std::optional<double> degrees = parse_number(value.substr(0, static_cast<std::size_t>(degree_digits)));
  const std::optional<double> minutes = parse_number(value.substr(static_cast<std::size_t>(degree_digits)));
  if (!degrees || !minutes || *minutes >= 60.0) return std::nullopt;
  const double angle = *degrees + *minutes / 60.0;
  if (hemisphere[0] == negative) return -angle;
  if (hemisphere[0] == positive) return angle;
  return std::nullopt;
}

std::string_view field(const NmeaSentence& sentence, std::size_t index) {
  return index < sentence.fields.size() ? std::string_view(sentence.fields[index]) : std::string_view();
}

}  // namespace

Result<NmeaSentence> parse_nmea_sentence(std::string_view line) {
  while (!line.empty() && (line.back() == '\r' || line.back() == '\n')) line.remove_suffix(1);
  if (line.empty() || (line[0] != '$' && line[0] != '!')) return Error("NMEA sentence does not start with '$'");
  if (line.size() > kMaxSentenceLength) return Error(fmt::format("NMEA sentence of {} characters (at most {})", line.size(), kMaxSentenceLength));
  std::string_view body = line.substr(1);
  for (const char c : body) {
    if (c < 0x20 || c > 0x7e) return Error("NMEA sentence holds a non-printable byte");
  }
  NmeaSentence sentence;
  if (const std::size_t star = body.rfind('*'); star != std::string_view::npos) {
    const std::string_view digits = body.substr(star + 1);
    if (digits.size() != 2 || hex_value(digits[0]) < 0 || hex_value(digits[1]) < 0) return Error("NMEA checksum is not two hex digits");
    body = body.substr(0, star);
    unsigned checksum = 0;
    for (const char c : body) checksum ^= static_cast<unsigned char>(c);
    const auto expected = static_cast<unsigned>(hex_value(digits[0]) * 16 + hex_value(digits[1]));
    if (checksum != expected) return Error(fmt::format("NMEA checksum mismatch ({:02X} computed, {:02X} written)", checksum, expected));
    sentence.checksum_present = true;
  }
  std::size_t start = 0;
  std::vector<std::string_view> parts;
  while (true) {
    const std::size_t comma = body.find(',', start);
    parts.push_back(body.substr(start, comma == std::string_view::npos ? std::string_view::npos : comma - start));
    if (comma == std::string_view::npos) break;
    start = comma + 1;
  }
  const std::string_view address = parts.front();
  if (address.empty()) return Error("NMEA sentence without an address");
  if (address[0] == 'P') {  // proprietary: P + maker's code
    sentence.talker = std::string(address);
  } else {
    if (address.size() < 5) return Error(fmt::format("NMEA address '{}' is shorter than talker + type", address));
    sentence.talker = std::string(address.substr(0, 2));
    sentence.type = std::string(address.substr(2));
  }
  for (std::size_t i = 1; i < parts.size(); ++i) sentence.fields.emplace_back(parts[i]);
  return sentence;
}

Result<NmeaDecoder> NmeaDecoder::create(NmeaDecoderConfig config) {
  for (const double value : {config.uere_autonomous, config.uere_dgps, config.uere_rtk_float, config.uere_rtk_fixed, config.vertical_factor,
                             config.unknown_geoid_sigma}) {
    if (!(value > 0.0 && std::isfinite(value))) return Error("NMEA decoder: error scales must be positive", "uere");
  }
  NmeaDecoder decoder(config);
  if (!config.date.empty()) {
    int year = 0, month = 0, day = 0;
    if (std::sscanf(config.date.c_str(), "%4d-%2d-%2d", &year, &month, &day) != 3 || !valid_date(year, month, day)) {
      return Error(fmt::format("NMEA decoder: date '{}' is not YYYY-MM-DD", config.date), "date");
    }
    decoder.date_days_ = days_from_civil(year, month, day);
  }
  return decoder;
}

void NmeaDecoder::feed(std::string_view bytes, std::vector<msgs::GnssMessage>& fixes) {
  for (const char c : bytes) {
    if (c == '$' || c == '!') {
      if (in_sentence_) abandon_line("NMEA sentence cut off by the next one");
      line_.assign(1, c);
      in_sentence_ = true;
      continue;
    }
    if (!in_sentence_) {
      ++statistics_.skipped_bytes;
      continue;
    }
    if (c == '\n' || c == '\r') {
      in_sentence_ = false;
      handle_line(line_, fixes);
      continue;
    }
    if (line_.size() >= kMaxSentenceLength) {
      in_sentence_ = false;
      ++statistics_.skipped_bytes;
      abandon_line(fmt::format("NMEA sentence longer than {} characters", kMaxSentenceLength));
      continue;
    }
    line_.push_back(c);
  }
}

void NmeaDecoder::flush(std::vector<msgs::GnssMessage>& fixes) {
  if (in_sentence_) {  // a last sentence without its line end
    in_sentence_ = false;
    handle_line(line_, fixes);
  }
  complete_epoch(std::nullopt, fixes);
}

namespace {
// Printable throughout and opened by an address ("$GPGGA,", "$PUBX,"): a sentence, perhaps a
// broken one. Anything else that starts with '$' is a '$' byte inside binary data.
bool looks_like_sentence(std::string_view line) {
  if (!std::all_of(line.begin(), line.end(), [](char c) { return c >= 0x20 && c <= 0x7e; })) return false;
  const std::size_t comma = line.find(',');
  if (comma == std::string_view::npos || comma < 3 || comma > 7) return false;
  return std::all_of(line.begin() + 1, line.begin() + static_cast<std::ptrdiff_t>(comma), [](char c) { return (c >= 'A' && c <= 'Z') || (c >= '0' && c <= '9'); });
}
}  // namespace

void NmeaDecoder::abandon_line(const std::string& why) {
  statistics_.skipped_bytes += line_.size();
  if (looks_like_sentence(line_)) malformed(why);  // else a '$' inside binary data: no sentence at all
}

void NmeaDecoder::malformed(const std::string& what) {
  ++statistics_.malformed;
  if (statistics_.first_error.empty()) statistics_.first_error = what;
}

void NmeaDecoder::handle_line(std::string_view line, std::vector<msgs::GnssMessage>& fixes) {
  // A '$' inside binary data (another protocol on the same port) starts no sentence.
  if (!looks_like_sentence(line)) {
    statistics_.skipped_bytes += line.size() + 1;
    return;
  }
  Result<NmeaSentence> sentence = parse_nmea_sentence(line);
  if (!sentence) {
    if (sentence.error().message.find("checksum") != std::string::npos) {
      ++statistics_.checksum_errors;
      if (statistics_.first_error.empty()) statistics_.first_error = sentence.error().message;
    } else {
      malformed(sentence.error().message);
    }
    return;
  }
  ++statistics_.sentences;
  handle(*sentence, fixes);
}

void NmeaDecoder::complete_epoch(std::optional<double> time_of_day, std::vector<msgs::GnssMessage>& fixes) {
  if (!pending_) return;
  if (time_of_day && std::abs(*time_of_day - pending_->time_of_day) < 1e-3) return;  // the same epoch
  Pending& done = *pending_;
  if (!done.has_gst) {
    const double horizontal = std::max(static_cast<double>(done.fix.hdop), 0.5) * done.hdop_sigma;
    const double vertical = config_.vertical_factor * horizontal;
    done.fix.position_covariance = Eigen::Vector3d(horizontal * horizontal, horizontal * horizontal, vertical * vertical).asDiagonal();
  } else {
    ++statistics_.gst;
  }
  if (done.unknown_geoid) (*done.fix.position_covariance)(2, 2) += config_.unknown_geoid_sigma * config_.unknown_geoid_sigma;
  fixes.push_back(done.fix);
  ++statistics_.fixes;
  pending_.reset();
}

void NmeaDecoder::handle(const NmeaSentence& sentence, std::vector<msgs::GnssMessage>& fixes) {
  const std::string& type = sentence.type;
  if (type == "GGA") {
    if (field(sentence, 0).empty()) {  // a receiver without a fix may leave out even the time
      ++statistics_.no_position;
      return;
    }
    const std::optional<double> time_of_day = parse_time_of_day(field(sentence, 0));
    if (!time_of_day) return malformed(fmt::format("{}GGA: time '{}' is not hhmmss.ss", sentence.talker, field(sentence, 0)));
    complete_epoch(time_of_day, fixes);
    if (field(sentence, 1).empty() || field(sentence, 3).empty()) {
      ++statistics_.no_position;
      return;
    }
    const std::optional<double> latitude = parse_angle(field(sentence, 1), field(sentence, 2), 2, 'S', 'N');
    const std::optional<double> longitude = parse_angle(field(sentence, 3), field(sentence, 4), 3, 'W', 'E');
    const std::optional<double> quality = parse_number(field(sentence, 5));
    if (!latitude || !longitude || !quality || std::abs(*latitude) > 90.0 || std::abs(*longitude) > 180.0) {
      return malformed(fmt::format("{}GGA: position or quality unreadable", sentence.talker));
    }
    if (!date_days_) {
      ++statistics_.no_date;
      return;
    }
    // The date's day, moved by one where midnight passed between the date and this time.
    int64_t days = *date_days_;
    if (date_time_of_day_) {
      if (*time_of_day < *date_time_of_day_ - kSecondsPerDay / 2) ++days;
      if (*time_of_day > *date_time_of_day_ + kSecondsPerDay / 2) --days;
    }
    Pending pending;
    pending.time_of_day = *time_of_day;
    msgs::GnssMessage& fix = pending.fix;
    fix.timestamp = Timestamp::from_nanoseconds(days * 86'400'000'000'000LL + std::llround(*time_of_day * 1e9));
    fix.latitude = *latitude;
    fix.longitude = *longitude;
    const std::optional<double> altitude_msl = parse_number(field(sentence, 8));
    const std::optional<double> geoid_separation = parse_number(field(sentence, 10));
    fix.altitude = altitude_msl.value_or(0.0) + geoid_separation.value_or(0.0);
    if (altitude_msl && !geoid_separation) {
      pending.unknown_geoid = true;
      ++statistics_.no_geoid_separation;
    }
    fix.satellites_used = static_cast<uint32_t>(parse_number(field(sentence, 6)).value_or(0.0));
    fix.hdop = static_cast<float>(parse_number(field(sentence, 7)).value_or(99.0));
    switch (static_cast<int>(*quality)) {
      case 1:
      case 3:
        fix.fix_type = gsa_mode_ == 2 ? msgs::GnssFixType::kFix2d : msgs::GnssFixType::kFix3d;
        pending.hdop_sigma = config_.uere_autonomous;
        break;
      case 2:
        fix.fix_type = msgs::GnssFixType::kFix3d;
        pending.hdop_sigma = config_.uere_dgps;
        break;
      case 4:
        fix.fix_type = msgs::GnssFixType::kRtkFixed;
        pending.hdop_sigma = config_.uere_rtk_fixed;
        break;
      case 5:
        fix.fix_type = msgs::GnssFixType::kRtkFloat;
        pending.hdop_sigma = config_.uere_rtk_float;
        break;
      default:  // 0 invalid, 6 dead reckoning, 7 manual, 8 simulation
        fix.fix_type = msgs::GnssFixType::kNoFix;
        pending.hdop_sigma = config_.uere_autonomous;
        break;
    }
    if (!altitude_msl && fix.fix_type != msgs::GnssFixType::kNoFix) fix.fix_type = msgs::GnssFixType::kFix2d;
    if (gst_ && std::abs(gst_->first - *time_of_day) < 1e-3) {  // the epoch's GST came first
      fix.position_covariance = gst_->second.asDiagonal();
      pending.has_gst = true;
    }
    pending_ = std::move(pending);
    return;
  }
  if (type == "RMC" || type == "ZDA") {
    if (field(sentence, 0).empty()) return;  // no time yet (no fix)
    const std::optional<double> time_of_day = parse_time_of_day(field(sentence, 0));
    if (!time_of_day) return malformed(fmt::format("{}{}: time '{}' is not hhmmss.ss", sentence.talker, type, field(sentence, 0)));
    complete_epoch(time_of_day, fixes);
    int64_t year = 0;
    int month = 0, day = 0;
    if (type == "RMC") {
      const std::string_view date = field(sentence, 8);
      const std::optional<double> day_value = parse_number(date.substr(0, 2));
      if (date.size() != 6 || !day_value) return;  // RMC without a date (no fix yet): nothing to learn
      day = static_cast<int>(*day_value);
      month = static_cast<int>(parse_number(date.substr(2, 2)).value_or(0.0));
      year = 2000 + static_cast<int64_t>(parse_number(date.substr(4, 2)).value_or(-1.0));
      if (year < 2000) return malformed(fmt::format("{}RMC: date '{}' is not ddmmyy", sentence.talker, date));
      if (year >= 2080) year -= 100;  // two-digit years: 1980-2079
    } else {
      day = static_cast<int>(parse_number(field(sentence, 1)).value_or(0.0));
      month = static_cast<int>(parse_number(field(sentence, 2)).value_or(0.0));
      year = static_cast<int64_t>(parse_number(field(sentence, 3)).value_or(0.0));
    }
    if (!valid_date(year, month, day)) return malformed(fmt::format("{}{}: date {}-{}-{} is not valid", sentence.talker, type, year, month, day));
    date_days_ = days_from_civil(year, month, day);
    date_time_of_day_ = *time_of_day;
    return;
  }
  if (type == "GST") {
    const std::optional<double> time_of_day = parse_time_of_day(field(sentence, 0));
    if (!time_of_day) return malformed(fmt::format("{}GST: time '{}' is not hhmmss.ss", sentence.talker, field(sentence, 0)));
    const std::optional<double> latitude_sigma = parse_number(field(sentence, 5)), longitude_sigma = parse_number(field(sentence, 6));
    const std::optional<double> altitude_sigma = parse_number(field(sentence, 7));
    if (!latitude_sigma || !longitude_sigma || !(*latitude_sigma > 0.0) || !(*longitude_sigma > 0.0)) return;  // without usable errors
    const double vertical = altitude_sigma && *altitude_sigma > 0.0 ? *altitude_sigma : config_.vertical_factor * std::max(*latitude_sigma, *longitude_sigma);
    const Eigen::Vector3d variances(*longitude_sigma * *longitude_sigma, *latitude_sigma * *latitude_sigma, vertical * vertical);
    if (pending_ && std::abs(*time_of_day - pending_->time_of_day) < 1e-3) {
      pending_->fix.position_covariance = variances.asDiagonal();
      pending_->has_gst = true;
    } else {
      gst_ = std::make_pair(*time_of_day, variances);  // for the epoch's GGA still to come
    }
    return;
  }
  if (type == "GSA") {
    // NMEA 4.11 GSA: mode (M/A), fix mode (1 none, 2 2D, 3 3D), ...
    gsa_mode_ = static_cast<int>(parse_number(field(sentence, 1)).value_or(0.0));
    return;
  }
  ++statistics_.other_sentences;
}

}  // namespace hanzo::fusion::drivers
