// Fuzz target: the encrypted-file reader (crypto/file_encryption.hpp) on any bytes. Input that
// is not an intact encrypted file must be refused without a crash; what decrypts must be what
// was encrypted (the seeds are real encrypted files of the fixed key below, so mutations reach
// every part of the format), and any input, encrypted with that key, must decrypt to itself.

#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <string>

#include "hanzo/fusion/crypto/file_encryption.hpp"

namespace {

const hanzo::fusion::crypto::EncryptionKey& key() {
  static const auto fixed =
      hanzo::fusion::crypto::EncryptionKey::from_hex("000102030405060708090a0b0c0d0e0f101112131415161718191a1b1c1d1e1f").value();
  return fixed;
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using namespace hanzo::fusion;
  const std::string bytes(reinterpret_cast<const char*>(data), size);
  const auto whole = crypto::decrypt(bytes, {key()});  // refused or decrypted, never a crash
  // The prefix reader (map metadata peeks) gives a prefix of what the whole file decrypts to.
  const auto prefix = crypto::decrypt_prefix(bytes, {key()});
  if (whole && prefix && whole->compare(0, prefix->size(), *prefix) != 0) std::abort();
  auto round_trip = crypto::decrypt(crypto::encrypt(bytes, key()), {key()});
  if (!round_trip || *round_trip != bytes) std::abort();
  return 0;
}
