// Fuzz target: sensor log files (MCAP with hanzo.fusion.v1 messages, io/sensor_log.hpp) and
// ROS 1 bags (io/ros1_bag.hpp), read from a file as the commands read them. The first byte picks
// the reader; the rest is the file (held in an anonymous memory file). Any input must be read or
// refused with an error, never crash; reading stops at the first error.

#include <sys/mman.h>
#include <unistd.h>

#include <cstddef>
#include <cstdint>
#include <string>

#include "hanzo/fusion/io/ros1_bag.hpp"
#include "hanzo/fusion/io/sensor_log.hpp"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using namespace hanzo::fusion;
  if (size == 0) return 0;
  const int fd = ::memfd_create("fuzz_log", 0);
  if (fd < 0) return 0;
  if (::write(fd, data + 1, size - 1) != static_cast<ssize_t>(size - 1)) {
    ::close(fd);
    return 0;
  }
  const std::string path = "/proc/self/fd/" + std::to_string(fd);
  if (data[0] % 2 == 0) {
    auto reader = io::SensorLogReader::open(path);
    if (reader) {
      io::LogEntry entry;
      for (int i = 0; i < 100000; ++i) {
        auto more = (*reader)->next(entry);
        if (!more || !*more) break;
      }
    }
  } else {
    (void)io::ros1::read_bag(path, [](const io::ros1::BagMessage&) { return ok_status(); });
  }
  ::close(fd);
  return 0;
}
