// The map store on S3 (a local s3rver) and encrypted at rest: the same versions, temporal
// queries and deletions as on disk; encrypted versions unreadable without their key, refused when
// tampered with, readable after a key rotation while the old key is given.
#include <filesystem>
#include <fstream>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "hanzo/fusion/core/files.hpp"
#include "hanzo/fusion/maps/map_store.hpp"
#include "map_fixtures.hpp"
#include "support/local_s3_server.hpp"

namespace hanzo::fusion::maps {
namespace {

namespace fs = std::filesystem;
using ::testing::HasSubstr;

msgs::FusionMap point_map(const std::string& map_id, float value, int64_t created_ns) {
  msgs::FusionMap map;
  map.map_id = map_id;
  map.created = Timestamp::from_nanoseconds(created_ns);
  msgs::PointLayer points;
  for (int i = 0; i < 1000; ++i) points.points.emplace_back(value, static_cast<float>(i), 0.0f);
  map.points = points;
  return map;
}

TEST(MapStoreOnS3, VersionsTemporalQueriesAndDeletionWorkAsOnDisk) {
  const fs::path folder = testing_maps::temp_path("s3");
  testing::LocalS3Server server(folder, "fusion-maps");
  ASSERT_EQ(server.error(), "");
  testing::LocalS3Server::use_credentials();
  auto opened = MapStore::open(server.url("site-a"));
  ASSERT_TRUE(opened) << opened.error().message;
  MapStore& store = *opened;
  for (int i = 1; i <= 3; ++i) {
    auto saved = store.save(point_map("warehouse", static_cast<float>(i), i * 1000));
    ASSERT_TRUE(saved) << saved.error().message;
    EXPECT_EQ(saved->version, static_cast<uint64_t>(i));
    EXPECT_EQ(saved->location, fmt::format("s3://fusion-maps/site-a/warehouse/{:020}.fmap", i));
  }
  ASSERT_TRUE(store.save(point_map("yard", 9.0f, 500)));
  EXPECT_TRUE(fs::exists(server.data_folder() / "site-a/warehouse/00000000000000000002.fmap._S3rver_object"));

  // A second store object (a restarted server) lists them from the bucket alone.
  auto reopened = MapStore::open(server.url("site-a"));
  ASSERT_TRUE(reopened);
  EXPECT_EQ(*reopened->map_ids(), (std::vector<std::string>{"warehouse", "yard"}));
  auto versions = reopened->versions("warehouse");
  ASSERT_TRUE(versions) << versions.error().message;
  ASSERT_EQ(versions->size(), 3u);
  EXPECT_EQ((*versions)[1].created.nanoseconds(), 2000);
  auto at = reopened->load_at("warehouse", Timestamp::from_nanoseconds(2500));
  ASSERT_TRUE(at) << at.error().message;
  EXPECT_EQ(at->version, 2u);
  EXPECT_EQ(at->points->points.front().x(), 2.0f);
  EXPECT_EQ(reopened->load("warehouse")->version, 3u);

  ASSERT_TRUE(reopened->remove_version("warehouse", 1));
  EXPECT_THAT(reopened->load("warehouse", 1).error().message, HasSubstr("no version 1"));
  ASSERT_TRUE(reopened->remove_map("warehouse"));
  EXPECT_EQ(*reopened->map_ids(), std::vector<std::string>{"yard"});
  EXPECT_EQ(reopened->save(point_map("warehouse", 7.0f, 9000))->version, 1u);
  fs::remove_all(folder);
}

class EncryptedMapStore : public ::testing::Test {
 protected:
  void SetUp() override { fs::remove_all(root_); }
  void TearDown() override { fs::remove_all(root_); }
  MapStore store(std::optional<crypto::EncryptionKey> key, std::vector<crypto::EncryptionKey> old_keys = {}) const {
    MapStoreConfig config;
    config.encryption_key = std::move(key);
    config.decryption_keys = std::move(old_keys);
    return std::move(MapStore::open(root_, config)).value();
  }
  const std::string root_ = testing_maps::temp_path("encrypted_store");
  const crypto::EncryptionKey old_key_ = crypto::EncryptionKey::generate();
  const crypto::EncryptionKey new_key_ = crypto::EncryptionKey::generate();
};

TEST_F(EncryptedMapStore, VersionsAreCiphertextOnDiskAndNeedTheirKey) {
  MapStore encrypted = store(old_key_);
  auto saved = encrypted.save(point_map("site", 1.0f, 1000));
  ASSERT_TRUE(saved) << saved.error().message;
  EXPECT_EQ(saved->key_id, old_key_.id());
  const std::string on_disk = *read_file(saved->location);
  EXPECT_TRUE(crypto::is_encrypted(on_disk));
  EXPECT_EQ(on_disk.find("site"), std::string::npos);  // not even the map id is readable

  // Listing and temporal queries read the metadata through the decryption.
  auto versions = store(std::nullopt, {old_key_}).versions("site");
  ASSERT_TRUE(versions) << versions.error().message;
  EXPECT_EQ(versions->front().created.nanoseconds(), 1000);
  EXPECT_EQ(versions->front().key_id, old_key_.id());
  EXPECT_EQ(store(std::nullopt, {old_key_}).load_at("site", Timestamp::from_nanoseconds(1500))->points->points.size(), 1000u);

  auto without_key = store(std::nullopt).load("site");
  ASSERT_FALSE(without_key);
  EXPECT_THAT(without_key.error().message, HasSubstr(old_key_.id()));
  EXPECT_THAT(without_key.error().message, HasSubstr("00000000000000000001.fmap"));
}

TEST_F(EncryptedMapStore, LargeVersionsListFromTheirFirstChunkAndLoadWhole) {
  msgs::FusionMap big = point_map("big", 1.0f, 4000);
  for (int i = 0; i < 400'000; ++i) big.points->points.emplace_back(static_cast<float>(i) * 0.37f, static_cast<float>(i % 977), 1.0f);
  auto saved = store(old_key_).save(big);
  ASSERT_TRUE(saved) << saved.error().message;
  ASSERT_GT(saved->file_bytes, 1u << 20);  // more than one encryption chunk
  MapStore reader = store(std::nullopt, {old_key_});
  auto versions = reader.versions("big");
  ASSERT_TRUE(versions) << versions.error().message;
  EXPECT_EQ(versions->front().unreadable, "");
  EXPECT_EQ(versions->front().created.nanoseconds(), 4000);
  EXPECT_EQ(reader.load("big")->points->points.size(), big.points->points.size());
}

TEST_F(EncryptedMapStore, ATamperedOrTruncatedVersionIsRefusedNamingIt) {
  MapStore encrypted = store(old_key_);
  auto saved = encrypted.save(point_map("site", 1.0f, 1000));
  ASSERT_TRUE(saved);
  std::string bytes = *read_file(saved->location);
  bytes[bytes.size() / 2] ^= 0x01;
  std::ofstream(saved->location, std::ios::binary | std::ios::trunc) << bytes;
  auto tampered = store(old_key_).load("site");
  ASSERT_FALSE(tampered);
  EXPECT_THAT(tampered.error().message, HasSubstr("does not authenticate"));

  // The damaged version is listed with the reason, and does not stop new versions.
  auto listed = store(old_key_).versions("site");
  ASSERT_TRUE(listed) << listed.error().message;
  EXPECT_THAT(listed->front().unreadable, HasSubstr("does not authenticate"));
  ASSERT_TRUE(encrypted.save(point_map("site", 2.0f, 2000)));
  const std::string second = testing_maps::temp_path("encrypted_store") + "/site/00000000000000000002.fmap";
  fs::resize_file(second, fs::file_size(second) - 10);
  auto truncated = store(old_key_).load("site", 2);
  ASSERT_FALSE(truncated);
  EXPECT_THAT(truncated.error().message, HasSubstr("truncated"));
}

TEST_F(EncryptedMapStore, AKeyRotationKeepsOlderVersionsReadable) {
  ASSERT_TRUE(store(std::nullopt).save(point_map("site", 1.0f, 1000)));  // from before encryption was on
  ASSERT_TRUE(store(old_key_).save(point_map("site", 2.0f, 2000)));
  MapStore rotated = store(new_key_, {old_key_});
  auto third = rotated.save(point_map("site", 3.0f, 3000));
  ASSERT_TRUE(third);
  EXPECT_EQ(third->key_id, new_key_.id());
  for (uint64_t version = 1; version <= 3; ++version) {
    auto loaded = rotated.load("site", version);
    ASSERT_TRUE(loaded) << version << ": " << loaded.error().message;
    EXPECT_EQ(loaded->points->points.front().x(), static_cast<float>(version));
  }
  auto versions = rotated.versions("site");
  ASSERT_TRUE(versions);
  EXPECT_EQ((*versions)[0].key_id, "");
  EXPECT_EQ((*versions)[1].key_id, old_key_.id());
  // Once the old key is retired, its version is refused with the key it needs.
  EXPECT_THAT(store(new_key_).load("site", 2).error().message, HasSubstr(old_key_.id()));
}

}  // namespace
}  // namespace hanzo::fusion::maps
