// Encryption at rest: exact round trips (empty, one byte, several 1 MiB chunks), and every kind
// of damage refused with its reason and nothing written: a changed byte anywhere, a changed key
// id, a file cut at any chunk boundary or inside a chunk, bytes appended, the wrong key; key
// rotation through several keys.
#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <random>
#include <sstream>

#include <gtest/gtest.h>

#include "hanzo/fusion/crypto/file_encryption.hpp"

namespace hanzo::fusion::crypto {
namespace {

std::string random_bytes(std::size_t size, uint32_t seed) {
  std::mt19937 rng(seed);
  std::string out(size, '\0');
  for (char& c : out) c = static_cast<char>(rng() & 0xff);
  return out;
}

TEST(FileEncryption, RoundTripsExactly) {
  const EncryptionKey key = EncryptionKey::generate();
  for (const std::size_t size : {std::size_t{0}, std::size_t{1}, std::size_t{1} << 20, (std::size_t{5} << 20) + 123}) {
    const std::string plaintext = random_bytes(size, static_cast<uint32_t>(size));
    const std::string ciphertext = encrypt(plaintext, key);
    EXPECT_TRUE(is_encrypted(ciphertext));
    // No 64-byte run of the plaintext shows in the ciphertext (shorter runs can match by chance).
    if (size >= 64) {
      EXPECT_EQ(ciphertext.find(plaintext.substr(0, 64)), std::string::npos);
    }
    auto decrypted = decrypt(ciphertext, {key});
    ASSERT_TRUE(decrypted.ok()) << decrypted.error().message;
    EXPECT_EQ(*decrypted, plaintext) << size;
  }
  // Two encryptions of the same data differ (fresh nonce per stream).
  EXPECT_NE(encrypt("same", key), encrypt("same", key));
}

TEST(FileEncryption, RefusesEveryDamageWithItsReason) {
  const EncryptionKey key = EncryptionKey::generate();
  const std::string plaintext = random_bytes((std::size_t{2} << 20) + 77, 7);  // 3 chunks
  const std::string ciphertext = encrypt(plaintext, key);
  const auto refused = [&](const std::string& data) {
    auto result = decrypt(data, {key});
    return result.ok() ? std::string("accepted") : result.error().message;
  };
  // A changed byte in every region: magic, key id, stream header, lengths, chunk data, tag.
  for (const std::size_t position : {std::size_t{2}, std::size_t{12}, std::size_t{30}, std::size_t{50}, std::size_t{1000},
                                     std::size_t{(1 << 20) + 100}, ciphertext.size() - 1}) {
    std::string changed = ciphertext;
    changed[position] = static_cast<char>(changed[position] ^ 0x40);
    EXPECT_NE(refused(changed), "accepted") << "byte " << position;
  }
  std::string other_id = ciphertext;
  other_id[9] = other_id[9] == 'a' ? 'b' : 'a';
  EXPECT_NE(refused(other_id).find("not among the keys given"), std::string::npos);
  // Cut anywhere: inside the header, at a chunk boundary, inside a chunk.
  const std::size_t first_chunk_end = 8 + 1 + 16 + 24 + 4 + (1 << 20) + 17;
  for (const std::size_t size : {std::size_t{5}, std::size_t{40}, first_chunk_end, first_chunk_end + 3, ciphertext.size() - 1}) {
    EXPECT_NE(refused(ciphertext.substr(0, size)).find("truncated"), std::string::npos) << size << ": " << refused(ciphertext.substr(0, size));
  }
  EXPECT_NE(refused(ciphertext + "x").find("after the final chunk"), std::string::npos);
  EXPECT_NE(refused(encrypt(plaintext, EncryptionKey::generate())).find("not among the keys given"), std::string::npos);
  EXPECT_NE(refused("plain text").find("bad magic"), std::string::npos);
  std::string future = ciphertext;
  future[6] = 2;
  EXPECT_NE(refused(future).find("version 2 is not supported"), std::string::npos);
}

TEST(FileEncryption, FilesKeysAndRotation) {
  const std::filesystem::path dir = std::filesystem::temp_directory_path() / ("hanzo_crypto_" + std::to_string(::getpid()));
  std::filesystem::remove_all(dir);
  std::filesystem::create_directories(dir);
  const EncryptionKey old_key = EncryptionKey::generate();
  const EncryptionKey new_key = EncryptionKey::generate();
  ASSERT_TRUE(old_key.save((dir / "old.key").string()).ok());
  auto loaded = EncryptionKey::load((dir / "old.key").string());
  ASSERT_TRUE(loaded.ok());
  EXPECT_EQ(loaded->to_hex(), old_key.to_hex());
  EXPECT_EQ(loaded->id(), old_key.id());
  EXPECT_EQ(std::filesystem::status(dir / "old.key").permissions() & std::filesystem::perms::group_read, std::filesystem::perms::none);
  EXPECT_FALSE(EncryptionKey::from_hex("abcd").ok());
  EXPECT_FALSE(EncryptionKey::from_hex(std::string(64, 'g')).ok());

  const std::string plain = (dir / "log.mcap").string();
  std::ofstream(plain, std::ios::binary) << random_bytes(3'000'000, 3);
  ASSERT_TRUE(encrypt_file(plain, (dir / "old.enc").string(), old_key).ok());
  ASSERT_TRUE(encrypt_file(plain, (dir / "new.enc").string(), new_key).ok());
  EXPECT_TRUE(is_encrypted_file((dir / "old.enc").string()));
  EXPECT_FALSE(is_encrypted_file(plain));
  EXPECT_EQ(encrypted_key_id((dir / "old.enc").string()).value(), old_key.id());
  // During the rotation both keys decrypt: each file names its own.
  for (const char* name : {"old.enc", "new.enc"}) {
    const std::string out = (dir / (std::string(name) + ".mcap")).string();
    auto used = decrypt_file((dir / name).string(), out, {new_key, old_key});
    ASSERT_TRUE(used.ok()) << used.error().message;
    std::ifstream a(plain, std::ios::binary), b(out, std::ios::binary);
    std::stringstream sa, sb;
    sa << a.rdbuf();
    sb << b.rdbuf();
    EXPECT_EQ(sa.str(), sb.str());
  }
  // A damaged file leaves nothing behind.
  std::filesystem::resize_file(dir / "old.enc", std::filesystem::file_size(dir / "old.enc") - 10);
  const std::string never = (dir / "never.mcap").string();
  auto refused = decrypt_file((dir / "old.enc").string(), never, {old_key});
  ASSERT_FALSE(refused.ok());
  EXPECT_NE(refused.error().message.find("truncated"), std::string::npos);
  EXPECT_FALSE(std::filesystem::exists(never));
  EXPECT_FALSE(std::filesystem::exists(never + ".partial"));
  std::filesystem::remove_all(dir);
}

}  // namespace
}  // namespace hanzo::fusion::crypto
