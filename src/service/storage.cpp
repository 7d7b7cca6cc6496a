#include "hanzo/fusion/service/storage.hpp"

#include "storage_backends.hpp"

namespace hanzo::fusion::service {

Result<std::unique_ptr<Storage>> open_storage(const std::string& url) {
  constexpr std::string_view kSqlite = "sqlite://";
  if (url.starts_with("postgresql://") || url.starts_with("postgres://")) return detail::open_postgresql_storage(url);
  if (url.starts_with(kSqlite)) {
    const std::string path = url.substr(kSqlite.size());
    if (path.empty()) return Error("storage URL 'sqlite://' names no file");
    return detail::open_sqlite_storage(path);
  }
  if (url.find("://") != std::string::npos) {
    return Error("storage URL '" + url.substr(0, url.find("://") + 3) + "...': unknown scheme (use sqlite://PATH or postgresql://...)");
  }
  if (url.empty()) return Error("storage URL is empty");
  return detail::open_sqlite_storage(url);
}

}  // namespace hanzo::fusion::service
