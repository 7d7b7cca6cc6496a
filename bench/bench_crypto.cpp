// Encryption at rest (libsodium XChaCha20-Poly1305 secretstream, 1 MiB chunks) against OpenSSL's
// AES-256-GCM over the same data in the same chunks (the common alternative; AES-NI on this
// machine): bytes per second, 64 MiB of log-like random data.

#include <algorithm>
#include <cstring>
#include <random>
#include <string>

#include <benchmark/benchmark.h>
#include <openssl/evp.h>

#include "hanzo/fusion/crypto/file_encryption.hpp"

namespace {

using namespace hanzo::fusion;

const std::string& data() {
  static const std::string bytes = [] {
    std::mt19937_64 rng(1);
    std::string out(64 << 20, '\0');
    for (std::size_t i = 0; i + 8 <= out.size(); i += 8) {
      const uint64_t value = rng();
      std::memcpy(out.data() + i, &value, 8);
    }
    return out;
  }();
  return bytes;
}

void BM_SecretstreamEncrypt(benchmark::State& state) {
  const crypto::EncryptionKey key = crypto::EncryptionKey::generate();
  for (auto _ : state) benchmark::DoNotOptimize(crypto::encrypt(data(), key));
  state.SetBytesProcessed(state.iterations() * static_cast<int64_t>(data().size()));
}
BENCHMARK(BM_SecretstreamEncrypt)->Unit(benchmark::kMillisecond);

void BM_SecretstreamDecrypt(benchmark::State& state) {
  const crypto::EncryptionKey key = crypto::EncryptionKey::generate();
  const std::string sealed = crypto::encrypt(data(), key);
  for (auto _ : state) benchmark::DoNotOptimize(crypto::decrypt(sealed, {key}));
  state.SetBytesProcessed(state.iterations() * static_cast<int64_t>(data().size()));
}
BENCHMARK(BM_SecretstreamDecrypt)->Unit(benchmark::kMillisecond);

// The peer: AES-256-GCM per 1 MiB chunk, a fresh 12-byte nonce each (counter), tag appended.
void BM_OpensslAes256GcmEncrypt(benchmark::State& state) {
  unsigned char key[32] = {1}, nonce[12] = {0};
  const std::string& plaintext = data();
  std::string out(plaintext.size() + (plaintext.size() >> 20) * 16 + 16, '\0');
  EVP_CIPHER_CTX* context = EVP_CIPHER_CTX_new();
  for (auto _ : state) {
    std::size_t written = 0;
    for (std::size_t offset = 0; offset < plaintext.size(); offset += 1 << 20) {
      ++nonce[0];
      EVP_EncryptInit_ex(context, EVP_aes_256_gcm(), nullptr, key, nonce);
      int length = 0;
      const int chunk = static_cast<int>(std::min<std::size_t>(1 << 20, plaintext.size() - offset));
      EVP_EncryptUpdate(context, reinterpret_cast<unsigned char*>(out.data() + written), &length,
                        reinterpret_cast<const unsigned char*>(plaintext.data() + offset), chunk);
      written += static_cast<std::size_t>(length);
      EVP_EncryptFinal_ex(context, reinterpret_cast<unsigned char*>(out.data() + written), &length);
      EVP_CIPHER_CTX_ctrl(context, EVP_CTRL_GCM_GET_TAG, 16, out.data() + written);
      written += 16;
    }
    benchmark::DoNotOptimize(out.data());
  }
  EVP_CIPHER_CTX_free(context);
  state.SetBytesProcessed(state.iterations() * static_cast<int64_t>(plaintext.size()));
}
BENCHMARK(BM_OpensslAes256GcmEncrypt)->Unit(benchmark::kMillisecond);

}  // namespace

BENCHMARK_MAIN();
