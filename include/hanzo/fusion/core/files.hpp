#pragma once
// Whole-file reads and durable writes with errors that name the path and the system's reason.

#include <string>
#include <string_view>

#include "hanzo/fusion/core/result.hpp"

namespace hanzo::fusion {

/// The file's bytes. Fails with "PATH: cannot open file (No such file or directory)" and the like.
Result<std::string> read_file(const std::string& path);

/// Creates or truncates `path`, writes `bytes` and fsyncs the file. On failure the partial file
/// is removed. Not atomic by itself: write a temporary name and rename or link it (see
/// yaml::write_file_atomically), then sync_directory() the folder to make the name durable.
Status write_file_durably(const std::string& path, std::string_view bytes);

/// fsyncs a folder, so that names created or renamed in it survive a power loss.
Status sync_directory(const std::string& path);

/// The end of writing a file through a temporary name: when `written` is ok, `partial` is
/// renamed to `path` (replacing it); otherwise, or when the rename fails, `partial` is removed
/// and the error returned. Whoever reads `path` sees the old file or the complete new one.
Status commit_partial_file(const std::string& partial, const std::string& path, const Status& written);

/// The environment variable naming the models folder the programs look in first: model files
/// the repository does not ship (YuNet, ALIKED, ALIKE: their owners' licences) and overrides of
/// the shipped ones.
inline constexpr const char* kModelsEnvironment = "HANZO_FUSION_MODELS";

/// Where a model file is (the search order of docs/security.md): the first of
/// $HANZO_FUSION_MODELS/<file_name>, $HANZO_FUSION_MODELS/<folder>/<file_name> (one level of
/// folders, e.g. a copy of a models tree with a folder per model), `installed_dir` and
/// `source_dir` (empty ones skipped) that holds `file_name`. None: an error naming every place
/// looked in.
Result<std::string> find_model_file(const std::string& file_name, const std::string& installed_dir, const std::string& source_dir);

}  // namespace hanzo::fusion
