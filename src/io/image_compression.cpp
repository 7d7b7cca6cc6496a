#include "image_compression.hpp"

#include "hanzo/fusion/io/image_file_check.hpp"

#include <algorithm>

#include <fmt/format.h>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "hanzo/fusion/msgs/convert.hpp"

namespace hanzo::fusion::io {
namespace {

// OpenCV's type of an encoding's pixels; -1 for those no compressed format here holds.
int opencv_type(msgs::ImageEncoding encoding) {
  switch (encoding) {
    case msgs::ImageEncoding::kRgb8:
    case msgs::ImageEncoding::kBgr8: return CV_8UC3;
    case msgs::ImageEncoding::kMono8: return CV_8UC1;
    case msgs::ImageEncoding::kDepth16: return CV_16UC1;
    case msgs::ImageEncoding::kDepth32f: return -1;
  }
  return -1;
}

}  // namespace

v1::ImageMessage compressed_image(const msgs::ImageMessage& image, ImageCompression compression, int jpeg_quality) {
  v1::ImageMessage proto = msgs::to_proto(image);
  const int type = opencv_type(image.encoding);
  const bool jpeg = compression == ImageCompression::kJpeg && type != -1 && image.encoding != msgs::ImageEncoding::kDepth16;
  const bool png = compression == ImageCompression::kPng && type != -1;
  if (!jpeg && !png) return proto;
  cv::Mat pixels(static_cast<int>(image.height), static_cast<int>(image.width), type, const_cast<uint8_t*>(image.data.data()));
  cv::Mat bgr;
  if (image.encoding == msgs::ImageEncoding::kRgb8) {
    cv::cvtColor(pixels, bgr, cv::COLOR_RGB2BGR);  // OpenCV writes files from BGR
    pixels = bgr;
  }
  std::vector<uint8_t> file;
  const std::vector<int> parameters =
      jpeg ? std::vector<int>{cv::IMWRITE_JPEG_QUALITY, std::clamp(jpeg_quality, 1, 100)} : std::vector<int>{cv::IMWRITE_PNG_COMPRESSION, 3};
  if (!cv::imencode(jpeg ? ".jpg" : ".png", pixels, file, parameters)) return proto;
  proto.set_data(file.data(), file.size());
  proto.set_compression(jpeg ? "jpeg" : "png");
  return proto;
}

Status decompress_image(v1::ImageMessage& image) {
  if (image.compression().empty()) return ok_status();
  if (image.compression() != "png" && image.compression() != "jpeg") {
    return Error(fmt::format("compression '{}': expected png or jpeg", image.compression()), "compression");
  }
  const std::optional<msgs::ImageEncoding> encoding = msgs::image_encoding_from_string(image.encoding());
  if (!encoding || opencv_type(*encoding) == -1) {
    return Error(fmt::format("a {} image of encoding '{}': only rgb8, bgr8, mono8 and depth16 are stored compressed", image.compression(),
                             image.encoding()),
                 "encoding");
  }
  const std::string& data = image.data();
  if (Status complete = check_image_complete(data, "data"); !complete) return Error(complete.error().message, "data");
  cv::Mat decoded;
  try {
    decoded = cv::imdecode(cv::Mat(1, static_cast<int>(data.size()), CV_8UC1, const_cast<char*>(data.data())), cv::IMREAD_UNCHANGED);
  } catch (const cv::Exception&) {
    decoded = cv::Mat();
  }
  if (decoded.empty()) return Error(fmt::format("data: not a readable {} file", image.compression()), "data");
  if (decoded.type() != opencv_type(*encoding) || decoded.cols != static_cast<int>(image.width()) ||
      decoded.rows != static_cast<int>(image.height())) {
    return Error(fmt::format("data: the {} file holds {}x{} pixels of {} channel(s), {} bytes each; the message says {}x{} {}",
                             image.compression(), decoded.cols, decoded.rows, decoded.channels(), decoded.elemSize1(), image.width(),
                             image.height(), image.encoding()),
                 "data");
  }
  if (*encoding == msgs::ImageEncoding::kRgb8) cv::cvtColor(decoded, decoded, cv::COLOR_BGR2RGB);
  if (!decoded.isContinuous()) decoded = decoded.clone();
  image.set_data(decoded.data, decoded.total() * decoded.elemSize());
  image.clear_compression();
  return ok_status();
}

}  // namespace hanzo::fusion::io
