#include "hanzo/fusion/service/session_recording.hpp"

#include <sys/stat.h>

#include <algorithm>
#include <filesystem>

#include <fmt/format.h>

#include "hanzo/fusion/core/logging.hpp"
#include "hanzo/fusion/io/sensor_log.hpp"
#include "hanzo/fusion/privacy/log_redaction.hpp"

namespace hanzo::fusion::service {

namespace fs = std::filesystem;

struct SessionRecording::State {
  RecordingConfig config;
  fs::path path;  // the MCAP being written
  std::unique_ptr<privacy::PrivacyFilter> filter;
  std::unique_ptr<io::SensorLogWriter> writer;
  privacy::TopicRedactionCounts audit;
  RecordingInfo info;
};

SessionRecording::SessionRecording(std::unique_ptr<State> state) : state_(std::move(state)) {}

SessionRecording::~SessionRecording() {
  if (const Status finished = finish(); !finished) logger()->warn("recording {}: {}", state_->path.string(), finished.error().message);
}

Result<std::unique_ptr<SessionRecording>> SessionRecording::start(const RecordingConfig& config, const std::string& session_id,
                                                                  std::optional<privacy::Redaction> redaction) {
  if (config.directory.empty()) return Error("the server records no sessions (no recordings folder)");
  std::error_code error;
  fs::create_directories(config.directory, error);
  if (error) return Error(fmt::format("{}: cannot create the recordings folder ({})", config.directory, error.message()));
  auto state = std::make_unique<State>();
  state->config = config;
  state->path = fs::path(config.directory) / (session_id + ".mcap");
  state->info.file = state->path.filename().string();
  state->info.active = true;
  state->info.privacy = redaction ? std::string(privacy::to_string(*redaction)) : "off";
  io::SensorLogWriterConfig writer_config;
  writer_config.foxglove_channels = false;  // the raw streams only
  if (redaction) {
    privacy::PrivacyFilterConfig filter_config;
    filter_config.redaction = *redaction;
    HANZO_ASSIGN_OR_RETURN(state->filter, privacy::PrivacyFilter::create(filter_config));
    State* raw = state.get();
    writer_config.image_filter = [raw](msgs::ImageMessage& image) -> Status {
      std::vector<privacy::RedactedRegion> regions;
      HANZO_ASSIGN_OR_RETURN(regions, raw->filter->apply(image));
      privacy::count_regions(regions, raw->audit);
      return ok_status();
    };
  }
  HANZO_ASSIGN_OR_RETURN(state->writer, io::SensorLogWriter::open(state->path.string(), writer_config));
  ::chmod(state->path.c_str(), S_IRUSR | S_IWUSR);
  return std::unique_ptr<SessionRecording>(new SessionRecording(std::move(state)));
}

void SessionRecording::record(const std::string& topic, const std::string& sensor, const msgs::SensorMessage& message) {
  State& s = *state_;
  if (!s.writer) return;
  const Status written = s.writer->write(topic, message, sensor);
  if (written) {
    ++s.info.messages;
    return;
  }
  if (!written.error().field.empty()) {  // msgs::validate refused it: the session will refuse it too
    ++s.info.invalid_messages;
    return;
  }
  s.info.error = written.error().message;
  logger()->error("recording {} stopped: {}", s.path.string(), written.error().message);
  (void)s.writer->close();
  s.writer.reset();
}

Status SessionRecording::finish() {
  State& s = *state_;
  if (!s.info.active) return ok_status();
  s.info.active = false;
  if (s.writer) {
    const Status closed = s.writer->close();
    s.writer.reset();
    if (!closed && !s.info.error) s.info.error = closed.error().message;
  }
  std::error_code error;
  if (s.config.key && fs::exists(s.path, error)) {
    const fs::path encrypted = s.path.string() + ".enc";
    if (const Status done = crypto::encrypt_file(s.path.string(), encrypted.string(), *s.config.key); !done) {
      s.info.error = "encryption: " + done.error().message;
      return done;
    }
    fs::remove(s.path, error);
    s.path = encrypted;
    s.info.file = encrypted.filename().string();
    s.info.encrypted = true;
  }
  s.info.bytes = fs::exists(s.path, error) ? fs::file_size(s.path, error) : 0;
  return s.info.error ? Status(Error(*s.info.error)) : ok_status();
}

RecordingInfo SessionRecording::info() const {
  RecordingInfo info = state_->info;
  info.images = state_->audit.images;
  info.redacted_images = state_->audit.redacted_images;
  info.faces = state_->audit.faces;
  info.licence_plates = state_->audit.licence_plates;
  if (info.active) {  // the chunks flushed so far
    std::error_code error;
    info.bytes = fs::file_size(state_->path, error);
    if (error) info.bytes = 0;
  }
  return info;
}

Result<RetentionOutcome> apply_recording_retention(const RecordingConfig& config, const std::vector<std::string>& active_files) {
  RetentionOutcome outcome;
  if (config.directory.empty() || !fs::exists(config.directory)) return outcome;
  struct Finished {
    fs::path path;
    fs::file_time_type modified;
    uint64_t bytes;
  };
  std::vector<Finished> finished;
  std::error_code error;
  for (const fs::directory_entry& entry : fs::directory_iterator(config.directory, error)) {
    const std::string name = entry.path().filename().string();
    const bool recording = name.ends_with(".mcap") || name.ends_with(".mcap.enc");
    if (!recording || !entry.is_regular_file() || std::find(active_files.begin(), active_files.end(), name) != active_files.end()) continue;
    finished.push_back({entry.path(), entry.last_write_time(), entry.file_size()});
  }
  if (error) return Error(fmt::format("{}: cannot list the recordings ({})", config.directory, error.message()));
  std::sort(finished.begin(), finished.end(), [](const Finished& a, const Finished& b) { return a.modified < b.modified; });
  uint64_t total = 0;
  for (const Finished& f : finished) total += f.bytes;
  const auto cutoff = fs::file_time_type::clock::now() - config.retention;
  for (const Finished& f : finished) {
    const bool expired = config.retention.count() > 0 && f.modified < cutoff;
    const bool over_cap = config.max_total_bytes > 0 && total > config.max_total_bytes;
    if (!expired && !over_cap) continue;
    if (!fs::remove(f.path, error)) return Error(fmt::format("{}: cannot delete ({})", f.path.string(), error.message()));
    outcome.deleted.push_back(f.path.filename().string());
    outcome.bytes_freed += f.bytes;
    total -= f.bytes;
  }
  for (const std::string& name : outcome.deleted) logger()->info("recording {} deleted by the retention policy", name);
  return outcome;
}

}  // namespace hanzo::fusion::service
