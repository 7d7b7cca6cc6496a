#pragma once
// Result<T>: the return type of every operation that can fail for a reason the caller should
// handle (bad file, bad message, missing sensor). Precondition violations are bugs and are
// asserted instead. The library never throws across its API for expected failures.

#include <cassert>
#include <string>
#include <utility>
#include <variant>

namespace hanzo::fusion {

/// Why an operation failed. `message` is one line for a person and names the offending field
/// and value ("ImuMessage.angular_velocity.x: non-finite value nan"). `field` is the
/// machine-readable path of the offending field when there is one ("angular_velocity.x"),
/// empty otherwise.
struct Error {
  Error() = default;
  explicit Error(std::string message_text, std::string field_path = {})
      : message(std::move(message_text)), field(std::move(field_path)) {}

  std::string message;
  std::string field;
};

template <typename T>
class [[nodiscard]] Result {
 public:
  Result(T value) : state_(std::in_place_index<0>, std::move(value)) {}  // NOLINT: implicit by design
  Result(Error error) : state_(std::in_place_index<1>, std::move(error)) {}  // NOLINT

  bool ok() const { return state_.index() == 0; }
  explicit operator bool() const { return ok(); }

  const T& value() const& { assert(ok()); return std::get<0>(state_); }
  T& value() & { assert(ok()); return std::get<0>(state_); }
  T&& value() && { assert(ok()); return std::get<0>(std::move(state_)); }
  const T& operator*() const& { return value(); }
  T& operator*() & { return value(); }
  const T* operator->() const { return &value(); }
  T* operator->() { return &value(); }

  const Error& error() const { assert(!ok()); return std::get<1>(state_); }

 private:
  std::variant<T, Error> state_;
};

/// Result of an operation that produces nothing but can fail.
template <>
class [[nodiscard]] Result<void> {
 public:
  Result() = default;
  Result(Error error) : error_(std::move(error)), ok_(false) {}  // NOLINT: implicit by design

  bool ok() const { return ok_; }
  explicit operator bool() const { return ok_; }
  const Error& error() const { assert(!ok_); return error_; }

 private:
  Error error_;
  bool ok_ = true;
};

using Status = Result<void>;

inline Status ok_status() { return {}; }

/// `result` with "context: " put before its error message (unchanged when ok), for callers
/// that know where the failing input came from ("poses.txt:12").
template <typename T>
Result<T> with_context(Result<T> result, const std::string& context) {
  if (result) return result;
  Error error = result.error();
  error.message = context + ": " + error.message;
  return error;
}

}  // namespace hanzo::fusion

/// Returns the error of `expression` (a Status or Result) from the enclosing function, which
/// must return a Status or Result, when it failed.
#define HANZO_RETURN_IF_ERROR(expression)           \
  do {                                              \
    if (auto hanzo_status_ = (expression); !hanzo_status_) { \
      return hanzo_status_.error();                 \
    }                                               \
  } while (false)

/// Moves the value of the Result `expression` into `target`, or returns its error from the
/// enclosing function.
#define HANZO_ASSIGN_OR_RETURN(target, expression) \
  do {                                             \
    auto hanzo_result_ = (expression);             \
    if (!hanzo_result_) {                          \
      return hanzo_result_.error();                \
    }                                              \
    target = std::move(hanzo_result_).value();     \
  } while (false)
