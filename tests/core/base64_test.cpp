// Base64: RFC 4648's test vectors, exact round trips of every length, rejected input by name.

#include "hanzo/fusion/core/base64.hpp"

#include <random>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

namespace hanzo::fusion {
namespace {

using ::testing::HasSubstr;

std::span<const uint8_t> bytes_of(std::string_view text) { return {reinterpret_cast<const uint8_t*>(text.data()), text.size()}; }

TEST(Base64, Rfc4648VectorsAndRoundTrips) {
  const std::vector<std::pair<std::string, std::string>> vectors = {
      {"", ""}, {"f", "Zg=="}, {"fo", "Zm8="}, {"foo", "Zm9v"}, {"foob", "Zm9vYg=="}, {"fooba", "Zm9vYmE="}, {"foobar", "Zm9vYmFy"}};
  for (const auto& [plain, encoded] : vectors) {
    EXPECT_EQ(base64_encode(bytes_of(plain)), encoded);
    const auto decoded = base64_decode(encoded);
    ASSERT_TRUE(decoded.ok()) << decoded.error().message;
    EXPECT_EQ(std::string(decoded->begin(), decoded->end()), plain);
  }
  std::mt19937 random(3);
  for (std::size_t size = 0; size < 70; ++size) {
    std::vector<uint8_t> data(size);
    for (uint8_t& b : data) b = static_cast<uint8_t>(random());
    const std::string text = base64_encode(data);
    EXPECT_EQ(base64_decode(text).value(), data);
    std::string wrapped = text;  // MIME-style line breaks are skipped
    for (std::size_t at = 76; at < wrapped.size(); at += 78) wrapped.insert(at, "\r\n");
    EXPECT_EQ(base64_decode(wrapped).value(), data);
  }
}

TEST(Base64, RejectsBadTextNamingWhatIsWrong) {
  EXPECT_THAT(base64_decode("Zm9v!mFy").error().message, HasSubstr("offset 4 is not base64"));
  EXPECT_THAT(base64_decode("Zm9vY").error().message, HasSubstr("multiple of 4"));
  EXPECT_THAT(base64_decode("Zg==Zm9v").error().message, HasSubstr("after the '=' padding"));
  EXPECT_THAT(base64_decode("Z=g=").error().message, HasSubstr("cannot pad"));
  EXPECT_THAT(base64_decode("Zm=v").error().message, HasSubstr("after the '=' padding"));
  EXPECT_THAT(base64_decode("====").error().message, HasSubstr("cannot pad"));
}

}  // namespace
}  // namespace hanzo::fusion
