#include "hanzo/fusion/core/logging.hpp"

#include <atomic>

#include <spdlog/sinks/null_sink.h>

namespace hanzo::fusion {
namespace {

std::shared_ptr<spdlog::logger> silent_logger() {
  static const auto logger = std::make_shared<spdlog::logger>("hanzo_fusion", std::make_shared<spdlog::sinks::null_sink_mt>());
  return logger;
}

std::atomic<std::shared_ptr<spdlog::logger>>& current() {
  static std::atomic<std::shared_ptr<spdlog::logger>> logger{silent_logger()};
  return logger;
}

}  // namespace

std::shared_ptr<spdlog::logger> logger() { return current().load(); }

void set_logger(std::shared_ptr<spdlog::logger> new_logger) {
  current().store(new_logger ? std::move(new_logger) : silent_logger());
}

}  // namespace hanzo::fusion
