#include "hanzo/fusion/maps/provenance.hpp"

#include <cerrno>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <memory>
#include <vector>

#include <fmt/format.h>
#include <openssl/evp.h>

namespace hanzo::fusion::maps {

Result<std::string> sha256_of_file(const std::string& path) {
  std::ifstream file(path, std::ios::binary);
  if (!file) return Error{fmt::format("{}: cannot open file ({})", path, std::strerror(errno))};
  const std::unique_ptr<EVP_MD_CTX, decltype(&EVP_MD_CTX_free)> context(EVP_MD_CTX_new(), &EVP_MD_CTX_free);
  if (!context || EVP_DigestInit_ex(context.get(), EVP_sha256(), nullptr) != 1) return Error{"SHA-256: cannot initialize"};
  std::vector<char> buffer(std::size_t{1} << 20);
  while (file) {
    file.read(buffer.data(), static_cast<std::streamsize>(buffer.size()));
    if (file.gcount() > 0 && EVP_DigestUpdate(context.get(), buffer.data(), static_cast<std::size_t>(file.gcount())) != 1) {
      return Error{fmt::format("{}: SHA-256 update failed", path)};
    }
  }
  if (file.bad()) return Error{fmt::format("{}: read error ({})", path, std::strerror(errno))};
  unsigned char digest[EVP_MAX_MD_SIZE];
  unsigned int length = 0;
  if (EVP_DigestFinal_ex(context.get(), digest, &length) != 1) return Error{fmt::format("{}: SHA-256 failed", path)};
  std::string hex;
  for (unsigned int i = 0; i < length; ++i) hex += fmt::format("{:02x}", digest[i]);
  return hex;
}

Result<msgs::InputLog> describe_input_file(const std::string& path) {
  msgs::InputLog input;
  HANZO_ASSIGN_OR_RETURN(input.sha256, sha256_of_file(path));
  std::error_code error;
  const std::filesystem::path absolute = std::filesystem::absolute(path, error);
  input.uri = "file://" + (error ? path : absolute.lexically_normal().string());
  return input;
}

}  // namespace hanzo::fusion::maps
