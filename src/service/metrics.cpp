#include "hanzo/fusion/service/metrics.hpp"

#include <algorithm>
#include <cassert>
#include <cmath>

#include <fmt/format.h>

#include "hanzo/fusion/core/yaml_value.hpp"

namespace hanzo::fusion::service {
namespace {

std::string escape_label_value(std::string_view value) {
  std::string escaped;
  escaped.reserve(value.size());
  for (char c : value) {
    if (c == '\\') escaped += "\\\\";
    else if (c == '"') escaped += "\\\"";
    else if (c == '\n') escaped += "\\n";
    else escaped += c;
  }
  return escaped;
}

std::string render_labels(const MetricLabels& labels, std::string_view extra_name = {}, std::string_view extra_value = {}) {
  if (labels.empty() && extra_name.empty()) return {};
  std::string text = "{";
  bool first = true;
  for (const auto& [name, value] : labels) {
    if (!first) text += ',';
    first = false;
    text += fmt::format("{}=\"{}\"", name, escape_label_value(value));
  }
  if (!extra_name.empty()) text += fmt::format("{}{}=\"{}\"", first ? "" : ",", extra_name, extra_value);
  return text + "}";
}

std::string format_value(double value) {
  if (std::isnan(value)) return "NaN";
  if (std::isinf(value)) return value > 0 ? "+Inf" : "-Inf";
  return format_double(value);
}

[[maybe_unused]] bool valid_metric_name(std::string_view name) {
  if (name.empty()) return false;
  for (std::size_t i = 0; i < name.size(); ++i) {
    const char c = name[i];
    const bool letter = (c >= 'a' && c <= 'z') || (c >= 'A' && c <= 'Z') || c == '_' || c == ':';
    if (!letter && !(i > 0 && c >= '0' && c <= '9')) return false;
  }
  return true;
}

std::string_view type_name(int type) {
  static constexpr std::string_view kNames[] = {"counter", "gauge", "histogram"};
  return kNames[type];
}

}  // namespace

Histogram::Histogram(std::vector<double> bounds)
    : bounds_(std::move(bounds)), bucket_counts_(std::make_unique<std::atomic<uint64_t>[]>(bounds_.size() + 1)) {
  assert(std::is_sorted(bounds_.begin(), bounds_.end()));
  for (std::size_t i = 0; i <= bounds_.size(); ++i) bucket_counts_[i].store(0);
}

void Histogram::observe(double value) {
  const auto bucket = static_cast<std::size_t>(std::lower_bound(bounds_.begin(), bounds_.end(), value) - bounds_.begin());
  bucket_counts_[bucket].fetch_add(1, std::memory_order_relaxed);
  sum_.fetch_add(value, std::memory_order_relaxed);
  count_.fetch_add(1, std::memory_order_relaxed);
}

std::vector<uint64_t> Histogram::cumulative_counts() const {
  std::vector<uint64_t> counts(bounds_.size() + 1);
  uint64_t total = 0;
  for (std::size_t i = 0; i <= bounds_.size(); ++i) {
    total += bucket_counts_[i].load(std::memory_order_relaxed);
    counts[i] = total;
  }
  return counts;
}

std::vector<double> latency_buckets_seconds() {
  return {5e-6, 1e-5, 2.5e-5, 5e-5, 1e-4, 2.5e-4, 5e-4, 1e-3, 2.5e-3, 5e-3, 1e-2, 2.5e-2, 5e-2, 0.1, 0.25, 0.5, 1.0, 2.5, 10.0};
}

MetricsRegistry::Series& MetricsRegistry::series(std::string_view name, std::string_view help, Type type,
                                                 const MetricLabels& labels) {
  assert(valid_metric_name(name));
  auto found = families_.find(name);
  if (found == families_.end()) {
    found = families_.emplace(std::string(name), Family{type, std::string(help), {}}).first;
  }
  assert(found->second.type == type && "a metric name is used with two types");
  Series& entry = found->second.series[render_labels(labels)];
  entry.labels = labels;
  return entry;
}

Counter& MetricsRegistry::counter(std::string_view name, std::string_view help, const MetricLabels& labels) {
  std::lock_guard lock(mutex_);
  Series& entry = series(name, help, Type::kCounter, labels);
  if (!entry.counter) entry.counter = std::make_unique<Counter>();
  return *entry.counter;
}

Gauge& MetricsRegistry::gauge(std::string_view name, std::string_view help, const MetricLabels& labels) {
  std::lock_guard lock(mutex_);
  Series& entry = series(name, help, Type::kGauge, labels);
  if (!entry.gauge) entry.gauge = std::make_unique<Gauge>();
  return *entry.gauge;
}

Histogram& MetricsRegistry::histogram(std::string_view name, std::string_view help, const std::vector<double>& bounds,
                                      const MetricLabels& labels) {
  std::lock_guard lock(mutex_);
  Family* family = nullptr;
  if (auto found = families_.find(name); found != families_.end()) family = &found->second;
  Series& entry = series(name, help, Type::kHistogram, labels);
  if (!entry.histogram) {
    // Every series of a family shares the first series' bounds.
    std::vector<double> family_bounds = bounds;
    if (family != nullptr) {
      for (const auto& [key, other] : family->series) {
        if (other.histogram) {
          family_bounds = other.histogram->bounds();
          break;
        }
      }
    }
    entry.histogram = std::make_unique<Histogram>(std::move(family_bounds));
  }
  return *entry.histogram;
}

void MetricsRegistry::remove_series(std::string_view label_name, std::string_view label_value) {
  std::lock_guard lock(mutex_);
  for (auto& [name, family] : families_) {
    std::erase_if(family.series, [&](const auto& item) {
      return std::any_of(item.second.labels.begin(), item.second.labels.end(),
                         [&](const auto& label) { return label.first == label_name && label.second == label_value; });
    });
  }
}

void MetricsRegistry::add_collector(std::function<void()> collect) {
  std::lock_guard lock(mutex_);
  collectors_.push_back(std::move(collect));
}

std::string MetricsRegistry::render() const {
  std::vector<std::function<void()>> collectors;
  {
    std::lock_guard lock(mutex_);
    collectors = collectors_;
  }
  for (const auto& collect : collectors) collect();
  std::lock_guard lock(mutex_);
  std::string text;
  for (const auto& [name, family] : families_) {
    if (family.series.empty()) continue;
    text += fmt::format("# HELP {} {}\n# TYPE {} {}\n", name, family.help, name, type_name(static_cast<int>(family.type)));
    for (const auto& [label_text, entry] : family.series) {
      if (entry.counter) text += fmt::format("{}{} {}\n", name, label_text, format_value(entry.counter->value()));
      if (entry.gauge) text += fmt::format("{}{} {}\n", name, label_text, format_value(entry.gauge->value()));
      if (entry.histogram) {
        const std::vector<uint64_t> counts = entry.histogram->cumulative_counts();
        const std::vector<double>& bounds = entry.histogram->bounds();
        for (std::size_t i = 0; i < counts.size(); ++i) {
          const std::string bound = i < bounds.size() ? format_value(bounds[i]) : "+Inf";
          text += fmt::format("{}_bucket{} {}\n", name, render_labels(entry.labels, "le", bound), counts[i]);
        }
        text += fmt::format("{}_sum{} {}\n", name, label_text, format_value(entry.histogram->sum()));
        text += fmt::format("{}_count{} {}\n", name, label_text, entry.histogram->count());
      }
    }
  }
  return text;
}

}  // namespace hanzo::fusion::service
