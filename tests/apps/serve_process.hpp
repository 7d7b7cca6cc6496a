#pragma once
// `hanzo-fusion serve` as a child process for the CLI tests: started on free ports, its REST
// endpoint requested with the curl CLI. HANZO_FUSION_CLI is the program under test.
#include <signal.h>
#include <spawn.h>
#include <sys/wait.h>
#include <unistd.h>

#include <array>
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <string>
#include <thread>

#include <fmt/format.h>
#include <nlohmann/json.hpp>

extern char** environ;

namespace hanzo::fusion::testing {

inline std::string read_file(const std::filesystem::path& path) {
  std::ifstream file(path);
  return {std::istreambuf_iterator<char>(file), {}};
}

// A running `hanzo-fusion serve --json ...`; stdout and stderr go to files in `dir`.
class Server {
 public:
  Server(const std::filesystem::path& dir, const std::string& arguments) : dir_(dir) {
    const std::string command = fmt::format("exec {} serve --bind 127.0.0.1 --port 0 --grpc-port 0 --json {} >{} 2>{}", HANZO_FUSION_CLI,
                                            arguments, (dir / "out.txt").string(), (dir / "err.txt").string());
    std::filesystem::remove(dir / "out.txt");  // never read a previous server's port
    const char* argv[] = {"/bin/sh", "-c", command.c_str(), nullptr};
    if (posix_spawn(&pid_, "/bin/sh", nullptr, nullptr, const_cast<char**>(argv), environ) != 0) pid_ = -1;
    for (int i = 0; i < 300 && port_ == 0 && running(); ++i) {
      const std::string out = read_file(dir / "out.txt");
      if (out.find('\n') != std::string::npos) {
        const nlohmann::json ready = nlohmann::json::parse(out);
        if (ready.contains("rest_port")) port_ = ready["rest_port"].get<int>();
        if (ready.contains("grpc_port")) grpc_port_ = ready["grpc_port"].get<int>();
        break;
      } std::this_thread::sleep_for(std::chrono::milliseconds(50));
    }
  }
  ~Server() { stop(SIGKILL); }

  bool running() {
    if (pid_ <= 0) return false;
    int status = 0;
    if (waitpid(pid_, &status, WNOHANG) == 0) return true;
    exit_status_ = status;
    pid_ = -1;
    return false;
  }
  int port() const { return port_; }
  int grpc_port() const { return grpc_port_; }
  /// Waits for the process to exit by itself; its exit status.
  int wait() {
    if (pid_ > 0) {
      waitpid(pid_, &exit_status_, 0);
      pid_ = -1;
    }
    return exit_status_;
  }
  std::string err() const { return read_file(dir_ / "err.txt"); }
  /// Sends `signal` and waits; the exit status.
  int stop(int signal) {
    if (pid_ > 0) {
      kill(pid_, signal);
      waitpid(pid_, &exit_status_, 0);
      pid_ = -1;
    }
    return exit_status_;
  }
  /// curl `path` on the server with extra curl options: {status, body}.
  std::pair<int, std::string> request(const std::string& path, const std::string& curl_options = "") const {
    const std::string command = fmt::format("curl -s -w '\\n%{{http_code}}' {} 'http://127.0.0.1:{}{}'", curl_options, port_, path);
    std::string output;
    FILE* pipe = popen(command.c_str(), "r");
    std::array<char, 4096> buffer{};
    std::size_t n = 0;
    while ((n = std::fread(buffer.data(), 1, buffer.size(), pipe)) > 0) output.append(buffer.data(), n);
    pclose(pipe);
    const std::size_t newline = output.rfind('\n');
    if (newline == std::string::npos) return {0, output};
    return {std::atoi(output.c_str() + newline + 1), output.substr(0, newline)};
  }

 private:
  std::filesystem::path dir_;
  pid_t pid_ = -1;
  int port_ = 0;
  int grpc_port_ = 0;
  int exit_status_ = -1;
};

}  // namespace hanzo::fusion::testing
