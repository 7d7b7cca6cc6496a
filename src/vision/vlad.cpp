#include "hanzo/fusion/vision/vlad.hpp"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <numeric>
#include <random>

#include <Eigen/Eigenvalues>
#include <fmt/format.h>

#include "hanzo/fusion/core/files.hpp"
#include "binary_file.hpp"

namespace hanzo::fusion::vision {
namespace {

constexpr char kMagic[8] = {'H', 'Z', 'V', 'L', 'A', 'D', '\0', '\0'};
constexpr uint32_t kVersion = 1;

using binary_file::put;
using binary_file::take;

Status check_descriptors(const cv::Mat& descriptors, int width) {
  if (descriptors.empty()) return ok_status();
  if (descriptors.type() != CV_32FC1) return Error(fmt::format("descriptors of type {}: VLAD aggregates float (learned) descriptors", cv::typeToString(descriptors.type())));
  if (width > 0 && descriptors.cols != width) return Error(fmt::format("descriptors of {} floats, the model's are {}", descriptors.cols, width));
  return ok_status();
}

}  // namespace

std::vector<PlaceMatch> rank_places(const std::vector<Eigen::VectorXf>& vectors, const Eigen::VectorXf& query, int count, int before, double min_score) {
  std::vector<PlaceMatch> matches;
  for (int entry = 0; entry < std::min(before, static_cast<int>(vectors.size())); ++entry) {
    const double score = VladModel::similarity(query, vectors[static_cast<std::size_t>(entry)]);
    if (score >= min_score) matches.push_back({entry, score});
  }
  std::sort(matches.begin(), matches.end(), [](const PlaceMatch& a, const PlaceMatch& b) { return a.score > b.score; });
  if (static_cast<int>(matches.size()) > count) matches.resize(static_cast<std::size_t>(std::max(count, 0)));
  return matches;
}

Status validate(const VladConfig& config) {
  if (config.clusters < 2 || config.clusters > 1024) return Error("VladConfig.clusters: must be in 2..1024", "clusters");
  if (config.dimensions < 1) return Error("VladConfig.dimensions: must be at least 1", "dimensions");
  if (config.kmeans_iterations < 1 || config.kmeans_attempts < 1) return Error("VladConfig.kmeans_iterations / kmeans_attempts: must be at least 1", "kmeans_iterations");
  if (config.max_kmeans_descriptors < config.clusters) return Error("VladConfig.max_kmeans_descriptors: must be at least clusters", "max_kmeans_descriptors");
  return ok_status();
}

Eigen::VectorXf VladModel::aggregate(const cv::Mat& descriptors) const {
  const int clusters = this->clusters(), size = descriptor_size();
  Eigen::VectorXf vlad = Eigen::VectorXf::Zero(static_cast<Eigen::Index>(clusters) * size);
  for (int row = 0; row < descriptors.rows; ++row) {
    const Eigen::Map<const Eigen::VectorXf> x(descriptors.ptr<float>(row), size);
    Eigen::Index nearest = 0;
    (centres_.rowwise() - x.transpose()).rowwise().squaredNorm().minCoeff(&nearest);
    vlad.segment(nearest * size, size) += x - centres_.row(nearest).transpose();
  }
  for (int k = 0; k < clusters; ++k) {  // intra-normalization
    const float norm = vlad.segment(static_cast<Eigen::Index>(k) * size, size).norm();
    if (norm > 0.0F) vlad.segment(static_cast<Eigen::Index>(k) * size, size) /= norm;
  }
  const float norm = vlad.norm();
  if (norm > 0.0F) vlad /= norm;
  return vlad;
}

Result<Eigen::VectorXf> VladModel::describe(const cv::Mat& descriptors) const {
  HANZO_RETURN_IF_ERROR(check_descriptors(descriptors, descriptor_size()));
  if (descriptors.empty()) return Eigen::VectorXf(Eigen::VectorXf::Zero(dimensions()));
  Eigen::VectorXf projected = projection_ * (aggregate(descriptors) - mean_);
  const float norm = projected.norm();
  if (norm > 0.0F) projected /= norm;
  return projected;
}

Result<VladModel> VladModel::train(const std::vector<cv::Mat>& image_descriptors, const std::string& extractor_name, const VladConfig& config) {
  HANZO_RETURN_IF_ERROR(validate(config));
  int width = 0, images = 0, total = 0;
  for (const cv::Mat& descriptors : image_descriptors) {
    HANZO_RETURN_IF_ERROR(check_descriptors(descriptors, width));
    if (descriptors.empty()) continue;
    width = descriptors.cols;
    ++images;
    total += descriptors.rows;
  }
  if (images < config.dimensions + 1) {
    return Error(fmt::format("{} images with descriptors: {} dimensions need at least {}", images, config.dimensions, config.dimensions + 1));
  }
  if (total < config.clusters) return Error(fmt::format("{} descriptors: fewer than the {} clusters", total, config.clusters));
  const int vlad_size = config.clusters * width;
  if (config.dimensions > vlad_size) return Error(fmt::format("VladConfig.dimensions {}: more than the {} of the VLAD vector", config.dimensions, vlad_size));

  // Centres: k-means++ on (a random subset of) every descriptor.
  cv::Mat all;
  for (const cv::Mat& descriptors : image_descriptors) {
    if (!descriptors.empty()) all.push_back(descriptors);
  }
  std::mt19937_64 random(config.seed);
  if (all.rows > config.max_kmeans_descriptors) {
    std::vector<int> order(static_cast<std::size_t>(all.rows));
    std::iota(order.begin(), order.end(), 0);
    std::shuffle(order.begin(), order.end(), random);
    cv::Mat subset(config.max_kmeans_descriptors, width, CV_32FC1);
    for (int i = 0; i < subset.rows; ++i) all.row(order[static_cast<std::size_t>(i)]).copyTo(subset.row(i));
    all = subset;
  }
  cv::setRNGSeed(static_cast<int>(config.seed));
  cv::Mat labels, centres;
  cv::kmeans(all, config.clusters, labels, cv::TermCriteria(cv::TermCriteria::COUNT + cv::TermCriteria::EPS, config.kmeans_iterations, 1e-4),
             config.kmeans_attempts, cv::KMEANS_PP_CENTERS, centres);
  VladModel model;
  model.extractor_name_ = extractor_name;
  model.training_images_ = images;
  model.centres_ = Eigen::Map<const RowMatrix>(centres.ptr<float>(), config.clusters, width);

  // Projection: PCA of the training images' VLAD vectors, whitened (regularized).
  Eigen::MatrixXd vlads(images, vlad_size);
  int row = 0;
  for (const cv::Mat& descriptors : image_descriptors) {
    if (!descriptors.empty()) vlads.row(row++) = model.aggregate(descriptors).cast<double>().transpose();
  }
  const Eigen::RowVectorXd mean = vlads.colwise().mean();
  vlads.rowwise() -= mean;
  // The eigenvectors of the images' Gram matrix give those of the covariance (images < dimensions).
  const Eigen::MatrixXd gram = vlads * vlads.transpose() / static_cast<double>(images - 1);
  const Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> eigen(gram);
  const Eigen::VectorXd& values = eigen.eigenvalues();  // ascending
  const double regularization = values.tail(config.dimensions).mean() / 10.0;
  model.projection_.resize(config.dimensions, vlad_size);
  for (int d = 0; d < config.dimensions; ++d) {
    const Eigen::Index index = images - 1 - d;
    const double value = std::max(values(index), 0.0);
    Eigen::VectorXd direction = vlads.transpose() * eigen.eigenvectors().col(index);
    const double length = direction.norm();
    if (length > 0.0) direction /= length;
    model.projection_.row(d) = (direction / std::sqrt(value + regularization)).cast<float>().transpose();
  }
  model.mean_ = mean.transpose().cast<float>();
  return model;
}

Result<VladModel> VladModel::load_default(const std::string& extractor_name) {
  const Result<std::string> path = find_model_file("vlad_" + extractor_name + ".hzvlad", HANZO_INSTALLED_MODELS_DIR, HANZO_SOURCE_MODELS_DIR "/trained");
  if (!path) return Error(fmt::format("the trained place-recognition model for {}: {}", extractor_name, path.error().message));
  Result<VladModel> model = load(*path);
  if (model && model->extractor_name() != extractor_name) {
    return Error(fmt::format("{}: trained on {} descriptors, not {}", *path, model->extractor_name(), extractor_name));
  }
  return model;
}

Status VladModel::save(const std::string& path) const {
  std::string out(kMagic, sizeof(kMagic));
  put<uint32_t>(out, kVersion);
  put<uint32_t>(out, static_cast<uint32_t>(extractor_name_.size()));
  out += extractor_name_;
  for (const int value : {clusters(), descriptor_size(), dimensions(), training_images_}) put<uint32_t>(out, static_cast<uint32_t>(value));
  const auto append = [&out](const float* data, Eigen::Index count) { out.append(reinterpret_cast<const char*>(data), static_cast<std::size_t>(count) * 4); };
  append(centres_.data(), centres_.size());
  append(mean_.data(), mean_.size());
  append(projection_.data(), projection_.size());
  put<uint32_t>(out, binary_file::crc32_of(out, out.size()));
  const std::string partial = path + ".partial";
  return commit_partial_file(partial, path, write_file_durably(partial, out));
}

Result<VladModel> VladModel::load(const std::string& path) {
  Result<std::string> read = read_file(path);
  if (!read) return read.error();
  const std::string& bytes = *read;
  if (bytes.size() < sizeof(kMagic) + 8 || std::memcmp(bytes.data(), kMagic, sizeof(kMagic)) != 0) {
    return Error(fmt::format("{}: not a hanzo-fusion VLAD model (magic bytes differ)", path));
  }
  std::size_t offset = sizeof(kMagic);
  const auto version = take<uint32_t>(bytes, offset);
  if (version != kVersion) return Error(fmt::format("{}: VLAD model version {} is not supported (this build reads version {})", path, version, kVersion));
  const auto name_size = take<uint32_t>(bytes, offset);
  if (name_size > 64 || bytes.size() < offset + name_size + 16 + 4) return Error(fmt::format("{}: truncated header", path));
  VladModel model;
  model.extractor_name_ = bytes.substr(offset, name_size);
  offset += name_size;
  const auto clusters = static_cast<Eigen::Index>(take<uint32_t>(bytes, offset));
  const auto size = static_cast<Eigen::Index>(take<uint32_t>(bytes, offset));
  const auto dimensions = static_cast<Eigen::Index>(take<uint32_t>(bytes, offset));
  model.training_images_ = static_cast<int>(take<uint32_t>(bytes, offset));
  if (clusters < 2 || clusters > 1024 || size < 1 || size > 1024 || dimensions < 1 || dimensions > clusters * size) {
    return Error(fmt::format("{}: header: {} clusters of {} floats projected to {} dimensions do not fit together", path, clusters, size, dimensions));
  }
  const std::size_t floats = static_cast<std::size_t>(clusters * size + clusters * size + dimensions * clusters * size);
  const std::size_t expected = offset + 4 * floats + 4;
  if (bytes.size() != expected) {
    return Error(fmt::format("{}: {} bytes, but the header's sizes need {} ({})", path, bytes.size(), expected, bytes.size() < expected ? "truncated" : "trailing bytes"));
  }
  uint32_t stored_crc;
  std::memcpy(&stored_crc, bytes.data() + bytes.size() - 4, 4);
  const uint32_t crc = binary_file::crc32_of(bytes, bytes.size() - 4);
  if (crc != stored_crc) return Error(fmt::format("{}: checksum mismatch (stored {:08x}, computed {:08x}): the file is corrupted", path, stored_crc, crc));
  const auto take_floats = [&](float* data, Eigen::Index count) {
    std::memcpy(data, bytes.data() + offset, static_cast<std::size_t>(count) * 4);
    offset += static_cast<std::size_t>(count) * 4;
  };
  model.centres_.resize(clusters, size);
  take_floats(model.centres_.data(), model.centres_.size());
  model.mean_.resize(clusters * size);
  take_floats(model.mean_.data(), model.mean_.size());
  model.projection_.resize(dimensions, clusters * size);
  take_floats(model.projection_.data(), model.projection_.size());
  if (!model.centres_.allFinite() || !model.mean_.allFinite() || !model.projection_.allFinite()) return Error(fmt::format("{}: non-finite values", path));
  return model;
}

}  // namespace hanzo::fusion::vision
