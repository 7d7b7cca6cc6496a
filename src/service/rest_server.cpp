#include "hanzo/fusion/service/rest_server.hpp"

#include <charconv>
#include <chrono>
#include <filesystem>
#include <fstream>
#include <functional>
#include <limits>
#include <memory>
#include <string_view>
#include <thread>
#include <tuple>

#include <fmt/format.h>
#include <httplib.h>
#include <openssl/crypto.h>

#include "hanzo/fusion/cloud/cloud_io.hpp"
#include "hanzo/fusion/core/logging.hpp"
#include "hanzo/fusion/maps/label_export.hpp"
#include "hanzo/fusion/maps/fusion_map_file.hpp"
#include "hanzo/fusion/maps/map_export.hpp"
#include "hanzo/fusion/maps/splat_ply.hpp"
#include "hanzo/fusion/calib/calibration_json.hpp"
#include "http_compression.hpp"
#include "json_codec.hpp"
#include "web_assets.hpp"

namespace hanzo::fusion::service {
namespace {

using nlohmann::json;
using Clock = std::chrono::steady_clock;

constexpr const char* kJson = "application/json";
constexpr const char* kSessionPattern = "([0-9a-zA-Z_-]{1,64})";

void send_json(httplib::Response& response, int status, const json& body) {
  response.status = status;
  response.set_content(body.dump(), kJson);
}

// A large text or JSON body compressed at a fast level for a client that accepts it, and sent
// as a sized content provider, which httplib neither recompresses nor re-encodes
// (http_compression.hpp). Small bodies (where httplib's own compression costs little) and
// binary ones are left as they are.
void compress_large_body(const httplib::Request& request, httplib::Response& response) {
  constexpr std::size_t kMinimumBytes = 16 * 1024;
  if (response.body.size() < kMinimumBytes || response.has_header("Content-Encoding")) return;
  const std::string type = response.get_header_value("Content-Type");
  if (type.rfind("text/", 0) != 0 && type.rfind(kJson, 0) != 0) return;
  const detail::ContentEncoding encoding = detail::negotiate_encoding(request.get_header_value("Accept-Encoding"));
  auto body = std::make_shared<std::string>();
  if (Result<std::string> compressed = detail::compress(response.body, encoding); compressed && encoding != detail::ContentEncoding::kIdentity) {
    *body = std::move(compressed).value();
    response.set_header("Content-Encoding", std::string(detail::to_string(encoding)));
  } else {
    body->swap(response.body);
  }
  response.body.clear();
  response.set_header("Vary", "Accept-Encoding");
  response.set_content_provider(body->size(), type, [body](std::size_t offset, std::size_t length, httplib::DataSink& sink) {
    return sink.write(body->data() + offset, length);
  });
}

// Replicas: the header naming the replica that serves a request's session (set with its 503),
// and the one marking a request another replica forwarded (answered where it arrives: no loops).
constexpr const char* kServedByHeader = "X-Hanzo-Served-By";
constexpr const char* kForwardedHeader = "X-Hanzo-Forwarded";
constexpr const char* kReplicaSecretHeader = "X-Hanzo-Replica-Secret";

void send_error(httplib::Response& response, const ApiError& error) {
  send_json(response, http_status(error.code), detail::error_to_json(error));
  if (!error.served_by.empty()) response.set_header(kServedByHeader, error.served_by);
}

// Answers a request for a session another replica serves with that replica's answer. When it
// does not answer (it died; its lease has not run out yet) the 503 stays, with Retry-After.
void forward_to_owner(const httplib::Request& request, httplib::Response& response) {
  const std::string owner = response.get_header_value(kServedByHeader);
  response.headers.erase(kServedByHeader);
  if (request.has_header(kForwardedHeader)) return;
  httplib::Client client(owner);
  client.set_connection_timeout(2, 0);
  client.set_read_timeout(60, 0);
  httplib::Request forwarded;
  forwarded.method = request.method;
  forwarded.path = request.target;
  forwarded.body = request.body;
  for (const char* header : {"Authorization", "Content-Type", "Accept"}) {
    if (request.has_header(header)) forwarded.set_header(header, request.get_header_value(header));
  }
  forwarded.set_header(kForwardedHeader, "1");
  httplib::Result answer = client.send(forwarded);
  if (!answer) {
    response.set_header("Retry-After", "1");
    logger()->warn("REST {} {}: the replica serving it ({}) does not answer: {}", request.method, request.path, owner,
                   httplib::to_string(answer.error()));
    return;
  }
  response.status = answer->status;
  response.body = std::move(answer->body);
  for (const char* header : {"Content-Type", "Content-Disposition", "Retry-After"}) {
    if (answer->has_header(header)) response.set_header(header, answer->get_header_value(header));
  }
}

// A query parameter as a non-negative integer within [minimum, maximum].
ApiResult<int64_t> integer_parameter(const httplib::Request& request, const std::string& name, int64_t fallback, int64_t minimum,
                                     int64_t maximum) {
  if (!request.has_param(name.c_str())) return fallback;
  const std::string text = request.get_param_value(name.c_str());
  int64_t value = 0;
  const auto [end, error] = std::from_chars(text.data(), text.data() + text.size(), value);
  if (error != std::errc() || end != text.data() + text.size()) {
    return ApiError{ErrorCode::kInvalidArgument, fmt::format("{}: expected an integer, got '{}'", name, text), name};
  }
  if (value < minimum || value > maximum) {
    return ApiError{ErrorCode::kInvalidArgument, fmt::format("{}: {} is outside {}..{}", name, value, minimum, maximum), name};
  }
  return value;
}

// `?format=`: fmap (default), pcd, ply or json; kInvalidArgument otherwise.
ApiResult<std::string> map_format(const httplib::Request& request) {
  const std::string format = request.has_param("format") ? request.get_param_value("format") : "fmap";
  if (format != "fmap" && format != "pcd" && format != "ply" && format != "json" && format != "splats" && format != "labels" && format != "classes") {
    return ApiError{ErrorCode::kInvalidArgument, fmt::format("format '{}': use fmap, pcd, ply, labels, classes, splats or json", format), "format"};
  }
  return format;
}

// The recording options of a form or query: record (true / false), privacy.
ApiStatus recording_options(const std::function<std::optional<std::string>(const char*)>& value, CreateSessionRequest& created) {
  if (const std::optional<std::string> record = value("record")) {
    if (*record != "true" && *record != "false") return ApiError{ErrorCode::kInvalidArgument, "record: expected true or false", "record"};
    created.record = *record == "true";
  }
  if (const std::optional<std::string> privacy = value("privacy")) created.privacy = *privacy;
  return api_ok();
}

// A YAML body holding the configuration and, optionally, the calibration (`fusion:` and
// `calibration:` at the top level: the two files one after the other, with or without `---`):
// split into the two texts, each keeping the body's line numbers (the other's lines left blank),
// so errors name the lines the client sent.
std::pair<std::string, std::string> split_configuration_and_calibration(const std::string& body) {
  std::string config, calibration;
  bool in_calibration = false;
  std::size_t start = 0;
  while (start < body.size()) {
    std::size_t end = body.find('\n', start);
    if (end == std::string::npos) end = body.size();
    const std::string_view line(body.data() + start, end - start);
    const bool top_level_key = !line.empty() && line[0] != ' ' && line[0] != '\t' && line[0] != '#' && line.find(':') != std::string_view::npos;
    if (line.starts_with("---")) {
      in_calibration = false;
    } else if (top_level_key) {
      in_calibration = line.starts_with("calibration:");
    }
    const std::string kept = line.starts_with("---") || line.starts_with("...") ? std::string() : std::string(line);
    config += (in_calibration ? std::string() : kept) + "\n";
    calibration += (in_calibration ? kept : std::string()) + "\n";
    start = end + 1;
  }
  if (calibration.find_first_not_of(" \t\n") == std::string::npos) calibration.clear();
  return {config, calibration};
}

// POST /v1/sessions: a JSON object (name, config, calibration: YAML text or JSON objects; record,
// privacy), the files themselves as multipart/form-data parts `config`, `calibration`, `name`,
// `record`, `privacy` (curl -F config=@fusion.yaml), or the configuration file as the body with a
// YAML content type (curl --data-binary @fusion.yaml -H 'Content-Type: application/yaml', the
// calibration after the configuration in the same body when there is one; name, record and
// privacy from the query).
ApiResult<CreateSessionRequest> create_session_request(const httplib::Request& request) {
  const std::string type = request.get_header_value("Content-Type");
  if (request.is_multipart_form_data()) {
    for (const auto& [part, content] : request.files) {
      if (part != "config" && part != "calibration" && part != "name" && part != "record" && part != "privacy") {
        return ApiError{ErrorCode::kInvalidArgument, fmt::format("unknown form part '{}' (known: config, calibration, name, record, privacy)", part),
                        part};
      }
    }
    if (!request.has_file("config")) {
      return ApiError{ErrorCode::kInvalidArgument, "config is missing (a form part with the fusion configuration file)", "config"};
    }
    const auto part = [&](const char* name) { return request.has_file(name) ? request.get_file_value(name).content : std::string(); };
    CreateSessionRequest created;
    created.name = part("name");
    created.config_yaml = part("config");
    created.calibration_yaml = part("calibration");
    const ApiStatus options = recording_options(
        [&](const char* name) { return request.has_file(name) ? std::optional<std::string>(part(name)) : std::nullopt; }, created);
    if (!options) return options.error();
    return created;
  }
  if (type.starts_with("application/yaml") || type.starts_with("application/x-yaml") || type.starts_with("text/yaml")) {
    if (request.body.empty()) return ApiError{ErrorCode::kInvalidArgument, "the request body is empty (expected the fusion configuration)", "body"};
    CreateSessionRequest created;
    created.name = request.has_param("name") ? request.get_param_value("name") : "";
    std::tie(created.config_yaml, created.calibration_yaml) = split_configuration_and_calibration(request.body);
    const ApiStatus options = recording_options(
        [&](const char* name) { return request.has_param(name) ? std::optional<std::string>(request.get_param_value(name)) : std::nullopt; },
        created);
    if (!options) return options.error();
    return created;
  }
  return detail::parse_create_session(request.body);
}

// A map as a FusionMap file, its point layer as binary PCD / PLY, or its Gaussian splats as the
// PLY of 3D Gaussian splatting viewers.
void send_map_file(httplib::Response& response, const msgs::FusionMap& map, const std::string& format) {
  Result<std::string> bytes = Error("");
  if (format == "fmap") {
    bytes = maps::serialize_fusion_map(map);
  } else if (format == "splats") {
    if (!map.gaussian_splats) return send_error(response, {ErrorCode::kNotFound, "the map has no Gaussian splats (yet)", "format"});
    bytes = maps::encode_splat_ply(*map.gaussian_splats);
  } else if (!map.points) {
    return send_error(response, {ErrorCode::kNotFound, "the map has no point layer", "format"});
  } else if (format == "labels" || format == "classes") {
    const bool labels = format == "labels";
    if (labels ? map.points->labels.empty() : map.points->classes.empty()) {
      return send_error(response, {ErrorCode::kNotFound, labels ? "the map's points have no semantic labels" : "the map's points have no segmentation classes",
                                   "format"});
    }
    bytes = labels ? maps::labelled_points_ply(*map.points) : maps::classified_points_ply(*map.points, map.semantic_classes);
  } else {
    bytes = cloud::encode_cloud(maps::to_point_cloud(*map.points), format);
  }
  if (!bytes) return send_error(response, ApiError::from(ErrorCode::kInternal, bytes.error()));
  response.set_header("Content-Disposition",
                       fmt::format("attachment; filename=\"{}-v{}.{}\"", map.map_id, map.version,
                                   format == "splats" || format == "labels" || format == "classes" ? format + ".ply" : format));
  response.set_content(std::move(bytes).value(), "application/octet-stream");
}

}  // namespace

struct RestServer::Impl {
  RestServerConfig config;
  SessionManager* sessions = nullptr;
  std::shared_ptr<const TokenStore> tokens;
  std::shared_ptr<MetricsRegistry> metrics;
  std::unique_ptr<httplib::Server> server;
  std::thread thread;
  int bound_port = 0;

  // The caller of a request, or the 401 to answer.
  ApiResult<Principal> authenticate(const httplib::Request& request) const {
    return authenticate_bearer(tokens.get(), request.get_header_value("Authorization"), "Authorization");
  }

  using Handler = std::function<void(const httplib::Request&, httplib::Response&, const Principal&)>;
  using PublicHandler = std::function<void(const httplib::Request&, httplib::Response&)>;

  // Wraps a handler with request metrics (by route, not by URL: session ids stay out of labels).
  httplib::Server::Handler measured(const std::string& method, const std::string& route, PublicHandler handler) {
    Histogram& latency = metrics->histogram("hanzo_fusion_http_request_seconds", "REST request latency by route",
                                            latency_buckets_seconds(), {{"method", method}, {"route", route}});
    return [this, method, route, handler = std::move(handler), &latency](const httplib::Request& request,
                                                                        httplib::Response& response) {
      const auto started = Clock::now();
      handler(request, response);
      compress_large_body(request, response);
      if (response.status == -1) response.status = 200;  // httplib's default, made explicit for the count
      latency.observe(std::chrono::duration<double>(Clock::now() - started).count());
      metrics->counter("hanzo_fusion_http_requests_total", "REST requests by route and status",
                       {{"method", method}, {"route", route}, {"status", std::to_string(response.status)}})
          .increment();
    };
  }

  httplib::Server::Handler authenticated(const std::string& method, const std::string& route, Handler handler) {
    return measured(method, route, [this, handler = std::move(handler)](const httplib::Request& request, httplib::Response& response) {
      auto principal = authenticate(request);
      if (!principal) return send_error(response, principal.error());
      handler(request, response, principal.value());
      if (response.has_header(kServedByHeader)) forward_to_owner(request, response);
    });
  }

  void add_routes() {
    httplib::Server& s = *server;
    const std::string session = std::string("/v1/sessions/") + kSessionPattern;

    s.Get("/v1/health", measured("GET", "/v1/health", [this](const httplib::Request&, httplib::Response& response) {
      send_json(response, 200, {{"status", "ok"}, {"active_sessions", sessions->active_sessions()},
                                {"storage", sessions->storage_backend()}, {"auth", tokens != nullptr}});
    }));
    // The web viewer: static files, public (the page asks for a token to call the API).
    for (const detail::WebAsset& asset : detail::web_assets()) {
      s.Get(std::string(asset.path), measured("GET", std::string(asset.path), [&asset](const httplib::Request&, httplib::Response& response) {
        response.set_header("Cache-Control", "no-cache");
        response.set_content(asset.body.data(), asset.body.size(), std::string(asset.content_type));
      }));
    }
    s.Get("/v1/openapi.json", measured("GET", "/v1/openapi.json", [](const httplib::Request&, httplib::Response& response) {
      response.set_content(std::string(openapi_document()), kJson);
    }));
    s.Get("/v1/metrics", authenticated("GET", "/v1/metrics", [this](const httplib::Request&, httplib::Response& response,
                                                                    const Principal& caller) {
      if (auto allowed = authorize(caller, Permission::kAdmin); !allowed) return send_error(response, allowed.error());
      response.set_content(metrics->render(), "text/plain; version=0.0.4; charset=utf-8");
    }));

    s.Post("/v1/sessions", authenticated("POST", "/v1/sessions", [this](const httplib::Request& request, httplib::Response& response,
                                                                      const Principal& caller) {
      auto parsed = create_session_request(request);
      if (!parsed) return send_error(response, parsed.error());
      auto created = sessions->create_session(caller, parsed.value());
      if (!created) return send_error(response, created.error());
      response.set_header("Location", "/v1/sessions/" + created->id);
      send_json(response, 201, detail::session_to_json(created.value()));
    }));
    s.Get("/v1/sessions", authenticated("GET", "/v1/sessions", [this](const httplib::Request&, httplib::Response& response,
                                                                    const Principal& caller) {
      auto listed = sessions->list_sessions(caller);
      if (!listed) return send_error(response, listed.error());
      json items = json::array();
      for (const SessionInfo& info : listed.value()) items.push_back(detail::session_to_json(info));
      send_json(response, 200, {{"sessions", std::move(items)}});
    }));
    s.Get(session, authenticated("GET", "/v1/sessions/{id}", [this](const httplib::Request& request, httplib::Response& response,
                                                                  const Principal& caller) {
      auto info = sessions->session_info(caller, request.matches[1]);
      if (!info) return send_error(response, info.error());
      send_json(response, 200, detail::session_to_json(info.value()));
    }));
    s.Delete(session, authenticated("DELETE", "/v1/sessions/{id}", [this](const httplib::Request& request,
                                                                       httplib::Response& response, const Principal& caller) {
      auto ended = sessions->end_session(caller, request.matches[1]);
      if (!ended) return send_error(response, ended.error());
      send_json(response, 200, detail::session_to_json(ended.value()));
    }));
    s.Post(session + "/sensors", authenticated("POST", "/v1/sessions/{id}/sensors", [this](const httplib::Request& request,
                                                                                        httplib::Response& response,
                                                                                        const Principal& caller) {
      auto parsed = detail::parse_sensor_registration(request.body);
      if (!parsed) return send_error(response, parsed.error());
      auto info = sessions->register_sensor(caller, request.matches[1], parsed.value());
      if (!info) return send_error(response, info.error());
      send_json(response, 201, detail::session_to_json(info.value()));
    }));
    s.Get(session + "/pose", authenticated("GET", "/v1/sessions/{id}/pose", [this](const httplib::Request& request,
                                                                                httplib::Response& response,
                                                                                const Principal& caller) {
      auto pose = sessions->current_pose(caller, request.matches[1]);
      if (!pose) return send_error(response, pose.error());
      send_json(response, 200, detail::pose_to_json(pose.value()));
    }));
    s.Get(session + "/recording", authenticated("GET", "/v1/sessions/{id}/recording", [this](const httplib::Request& request,
                                                                                          httplib::Response& response,
                                                                                          const Principal& caller) {
      auto stored = sessions->recording(caller, request.matches[1]);
      if (!stored) return send_error(response, stored.error());
      const std::string key = stored->key;
      response.set_header("Content-Disposition", fmt::format("attachment; filename=\"{}\"", std::filesystem::path(key).filename().string()));
      // Streamed in ranges from where it is kept (a file, or S3): a recording can be gigabytes.
      response.set_content_provider(static_cast<std::size_t>(stored->bytes), "application/octet-stream",
                                    [store = stored->store, key](std::size_t offset, std::size_t length, httplib::DataSink& sink) {
                                      Result<std::string> bytes = store->get_range(key, offset, std::min<std::size_t>(length, 4 << 20));
                                      if (!bytes || bytes->empty()) {
                                        logger()->error("streaming {}: {}", store->location_of(key), bytes ? "ended early" : bytes.error().message);
                                        return false;
                                      }
                                      sink.write(bytes->data(), bytes->size());
                                      return true;
                                    });
    }));
    s.Get(session + "/trajectory", authenticated("GET", "/v1/sessions/{id}/trajectory", [this](const httplib::Request& request,
                                                                                            httplib::Response& response,
                                                                                            const Principal& caller) {
      const std::string format = request.has_param("format") ? request.get_param_value("format") : "json";
      if (format != "json" && format != "tum") {
        return send_error(response, {ErrorCode::kInvalidArgument, fmt::format("format '{}': use json or tum", format), "format"});
      }
      auto after = integer_parameter(request, "after", std::numeric_limits<int64_t>::min(), std::numeric_limits<int64_t>::min(),
                                     std::numeric_limits<int64_t>::max());
      if (!after) return send_error(response, after.error());
      auto limit = integer_parameter(request, "limit", 10000, 1, 100000);
      if (!limit) return send_error(response, limit.error());
      auto page = sessions->trajectory(caller, request.matches[1], Timestamp::from_nanoseconds(after.value()),
                                       static_cast<std::size_t>(limit.value()));
      if (!page) return send_error(response, page.error());
      const std::optional<Timestamp>& next = page->next_after;
      if (format == "tum") {
        if (next) response.set_header("X-Next-After", std::to_string(next->nanoseconds()));
        response.set_content(detail::poses_to_tum(page->poses), "text/plain; charset=utf-8");
        return;
      }
      response.status = 200;
      response.set_content(detail::trajectory_page_to_json(page->poses, next), kJson);
    }));
    s.Get(session + "/map", authenticated("GET", "/v1/sessions/{id}/map", [this](const httplib::Request& request,
                                                                              httplib::Response& response, const Principal& caller) {
      auto format = map_format(request);
      if (!format) return send_error(response, format.error());
      auto map = sessions->map(caller, request.matches[1]);
      if (!map) return send_error(response, map.error());
      if (format.value() == "json") return send_json(response, 200, detail::map_to_json(map.value()));
      send_map_file(response, map.value(), format.value());
    }));
    s.Post(session + "/loop-closure", authenticated("POST", "/v1/sessions/{id}/loop-closure", [this](const httplib::Request& request,
                                                                                              httplib::Response& response,
                                                                                              const Principal& caller) {
      auto parsed = detail::parse_loop_closure(request.body);
      if (!parsed) return send_error(response, parsed.error());
      auto outcome = sessions->close_loop(caller, request.matches[1], parsed.value());
      if (!outcome) return send_error(response, outcome.error());
      send_json(response, 200, detail::loop_closure_to_json(outcome.value()));
    }));

    s.Post(session + "/relocalize", authenticated("POST", "/v1/sessions/{id}/relocalize", [this](const httplib::Request& request,
                                                                                          httplib::Response& response,
                                                                                          const Principal& caller) {
      auto parsed = detail::parse_relocalize(request.body);
      if (!parsed) return send_error(response, parsed.error());
      auto result = sessions->relocalize(caller, request.matches[1], parsed.value());
      if (!result) return send_error(response, result.error());
      send_json(response, 200, detail::relocalization_to_json(result.value()));
    }));

    // Calibration procedures (docs/calibration.md): CPU work for the caller, nothing stored.
    s.Post("/v1/calibrate", authenticated("POST", "/v1/calibrate", [](const httplib::Request& request, httplib::Response& response,
                                                                    const Principal& caller) {
      if (auto allowed = authorize(caller, Permission::kSessionWrite); !allowed) return send_error(response, allowed.error());
      auto parsed = detail::parse_calibrate(request.body);
      if (!parsed) return send_error(response, parsed.error());
      // Bad values name their field (400); data that cannot calibrate (motion about one axis, too
      // few views with the whole board: field "images") is refused (422).
      const auto refused = [&response](const Error& error) {
        const bool unusable = error.field.empty() || error.field == "images";
        send_error(response, ApiError::from(unusable ? ErrorCode::kRejected : ErrorCode::kInvalidArgument, error));
      };
      if (auto* motion = std::get_if<detail::MotionCalibrateRequest>(&parsed.value())) {
        auto calibrated = calib::calibrate_from_motion(motion->input, motion->config);
        if (!calibrated) return refused(calibrated.error());
        return send_json(response, 200, calib::motion_calibration_to_json(calibrated.value()));
      }
      const auto& camera = std::get<detail::CameraCalibrateRequest>(parsed.value());
      auto calibrated = calib::calibrate_camera(camera.images, camera.config);
      if (!calibrated) return refused(calibrated.error());
      nlohmann::json answer = calib::camera_calibration_to_json(calibrated.value());
      answer["sensor"] = camera.sensor;
      send_json(response, 200, answer);
    }));

    // Stored maps.
    s.Get("/v1/maps", authenticated("GET", "/v1/maps", [this](const httplib::Request&, httplib::Response& response, const Principal& caller) {
      auto listed = sessions->list_maps(caller);
      if (!listed) return send_error(response, listed.error());
      json items = json::array();
      for (const StoredMap& map : listed.value()) items.push_back(detail::stored_map_to_json(map));
      send_json(response, 200, {{"maps", std::move(items)}});
    }));
    s.Post("/v1/maps", authenticated("POST", "/v1/maps", [this](const httplib::Request& request, httplib::Response& response,
                                                                const Principal& caller) {
      Result<msgs::FusionMap> map = maps::parse_fusion_map(request.body, "request body");
      if (!map) return send_error(response, {ErrorCode::kInvalidArgument, map.error().message, "body"});
      const std::string name = request.has_param("name") ? request.get_param_value("name") : "";
      auto saved = sessions->load_map(caller, std::move(map).value(), name);
      if (!saved) return send_error(response, saved.error());
      send_json(response, 201, {{"map_id", saved->map_id}, {"version", saved->version}, {"parent_version", saved->parent_version},
                                {"bytes", saved->file_bytes}});
    }));
    s.Get("/v1/maps/([A-Za-z0-9._-]{1,128})", authenticated("GET", "/v1/maps/{id}", [this](const httplib::Request& request,
                                                                                          httplib::Response& response, const Principal& caller) {
      auto format = map_format(request);
      if (!format) return send_error(response, format.error());
      auto version = integer_parameter(request, "version", 0, 0, std::numeric_limits<int64_t>::max());
      if (!version) return send_error(response, version.error());
      std::optional<uint64_t> wanted = version.value() > 0 ? std::optional<uint64_t>(static_cast<uint64_t>(version.value())) : std::nullopt;
      // A temporal query: the newest version created at or before at_ns.
      auto at = integer_parameter(request, "at_ns", -1, 0, std::numeric_limits<int64_t>::max());
      if (!at) return send_error(response, at.error());
      if (at.value() >= 0) {
        if (wanted) return send_error(response, {ErrorCode::kInvalidArgument, "give version or at_ns, not both", "at_ns"});
        auto info = sessions->stored_map_info(caller, request.matches[1]);
        if (!info) return send_error(response, info.error());
        for (const maps::MapVersionInfo& stored : info->versions) {
          if (stored.unreadable.empty() && stored.created.nanoseconds() <= at.value()) wanted = stored.version;
        }
        if (!wanted) {
          return send_error(response, {ErrorCode::kNotFound,
                                       fmt::format("map '{}' has no version created at or before {} ns", std::string(request.matches[1]), at.value()),
                                       "at_ns"});
        }
      }
      if (format.value() == "json") {
        auto info = sessions->stored_map_info(caller, request.matches[1]);
        if (!info) return send_error(response, info.error());
        return send_json(response, 200, detail::stored_map_to_json(info.value()));
      }
      if (format.value() == "fmap") {  // the stored file as it is
        auto file = sessions->stored_map_file(caller, request.matches[1], wanted);
        if (!file) return send_error(response, file.error());
        response.set_header("Content-Disposition", fmt::format("attachment; filename=\"{}-v{}.fmap\"", std::string(request.matches[1]), file->first));
        response.set_content(std::move(file->second), "application/octet-stream");
        return;
      }
      auto map = sessions->stored_map(caller, request.matches[1], wanted);
      if (!map) return send_error(response, map.error());
      send_map_file(response, map.value(), format.value());
    }));

    s.Delete("/v1/maps/([A-Za-z0-9._-]{1,128})", authenticated("DELETE", "/v1/maps/{id}", [this](const httplib::Request& request,
                                                                                                httplib::Response& response,
                                                                                                const Principal& caller) {
      auto version = integer_parameter(request, "version", 0, 1, std::numeric_limits<int64_t>::max());
      if (!version) return send_error(response, version.error());
      const std::optional<uint64_t> wanted = version.value() > 0 ? std::optional<uint64_t>(static_cast<uint64_t>(version.value())) : std::nullopt;
      auto deleted = sessions->delete_map(caller, request.matches[1], wanted);
      if (!deleted) return send_error(response, deleted.error());
      json answer = {{"map_id", std::string(request.matches[1])}, {"versions_deleted", deleted.value()}};
      if (wanted) answer["version"] = *wanted;
      send_json(response, 200, answer);
    }));

    // Replicas: another replica asks this one to let a session go (SessionManager::hand_over).
    s.Post("/v1/replica/sessions/" + std::string(kSessionPattern) + "/handover",
           measured("POST", "/v1/replica/sessions/{id}/handover", [this](const httplib::Request& request, httplib::Response& response) {
             const std::string secret = request.get_header_value(kReplicaSecretHeader);
             if (config.replica_secret.empty()) return send_error(response, {ErrorCode::kNotFound, "this server runs no replicas", ""});
             if (secret.size() != config.replica_secret.size() ||
                 CRYPTO_memcmp(secret.data(), config.replica_secret.data(), secret.size()) != 0) {
               return send_error(response, {ErrorCode::kUnauthenticated, "X-Hanzo-Replica-Secret: missing or wrong", "X-Hanzo-Replica-Secret"});
             }
             const json body = json::parse(request.body, nullptr, false);
             if (!body.is_object() || !body.contains("replica") || !body["replica"].is_string() || !body.contains("url") || !body["url"].is_string()) {
               return send_error(response, {ErrorCode::kInvalidArgument, "expected {\"replica\": ID, \"url\": URL} of the replica taking the session", "replica"});
             }
             if (const ApiStatus handed = sessions->hand_over(request.matches[1], body["replica"], body["url"]); !handed) {
               return send_error(response, handed.error());
             }
             send_json(response, 200, {{"handed_over", request.matches[1].str()}});
           }));

    // Errors httplib answers itself (no route, body too large) get the same JSON shape.
    s.set_error_handler([](const httplib::Request& request, httplib::Response& response) {
      if (!response.body.empty()) return;
      ErrorCode code = ErrorCode::kNotFound;
      std::string message = fmt::format("no route {} {}", request.method, request.path);
      if (response.status == 413) {
        code = ErrorCode::kPayloadTooLarge;
        message = "the request body is larger than the server accepts";
      } else if (response.status == 400) {
        code = ErrorCode::kInvalidArgument;
        message = "malformed request";
      } else if (response.status != 404) {
        code = ErrorCode::kInternal;
        message = fmt::format("HTTP {}", response.status);
      }
      const int status = response.status;
      send_json(response, status, detail::error_to_json({code, message, ""}));
    });
    s.set_exception_handler([](const httplib::Request& request, httplib::Response& response, std::exception_ptr exception) {
      std::string what = "unknown exception";
      try {
        std::rethrow_exception(exception);
      } catch (const std::exception& error) {
        what = error.what();
      } catch (...) {
      }
      logger()->error("REST {} {}: {}", request.method, request.path, what);
      send_error(response, {ErrorCode::kInternal, "internal error: " + what, ""});
    });
  }
};

RestServer::RestServer(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}

std::function<Status(const SessionLease& lease)> replica_handover_requester(std::string secret, std::string replica_id, std::string replica_url) {
  const std::string body = json({{"replica", std::move(replica_id)}, {"url", std::move(replica_url)}}).dump();
  return [secret = std::move(secret), body](const SessionLease& lease) -> Status {
    httplib::Client client(lease.owner_url);
    client.set_connection_timeout(2, 0);
    client.set_read_timeout(30, 0);  // the holder commits poses and saves the map first
    const httplib::Headers headers = {{kReplicaSecretHeader, secret}};
    httplib::Result answer = client.Post(fmt::format("/v1/replica/sessions/{}/handover", lease.session_id), headers, body, "application/json");
    if (!answer) {
      return Error(fmt::format("replica '{}' ({}) does not answer: {}", lease.owner, lease.owner_url, httplib::to_string(answer.error())));
    }
    if (answer->status != 200) return Error(fmt::format("replica '{}' ({}) answered {}: {}", lease.owner, lease.owner_url, answer->status, answer->body));
    return ok_status();
  };
}

RestServer::~RestServer() { stop(); }

Result<std::unique_ptr<RestServer>> RestServer::create(const RestServerConfig& config, SessionManager& sessions,
                                                       std::shared_ptr<const TokenStore> tokens,
                                                       std::shared_ptr<MetricsRegistry> metrics) {
  auto impl = std::make_unique<Impl>();
  impl->config = config;
  impl->sessions = &sessions;
  impl->tokens = std::move(tokens);
  impl->metrics = metrics ? std::move(metrics) : std::make_shared<MetricsRegistry>();
  const bool tls = !config.tls_certificate.empty() || !config.tls_private_key.empty();
  if (tls) {
    if (config.tls_certificate.empty() || config.tls_private_key.empty()) {
      return Error("HTTPS needs both a certificate and a private key file");
    }
    for (const std::string& path : {config.tls_certificate, config.tls_private_key}) {
      if (!std::filesystem::is_regular_file(path)) return Error(fmt::format("{}: no such file", path));
    }
    auto server = std::make_unique<httplib::SSLServer>(config.tls_certificate.c_str(), config.tls_private_key.c_str());
    if (!server->is_valid()) {
      return Error(fmt::format("{} / {}: cannot load the TLS certificate and key (PEM expected, key must match)",
                               config.tls_certificate, config.tls_private_key));
    }
    impl->server = std::move(server);
  } else {
    impl->server = std::make_unique<httplib::Server>();
  }
  const std::size_t threads = std::max<std::size_t>(1, config.threads);
  impl->server->new_task_queue = [threads] { return new httplib::ThreadPool(threads); };
  impl->server->set_payload_max_length(config.max_body_bytes);
  impl->server->set_tcp_nodelay(true);  // small JSON replies: no Nagle delay (40 ms per request otherwise)
  impl->server->set_read_timeout(30, 0);
  impl->server->set_write_timeout(30, 0);
  impl->add_routes();
  return std::unique_ptr<RestServer>(new RestServer(std::move(impl)));
}

Status RestServer::start() {
  Impl& impl = *impl_;
  if (impl.config.port == 0) {
    impl.bound_port = impl.server->bind_to_any_port(impl.config.bind_address.c_str());
    if (impl.bound_port <= 0) return Error(fmt::format("cannot bind {}:<any>", impl.config.bind_address));
  } else {
    if (!impl.server->bind_to_port(impl.config.bind_address.c_str(), impl.config.port)) {
      return Error(fmt::format("cannot bind {}:{} (in use, or no permission)", impl.config.bind_address, impl.config.port));
    }
    impl.bound_port = impl.config.port;
  }
  impl.thread = std::thread([&impl] { impl.server->listen_after_bind(); });
  // httplib's stop() does nothing until the listener runs: a server stopped right after start
  // would otherwise accept forever and its destructor never return.
  while (!impl.server->is_running()) std::this_thread::sleep_for(std::chrono::milliseconds(1));
  logger()->info("REST API on {}://{}:{}", https() ? "https" : "http", impl.config.bind_address, impl.bound_port);
  return ok_status();
}

int RestServer::port() const { return impl_->bound_port; }

bool RestServer::https() const { return !impl_->config.tls_certificate.empty(); }

void RestServer::stop() {
  if (!impl_ || !impl_->server) return;
  impl_->server->stop();
  if (impl_->thread.joinable()) impl_->thread.join();
}

}  // namespace hanzo::fusion::service
