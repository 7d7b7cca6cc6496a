// hanzo-fusion crypto keygen|encrypt|decrypt: encryption at rest of logs, maps and other files
// (crypto/file_encryption.hpp). Keys come from --key files or $HANZO_ENCRYPTION_KEY.

#include <filesystem>
#include <memory>
#include <string>
#include <vector>

#include <fmt/format.h>

#include "commands.hpp"
#include "hanzo/fusion/crypto/file_encryption.hpp"

namespace hanzo::fusion::app {
namespace {

struct CryptoOptions {
  std::string input;
  std::string output;
  std::vector<std::string> key_files;
};

// The keys of --key, or the environment's when none is given.
Result<std::vector<crypto::EncryptionKey>> load_keys(const std::vector<std::string>& files) {
  std::vector<crypto::EncryptionKey> keys;
  if (files.empty()) {
    Result<crypto::EncryptionKey> key = crypto::EncryptionKey::from_environment();
    if (!key) return key.error();
    keys.push_back(*key);
  }
  for (const std::string& file : files) {
    Result<crypto::EncryptionKey> key = crypto::EncryptionKey::load(file);
    if (!key) return key.error();
    keys.push_back(*key);
  }
  return keys;
}

}  // namespace

void add_crypto_command(CLI::App& app, const Output& output, Command& run) {
  CLI::App* crypto_command = app.add_subcommand("crypto", "Encryption at rest of sensor logs, maps and other files");
  crypto_command->require_subcommand(1);
  auto options = std::make_shared<CryptoOptions>();

  CLI::App* keygen = crypto_command->add_subcommand("keygen", "Write a new random key (64 hex digits, readable by its owner only)");
  keygen->add_option("OUT", options->output, "Key file to write")->required();
  keygen->callback([&output, &run, options] {
    run = [&output, options] {
      nlohmann::json result = {{"output", options->output}};
      if (std::filesystem::exists(options->output)) {
        return report_failure(output, result, fmt::format("{} exists: a key is never overwritten", options->output));
      }
      const crypto::EncryptionKey key = crypto::EncryptionKey::generate();
      if (Status saved = key.save(options->output); !saved) return report_failure(output, result, saved.error().message);
      result["ok"] = true;
      result["key_id"] = key.id();
      return report_success(output, result, fmt::format("{}: key {}\n", options->output, key.id()));
    };
  });

  CLI::App* encrypt = crypto_command->add_subcommand("encrypt", "Encrypt a file (XChaCha20-Poly1305 secretstream)");
  encrypt->add_option("IN", options->input, "File to encrypt")->required();
  encrypt->add_option("OUT", options->output, "Encrypted file to write")->required();
  encrypt->add_option("--key", options->key_files, "Key file (default: $HANZO_ENCRYPTION_KEY)");
  encrypt->callback([&output, &run, options] {
    run = [&output, options] {
      nlohmann::json result = {{"input", options->input}, {"output", options->output}};
      if (options->key_files.size() > 1) return report_failure(output, result, "encrypt takes one --key");
      Result<std::vector<crypto::EncryptionKey>> keys = load_keys(options->key_files);
      if (!keys) return report_failure(output, result, keys.error().message);
      const crypto::EncryptionKey& key = keys->front();
      if (crypto::is_encrypted_file(options->input)) return report_failure(output, result, fmt::format("{} is encrypted already", options->input));
      if (Status done = crypto::encrypt_file(options->input, options->output, key); !done) return report_failure(output, result, done.error().message);
      result["ok"] = true;
      result["key_id"] = key.id();
      result["bytes"] = std::filesystem::file_size(options->output);
      return report_success(output, result, fmt::format("{} -> {}: encrypted with key {}\n", options->input, options->output, key.id()));
    };
  });

  CLI::App* decrypt = crypto_command->add_subcommand("decrypt", "Decrypt a file; nothing is written unless it authenticates completely");
  decrypt->add_option("IN", options->input, "Encrypted file")->required();
  decrypt->add_option("OUT", options->output, "Decrypted file to write")->required();
  decrypt->add_option("--key", options->key_files, "Key file; repeat it for every key in use during a rotation (default: $HANZO_ENCRYPTION_KEY)");
  decrypt->callback([&output, &run, options] {
    run = [&output, options] {
      nlohmann::json result = {{"input", options->input}, {"output", options->output}};
      Result<std::vector<crypto::EncryptionKey>> keys = load_keys(options->key_files);
      if (!keys) return report_failure(output, result, keys.error().message);
      Result<std::string> used = crypto::decrypt_file(options->input, options->output, *keys);
      if (!used) return report_failure(output, result, used.error().message);
      result["ok"] = true;
      result["key_id"] = *used;
      result["bytes"] = std::filesystem::file_size(options->output);
      return report_success(output, result, fmt::format("{} -> {}: decrypted with key {}\n", options->input, options->output, *used));
    };
  });
}

}  // namespace hanzo::fusion::app
