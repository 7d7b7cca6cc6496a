#include "hanzo/fusion/io/ros2_bag.hpp"

#include <sqlite3.h>
#include <unistd.h>
#include <zstd.h>

#include <algorithm>
#include <atomic>
#include <filesystem>
#include <fstream>
#include <map>
#include <memory>

#include <fmt/format.h>
#include <yaml-cpp/yaml.h>

#include "hanzo/fusion/io/mcap.hpp"

namespace hanzo::fusion::io::ros2 {
namespace {

namespace fs = std::filesystem;

bool ends_with(std::string_view text, std::string_view suffix) {
  return text.size() >= suffix.size() && text.substr(text.size() - suffix.size()) == suffix;
}

// "x.mcap" / "x.mcap.zstd" -> "mcap"; "x.db3" / "x.db3.zstd" -> "sqlite3"; otherwise "".
std::string storage_of(std::string_view file) {
  if (ends_with(file, ".zstd")) file.remove_suffix(5);
  if (ends_with(file, ".mcap")) return "mcap";
  if (ends_with(file, ".db3")) return "sqlite3";
  return "";
}

// Decompresses a zstd stream (rosbag2 writes frames of unknown content size) chunk by chunk.
class ZstdDecompressor {
 public:
  ZstdDecompressor() : context_(ZSTD_createDStream(), ZSTD_freeDStream) {}
  // Feeds `input` and hands each decompressed piece to `write`.
  template <typename Write>
  Status feed(std::string_view input, const Write& write) {
    ZSTD_inBuffer in{input.data(), input.size(), 0};
    std::string out(ZSTD_DStreamOutSize(), '\0');
    while (in.pos < in.size) {
      ZSTD_outBuffer buffer{out.data(), out.size(), 0};
      const std::size_t result = ZSTD_decompressStream(context_.get(), &buffer, &in);
      if (ZSTD_isError(result)) return Error(fmt::format("zstd: {}", ZSTD_getErrorName(result)));
      HANZO_RETURN_IF_ERROR(write(std::string_view(out.data(), buffer.pos)));
      finished_ = result == 0;
    }
    return ok_status();
  }
  bool finished() const { return finished_; }

 private:
  std::unique_ptr<ZSTD_DStream, std::size_t (*)(ZSTD_DStream*)> context_;
  bool finished_ = false;
};

Result<std::string> decompress_message(std::string_view compressed) {
  constexpr std::size_t kMaxMessageBytes = std::size_t{1} << 31;
  std::string out;
  ZstdDecompressor decompressor;
  HANZO_RETURN_IF_ERROR(decompressor.feed(compressed, [&](std::string_view piece) -> Status {
    if (out.size() + piece.size() > kMaxMessageBytes) return Error("zstd: a message decompresses to more than 2 GiB");
    out.append(piece);
    return ok_status();
  }));
  if (!decompressor.finished()) return Error("zstd: the compressed message is truncated");
  return out;
}

// A zstd-compressed storage file decompressed into a temporary file, removed on destruction.
class DecompressedFile {
 public:
  static Result<std::unique_ptr<DecompressedFile>> create(const std::string& compressed_path) {
    std::ifstream in(compressed_path, std::ios::binary);
    if (!in) return Error(fmt::format("{}: cannot open", compressed_path));
    static std::atomic<int> counter = 0;  // several imports in one process get their own files
    const fs::path name = fs::path(compressed_path).filename().replace_extension("");  // drop ".zstd"
    auto file = std::unique_ptr<DecompressedFile>(new DecompressedFile(
        (fs::temp_directory_path() / fmt::format("hanzo_rosbag2_{}_{}_{}", ::getpid(), counter++, name.string())).string()));
    std::ofstream out(file->path_, std::ios::binary);
    if (!out) return Error(fmt::format("{}: cannot create the temporary file {}", compressed_path, file->path_));
    ZstdDecompressor decompressor;
    std::string buffer(1 << 20, '\0');
    while (in) {
      in.read(buffer.data(), static_cast<std::streamsize>(buffer.size()));
      const Status fed = decompressor.feed(std::string_view(buffer.data(), static_cast<std::size_t>(in.gcount())),
                                           [&](std::string_view piece) -> Status {
                                             out.write(piece.data(), static_cast<std::streamsize>(piece.size()));
                                             return out ? ok_status() : Error("cannot write the temporary file");
                                           });
      if (!fed) return Error(fmt::format("{}: {}", compressed_path, fed.error().message));
    }
    if (!decompressor.finished()) return Error(fmt::format("{}: the zstd stream is truncated", compressed_path));
    out.close();
    if (!out) return Error(fmt::format("{}: cannot write the temporary file {}", compressed_path, file->path_));
    return file;
  }
  ~DecompressedFile() {
    std::error_code ignored;
    fs::remove(path_, ignored);
  }
  const std::string& path() const { return path_; }

 private:
  explicit DecompressedFile(std::string path) : path_(std::move(path)) {}
  std::string path_;
};

// A read-only rosbag2 SQLite database.
class Database {
 public:
  static Result<std::unique_ptr<Database>> open(const std::string& path) {
    sqlite3* handle = nullptr;
    const int opened = sqlite3_open_v2(path.c_str(), &handle, SQLITE_OPEN_READONLY, nullptr);
    auto database = std::unique_ptr<Database>(new Database(handle, path));
    if (opened != SQLITE_OK) return Error(fmt::format("{}: cannot open as SQLite: {}", path, sqlite3_errstr(opened)));
    for (const char* table : {"topics", "messages"}) {
      auto statement = database->prepare(fmt::format("SELECT 1 FROM sqlite_master WHERE type='table' AND name='{}'", table));
      if (!statement) return statement.error();
      if (sqlite3_step(statement->get()) != SQLITE_ROW) {
        return Error(fmt::format("{}: not a rosbag2 SQLite database (no table '{}')", path, table));
      }
    }
    return database;
  }
  ~Database() { sqlite3_close(handle_); }

  using Statement = std::unique_ptr<sqlite3_stmt, int (*)(sqlite3_stmt*)>;
  Result<Statement> prepare(const std::string& sql) {
    sqlite3_stmt* statement = nullptr;
    if (sqlite3_prepare_v2(handle_, sql.c_str(), -1, &statement, nullptr) != SQLITE_OK) {
      return Error(fmt::format("{}: {} ({})", path_, sqlite3_errmsg(handle_), sql));
    }
    return Statement(statement, sqlite3_finalize);
  }
  std::string error() const { return fmt::format("{}: {}", path_, sqlite3_errmsg(handle_)); }

  // Topics by their id in the topics table.
  Result<std::map<int64_t, Topic>> topics() {
    Statement statement(nullptr, sqlite3_finalize);
    HANZO_ASSIGN_OR_RETURN(statement, prepare("SELECT id, name, type, serialization_format FROM topics"));
    std::map<int64_t, Topic> topics;
    int step;
    while ((step = sqlite3_step(statement.get())) == SQLITE_ROW) {
      auto text = [&](int column) {
        const unsigned char* value = sqlite3_column_text(statement.get(), column);
        return value ? std::string(reinterpret_cast<const char*>(value)) : std::string();
      };
      topics[sqlite3_column_int64(statement.get(), 0)] = Topic{text(1), text(2), text(3)};
    }
    if (step != SQLITE_DONE) return Error(error());
    return topics;
  }

 private:
  Database(sqlite3* handle, std::string path) : handle_(handle), path_(std::move(path)) {}
  sqlite3* handle_;
  std::string path_;
};

Result<std::vector<Topic>> file_topics(const std::string& path, const std::string& storage) {
  std::vector<Topic> topics;
  if (storage == "mcap") {
    std::unique_ptr<mcap::McapReader> reader;
    HANZO_ASSIGN_OR_RETURN(reader, mcap::McapReader::open(path));
    for (const auto& [id, channel] : reader->channels()) {
      const auto schema = reader->schemas().find(channel.schema_id);
      topics.push_back({channel.topic, schema == reader->schemas().end() ? "" : schema->second.name, channel.message_encoding});
    }
  } else {
    std::unique_ptr<Database> database;
    HANZO_ASSIGN_OR_RETURN(database, Database::open(path));
    std::map<int64_t, Topic> by_id;
    HANZO_ASSIGN_OR_RETURN(by_id, database->topics());
    for (auto& [id, topic] : by_id) topics.push_back(std::move(topic));
  }
  return topics;
}

Status read_mcap(const std::string& path, BagSummary& summary, const std::function<Status(const BagMessage&)>& emit) {
  std::unique_ptr<mcap::McapReader> reader;
  HANZO_ASSIGN_OR_RETURN(reader, mcap::McapReader::open(path));
  if (reader->warning()) summary.warnings.push_back(fmt::format("{}: {}", path, *reader->warning()));
  std::map<uint16_t, Topic> topics;
  for (const auto& [id, channel] : reader->channels()) {
    const auto schema = reader->schemas().find(channel.schema_id);
    topics[id] = {channel.topic, schema == reader->schemas().end() ? "" : schema->second.name, channel.message_encoding};
  }
  mcap::MessageIterator messages = reader->messages();
  mcap::MessageView view;
  while (true) {
    bool more = false;
    HANZO_ASSIGN_OR_RETURN(more, messages.next(view));
    if (!more) return ok_status();
    const BagMessage message{&topics.at(view.channel->id), static_cast<int64_t>(view.log_time), view.data};
    HANZO_RETURN_IF_ERROR(emit(message));
  }
}

Status read_sqlite(const std::string& path, const std::function<Status(const BagMessage&)>& emit) {
  std::unique_ptr<Database> database;
  HANZO_ASSIGN_OR_RETURN(database, Database::open(path));
  std::map<int64_t, Topic> topics;
  HANZO_ASSIGN_OR_RETURN(topics, database->topics());
  Database::Statement statement(nullptr, sqlite3_finalize);
  HANZO_ASSIGN_OR_RETURN(statement, database->prepare("SELECT topic_id, timestamp, data FROM messages ORDER BY timestamp, id"));
  int step;
  while ((step = sqlite3_step(statement.get())) == SQLITE_ROW) {
    const int64_t topic_id = sqlite3_column_int64(statement.get(), 0);
    const auto topic = topics.find(topic_id);
    if (topic == topics.end()) return Error(fmt::format("{}: a message of topic id {}, which the topics table lacks", path, topic_id));
    const void* blob = sqlite3_column_blob(statement.get(), 2);
    const int size = sqlite3_column_bytes(statement.get(), 2);
    const BagMessage message{&topic->second, sqlite3_column_int64(statement.get(), 1),
                             std::string_view(static_cast<const char*>(blob), static_cast<std::size_t>(size))};
    HANZO_RETURN_IF_ERROR(emit(message));
  }
  if (step != SQLITE_DONE) return Error(database->error());
  return ok_status();
}

Status read_metadata(const fs::path& folder, Bag& bag) {
  const fs::path metadata_path = folder / "metadata.yaml";
  try {
    const YAML::Node root = YAML::LoadFile(metadata_path.string());
    const YAML::Node info = root["rosbag2_bagfile_information"];
    if (!info || !info.IsMap()) return Error(fmt::format("{}: no rosbag2_bagfile_information", metadata_path.string()));
    bag.storage = info["storage_identifier"] ? info["storage_identifier"].as<std::string>() : "";
    if (info["compression_format"]) bag.compression = info["compression_format"].as<std::string>();
    if (info["compression_mode"]) bag.compression_mode = info["compression_mode"].as<std::string>();
    const YAML::Node files = info["relative_file_paths"];
    if (!files || !files.IsSequence() || files.size() == 0) {
      return Error(fmt::format("{}: relative_file_paths lists no storage file", metadata_path.string()));
    }
    for (const YAML::Node& file : files) {
      const fs::path relative = file.as<std::string>();
      // Older rosbag2 wrote paths that include the bag folder's name.
      fs::path resolved = folder / relative;
      if (!fs::exists(resolved)) resolved = folder / relative.filename();
      if (!fs::exists(resolved)) {
        return Error(fmt::format("{}: storage file {} does not exist", metadata_path.string(), relative.string()));
      }
      bag.files.push_back(resolved.string());
    }
    if (const YAML::Node custom = info["custom_data"]; custom && custom.IsMap()) {
      for (const auto& entry : custom) bag.custom_data[entry.first.as<std::string>("")] = entry.second.as<std::string>("");
    }
    if (const YAML::Node topics = info["topics_with_message_count"]; topics && topics.IsSequence()) {
      for (const YAML::Node& entry : topics) {
        const YAML::Node metadata = entry["topic_metadata"];
        if (!metadata) continue;
        bag.topics.push_back({metadata["name"].as<std::string>(""), metadata["type"].as<std::string>(""),
                              metadata["serialization_format"].as<std::string>("cdr")});
      }
    }
  } catch (const YAML::Exception& e) {
    return Error(fmt::format("{}: {}", metadata_path.string(), e.what()));
  }
  if (bag.storage != "mcap" && bag.storage != "sqlite3") {
    return Error(fmt::format("{}: storage_identifier '{}' is not supported (mcap, sqlite3)", metadata_path.string(), bag.storage));
  }
  if (!bag.compression.empty() && bag.compression != "zstd") {
    return Error(fmt::format("{}: compression_format '{}' is not supported (zstd)", metadata_path.string(), bag.compression));
  }
  if (!bag.compression.empty() && bag.compression_mode != "FILE" && bag.compression_mode != "MESSAGE") {
    return Error(fmt::format("{}: compression_mode '{}' is not supported (FILE, MESSAGE)", metadata_path.string(), bag.compression_mode));
  }
  return ok_status();
}

}  // namespace

Result<Bag> open_bag(const std::string& path) {
  Bag bag;
  std::error_code error;
  if (fs::is_directory(path, error)) {
    if (fs::exists(fs::path(path) / "metadata.yaml")) {
      HANZO_RETURN_IF_ERROR(read_metadata(path, bag));
    } else {
      for (const auto& entry : fs::directory_iterator(path, error)) {
        if (!storage_of(entry.path().string()).empty()) bag.files.push_back(entry.path().string());
      }
      std::sort(bag.files.begin(), bag.files.end());
      if (bag.files.empty()) return Error(fmt::format("{}: neither metadata.yaml nor .mcap / .db3 files: not a ROS 2 bag", path));
    }
  } else if (fs::exists(path, error)) {
    bag.files.push_back(path);
  } else {
    return Error(fmt::format("{}: no such file or folder", path));
  }
  if (bag.storage.empty()) {
    bag.storage = storage_of(bag.files.front());
    if (bag.storage.empty()) return Error(fmt::format("{}: not a ROS 2 bag storage file (.mcap or .db3)", bag.files.front()));
    if (ends_with(bag.files.front(), ".zstd")) {
      bag.compression = "zstd";
      bag.compression_mode = "FILE";
    }
    for (const std::string& file : bag.files) {
      if (storage_of(file) != bag.storage) return Error(fmt::format("{}: the folder mixes .mcap and .db3 files", path));
    }
  }
  if (bag.topics.empty() && bag.compression_mode != "FILE") {
    // No metadata.yaml: the topics of every file.
    for (const std::string& file : bag.files) {
      std::vector<Topic> topics;
      HANZO_ASSIGN_OR_RETURN(topics, file_topics(file, bag.storage));
      for (Topic& topic : topics) {
        const bool known = std::any_of(bag.topics.begin(), bag.topics.end(), [&](const Topic& t) { return t.name == topic.name; });
        if (!known) bag.topics.push_back(std::move(topic));
      }
    }
  }
  if (bag.topics.empty() && bag.compression_mode == "FILE") {
    return Error(fmt::format("{}: zstd-compressed storage files need the bag's metadata.yaml for their topics", path));
  }
  std::sort(bag.topics.begin(), bag.topics.end(), [](const Topic& a, const Topic& b) { return a.name < b.name; });
  return bag;
}

Result<BagSummary> read_bag(const Bag& bag, const std::function<Status(const BagMessage&)>& on_message) {
  BagSummary summary;
  std::string decompressed;
  auto emit = [&](const BagMessage& message) -> Status {
    ++summary.messages;
    if (bag.compression_mode != "MESSAGE") return on_message(message);
    HANZO_ASSIGN_OR_RETURN(decompressed, decompress_message(message.data));
    BagMessage plain = message;
    plain.data = decompressed;
    return on_message(plain);
  };
  for (const std::string& file : bag.files) {
    std::unique_ptr<DecompressedFile> plain_file;
    if (bag.compression_mode == "FILE") HANZO_ASSIGN_OR_RETURN(plain_file, DecompressedFile::create(file));
    const std::string& path = plain_file ? plain_file->path() : file;
    const Status read = bag.storage == "mcap" ? read_mcap(path, summary, emit) : read_sqlite(path, emit);
    if (!read) {
      const std::string& message = read.error().message;
      return Error(message.rfind(path, 0) == 0 ? file + message.substr(path.size()) : message);
    }
  }
  return summary;
}

}  // namespace hanzo::fusion::io::ros2
