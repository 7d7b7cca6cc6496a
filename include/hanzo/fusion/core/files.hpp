#pragma once
// Whole-file reads with errors that name the path and the system's reason.

#include <string>

#include "hanzo/fusion/core/result.hpp"

namespace hanzo::fusion {

/// The file's bytes. Fails with "PATH: cannot open file (No such file or directory)" and the like.
Result<std::string> read_file(const std::string& path);

}  // namespace hanzo::fusion
