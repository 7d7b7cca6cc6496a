#include "hanzo/fusion/drivers/byte_source.hpp"

#include <arpa/inet.h>
#include <fcntl.h>
#include <netdb.h>
#include <netinet/in.h>
#include <poll.h>
#include <sys/socket.h>
#include <termios.h>
#include <unistd.h>

#include <cerrno>
#include <charconv>
#include <cstring>
#include <utility>

#include <fmt/format.h>

namespace hanzo::fusion::drivers {

namespace {

constexpr std::size_t kMaxDatagram = 65536;

std::string system_error() { return std::strerror(errno); }

Result<uint16_t> parse_port(std::string_view text, std::string_view url) {
  int port = 0;
  const auto [end, error] = std::from_chars(text.data(), text.data() + text.size(), port);
  if (text.empty() || error != std::errc() || end != text.data() + text.size() || port < 1 || port > 65535) {
    return Error(fmt::format("{}: expected a port 1-65535, got '{}'", url, text));
  }
  return static_cast<uint16_t>(port);
}

std::optional<speed_t> speed_of(int baud) {
  switch (baud) {
    case 4800: return B4800;
    case 9600: return B9600;
    case 19200: return B19200;
    case 38400: return B38400;
    case 57600: return B57600;
    case 115200: return B115200;
    case 230400: return B230400;
    case 460800: return B460800;
    case 921600: return B921600;
    default: return std::nullopt;
  }
}

/// A file descriptor read with poll(); closed on destruction.
class DescriptorSource : public ByteSource {
 public:
  DescriptorSource(int descriptor, SourceAddress address, bool datagrams)
      : descriptor_(descriptor), address_(std::move(address)), datagrams_(datagrams) {}
  ~DescriptorSource() override { ::close(descriptor_); }
  DescriptorSource(const DescriptorSource&) = delete;
  DescriptorSource& operator=(const DescriptorSource&) = delete;

  Result<std::optional<ReceivedBytes>> read(std::chrono::milliseconds timeout) override {
    pollfd request{descriptor_, POLLIN, 0};
    const int ready = ::poll(&request, 1, static_cast<int>(timeout.count()));
    if (ready < 0 && errno != EINTR) return Error(fmt::format("{}: {}", address_.url, system_error()));
    if (ready <= 0) return std::optional<ReceivedBytes>();
    ReceivedBytes received;
    received.bytes.resize(kMaxDatagram);
    const ssize_t got = ::read(descriptor_, received.bytes.data(), received.bytes.size());
    received.time = Timestamp::wall_clock_now();
    if (got < 0) {
      if (errno == EAGAIN || errno == EINTR) return std::optional<ReceivedBytes>();
      return Error(fmt::format("{}: {}", address_.url, system_error()));
    }
    if (got == 0 && !datagrams_) return Error(fmt::format("{}: the stream ended", address_.url));
    received.bytes.resize(static_cast<std::size_t>(got));
    received.destination_port = address_.port;
    return std::optional<ReceivedBytes>(std::move(received));
  }
  const SourceAddress& address() const override { return address_; }

 private:
  int descriptor_;
  SourceAddress address_;
  bool datagrams_;
};

Result<std::unique_ptr<ByteSource>> open_udp(const SourceAddress& address) {
  const int descriptor = ::socket(AF_INET, SOCK_DGRAM | SOCK_CLOEXEC, 0);
  if (descriptor < 0) return Error(fmt::format("{}: socket: {}", address.url, system_error()));
  const int yes = 1;
  ::setsockopt(descriptor, SOL_SOCKET, SO_REUSEADDR, &yes, sizeof(yes));
  const int buffer = 8 << 20;  // a LiDAR's burst while the reader is busy
  ::setsockopt(descriptor, SOL_SOCKET, SO_RCVBUF, &buffer, sizeof(buffer));
  sockaddr_in local{};
  local.sin_family = AF_INET;
  local.sin_port = htons(address.port);
  local.sin_addr.s_addr = htonl(INADDR_ANY);
  if (!address.host.empty() && ::inet_pton(AF_INET, address.host.c_str(), &local.sin_addr) != 1) {
    ::close(descriptor);
    return Error(fmt::format("{}: '{}' is not an IPv4 address of this machine", address.url, address.host));
  }
  if (::bind(descriptor, reinterpret_cast<const sockaddr*>(&local), sizeof(local)) != 0) {
    const std::string why = system_error();
    ::close(descriptor);
    return Error(fmt::format("{}: cannot listen on port {}: {}", address.url, address.port, why));
  }
  return std::unique_ptr<ByteSource>(std::make_unique<DescriptorSource>(descriptor, address, true));
}

Result<std::unique_ptr<ByteSource>> open_tcp(const SourceAddress& address) {
  addrinfo hints{};
  hints.ai_family = AF_UNSPEC;
  hints.ai_socktype = SOCK_STREAM;
  addrinfo* found = nullptr;
  if (const int error = ::getaddrinfo(address.host.c_str(), std::to_string(address.port).c_str(), &hints, &found); error != 0) {
    return Error(fmt::format("{}: {}", address.url, ::gai_strerror(error)));
  }
  std::string why = "no address";
  for (addrinfo* candidate = found; candidate != nullptr; candidate = candidate->ai_next) {
    const int descriptor = ::socket(candidate->ai_family, candidate->ai_socktype | SOCK_CLOEXEC, candidate->ai_protocol);
    if (descriptor < 0) continue;
    if (::connect(descriptor, candidate->ai_addr, candidate->ai_addrlen) == 0) {
      ::freeaddrinfo(found);
      return std::unique_ptr<ByteSource>(std::make_unique<DescriptorSource>(descriptor, address, false));
    }
    why = system_error();
    ::close(descriptor);
  }
  ::freeaddrinfo(found);
  return Error(fmt::format("{}: cannot connect: {}", address.url, why));
}

Result<std::unique_ptr<ByteSource>> open_serial(const SourceAddress& address) {
  const std::optional<speed_t> speed = speed_of(address.baud);
  if (!speed) return Error(fmt::format("{}: baud {} is not one of 4800 .. 921600", address.url, address.baud));
  const int descriptor = ::open(address.device.c_str(), O_RDWR | O_NOCTTY | O_NONBLOCK | O_CLOEXEC);
  if (descriptor < 0) return Error(fmt::format("{}: cannot open {}: {}", address.url, address.device, system_error()));
  termios settings{};
  if (::tcgetattr(descriptor, &settings) != 0) {
    const std::string why = system_error();
    ::close(descriptor);
    return Error(fmt::format("{}: {} is not a serial port: {}", address.url, address.device, why));
  }
  ::cfmakeraw(&settings);
  settings.c_cflag |= CLOCAL | CREAD;
  ::cfsetispeed(&settings, *speed);
  ::cfsetospeed(&settings, *speed);
  if (::tcsetattr(descriptor, TCSANOW, &settings) != 0) {
    const std::string why = system_error();
    ::close(descriptor);
    return Error(fmt::format("{}: cannot set {} baud 8N1 raw: {}", address.url, address.baud, why));
  }
  return std::unique_ptr<ByteSource>(std::make_unique<DescriptorSource>(descriptor, address, false));
}

}  // namespace

Result<SourceAddress> parse_source_url(std::string_view url) {
  SourceAddress address;
  address.url = std::string(url);
  const std::size_t scheme_end = url.find("://");
  if (scheme_end == std::string_view::npos) return Error(fmt::format("{}: expected udp://, tcp:// or serial://", url));
  const std::string_view scheme = url.substr(0, scheme_end), rest = url.substr(scheme_end + 3);
  if (scheme == "udp" || scheme == "tcp") {
    address.kind = scheme == "udp" ? SourceAddress::Kind::kUdp : SourceAddress::Kind::kTcp;
    const std::size_t colon = rest.rfind(':');
    if (colon == std::string_view::npos) return Error(fmt::format("{}: expected HOST:PORT or :PORT", url));
    address.host = std::string(rest.substr(0, colon));
    HANZO_ASSIGN_OR_RETURN(address.port, parse_port(rest.substr(colon + 1), url));
    if (address.kind == SourceAddress::Kind::kTcp && address.host.empty()) return Error(fmt::format("{}: a TCP source needs the server's host", url));
    return address;
  }
  if (scheme == "serial") {
    address.kind = SourceAddress::Kind::kSerial;
    const std::size_t query = rest.find('?');
    address.device = std::string(rest.substr(0, query));
    if (address.device.empty() || address.device.front() != '/') return Error(fmt::format("{}: expected serial:///dev/NAME", url));
    if (query != std::string_view::npos) {
      const std::string_view option = rest.substr(query + 1);
      if (option.rfind("baud=", 0) != 0) return Error(fmt::format("{}: the only option is baud=N", url));
      const std::string_view value = option.substr(5);
      const auto [end, error] = std::from_chars(value.data(), value.data() + value.size(), address.baud);
      if (value.empty() || error != std::errc() || end != value.data() + value.size()) return Error(fmt::format("{}: baud '{}' is not a number", url, value));
    }
    if (!speed_of(address.baud)) return Error(fmt::format("{}: baud {} is not one of 4800 .. 921600", url, address.baud));
    return address;
  }
  return Error(fmt::format("{}: unknown scheme '{}' (expected udp, tcp or serial)", url, scheme));
}

Result<std::unique_ptr<ByteSource>> open_source(const SourceAddress& address) {
  switch (address.kind) {
    case SourceAddress::Kind::kUdp: return open_udp(address);
    case SourceAddress::Kind::kTcp: return open_tcp(address);
    case SourceAddress::Kind::kSerial: return open_serial(address);
  }
  return Error(fmt::format("{}: unknown source", address.url));
}

}  // namespace hanzo::fusion::drivers
