// The S3 ObjectStore: path-style REST requests (https://ENDPOINT/BUCKET/PREFIX+KEY) over
// libcurl, signed with Signature Version 4 (s3_signature.hpp) over the SHA-256 of the payload.
// Uploads are read into memory one request (or one multipart part) at a time, so a put_file of
// any size holds at most part_bytes; downloads to files stream.

#include <curl/curl.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <ctime>
#include <filesystem>
#include <fstream>
#include <functional>
#include <map>
#include <mutex>
#include <thread>

#include <fmt/format.h>

#include "hanzo/fusion/core/files.hpp"
#include "hanzo/fusion/core/logging.hpp"
#include "hanzo/fusion/object_store/object_store.hpp"
#include "hanzo/fusion/object_store/s3_signature.hpp"
#include "s3_xml.hpp"

namespace hanzo::fusion::object_store {
namespace {

using Query = std::vector<std::pair<std::string, std::string>>;
using Headers = std::vector<std::pair<std::string, std::string>>;

void initialize_curl() {
  static std::once_flag once;
  std::call_once(once, [] { curl_global_init(CURL_GLOBAL_DEFAULT); });
}

std::string amz_date_now() {
  const std::time_t now = std::time(nullptr);
  std::tm utc{};
  gmtime_r(&now, &utc);
  char text[32];
  std::strftime(text, sizeof(text), "%Y%m%dT%H%M%SZ", &utc);
  return text;
}

/// "2026-11-28T11:40:00.000Z" (S3 listings) or "Sat, 28 Nov 2026 11:40:00 GMT" (HTTP headers).
Timestamp parse_time(const std::string& text) {
  std::tm utc{};
  const char* end = strptime(text.c_str(), "%Y-%m-%dT%H:%M:%S", &utc);
  if (end == nullptr) end = strptime(text.c_str(), "%a, %d %b %Y %H:%M:%S", &utc);
  if (end == nullptr) return Timestamp{};
  return Timestamp::from_nanoseconds(static_cast<int64_t>(timegm(&utc)) * 1'000'000'000);
}

struct Response {
  long status = 0;
  std::string body;
  std::map<std::string, std::string> headers;  // lower-case names
};

/// What a request sends and where its response body goes.
struct Exchange {
  Exchange(std::string method_name, std::string object_key, Query query_parameters = {}, Headers extra_headers = {},
           std::string_view body = {})
      : method(std::move(method_name)), key(std::move(object_key)), query(std::move(query_parameters)), headers(std::move(extra_headers)),
        payload(body) {}
  std::string method;
  std::string key;  // empty: a bucket-level request
  Query query;
  Headers headers;            // beyond host / x-amz-*: range, if-none-match, content-type
  std::string_view payload;   // request body (PUT, POST)
  std::FILE* sink = nullptr;  // response body to this file (GET to a file) instead of memory
};

std::size_t write_to_string(char* data, std::size_t size, std::size_t count, void* user) {
  static_cast<std::string*>(user)->append(data, size * count);
  return size * count;
}

std::size_t write_to_file(char* data, std::size_t size, std::size_t count, void* user) {
  return std::fwrite(data, size, count, static_cast<std::FILE*>(user)) * size;
}

std::size_t collect_header(char* data, std::size_t size, std::size_t count, void* user) {
  const std::string_view line(data, size * count);
  const auto colon = line.find(':');
  if (colon != std::string_view::npos) {
    std::string name(line.substr(0, colon));
    std::transform(name.begin(), name.end(), name.begin(), [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
    std::string_view value = line.substr(colon + 1);
    while (!value.empty() && (value.front() == ' ' || value.front() == '\t')) value.remove_prefix(1);
    while (!value.empty() && (value.back() == '\r' || value.back() == '\n' || value.back() == ' ')) value.remove_suffix(1);
    (*static_cast<std::map<std::string, std::string>*>(user))[name] = std::string(value);
  }
  return size * count;
}

struct UploadCursor {
  std::string_view data;
  std::size_t offset = 0;
};

std::size_t read_payload(char* buffer, std::size_t size, std::size_t count, void* user) {
  auto* cursor = static_cast<UploadCursor*>(user);
  const std::size_t n = std::min(size * count, cursor->data.size() - cursor->offset);
  std::memcpy(buffer, cursor->data.data() + cursor->offset, n);
  cursor->offset += n;
  return n;
}

bool transient(long status) { return status == 429 || status >= 500; }

class S3ObjectStore final : public ObjectStore {
 public:
  S3ObjectStore(S3Config config, std::string scheme_authority, std::string host)
      : config_(std::move(config)), base_url_(std::move(scheme_authority)), host_(std::move(host)) {}

  std::string location() const override { return fmt::format("s3://{}/{}", config_.bucket, config_.prefix); }
  std::string location_of(const std::string& key) const override { return fmt::format("s3://{}/{}{}", config_.bucket, config_.prefix, key); }

  Status put(const std::string& key, std::string_view bytes) override {
    HANZO_RETURN_IF_ERROR(validate_object_key(key));
    Response response;
    HANZO_ASSIGN_OR_RETURN(response, perform(Exchange{"PUT", key, {}, {}, bytes}, "PUT"));
    if (response.status != 200) return failure(key, "PUT", response);
    return ok_status();
  }

  Result<bool> put_if_absent(const std::string& key, std::string_view bytes) override {
    HANZO_RETURN_IF_ERROR(validate_object_key(key));
    Response response;
    HANZO_ASSIGN_OR_RETURN(response, perform(Exchange{"PUT", key, {}, {{"if-none-match", "*"}}, bytes}, "PUT"));
    if (response.status == 412 || response.status == 409) return false;
    if (response.status != 200) return failure(key, "PUT", response);
    return true;
  }

  Status put_file(const std::string& key, const std::string& path) override {
    HANZO_RETURN_IF_ERROR(validate_object_key(key));
    std::error_code error;
    const uint64_t size = std::filesystem::file_size(path, error);
    if (error) return Error(fmt::format("{}: cannot read ({})", path, error.message()));
    if (size < config_.multipart_threshold_bytes) {
      std::string bytes;
      HANZO_ASSIGN_OR_RETURN(bytes, read_file(path));
      return put(key, bytes);
    }
    return put_multipart(key, path, size);
  }

  Result<std::string> get(const std::string& key) const override {
    HANZO_RETURN_IF_ERROR(validate_object_key(key));
    Response response;
    HANZO_ASSIGN_OR_RETURN(response, perform(Exchange{"GET", key}, "GET"));
    if (response.status != 200) return failure(key, "GET", response);
    return std::move(response.body);
  }

  Result<std::string> get_range(const std::string& key, uint64_t offset, uint64_t length) const override {
    HANZO_RETURN_IF_ERROR(validate_object_key(key));
    if (length == 0) return std::string{};
    Response response;
    HANZO_ASSIGN_OR_RETURN(response, perform(Exchange{"GET", key, {}, {{"range", fmt::format("bytes={}-{}", offset, offset + length - 1)}}}, "GET"));
    if (response.status == 416) return std::string{};  // the object ends before offset
    if (response.status == 200) {  // a server that ignores Range sends the whole object
      return offset >= response.body.size() ? std::string{} : response.body.substr(offset, length);
    }
    if (response.status != 206) return failure(key, "GET", response);
    return std::move(response.body);
  }

  Status get_to_file(const std::string& key, const std::string& path) const override {
    HANZO_RETURN_IF_ERROR(validate_object_key(key));
    const std::string partial = path + ".partial";
    std::FILE* file = std::fopen(partial.c_str(), "wb");
    if (file == nullptr) return Error(fmt::format("{}: cannot write ({})", partial, std::strerror(errno)));
    Exchange exchange("GET", key);
    exchange.sink = file;
    Result<Response> response = perform(exchange, "GET");
    const bool written = std::fflush(file) == 0;
    std::fclose(file);
    Status done = ok_status();
    if (!response) {
      done = response.error();
    } else if (response->status != 200) {
      // An error response's body went to the file: read it back for the reason.
      Result<std::string> body = read_file(partial);
      response->body = body ? *body : std::string{};
      done = failure(key, "GET", *response);
    } else if (!written) {
      done = Error(fmt::format("{}: write failed", partial));
    }
    return commit_partial_file(partial, path, done);
  }

  Result<std::optional<ObjectInfo>> stat(const std::string& key) const override {
    HANZO_RETURN_IF_ERROR(validate_object_key(key));
    Response response;
    HANZO_ASSIGN_OR_RETURN(response, perform(Exchange{"HEAD", key}, "HEAD"));
    if (response.status == 404) return std::optional<ObjectInfo>{};
    if (response.status != 200) return failure(key, "HEAD", response);
    ObjectInfo info{key, 0, parse_time(response.headers["last-modified"])};
    try {
      info.size = std::stoull(response.headers["content-length"]);
    } catch (const std::exception&) {
      return Error(fmt::format("{}: HEAD: no valid Content-Length in the response", location_of(key)));
    }
    return std::optional<ObjectInfo>(std::move(info));
  }

  Result<std::vector<ObjectInfo>> list(const std::string& prefix) const override {
    std::vector<ObjectInfo> objects;
    std::string continuation;
    for (int page = 0;; ++page) {
      Query query{{"list-type", "2"}, {"prefix", config_.prefix + prefix}, {"max-keys", std::to_string(config_.list_page_size)}};
      if (!continuation.empty()) query.emplace_back("continuation-token", continuation);
      Response response;
      HANZO_ASSIGN_OR_RETURN(response, perform(Exchange{"GET", "", query}, "LIST"));
      if (response.status != 200) return failure(prefix, "LIST", response);
      for (const std::string_view entry : xml::elements(response.body, "Contents")) {
        std::string key = xml::text(entry, "Key");
        if (!key.starts_with(config_.prefix)) continue;
        key.erase(0, config_.prefix.size());
        uint64_t size = 0;
        try {
          size = std::stoull(xml::text(entry, "Size"));
        } catch (const std::exception&) {
          return Error(fmt::format("{}: LIST: an entry without a valid Size", location_of(prefix)));
        }
        objects.push_back({std::move(key), size, parse_time(xml::text(entry, "LastModified"))});
      }
      if (xml::text(response.body, "IsTruncated") != "true") break;
      continuation = xml::text(response.body, "NextContinuationToken");
      if (continuation.empty()) return Error(fmt::format("{}: LIST: a truncated page without a continuation token", location_of(prefix)));
    }
    std::sort(objects.begin(), objects.end(), [](const ObjectInfo& a, const ObjectInfo& b) { return a.key < b.key; });
    return objects;
  }

  Status remove(const std::string& key) override {
    HANZO_RETURN_IF_ERROR(validate_object_key(key));
    Response response;
    HANZO_ASSIGN_OR_RETURN(response, perform(Exchange{"DELETE", key}, "DELETE"));
    if (response.status != 204 && response.status != 200 && response.status != 404) return failure(key, "DELETE", response);
    return ok_status();
  }

  Status remove_all(const std::string& prefix) override {
    std::vector<ObjectInfo> objects;
    HANZO_ASSIGN_OR_RETURN(objects, list(prefix));
    for (const ObjectInfo& object : objects) HANZO_RETURN_IF_ERROR(remove(object.key));
    return ok_status();
  }

 private:
  Status put_multipart(const std::string& key, const std::string& path, uint64_t size) {
    Response response;
    HANZO_ASSIGN_OR_RETURN(response, perform(Exchange{"POST", key, {{"uploads", ""}}}, "CreateMultipartUpload"));
    if (response.status != 200) return failure(key, "CreateMultipartUpload", response);
    const std::string upload_id = xml::text(response.body, "UploadId");
    if (upload_id.empty()) return Error(fmt::format("{}: CreateMultipartUpload: no UploadId in the response", location_of(key)));

    Status uploaded = upload_parts(key, path, size, upload_id);
    if (!uploaded) {
      // Abort, so the service frees the parts; the error reported is the upload's.
      const Result<Response> aborted = perform(Exchange{"DELETE", key, {{"uploadId", upload_id}}}, "AbortMultipartUpload");
      if (!aborted || aborted->status != 204) logger()->warn("{}: could not abort the failed multipart upload {}", location_of(key), upload_id);
    }
    return uploaded;
  }

  Status upload_parts(const std::string& key, const std::string& path, uint64_t size, const std::string& upload_id) {
    std::ifstream file(path, std::ios::binary);
    if (!file) return Error(fmt::format("{}: cannot open ({})", path, std::strerror(errno)));
    const uint64_t part_bytes = std::max<uint64_t>(config_.part_bytes, uint64_t{5} << 20);
    std::string part(static_cast<std::size_t>(std::min(part_bytes, size)), '\0');
    std::string manifest = "<CompleteMultipartUpload>";
    uint64_t sent = 0;
    for (int number = 1; sent < size; ++number) {
      const auto length = static_cast<std::size_t>(std::min(part_bytes, size - sent));
      file.read(part.data(), static_cast<std::streamsize>(length));
      if (static_cast<std::size_t>(file.gcount()) != length) return Error(fmt::format("{}: changed size while being uploaded", path));
      Response response;
      const std::string operation = fmt::format("UploadPart {}", number);
      HANZO_ASSIGN_OR_RETURN(response, perform(Exchange{"PUT", key, {{"partNumber", std::to_string(number)}, {"uploadId", upload_id}}, {},
                                                std::string_view(part.data(), length)},
                                               operation));
      if (response.status != 200) return failure(key, operation, response);
      const std::string& etag = response.headers["etag"];
      if (etag.empty()) return Error(fmt::format("{}: {}: no ETag in the response", location_of(key), operation));
      manifest += fmt::format("<Part><PartNumber>{}</PartNumber><ETag>{}</ETag></Part>", number, xml::escape(etag));
      sent += length;
    }
    manifest += "</CompleteMultipartUpload>";
    Response response;
    HANZO_ASSIGN_OR_RETURN(
        response, perform(Exchange{"POST", key, {{"uploadId", upload_id}}, {{"content-type", "application/xml"}}, manifest}, "CompleteMultipartUpload"));
    // S3 may answer 200 with an error document once the request was accepted.
    if (response.status != 200 || !xml::elements(response.body, "Error").empty()) {
      if (response.status == 200) response.status = 500;
      return failure(key, "CompleteMultipartUpload", response);
    }
    logger()->info("{}: stored in {} parts ({} bytes)", location_of(key), (size + part_bytes - 1) / part_bytes, size);
    return ok_status();
  }

  Error failure(const std::string& key, std::string_view operation, const Response& response) const {
    const std::string code = xml::text(response.body, "Code");
    const std::string message = xml::text(response.body, "Message");
    const std::string where = location_of(key);
    if (response.status == 404 && (code.empty() || code == "NoSuchKey")) {
      return Error(fmt::format("{}: no such object", where), std::string(kNotFound));
    }
    std::string reason = code.empty() ? "" : " " + code;
    if (!message.empty()) reason += ": " + message;
    if (code == "NoSuchBucket") reason += fmt::format(" (create bucket '{}' first)", config_.bucket);
    return Error(fmt::format("{}: {}: HTTP {}{}", where, operation, response.status, reason));
  }

  /// One request, retried while it fails transiently.
  Result<Response> perform(const Exchange& exchange, std::string_view operation) const {
    initialize_curl();
    const std::string where = exchange.key.empty() ? location() : location_of(exchange.key);
    std::string last_error;
    for (int attempt = 1;; ++attempt) {
      if (exchange.sink != nullptr) {
        std::rewind(exchange.sink);
        if (::ftruncate(fileno(exchange.sink), 0) != 0) return Error(fmt::format("{}: {}: cannot reset the download file", where, operation));
      }
      Result<Response> response = perform_once(exchange, where, operation);
      const bool retry = !response || transient(response->status);
      if (!retry) return response;
      last_error = response ? fmt::format("HTTP {} {}", response->status, xml::text(response->body, "Code")) : response.error().message;
      if (attempt >= config_.max_attempts) break;
      const auto wait = std::chrono::milliseconds(100 << std::min(attempt, 6));
      logger()->warn("{}: {} failed ({}); attempt {} of {} in {} ms", where, operation, last_error, attempt + 1, config_.max_attempts, wait.count());
      std::this_thread::sleep_for(wait);
    }
    return Error(fmt::format("{}: {} failed after {} attempts: {}", where, operation, config_.max_attempts, last_error));
  }

  Result<Response> perform_once(const Exchange& exchange, const std::string& where, std::string_view operation) const {
    const std::string path = "/" + config_.bucket + (exchange.key.empty() ? "" : "/" + config_.prefix + exchange.key);
    const std::string query = canonical_query(exchange.query);
    const std::string url = base_url_ + uri_encode(path, true) + (query.empty() ? "" : "?" + query);
    const std::string amz_date = amz_date_now();
    SignableRequest signable{exchange.method, path, exchange.query, exchange.headers, sha256_hex(exchange.payload)};
    signable.headers.emplace_back("host", host_);
    signable.headers.emplace_back("x-amz-date", amz_date);
    signable.headers.emplace_back("x-amz-content-sha256", signable.payload_sha256);
    if (!config_.session_token.empty()) signable.headers.emplace_back("x-amz-security-token", config_.session_token);
    const std::string authorization = authorization_header(signable, {config_.access_key_id, config_.secret_access_key}, config_.region, amz_date);

    std::unique_ptr<CURL, decltype(&curl_easy_cleanup)> curl(curl_easy_init(), curl_easy_cleanup);
    if (!curl) return Error(fmt::format("{}: {}: cannot start an HTTP request (libcurl)", where, operation));
    curl_slist* header_list = nullptr;
    for (const auto& [name, value] : signable.headers) header_list = curl_slist_append(header_list, fmt::format("{}: {}", name, value).c_str());
    header_list = curl_slist_append(header_list, fmt::format("Authorization: {}", authorization).c_str());
    header_list = curl_slist_append(header_list, "Expect:");  // no 100-continue round trip
    std::unique_ptr<curl_slist, decltype(&curl_slist_free_all)> headers(header_list, curl_slist_free_all);

    Response response;
    UploadCursor cursor{exchange.payload};
    CURL* handle = curl.get();
    curl_easy_setopt(handle, CURLOPT_URL, url.c_str());
    curl_easy_setopt(handle, CURLOPT_HTTPHEADER, headers.get());
    curl_easy_setopt(handle, CURLOPT_NOSIGNAL, 1L);
    curl_easy_setopt(handle, CURLOPT_CONNECTTIMEOUT, config_.connect_timeout_seconds);
    curl_easy_setopt(handle, CURLOPT_LOW_SPEED_LIMIT, 1024L);
    curl_easy_setopt(handle, CURLOPT_LOW_SPEED_TIME, config_.stall_timeout_seconds);
    curl_easy_setopt(handle, CURLOPT_HEADERFUNCTION, collect_header);
    curl_easy_setopt(handle, CURLOPT_HEADERDATA, &response.headers);
    if (exchange.sink != nullptr) {
      curl_easy_setopt(handle, CURLOPT_WRITEFUNCTION, write_to_file);
      curl_easy_setopt(handle, CURLOPT_WRITEDATA, exchange.sink);
    } else {
      curl_easy_setopt(handle, CURLOPT_WRITEFUNCTION, write_to_string);
      curl_easy_setopt(handle, CURLOPT_WRITEDATA, &response.body);
    }
    if (exchange.method == "PUT") {
      curl_easy_setopt(handle, CURLOPT_UPLOAD, 1L);
      curl_easy_setopt(handle, CURLOPT_READFUNCTION, read_payload);
      curl_easy_setopt(handle, CURLOPT_READDATA, &cursor);
      curl_easy_setopt(handle, CURLOPT_INFILESIZE_LARGE, static_cast<curl_off_t>(exchange.payload.size()));
    } else if (exchange.method == "POST") {
      curl_easy_setopt(handle, CURLOPT_POST, 1L);
      curl_easy_setopt(handle, CURLOPT_POSTFIELDS, exchange.payload.data());
      curl_easy_setopt(handle, CURLOPT_POSTFIELDSIZE_LARGE, static_cast<curl_off_t>(exchange.payload.size()));
    } else if (exchange.method == "HEAD") {
      curl_easy_setopt(handle, CURLOPT_NOBODY, 1L);
    } else if (exchange.method == "DELETE") {
      curl_easy_setopt(handle, CURLOPT_CUSTOMREQUEST, "DELETE");
    }
    const CURLcode code = curl_easy_perform(handle);
    if (code != CURLE_OK) {
      return Error(fmt::format("{}: {}: cannot reach {} ({})", where, operation, base_url_, curl_easy_strerror(code)));
    }
    curl_easy_getinfo(handle, CURLINFO_RESPONSE_CODE, &response.status);
    return response;
  }

  S3Config config_;
  std::string base_url_;  // scheme://authority, no trailing '/'
  std::string host_;      // the Host header: authority without a default port
};

std::string environment(const char* name) {
  const char* value = std::getenv(name);
  return value == nullptr ? std::string{} : std::string(value);
}

}  // namespace

bool is_s3_url(std::string_view url) { return url.starts_with("s3://"); }

Result<std::unique_ptr<ObjectStore>> open_s3_object_store(const S3Config& given) {
  S3Config config = given;
  if (config.bucket.empty()) return Error("S3 store: no bucket given", "bucket");
  for (const char c : config.bucket) {
    if (!(std::islower(static_cast<unsigned char>(c)) || std::isdigit(static_cast<unsigned char>(c)) || c == '-' || c == '.')) {
      return Error(fmt::format("S3 store: bucket '{}': only lower-case letters, digits, '-' and '.' are allowed", config.bucket), "bucket");
    }
  }
  if (!config.prefix.empty() && config.prefix.back() != '/') config.prefix += '/';
  if (config.region.empty()) return Error("S3 store: no region given", "region");
  if (config.access_key_id.empty() || config.secret_access_key.empty()) {
    return Error("S3 store: no credentials (set AWS_ACCESS_KEY_ID and AWS_SECRET_ACCESS_KEY)", "access_key_id");
  }
  if (config.endpoint.empty()) config.endpoint = fmt::format("https://s3.{}.amazonaws.com", config.region);
  while (config.endpoint.ends_with('/')) config.endpoint.pop_back();
  const auto scheme_end = config.endpoint.find("://");
  const std::string scheme = scheme_end == std::string::npos ? "" : config.endpoint.substr(0, scheme_end);
  if (scheme != "http" && scheme != "https") {
    return Error(fmt::format("S3 store: endpoint '{}' must start with http:// or https://", config.endpoint), "endpoint");
  }
  const std::string authority = config.endpoint.substr(scheme_end + 3);
  if (authority.empty() || authority.find('/') != std::string::npos) {
    return Error(fmt::format("S3 store: endpoint '{}' must be scheme://host[:port] without a path", config.endpoint), "endpoint");
  }
  std::string host = authority;
  if ((scheme == "http" && host.ends_with(":80")) || (scheme == "https" && host.ends_with(":443"))) host.erase(host.rfind(':'));
  if (config.multipart_threshold_bytes < (uint64_t{5} << 20) || config.part_bytes < (uint64_t{5} << 20)) {
    return Error("S3 store: multipart threshold and part size must be at least 5 MiB (S3's smallest part)", "part_bytes");
  }
  if (config.list_page_size < 1 || config.list_page_size > 1000) return Error("S3 store: list_page_size must be 1..1000", "list_page_size");
  if (config.max_attempts < 1) config.max_attempts = 1;
  const std::string base_url = config.endpoint;
  return std::unique_ptr<ObjectStore>(new S3ObjectStore(std::move(config), base_url, std::move(host)));
}

Result<std::unique_ptr<ObjectStore>> open_object_store(const std::string& url) {
  if (url.starts_with("file://")) return open_local_object_store(url.substr(7));
  if (!is_s3_url(url)) return open_local_object_store(url);
  S3Config config;
  std::string rest = url.substr(5);
  std::string parameters;
  if (const auto question = rest.find('?'); question != std::string::npos) {
    parameters = rest.substr(question + 1);
    rest.erase(question);
  }
  const auto slash = rest.find('/');
  config.bucket = rest.substr(0, slash);
  config.prefix = slash == std::string::npos ? "" : rest.substr(slash + 1);
  config.endpoint = environment("AWS_ENDPOINT_URL_S3");
  if (config.endpoint.empty()) config.endpoint = environment("AWS_ENDPOINT_URL");
  if (const std::string region = environment("AWS_REGION"); !region.empty()) {
    config.region = region;
  } else if (const std::string fallback = environment("AWS_DEFAULT_REGION"); !fallback.empty()) {
    config.region = fallback;
  }
  for (std::size_t start = 0; start < parameters.size();) {
    const std::size_t end = std::min(parameters.find('&', start), parameters.size());
    const std::string parameter = parameters.substr(start, end - start);
    const auto equals = parameter.find('=');
    const std::string name = parameter.substr(0, equals);
    const std::string value = equals == std::string::npos ? "" : parameter.substr(equals + 1);
    if (name == "endpoint") {
      config.endpoint = value;
    } else if (name == "region") {
      config.region = value;
    } else {
      return Error(fmt::format("{}: unknown setting '{}' (known: endpoint, region)", url, name), "url");
    }
    start = end + 1;
  }
  config.access_key_id = environment("AWS_ACCESS_KEY_ID");
  config.secret_access_key = environment("AWS_SECRET_ACCESS_KEY");
  config.session_token = environment("AWS_SESSION_TOKEN");
  return open_s3_object_store(config);
}

}  // namespace hanzo::fusion::object_store
