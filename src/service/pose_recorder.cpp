#include "pose_recorder.hpp"

#include <algorithm>

#include "hanzo/fusion/core/logging.hpp"

namespace hanzo::fusion::service::detail {

PoseRecorder::PoseRecorder(Storage& storage, std::chrono::milliseconds interval, std::size_t max_pending,
                           MetricsRegistry& metrics)
    : storage_(storage),
      interval_(interval),
      max_pending_(max_pending),
      pending_gauge_(metrics.gauge("hanzo_fusion_storage_pending_poses", "Poses waiting to be committed to storage")),
      dropped_counter_(metrics.counter("hanzo_fusion_storage_dropped_poses_total",
                                       "Poses dropped because the storage queue was full")),
      error_counter_(metrics.counter("hanzo_fusion_storage_errors_total", "Failed storage commits (retried)")),
      committed_counter_(metrics.counter("hanzo_fusion_storage_committed_poses_total", "Poses committed to storage")),
      commit_seconds_(metrics.histogram("hanzo_fusion_storage_commit_seconds", "Duration of one storage commit",
                                        latency_buckets_seconds())),
      writer_([this] { run(); }) {}

PoseRecorder::~PoseRecorder() {
  {
    std::lock_guard lock(mutex_);
    stopping_ = true;
  }
  wake_writer_.notify_all();
  writer_.join();
}

void PoseRecorder::enqueue(const std::string& session_id, const msgs::PoseEstimate& pose) {
  std::lock_guard lock(mutex_);
  if (queue_.size() >= max_pending_) {
    dropped_counter_.increment();
    return;
  }
  queue_.push_back({session_id, pose});
  ++enqueued_sequence_;
  pending_gauge_.set(static_cast<double>(queue_.size()));
}

Status PoseRecorder::flush() {
  std::unique_lock lock(mutex_);
  const uint64_t target = enqueued_sequence_;
  last_error_.reset();
  flush_requested_ = true;
  wake_writer_.notify_all();
  committed_.wait(lock, [&] { return committed_sequence_ >= target || last_error_.has_value() || stopping_; });
  if (committed_sequence_ >= target) return ok_status();
  if (last_error_) return *last_error_;
  return Error("storage writer stopped before the poses were committed");
}

StorageProgress PoseRecorder::progress(const std::string& session_id) const {
  std::lock_guard lock(mutex_);
  const auto found = progress_.find(session_id);
  return found == progress_.end() ? StorageProgress{} : found->second;
}

void PoseRecorder::restore(const std::string& session_id, StorageProgress progress) {
  std::lock_guard lock(mutex_);
  progress_[session_id] = progress;
}

void PoseRecorder::run() {
  std::vector<StoredPose> batch;
  std::unique_lock lock(mutex_);
  while (true) {
    wake_writer_.wait_for(lock, interval_, [&] { return stopping_ || flush_requested_; });
    if (queue_.empty()) {
      flush_requested_ = false;
      committed_.notify_all();
      if (stopping_) break;
      continue;
    }
    batch.clear();
    batch.swap(queue_);
    const uint64_t batch_end = enqueued_sequence_;
    lock.unlock();
    const auto started = std::chrono::steady_clock::now();
    const Status status = storage_.append_poses(batch);
    commit_seconds_.observe(std::chrono::duration<double>(std::chrono::steady_clock::now() - started).count());
    lock.lock();
    if (status) {
      committed_sequence_ = batch_end;
      committed_counter_.increment(static_cast<double>(batch.size()));
      for (const StoredPose& pose : batch) {
        StorageProgress& progress = progress_[pose.session_id];
        ++progress.stored;
        if (!progress.stored_through || pose.estimate.timestamp > *progress.stored_through) {
          progress.stored_through = pose.estimate.timestamp;
        }
      }
    } else {
      error_counter_.increment();
      last_error_ = status.error();
      logger()->error("storage: {} ({} poses kept for the next attempt)", status.error().message, batch.size());
      if (stopping_) {
        dropped_counter_.increment(static_cast<double>(batch.size()));
        committed_.notify_all();
        break;
      }
      // Retried first with the next batch; the queue may now exceed max_pending_ by one batch.
      queue_.insert(queue_.begin(), std::make_move_iterator(batch.begin()), std::make_move_iterator(batch.end()));
      flush_requested_ = false;
    }
    pending_gauge_.set(static_cast<double>(queue_.size()));
    committed_.notify_all();
  }
}

}  // namespace hanzo::fusion::service::detail
