// The local-disk ObjectStore: object KEY is the file ROOT/KEY. Writes go to a hidden temporary
// file in the object's folder (".<name>.<random>.tmp", never listed), are fsynced, and are
// renamed (put) or linked (put_if_absent) under the final name, so a crash leaves either the
// old object or the new one, never a partial file.

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <cstring>
#include <filesystem>
#include <random>

#include <fmt/format.h>

#include "hanzo/fusion/core/files.hpp"
#include "hanzo/fusion/object_store/object_store.hpp"

namespace hanzo::fusion::object_store {
namespace {

namespace fs = std::filesystem;

bool is_temporary(const std::string& file_name) { return !file_name.empty() && file_name.front() == '.' && file_name.ends_with(".tmp"); }

Timestamp modified_time(const fs::path& path) {
  struct stat info {};
  if (::stat(path.c_str(), &info) != 0) return Timestamp{};
  return Timestamp::from_nanoseconds(static_cast<int64_t>(info.st_mtim.tv_sec) * 1'000'000'000 + info.st_mtim.tv_nsec);
}

class LocalObjectStore final : public ObjectStore {
 public:
  explicit LocalObjectStore(fs::path root) : root_(std::move(root)) {}

  std::string location() const override { return "file://" + root_.string(); }
  std::string location_of(const std::string& key) const override { return (root_ / key).string(); }

  Status put(const std::string& key, std::string_view bytes) override {
    std::string temporary;
    HANZO_ASSIGN_OR_RETURN(temporary, write_temporary(key, bytes));
    std::error_code error;
    fs::rename(temporary, root_ / key, error);
    if (error) {
      ::unlink(temporary.c_str());
      return Error(fmt::format("{}: cannot store ({})", location_of(key), error.message()));
    }
    return sync_directory((root_ / key).parent_path().string());
  }

  Result<bool> put_if_absent(const std::string& key, std::string_view bytes) override {
    std::string temporary;
    HANZO_ASSIGN_OR_RETURN(temporary, write_temporary(key, bytes));
    const std::string path = location_of(key);
    const int linked = ::link(temporary.c_str(), path.c_str());
    const int link_errno = errno;
    ::unlink(temporary.c_str());
    if (linked != 0 && link_errno == EEXIST) return false;
    if (linked != 0) return Error(fmt::format("{}: cannot store ({})", path, std::strerror(link_errno)));
    HANZO_RETURN_IF_ERROR(sync_directory((root_ / key).parent_path().string()));
    return true;
  }

  Status put_file(const std::string& key, const std::string& path) override {
    HANZO_RETURN_IF_ERROR(validate_object_key(key));
    HANZO_RETURN_IF_ERROR(make_parent(key));
    const fs::path target = root_ / key;
    const fs::path temporary = temporary_path(target);
    std::error_code error;
    fs::copy_file(path, temporary, fs::copy_options::overwrite_existing, error);
    if (!error) {
      // copy_file does not fsync: make the bytes durable before the name.
      const int fd = ::open(temporary.c_str(), O_RDONLY | O_CLOEXEC);
      if (fd < 0 || ::fsync(fd) != 0) error = std::error_code(errno, std::generic_category());
      if (fd >= 0) ::close(fd);
    }
    if (!error) fs::rename(temporary, target, error);
    if (error) {
      fs::remove(temporary, error);
      return Error(fmt::format("{}: cannot store {} ({})", target.string(), path, error.message()));
    }
    return sync_directory(target.parent_path().string());
  }

  Result<std::string> get(const std::string& key) const override {
    HANZO_RETURN_IF_ERROR(check_exists(key));
    return read_file(location_of(key));
  }

  Result<std::string> get_range(const std::string& key, uint64_t offset, uint64_t length) const override {
    HANZO_RETURN_IF_ERROR(check_exists(key));
    const std::string path = location_of(key);
    const int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
    if (fd < 0) return Error(fmt::format("{}: cannot open ({})", path, std::strerror(errno)));
    struct stat info {};
    ::fstat(fd, &info);
    const auto size = static_cast<uint64_t>(info.st_size);
    std::string bytes(offset >= size ? 0 : std::min(length, size - offset), '\0');
    std::size_t done = 0;
    while (done < bytes.size()) {
      const ssize_t n = ::pread(fd, bytes.data() + done, bytes.size() - done, static_cast<off_t>(offset + done));
      if (n < 0 && errno == EINTR) continue;
      if (n <= 0) break;
      done += static_cast<std::size_t>(n);
    }
    ::close(fd);
    bytes.resize(done);
    return bytes;
  }

  Status get_to_file(const std::string& key, const std::string& path) const override {
    HANZO_RETURN_IF_ERROR(check_exists(key));
    const std::string partial = path + ".partial";
    std::error_code error;
    fs::copy_file(location_of(key), partial, fs::copy_options::overwrite_existing, error);
    return commit_partial_file(partial, path,
                               error ? Status(Error(fmt::format("{}: cannot copy to {} ({})", location_of(key), path, error.message())))
                                     : ok_status());
  }

  Result<std::optional<ObjectInfo>> stat(const std::string& key) const override {
    HANZO_RETURN_IF_ERROR(validate_object_key(key));
    const fs::path path = root_ / key;
    std::error_code error;
    if (!fs::is_regular_file(path, error)) return std::optional<ObjectInfo>{};
    const uint64_t size = fs::file_size(path, error);
    if (error) return Error(fmt::format("{}: cannot read its size ({})", path.string(), error.message()));
    return std::optional<ObjectInfo>(ObjectInfo{key, size, modified_time(path)});
  }

  Result<std::vector<ObjectInfo>> list(const std::string& prefix) const override {
    // Walk only the folder the prefix lies in.
    const auto slash = prefix.rfind('/');
    const fs::path start = slash == std::string::npos ? root_ : root_ / prefix.substr(0, slash);
    std::vector<ObjectInfo> objects;
    std::error_code error;
    if (!fs::is_directory(start, error)) return objects;
    for (fs::recursive_directory_iterator it(start, error), end; !error && it != end; it.increment(error)) {
      if (!it->is_regular_file(error) || is_temporary(it->path().filename().string())) continue;
      std::string key = fs::relative(it->path(), root_, error).generic_string();
      if (error || !key.starts_with(prefix)) continue;
      const uint64_t size = it->file_size(error);
      objects.push_back({std::move(key), size, modified_time(it->path())});
    }
    if (error) return Error(fmt::format("{}: cannot list ({})", start.string(), error.message()));
    std::sort(objects.begin(), objects.end(), [](const ObjectInfo& a, const ObjectInfo& b) { return a.key < b.key; });
    return objects;
  }

  Status remove(const std::string& key) override {
    HANZO_RETURN_IF_ERROR(validate_object_key(key));
    const fs::path path = root_ / key;
    if (::unlink(path.c_str()) != 0 && errno != ENOENT) {
      return Error(fmt::format("{}: cannot delete ({})", path.string(), std::strerror(errno)));
    }
    // Folders that held only this object go too (object stores have no empty folders).
    std::error_code error;
    for (fs::path folder = path.parent_path(); folder != root_ && fs::is_empty(folder, error) && !error; folder = folder.parent_path()) {
      if (!fs::remove(folder, error)) break;
    }
    fs::path folder = path.parent_path();
    while (folder != root_ && !fs::exists(folder, error)) folder = folder.parent_path();
    return sync_directory(folder.string());
  }

  Status remove_all(const std::string& prefix) override {
    std::vector<ObjectInfo> objects;
    HANZO_ASSIGN_OR_RETURN(objects, list(prefix));
    for (const ObjectInfo& object : objects) HANZO_RETURN_IF_ERROR(remove(object.key));
    if (prefix.ends_with('/')) {  // a folder: also the temporary files of interrupted writes
      HANZO_RETURN_IF_ERROR(validate_object_key(prefix.substr(0, prefix.size() - 1)));
      std::error_code error;
      fs::remove_all(root_ / prefix, error);
      if (error) return Error(fmt::format("{}: cannot delete ({})", (root_ / prefix).string(), error.message()));
    }
    return ok_status();
  }

 private:
  // Unique per writer: the process id keeps forked writers, whose random generators were copied
  // from one parent, apart.
  static fs::path temporary_path(const fs::path& target) {
    thread_local std::mt19937_64 random(std::random_device{}());
    return target.parent_path() / fmt::format(".{}.{}.{:016x}.tmp", target.filename().string(), ::getpid(), random());
  }

  Status make_parent(const std::string& key) const {
    std::error_code error;
    fs::create_directories((root_ / key).parent_path(), error);
    if (error) return Error(fmt::format("{}: cannot create folder ({})", (root_ / key).parent_path().string(), error.message()));
    return ok_status();
  }

  Result<std::string> write_temporary(const std::string& key, std::string_view bytes) const {
    HANZO_RETURN_IF_ERROR(validate_object_key(key));
    HANZO_RETURN_IF_ERROR(make_parent(key));
    const std::string temporary = temporary_path(root_ / key).string();
    HANZO_RETURN_IF_ERROR(write_file_durably(temporary, bytes));
    return temporary;
  }

  Status check_exists(const std::string& key) const {
    HANZO_RETURN_IF_ERROR(validate_object_key(key));
    std::error_code error;
    if (!fs::is_regular_file(root_ / key, error)) return Error(fmt::format("{}: no such object", location_of(key)), std::string(kNotFound));
    return ok_status();
  }

  fs::path root_;
};

}  // namespace

Status validate_object_key(const std::string& key) {
  if (key.empty() || key.size() > 1024) return Error(fmt::format("object key: must be 1 to 1024 bytes, got {}", key.size()), "key");
  for (const char c : key) {
    if (c < 0x20 || c > 0x7e || c == '\\') return Error(fmt::format("object key '{}': only printable ASCII without '\\' is allowed", key), "key");
  }
  if (key.front() == '/' || key.find("//") != std::string::npos) {
    return Error(fmt::format("object key '{}': must not start with '/' or hold an empty segment", key), "key");
  }
  for (std::size_t start = 0; start <= key.size();) {
    const std::size_t end = std::min(key.find('/', start), key.size());
    const std::string_view segment(key.data() + start, end - start);
    if (segment == "." || segment == "..") return Error(fmt::format("object key '{}': '.' and '..' segments are not allowed", key), "key");
    start = end + 1;
  }
  return ok_status();
}

Result<std::unique_ptr<ObjectStore>> open_local_object_store(const std::string& root) {
  std::error_code error;
  fs::create_directories(root, error);
  if (error || !fs::is_directory(root)) {
    return Error(fmt::format("{}: cannot create the store folder ({})", root, error ? error.message() : "not a folder"));
  }
  fs::path normal = fs::absolute(root).lexically_normal();
  if (normal.filename().empty()) normal = normal.parent_path();  // "/data/" -> "/data"
  return std::unique_ptr<ObjectStore>(new LocalObjectStore(normal));
}

}  // namespace hanzo::fusion::object_store
