#pragma once
// A subscriber's queue: the session pushes, the subscriber (a gRPC stream, a web client) pops.
// Bounded: when the subscriber is slower than the session, the oldest entry is dropped and
// counted, so a slow subscriber never blocks fusion and never grows memory without bound.
// Thread-safe.

#include <chrono>
#include <condition_variable>
#include <cstddef>
#include <cstdint>
#include <deque>
#include <mutex>
#include <optional>

namespace hanzo::fusion::service {

template <typename T>
class Subscription {
 public:
  explicit Subscription(std::size_t capacity) : capacity_(capacity == 0 ? 1 : capacity) {}

  /// Adds `value`, dropping the oldest entry when full. Ignored once closed.
  void publish(const T& value) {
    {
      std::lock_guard lock(mutex_);
      if (closed_) return;
      if (queue_.size() >= capacity_) {
        queue_.pop_front();
        ++dropped_;
      }
      queue_.push_back(value);
    }
    ready_.notify_one();
  }

  /// The oldest entry; waits up to `timeout` (a zero timeout never waits, nor makes a system
  /// call: a stream polls its queue after every message). nullopt on timeout or when closed
  /// and drained.
  std::optional<T> pop(std::chrono::milliseconds timeout) {
    std::unique_lock lock(mutex_);
    if (timeout.count() > 0) ready_.wait_for(lock, timeout, [&] { return !queue_.empty() || closed_; });
    if (queue_.empty()) return std::nullopt;
    T value = std::move(queue_.front());
    queue_.pop_front();
    return value;
  }

  /// No more entries will come (session ended, server stopping); wakes a waiting pop().
  void close() {
    {
      std::lock_guard lock(mutex_);
      closed_ = true;
    }
    ready_.notify_all();
  }

  bool closed() const {
    std::lock_guard lock(mutex_);
    return closed_;
  }
  std::size_t depth() const {
    std::lock_guard lock(mutex_);
    return queue_.size();
  }
  uint64_t dropped() const {
    std::lock_guard lock(mutex_);
    return dropped_;
  }
  std::size_t capacity() const { return capacity_; }

 private:
  const std::size_t capacity_;
  mutable std::mutex mutex_;
  std::condition_variable ready_;
  std::deque<T> queue_;
  uint64_t dropped_ = 0;
  bool closed_ = false;
};

}  // namespace hanzo::fusion::service
