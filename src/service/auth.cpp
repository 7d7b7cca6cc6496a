#include "hanzo/fusion/service/auth.hpp"
#include "hanzo/fusion/service/jwt_verifier.hpp"

#include <array>
#include <cctype>

#include <fmt/format.h>
#include <openssl/crypto.h>
#include <openssl/evp.h>

#include "hanzo/fusion/core/yaml_value.hpp"

namespace hanzo::fusion::service {
namespace {

constexpr std::size_t kMinimumTokenLength = 16;

constexpr std::array<Permission, 5> kPermissions = {Permission::kSessionRead, Permission::kSessionWrite, Permission::kMapRead,
                                                    Permission::kMapWrite, Permission::kAdmin};

bool is_sha256_hex(std::string_view text) {
  if (text.size() != 64) return false;
  for (char c : text) {
    if (!std::isxdigit(static_cast<unsigned char>(c))) return false;
  }
  return true;
}

std::string lowercase(std::string_view text) {
  std::string result(text);
  for (char& c : result) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  return result;
}

Result<uint32_t> parse_permission(std::string_view name, const std::string& where) {
  const std::optional<Permission> permission = permission_from_string(name);
  if (!permission) {
    return Error(fmt::format("{}: unknown permission '{}' (known: fusion:session:read, fusion:session:write, "
                             "fusion:map:read, fusion:map:write, fusion:admin)", where, name));
  }
  return static_cast<uint32_t>(*permission);
}

std::vector<std::string_view> split(std::string_view text, char separator) {
  std::vector<std::string_view> parts;
  std::size_t start = 0;
  while (start <= text.size()) {
    const std::size_t end = std::min(text.find(separator, start), text.size());
    parts.push_back(text.substr(start, end - start));
    start = end + 1;
  }
  return parts;
}

}  // namespace

std::string_view to_string(Permission permission) {
  switch (permission) {
    case Permission::kSessionRead: return "fusion:session:read";
    case Permission::kSessionWrite: return "fusion:session:write";
    case Permission::kMapRead: return "fusion:map:read";
    case Permission::kMapWrite: return "fusion:map:write";
    case Permission::kAdmin: return "fusion:admin";
  }
  return "unknown";
}

std::optional<Permission> permission_from_string(std::string_view name) {
  for (Permission permission : kPermissions) {
    if (to_string(permission) == name) return permission;
  }
  return std::nullopt;
}

bool Principal::has(Permission permission) const {
  const uint32_t bits = static_cast<uint32_t>(permission) | static_cast<uint32_t>(Permission::kAdmin);
  return (permissions & bits) != 0;
}

Principal Principal::local_development() {
  uint32_t all = 0;
  for (Permission permission : kPermissions) all |= static_cast<uint32_t>(permission);
  return {"local-development", "local", all};
}

std::string sha256_hex(std::string_view text) {
  std::array<unsigned char, EVP_MAX_MD_SIZE> digest{};
  unsigned int length = 0;
  EVP_Digest(text.data(), text.size(), digest.data(), &length, EVP_sha256(), nullptr);
  std::string hex;
  hex.reserve(2 * length);
  for (unsigned int i = 0; i < length; ++i) hex += fmt::format("{:02x}", digest[i]);
  return hex;
}

Status TokenStore::add(const std::string& digest_hex, Principal principal, const std::string& where) {
  if (principal.organization.empty()) return Error(fmt::format("{}: organization is empty", where));
  if (principal.permissions == 0) return Error(fmt::format("{}: no permissions", where));
  if (!principals_.emplace(digest_hex, std::move(principal)).second) {
    return Error(fmt::format("{}: the same token is listed twice", where));
  }
  return ok_status();
}

Result<TokenStore> TokenStore::load(const std::string& path) {
  Result<YamlValue> document = YamlValue::load_file(path);
  if (!document) return document.error();
  return parse_document(document.value());
}

Result<TokenStore> TokenStore::parse(const std::string& yaml_text, const std::string& source_name) {
  Result<YamlValue> document = YamlValue::load_string(yaml_text, source_name);
  if (!document) return document.error();
  return parse_document(document.value());
}

Result<TokenStore> TokenStore::parse_document(const YamlValue& root) {
  HANZO_RETURN_IF_ERROR(root.check_keys({"tokens"}));
  const YamlValue tokens = root["tokens"];
  if (!tokens.is_sequence()) return tokens.error("expected a list of tokens");
  TokenStore store;
  for (const YamlValue& entry : tokens.elements()) {
    HANZO_RETURN_IF_ERROR(entry.check_keys({"name", "organization", "permissions", "token", "token_sha256"}));
    Principal principal;
    if (entry["name"].present()) HANZO_ASSIGN_OR_RETURN(principal.name, entry["name"].as_string());
    HANZO_ASSIGN_OR_RETURN(principal.organization, entry["organization"].as_string());
    const YamlValue permissions = entry["permissions"];
    if (!permissions.is_sequence()) return permissions.error("expected a list of permissions");
    for (const YamlValue& item : permissions.elements()) {
      std::string name;
      HANZO_ASSIGN_OR_RETURN(name, item.as_string());
      uint32_t bit = 0;
      HANZO_ASSIGN_OR_RETURN(bit, parse_permission(name, item.error("").message));
      principal.permissions |= bit;
    }
    const bool has_token = entry["token"].present();
    const bool has_digest = entry["token_sha256"].present();
    if (has_token == has_digest) return entry.error("give exactly one of token and token_sha256");
    std::string digest;
    if (has_token) {
      std::string token;
      HANZO_ASSIGN_OR_RETURN(token, entry["token"].as_string());
      if (token.size() < kMinimumTokenLength) {
        return entry["token"].error(fmt::format("a token needs at least {} characters", kMinimumTokenLength));
      }
      digest = sha256_hex(token);
    } else {
      HANZO_ASSIGN_OR_RETURN(digest, entry["token_sha256"].as_string());
      if (!is_sha256_hex(digest)) return entry["token_sha256"].error("expected 64 hex digits");
      digest = lowercase(digest);
    }
    if (principal.name.empty()) principal.name = principal.organization + "/" + digest.substr(0, 8);
    HANZO_RETURN_IF_ERROR(store.add(digest, std::move(principal), entry.error("").message));
  }
  return store;
}

Result<TokenStore> TokenStore::parse_inline(std::string_view specification) {
  TokenStore store;
  int index = 0;
  for (std::string_view item : split(specification, ';')) {
    ++index;
    if (item.empty()) continue;
    const std::string where = fmt::format("HANZO_FUSION_TOKENS entry {}", index);
    const std::size_t equals = item.rfind('=');
    const std::size_t colon = equals == std::string_view::npos ? equals : item.find(':', equals);
    if (equals == std::string_view::npos || colon == std::string_view::npos) {
      return Error(fmt::format("{}: expected TOKEN=ORGANIZATION:PERMISSION,PERMISSION", where));
    }
    const std::string_view token = item.substr(0, equals);
    if (token.size() < kMinimumTokenLength) {
      return Error(fmt::format("{}: a token needs at least {} characters", where, kMinimumTokenLength));
    }
    Principal principal;
    principal.organization = std::string(item.substr(equals + 1, colon - equals - 1));
    for (std::string_view name : split(item.substr(colon + 1), ',')) {
      uint32_t bit = 0;
      HANZO_ASSIGN_OR_RETURN(bit, parse_permission(name, where));
      principal.permissions |= bit;
    }
    const std::string digest = sha256_hex(token);
    principal.name = principal.organization + "/" + digest.substr(0, 8);
    HANZO_RETURN_IF_ERROR(store.add(digest, std::move(principal), where));
  }
  return store;
}

std::optional<Principal> TokenStore::authenticate(std::string_view token) const {
  if (token.empty()) return std::nullopt;
  const std::string digest = sha256_hex(token);
  // The map lookup hashes the digest, not the secret, so its timing tells nothing about the
  // token; the final comparison is constant-time as well.
  const auto found = principals_.find(digest);
  if (found == principals_.end() || CRYPTO_memcmp(found->first.data(), digest.data(), digest.size()) != 0) {
    return std::nullopt;
  }
  return found->second;
}

std::optional<std::string_view> bearer_token(std::string_view authorization_header) {
  constexpr std::string_view kScheme = "Bearer ";
  if (authorization_header.size() <= kScheme.size()) return std::nullopt;
  for (std::size_t i = 0; i < kScheme.size(); ++i) {
    if (std::tolower(static_cast<unsigned char>(authorization_header[i])) != std::tolower(static_cast<unsigned char>(kScheme[i]))) {
      return std::nullopt;
    }
  }
  std::string_view token = authorization_header.substr(kScheme.size());
  while (!token.empty() && token.front() == ' ') token.remove_prefix(1);
  while (!token.empty() && (token.back() == ' ' || token.back() == '\r')) token.remove_suffix(1);
  if (token.empty()) return std::nullopt;
  return token;
}

ApiResult<Principal> authenticate_bearer(const TokenStore* tokens, std::string_view authorization_header,
                                         const std::string& field_name) {
  if (tokens == nullptr) return Principal::local_development();
  if (authorization_header.empty()) {
    return ApiError{ErrorCode::kUnauthenticated, fmt::format("missing API token (send '{}: Bearer TOKEN')", field_name), field_name};
  }
  const std::optional<std::string_view> token = bearer_token(authorization_header);
  if (!token) return ApiError{ErrorCode::kUnauthenticated, fmt::format("{} is not 'Bearer TOKEN'", field_name), field_name};
  if (tokens->jwt_verifier() != nullptr && JwtVerifier::looks_like_jwt(*token) && !tokens->authenticate(*token)) {
    ApiResult<Principal> verified = tokens->jwt_verifier()->verify(*token);
    if (!verified) return ApiError{ErrorCode::kUnauthenticated, verified.error().message, field_name};
    return verified;
  }
  std::optional<Principal> principal = tokens->authenticate(*token);
  if (!principal) return ApiError{ErrorCode::kUnauthenticated, "unknown API token", field_name};
  return std::move(*principal);
}

ApiStatus authorize(const std::optional<Principal>& principal, Permission permission, std::string_view resource_organization) {
  if (!principal) {
    return ApiError{ErrorCode::kUnauthenticated, "missing or unknown API token (send 'Authorization: Bearer TOKEN')", ""};
  }
  if (!principal->has(permission)) {
    return ApiError{ErrorCode::kPermissionDenied,
                    fmt::format("token '{}' lacks the permission {}", principal->name, to_string(permission)), ""};
  }
  if (!resource_organization.empty() && resource_organization != principal->organization) {
    return ApiError{ErrorCode::kPermissionDenied,
                    fmt::format("token '{}' of organization '{}' cannot access resources of another organization",
                                principal->name, principal->organization), ""};
  }
  return api_ok();
}

}  // namespace hanzo::fusion::service
