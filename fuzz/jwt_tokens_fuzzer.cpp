// Fuzz target: bearer JWTs and JWKS documents (service/jwt_verifier.hpp), the identity input of
// every request. The first byte picks what the rest is: a token verified against a fixed JWKS,
// or a JWKS document. Any input must be accepted or refused without a crash; no token without a
// signature of the fixed key may be accepted (the fuzzer cannot forge one).

#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <string>

#include "hanzo/fusion/service/jwt_verifier.hpp"

namespace {

// An RSA-2048 public key made for this target (its private key was discarded: no input can
// carry a valid signature).
constexpr const char* kJwks =
    R"({"keys":[{"kty":"RSA","kid":"k1","use":"sig","alg":"RS256","e":"AQAB","n":"yPzQuCbe84EZAw0dhgQrTyoku1TZ2frqjak6w9XTfkVD8NAmrtf-YAsFfJnVpzPBXEikCWuR2119c-ZwiiROtyw6fbN1uLUuipx0aVs3oKr7GQqCFSOk0VvsTryLjHVXhVHTWxRyMCnKUo65PZIbydgvpKXwZAPdZK-dL0pDQxUp6HUrQdbAoMJUFL2AP3UG7cs6-M6LmbZylWsZ0tDXVWG_LL16qp-K1INeRuGPlicKfwYSTS0DM2Jk_BQgqCM5Bj7CvYEDhO8J_wzlPwc3kyTGvBlbEzB5zyjaqQYfSgYTUbjqnb_cjsuazXBnlL5p0VsT0WFro8B61VEaZNKQnw"}]})";

const hanzo::fusion::service::JwtVerifier& verifier() {
  static const auto made = hanzo::fusion::service::JwtVerifier::create(kJwks, {"https://login.example.com/", "hanzo-fusion"}).value();
  return *made;
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using namespace hanzo::fusion::service;
  if (size == 0) return 0;
  const std::string text(reinterpret_cast<const char*>(data) + 1, size - 1);
  if (data[0] % 2 == 0) {
    if (verifier().verify(text, 1800000000).ok()) std::abort();  // forged
  } else {
    (void)JwtVerifier::create(text, {"https://login.example.com/", "hanzo-fusion"});
  }
  return 0;
}
