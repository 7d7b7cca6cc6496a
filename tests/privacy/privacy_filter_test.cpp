// The privacy filter on real photos (../shared/data/privacy_faces, faces counted by eye) and real
// street images (KITTI raw 2011_09_26_drive_0052: cars with German plates, no faces close enough).
#include <algorithm>
#include <filesystem>
#include <map>
#include <fstream>
#include <string>

#include <unistd.h>

#include <gtest/gtest.h>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "hanzo/fusion/io/sensor_log.hpp"
#include "hanzo/fusion/privacy/log_redaction.hpp"
#include "hanzo/fusion/privacy/privacy_filter.hpp"

namespace hanzo::fusion::privacy {
namespace {

const std::string kFaces = std::string(HANZO_DATA_DIR) + "/privacy_faces/";

std::unique_ptr<PrivacyFilter> make_filter(PrivacyFilterConfig config = {}) {
  auto filter = PrivacyFilter::create(config);
  EXPECT_TRUE(filter.ok()) << (filter.ok() ? "" : filter.error().message);
  return filter ? std::move(filter).value() : nullptr;
}

int count(const std::vector<RedactedRegion>& regions, const std::string& kind) {
  return static_cast<int>(std::count_if(regions.begin(), regions.end(), [&](const RedactedRegion& r) { return r.kind == kind; }));
}

bool covers(const std::vector<RedactedRegion>& regions, const cv::Point& point) {
  return std::any_of(regions.begin(), regions.end(), [&](const RedactedRegion& r) { return r.box.contains(point); });
}

TEST(PrivacyFilter, FindsEveryFaceOfTheTestPhotos) {
  auto filter = make_filter();
  ASSERT_NE(filter, nullptr);
  // SOURCE.md counts the faces; obama_and_biden.jpg shows a third, a girl's face cut by the
  // bottom edge (at about (1700, 1130)), which counts too.
  const std::vector<std::pair<std::string, int>> photos{
      {"obama.jpg", 1}, {"two_people.jpg", 2}, {"obama_and_biden.jpg", 3}, {"kit_with_rose.jpg", 2}, {"alex-lacamoire.png", 1}};
  for (const auto& [file, faces] : photos) {
    const cv::Mat image = cv::imread(kFaces + file);
    ASSERT_FALSE(image.empty()) << file;
    auto regions = filter->detect(image);
    ASSERT_TRUE(regions.ok()) << regions.error().message;
    EXPECT_EQ(count(*regions, "face"), faces) << file;
    EXPECT_EQ(count(*regions, "licence_plate"), 0) << file;
  }
  const cv::Mat both = cv::imread(kFaces + "obama_and_biden.jpg");
  auto regions = filter->detect(both);
  ASSERT_TRUE(regions.ok());
  EXPECT_TRUE(covers(*regions, {1230, 480}));  // Biden
  EXPECT_TRUE(covers(*regions, {840, 520}));   // Obama
  EXPECT_TRUE(covers(*regions, {1700, 1130}));
}

TEST(PrivacyFilter, FindsFacesDownTo24PixelsAndInGreyImages) {
  auto filter = make_filter();
  ASSERT_NE(filter, nullptr);
  const cv::Mat image = cv::imread(kFaces + "two_people.jpg");
  ASSERT_FALSE(image.empty());
  // The faces are about 150 px wide: scaled to 24, 32 and 64 px.
  for (const double face_width : {24.0, 32.0, 64.0}) {
    cv::Mat small;
    cv::resize(image, small, cv::Size(), face_width / 150.0, face_width / 150.0, cv::INTER_AREA);
    auto regions = filter->detect(small);
    ASSERT_TRUE(regions.ok());
    EXPECT_EQ(count(*regions, "face"), 2) << face_width << " px faces in a " << small.cols << " x " << small.rows << " image";
  }
  cv::Mat grey;
  cv::cvtColor(image, grey, cv::COLOR_BGR2GRAY);
  auto regions = filter->detect(grey);
  ASSERT_TRUE(regions.ok());
  EXPECT_EQ(count(*regions, "face"), 2);
}

TEST(PrivacyFilter, FindsLicencePlatesAndNoFacesInStreetImages) {
  auto filter = make_filter();
  ASSERT_NE(filter, nullptr);
  const std::string folder = std::string(HANZO_DATA_DIR) + "/kitti_raw_0052/image_02/";
  // Frame 50: the car ahead (plate "KA JS 6312" at about (660, 318)) and a truck's plate at the
  // left edge (about (70, 332)).
  const cv::Mat frame = cv::imread(folder + "0000000050.png");
  ASSERT_FALSE(frame.empty());
  auto regions = filter->detect(frame);
  ASSERT_TRUE(regions.ok());
  EXPECT_TRUE(covers(*regions, {660, 318}));
  EXPECT_TRUE(covers(*regions, {70, 332}));
  int faces = 0, frames = 0;
  for (const auto& entry : std::filesystem::directory_iterator(folder)) {
    const cv::Mat image = cv::imread(entry.path().string());
    if (image.empty()) continue;
    auto found = filter->detect(image);
    ASSERT_TRUE(found.ok());
    faces += count(*found, "face");
    ++frames;
  }
  EXPECT_GT(frames, 50);
  EXPECT_EQ(faces, 0);
}

TEST(PrivacyFilter, BlursOrBlacksOutOnlyTheRegions) {
  const cv::Mat original = cv::imread(kFaces + "obama.jpg");
  ASSERT_FALSE(original.empty());
  for (const Redaction redaction : {Redaction::kBlur, Redaction::kBlackOut}) {
    PrivacyFilterConfig config;
    config.redaction = redaction;
    auto filter = make_filter(config);
    ASSERT_NE(filter, nullptr);
    cv::Mat image = original.clone();
    auto regions = filter->apply(image);
    ASSERT_TRUE(regions.ok());
    ASSERT_EQ(regions->size(), 1U);
    const cv::Rect face = regions->front().box;
    // Inside the face: black, or blurred (the detail, the Laplacian's spread, gone).
    const auto detail = [](const cv::Mat& pixels) {
      cv::Mat grey, laplacian;
      cv::cvtColor(pixels, grey, cv::COLOR_BGR2GRAY);
      cv::Laplacian(grey, laplacian, CV_64F);
      cv::Scalar mean, deviation;
      cv::meanStdDev(laplacian, mean, deviation);
      return deviation[0];
    };
    if (redaction == Redaction::kBlackOut) {
      EXPECT_EQ(cv::countNonZero(image(face).reshape(1)), 0);
    } else {
      EXPECT_LT(detail(image(face)), 0.1 * detail(original(face)));
    }
    // Outside the enlarged region nothing changed.
    cv::Mat changed;
    cv::absdiff(image, original, changed);
    cv::Mat mask = cv::Mat::ones(image.size(), CV_8U);
    const int dx = face.width / 10 + 1, dy = face.height / 10 + 1;
    mask(cv::Rect(face.x - dx, face.y - dy, face.width + 2 * dx, face.height + 2 * dy) & cv::Rect(0, 0, image.cols, image.rows)).setTo(0);
    std::vector<cv::Mat> channels;
    cv::split(changed, channels);
    const cv::Mat outside = mask * 255;
    for (const cv::Mat& channel : channels) EXPECT_EQ(cv::countNonZero(channel & outside), 0) << to_string(redaction);
  }
}

TEST(PrivacyFilter, RefusesBadInputWithAReason) {
  auto filter = make_filter();
  ASSERT_NE(filter, nullptr);
  cv::Mat empty;
  auto refused = filter->apply(empty);
  ASSERT_FALSE(refused.ok());
  EXPECT_NE(refused.error().message.find("empty"), std::string::npos);
  cv::Mat floating(100, 100, CV_32FC3, cv::Scalar::all(0.5));
  refused = filter->apply(floating);
  ASSERT_FALSE(refused.ok());
  EXPECT_NE(refused.error().message.find("8-bit"), std::string::npos);
  PrivacyFilterConfig config;
  config.face_model_path = "/nonexistent/yunet.onnx";
  auto missing = PrivacyFilter::create(config);
  ASSERT_FALSE(missing.ok());
  EXPECT_NE(missing.error().message.find("/nonexistent/yunet.onnx"), std::string::npos);
  config = {};
  config.face_score_threshold = 1.5;
  EXPECT_FALSE(PrivacyFilter::create(config).ok());
  EXPECT_FALSE(parse_redaction("pixelate").ok());
  EXPECT_EQ(parse_redaction("black").value(), Redaction::kBlackOut);
}

msgs::ImageMessage image_message(const cv::Mat& bgr, msgs::ImageEncoding encoding, Timestamp time) {
  cv::Mat pixels;  // a buffer of its own: converting into a header sharing `bgr` would change the photo
  if (encoding == msgs::ImageEncoding::kRgb8) {
    cv::cvtColor(bgr, pixels, cv::COLOR_BGR2RGB);
  } else {
    pixels = bgr;
  }
  msgs::ImageMessage message;
  message.timestamp = time;
  message.frame_id = "camera";
  message.width = static_cast<uint32_t>(pixels.cols);
  message.height = static_cast<uint32_t>(pixels.rows);
  message.encoding = encoding;
  message.data.assign(pixels.data, pixels.data + pixels.total() * pixels.elemSize());
  return message;
}

// A log with the two-people photo as a bgr8 and an rgb8 camera image, an IMU message and a
// metadata record: the faces are blurred in both encodings, the rest is copied exactly.
TEST(LogRedaction, BlursTheCameraImagesOfASensorLogAndCopiesTheRest) {
  const std::filesystem::path dir = std::filesystem::temp_directory_path() / ("hanzo_privacy_log_" + std::to_string(::getpid()));
  std::filesystem::remove_all(dir);
  std::filesystem::create_directories(dir);
  const std::string input = (dir / "in.mcap").string(), output = (dir / "out.mcap").string();
  cv::Mat photo = cv::imread(kFaces + "two_people.jpg");
  ASSERT_FALSE(photo.empty());
  cv::resize(photo, photo, cv::Size(), 0.5, 0.5, cv::INTER_AREA);
  const Timestamp start = Timestamp::from_seconds(1700000000.0);
  msgs::ImuMessage imu;
  imu.timestamp = start;
  imu.frame_id = "imu";
  imu.angular_velocity = Eigen::Vector3d(0.1, -0.2, 0.3);
  imu.linear_acceleration = Eigen::Vector3d(0.0, 0.1, 9.81);
  {
    auto writer = io::SensorLogWriter::open(input).value();
    ASSERT_TRUE(writer->add_metadata({"calibration", {{"camera_to_body", "identity"}}}).ok());
    ASSERT_TRUE(writer->write("/imu", msgs::SensorMessage(imu)).ok());
    ASSERT_TRUE(writer->write("/camera", msgs::SensorMessage(image_message(photo, msgs::ImageEncoding::kBgr8, start + Duration::from_seconds(0.1))),
                              "front_camera").ok());
    ASSERT_TRUE(writer->write("/camera", msgs::SensorMessage(image_message(photo, msgs::ImageEncoding::kRgb8, start + Duration::from_seconds(0.2))),
                              "front_camera").ok());
    ASSERT_TRUE(writer->close().ok());
  }
  auto filter = make_filter();
  ASSERT_NE(filter, nullptr);
  auto summary = redact_log(*filter, input, output, {});
  ASSERT_TRUE(summary.ok()) << summary.error().message;
  EXPECT_EQ(summary->messages, 3U);
  EXPECT_EQ(summary->total.images, 2U);
  EXPECT_EQ(summary->total.redacted_images, 2U);
  EXPECT_EQ(summary->total.faces, 4U);
  EXPECT_EQ(summary->by_topic.at("/camera").faces, 4U);
  EXPECT_FALSE(std::filesystem::exists(output + ".partial"));

  auto reader = io::SensorLogReader::open(output).value();
  const std::vector<io::mcap::Metadata>& metadata = reader->mcap().metadata();
  ASSERT_EQ(metadata.size(), 2U);  // the log format's record and the copied one
  const auto calibration = std::find_if(metadata.begin(), metadata.end(), [](const io::mcap::Metadata& m) { return m.name == "calibration"; });
  ASSERT_NE(calibration, metadata.end());
  EXPECT_EQ(calibration->values.at("camera_to_body"), "identity");
  EXPECT_EQ(reader->mcap().channel_by_topic("/camera")->metadata.at("sensor"), "front_camera");
  io::LogEntry entry;
  int images = 0;
  std::map<msgs::ImageEncoding, std::vector<uint8_t>> written_by_encoding;
  while (reader->next(entry).value()) {
    const auto& message = std::get<msgs::SensorMessage>(entry.message);
    if (const auto* copied = std::get_if<msgs::ImuMessage>(&message)) {
      EXPECT_EQ(copied->angular_velocity, imu.angular_velocity);
      EXPECT_EQ(copied->linear_acceleration, imu.linear_acceleration);
      continue;
    }
    const auto& image = std::get<msgs::ImageMessage>(message);
    const msgs::ImageMessage original = image_message(photo, image.encoding, entry.log_time);
    ASSERT_EQ(image.data.size(), original.data.size());
    EXPECT_NE(image.data, original.data);
    written_by_encoding[image.encoding] = image.data;
    // The redacted image has no face left.
    cv::Mat pixels(static_cast<int>(image.height), static_cast<int>(image.width), CV_8UC3, const_cast<uint8_t*>(image.data.data()));
    cv::Mat bgr = pixels.clone();
    if (image.encoding == msgs::ImageEncoding::kRgb8) cv::cvtColor(pixels, bgr, cv::COLOR_RGB2BGR);  // into the clone's own buffer
    EXPECT_EQ(count(filter->detect(bgr).value(), "face"), 0) << msgs::to_string(image.encoding);
    ++images;
  }
  EXPECT_EQ(images, 2);
  // The rgb8 image comes back in its own channel order: swapped to BGR it is the bgr8 one, blur
  // and all (the blur treats channels alike).
  const std::vector<uint8_t>& rgb = written_by_encoding[msgs::ImageEncoding::kRgb8];
  const std::vector<uint8_t>& bgr = written_by_encoding[msgs::ImageEncoding::kBgr8];
  ASSERT_EQ(rgb.size(), bgr.size());
  std::size_t differing = 0;
  for (std::size_t i = 0; i + 2 < rgb.size(); i += 3) differing += rgb[i] != bgr[i + 2] || rgb[i + 1] != bgr[i + 1] || rgb[i + 2] != bgr[i];
  EXPECT_EQ(differing, 0u);

  // Refused: the input as output, a file that is not a log; no output file is left behind. A
  // log cut off is redacted as far as it reads, with the reader's warning.
  EXPECT_FALSE(redact_log(*filter, input, input, {}).ok());
  const std::string text = (dir / "text.mcap").string();
  std::ofstream(text) << "not a log";
  const std::string never = (dir / "never.mcap").string();
  auto refused = redact_log(*filter, text, never, {});
  ASSERT_FALSE(refused.ok());
  EXPECT_NE(refused.error().message.find("magic"), std::string::npos) << refused.error().message;
  EXPECT_FALSE(std::filesystem::exists(never));
  EXPECT_FALSE(std::filesystem::exists(never + ".partial"));
  const std::string cut = (dir / "cut.mcap").string();
  std::filesystem::copy_file(input, cut);
  std::filesystem::resize_file(cut, std::filesystem::file_size(input) - 200);
  auto recovered = redact_log(*filter, cut, (dir / "cut_out.mcap").string(), {});
  ASSERT_TRUE(recovered.ok()) << recovered.error().message;
  EXPECT_TRUE(recovered->input_warning.has_value());
  std::filesystem::remove_all(dir);
}

}  // namespace
}  // namespace hanzo::fusion::privacy
