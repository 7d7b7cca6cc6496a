// The ObjectStore contract, run on both backends: the local disk and an S3 server (s3rver on
// 127.0.0.1, which checks each request's access key but not its signature). Plus the Signature
// Version 4 against the Amazon S3 API reference's worked example and the AWS SDK's own signer,
// and the S3 client's refusals and error messages.
#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <random>

#include <fmt/format.h>
#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "hanzo/fusion/object_store/object_store.hpp"
#include "hanzo/fusion/object_store/s3_signature.hpp"
#include "support/local_s3_server.hpp"

namespace hanzo::fusion::object_store {
namespace {

namespace fs = std::filesystem;
using ::testing::HasSubstr;

std::string random_bytes(std::size_t size, uint64_t seed) {
  std::mt19937_64 random(seed);
  std::string bytes(size, '\0');
  for (char& c : bytes) c = static_cast<char>(random() & 0xff);
  return bytes;
}

// Amazon S3 API reference, "Signature Calculations for the Authorization Header", example
// "GET Object" (bytes 0-9 of examplebucket/test.txt).
TEST(S3Signature, MatchesTheWorkedExampleOfTheS3Reference) {
  SignableRequest request;
  request.method = "GET";
  request.path = "/test.txt";
  request.payload_sha256 = sha256_hex("");
  request.headers = {{"Host", "examplebucket.s3.amazonaws.com"},
                     {"Range", "bytes=0-9"},
                     {"x-amz-content-sha256", request.payload_sha256},
                     {"x-amz-date", "20130524T000000Z"}};
  EXPECT_EQ(authorization_header(request, {"AKIAIOSFODNN7EXAMPLE", "wJalrXUtnFEMI/K7MDENG/bPxRfiCYEXAMPLEKEY"}, "us-east-1", "20130524T000000Z"),
            "AWS4-HMAC-SHA256 Credential=AKIAIOSFODNN7EXAMPLE/20130524/us-east-1/s3/aws4_request,"
            "SignedHeaders=host;range;x-amz-content-sha256;x-amz-date,"
            "Signature=f0e8bdb87c964420e857bd35b5d6ed310bd44f0170aba48dd91039c6036bdb41");
}

// Every kind of request the client sends, signed here and by Amazon's own signer
// (@smithy/signature-v4, the AWS SDK for JavaScript's; tests/conformance/sigv4_sign.mjs).
TEST(S3Signature, AgreesWithTheAwsSdkSignerOnEveryKindOfRequest) {
  const std::string date = "20261128T101500Z";
  const auto request = [&](std::string method, std::string path, std::vector<std::pair<std::string, std::string>> query,
                           std::vector<std::pair<std::string, std::string>> extra, std::string_view payload) {
    SignableRequest signable{std::move(method), std::move(path), std::move(query), std::move(extra), sha256_hex(payload)};
    signable.headers.emplace_back("host", "127.0.0.1:4568");
    signable.headers.emplace_back("x-amz-date", date);
    signable.headers.emplace_back("x-amz-content-sha256", signable.payload_sha256);
    return signable;
  };
  const std::vector<SignableRequest> requests = {
      request("PUT", "/fleet/site-a/maps/warehouse/00000000000000000001.fmap", {}, {{"if-none-match", "*"}}, "map bytes"),
      request("GET", "/fleet", {{"list-type", "2"}, {"prefix", "site-a/maps/x y+z/"}, {"max-keys", "3"}, {"continuation-token", "1/ab+c=="}}, {}, ""),
      request("POST", "/fleet/site-a/recordings/a b(1)!/\xc3\xbc.mcap", {{"uploads", ""}}, {}, ""),
      request("PUT", "/fleet/site-a/recordings/r.mcap", {{"partNumber", "2"}, {"uploadId", "2~abc_DEF-123.xyz"}}, {}, std::string(70000, 'p')),
      request("POST", "/fleet/site-a/recordings/r.mcap", {{"uploadId", "2~abc"}}, {{"content-type", "application/xml"}},
              "<CompleteMultipartUpload></CompleteMultipartUpload>"),
      request("GET", "/fleet/site-a/maps/m/1.fmap", {}, {{"range", "bytes=0-65535"}, {"x-amz-security-token", "FwoGZXIvYXdzE//token+/="}}, ""),
      request("DELETE", "/fleet/site-a/maps/m/1.fmap", {}, {}, ""),
  };
  const SigningKeys keys{"AKIDEXAMPLE", "wJalrXUtnFEMI/K7MDENG+bPxRfiCYEXAMPLEKEY"};
  nlohmann::json input = nlohmann::json::array();
  for (const SignableRequest& r : requests) {
    nlohmann::json query = nlohmann::json::object(), headers = nlohmann::json::object();
    for (const auto& [name, value] : r.query) query[name] = value;
    for (const auto& [name, value] : r.headers) headers[name] = value;
    input.push_back({{"method", r.method}, {"path", r.path}, {"query", query}, {"headers", headers}, {"access_key", keys.access_key_id},
                     {"secret", keys.secret_access_key}, {"region", "eu-central-1"}, {"amz_date", date}});
  }
  const fs::path file = fs::temp_directory_path() / fmt::format("hanzo_sigv4_requests_{}.json", ::getpid());
  std::ofstream(file) << input.dump();
  FILE* pipe = popen(fmt::format("{} tests/conformance/sigv4_sign.mjs {}", HANZO_NODE_EXECUTABLE, file.string()).c_str(), "r");
  ASSERT_NE(pipe, nullptr);
  std::string output;
  char buffer[4096];
  for (std::size_t n = 0; (n = std::fread(buffer, 1, sizeof(buffer), pipe)) > 0;) output.append(buffer, n);
  ASSERT_EQ(pclose(pipe), 0) << output;
  const nlohmann::json expected = nlohmann::json::parse(output);
  ASSERT_EQ(expected.size(), requests.size());
  const auto part = [](const std::string& header, const std::string& name) {
    const auto at = header.find(name + "=");
    return header.substr(at + name.size() + 1, header.find_first_of(", ", at) - at - name.size() - 1);
  };
  for (std::size_t i = 0; i < requests.size(); ++i) {
    const std::string ours = authorization_header(requests[i], keys, "eu-central-1", date);
    const std::string theirs = expected[i];
    EXPECT_EQ(part(ours, "SignedHeaders"), part(theirs, "SignedHeaders")) << requests[i].method << " " << requests[i].path;
    EXPECT_EQ(part(ours, "Signature"), part(theirs, "Signature")) << requests[i].method << " " << requests[i].path;
    EXPECT_EQ(part(ours, "Credential"), part(theirs, "Credential"));
  }
  fs::remove(file);
}

TEST(S3Signature, EncodesUrisAndQueriesTheWaySigV4Does) {
  EXPECT_EQ(uri_encode("maps/a b+c~_.-/ü", true), "maps/a%20b%2Bc~_.-/%C3%BC");
  EXPECT_EQ(uri_encode("a/b", false), "a%2Fb");
  EXPECT_EQ(canonical_query({{"prefix", "maps/x y"}, {"list-type", "2"}, {"uploads", ""}}), "list-type=2&prefix=maps%2Fx%20y&uploads=");
}

TEST(ObjectKeys, RefusesKeysThatCouldEscapeTheStore) {
  for (const std::string& key : std::vector<std::string>{"", "/etc/passwd", "a//b", "../x", "a/../b", "a/./b", "a\\b", std::string("a\nb"), std::string(1025, 'k')}) {
    EXPECT_FALSE(validate_object_key(key)) << key;
  }
  for (const std::string key : {"maps/0001.fmap", "recordings/s-1.mcap.enc", "a.b/c_d-e"}) EXPECT_TRUE(validate_object_key(key)) << key;
}

TEST(ObjectStoreUrl, ParsesS3UrlsAndRefusesIncompleteSettings) {
  unsetenv("AWS_ACCESS_KEY_ID");
  unsetenv("AWS_SECRET_ACCESS_KEY");
  auto missing_keys = open_object_store("s3://bucket/prefix?endpoint=http://127.0.0.1:9");
  ASSERT_FALSE(missing_keys);
  EXPECT_THAT(missing_keys.error().message, HasSubstr("AWS_ACCESS_KEY_ID"));
  testing::LocalS3Server::use_credentials();
  auto opened = open_object_store("s3://bucket/prefix?endpoint=http://127.0.0.1:9&region=eu-west-1");
  ASSERT_TRUE(opened) << opened.error().message;
  EXPECT_EQ((*opened)->location_of("maps/x"), "s3://bucket/prefix/maps/x");
  EXPECT_FALSE(open_object_store("s3://bucket?colour=red"));
  EXPECT_FALSE(open_object_store("s3://Bad_Bucket/x?endpoint=http://127.0.0.1:9"));
  EXPECT_FALSE(open_object_store("s3://bucket/x?endpoint=ftp://127.0.0.1:9"));
  EXPECT_FALSE(open_object_store("s3://bucket/x?endpoint=http://127.0.0.1:9/path"));
}

TEST(S3ObjectStore, AnUnreachableEndpointIsAnErrorNamingIt) {
  S3Config config;
  config.endpoint = "http://127.0.0.1:9";  // discard port: nothing listens
  config.bucket = "bucket";
  config.access_key_id = config.secret_access_key = "x";
  config.max_attempts = 2;
  auto store = open_s3_object_store(config);
  ASSERT_TRUE(store);
  const auto got = (*store)->get("maps/x");
  ASSERT_FALSE(got);
  EXPECT_THAT(got.error().message, HasSubstr("http://127.0.0.1:9"));
  EXPECT_THAT(got.error().message, HasSubstr("after 2 attempts"));
}

enum class Backend { kLocal, kS3 };

class ObjectStoreContract : public ::testing::TestWithParam<Backend> {
 protected:
  void SetUp() override {
    // One folder per test process: ctest runs tests side by side.
    folder_ = fs::temp_directory_path() / fmt::format("hanzo_object_store_{}_{}", GetParam() == Backend::kS3 ? "s3" : "local", ::getpid());
    fs::remove_all(folder_);
    if (GetParam() == Backend::kLocal) {
      auto opened = open_local_object_store((folder_ / "store").string());
      ASSERT_TRUE(opened) << opened.error().message;
      store_ = std::move(opened).value();
      return;
    }
    server_ = std::make_unique<testing::LocalS3Server>(folder_ / "s3", "fusion-test");
    ASSERT_EQ(server_->error(), "");
    S3Config config = server_->config("site-a/");
    config.multipart_threshold_bytes = config.part_bytes = 5 << 20;
    config.list_page_size = 3;  // listings below take several pages
    auto opened = open_s3_object_store(config);
    ASSERT_TRUE(opened) << opened.error().message;
    store_ = std::move(opened).value();
  }
  void TearDown() override {
    store_.reset();
    server_.reset();
    fs::remove_all(folder_);
  }

  fs::path folder_;
  std::unique_ptr<testing::LocalS3Server> server_;
  std::unique_ptr<ObjectStore> store_;
};

TEST_P(ObjectStoreContract, StoresReadsListsAndDeletesObjectsExactly) {
  const std::string bytes = random_bytes(100'000, 1);
  ASSERT_TRUE(store_->put("maps/m1/0001.fmap", bytes));
  ASSERT_TRUE(store_->put("maps/m1/0002.fmap", "second"));
  ASSERT_TRUE(store_->put("maps/m2/0001.fmap", ""));
  for (int i = 0; i < 5; ++i) ASSERT_TRUE(store_->put(fmt::format("recordings/s{}.mcap", i), std::to_string(i)));

  EXPECT_EQ(*store_->get("maps/m1/0001.fmap"), bytes);
  EXPECT_EQ(*store_->get("maps/m2/0001.fmap"), "");
  EXPECT_EQ(*store_->get_range("maps/m1/0001.fmap", 10, 20), bytes.substr(10, 20));
  EXPECT_EQ(*store_->get_range("maps/m1/0001.fmap", 99'990, 100), bytes.substr(99'990));

  const auto maps = store_->list("maps/");
  ASSERT_TRUE(maps) << maps.error().message;
  ASSERT_EQ(maps->size(), 3u);
  EXPECT_EQ((*maps)[0].key, "maps/m1/0001.fmap");
  EXPECT_EQ((*maps)[0].size, bytes.size());
  EXPECT_GT((*maps)[0].modified.nanoseconds(), 0);
  EXPECT_EQ(store_->list("maps/m1/")->size(), 2u);
  EXPECT_EQ(store_->list("recordings/")->size(), 5u);  // two pages of 3 on S3
  EXPECT_EQ(store_->list("nothing/")->size(), 0u);

  const auto info = store_->stat("maps/m1/0002.fmap");
  ASSERT_TRUE(info && info->has_value());
  EXPECT_EQ((*info)->size, 6u);
  EXPECT_FALSE(store_->stat("maps/m1/0003.fmap")->has_value());

  ASSERT_TRUE(store_->put("maps/m1/0002.fmap", "replaced"));
  EXPECT_EQ(*store_->get("maps/m1/0002.fmap"), "replaced");
  ASSERT_TRUE(store_->remove("maps/m1/0002.fmap"));
  ASSERT_TRUE(store_->remove("maps/m1/0002.fmap"));  // again: not an error
  const auto gone = store_->get("maps/m1/0002.fmap");
  ASSERT_FALSE(gone);
  EXPECT_EQ(gone.error().field, kNotFound);
  EXPECT_EQ(store_->list("maps/")->size(), 2u);
}

TEST_P(ObjectStoreContract, PutIfAbsentNeverReplacesOnDisk) {
  ASSERT_TRUE(*store_->put_if_absent("maps/m/0001.fmap", "first"));
  const auto second = store_->put_if_absent("maps/m/0001.fmap", "second");
  ASSERT_TRUE(second);
  if (GetParam() == Backend::kLocal) {
    EXPECT_FALSE(*second);
    EXPECT_EQ(*store_->get("maps/m/0001.fmap"), "first");
  }  // s3rver ignores If-None-Match (AWS S3, MinIO and Ceph honour it)
}

TEST_P(ObjectStoreContract, LargeFilesGoUpAndComeDownWhole) {
  // Above the 5 MiB multipart threshold set for S3: three parts, the last one short.
  const std::string bytes = random_bytes((11 << 20) + 12345, 2);
  const fs::path input = folder_ / "input.bin", output = folder_ / "output.bin";
  fs::create_directories(folder_);
  std::ofstream(input, std::ios::binary) << bytes;
  ASSERT_TRUE(store_->put_file("recordings/big.mcap", input.string()));
  ASSERT_TRUE(store_->get_to_file("recordings/big.mcap", output.string()));
  std::ifstream read_back(output, std::ios::binary);
  EXPECT_TRUE(std::string(std::istreambuf_iterator<char>(read_back), {}) == bytes);
  EXPECT_EQ((*store_->stat("recordings/big.mcap"))->size, bytes.size());

  const auto missing = store_->get_to_file("recordings/none.mcap", (folder_ / "none.bin").string());
  ASSERT_FALSE(missing);
  EXPECT_EQ(missing.error().field, kNotFound);
  EXPECT_FALSE(fs::exists(folder_ / "none.bin"));
  EXPECT_FALSE(fs::exists(folder_ / "none.bin.partial"));
}

TEST_P(ObjectStoreContract, RefusesBadKeys) {
  const auto escaped = store_->put("../outside", "x");
  ASSERT_FALSE(escaped);
  EXPECT_EQ(escaped.error().field, "key");
  EXPECT_FALSE(fs::exists(folder_ / "outside"));
}

INSTANTIATE_TEST_SUITE_P(Backends, ObjectStoreContract, ::testing::Values(Backend::kLocal, Backend::kS3),
                         [](const auto& instance) { return instance.param == Backend::kS3 ? std::string("S3") : std::string("LocalDisk"); });

TEST(S3ObjectStore, WrongCredentialsAndMissingBucketsAreReportedWithS3sReason) {
  const fs::path folder = fs::temp_directory_path() / fmt::format("hanzo_object_store_s3_errors_{}", ::getpid());
  testing::LocalS3Server server(folder, "fusion-test");
  ASSERT_EQ(server.error(), "");
  // s3rver knows one access key (it checks the key, not Signature Version 4 signatures: those
  // are checked against the S3 reference above and Amazon's own signer in the conformance tests).
  S3Config unknown_key = server.config();
  unknown_key.access_key_id = "AKIAUNKNOWN";
  auto store = open_s3_object_store(unknown_key);
  ASSERT_TRUE(store);
  const auto refused = (*store)->put("maps/x", "bytes");
  ASSERT_FALSE(refused);
  EXPECT_THAT(refused.error().message, HasSubstr("HTTP 403 InvalidAccessKeyId"));

  S3Config other_bucket = server.config();
  other_bucket.bucket = "no-such-bucket";
  auto missing = open_s3_object_store(other_bucket);
  ASSERT_TRUE(missing);
  const auto listed = (*missing)->list("");
  ASSERT_FALSE(listed);
  EXPECT_THAT(listed.error().message, HasSubstr("NoSuchBucket"));
  fs::remove_all(folder);
}

}  // namespace
}  // namespace hanzo::fusion::object_store
