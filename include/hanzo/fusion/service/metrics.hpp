#pragma once
// Metrics in the Prometheus text exposition format (version 0.0.4), served at /v1/metrics.
//
//   MetricsRegistry registry;
//   Counter& received = registry.counter("hanzo_fusion_messages_received_total", "Messages pushed",
//                                        {{"session", id}, {"sensor", "imu"}});
//   received.increment();                       // lock-free; keep the reference
//   registry.render();                          // "# HELP ...\n# TYPE ... counter\n..."
//
// A series is identified by its name and label set; asking again returns the same object, whose
// address stays valid until remove_series() drops it (e.g. the series of a deleted session).
// Names must match [a-zA-Z_:][a-zA-Z0-9_:]*; label values are escaped as the format requires.
// Thread-safe.

#include <atomic>
#include <cstdint>
#include <functional>
#include <map>
#include <memory>
#include <mutex>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

namespace hanzo::fusion::service {

using MetricLabels = std::vector<std::pair<std::string, std::string>>;

class Counter {
 public:
  void increment(double amount = 1.0) { value_.fetch_add(amount, std::memory_order_relaxed); }
  /// Mirrors a monotonic total counted elsewhere (a session's own counters), set by a collector.
  void set_total(double total) { value_.store(total, std::memory_order_relaxed); }
  double value() const { return value_.load(std::memory_order_relaxed); }

 private:
  std::atomic<double> value_{0.0};
};

class Gauge {
 public:
  void set(double value) { value_.store(value, std::memory_order_relaxed); }
  void add(double amount) { value_.fetch_add(amount, std::memory_order_relaxed); }
  double value() const { return value_.load(std::memory_order_relaxed); }

 private:
  std::atomic<double> value_{0.0};
};

/// Cumulative buckets with upper bounds `bounds` (ascending; +Inf is implicit).
class Histogram {
 public:
  explicit Histogram(std::vector<double> bounds);
  void observe(double value);
  const std::vector<double>& bounds() const { return bounds_; }
  /// Observations <= bounds()[i] (cumulative), then the total count.
  std::vector<uint64_t> cumulative_counts() const;
  double sum() const { return sum_.load(std::memory_order_relaxed); }
  uint64_t count() const { return count_.load(std::memory_order_relaxed); }

 private:
  std::vector<double> bounds_;
  std::unique_ptr<std::atomic<uint64_t>[]> bucket_counts_;  // per bucket, not cumulative
  std::atomic<double> sum_{0.0};
  std::atomic<uint64_t> count_{0};
};

/// Latency buckets in seconds, 5 us to 10 s.
std::vector<double> latency_buckets_seconds();

class MetricsRegistry {
 public:
  Counter& counter(std::string_view name, std::string_view help, const MetricLabels& labels = {});
  Gauge& gauge(std::string_view name, std::string_view help, const MetricLabels& labels = {});
  /// The bounds of a family are fixed by its first series.
  Histogram& histogram(std::string_view name, std::string_view help, const std::vector<double>& bounds,
                       const MetricLabels& labels = {});

  /// `collect` runs at the start of every render() (outside the registry's lock) to bring
  /// mirrored series up to date.
  void add_collector(std::function<void()> collect);

  /// Drops every series that carries label `label_name` with value `label_value`.
  void remove_series(std::string_view label_name, std::string_view label_value);
  /// The exposition text of every family, sorted by name.
  std::string render() const;

 private:
  enum class Type { kCounter, kGauge, kHistogram };
  struct Series {
    MetricLabels labels;
    std::unique_ptr<Counter> counter;
    std::unique_ptr<Gauge> gauge;
    std::unique_ptr<Histogram> histogram;
  };
  struct Family {
    Type type = Type::kCounter;
    std::string help;
    std::map<std::string, Series> series;  // by rendered label set
  };
  Series& series(std::string_view name, std::string_view help, Type type, const MetricLabels& labels);

  mutable std::mutex mutex_;
  std::map<std::string, Family, std::less<>> families_;
  std::vector<std::function<void()>> collectors_;  // guarded by mutex_, called without it
};

}  // namespace hanzo::fusion::service
