#include "hanzo/fusion/crypto/file_encryption.hpp"

#include <sys/mman.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <cctype>
#include <cerrno>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <mutex>
#include <sstream>

#include <fmt/format.h>
#include <sodium.h>

#include "hanzo/fusion/core/files.hpp"

namespace hanzo::fusion::crypto {
namespace {

constexpr std::string_view kMagic{"HZENC\0\x01\n", 8};
constexpr std::size_t kChunkSize = 1 << 20;  // plaintext bytes per chunk
constexpr std::size_t kHeaderBytes = crypto_secretstream_xchacha20poly1305_HEADERBYTES;
constexpr std::size_t kOverhead = crypto_secretstream_xchacha20poly1305_ABYTES;

void initialize_sodium() {
  static std::once_flag once;
  std::call_once(once, [] {
    if (sodium_init() < 0) std::abort();  // libsodium cannot work without its RNG: nothing else to do
  });
}

std::string hex(const uint8_t* data, std::size_t size) {
  std::string out(2 * size + 1, '\0');
  sodium_bin2hex(out.data(), out.size(), data, size);
  out.pop_back();
  return out;
}

void put_u32(std::string& out, uint32_t value) {
  for (int i = 0; i < 4; ++i) out.push_back(static_cast<char>((value >> (8 * i)) & 0xff));
}

// Reads exactly n bytes; false at a clean end of input (nothing read), an error when cut short.
Result<bool> read_exact(std::istream& in, char* data, std::size_t n, const std::string& what) {
  in.read(data, static_cast<std::streamsize>(n));
  const auto got = static_cast<std::size_t>(in.gcount());
  if (got == n) return true;
  if (got == 0) return false;
  return Error(fmt::format("truncated: {} cut after {} of {} bytes", what, got, n));
}

// The bytes before the stream header: magic, key id length, key id.
std::string preamble(const std::string& key_id) {
  std::string out(kMagic);
  out.push_back(static_cast<char>(key_id.size()));
  out += key_id;
  return out;
}

Status encrypt_stream(std::istream& in, std::ostream& out, const EncryptionKey& key) {
  initialize_sodium();
  const std::string associated = preamble(key.id());
  crypto_secretstream_xchacha20poly1305_state state;
  std::array<unsigned char, kHeaderBytes> header{};
  crypto_secretstream_xchacha20poly1305_init_push(&state, header.data(), key.bytes().data());
  out.write(associated.data(), static_cast<std::streamsize>(associated.size()));
  out.write(reinterpret_cast<const char*>(header.data()), static_cast<std::streamsize>(header.size()));
  // Buffers reused by the thread's next call (fresh 1 MiB allocations are page faults each time).
  thread_local std::string plaintext(kChunkSize, '\0'), next(kChunkSize, '\0'), ciphertext(kChunkSize + kOverhead, '\0');
  in.read(plaintext.data(), static_cast<std::streamsize>(kChunkSize));
  std::size_t size = static_cast<std::size_t>(in.gcount());
  bool first = true;
  while (true) {
    // Look one chunk ahead: the last chunk (possibly empty) carries the final tag.
    in.read(next.data(), static_cast<std::streamsize>(kChunkSize));
    const auto next_size = static_cast<std::size_t>(in.gcount());
    const bool last = next_size == 0;
    unsigned long long written = 0;
    crypto_secretstream_xchacha20poly1305_push(
        &state, reinterpret_cast<unsigned char*>(ciphertext.data()), &written, reinterpret_cast<const unsigned char*>(plaintext.data()), size,
        first ? reinterpret_cast<const unsigned char*>(associated.data()) : nullptr, first ? associated.size() : 0,
        last ? crypto_secretstream_xchacha20poly1305_TAG_FINAL : crypto_secretstream_xchacha20poly1305_TAG_MESSAGE);
    std::string length;
    put_u32(length, static_cast<uint32_t>(written));
    out.write(length.data(), 4);
    out.write(ciphertext.data(), static_cast<std::streamsize>(written));
    first = false;
    if (last) break;
    std::swap(plaintext, next);
    size = next_size;
  }
  sodium_memzero(plaintext.data(), plaintext.size());
  sodium_memzero(next.data(), next.size());
  if (in.bad()) return Error("reading the input failed");
  if (!out) return Error("writing the encrypted output failed");
  return ok_status();
}

Result<std::string> read_key_id(std::istream& in) {
  std::string magic(kMagic.size(), '\0');
  Result<bool> got = read_exact(in, magic.data(), magic.size(), "the header");
  if (!got) return got.error();
  if (!*got || magic.compare(0, 6, kMagic.substr(0, 6)) != 0) return Error("not an encrypted hanzo-fusion file (bad magic)");
  if (magic != kMagic) return Error(fmt::format("encrypted file format version {} is not supported (this build reads version 1)",
                                                static_cast<int>(static_cast<unsigned char>(magic[6]))));
  char length = 0;
  HANZO_ASSIGN_OR_RETURN(got, read_exact(in, &length, 1, "the header"));
  if (!*got) return Error("truncated: the header ends before the key id");
  std::string key_id(static_cast<unsigned char>(length), '\0');
  if (!key_id.empty()) {
    HANZO_ASSIGN_OR_RETURN(got, read_exact(in, key_id.data(), key_id.size(), "the key id"));
    if (!*got) return Error("truncated: the header ends before the key id");
  }
  return key_id;
}

// With `prefix_only`, `in` holds only the first bytes of a file: decryption stops without an
// error where they end (after the last complete chunk) instead of calling that truncation.
Result<std::string> decrypt_stream(std::istream& in, std::ostream& out, const std::vector<EncryptionKey>& keys, bool prefix_only = false) {
  initialize_sodium();
  std::string key_id;
  HANZO_ASSIGN_OR_RETURN(key_id, read_key_id(in));
  const auto key = std::find_if(keys.begin(), keys.end(), [&](const EncryptionKey& k) { return k.id() == key_id; });
  if (key == keys.end()) {
    std::string given;
    for (const EncryptionKey& k : keys) given += (given.empty() ? "" : ", ") + k.id();
    return Error(fmt::format("encrypted with key {}, which is not among the keys given ({})", key_id, given.empty() ? "none" : given));
  }
  const std::string associated = preamble(key_id);
  std::array<unsigned char, kHeaderBytes> header{};
  Result<bool> got = read_exact(in, reinterpret_cast<char*>(header.data()), header.size(), "the stream header");
  if (!got) return got.error();
  if (!*got) return Error("truncated: no stream header");
  crypto_secretstream_xchacha20poly1305_state state;
  if (crypto_secretstream_xchacha20poly1305_init_pull(&state, header.data(), key->bytes().data()) != 0) {
    return Error("the stream header is invalid");
  }
  thread_local std::string ciphertext, plaintext(kChunkSize, '\0');
  for (uint64_t chunk = 0;; ++chunk) {
    std::array<char, 4> length_bytes{};
    got = read_exact(in, length_bytes.data(), 4, fmt::format("chunk {}'s length", chunk));
    if (prefix_only && (!got || !*got)) break;
    if (!got) return got.error();
    if (!*got) return Error(fmt::format("truncated: the file ends after chunk {} without the final chunk", chunk));
    uint32_t length = 0;
    for (int i = 0; i < 4; ++i) length |= static_cast<uint32_t>(static_cast<unsigned char>(length_bytes[static_cast<std::size_t>(i)])) << (8 * i);
    if (length < kOverhead || length > kChunkSize + kOverhead) return Error(fmt::format("chunk {}: invalid length {}", chunk, length));
    ciphertext.resize(length);
    got = read_exact(in, ciphertext.data(), length, fmt::format("chunk {}", chunk));
    if (prefix_only && (!got || !*got)) break;
    if (!got) return got.error();
    if (!*got) return Error(fmt::format("truncated: the file ends before chunk {}", chunk));
    unsigned long long size = 0;
    unsigned char tag = 0;
    if (crypto_secretstream_xchacha20poly1305_pull(&state, reinterpret_cast<unsigned char*>(plaintext.data()), &size, &tag,
                                                   reinterpret_cast<const unsigned char*>(ciphertext.data()), length,
                                                   chunk == 0 ? reinterpret_cast<const unsigned char*>(associated.data()) : nullptr,
                                                   chunk == 0 ? associated.size() : 0) != 0) {
      return Error(fmt::format("chunk {} does not authenticate: the file was changed, or key {} is not the one it was encrypted with", chunk,
                               key_id));
    }
    out.write(plaintext.data(), static_cast<std::streamsize>(size));
    if (tag == crypto_secretstream_xchacha20poly1305_TAG_FINAL) break;
  }
  sodium_memzero(plaintext.data(), plaintext.size());
  if (!prefix_only && in.peek() != std::char_traits<char>::eof()) return Error("bytes after the final chunk: the file was changed");
  if (!out) return Error("writing the decrypted output failed");
  return key_id;
}

// Runs `write` into path + ".partial" and renames it to path when it succeeded; removes it otherwise.
template <typename Write>
auto write_atomically(const std::string& path, Write write) -> decltype(write(std::declval<std::ofstream&>())) {
  const std::string partial = path + ".partial";
  decltype(write(std::declval<std::ofstream&>())) result = Error("not run");
  {
    std::ofstream out(partial, std::ios::binary | std::ios::trunc);
    if (!out) return Error(fmt::format("cannot write {}", partial));
    ::chmod(partial.c_str(), S_IRUSR | S_IWUSR);
    result = write(out);
    out.close();
    if (result && !out) result = Error(fmt::format("writing {} failed", partial));
  }
  if (Status committed = commit_partial_file(partial, path, result ? ok_status() : Status(result.error())); !committed) return committed.error();
  return result;
}

}  // namespace

EncryptionKey::EncryptionKey(const std::array<uint8_t, 32>& bytes) : bytes_(bytes) {
  initialize_sodium();
  std::array<uint8_t, 32> digest{};
  crypto_generichash(digest.data(), digest.size(), bytes_.data(), bytes_.size(), nullptr, 0);
  id_ = hex(digest.data(), 8);
}

EncryptionKey EncryptionKey::generate() {
  initialize_sodium();
  std::array<uint8_t, 32> bytes{};
  randombytes_buf(bytes.data(), bytes.size());
  return EncryptionKey(bytes);
}

Result<EncryptionKey> EncryptionKey::from_hex(std::string_view text) {
  initialize_sodium();
  while (!text.empty() && std::isspace(static_cast<unsigned char>(text.front()))) text.remove_prefix(1);
  while (!text.empty() && std::isspace(static_cast<unsigned char>(text.back()))) text.remove_suffix(1);
  std::array<uint8_t, 32> bytes{};
  std::size_t size = 0;
  const char* end = nullptr;
  if (text.size() != 64 || sodium_hex2bin(bytes.data(), bytes.size(), text.data(), text.size(), nullptr, &size, &end) != 0 || size != 32) {
    return Error(fmt::format("an encryption key is 64 hex digits (32 bytes), got {} characters", text.size()));
  }
  return EncryptionKey(bytes);
}

Result<EncryptionKey> EncryptionKey::load(const std::string& path) {
  std::ifstream in(path);
  if (!in) return Error(fmt::format("{}: cannot read the key file ({})", path, std::strerror(errno)));
  std::stringstream text;
  text << in.rdbuf();
  return with_context(from_hex(text.str()), path);
}

Result<EncryptionKey> EncryptionKey::from_environment() {
  const char* value = std::getenv("HANZO_ENCRYPTION_KEY");
  if (value == nullptr || *value == '\0') return Error("no key given and HANZO_ENCRYPTION_KEY is not set");
  return with_context(from_hex(value), "HANZO_ENCRYPTION_KEY");
}

Status EncryptionKey::save(const std::string& path) const {
  Result<bool> saved = write_atomically(path, [this](std::ofstream& out) -> Result<bool> {
    out << to_hex() << '\n';
    return true;
  });
  if (!saved) return saved.error();
  return ok_status();
}

std::string EncryptionKey::to_hex() const { return hex(bytes_.data(), bytes_.size()); }

bool is_encrypted(std::string_view first_bytes) { return first_bytes.substr(0, 6) == kMagic.substr(0, 6); }

bool is_encrypted_file(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  std::string first(kMagic.size(), '\0');
  in.read(first.data(), static_cast<std::streamsize>(first.size()));
  return static_cast<std::size_t>(in.gcount()) == first.size() && is_encrypted(first);
}

Result<std::string> encrypted_key_id(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) return Error(fmt::format("{}: cannot read", path));
  return with_context(read_key_id(in), path);
}

Result<std::string> encrypted_key_id_of(std::string_view first_bytes) {
  std::istringstream in{std::string(first_bytes.substr(0, std::min<std::size_t>(first_bytes.size(), 8 + 1 + 255)))};
  return read_key_id(in);
}

Status encrypt_file(const std::string& input, const std::string& output, const EncryptionKey& key) {
  std::ifstream in(input, std::ios::binary);
  if (!in) return Error(fmt::format("{}: cannot read", input));
  Result<bool> done = write_atomically(output, [&](std::ofstream& out) -> Result<bool> {
    HANZO_RETURN_IF_ERROR(encrypt_stream(in, out, key));
    return true;
  });
  if (!done) return Error(fmt::format("{}: {}", output, done.error().message));
  return ok_status();
}

Result<std::string> decrypt_file(const std::string& input, const std::string& output, const std::vector<EncryptionKey>& keys) {
  std::ifstream in(input, std::ios::binary);
  if (!in) return Error(fmt::format("{}: cannot read", input));
  return with_context(write_atomically(output, [&](std::ofstream& out) { return decrypt_stream(in, out, keys); }), input);
}

Result<std::vector<EncryptionKey>> keys_from_environment() {
  std::vector<EncryptionKey> keys;
  const char* value = std::getenv("HANZO_ENCRYPTION_KEY");
  if (value == nullptr) return keys;
  std::string_view text(value);
  while (!text.empty()) {
    const std::size_t comma = text.find(',');
    Result<EncryptionKey> key = EncryptionKey::from_hex(text.substr(0, comma));
    if (!key) return with_context(Result<std::vector<EncryptionKey>>(key.error()), "HANZO_ENCRYPTION_KEY");
    keys.push_back(*key);
    if (comma == std::string_view::npos) break;
    text.remove_prefix(comma + 1);
  }
  return keys;
}

Result<int> decrypt_to_memory_file(const std::string& path, const std::vector<EncryptionKey>& keys) {
  std::ifstream in(path, std::ios::binary);
  if (!in) return Error(fmt::format("{}: cannot read", path));
  const int fd = ::memfd_create("hanzo-decrypted", MFD_CLOEXEC);
  if (fd < 0) return Error(fmt::format("{}: cannot make an in-memory file ({})", path, std::strerror(errno)));
  std::ofstream out(fmt::format("/proc/self/fd/{}", fd), std::ios::binary);
  Result<std::string> used = decrypt_stream(in, out, keys);
  out.close();
  if (!used || !out) {
    ::close(fd);
    return Error(fmt::format("{}: {}", path, used ? "writing the decrypted copy failed" : used.error().message));
  }
  return fd;
}

std::string encrypt(std::string_view plaintext, const EncryptionKey& key) {
  std::istringstream in{std::string(plaintext)};
  std::ostringstream out;
  (void)encrypt_stream(in, out, key);  // in-memory streams do not fail
  return out.str();
}

Result<std::string> decrypt(std::string_view ciphertext, const std::vector<EncryptionKey>& keys) {
  std::istringstream in{std::string(ciphertext)};
  std::ostringstream out;
  HANZO_RETURN_IF_ERROR(decrypt_stream(in, out, keys));
  return out.str();
}

Result<std::string> decrypt_prefix(std::string_view first_bytes, const std::vector<EncryptionKey>& keys) {
  std::istringstream in{std::string(first_bytes)};
  std::ostringstream out;
  HANZO_RETURN_IF_ERROR(decrypt_stream(in, out, keys, true));
  return out.str();
}

}  // namespace hanzo::fusion::crypto
