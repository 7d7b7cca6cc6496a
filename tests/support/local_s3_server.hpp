#pragma once
// A local S3-compatible server for tests: s3rver (tests/s3server/node_modules, installed by
// scripts/install-deps.sh) on 127.0.0.1 with a free port, serving one bucket from a scratch
// folder, stopped when the object goes. s3rver checks Signature Version 4 signatures against its
// fixed credentials (access key and secret "S3RVER"). Tests run from the repository root.

#include <signal.h>
#include <spawn.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <filesystem>
#include <fstream>
#include <string>
#include <thread>

#include <fmt/format.h>

#include "hanzo/fusion/object_store/object_store.hpp"

extern char** environ;

namespace hanzo::fusion::testing {

class LocalS3Server {
 public:
  static constexpr const char* kAccessKey = "S3RVER";
  static constexpr const char* kSecretKey = "S3RVER";

  LocalS3Server(const std::filesystem::path& folder, const std::string& bucket) : folder_(folder), bucket_(bucket) {
    std::filesystem::remove_all(folder_);
    std::filesystem::create_directories(folder_ / "data");
    const std::string script = std::filesystem::absolute("tests/s3server/node_modules/s3rver/bin/s3rver.js").string();
    if (!std::filesystem::exists(script)) {
      error_ = script + " is missing: run scripts/install-deps.sh";
      return;
    }
    // --openssl-legacy-provider: s3rver's continuation tokens use DES, which OpenSSL 3 keeps
    // in its legacy provider.
    const std::string command = fmt::format("exec {} --openssl-legacy-provider {} -d {} -a 127.0.0.1 -p 0 --configure-bucket {} >{} 2>&1", HANZO_NODE_EXECUTABLE, script,
                                            (folder_ / "data").string(), bucket_, (folder_ / "log.txt").string());
    const char* argv[] = {"/bin/sh", "-c", command.c_str(), nullptr};
    if (posix_spawn(&pid_, "/bin/sh", nullptr, nullptr, const_cast<char**>(argv), environ) != 0) {
      pid_ = -1;
      error_ = "cannot start node";
      return;
    }
    for (int i = 0; i < 400 && port_ == 0; ++i) {
      std::ifstream log(folder_ / "log.txt");
      const std::string text{std::istreambuf_iterator<char>(log), {}};
      const std::string marker = "listening on 127.0.0.1:";
      if (const auto at = text.find(marker); at != std::string::npos) port_ = std::atoi(text.c_str() + at + marker.size());
      if (port_ == 0) std::this_thread::sleep_for(std::chrono::milliseconds(25));
    }
    if (port_ == 0) error_ = "s3rver did not start: see " + (folder_ / "log.txt").string();
  }
  ~LocalS3Server() {
    if (pid_ > 0) {
      kill(pid_, SIGTERM);
      waitpid(pid_, nullptr, 0);
    }
  }
  LocalS3Server(const LocalS3Server&) = delete;
  LocalS3Server& operator=(const LocalS3Server&) = delete;

  /// Empty when the server runs; else why not.
  const std::string& error() const { return error_; }
  std::string endpoint() const { return fmt::format("http://127.0.0.1:{}", port_); }
  const std::string& bucket() const { return bucket_; }
  /// The bucket's folder on disk (where s3rver keeps the objects).
  std::filesystem::path data_folder() const { return folder_ / "data" / bucket_; }

  object_store::S3Config config(const std::string& prefix = "") const {
    object_store::S3Config config;
    config.endpoint = endpoint();
    config.bucket = bucket_;
    config.prefix = prefix;
    config.access_key_id = kAccessKey;
    config.secret_access_key = kSecretKey;
    return config;
  }
  /// "s3://bucket/prefix?endpoint=..." (credentials from the environment: see use_credentials).
  std::string url(const std::string& prefix = "") const { return fmt::format("s3://{}/{}?endpoint={}", bucket_, prefix, endpoint()); }
  /// Sets AWS_ACCESS_KEY_ID / AWS_SECRET_ACCESS_KEY to the server's credentials.
  static void use_credentials() {
    setenv("AWS_ACCESS_KEY_ID", kAccessKey, 1);
    setenv("AWS_SECRET_ACCESS_KEY", kSecretKey, 1);
  }

 private:
  std::filesystem::path folder_;
  std::string bucket_;
  pid_t pid_ = -1;
  int port_ = 0;
  std::string error_;
};

}  // namespace hanzo::fusion::testing
