#pragma once
// Encryption at rest of sensor logs, maps and any other file: libsodium's
// crypto_secretstream_xchacha20poly1305 (XChaCha20-Poly1305, one authenticated chunk after the
// other, the last one tagged final).
//
// File layout (integers little-endian):
//   "HZENC" 0x00 0x01 0x0a   8 bytes: magic with format version 1
//   u8 key id length n, n bytes key id (the key's fingerprint, see EncryptionKey)
//   24 bytes secretstream header
//   chunks: u32 ciphertext length, ciphertext (plaintext of at most 1 MiB + 17 bytes)
// The first chunk authenticates the bytes before it (magic, version, key id) as associated
// data, so a changed key id is caught like a changed byte of data. Decryption refuses, with the
// chunk's number: a chunk that does not authenticate (tampered, or the wrong key), a file that
// ends before the final chunk (truncated), and bytes after it. Callers write the plaintext to a
// temporary file and keep it only when decryption completed (decrypt_file does), so a refused
// file is never half-read.
//
// Keys: 32 random bytes, stored as 64 hex digits (a key file, or the HANZO_ENCRYPTION_KEY
// environment variable). A key's id is the first 8 bytes of BLAKE2b(key) in hex: a file names
// the key that encrypted it without revealing it. Rotation: encrypt new data with the new key,
// give decryption every key still in use (old files name theirs), re-encrypt old files with
// `crypto encrypt` of their decryption, then retire the old key (docs/security.md).

#include <array>
#include <cstdint>
#include <string>
#include <string_view>
#include <vector>

#include "hanzo/fusion/core/result.hpp"

namespace hanzo::fusion::crypto {

class EncryptionKey {
 public:
  /// 32 fresh random bytes (libsodium's randombytes).
  static EncryptionKey generate();
  /// 64 hex digits, surrounding white space ignored.
  static Result<EncryptionKey> from_hex(std::string_view hex);
  /// A key file written by save() (or any file holding the 64 hex digits).
  static Result<EncryptionKey> load(const std::string& path);
  /// From $HANZO_ENCRYPTION_KEY; an error saying so when it is not set.
  static Result<EncryptionKey> from_environment();

  /// Writes the hex digits and a newline; the file is created readable by its owner only.
  Status save(const std::string& path) const;
  std::string to_hex() const;
  /// First 8 bytes of BLAKE2b-256 of the key, 16 hex digits.
  const std::string& id() const { return id_; }
  const std::array<uint8_t, 32>& bytes() const { return bytes_; }

 private:
  explicit EncryptionKey(const std::array<uint8_t, 32>& bytes);
  std::array<uint8_t, 32> bytes_{};
  std::string id_;
};

/// Whether the bytes (at least the first 8 of a file) start with the encrypted-file magic.
bool is_encrypted(std::string_view first_bytes);
bool is_encrypted_file(const std::string& path);

/// The id of the key that encrypted `path`, from its header.
Result<std::string> encrypted_key_id(const std::string& path);
/// The same from a file's first bytes (at least its header).
Result<std::string> encrypted_key_id_of(std::string_view first_bytes);

/// Encrypts `input` into `output` (written as output + ".partial", renamed when complete).
Status encrypt_file(const std::string& input, const std::string& output, const EncryptionKey& key);
/// Decrypts with the key among `keys` whose id the file names. Nothing is left at `output`
/// unless every chunk authenticated and the final one was reached. Returns the key id used.
Result<std::string> decrypt_file(const std::string& input, const std::string& output, const std::vector<EncryptionKey>& keys);

/// The keys of $HANZO_ENCRYPTION_KEY: one key, or several separated by commas (during a
/// rotation); empty when it is not set.
Result<std::vector<EncryptionKey>> keys_from_environment();

/// Decrypts `path` into an anonymous in-memory file (memfd_create: nothing reaches the disk) and
/// returns its descriptor, positioned at 0; the caller closes it. Readers that take a path read
/// it as "/proc/self/fd/<fd>". Refused as decrypt_file refuses.
Result<int> decrypt_to_memory_file(const std::string& path, const std::vector<EncryptionKey>& keys);

/// The same on memory (small files, tests).
std::string encrypt(std::string_view plaintext, const EncryptionKey& key);
Result<std::string> decrypt(std::string_view ciphertext, const std::vector<EncryptionKey>& keys);

/// The plaintext of the complete chunks among the first bytes of an encrypted file (each chunk
/// authenticated), for a peek at a file's start, such as a map's metadata, without fetching all
/// of it. Says nothing about the rest of the file: decrypt the whole file to trust all of it.
Result<std::string> decrypt_prefix(std::string_view first_bytes, const std::vector<EncryptionKey>& keys);

/// Bytes an encrypted file needs for its first `plaintext_bytes` bytes of plaintext.
inline constexpr uint64_t encrypted_prefix_bytes(uint64_t plaintext_bytes) {
  constexpr uint64_t kChunk = uint64_t{1} << 20, kPerChunk = 4 + 17, kHeader = 8 + 1 + 255 + 24;
  return kHeader + plaintext_bytes + ((plaintext_bytes + kChunk - 1) / kChunk + 1) * kPerChunk;
}

}  // namespace hanzo::fusion::crypto
