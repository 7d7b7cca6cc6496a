// Bearer JWTs of an OIDC provider: tokens signed here with fresh RSA-2048 and P-256 keys (libjwt,
// OpenSSL), published as a JWKS, verified by JwtVerifier and through authenticate_bearer; every
// refusal is a 401 with its reason, a missing scope a 403.
#include <chrono>
#include <memory>
#include <mutex>
#include <thread>
#include <string>

#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <fmt/format.h>
#include <jwt.h>
#include <nlohmann/json.hpp>
#include <openssl/bn.h>
#include <openssl/core_names.h>
#include <openssl/evp.h>
#include <openssl/pem.h>

#include "hanzo/fusion/core/base64.hpp"
#include "hanzo/fusion/service/auth.hpp"
#include "hanzo/fusion/service/jwt_verifier.hpp"

// Last: httplib pulls in <resolv.h>, whose `_res` macro breaks headers included after it.
#include <httplib.h>

namespace hanzo::fusion::service {
namespace {

using ::testing::HasSubstr;
using json = nlohmann::json;

constexpr int64_t kNow = 1800000000;  // 2027-01-15

std::string base64url(const std::string& bytes) {
  std::string text = base64_encode(std::span<const uint8_t>(reinterpret_cast<const uint8_t*>(bytes.data()), bytes.size()));
  for (char& c : text) {
    if (c == '+') c = '-';
    else if (c == '/') c = '_';
  }
  while (!text.empty() && text.back() == '=') text.pop_back();
  return text;
}

// A key pair: the private key as PEM (to sign) and the public key as a JWK.
struct SigningKey {
  std::string private_pem;
  json jwk;
  jwt_alg_t algorithm;
};

SigningKey make_key(bool rsa, const std::string& kid) {
  EVP_PKEY* key = rsa ? EVP_PKEY_Q_keygen(nullptr, nullptr, "RSA", static_cast<size_t>(2048))
                      : EVP_PKEY_Q_keygen(nullptr, nullptr, "EC", "P-256");
  BIO* bio = BIO_new(BIO_s_mem());
  PEM_write_bio_PrivateKey(bio, key, nullptr, nullptr, 0, nullptr, nullptr);
  char* data = nullptr;
  const long size = BIO_get_mem_data(bio, &data);
  SigningKey out{std::string(data, static_cast<size_t>(size)), json::object(), rsa ? JWT_ALG_RS256 : JWT_ALG_ES256};
  BIO_free(bio);
  const auto bignum = [&](const char* name) {
    BIGNUM* number = nullptr;
    EVP_PKEY_get_bn_param(key, name, &number);
    std::string bytes(static_cast<size_t>(BN_num_bytes(number)), '\0');
    BN_bn2bin(number, reinterpret_cast<unsigned char*>(bytes.data()));
    BN_free(number);
    return base64url(bytes);
  };
  if (rsa) {
    out.jwk = {{"kty", "RSA"}, {"kid", kid}, {"use", "sig"}, {"alg", "RS256"}, {"n", bignum(OSSL_PKEY_PARAM_RSA_N)}, {"e", bignum(OSSL_PKEY_PARAM_RSA_E)}};
  } else {
    unsigned char point[65];
    size_t length = 0;
    EVP_PKEY_get_octet_string_param(key, OSSL_PKEY_PARAM_PUB_KEY, point, sizeof(point), &length);
    out.jwk = {{"kty", "EC"}, {"kid", kid}, {"crv", "P-256"},
               {"x", base64url(std::string(reinterpret_cast<char*>(point + 1), 32))},
               {"y", base64url(std::string(reinterpret_cast<char*>(point + 33), 32))}};
  }
  EVP_PKEY_free(key);
  return out;
}

json claims(int64_t expires = kNow + 600) {
  return {{"iss", "https://login.example.com/"}, {"aud", "hanzo-fusion"}, {"sub", "robot-7"}, {"org", "acme"},
          {"scope", "openid fusion:session:write fusion:session:read"}, {"iat", kNow - 10}, {"exp", expires}};
}

std::string sign(const SigningKey& key, const json& payload, const std::string& kid) {
  jwt_t* token = nullptr;
  jwt_new(&token);
  jwt_add_grants_json(token, payload.dump().c_str());
  if (!kid.empty()) jwt_add_header(token, "kid", kid.c_str());
  jwt_set_alg(token, key.algorithm, reinterpret_cast<const unsigned char*>(key.private_pem.data()), static_cast<int>(key.private_pem.size()));
  char* encoded = jwt_encode_str(token);
  std::string out = encoded != nullptr ? encoded : "";
  std::free(encoded);
  jwt_free(token);
  return out;
}

class JwtVerifierTest : public ::testing::Test {
 protected:
  void SetUp() override {
    rsa_ = make_key(true, "rsa-1");
    ec_ = make_key(false, "ec-1");
    json jwks = {{"keys", {rsa_.jwk, ec_.jwk, {{"kty", "oct"}, {"kid", "hmac"}, {"k", "c2VjcmV0"}}}}};
    auto verifier = JwtVerifier::create(jwks.dump(), {"https://login.example.com/", "hanzo-fusion"});
    ASSERT_TRUE(verifier.ok()) << verifier.error().message;
    verifier_ = *verifier;
  }
  std::string refusal(const std::string& token) const {
    auto result = verifier_->verify(token, kNow);
    if (result) return "accepted";
    EXPECT_EQ(result.error().code, ErrorCode::kUnauthenticated);
    return result.error().message;
  }
  SigningKey rsa_, ec_;
  std::shared_ptr<const JwtVerifier> verifier_;
};

TEST_F(JwtVerifierTest, AcceptsRs256AndEs256AndMapsOrganizationAndScopes) {
  EXPECT_EQ(verifier_->key_count(), 2U);  // the HMAC key is not a signing key here
  for (const SigningKey* key : {&rsa_, &ec_}) {
    const std::string token = sign(*key, claims(), key->jwk["kid"]);
    auto principal = verifier_->verify(token, kNow);
    ASSERT_TRUE(principal.ok()) << principal.error().message;
    EXPECT_EQ(principal->name, "robot-7");
    EXPECT_EQ(principal->organization, "acme");
    EXPECT_TRUE(principal->has(Permission::kSessionWrite));
    EXPECT_TRUE(principal->has(Permission::kSessionRead));
    EXPECT_FALSE(principal->has(Permission::kMapWrite));
  }
  json listed = claims();
  listed["aud"] = {"other", "hanzo-fusion"};
  listed["scope"] = {"fusion:map:read"};
  auto principal = verifier_->verify(sign(rsa_, listed, "rsa-1"), kNow);
  ASSERT_TRUE(principal.ok());
  EXPECT_TRUE(principal->has(Permission::kMapRead));
  EXPECT_FALSE(principal->has(Permission::kSessionRead));
  // Within the leeway an expired token still passes; beyond it, not.
  EXPECT_EQ(refusal(sign(rsa_, claims(kNow - 30), "rsa-1")), "accepted");
}

TEST_F(JwtVerifierTest, RefusesEachBadTokenWithItsReason) {
  EXPECT_THAT(refusal(sign(rsa_, claims(kNow - 3600), "rsa-1")), HasSubstr("token expired at 2027-01-15T07:00:00Z"));
  json wrong = claims();
  wrong["aud"] = "someone-else";
  EXPECT_THAT(refusal(sign(rsa_, wrong, "rsa-1")), HasSubstr("audience \"someone-else\" is not 'hanzo-fusion'"));
  wrong = claims();
  wrong["iss"] = "https://evil.example.com/";
  EXPECT_THAT(refusal(sign(rsa_, wrong, "rsa-1")), HasSubstr("issuer 'https://evil.example.com/' is not"));
  wrong = claims();
  wrong["nbf"] = kNow + 3600;
  EXPECT_THAT(refusal(sign(rsa_, wrong, "rsa-1")), HasSubstr("not valid before"));
  wrong = claims();
  wrong.erase("org");
  EXPECT_THAT(refusal(sign(rsa_, wrong, "rsa-1")), HasSubstr("no organization claim \"org\""));
  wrong = claims();
  wrong.erase("exp");
  EXPECT_THAT(refusal(sign(rsa_, wrong, "rsa-1")), HasSubstr("no expiry"));
  // Signed by another key that claims a known kid.
  const SigningKey impostor = make_key(true, "rsa-1");
  EXPECT_THAT(refusal(sign(impostor, claims(), "rsa-1")), HasSubstr("signature does not verify"));
  EXPECT_THAT(refusal(sign(rsa_, claims(), "rsa-9")), HasSubstr("no key 'rsa-9'"));
  EXPECT_THAT(refusal(sign(ec_, claims(), "rsa-1")), HasSubstr("is not an ES256 key"));
  // The classic confusions: "none", and HS256 keyed with the RSA public key.
  jwt_t* token = nullptr;
  jwt_new(&token);
  jwt_add_grants_json(token, claims().dump().c_str());
  jwt_add_header(token, "kid", "rsa-1");
  jwt_set_alg(token, JWT_ALG_NONE, nullptr, 0);
  char* unsigned_token = jwt_encode_str(token);
  EXPECT_THAT(refusal(unsigned_token), HasSubstr("'none'"));
  std::free(unsigned_token);
  const std::string secret = rsa_.jwk["n"];
  jwt_set_alg(token, JWT_ALG_HS256, reinterpret_cast<const unsigned char*>(secret.data()), static_cast<int>(secret.size()));
  char* hmac_token = jwt_encode_str(token);
  EXPECT_THAT(refusal(hmac_token), HasSubstr("algorithm 'HS256'"));
  std::free(hmac_token);
  jwt_free(token);
  // A changed payload.
  std::string changed = sign(rsa_, claims(), "rsa-1");
  const size_t dot = changed.find('.');
  changed[dot + 5] = changed[dot + 5] == 'A' ? 'B' : 'A';
  EXPECT_NE(refusal(changed), "accepted");
  EXPECT_THAT(refusal("not-a-jwt"), HasSubstr("not a JWT"));
  // A header whose kid is not a string, before any signature is checked: refused, never thrown.
  // base64url of {"alg":"RS256","kid":5} and of {}
  const std::string odd_header = "eyJhbGciOiJSUzI1NiIsImtpZCI6NX0.e30.c2ln";
  EXPECT_THAT(refusal(odd_header), HasSubstr("no key ''"));
  // Claims of the wrong type in a validly signed token.
  wrong = claims();
  wrong["iss"] = 7;
  EXPECT_THAT(refusal(sign(rsa_, wrong, "rsa-1")), HasSubstr("issuer '' is not"));
  wrong = claims();
  wrong["exp"] = 1e300;  // beyond any time: clamped to the year 9999
  wrong["sub"] = false;
  EXPECT_EQ(refusal(sign(rsa_, wrong, "rsa-1")), "accepted");
}

TEST_F(JwtVerifierTest, BearerHeadersReachTheVerifierAndScopesDecide) {
  auto store = TokenStore::parse_inline("static-token-0123456789=acme:fusion:session:read");
  ASSERT_TRUE(store.ok()) << store.error().message;
  store->set_jwt_verifier(verifier_);
  // Static tokens still work.
  auto fixed = authenticate_bearer(&*store, "Bearer static-token-0123456789", "Authorization");
  ASSERT_TRUE(fixed.ok());
  EXPECT_EQ(fixed->organization, "acme");
  // An expired JWT: 401 with the reason.
  json expired = claims(1000);
  auto refused = authenticate_bearer(&*store, "Bearer " + sign(ec_, expired, "ec-1"), "Authorization");
  ASSERT_FALSE(refused.ok());
  EXPECT_EQ(refused.error().code, ErrorCode::kUnauthenticated);
  EXPECT_THAT(refused.error().message, HasSubstr("expired"));
  // A valid one without the map scope: authenticated, then 403 for maps and for other organizations.
  json valid = claims(std::numeric_limits<int32_t>::max());
  valid["iat"] = 1000;
  auto principal = authenticate_bearer(&*store, "Bearer " + sign(ec_, valid, "ec-1"), "Authorization");
  ASSERT_TRUE(principal.ok()) << principal.error().message;
  EXPECT_TRUE(authorize(principal.value(), Permission::kSessionWrite, "acme").ok());
  const ApiStatus maps = authorize(principal.value(), Permission::kMapWrite, "acme");
  ASSERT_FALSE(maps.ok());
  EXPECT_EQ(maps.error().code, ErrorCode::kPermissionDenied);
  EXPECT_EQ(authorize(principal.value(), Permission::kSessionRead, "globex").error().code, ErrorCode::kPermissionDenied);
}

// Keys from the provider's jwks_uri (a local HTTP server): fetched at start, fetched again when a
// token names a kid the keys lack (the provider rotated its keys).
TEST(JwtVerifier, FetchesKeysFromAUrlAndRefetchesWhenTheProviderRotates) {
  const SigningKey first = make_key(true, "rsa-1");
  const SigningKey second = make_key(false, "ec-2");
  std::mutex mutex;
  std::string served = json{{"keys", {first.jwk}}}.dump();
  httplib::Server server;
  server.Get("/jwks.json", [&](const httplib::Request&, httplib::Response& response) {
    std::lock_guard lock(mutex);
    response.set_content(served, "application/json");
  });
  const int port = server.bind_to_any_port("127.0.0.1");
  std::thread thread([&] { server.listen_after_bind(); });
  while (!server.is_running()) std::this_thread::sleep_for(std::chrono::milliseconds(5));
  const std::string url = fmt::format("http://127.0.0.1:{}/jwks.json", port);
  JwtVerifierConfig config{"https://login.example.com/", "hanzo-fusion"};
  config.refetch_interval_s = 0;
  auto verifier = JwtVerifier::open(url, config);
  ASSERT_TRUE(verifier.ok()) << verifier.error().message;
  EXPECT_TRUE((*verifier)->verify(sign(first, claims(), "rsa-1"), kNow).ok());
  EXPECT_FALSE((*verifier)->verify(sign(second, claims(), "ec-2"), kNow).ok());
  {
    std::lock_guard lock(mutex);
    served = json{{"keys", {second.jwk}}}.dump();
  }
  auto rotated = (*verifier)->verify(sign(second, claims(), "ec-2"), kNow);
  EXPECT_TRUE(rotated.ok()) << rotated.error().message;
  // The provider's answer gone: the refetch fails, the keys it had stay.
  server.stop();
  thread.join();
  EXPECT_TRUE((*verifier)->verify(sign(second, claims(), "ec-2"), kNow).ok());
  EXPECT_THAT((*verifier)->verify(sign(first, claims(), "rsa-9"), kNow).error().message, HasSubstr("no key 'rsa-9'"));
  auto unreachable = JwtVerifier::open(url, config);
  ASSERT_FALSE(unreachable.ok());
  EXPECT_THAT(unreachable.error().message, HasSubstr(url));
}

TEST(JwtVerifier, RefusesBadKeySets) {
  const JwtVerifierConfig config{"https://login.example.com/", "hanzo-fusion"};
  EXPECT_THAT(JwtVerifier::create("{", config).error().message, HasSubstr("\"keys\" list"));
  EXPECT_THAT(JwtVerifier::create(R"({"keys": []})", config).error().message, HasSubstr("no RS256 or ES256"));
  EXPECT_THAT(JwtVerifier::create(R"({"keys": [{"kty": "RSA", "kid": "short", "n": "AQAB", "e": "AQAB"}]})", config).error().message,
              HasSubstr("kid short): an RSA key of 17 bits"));
  EXPECT_THAT(JwtVerifier::create(R"({"keys": [{"kty": "EC", "crv": "P-384", "x": "AA", "y": "AA"}]})", config).error().message,
              HasSubstr("P-384"));
  EXPECT_THAT(JwtVerifier::create(R"({"keys": []})", {"", "aud"}).error().message, HasSubstr("issuer"));
  // Members of the wrong type (found by libFuzzer: json::value threw): refused, never thrown.
  EXPECT_THAT(JwtVerifier::create(R"({"keys": [{"kty": 1}]})", config).error().message, HasSubstr("no RS256 or ES256"));
  EXPECT_THAT(JwtVerifier::create(R"({"keys": [{"kty": "EC", "kid": [], "crv": 256, "x": "AA", "y": "AA"}]})", config).error().message,
              HasSubstr("ES256 needs P-256"));
  EXPECT_THAT(JwtVerifier::load("/nonexistent/jwks.json", config).error().message, HasSubstr("/nonexistent/jwks.json"));
}

}  // namespace
}  // namespace hanzo::fusion::service
