// Live byte sources: URLs parsed or refused by name; a UDP datagram, a TCP stream and a
// pseudo-terminal (as a serial port) each deliver what was sent, and an NMEA receiver's bytes
// through the pseudo-terminal decode into its fix.
#include <arpa/inet.h>
#include <fcntl.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <unistd.h>

#include <chrono>
#include <cstdlib>
#include <string>
#include <thread>

#include <fmt/format.h>
#include <gtest/gtest.h>

#include "hanzo/fusion/drivers/byte_source.hpp"
#include "hanzo/fusion/drivers/nmea.hpp"

namespace hanzo::fusion::drivers {
namespace {

using std::chrono::milliseconds;

TEST(ByteSource, UrlsAreParsedAndBadOnesRefusedByName) {
  const SourceAddress udp = parse_source_url("udp://:2368").value();
  EXPECT_EQ(udp.kind, SourceAddress::Kind::kUdp);
  EXPECT_EQ(udp.port, 2368);
  EXPECT_TRUE(udp.host.empty());
  const SourceAddress tcp = parse_source_url("tcp://10.0.0.5:2947").value();
  EXPECT_EQ(tcp.kind, SourceAddress::Kind::kTcp);
  EXPECT_EQ(tcp.host, "10.0.0.5");
  const SourceAddress serial = parse_source_url("serial:///dev/ttyUSB0?baud=9600").value();
  EXPECT_EQ(serial.device, "/dev/ttyUSB0");
  EXPECT_EQ(serial.baud, 9600);
  EXPECT_EQ(parse_source_url("serial:///dev/ttyACM0").value().baud, 115200);
  for (const char* bad : {"2368", "udp://:99999", "udp://host", "tcp://:2947", "serial://ttyUSB0", "serial:///dev/ttyUSB0?baud=12345",
                          "serial:///dev/ttyUSB0?parity=even", "http://x:80"}) {
    const auto refused = parse_source_url(bad);
    ASSERT_FALSE(refused.ok()) << bad;
    EXPECT_NE(refused.error().message.find(bad), std::string::npos) << refused.error().message;
  }
  EXPECT_FALSE(open_source(parse_source_url("serial:///dev/no_such_tty").value()).ok());
}

TEST(ByteSource, UdpAndTcpDeliverWhatWasSent) {
  const uint16_t port = static_cast<uint16_t>(30000 + ::getpid() % 20000);
  auto udp = open_source(parse_source_url(fmt::format("udp://127.0.0.1:{}", port)).value()).value();
  EXPECT_FALSE(udp->read(milliseconds(20)).value().has_value()) << "nothing sent yet";
  const int sender = ::socket(AF_INET, SOCK_DGRAM, 0);
  sockaddr_in to{};
  to.sin_family = AF_INET;
  to.sin_port = htons(port);
  ::inet_pton(AF_INET, "127.0.0.1", &to.sin_addr);
  ASSERT_EQ(::sendto(sender, "packet", 6, 0, reinterpret_cast<const sockaddr*>(&to), sizeof(to)), 6);
  ::close(sender);
  const auto datagram = udp->read(milliseconds(1000)).value();
  ASSERT_TRUE(datagram.has_value());
  EXPECT_EQ(datagram->bytes, "packet");
  EXPECT_EQ(datagram->destination_port, port);

  // A TCP server on the next port: the source connects and reads its bytes, then the end.
  const int listener = ::socket(AF_INET, SOCK_STREAM, 0);
  const int yes = 1;
  ::setsockopt(listener, SOL_SOCKET, SO_REUSEADDR, &yes, sizeof(yes));
  sockaddr_in local = to;
  local.sin_port = htons(static_cast<uint16_t>(port + 1));
  ASSERT_EQ(::bind(listener, reinterpret_cast<const sockaddr*>(&local), sizeof(local)), 0);
  ASSERT_EQ(::listen(listener, 1), 0);
  std::thread server([listener] {
    const int client = ::accept(listener, nullptr, nullptr);
    (void)!::write(client, "$GPGGA,", 7);
    ::close(client);
  });
  auto tcp = open_source(parse_source_url(fmt::format("tcp://127.0.0.1:{}", port + 1)).value()).value();
  std::string stream;
  Result<std::optional<ReceivedBytes>> got = tcp->read(milliseconds(1000));
  for (int i = 0; i < 10 && got && (!*got || (*got)->bytes.size() + stream.size() < 7); ++i) {
    if (*got) stream += (*got)->bytes;
    got = tcp->read(milliseconds(100));
  }
  if (got && *got) stream += (*got)->bytes;
  server.join();
  ::close(listener);
  EXPECT_EQ(stream, "$GPGGA,");
  Result<std::optional<ReceivedBytes>> ended = tcp->read(milliseconds(1000));
  while (ended && !*ended) ended = tcp->read(milliseconds(100));
  ASSERT_FALSE(ended.ok()) << "the server closed";
  EXPECT_NE(ended.error().message.find("ended"), std::string::npos);
}

TEST(ByteSource, APseudoTerminalReadsLikeASerialReceiver) {
  const int master = ::posix_openpt(O_RDWR | O_NOCTTY);
  ASSERT_GE(master, 0);
  ASSERT_EQ(::grantpt(master), 0);
  ASSERT_EQ(::unlockpt(master), 0);
  const std::string device = ::ptsname(master);
  auto serial = open_source(parse_source_url("serial://" + device + "?baud=9600").value()).value();
  const std::string sentences =
      "$GPRMC,123519,A,4807.038,N,01131.000,E,022.4,084.4,230394,003.1,W*6A\r\n"
      "$GPGGA,123519,4807.038,N,01131.000,E,1,08,0.9,545.4,M,46.9,M,,*47\r\n";
  ASSERT_EQ(::write(master, sentences.data(), sentences.size()), static_cast<ssize_t>(sentences.size()));
  NmeaDecoder decoder = NmeaDecoder::create().value();
  std::vector<msgs::GnssMessage> fixes;
  std::size_t received = 0;
  for (int i = 0; i < 20 && received < sentences.size(); ++i) {
    const auto bytes = serial->read(milliseconds(100)).value();
    if (!bytes) continue;
    received += bytes->bytes.size();
    decoder.feed(bytes->bytes, fixes);
  }
  decoder.flush(fixes);
  ::close(master);
  EXPECT_EQ(received, sentences.size());
  ASSERT_EQ(fixes.size(), 1U);
  EXPECT_NEAR(fixes[0].latitude, 48.1173, 1e-4);
  EXPECT_NEAR(fixes[0].longitude, 11.516667, 1e-5);
}

}  // namespace
}  // namespace hanzo::fusion::drivers
