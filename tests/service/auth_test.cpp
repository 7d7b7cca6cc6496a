#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "hanzo/fusion/service/auth.hpp"
#include "service_fixtures.hpp"

namespace hanzo::fusion::service {
namespace {

using ::testing::HasSubstr;

TEST(TokenStore, FileMapsTokensToOrganizationAndPermissions) {
  auto store = TokenStore::parse(testing::kTokensYaml, "tokens.yaml");
  ASSERT_TRUE(store.ok()) << store.error().message;
  EXPECT_EQ(store->size(), 6u);
  const auto robot = store->authenticate("acme-robot-secret-0001");
  ASSERT_TRUE(robot.has_value());
  EXPECT_EQ(robot->name, "acme-robot");
  EXPECT_EQ(robot->organization, "acme");
  EXPECT_TRUE(robot->has(Permission::kSessionWrite));
  EXPECT_TRUE(robot->has(Permission::kMapRead));
  EXPECT_FALSE(robot->has(Permission::kMapWrite));
  EXPECT_FALSE(robot->has(Permission::kAdmin));
  // Admin implies every permission.
  const auto admin = store->authenticate("acme-admin-secret-00003");
  ASSERT_TRUE(admin.has_value());
  EXPECT_TRUE(admin->has(Permission::kMapWrite));
  EXPECT_TRUE(admin->has(Permission::kSessionRead));
  // Unknown, empty, prefix of a real token.
  EXPECT_FALSE(store->authenticate("acme-robot-secret-0002").has_value());
  EXPECT_FALSE(store->authenticate("").has_value());
  EXPECT_FALSE(store->authenticate("acme-robot-secret-000").has_value());
}

TEST(TokenStore, AcceptsDigestsInsteadOfSecrets) {
  const std::string yaml = "tokens:\n  - organization: acme\n    permissions: [fusion:map:read]\n    token_sha256: \"" +
                           sha256_hex("a-long-enough-token-xyz") + "\"\n";
  auto store = TokenStore::parse(yaml, "tokens.yaml");
  ASSERT_TRUE(store.ok()) << store.error().message;
  const auto principal = store->authenticate("a-long-enough-token-xyz");
  ASSERT_TRUE(principal.has_value());
  EXPECT_EQ(principal->organization, "acme");
  EXPECT_EQ(sha256_hex("abc"), "ba7816bf8f01cfea414140de5dae2223b00361a396177a9cb410ff61f20015ad");  // FIPS 180-2 vector
}

TEST(TokenStore, RejectsBadFilesNamingTheProblem) {
  struct Case {
    std::string yaml;
    std::string expected;
  };
  const std::vector<Case> cases = {
      {"tokens:\n  - organization: a\n    permissions: [fusion:session:read]\n    token: short\n", "at least 16 characters"},
      {"tokens:\n  - organization: a\n    permissions: [fusion:everything]\n    token: 0123456789abcdef\n", "unknown permission 'fusion:everything'"},
      {"tokens:\n  - permissions: [fusion:session:read]\n    token: 0123456789abcdef\n", "organization"},
      {"tokens:\n  - organization: a\n    permissions: []\n    token: 0123456789abcdef\n", "no permissions"},
      {"tokens:\n  - organization: a\n    permissions: [fusion:admin]\n    token: 0123456789abcdef\n"
       "  - organization: b\n    permissions: [fusion:admin]\n    token: 0123456789abcdef\n", "listed twice"},
      {"tokens:\n  - organization: a\n    permissions: [fusion:admin]\n", "exactly one of token and token_sha256"},
      {"tokens:\n  - organization: a\n    permissions: [fusion:admin]\n    token_sha256: abc\n", "64 hex digits"},
      {"tokens:\n  - organization: a\n    permissions: [fusion:admin]\n    tokne: 0123456789abcdef\n", "tokne"},
      {"tokens: 5\n", "list of tokens"},
      {"tokens: [\n", "tokens.yaml"},
  };
  for (const Case& test : cases) {
    auto store = TokenStore::parse(test.yaml, "tokens.yaml");
    ASSERT_FALSE(store.ok()) << test.yaml;
    EXPECT_THAT(store.error().message, HasSubstr(test.expected)) << test.yaml;
  }
  EXPECT_FALSE(TokenStore::load("/nonexistent/tokens.yaml").ok());
}

TEST(TokenStore, InlineSpecificationFromTheEnvironment) {
  auto store = TokenStore::parse_inline("robot-token-0123456789=acme:fusion:session:write,fusion:session:read;"
                                        "viewer-token-0123456789=globex:fusion:map:read");
  ASSERT_TRUE(store.ok()) << store.error().message;
  EXPECT_EQ(store->size(), 2u);
  const auto viewer = store->authenticate("viewer-token-0123456789");
  ASSERT_TRUE(viewer.has_value());
  EXPECT_EQ(viewer->organization, "globex");
  EXPECT_TRUE(viewer->has(Permission::kMapRead));
  EXPECT_FALSE(viewer->has(Permission::kSessionRead));
  EXPECT_FALSE(TokenStore::parse_inline("robot-token-0123456789").ok());
  EXPECT_FALSE(TokenStore::parse_inline("short=acme:fusion:admin").ok());
  EXPECT_THAT(TokenStore::parse_inline("robot-token-0123456789=acme:fusion:root").error().message, HasSubstr("fusion:root"));
}

TEST(Authorization, BearerHeaderParsing) {
  EXPECT_EQ(bearer_token("Bearer abc"), "abc");
  EXPECT_EQ(bearer_token("bearer  abc "), "abc");
  EXPECT_FALSE(bearer_token("Basic abc").has_value());
  EXPECT_FALSE(bearer_token("Bearer ").has_value());
  EXPECT_FALSE(bearer_token("").has_value());
}

TEST(Authorization, MatrixOfPrincipalPermissionAndOrganization) {
  const Principal reader{"reader", "acme", static_cast<uint32_t>(Permission::kSessionRead)};
  EXPECT_EQ(authorize(std::nullopt, Permission::kSessionRead).error().code, ErrorCode::kUnauthenticated);
  EXPECT_TRUE(authorize(reader, Permission::kSessionRead, "acme").ok());
  EXPECT_EQ(authorize(reader, Permission::kSessionWrite, "acme").error().code, ErrorCode::kPermissionDenied);
  EXPECT_EQ(authorize(reader, Permission::kSessionRead, "globex").error().code, ErrorCode::kPermissionDenied);
  // Admin is all permissions inside its own organization only.
  const Principal admin{"admin", "acme", static_cast<uint32_t>(Permission::kAdmin)};
  EXPECT_TRUE(authorize(admin, Permission::kMapWrite, "acme").ok());
  EXPECT_EQ(authorize(admin, Permission::kMapWrite, "globex").error().code, ErrorCode::kPermissionDenied);
  EXPECT_TRUE(Principal::local_development().has(Permission::kAdmin));
}

}  // namespace
}  // namespace hanzo::fusion::service
