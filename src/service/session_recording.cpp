#include "hanzo/fusion/service/session_recording.hpp"

#include <sys/stat.h>

#include <algorithm>
#include <condition_variable>
#include <deque>
#include <filesystem>
#include <mutex>
#include <thread>

#include <fmt/format.h>

#include "hanzo/fusion/core/logging.hpp"
#include "hanzo/fusion/io/sensor_log.hpp"
#include "hanzo/fusion/privacy/log_redaction.hpp"

namespace hanzo::fusion::service {

namespace fs = std::filesystem;

namespace {

// Bytes a queued message holds (its payload), for the queue's budget.
uint64_t payload_bytes(const msgs::SensorMessage& message) {
  if (const auto* cloud = std::get_if<msgs::PointCloudMessage>(&message)) return cloud->points.size() * 24 + 64;
  if (const auto* image = std::get_if<msgs::ImageMessage>(&message)) return image->data.size() + 64;
  return 256;
}

struct QueuedMessage {
  std::string topic;
  std::string sensor;
  msgs::SensorMessage message;
  uint64_t bytes = 0;
};

}  // namespace

struct SessionRecording::State {
  RecordingConfig config;
  fs::path path;  // the MCAP being written
  std::unique_ptr<privacy::PrivacyFilter> filter;  // used by the writer thread only
  std::unique_ptr<io::SensorLogWriter> writer;     // used by the writer thread only

  mutable std::mutex mutex;  // guards everything below
  std::condition_variable wake;
  std::deque<QueuedMessage> queue;
  uint64_t queued_bytes = 0;
  bool stopping = false;
  bool finished = false;
  privacy::TopicRedactionCounts audit;
  RecordingInfo info;
  std::thread thread;

  void run() {
    while (true) {
      QueuedMessage next;
      {
        std::unique_lock lock(mutex);
        wake.wait(lock, [&] { return stopping || !queue.empty(); });
        if (queue.empty()) return;
        next = std::move(queue.front());
        queue.pop_front();
        queued_bytes -= next.bytes;
      }
      write(next);
    }
  }

  void write(const QueuedMessage& queued) {
    if (!writer) return;  // stopped by an earlier error
    const Status written = writer->write(queued.topic, queued.message, queued.sensor);
    std::lock_guard lock(mutex);
    if (written) {
      ++info.messages;
    } else if (!written.error().field.empty()) {  // msgs::validate refused it: the session refuses it too
      ++info.invalid_messages;
    } else {
      info.error = written.error().message;
      logger()->error("recording {} stopped: {}", path.string(), written.error().message);
      (void)writer->close();
      writer.reset();
    }
  }
};

SessionRecording::SessionRecording(std::unique_ptr<State> state) : state_(std::move(state)) {
  State* raw = state_.get();
  state_->thread = std::thread([raw] { raw->run(); });
}

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
      std::lock_guard lock(raw->mutex);
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
  const uint64_t bytes = payload_bytes(message);
  {
    std::lock_guard lock(s.mutex);
    if (s.stopping || s.info.error) return;
    if (s.queued_bytes + bytes > s.config.max_queued_bytes) {
      if (s.info.dropped_messages++ == 0) logger()->warn("recording {}: the writer is behind; messages are left out", s.path.string());
      return;
    }
    s.queue.push_back({topic, sensor, message, bytes});
    s.queued_bytes += bytes;
  }
  s.wake.notify_one();
}

Status SessionRecording::finish() {
  State& s = *state_;
  {
    std::lock_guard lock(s.mutex);
    if (s.finished) return s.info.error ? Status(Error(*s.info.error)) : ok_status();
    s.finished = true;
    s.stopping = true;
  }
  s.wake.notify_one();
  if (s.thread.joinable()) s.thread.join();  // writes what is queued first
  std::optional<std::string> failure;
  if (s.writer) {
    const Status closed = s.writer->close();
    s.writer.reset();
    if (!closed) failure = closed.error().message;
  }
  std::error_code error;
  fs::path path = s.path;
  bool encrypted = false;
  if (!failure && s.config.key && fs::exists(path, error)) {
    const fs::path sealed = path.string() + ".enc";
    if (const Status done = crypto::encrypt_file(path.string(), sealed.string(), *s.config.key); !done) {
      failure = "encryption: " + done.error().message;
    } else {
      fs::remove(path, error);
      path = sealed;
      encrypted = true;
    }
  }
  std::lock_guard lock(s.mutex);
  s.path = path;
  s.info.active = false;
  s.info.file = path.filename().string();
  s.info.encrypted = encrypted;
  s.info.bytes = fs::exists(path, error) ? fs::file_size(path, error) : 0;
  if (failure && !s.info.error) s.info.error = failure;
  return s.info.error ? Status(Error(*s.info.error)) : ok_status();
}

RecordingInfo SessionRecording::info() const {
  std::lock_guard lock(state_->mutex);
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
