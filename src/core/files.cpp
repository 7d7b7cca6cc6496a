#include "hanzo/fusion/core/files.hpp"

#include "hanzo/fusion/core/logging.hpp"

#include <cerrno>
#include <cstring>
#include <algorithm>
#include <filesystem>
#include <fstream>
#include <cstdlib>
#include <sstream>

#include <fcntl.h>
#include <unistd.h>

#include <fmt/format.h>
#include <fmt/ranges.h>

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

Result<std::string> find_model_file(const std::string& file_name, const std::string& installed_dir, const std::string& source_dir) {
  namespace fs = std::filesystem;
  const char* environment = std::getenv(kModelsEnvironment);
  const bool given = environment != nullptr && *environment != '\0';
  std::vector<std::string> looked;
  if (given) {
    const fs::path root(environment);
    if (fs::is_regular_file(root / file_name)) return (root / file_name).string();
    std::error_code ec;
    std::vector<fs::path> folders;
    for (fs::directory_iterator entry(root, ec), end; !ec && entry != end; entry.increment(ec)) {
      if (entry->is_directory()) folders.push_back(entry->path());
    }
    std::sort(folders.begin(), folders.end());  // the same choice on every machine
    for (const fs::path& folder : folders) {
      if (fs::is_regular_file(folder / file_name)) return (folder / file_name).string();
    }
    looked.push_back(fmt::format("{}={} (and its folders)", kModelsEnvironment, environment));
  } else {
    looked.push_back(fmt::format("${} (not set)", kModelsEnvironment));
  }
  for (const std::string& folder : {installed_dir, source_dir}) {
    if (folder.empty()) continue;
    if (fs::is_regular_file(fs::path(folder) / file_name)) {
      if (given) logger()->debug("{}={} holds no {}: using {}", kModelsEnvironment, environment, file_name, (fs::path(folder) / file_name).string());
      return (fs::path(folder) / file_name).string();
    }
    looked.push_back(folder);
  }
  return Error(fmt::format("{} not found (looked in {})", file_name, fmt::join(looked, ", ")));
}

}  // namespace hanzo::fusion
