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

constexpr std::string_view kArchivePrefix = "recordings/";

bool is_recording_file(const std::string& name) { return name.ends_with(".mcap") || name.ends_with(".mcap.enc"); }

// Uploads a finished recording to the archive and removes the local file; its archive location.
Result<std::string> archive_recording(object_store::ObjectStore& archive, const fs::path& path) {
  const std::string key = std::string(kArchivePrefix) + path.filename().string();
  HANZO_RETURN_IF_ERROR(archive.put_file(key, path.string()));
  std::error_code error;
  fs::remove(path, error);
  if (error) logger()->warn("{}: stored in {}, but the local copy could not be removed ({})", path.string(), archive.location_of(key), error.message());
  logger()->info("recording {} stored in {}", path.filename().string(), archive.location_of(key));
  return archive.location_of(key);
}

// Encrypts a plain recording into <file>.enc (keeping its modification time, which retention
// goes by) and removes the plaintext; the sealed path.
Result<fs::path> seal_recording(const fs::path& path, const crypto::EncryptionKey& key) {
  const fs::path sealed = path.string() + ".enc";
  std::error_code error;
  const fs::file_time_type modified = fs::last_write_time(path, error);
  if (const Status done = crypto::encrypt_file(path.string(), sealed.string(), key); !done) return Error("encryption: " + done.error().message);
  if (!error) fs::last_write_time(sealed, modified, error);
  fs::remove(path, error);
  if (error) return Error(fmt::format("{}: encrypted, but the plaintext could not be removed ({})", path.string(), error.message()));
  return sealed;
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
  state->info.location = state->path.string();
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
    if (Result<fs::path> sealed = seal_recording(path, *s.config.key); !sealed) {
      failure = sealed.error().message;
    } else {
      path = *sealed;
      encrypted = true;
    }
  }
  const uint64_t bytes = fs::exists(path, error) ? fs::file_size(path, error) : 0;
  std::string location = path.string();
  bool archived_ok = false;
  if (!failure && s.config.archive && fs::exists(path, error)) {
    Result<std::string> archived = archive_recording(*s.config.archive, path);
    if (archived) {
      location = *archived;
      archived_ok = true;
    } else {  // kept in the folder; the next retention pass uploads it
      failure = "archive: " + archived.error().message;
    }
  }
  std::lock_guard lock(s.mutex);
  s.path = path;
  s.info.active = false;
  s.info.file = path.filename().string();
  s.info.location = location;
  s.info.archived = archived_ok;
  s.info.encrypted = encrypted;
  s.info.bytes = bytes;
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
  if (config.directory.empty()) return outcome;
  const auto active = [&](const std::string& name) { return std::find(active_files.begin(), active_files.end(), name) != active_files.end(); };
  std::error_code error;
  // Plain recordings left by an earlier run (a server stopped without finishing them, or a failed
  // encryption) are encrypted before anything else happens to them.
  if (config.key && fs::is_directory(config.directory, error)) {
    std::vector<fs::path> plain;
    for (const fs::directory_entry& entry : fs::directory_iterator(config.directory, error)) {
      const std::string name = entry.path().filename().string();
      if (name.ends_with(".mcap") && entry.is_regular_file() && !active(name)) plain.push_back(entry.path());
    }
    for (const fs::path& path : plain) {
      HANZO_RETURN_IF_ERROR(seal_recording(path, *config.key));
      logger()->warn("recording {} was not encrypted (left by an earlier run); encrypted now", path.filename().string());
    }
  }
  if (config.archive && fs::is_directory(config.directory, error)) {
    for (const fs::directory_entry& entry : fs::directory_iterator(config.directory, error)) {
      const std::string name = entry.path().filename().string();
      if (!is_recording_file(name) || !entry.is_regular_file() || active(name)) continue;
      if (Result<std::string> archived = archive_recording(*config.archive, entry.path()); !archived) return archived.error();
    }
  }
  std::shared_ptr<object_store::ObjectStore> store = config.archive;
  std::string prefix(kArchivePrefix);
  if (!store) {
    if (!fs::is_directory(config.directory, error)) return outcome;
    std::unique_ptr<object_store::ObjectStore> local;
    HANZO_ASSIGN_OR_RETURN(local, object_store::open_local_object_store(config.directory));
    store = std::move(local);
    prefix.clear();
  }
  std::vector<object_store::ObjectInfo> objects;
  HANZO_ASSIGN_OR_RETURN(objects, store->list(prefix));
  std::vector<object_store::ObjectInfo> finished;
  for (object_store::ObjectInfo& object : objects) {
    const std::string name = object.key.substr(prefix.size());
    if (is_recording_file(name) && name.find('/') == std::string::npos && !active(name)) finished.push_back(std::move(object));
  }
  std::sort(finished.begin(), finished.end(), [](const auto& a, const auto& b) { return a.modified < b.modified; });
  uint64_t total = 0;
  for (const object_store::ObjectInfo& f : finished) total += f.size;
  const Timestamp cutoff = Timestamp::wall_clock_now() - Duration::from_seconds(std::chrono::duration<double>(config.retention).count());
  for (const object_store::ObjectInfo& f : finished) {
    const bool expired = config.retention.count() > 0 && f.modified < cutoff;
    const bool over_cap = config.max_total_bytes > 0 && total > config.max_total_bytes;
    if (!expired && !over_cap) continue;
    HANZO_RETURN_IF_ERROR(store->remove(f.key));
    outcome.deleted.push_back(f.key.substr(prefix.size()));
    outcome.bytes_freed += f.size;
    total -= f.size;
  }
  for (const std::string& name : outcome.deleted) logger()->info("recording {} deleted by the retention policy", name);
  return outcome;
}

Result<StoredRecording> find_recording(const RecordingConfig& config, const std::string& file) {
  const fs::path local = fs::path(config.directory) / file;
  std::error_code error;
  if (!config.directory.empty() && fs::is_regular_file(local, error)) {
    std::unique_ptr<object_store::ObjectStore> folder;
    HANZO_ASSIGN_OR_RETURN(folder, object_store::open_local_object_store(config.directory));
    return StoredRecording{std::move(folder), file, fs::file_size(local, error)};
  }
  if (config.archive) {
    const std::string key = std::string(kArchivePrefix) + file;
    std::optional<object_store::ObjectInfo> info;
    HANZO_ASSIGN_OR_RETURN(info, config.archive->stat(key));
    if (info) return StoredRecording{config.archive, key, info->size};
  }
  return Error(fmt::format("recording {}: not stored (deleted by the retention policy)", file), std::string(object_store::kNotFound));
}

}  // namespace hanzo::fusion::service
