// hanzo-fusion send CAPTURE [--to HOST] [--port P] [--rate R]: a packet capture's UDP datagrams
// sent again at their recorded pace (R times faster), each to its recorded destination port (or
// --port) on HOST (default 127.0.0.1): a recorded LiDAR or GNSS receiver standing in for the real
// one, for `drive` and `serve` setups. Exit 0 when every datagram was sent.
#include <arpa/inet.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <unistd.h>

#include <cerrno>
#include <chrono>
#include <cstring>
#include <memory>
#include <string>
#include <thread>

#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include "commands.hpp"
#include "hanzo/fusion/drivers/pcap.hpp"

namespace hanzo::fusion::app {

namespace {

struct SendOptions {
  std::string capture;
  std::string host = "127.0.0.1";
  int port = 0;       // 0: each datagram's recorded destination port
  double rate = 1.0;  // x recorded pace
};

int run_send(const Output& output, const SendOptions& options) {
  nlohmann::json result = {{"capture", options.capture}, {"to", options.host}};
  Result<drivers::PcapReader> reader = drivers::PcapReader::open(options.capture);
  if (!reader) return report_failure(output, result, reader.error().message);
  sockaddr_in destination{};
  destination.sin_family = AF_INET;
  if (::inet_pton(AF_INET, options.host.c_str(), &destination.sin_addr) != 1) {
    return report_failure(output, result, fmt::format("--to {}: expected an IPv4 address", options.host));
  }
  const int sender = ::socket(AF_INET, SOCK_DGRAM | SOCK_CLOEXEC, 0);
  if (sender < 0) return report_failure(output, result, fmt::format("socket: {}", std::strerror(errno)));
  std::unique_ptr<int, void (*)(int*)> closer(new int(sender), [](int* descriptor) {
    ::close(*descriptor);
    delete descriptor;
  });
  uint64_t sent = 0, failed = 0;
  std::optional<Timestamp> first_recorded;
  const auto started = std::chrono::steady_clock::now();
  while (true) {
    Result<std::optional<drivers::UdpDatagram>> datagram = reader->next();
    if (!datagram) return report_failure(output, result, datagram.error().message);
    if (!*datagram) break;
    if (!first_recorded) first_recorded = (*datagram)->time;
    // Wait until the datagram's recorded offset (divided by the rate) has passed.
    const double offset = ((*datagram)->time - *first_recorded).seconds() / options.rate;
    std::this_thread::sleep_until(started + std::chrono::duration_cast<std::chrono::steady_clock::duration>(std::chrono::duration<double>(offset)));
    destination.sin_port = htons(static_cast<uint16_t>(options.port > 0 ? options.port : (*datagram)->destination_port));
    const std::string& payload = (*datagram)->payload;
    if (::sendto(sender, payload.data(), payload.size(), 0, reinterpret_cast<const sockaddr*>(&destination), sizeof(destination)) < 0) {
      ++failed;
    } else {
      ++sent;
    }
  }
  result["sent"] = sent;
  result["failed"] = failed;
  result["seconds"] = std::chrono::duration<double>(std::chrono::steady_clock::now() - started).count();
  if (sent == 0 || failed > 0) return report_failure(output, result, fmt::format("{}: {} datagrams sent, {} failed", options.capture, sent, failed));
  result["ok"] = true;
  return report_success(output, result, fmt::format("{}: {} datagrams sent to {} in {:.2f} s\n", options.capture, sent, options.host,
                                                    result["seconds"].get<double>()));
}

}  // namespace

void add_send_command(CLI::App& app, const Output& output, Command& run) {
  auto options = std::make_shared<SendOptions>();
  CLI::App* command = app.add_subcommand("send", "Send a packet capture's UDP datagrams again at their recorded pace (a recorded sensor for drive / serve)");
  command->add_option("CAPTURE", options->capture, "pcap or pcapng file")->required();
  command->add_option("--to", options->host, "IPv4 address to send to")->capture_default_str();
  command->add_option("--port", options->port, "Send every datagram to this port (default: each one's recorded port)")->check(CLI::Range(1, 65535));
  command->add_option("--rate", options->rate, "Pace: times the recorded speed")->check(CLI::PositiveNumber)->capture_default_str();
  command->callback([&output, &run, options] { run = [&output, options] { return run_send(output, *options); }; });
}

}  // namespace hanzo::fusion::app
