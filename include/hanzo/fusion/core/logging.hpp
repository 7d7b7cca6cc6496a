#pragma once
// The library's logger. hanzo-fusion never prints to stdout/stderr by itself: every module
// logs through logger(), which discards everything until the application installs a logger
// with set_logger() (the hanzo-fusion program logs to stderr).

#include <memory>

#include <spdlog/logger.h>

namespace hanzo::fusion {

/// The current library logger (never null). Thread-safe.
std::shared_ptr<spdlog::logger> logger();
/// Replaces the library logger; nullptr restores the silent default. Thread-safe.
void set_logger(std::shared_ptr<spdlog::logger> new_logger);

}  // namespace hanzo::fusion
