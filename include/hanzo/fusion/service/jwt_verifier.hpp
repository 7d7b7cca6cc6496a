#pragma once
// Bearer JWTs from an OIDC provider (RFC 7519), verified against the provider's keys (a JWKS
// file, RFC 7517) and mapped to a Principal (auth.hpp).
//
// A token is accepted when, in this order:
//   - it is three base64url parts and its header's "alg" is RS256 or ES256 (never "none" or an
//     HMAC algorithm: a public key must not become an HMAC secret),
//   - the JWKS has the header's "kid" (or, without a kid, exactly one key), of the algorithm's
//     type (RSA for RS256, EC P-256 for ES256), and the signature verifies (libjwt, OpenSSL),
//   - "iss" equals the configured issuer, "aud" (a string or a list) holds the configured
//     audience, "exp" is in the future and "nbf" / "iat" not in the future (both with
//     `leeway_s` seconds of clock skew allowed).
// Each failure names its reason ("token expired at 2026-11-27T21:00:00Z", "audience 'x' is not
// 'hanzo-fusion'"), which the servers return with 401. The principal: name = "sub",
// organization = the `organization_claim` (default "org"), permissions = the fusion:* names in
// the `scope_claim` (default "scope": a space-separated string or a list; other scopes are
// ignored). A token without the organization claim is refused; one without fusion scopes is
// accepted with no permissions (every request then gets 403).
//
// Keys from a URL (the provider's jwks_uri, http or https): fetched when the verifier is made,
// and again when a token names a kid the keys lack (the provider rotated its keys), at most once
// per `refetch_interval_s`; a failed refetch keeps the keys it had.

#include <cstdint>
#include <map>
#include <mutex>
#include <optional>
#include <memory>
#include <string>
#include <string_view>

#include "hanzo/fusion/core/result.hpp"
#include "hanzo/fusion/service/api_error.hpp"
#include "hanzo/fusion/service/auth.hpp"

namespace hanzo::fusion::service {

struct JwtVerifierConfig {
  std::string issuer;                       ///< required: the provider's "iss"
  std::string audience;                     ///< required: this server's client id / audience
  std::string organization_claim = "org";
  std::string scope_claim = "scope";
  int64_t leeway_s = 60;                    ///< clock skew allowed on exp / nbf / iat
  int64_t refetch_interval_s = 60;          ///< keys from a URL: least time between two fetches
};

class JwtVerifier {
 public:
  /// `jwks_json`: {"keys": [{"kty": "RSA", "kid", "n", "e"} | {"kty": "EC", "crv": "P-256", "kid", "x", "y"}]};
  /// keys of other types are skipped, a malformed key is an error naming it.
  static Result<std::shared_ptr<const JwtVerifier>> create(const std::string& jwks_json, JwtVerifierConfig config);
  static Result<std::shared_ptr<const JwtVerifier>> load(const std::string& jwks_path, JwtVerifierConfig config);
  /// The keys of an http:// or https:// URL (see the header comment).
  static Result<std::shared_ptr<const JwtVerifier>> fetch(const std::string& jwks_url, JwtVerifierConfig config);
  /// fetch() for http(s) URLs, load() otherwise.
  static Result<std::shared_ptr<const JwtVerifier>> open(const std::string& jwks_file_or_url, JwtVerifierConfig config);
  ~JwtVerifier();

  /// The principal of a valid token; kUnauthenticated with the reason otherwise. `now_s`: Unix
  /// time (seconds) to check against (0: the system clock).
  ApiResult<Principal> verify(std::string_view token, int64_t now_s = 0) const;
  std::size_t key_count() const;

  /// Whether the text has a JWT's shape (three dot-separated base64url parts).
  static bool looks_like_jwt(std::string_view token);

 private:
  struct Key {
    std::string algorithm;  // "RS256" or "ES256"
    std::string pem;        // SubjectPublicKeyInfo PEM
  };
  using KeySet = std::map<std::string, Key>;  // by kid ("" for a key without one)
  explicit JwtVerifier(JwtVerifierConfig config) : config_(std::move(config)) {}
  static Result<KeySet> parse_keys(const std::string& jwks_json);
  static Result<std::shared_ptr<const JwtVerifier>> make(const std::string& jwks_json, JwtVerifierConfig config, std::string url);
  /// The key for `kid`, refetching the URL's keys once when it is unknown.
  std::optional<Key> find_key(const std::string& kid) const;

  JwtVerifierConfig config_;
  std::string url_;  // "" for keys from a file
  mutable std::mutex mutex_;
  mutable std::shared_ptr<const KeySet> keys_;
  mutable int64_t last_fetch_s_ = 0;
};

}  // namespace hanzo::fusion::service
