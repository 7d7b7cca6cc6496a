#pragma once
// API tokens: who is calling (a Principal: organization + permissions) and whether they may.
//
// Token file (YAML; `--tokens FILE` or the HANZO_FUSION_TOKENS_FILE environment variable):
//
//   tokens:
//     - name: warehouse-robot-7          # for logs and metrics, never the secret
//       organization: acme
//       permissions: [fusion:session:write, fusion:session:read, fusion:map:read]
//       token: "hf_4c1d..."              # the secret as sent in "Authorization: Bearer ..."
//     - name: dashboard
//       organization: acme
//       permissions: [fusion:map:read, fusion:session:read]
//       token_sha256: "9f86d08..."       # or its SHA-256 (hex), so the file holds no secret
//
// Or inline in HANZO_FUSION_TOKENS: "TOKEN=ORG:PERM,PERM;TOKEN=ORG:PERM" (for containers).
// Besides (or instead of) these static tokens, the store can verify bearer JWTs of an OIDC
// provider (jwt_verifier.hpp): a token shaped like a JWT goes to the verifier.
// Tokens shorter than 16 characters are rejected (guessable). Lookups compare SHA-256 digests
// in constant time. `fusion:admin` implies every other permission, inside its organization:
// sessions and maps belong to the organization that created them and no token reaches another
// organization's resources.

#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <string_view>
#include <unordered_map>
#include <vector>

#include "hanzo/fusion/core/result.hpp"
#include "hanzo/fusion/service/api_error.hpp"

namespace hanzo::fusion {
class YamlValue;
}

namespace hanzo::fusion::service {

class JwtVerifier;

enum class Permission : uint32_t {
  kSessionRead = 1u << 0,   // fusion:session:read   state, pose, trajectory, subscriptions
  kSessionWrite = 1u << 1,  // fusion:session:write  create, delete, sensors, streams, loop closure
  kMapRead = 1u << 2,       // fusion:map:read       maps of sessions, stored maps
  kMapWrite = 1u << 3,      // fusion:map:write      load maps, relocalize against them
  kAdmin = 1u << 4,         // fusion:admin          everything above, plus metrics
};

std::string_view to_string(Permission permission);  // "fusion:session:read", ...
std::optional<Permission> permission_from_string(std::string_view name);

/// The caller of a request.
struct Principal {
  std::string name;
  std::string organization;
  uint32_t permissions = 0;  // bits of Permission

  bool has(Permission permission) const;
  /// The principal every request gets when auth is off (--insecure-no-auth): organization
  /// "local", every permission.
  static Principal local_development();
};

class TokenStore {
 public:
  static Result<TokenStore> load(const std::string& path);
  static Result<TokenStore> parse(const std::string& yaml_text, const std::string& source_name);
  /// "TOKEN=ORG:PERM,PERM;..." as in HANZO_FUSION_TOKENS.
  static Result<TokenStore> parse_inline(std::string_view specification);

  /// The principal of `token`, or nullopt for an unknown token.
  std::optional<Principal> authenticate(std::string_view token) const;
  std::size_t size() const { return principals_.size(); }
  /// JWTs (tokens of a JWT's shape) are verified by `verifier` (null: only static tokens).
  void set_jwt_verifier(std::shared_ptr<const JwtVerifier> verifier) { jwt_verifier_ = std::move(verifier); }
  const JwtVerifier* jwt_verifier() const { return jwt_verifier_.get(); }

 private:
  static Result<TokenStore> parse_document(const YamlValue& root);
  Status add(const std::string& digest_hex, Principal principal, const std::string& where);
  std::unordered_map<std::string, Principal> principals_;  // by SHA-256 hex of the token
  std::shared_ptr<const JwtVerifier> jwt_verifier_;
};

/// SHA-256 of `text` as 64 lowercase hex digits.
std::string sha256_hex(std::string_view text);

/// The token of an "Authorization: Bearer TOKEN" header value; nullopt when it is not one.
std::optional<std::string_view> bearer_token(std::string_view authorization_header);

/// The caller behind an "Authorization" header value (REST header or gRPC metadata): `tokens`
/// null (auth off) gives Principal::local_development(); a missing, non-Bearer or unknown token,
/// or a JWT the store's verifier refuses (with its reason), is kUnauthenticated with field
/// `field_name`.
ApiResult<Principal> authenticate_bearer(const TokenStore* tokens, std::string_view authorization_header,
                                         const std::string& field_name);

/// Decides a request: kUnauthenticated without a principal, kPermissionDenied when it lacks
/// `permission` or the resource belongs to another organization (`resource_organization`
/// empty: not organization-scoped, e.g. creating a session).
ApiStatus authorize(const std::optional<Principal>& principal, Permission permission,
                    std::string_view resource_organization = {});

}  // namespace hanzo::fusion::service
