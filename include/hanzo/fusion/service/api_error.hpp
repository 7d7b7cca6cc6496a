#pragma once
// Errors of the server's operations, one vocabulary for REST and gRPC. Every failed request
// answers with {"error": {"code": "not_found", "message": "...", "field": "..."}} and the HTTP
// status (or gRPC status) of its code; `message` names the offending value, `field` is the
// machine-readable path of the offending request field ("" when none).

#include <cassert>
#include <string>
#include <string_view>
#include <utility>
#include <variant>

#include "hanzo/fusion/core/result.hpp"

namespace hanzo::fusion::service {

enum class ErrorCode {
  kInvalidArgument,     // 400  INVALID_ARGUMENT    malformed JSON, wrong types, NaN, bad config
  kUnauthenticated,     // 401  UNAUTHENTICATED     missing or unknown API token
  kPermissionDenied,    // 403  PERMISSION_DENIED   missing permission or another organization
  kNotFound,            // 404  NOT_FOUND           unknown session, map, route
  kConflict,            // 409  ALREADY_EXISTS      sensor already registered, session ended
  kPayloadTooLarge,     // 413  RESOURCE_EXHAUSTED  body over the configured limit
  kRejected,            // 422  FAILED_PRECONDITION message rejected by the session (out of order...)
  kResourceExhausted,   // 429  RESOURCE_EXHAUSTED  too many sessions
  kInternal,            // 500  INTERNAL            storage failure
  kUnavailable,         // 503  UNAVAILABLE         shutting down
};

std::string_view to_string(ErrorCode code);  // "invalid_argument", "not_found", ...
int http_status(ErrorCode code);

struct ApiError {
  ErrorCode code = ErrorCode::kInternal;
  std::string message;
  std::string field;
  /// kUnavailable for a session another replica serves: that replica's REST URL. The REST
  /// front end forwards the request there; gRPC answers UNAVAILABLE naming it.
  std::string served_by = "";

  /// The library error `error` (message and field kept) under `code`.
  static ApiError from(ErrorCode code, const Error& error) { return {code, error.message, error.field}; }
};

/// A value or an ApiError (Result<T> with an error code).
template <typename T>
class [[nodiscard]] ApiResult {
 public:
  ApiResult(T value) : state_(std::in_place_index<0>, std::move(value)) {}       // NOLINT: implicit by design
  ApiResult(ApiError error) : state_(std::in_place_index<1>, std::move(error)) {}  // NOLINT
  bool ok() const { return state_.index() == 0; }
  explicit operator bool() const { return ok(); }
  const T& value() const& { assert(ok()); return std::get<0>(state_); }
  T& value() & { assert(ok()); return std::get<0>(state_); }
  T&& value() && { assert(ok()); return std::get<0>(std::move(state_)); }
  const T* operator->() const { return &value(); }
  T* operator->() { return &value(); }
  const ApiError& error() const { assert(!ok()); return std::get<1>(state_); }

 private:
  std::variant<T, ApiError> state_;
};

struct Done {};  // the value of an ApiResult that carries nothing
using ApiStatus = ApiResult<Done>;
inline ApiStatus api_ok() { return Done{}; }

}  // namespace hanzo::fusion::service
