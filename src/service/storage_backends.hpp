#pragma once
// The storage backends behind open_storage().
#include <memory>
#include <string>

#include "hanzo/fusion/service/storage.hpp"

namespace hanzo::fusion::service::detail {

Result<std::unique_ptr<Storage>> open_sqlite_storage(const std::string& path);
Result<std::unique_ptr<Storage>> open_postgresql_storage(const std::string& uri);

}  // namespace hanzo::fusion::service::detail
