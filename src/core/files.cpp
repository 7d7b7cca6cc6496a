#include "hanzo/fusion/core/files.hpp"

#include "hanzo/fusion/core/logging.hpp"

#include <cerrno>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <cstdlib>
#include <sstream>

#include <fcntl.h>
#include <unistd.h>

#include <fmt/format.h>

namespace hanzo::fusion {

Result<std::string> read_file(const std::string& path) {
  std::ifstream file(path, std::ios::binary);
  if (!file) return Error(fmt::format("{}: cannot open file ({})", path, std::strerror(errno)));
  std::ostringstream text;
  text << file.rdbuf();
  if (file.bad()) return Error(fmt::format("{}: read error ({})", path, std::strerror(errno)));
  return text.str();
}

Status write_file_durably(const std::string& path, std::string_view bytes) {
  const int fd = ::open(path.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0644);
  if (fd < 0) return Error{fmt::format("{}: cannot write ({})", path, std::strerror(errno))};
  size_t written = 0;
  while (written < bytes.size()) {
    const ssize_t n = ::write(fd, bytes.data() + written, bytes.size() - written);
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0) break;
    written += static_cast<size_t>(n);
  }
  const bool complete = written == bytes.size() && ::fsync(fd) == 0;
  const int saved_errno = errno;
  ::close(fd);
  if (!complete) {
    ::unlink(path.c_str());
    return Error{fmt::format("{}: write failed ({})", path, std::strerror(saved_errno))};
  }
  return ok_status();
}

Status commit_partial_file(const std::string& partial, const std::string& path, const Status& written) {
  std::error_code ignored;
  if (!written) {
    std::filesystem::remove(partial, ignored);
    return written;
  }
  std::error_code error;
  std::filesystem::rename(partial, path, error);
  if (error) {
    std::filesystem::remove(partial, ignored);
    return Error{fmt::format("{}: cannot write ({})", path, error.message())};
  }
  return ok_status();
}

Status sync_directory(const std::string& path) {
  const int fd = ::open(path.c_str(), O_RDONLY | O_DIRECTORY | O_CLOEXEC);
  if (fd < 0) return Error{fmt::format("{}: cannot open folder ({})", path, std::strerror(errno))};
  const bool synced = ::fsync(fd) == 0;
  const int saved_errno = errno;
  ::close(fd);
  if (!synced) return Error{fmt::format("{}: cannot sync folder ({})", path, std::strerror(saved_errno))};
  return ok_status();
}

std::string find_model_file(const std::string& file_name, const std::string& installed_dir, const std::string& source_dir) {
  namespace fs = std::filesystem;
  const char* environment = std::getenv("HANZO_MODELS_DIR");
  const bool overridden = environment != nullptr && *environment != '\0';
  if (overridden) {
    if (fs::is_regular_file(fs::path(environment) / file_name)) return (fs::path(environment) / file_name).string();
    logger()->warn("HANZO_MODELS_DIR={} holds no {}: looking in {} and {}", environment, file_name, installed_dir, source_dir);
  }
  for (const std::string& folder : {installed_dir, source_dir}) {
    if (fs::is_regular_file(fs::path(folder) / file_name)) return (fs::path(folder) / file_name).string();
  }
  return (fs::path(overridden ? environment : source_dir) / file_name).string();
}

}  // namespace hanzo::fusion
