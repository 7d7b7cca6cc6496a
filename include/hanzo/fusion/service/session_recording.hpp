#pragma once
// Raw sensor logging of server sessions (HIP-0083 "Storage and Persistence": raw sensor streams
// optionally logged in the standard message format): a recording session writes every message
// pushed into it, as it arrived, to a sensor log (io/sensor_log.hpp: MCAP, zstd chunks, the
// session's topics and sensor names) in the recordings folder, so the drive can be replayed
// with `hanzo-fusion run` or streamed again.
//
//   - Privacy: with a redaction (the default: blur), camera images pass the privacy filter
//     (privacy/privacy_filter.hpp: faces and licence plates) before anything of them is
//     written; the counts are the session's audit (images, redacted images, faces, plates).
//   - Encryption at rest: with a key, the finished log is encrypted (crypto/file_encryption.hpp,
//     XChaCha20-Poly1305 secretstream) into <id>.mcap.enc and the plaintext removed when the
//     session ends. While the session runs, the log being written is a plaintext file (mode
//     0600) in the recordings folder.
//   - Object storage: with an archive store (an S3 bucket), the finished (and encrypted) log is
//     uploaded as recordings/<file> and the local file removed once stored. When the upload
//     fails the file stays in the recordings folder (and is served from there); the next
//     retention pass uploads it.
//   - Retention: apply_recording_retention() deletes finished recordings older than the
//     retention and, beyond a total size, the oldest ones, wherever they are kept; recordings
//     still being written are never deleted.
// Writing (privacy filter, serialization, compression) runs on the recording's own thread: the
// session only queues a copy, so recording never slows fusion. When the writer falls behind
// (the privacy filter takes ~70 ms an image on one core) and the queue holds max_queued_bytes,
// further messages are left out of the recording and counted (dropped_messages) rather than
// stalling the session. A message that fails validation is not written (counted); a write
// error stops the recording (the error is kept and reported) without affecting the fusion.

#include <chrono>
#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "hanzo/fusion/core/result.hpp"
#include "hanzo/fusion/crypto/file_encryption.hpp"
#include "hanzo/fusion/msgs/sensor_messages.hpp"
#include "hanzo/fusion/object_store/object_store.hpp"
#include "hanzo/fusion/privacy/privacy_filter.hpp"

namespace hanzo::fusion::service {

struct RecordingConfig {
  /// Folder of the recordings (the server uses DATA_DIR/recordings). Empty: sessions cannot record.
  std::string directory;
  /// Whether a session records when its create request does not say.
  bool record_by_default = false;
  /// Images redacted before they are written (faces and licence plates); nullopt: written as
  /// they came. A session may ask for "blur", "black" or, when allow_unfiltered, "off".
  std::optional<privacy::Redaction> redaction = privacy::Redaction::kBlur;
  /// Whether a session may turn the privacy filter off for its recording.
  bool allow_unfiltered = false;
  /// Finished recordings are encrypted with this key (none: kept as plain MCAP).
  std::optional<crypto::EncryptionKey> key;
  /// Finished recordings are moved into this store as recordings/<file>; null: they stay in
  /// `directory`.
  std::shared_ptr<object_store::ObjectStore> archive;
  /// Finished recordings older than this are deleted by apply_recording_retention (0: kept).
  std::chrono::hours retention{24 * 30};
  /// Beyond this many bytes of finished recordings the oldest are deleted (0: no cap).
  uint64_t max_total_bytes = 0;
  /// Messages waiting for the writer, at most (bytes of their payloads); beyond it messages are dropped.
  uint64_t max_queued_bytes = 512ull << 20;
};

/// What a session's recording holds; reported in the session status.
struct RecordingInfo {
  std::string file;            ///< file name (<id>.mcap, <id>.mcap.enc when finished encrypted)
  std::string location;        ///< where it is: its path, or its s3:// URL once archived
  bool archived = false;       ///< moved into the archive store
  bool active = false;         ///< still being written
  bool encrypted = false;
  std::string privacy;         ///< "blur", "black" or "off"
  uint64_t messages = 0;       ///< written
  uint64_t invalid_messages = 0;  ///< not written: failed validation
  uint64_t dropped_messages = 0;  ///< not written: the writer was max_queued_bytes behind
  uint64_t bytes = 0;          ///< of the file (when finished) or written so far (approximate while active)
  uint64_t images = 0;         ///< privacy audit: images checked
  uint64_t redacted_images = 0;
  uint64_t faces = 0;
  uint64_t licence_plates = 0;
  std::optional<std::string> error;  ///< why the recording stopped early
};

class SessionRecording {
 public:
  /// Creates <directory>/<session_id>.mcap. `redaction` nullopt: images unfiltered. Fails when
  /// the file cannot be created or the privacy models cannot be loaded.
  static Result<std::unique_ptr<SessionRecording>> start(const RecordingConfig& config, const std::string& session_id,
                                                         std::optional<privacy::Redaction> redaction);
  ~SessionRecording();
  SessionRecording(const SessionRecording&) = delete;
  SessionRecording& operator=(const SessionRecording&) = delete;

  /// Queues a copy of one message as it arrived on `topic` from `sensor` for the writer thread
  /// (which runs the privacy filter on images first). Thread-safe.
  void record(const std::string& topic, const std::string& sensor, const msgs::SensorMessage& message);
  /// Writes what is queued, finishes the log (and encrypts it with the config's key). Idempotent.
  Status finish();
  RecordingInfo info() const;

 private:
  struct State;
  explicit SessionRecording(std::unique_ptr<State> state);
  std::unique_ptr<State> state_;
};

/// The recordings a retention pass deleted, by file name.
struct RetentionOutcome {
  std::vector<std::string> deleted;
  uint64_t bytes_freed = 0;
};

/// With a key, encrypts the plain recordings (*.mcap not in `active_files`: left by a server that
/// stopped without finishing them, or whose encryption failed) keeping their modification times;
/// archives finished recordings left in the folder (an earlier upload failed), then deletes
/// finished recordings (*.mcap, *.mcap.enc not in `active_files`) stored before now - retention,
/// then the oldest while the rest exceed max_total_bytes.
Result<RetentionOutcome> apply_recording_retention(const RecordingConfig& config, const std::vector<std::string>& active_files);

/// A finished recording where it is kept: the archive (key recordings/<file>) or the folder.
struct StoredRecording {
  std::shared_ptr<object_store::ObjectStore> store;
  std::string key;
  uint64_t bytes = 0;
};
/// The finished recording `file`: in the folder while it has not been archived, else in the
/// archive. An Error with field object_store::kNotFound when it is in neither (deleted).
Result<StoredRecording> find_recording(const RecordingConfig& config, const std::string& file);

}  // namespace hanzo::fusion::service
