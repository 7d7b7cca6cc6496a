// Raw sensor logging of server sessions (service/session_recording.hpp): what a session is given
// is written as it came, images through the privacy filter (a real photo's face is found and
// blurred before anything is written), finished logs encrypted, the retention policy applied;
// through the SessionManager with its request options and refusals.

#include <sys/stat.h>

#include <filesystem>
#include <fstream>

#include <fmt/format.h>
#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "hanzo/fusion/crypto/file_encryption.hpp"
#include "hanzo/fusion/io/sensor_log.hpp"
#include "hanzo/fusion/service/session_manager.hpp"
#include "hanzo/fusion/service/session_recording.hpp"
#include "support/local_s3_server.hpp"
#include "service_fixtures.hpp"

namespace hanzo::fusion::service {
namespace {

namespace fs = std::filesystem;
using ::testing::HasSubstr;

const Timestamp kStart = Timestamp::from_nanoseconds(1'700'000'000'000'000'000);
const Principal kRobot{"robot", "acme", static_cast<uint32_t>(Permission::kSessionWrite) | static_cast<uint32_t>(Permission::kSessionRead)};

// A real photo with a face (../shared/data/privacy_faces) as an rgb8 camera message.
msgs::ImageMessage face_photo(Timestamp time) {
  cv::Mat bgr = cv::imread(std::string(HANZO_DATA_DIR) + "/privacy_faces/obama.jpg", cv::IMREAD_COLOR);
  EXPECT_FALSE(bgr.empty());
  cv::Mat rgb;
  cv::cvtColor(bgr, rgb, cv::COLOR_BGR2RGB);
  msgs::ImageMessage image;
  image.timestamp = time;
  image.width = static_cast<uint32_t>(rgb.cols);
  image.height = static_cast<uint32_t>(rgb.rows);
  image.encoding = msgs::ImageEncoding::kRgb8;
  image.data.assign(rgb.data, rgb.data + rgb.total() * rgb.elemSize());
  return image;
}

msgs::ImuMessage imu_at(Timestamp time, double z = 9.81) {
  msgs::ImuMessage imu;
  imu.timestamp = time;
  imu.linear_acceleration = {0.0, 0.0, z};
  return imu;
}

std::vector<io::LogEntry> read_log(const std::string& path) {
  std::vector<io::LogEntry> entries;
  auto reader = io::SensorLogReader::open(path);
  EXPECT_TRUE(reader.ok()) << (reader.ok() ? "" : reader.error().message);
  if (!reader.ok()) return entries;
  io::LogEntry entry;
  while (true) {
    auto more = (*reader)->next(entry);
    EXPECT_TRUE(more.ok());
    if (!more.ok() || !*more) return entries;
    entries.push_back(entry);
  }
}

TEST(SessionRecording, WritesWhatCameAndBlursFacesBeforeWriting) {
  const fs::path dir = testing::scratch_dir();
  RecordingConfig config;
  config.directory = (dir / "recordings").string();
  auto recording = SessionRecording::start(config, "s1", privacy::Redaction::kBlur);
  ASSERT_TRUE(recording.ok()) << recording.error().message;
  const msgs::ImageMessage photo = face_photo(kStart + Duration::from_milliseconds(50));
  (*recording)->record("/imu", "imu", imu_at(kStart));
  (*recording)->record("/camera", "camera", photo);
  (*recording)->record("/imu", "imu", imu_at(kStart + Duration::from_milliseconds(10), std::nan("")));  // refused: not written
  (*recording)->record("/imu", "imu", imu_at(kStart + Duration::from_milliseconds(20)));
  RecordingInfo info = (*recording)->info();
  EXPECT_TRUE(info.active);
  EXPECT_EQ(info.file, "s1.mcap");
  struct stat mode {};
  ASSERT_EQ(::stat((dir / "recordings" / "s1.mcap").c_str(), &mode), 0);
  EXPECT_EQ(mode.st_mode & 0777, 0600u);  // only the server reads a recording being written
  ASSERT_TRUE((*recording)->finish().ok());
  info = (*recording)->info();
  EXPECT_FALSE(info.active);
  EXPECT_EQ(info.messages, 3u);
  EXPECT_EQ(info.invalid_messages, 1u);
  EXPECT_EQ(info.privacy, "blur");
  EXPECT_EQ(info.images, 1u);
  EXPECT_EQ(info.redacted_images, 1u);
  EXPECT_GE(info.faces, 1u);
  EXPECT_EQ(info.bytes, fs::file_size(dir / "recordings" / "s1.mcap"));

  const std::vector<io::LogEntry> entries = read_log((dir / "recordings" / "s1.mcap").string());
  ASSERT_EQ(entries.size(), 3u);
  EXPECT_EQ(entries[0].topic, "/imu");
  EXPECT_EQ(std::get<msgs::ImuMessage>(std::get<msgs::SensorMessage>(entries[0].message)).linear_acceleration.z(), 9.81);
  const auto& written = std::get<msgs::ImageMessage>(std::get<msgs::SensorMessage>(entries[2].message));  // in log-time order
  ASSERT_EQ(written.data.size(), photo.data.size());
  // Blurred inside the faces the filter finds in the original, untouched outside them.
  auto filter = privacy::PrivacyFilter::create({});
  ASSERT_TRUE(filter.ok()) << filter.error().message;
  const cv::Mat original = cv::imread(std::string(HANZO_DATA_DIR) + "/privacy_faces/obama.jpg", cv::IMREAD_COLOR);  // BGR
  auto faces = (*filter)->detect(original);
  ASSERT_TRUE(faces.ok() && !faces->empty());
  cv::Mat inside(original.size(), CV_8UC1, cv::Scalar(0));
  for (const privacy::RedactedRegion& face : *faces) {
    const int grow_x = face.box.width / 4, grow_y = face.box.height / 4;  // beyond the filter's margin
    cv::rectangle(inside, cv::Rect(face.box.x - grow_x, face.box.y - grow_y, face.box.width + 2 * grow_x, face.box.height + 2 * grow_y),
                  cv::Scalar(255), cv::FILLED);
  }
  std::size_t changed_inside = 0, changed_outside = 0;
  for (std::size_t i = 0; i < photo.data.size(); ++i) {
    if (written.data[i] == photo.data[i]) continue;
    const std::size_t pixel = i / 3;
    (inside.data[pixel] ? changed_inside : changed_outside) += 1;
  }
  EXPECT_GT(changed_inside, 1000u);
  EXPECT_EQ(changed_outside, 0u);

  // A writer too far behind leaves messages out (counted) instead of stalling the session.
  config.max_queued_bytes = 1;
  auto behind = SessionRecording::start(config, "s1b", std::nullopt);
  ASSERT_TRUE(behind.ok());
  for (int i = 0; i < 5; ++i) (*behind)->record("/imu", "imu", imu_at(kStart + Duration::from_milliseconds(10 * i)));
  ASSERT_TRUE((*behind)->finish().ok());
  EXPECT_EQ((*behind)->info().dropped_messages, 5u);
  EXPECT_EQ((*behind)->info().messages, 0u);
  fs::remove_all(dir);
}

TEST(SessionRecording, FinishedRecordingsAreEncryptedAndTheRetentionPolicyDeletesOldOnes) {
  const fs::path dir = testing::scratch_dir();
  RecordingConfig config;
  config.directory = (dir / "recordings").string();
  config.key = crypto::EncryptionKey::generate();
  auto recording = SessionRecording::start(config, "s2", std::nullopt);
  ASSERT_TRUE(recording.ok()) << recording.error().message;
  for (int i = 0; i < 100; ++i) (*recording)->record("/imu", "imu", imu_at(kStart + Duration::from_milliseconds(10 * i)));
  ASSERT_TRUE((*recording)->finish().ok());
  const RecordingInfo info = (*recording)->info();
  EXPECT_TRUE(info.encrypted);
  EXPECT_EQ(info.file, "s2.mcap.enc");
  EXPECT_EQ(info.privacy, "off");
  EXPECT_FALSE(fs::exists(dir / "recordings" / "s2.mcap"));  // no plaintext left
  ASSERT_TRUE(crypto::is_encrypted_file((dir / "recordings" / "s2.mcap.enc").string()));
  auto decrypted = crypto::decrypt_file((dir / "recordings" / "s2.mcap.enc").string(), (dir / "plain.mcap").string(), {*config.key});
  ASSERT_TRUE(decrypted.ok()) << decrypted.error().message;
  EXPECT_EQ(read_log((dir / "plain.mcap").string()).size(), 100u);

  // Retention: a 40-day-old recording goes; a recent one stays; one still being written stays.
  std::ofstream(dir / "recordings" / "old.mcap") << std::string(1000, 'x');
  std::ofstream(dir / "recordings" / "active.mcap") << std::string(1000, 'x');
  std::ofstream(dir / "recordings" / "notes.txt") << "not a recording";
  const auto long_ago = fs::file_time_type::clock::now() - std::chrono::hours(24 * 40);
  fs::last_write_time(dir / "recordings" / "old.mcap", long_ago);
  fs::last_write_time(dir / "recordings" / "active.mcap", long_ago);
  // A plain recording an earlier run left (stopped without finishing it) is encrypted first,
  // keeping its age.
  std::ofstream(dir / "recordings" / "left.mcap") << std::string(800, 'y');
  fs::last_write_time(dir / "recordings" / "left.mcap", fs::file_time_type::clock::now() - std::chrono::hours(2));
  auto outcome = apply_recording_retention(config, {"active.mcap"});
  ASSERT_TRUE(outcome.ok()) << outcome.error().message;
  EXPECT_EQ(outcome->deleted, std::vector<std::string>{"old.mcap.enc"});
  EXPECT_TRUE(fs::exists(dir / "recordings" / "s2.mcap.enc"));
  EXPECT_TRUE(fs::exists(dir / "recordings" / "active.mcap"));  // being written: untouched
  EXPECT_TRUE(fs::exists(dir / "recordings" / "notes.txt"));
  EXPECT_FALSE(fs::exists(dir / "recordings" / "left.mcap"));
  ASSERT_TRUE(crypto::is_encrypted_file((dir / "recordings" / "left.mcap.enc").string()));
  EXPECT_LT(fs::last_write_time(dir / "recordings" / "left.mcap.enc"), fs::file_time_type::clock::now() - std::chrono::minutes(90));
  ASSERT_TRUE(crypto::decrypt_file((dir / "recordings" / "left.mcap.enc").string(), (dir / "left.mcap").string(), {*config.key}).ok());
  std::string left_bytes;
  std::getline(std::ifstream(dir / "left.mcap"), left_bytes);
  EXPECT_EQ(left_bytes, std::string(800, 'y'));
  fs::remove(dir / "recordings" / "left.mcap.enc");
  // A size cap deletes the oldest finished recordings first.
  std::ofstream(dir / "recordings" / "older.mcap") << std::string(5000, 'x');
  fs::last_write_time(dir / "recordings" / "older.mcap", fs::file_time_type::clock::now() - std::chrono::hours(1));
  config.max_total_bytes = fs::file_size(dir / "recordings" / "s2.mcap.enc") + 100;
  outcome = apply_recording_retention(config, {"active.mcap"});
  ASSERT_TRUE(outcome.ok());
  EXPECT_EQ(outcome->deleted, std::vector<std::string>{"older.mcap.enc"});
  EXPECT_TRUE(fs::exists(dir / "recordings" / "s2.mcap.enc"));
  fs::remove_all(dir);
}

// With an archive store (S3 here), finished recordings move there; an upload that fails leaves
// the recording in the folder, still served, until a retention pass stores it; retention then
// applies to the archive.
TEST(SessionRecording, FinishedRecordingsMoveToTheObjectStoreAndRetentionAppliesThere) {
  const fs::path dir = testing::scratch_dir();
  hanzo::fusion::testing::LocalS3Server s3(dir / "s3", "fleet");
  ASSERT_EQ(s3.error(), "");
  RecordingConfig config;
  config.directory = (dir / "recordings").string();
  config.key = crypto::EncryptionKey::generate();
  config.archive = std::move(object_store::open_s3_object_store(s3.config("site-a")).value());
  const auto record = [&](const RecordingConfig& with, const std::string& id) {
    auto recording = SessionRecording::start(with, id, std::nullopt);
    EXPECT_TRUE(recording.ok());
    for (int i = 0; i < 50; ++i) (*recording)->record("/imu", "imu", imu_at(kStart + Duration::from_milliseconds(10 * i)));
    const Status finished = (*recording)->finish();
    return std::make_pair(finished, (*recording)->info());
  };
  const auto [finished, info] = record(config, "s3-session");
  ASSERT_TRUE(finished) << finished.error().message;
  EXPECT_TRUE(info.archived);
  EXPECT_EQ(info.location, "s3://fleet/site-a/recordings/s3-session.mcap.enc");
  EXPECT_FALSE(fs::exists(dir / "recordings" / "s3-session.mcap.enc"));
  auto stored = find_recording(config, "s3-session.mcap.enc");
  ASSERT_TRUE(stored) << stored.error().message;
  EXPECT_EQ(stored->bytes, info.bytes);
  ASSERT_TRUE(stored->store->get_to_file(stored->key, (dir / "download.enc").string()));
  ASSERT_TRUE(crypto::decrypt_file((dir / "download.enc").string(), (dir / "download.mcap").string(), {*config.key}));
  EXPECT_EQ(read_log((dir / "download.mcap").string()).size(), 50u);

  // The object store is down: the recording stays in the folder and is served from there.
  RecordingConfig unreachable = config;
  object_store::S3Config nowhere = s3.config("site-a");
  nowhere.endpoint = "http://127.0.0.1:9";
  nowhere.max_attempts = 1;
  unreachable.archive = std::move(object_store::open_s3_object_store(nowhere).value());
  const auto [failed, kept] = record(unreachable, "offline-session");
  ASSERT_FALSE(failed);
  EXPECT_THAT(failed.error().message, HasSubstr("archive: "));
  EXPECT_FALSE(kept.archived);
  ASSERT_TRUE(fs::exists(dir / "recordings" / "offline-session.mcap.enc"));
  EXPECT_EQ(find_recording(unreachable, "offline-session.mcap.enc")->store->location(), "file://" + (dir / "recordings").string());
  // Back online, the next retention pass stores it.
  ASSERT_TRUE(apply_recording_retention(config, {}));
  EXPECT_FALSE(fs::exists(dir / "recordings" / "offline-session.mcap.enc"));
  EXPECT_TRUE(find_recording(config, "offline-session.mcap.enc")->store->location().starts_with("s3://"));

  // Retention over the archive: a size cap below both deletes the older first.
  config.max_total_bytes = info.bytes + 10;
  auto outcome = apply_recording_retention(config, {});
  ASSERT_TRUE(outcome) << outcome.error().message;
  EXPECT_EQ(outcome->deleted.size(), 1u);
  auto missing = find_recording(config, outcome->deleted.front());
  ASSERT_FALSE(missing);
  EXPECT_EQ(missing.error().field, object_store::kNotFound);
  fs::remove_all(dir);
}

TEST(SessionRecording, SessionsRecordWhenAskedAndRefuseWhatTheServerDoesNotAllow) {
  const fs::path dir = testing::scratch_dir();
  auto storage = open_storage("sqlite://" + (dir / "fusion.db").string());
  ASSERT_TRUE(storage.ok());
  SessionManagerConfig config;
  config.recording.directory = (dir / "recordings").string();
  auto metrics = std::make_shared<MetricsRegistry>();
  auto manager = SessionManager::create(config, std::move(storage).value(), metrics);
  ASSERT_TRUE(manager.ok()) << manager.error().message;
  const std::string fusion_yaml = testing::read_text("examples/data/fusion.yaml");

  CreateSessionRequest plain{"plain", fusion_yaml, ""};
  auto unrecorded = (*manager)->create_session(kRobot, plain);
  ASSERT_TRUE(unrecorded.ok());
  EXPECT_FALSE(unrecorded->recording.has_value());  // the server's default: not recorded
  EXPECT_EQ((*manager)->recording(kRobot, unrecorded->id).error().code, ErrorCode::kNotFound);

  CreateSessionRequest unfiltered{"unfiltered", fusion_yaml, ""};
  unfiltered.record = true;
  unfiltered.privacy = "off";
  auto refused = (*manager)->create_session(kRobot, unfiltered);
  ASSERT_FALSE(refused.ok());
  EXPECT_EQ(refused.error().field, "privacy");
  unfiltered.privacy = "pixelate";
  EXPECT_THAT((*manager)->create_session(kRobot, unfiltered).error().message, HasSubstr("privacy"));

  CreateSessionRequest recorded{"recorded", fusion_yaml, ""};
  recorded.record = true;
  auto session = (*manager)->create_session(kRobot, recorded);
  ASSERT_TRUE(session.ok()) << session.error().message;
  ASSERT_TRUE(session->recording.has_value());
  EXPECT_EQ(session->recording->privacy, "blur");
  const std::vector<testing::TimedMessage> sample = testing::sample_recording();
  for (const testing::TimedMessage& message : sample) ASSERT_TRUE((*manager)->push(kRobot, session->id, message.sensor, message.message).ok());
  EXPECT_EQ((*manager)->recording(kRobot, session->id).error().code, ErrorCode::kConflict);  // still being written
  EXPECT_THAT(metrics->render(), HasSubstr(fmt::format("hanzo_fusion_recorded_messages_total{{session=\"{}\"}}", session->id)));
  auto ended = (*manager)->end_session(kRobot, session->id);
  ASSERT_TRUE(ended.ok());
  EXPECT_EQ(ended->recording->messages, sample.size());
  auto stored = (*manager)->recording(kRobot, session->id);
  ASSERT_TRUE(stored.ok()) << stored.error().message;
  const std::vector<io::LogEntry> entries = read_log(stored->store->location_of(stored->key));
  ASSERT_EQ(entries.size(), sample.size());
  EXPECT_EQ(entries.front().topic, "/imu");  // the configuration's topics

  // The recording replays into a session like the original pushes.
  auto again = (*manager)->create_session(kRobot, plain);
  ASSERT_TRUE(again.ok());
  for (const io::LogEntry& entry : entries) {
    ASSERT_TRUE((*manager)->push(kRobot, again->id, entry.topic.substr(1), std::get<msgs::SensorMessage>(entry.message)).ok());
  }
  auto replayed = (*manager)->end_session(kRobot, again->id);
  ASSERT_TRUE(replayed.ok());
  EXPECT_EQ(replayed->summary.poses, ended->summary.poses);

  // Without a recordings folder a session cannot record.
  auto storage_without = open_storage("sqlite://" + (dir / "other.db").string());
  ASSERT_TRUE(storage_without.ok());
  auto without = SessionManager::create({}, std::move(storage_without).value(), std::make_shared<MetricsRegistry>());
  ASSERT_TRUE(without.ok());
  EXPECT_EQ((*without)->create_session(kRobot, recorded).error().field, "record");
  fs::remove_all(dir);
}

// A session still recording when the server stops: its log is finished (encrypted) at the stop
// and, after the restart, served for the session that goes on running unrecorded.
TEST(SessionRecording, ARecordingCutByAServerStopIsServedAfterTheRestart) {
  const fs::path dir = testing::scratch_dir();
  SessionManagerConfig config;
  config.recording.directory = (dir / "recordings").string();
  config.recording.key = crypto::EncryptionKey::generate();
  const std::string fusion_yaml = testing::read_text("examples/data/fusion.yaml");
  const std::vector<testing::TimedMessage> sample = testing::sample_recording();
  std::string id;
  {
    auto manager = SessionManager::create(config, open_storage("sqlite://" + (dir / "sessions.db").string()).value(), nullptr);
    ASSERT_TRUE(manager.ok()) << manager.error().message;
    CreateSessionRequest recorded{"recorded", fusion_yaml, ""};
    recorded.record = true;
    auto session = (*manager)->create_session(kRobot, recorded);
    ASSERT_TRUE(session.ok()) << session.error().message;
    id = session->id;
    for (const testing::TimedMessage& message : sample) ASSERT_TRUE((*manager)->push(kRobot, id, message.sensor, message.message).ok());
  }  // the server stops
  EXPECT_FALSE(fs::exists(dir / "recordings" / (id + ".mcap")));  // no plaintext left
  auto manager = SessionManager::create(config, open_storage("sqlite://" + (dir / "sessions.db").string()).value(), nullptr);
  ASSERT_TRUE(manager.ok()) << manager.error().message;
  auto restored = (*manager)->session_info(kRobot, id);
  ASSERT_TRUE(restored.ok());
  EXPECT_FALSE(restored->ended.has_value());
  auto stored = (*manager)->recording(kRobot, id);
  ASSERT_TRUE(stored.ok()) << stored.error().message;
  EXPECT_EQ(stored->key, id + ".mcap.enc");
  ASSERT_TRUE(crypto::decrypt_file(stored->store->location_of(stored->key), (dir / "plain.mcap").string(), {*config.recording.key}).ok());
  EXPECT_EQ(read_log((dir / "plain.mcap").string()).size(), sample.size());
  fs::remove_all(dir);
}

}  // namespace
}  // namespace hanzo::fusion::service
