#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "hanzo/fusion/service/metrics.hpp"

namespace hanzo::fusion::service {
namespace {

using ::testing::HasSubstr;
using ::testing::Not;

TEST(Metrics, RendersThePrometheusTextFormat) {
  MetricsRegistry registry;
  registry.counter("requests_total", "Requests", {{"route", "/v1/health"}}).increment(3);
  registry.gauge("queue_depth", "Depth").set(7.5);
  Histogram& latency = registry.histogram("latency_seconds", "Latency", {0.1, 1.0});
  latency.observe(0.05);
  latency.observe(0.1);  // le is inclusive
  latency.observe(3.0);
  EXPECT_EQ(registry.render(),
            "# HELP latency_seconds Latency\n"
            "# TYPE latency_seconds histogram\n"
            "latency_seconds_bucket{le=\"0.1\"} 2\n"
            "latency_seconds_bucket{le=\"1.0\"} 2\n"
            "latency_seconds_bucket{le=\"+Inf\"} 3\n"
            "latency_seconds_sum 3.15\n"
            "latency_seconds_count 3\n"
            "# HELP queue_depth Depth\n"
            "# TYPE queue_depth gauge\n"
            "queue_depth 7.5\n"
            "# HELP requests_total Requests\n"
            "# TYPE requests_total counter\n"
            "requests_total{route=\"/v1/health\"} 3.0\n");
}

TEST(Metrics, SameSeriesIsSharedAndLabelValuesAreEscaped) {
  MetricsRegistry registry;
  Counter& first = registry.counter("c_total", "C", {{"sensor", "a\"b\\c\nd"}});
  Counter& second = registry.counter("c_total", "C", {{"sensor", "a\"b\\c\nd"}});
  EXPECT_EQ(&first, &second);
  first.increment();
  second.increment();
  EXPECT_THAT(registry.render(), HasSubstr("c_total{sensor=\"a\\\"b\\\\c\\nd\"} 2.0\n"));
}

TEST(Metrics, RemovingASessionDropsItsSeriesOnly) {
  MetricsRegistry registry;
  registry.counter("poses_total", "Poses", {{"session", "s1"}}).increment();
  registry.counter("poses_total", "Poses", {{"session", "s2"}}).increment();
  registry.remove_series("session", "s1");
  const std::string text = registry.render();
  EXPECT_THAT(text, Not(HasSubstr("s1")));
  EXPECT_THAT(text, HasSubstr("poses_total{session=\"s2\"} 1.0"));
}

TEST(Metrics, CollectorsRunAtEveryRender) {
  MetricsRegistry registry;
  int scrapes = 0;
  registry.add_collector([&] { registry.counter("mirrored_total", "Mirrored").set_total(++scrapes * 10.0); });
  EXPECT_THAT(registry.render(), HasSubstr("mirrored_total 10.0"));
  EXPECT_THAT(registry.render(), HasSubstr("mirrored_total 20.0"));
}

}  // namespace
}  // namespace hanzo::fusion::service
