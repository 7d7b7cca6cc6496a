#pragma once
// PoseRecorder: the storage writer of the SessionManager. Sessions enqueue PoseEstimates from
// their pose callbacks (never blocking on the database); a writer thread commits what is queued
// every `interval` in one transaction. A failed commit is retried with the next batch (nothing
// is dropped while the queue is below max_pending); beyond max_pending new poses are dropped
// and counted (hanzo_fusion_storage_dropped_poses_total).

#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <map>
#include <mutex>
#include <optional>
#include <string>
#include <thread>
#include <vector>

#include "hanzo/fusion/service/metrics.hpp"
#include "hanzo/fusion/service/storage.hpp"

namespace hanzo::fusion::service::detail {

struct StorageProgress {
  uint64_t stored = 0;                     // poses committed
  std::optional<Timestamp> stored_through;  // newest committed timestamp
};

class PoseRecorder {
 public:
  PoseRecorder(Storage& storage, std::chrono::milliseconds interval, std::size_t max_pending, MetricsRegistry& metrics);
  ~PoseRecorder();  // commits what is queued, then stops the writer
  PoseRecorder(const PoseRecorder&) = delete;
  PoseRecorder& operator=(const PoseRecorder&) = delete;

  void enqueue(const std::string& session_id, const msgs::PoseEstimate& pose);
  /// Waits until everything enqueued before the call is committed; the last commit error otherwise.
  Status flush();
  /// What is durable of a session (seeded by `restore` for sessions found in storage).
  StorageProgress progress(const std::string& session_id) const;
  void restore(const std::string& session_id, StorageProgress progress);

 private:
  void run();

  Storage& storage_;
  const std::chrono::milliseconds interval_;
  const std::size_t max_pending_;
  Gauge& pending_gauge_;
  Counter& dropped_counter_;
  Counter& error_counter_;
  Counter& committed_counter_;
  Histogram& commit_seconds_;

  mutable std::mutex mutex_;
  std::condition_variable wake_writer_;
  std::condition_variable committed_;
  std::vector<StoredPose> queue_;
  uint64_t enqueued_sequence_ = 0;   // poses ever enqueued
  uint64_t committed_sequence_ = 0;  // of those, committed (or dropped)
  std::optional<Error> last_error_;
  bool flush_requested_ = false;
  bool stopping_ = false;
  std::map<std::string, StorageProgress> progress_;
  std::thread writer_;
};

}  // namespace hanzo::fusion::service::detail
