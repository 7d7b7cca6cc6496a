#include "hanzo/fusion/maps/map_store.hpp"

#include <csignal>
#include <filesystem>
#include <fstream>
#include <set>

#include <sys/wait.h>
#include <unistd.h>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "map_fixtures.hpp"

namespace hanzo::fusion::maps {
namespace {

using ::testing::HasSubstr;

class MapStoreTest : public ::testing::Test {
 protected:
  void SetUp() override {
    std::filesystem::remove_all(root_);
    auto opened = MapStore::open(root_);
    ASSERT_TRUE(opened.ok()) << opened.error().message;
    store_.emplace(std::move(opened).value());
  }
  void TearDown() override { std::filesystem::remove_all(root_); }

  msgs::FusionMap small_map(const std::string& map_id, float value) const {
    msgs::FusionMap map;
    map.map_id = map_id;
    msgs::PointLayer points;
    points.points.emplace_back(value, value, value);
    map.points = points;
    return map;
  }

  const std::string root_ = testing_maps::temp_path(
      std::string("store_") + ::testing::UnitTest::GetInstance()->current_test_info()->name());
  std::optional<MapStore> store_;
};

TEST_F(MapStoreTest, EachSaveIsANewVersionAndEveryVersionLoads) {
  auto first = store_->save(small_map("warehouse", 1.0f));
  ASSERT_TRUE(first.ok()) << first.error().message;
  EXPECT_EQ(first->version, 1u);
  EXPECT_EQ(first->parent_version, 0u);

  // Load, change and save: version 2 derived from 1.
  auto loaded = store_->load("warehouse");
  ASSERT_TRUE(loaded.ok()) << loaded.error().message;
  EXPECT_EQ(loaded->version, 1u);
  loaded->points->points.emplace_back(5.0f, 5.0f, 5.0f);
  auto second = store_->save(*loaded);
  ASSERT_TRUE(second.ok()) << second.error().message;
  EXPECT_EQ(second->version, 2u);
  EXPECT_EQ(second->parent_version, 1u);

  auto versions = store_->versions("warehouse");
  ASSERT_TRUE(versions.ok()) << versions.error().message;
  ASSERT_EQ(versions->size(), 2u);
  EXPECT_EQ((*versions)[0].version, 1u);
  EXPECT_EQ((*versions)[1].parent_version, 1u);
  EXPECT_GT((*versions)[1].file_bytes, 0u);

  auto old = store_->load("warehouse", 1);
  ASSERT_TRUE(old.ok());
  EXPECT_EQ(old->points->points.size(), 1u);
  auto latest = store_->load("warehouse");
  ASSERT_TRUE(latest.ok());
  EXPECT_EQ(latest->points->points.size(), 2u);
  EXPECT_THAT(store_->load("warehouse", 9).error().message, HasSubstr("no version 9"));
  EXPECT_THAT(store_->load("unknown-map").error().message, HasSubstr("not in the store"));
}

TEST_F(MapStoreTest, DeletedVersionsAreGoneAndTheirNumbersNeverComeBack) {
  for (float value : {1.0f, 2.0f, 3.0f}) ASSERT_TRUE(store_->save(small_map("warehouse", value)).ok());
  ASSERT_TRUE(store_->remove_version("warehouse", 1).ok());
  EXPECT_THAT(store_->load("warehouse", 1).error().message, HasSubstr("no version 1 (stored: 2 versions, 2 to 3)"));
  EXPECT_EQ(store_->load("warehouse", 2)->points->points.front().x(), 2.0f);

  // The newest cannot go alone (the next save would take its number again); unknown ones fail.
  auto newest = store_->remove_version("warehouse", 3);
  ASSERT_FALSE(newest.ok());
  EXPECT_EQ(newest.error().field, "version");
  EXPECT_THAT(newest.error().message, HasSubstr("version 3 is the newest"));
  EXPECT_THAT(store_->remove_version("warehouse", 1).error().message, HasSubstr("no version 1"));
  EXPECT_THAT(store_->remove_version("../escape", 1).error().message, HasSubstr("map_id"));
  EXPECT_EQ(store_->save(small_map("warehouse", 4.0f))->version, 4u);
  ASSERT_TRUE(store_->remove_version("warehouse", 3).ok());
  auto versions = store_->versions("warehouse");
  ASSERT_EQ(versions->size(), 2u);
  EXPECT_EQ((*versions)[0].version, 2u);
  EXPECT_EQ((*versions)[1].version, 4u);
}

TEST_F(MapStoreTest, ADeletedMapLeavesNothingBehindAndOtherMapsAlone) {
  for (float value : {1.0f, 2.0f}) ASSERT_TRUE(store_->save(small_map("warehouse", value)).ok());
  ASSERT_TRUE(store_->save(small_map("yard", 5.0f)).ok());
  std::ofstream(root_ + "/warehouse/.123-interrupted.tmp") << "partial";  // a save killed midway
  ASSERT_TRUE(store_->remove_map("warehouse").ok());
  EXPECT_FALSE(std::filesystem::exists(root_ + "/warehouse"));
  EXPECT_EQ(*store_->map_ids(), std::vector<std::string>{"yard"});
  EXPECT_THAT(store_->load("warehouse").error().message, HasSubstr("not in the store"));
  EXPECT_THAT(store_->remove_map("warehouse").error().message, HasSubstr("not in the store"));
  EXPECT_EQ(store_->load("yard")->points->points.front().x(), 5.0f);
  // The id can be used again: a new map, from version 1.
  EXPECT_EQ(store_->save(small_map("warehouse", 7.0f))->version, 1u);
}

TEST_F(MapStoreTest, LoadAtATimeGivesTheVersionOfThatTime) {
  msgs::FusionMap map = small_map("site", 1.0f);
  map.created = Timestamp::from_nanoseconds(1'000);
  ASSERT_TRUE(store_->save(map).ok());
  map = small_map("site", 2.0f);
  map.created = Timestamp::from_nanoseconds(2'000);
  ASSERT_TRUE(store_->save(map).ok());
  auto at = store_->load_at("site", Timestamp::from_nanoseconds(1'500));
  ASSERT_TRUE(at.ok()) << at.error().message;
  EXPECT_EQ(at->version, 1u);
  EXPECT_EQ(store_->load_at("site", Timestamp::from_nanoseconds(5'000))->version, 2u);
  EXPECT_FALSE(store_->load_at("site", Timestamp::from_nanoseconds(10)).ok());
}

TEST_F(MapStoreTest, NewMapsGetAUuidAndMapIdsCannotEscapeTheStore) {
  auto saved = store_->save(small_map("", 1.0f));
  ASSERT_TRUE(saved.ok()) << saved.error().message;
  EXPECT_EQ(saved->map_id.size(), 36u);
  EXPECT_EQ(saved->map_id[14], '4');
  EXPECT_NE(generate_map_id(), generate_map_id());
  for (const std::string& bad : std::vector<std::string>{"../escape", ".hidden", "a/b", std::string(200, 'x')}) {
    EXPECT_EQ(store_->save(small_map(bad, 1.0f)).error().field, "map_id") << bad;
  }
  auto ids = store_->map_ids();
  ASSERT_TRUE(ids.ok());
  EXPECT_EQ(ids->size(), 1u);
}

// Geometric labels, segmentation classes and the label table are kept by every stored version.
TEST_F(MapStoreTest, LabelsAndSegmentationClassesSurviveVersions) {
  msgs::FusionMap map = testing_maps::full_map();
  map.map_id = "labelled";
  ASSERT_TRUE(store_->save(map).ok());
  msgs::FusionMap loaded = store_->load("labelled").value();
  map.version = loaded.version;
  map.parent_version = loaded.parent_version;
  testing_maps::expect_same(loaded, map);
  // A new version with one point relabelled: the old version keeps its classes.
  loaded.points->classes[1] = 2;
  ASSERT_TRUE(store_->save(loaded).ok());
  EXPECT_EQ(store_->load("labelled", 2)->points->classes[1], 2u);
  EXPECT_EQ(store_->load("labelled", 1)->points->classes[1], map.points->classes[1]);
  EXPECT_EQ(store_->load("labelled", 2)->semantic_classes, map.semantic_classes);
}

TEST_F(MapStoreTest, AWriterKilledMidSaveLeavesEveryStoredVersionReadable) {
  ASSERT_TRUE(store_->save(small_map("killed", 1.0f)).ok());
  // A child saves large maps in a loop and is killed with SIGKILL while it writes.
  msgs::FusionMap big = testing_maps::full_map();
  big.map_id = "killed";
  for (int i = 0; i < 300'000; ++i) big.points->points.emplace_back(static_cast<float>(i), 0.0f, 0.0f);
  big.points->position_std.clear();
  big.points->labels.clear();
  big.points->intensities.clear();
  big.points->classes.clear();
  big.points->class_probability.clear();
  int pipe_ends[2];
  ASSERT_EQ(::pipe(pipe_ends), 0);
  const pid_t child = ::fork();
  ASSERT_GE(child, 0);
  if (child == 0) {
    ::close(pipe_ends[0]);
    auto store = MapStore::open(root_);
    for (int i = 0; i < 1000; ++i) {
      if (!store->save(big).ok()) ::_exit(1);
      if (i == 0) (void)!::write(pipe_ends[1], "x", 1);  // one complete save, then keep going
    }
    ::_exit(0);
  }
  ::close(pipe_ends[1]);
  char signal_byte = 0;
  ASSERT_EQ(::read(pipe_ends[0], &signal_byte, 1), 1);
  ::close(pipe_ends[0]);
  ::kill(child, SIGKILL);
  int status = 0;
  ::waitpid(child, &status, 0);

  auto versions = store_->versions("killed");
  ASSERT_TRUE(versions.ok()) << versions.error().message;
  ASSERT_GE(versions->size(), 2u);
  for (const MapVersionInfo& info : *versions) {
    auto loaded = store_->load("killed", info.version);
    ASSERT_TRUE(loaded.ok()) << info.version << ": " << loaded.error().message;
  }
  EXPECT_EQ(store_->load("killed", 1)->points->points.size(), 1u);
  // Saving goes on after the crash, past whatever the killed writer left.
  auto next = store_->save(small_map("killed", 3.0f));
  ASSERT_TRUE(next.ok()) << next.error().message;
  EXPECT_EQ(next->version, versions->back().version + 1);
}

TEST_F(MapStoreTest, ConcurrentWritersNeverShareAVersion) {
  std::vector<pid_t> children;
  for (int writer = 0; writer < 3; ++writer) {
    const pid_t child = ::fork();
    ASSERT_GE(child, 0);
    if (child == 0) {
      auto store = MapStore::open(root_);
      for (int i = 0; i < 5; ++i) {
        msgs::FusionMap map = small_map("shared", static_cast<float>(writer * 10 + i));
        if (!store->save(map).ok()) ::_exit(1);
      }
      ::_exit(0);
    }
    children.push_back(child);
  }
  for (const pid_t child : children) {
    int status = 0;
    ::waitpid(child, &status, 0);
    EXPECT_TRUE(WIFEXITED(status) && WEXITSTATUS(status) == 0);
  }
  auto versions = store_->versions("shared");
  ASSERT_TRUE(versions.ok()) << versions.error().message;
  ASSERT_EQ(versions->size(), 15u);
  std::set<float> values;
  for (const MapVersionInfo& info : *versions) {
    EXPECT_EQ(info.version, values.size() + 1);
    values.insert(store_->load("shared", info.version)->points->points[0].x());
  }
  EXPECT_EQ(values.size(), 15u);  // no save overwrote another
}

TEST_F(MapStoreTest, ACorruptedVersionFileIsReportedByName) {
  ASSERT_TRUE(store_->save(small_map("broken", 1.0f)).ok());
  const std::string path = root_ + "/broken/00000000000000000001.fmap";
  std::ofstream(path, std::ios::binary | std::ios::trunc) << "garbage";
  auto loaded = store_->load("broken", 1);
  ASSERT_FALSE(loaded.ok());
  EXPECT_THAT(loaded.error().message, HasSubstr("00000000000000000001.fmap"));
}

}  // namespace
}  // namespace hanzo::fusion::maps
