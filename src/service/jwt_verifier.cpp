#include "hanzo/fusion/service/jwt_verifier.hpp"

#include <algorithm>
#include <chrono>
#include <fstream>
#include <optional>
#include <sstream>

#include <fmt/chrono.h>
#include <fmt/format.h>
#include <jwt.h>
#include <nlohmann/json.hpp>
#include <openssl/bn.h>
#include <openssl/core_names.h>
#include <openssl/evp.h>
#include <openssl/param_build.h>
#include <openssl/pem.h>

#include "hanzo/fusion/core/base64.hpp"
#include "hanzo/fusion/core/logging.hpp"

// Last: httplib pulls in <resolv.h>, whose `_res` macro breaks headers included after it.
#include <httplib.h>

namespace hanzo::fusion::service {
namespace {

using json = nlohmann::json;

Result<std::string> base64url_decode(std::string_view text) {
  std::string standard(text);
  for (char& c : standard) {
    if (c == '-') c = '+';
    else if (c == '_') c = '/';
  }
  while (standard.size() % 4 != 0) standard.push_back('=');
  Result<std::vector<uint8_t>> bytes = base64_decode(standard);
  if (!bytes) return bytes.error();
  return std::string(bytes->begin(), bytes->end());
}

// OpenSSL objects released on scope exit.
struct BignumDeleter { void operator()(BIGNUM* p) const { BN_free(p); } };
struct KeyDeleter { void operator()(EVP_PKEY* p) const { EVP_PKEY_free(p); } };
struct ContextDeleter { void operator()(EVP_PKEY_CTX* p) const { EVP_PKEY_CTX_free(p); } };
struct BuilderDeleter { void operator()(OSSL_PARAM_BLD* p) const { OSSL_PARAM_BLD_free(p); } };
struct ParamsDeleter { void operator()(OSSL_PARAM* p) const { OSSL_PARAM_free(p); } };
struct BioDeleter { void operator()(BIO* p) const { BIO_free(p); } };

// A member that is a string, else `fallback` (missing, or another type: JWKS and token JSON are
// outside input, and json::value() would throw on a type mismatch).
std::string text_member(const json& object, const char* name, const char* fallback = "") {
  const auto found = object.find(name);
  return found != object.end() && found->is_string() ? found->get<std::string>() : std::string(fallback);
}

// A numeric claim (seconds since the epoch) clamped to years 1..9999; empty when absent or not a number.
std::optional<int64_t> time_claim(const json& claims, const char* name) {
  const auto found = claims.find(name);
  if (found == claims.end() || !found->is_number()) return std::nullopt;
  const double value = found->get<double>();
  if (!(value == value)) return std::nullopt;
  return static_cast<int64_t>(std::clamp(value, -62135596800.0, 253402300799.0));
}

Result<std::string> field(const json& key, const char* name) {
  if (!key.contains(name) || !key[name].is_string()) return Error(fmt::format("missing \"{}\"", name));
  return with_context(base64url_decode(key[name].get<std::string>()), name);
}

// A public key from OpenSSL parameters (RSA n, e or EC group + public point) as PEM.
Result<std::string> public_key_pem(const char* type, OSSL_PARAM_BLD* builder) {
  std::unique_ptr<OSSL_PARAM, ParamsDeleter> params(OSSL_PARAM_BLD_to_param(builder));
  std::unique_ptr<EVP_PKEY_CTX, ContextDeleter> context(EVP_PKEY_CTX_new_from_name(nullptr, type, nullptr));
  EVP_PKEY* raw = nullptr;
  if (!params || !context || EVP_PKEY_fromdata_init(context.get()) <= 0 ||
      EVP_PKEY_fromdata(context.get(), &raw, EVP_PKEY_PUBLIC_KEY, params.get()) <= 0) {
    return Error("OpenSSL refuses the key's numbers");
  }
  std::unique_ptr<EVP_PKEY, KeyDeleter> key(raw);
  std::unique_ptr<BIO, BioDeleter> bio(BIO_new(BIO_s_mem()));
  if (!bio || PEM_write_bio_PUBKEY(bio.get(), key.get()) != 1) return Error("cannot write the key as PEM");
  char* data = nullptr;
  const long size = BIO_get_mem_data(bio.get(), &data);
  return std::string(data, static_cast<std::size_t>(size));
}

Result<std::string> rsa_pem(const json& key) {
  std::string n, e;
  HANZO_ASSIGN_OR_RETURN(n, field(key, "n"));
  HANZO_ASSIGN_OR_RETURN(e, field(key, "e"));
  std::unique_ptr<BIGNUM, BignumDeleter> modulus(BN_bin2bn(reinterpret_cast<const unsigned char*>(n.data()), static_cast<int>(n.size()), nullptr));
  std::unique_ptr<BIGNUM, BignumDeleter> exponent(BN_bin2bn(reinterpret_cast<const unsigned char*>(e.data()), static_cast<int>(e.size()), nullptr));
  if (BN_num_bits(modulus.get()) < 2048) return Error(fmt::format("an RSA key of {} bits (at least 2048)", BN_num_bits(modulus.get())));
  std::unique_ptr<OSSL_PARAM_BLD, BuilderDeleter> builder(OSSL_PARAM_BLD_new());
  OSSL_PARAM_BLD_push_BN(builder.get(), OSSL_PKEY_PARAM_RSA_N, modulus.get());
  OSSL_PARAM_BLD_push_BN(builder.get(), OSSL_PKEY_PARAM_RSA_E, exponent.get());
  return public_key_pem("RSA", builder.get());
}

Result<std::string> ec_pem(const json& key) {
  if (text_member(key, "crv") != "P-256") return Error(fmt::format("curve '{}' (ES256 needs P-256)", text_member(key, "crv")));
  std::string x, y;
  HANZO_ASSIGN_OR_RETURN(x, field(key, "x"));
  HANZO_ASSIGN_OR_RETURN(y, field(key, "y"));
  if (x.size() != 32 || y.size() != 32) return Error("P-256 coordinates are 32 bytes each");
  const std::string point = std::string(1, '\x04') + x + y;  // uncompressed SEC1 point
  std::unique_ptr<OSSL_PARAM_BLD, BuilderDeleter> builder(OSSL_PARAM_BLD_new());
  OSSL_PARAM_BLD_push_utf8_string(builder.get(), OSSL_PKEY_PARAM_GROUP_NAME, "prime256v1", 0);
  OSSL_PARAM_BLD_push_octet_string(builder.get(), OSSL_PKEY_PARAM_PUB_KEY, point.data(), point.size());
  return public_key_pem("EC", builder.get());
}

int64_t unix_now() {
  return std::chrono::duration_cast<std::chrono::seconds>(std::chrono::system_clock::now().time_since_epoch()).count();
}

// The body of a 200 answer to GET `url` (http or https), or why there is none.
Result<std::string> http_get(const std::string& url) {
  const std::size_t scheme_end = url.find("://");
  if (scheme_end == std::string::npos) return Error(fmt::format("{}: not an http(s) URL", url));
  const std::size_t path_start = url.find('/', scheme_end + 3);
  const std::string origin = url.substr(0, path_start);
  const std::string path = path_start == std::string::npos ? "/" : url.substr(path_start);
  httplib::Client client(origin);
  client.set_connection_timeout(5);
  client.set_read_timeout(10);
  client.set_follow_location(true);
  const httplib::Result response = client.Get(path);
  if (!response) return Error(fmt::format("{}: {}", url, httplib::to_string(response.error())));
  if (response->status != 200) return Error(fmt::format("{}: HTTP {}", url, response->status));
  return response->body;
}

ApiError unauthenticated(std::string reason) { return ApiError{ErrorCode::kUnauthenticated, "JWT refused: " + reason, "Authorization"}; }

std::string utc(int64_t seconds) {
  return fmt::format("{:%Y-%m-%dT%H:%M:%SZ}", fmt::gmtime(static_cast<std::time_t>(seconds)));
}

}  // namespace

JwtVerifier::~JwtVerifier() = default;

bool JwtVerifier::looks_like_jwt(std::string_view token) {
  if (std::count(token.begin(), token.end(), '.') != 2) return false;
  return std::all_of(token.begin(), token.end(), [](char c) { return std::isalnum(static_cast<unsigned char>(c)) || c == '-' || c == '_' || c == '.'; });
}

Result<JwtVerifier::KeySet> JwtVerifier::parse_keys(const std::string& jwks_json) {
  const json jwks = json::parse(jwks_json, nullptr, false);
  if (jwks.is_discarded() || !jwks.is_object() || !jwks.contains("keys") || !jwks["keys"].is_array()) {
    return Error("JWKS: expected a JSON object with a \"keys\" list");
  }
  KeySet keys;
  for (std::size_t i = 0; i < jwks["keys"].size(); ++i) {
    const json& key = jwks["keys"][i];
    const std::string kid = key.is_object() ? text_member(key, "kid") : "";
    const std::string where = fmt::format("JWKS key {}{}", i, kid.empty() ? "" : " (kid " + kid + ")");
    if (!key.is_object()) return Error(where + ": not an object");
    if (key.contains("use") && key["use"] != "sig") continue;  // encryption keys
    const std::string type = text_member(key, "kty");
    Result<std::string> pem = Error("");
    std::string algorithm;
    if (type == "RSA") {
      pem = rsa_pem(key);
      algorithm = "RS256";
    } else if (type == "EC") {
      pem = ec_pem(key);
      algorithm = "ES256";
    } else {
      continue;  // other key types (oct, OKP) are not used for RS256 / ES256
    }
    if (!pem) return Error(where + ": " + pem.error().message);
    if (key.contains("alg") && key["alg"] != algorithm) continue;  // e.g. an RSA key for PS256
    if (!keys.emplace(kid, Key{algorithm, *pem}).second) return Error(where + ": kid listed twice");
  }
  if (keys.empty()) return Error("JWKS: no RS256 or ES256 signing key");
  return keys;
}

Result<std::shared_ptr<const JwtVerifier>> JwtVerifier::make(const std::string& jwks_json, JwtVerifierConfig config, std::string url) {
  if (config.issuer.empty()) return Error("JWT verification needs the issuer (--jwt-issuer)");
  if (config.audience.empty()) return Error("JWT verification needs the audience (--jwt-audience)");
  KeySet keys;
  HANZO_ASSIGN_OR_RETURN(keys, parse_keys(jwks_json));
  std::shared_ptr<JwtVerifier> verifier(new JwtVerifier(std::move(config)));
  verifier->keys_ = std::make_shared<const KeySet>(std::move(keys));
  verifier->url_ = std::move(url);
  verifier->last_fetch_s_ = verifier->url_.empty() ? 0 : unix_now();
  return std::shared_ptr<const JwtVerifier>(std::move(verifier));
}

Result<std::shared_ptr<const JwtVerifier>> JwtVerifier::create(const std::string& jwks_json, JwtVerifierConfig config) {
  return make(jwks_json, std::move(config), "");
}

Result<std::shared_ptr<const JwtVerifier>> JwtVerifier::load(const std::string& jwks_path, JwtVerifierConfig config) {
  std::ifstream in(jwks_path);
  if (!in) return Error(fmt::format("{}: cannot read the JWKS file", jwks_path));
  std::stringstream text;
  text << in.rdbuf();
  return with_context(create(text.str(), std::move(config)), jwks_path);
}

Result<std::shared_ptr<const JwtVerifier>> JwtVerifier::fetch(const std::string& jwks_url, JwtVerifierConfig config) {
  std::string body;
  HANZO_ASSIGN_OR_RETURN(body, http_get(jwks_url));
  return with_context(make(body, std::move(config), jwks_url), jwks_url);
}

Result<std::shared_ptr<const JwtVerifier>> JwtVerifier::open(const std::string& jwks_file_or_url, JwtVerifierConfig config) {
  if (jwks_file_or_url.starts_with("http://") || jwks_file_or_url.starts_with("https://")) return fetch(jwks_file_or_url, std::move(config));
  return load(jwks_file_or_url, std::move(config));
}

std::size_t JwtVerifier::key_count() const {
  std::lock_guard lock(mutex_);
  return keys_->size();
}

std::optional<JwtVerifier::Key> JwtVerifier::find_key(const std::string& kid) const {
  std::shared_ptr<const KeySet> keys;
  {
    std::lock_guard lock(mutex_);
    keys = keys_;
  }
  const auto lookup = [&kid](const KeySet& set) -> std::optional<Key> {
    auto key = set.find(kid);
    if (key == set.end() && kid.empty() && set.size() == 1) key = set.begin();
    if (key == set.end()) return std::nullopt;
    return key->second;
  };
  if (std::optional<Key> found = lookup(*keys); found || url_.empty()) return found;
  // Unknown kid with keys from a URL: the provider may have rotated them.
  {
    std::lock_guard lock(mutex_);
    const int64_t now = unix_now();
    if (now - last_fetch_s_ < config_.refetch_interval_s) return lookup(*keys_);
    last_fetch_s_ = now;
  }
  Result<std::string> body = http_get(url_);
  Result<KeySet> fetched = body ? parse_keys(*body) : Result<KeySet>(body.error());
  if (!fetched) {
    logger()->warn("JWKS {}: refetch failed, keeping the previous keys: {}", url_, fetched.error().message);
    return std::nullopt;
  }
  auto fresh = std::make_shared<const KeySet>(std::move(fetched).value());
  {
    std::lock_guard lock(mutex_);
    keys_ = fresh;
  }
  return lookup(*fresh);
}

ApiResult<Principal> JwtVerifier::verify(std::string_view token, int64_t now_s) const {
  if (!looks_like_jwt(token)) return unauthenticated("not a JWT (three base64url parts)");
  const Result<std::string> header_text = base64url_decode(token.substr(0, token.find('.')));
  const json header = header_text ? json::parse(*header_text, nullptr, false) : json();
  if (header.is_discarded() || !header.is_object() || !header.contains("alg") || !header["alg"].is_string()) {
    return unauthenticated("the header is not a JSON object with \"alg\"");
  }
  const std::string algorithm = header["alg"];
  if (algorithm != "RS256" && algorithm != "ES256") return unauthenticated(fmt::format("algorithm '{}' (RS256 or ES256 accepted)", algorithm));
  const std::string kid = text_member(header, "kid");
  const std::optional<Key> key = find_key(kid);
  if (!key) return unauthenticated(fmt::format("no key '{}' in the JWKS", kid));
  if (key->algorithm != algorithm) return unauthenticated(fmt::format("key '{}' is not an {} key", kid, algorithm));
  const std::string token_text(token);
  jwt_t* decoded = nullptr;
  if (jwt_decode(&decoded, token_text.c_str(), reinterpret_cast<const unsigned char*>(key->pem.data()),
                 static_cast<int>(key->pem.size())) != 0 || decoded == nullptr) {
    return unauthenticated("the signature does not verify");
  }
  std::unique_ptr<jwt_t, decltype(&jwt_free)> owner(decoded, &jwt_free);
  if (std::string(jwt_alg_str(jwt_get_alg(decoded))) != algorithm) return unauthenticated("the algorithm changed while verifying");
  char* grants = jwt_get_grants_json(decoded, nullptr);
  const json claims = grants != nullptr ? json::parse(grants, nullptr, false) : json();
  std::free(grants);
  if (!claims.is_object()) return unauthenticated("the claims are not a JSON object");

  if (text_member(claims, "iss") != config_.issuer) {
    return unauthenticated(fmt::format("issuer '{}' is not '{}'", text_member(claims, "iss"), config_.issuer));
  }
  bool audience_ok = false;
  if (claims.contains("aud") && claims["aud"].is_string()) audience_ok = claims["aud"] == config_.audience;
  if (claims.contains("aud") && claims["aud"].is_array()) {
    for (const json& audience : claims["aud"]) audience_ok = audience_ok || audience == config_.audience;
  }
  if (!audience_ok) return unauthenticated(fmt::format("audience {} is not '{}'", claims.contains("aud") ? claims["aud"].dump() : "missing", config_.audience));
  const int64_t now = now_s != 0 ? now_s : unix_now();
  const std::optional<int64_t> exp = time_claim(claims, "exp");
  if (!exp) return unauthenticated("no expiry (\"exp\")");
  if (now > *exp + config_.leeway_s) return unauthenticated(fmt::format("token expired at {}", utc(*exp)));
  for (const char* not_before : {"nbf", "iat"}) {
    if (const std::optional<int64_t> start = time_claim(claims, not_before); start && *start > now + config_.leeway_s) {
      return unauthenticated(fmt::format("token not valid before {} (\"{}\")", utc(*start), not_before));
    }
  }
  Principal principal;
  principal.name = text_member(claims, "sub", "jwt");
  if (!claims.contains(config_.organization_claim) || !claims[config_.organization_claim].is_string() ||
      claims[config_.organization_claim].get<std::string>().empty()) {
    return unauthenticated(fmt::format("no organization claim \"{}\"", config_.organization_claim));
  }
  principal.organization = claims[config_.organization_claim];
  std::vector<std::string> scopes;
  if (claims.contains(config_.scope_claim)) {
    const json& scope = claims[config_.scope_claim];
    if (scope.is_string()) {
      std::istringstream words(scope.get<std::string>());
      for (std::string word; words >> word;) scopes.push_back(word);
    } else if (scope.is_array()) {
      for (const json& word : scope) {
        if (word.is_string()) scopes.push_back(word);
      }
    }
  }
  for (const std::string& scope : scopes) {
    if (const std::optional<Permission> permission = permission_from_string(scope)) principal.permissions |= static_cast<uint32_t>(*permission);
  }
  return principal;
}

}  // namespace hanzo::fusion::service
