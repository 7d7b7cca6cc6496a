#include "hanzo/fusion/vision/vocabulary.hpp"

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <limits>
#include <numeric>
#include <random>

#include <fmt/format.h>

#include "hanzo/fusion/core/files.hpp"
#include "hanzo/fusion/vision/orb_extractor.hpp"
#include "binary_file.hpp"

namespace hanzo::fusion::vision {
namespace {

constexpr char kMagic[8] = {'H', 'Z', 'V', 'O', 'C', 'A', 'B', '\0'};
constexpr uint32_t kVersion = 1;
constexpr uint32_t kNoParent = 0xffffffffu;
constexpr std::size_t kDescriptorBytes = 32;
constexpr std::size_t kNodeBytes = 4 + kDescriptorBytes + 8;
constexpr const char* kDefaultFile = "orb_vocabulary.hzvoc";

bool is_orb_layout(const cv::Mat& descriptors) {
  return descriptors.empty() || (descriptors.type() == CV_8UC1 && descriptors.cols == static_cast<int>(kDescriptorBytes) && descriptors.isContinuous());
}

// Bitwise majority of the member descriptors (ties to 0: DBoW2's convention).
void majority(const std::vector<const unsigned char*>& descriptors, const std::vector<int>& members, unsigned char* centre) {
  int counts[kDescriptorBytes * 8] = {};
  for (int member : members) {
    const unsigned char* descriptor = descriptors[static_cast<std::size_t>(member)];
    for (std::size_t bit = 0; bit < kDescriptorBytes * 8; ++bit) counts[bit] += (descriptor[bit / 8] >> (bit % 8)) & 1;
  }
  std::memset(centre, 0, kDescriptorBytes);
  for (std::size_t bit = 0; bit < kDescriptorBytes * 8; ++bit) {
    if (2 * counts[bit] > static_cast<int>(members.size())) centre[bit / 8] |= static_cast<unsigned char>(1u << (bit % 8));
  }
}

using binary_file::put;
using binary_file::take;

}  // namespace

Status validate(const VocabularyConfig& config) {
  if (config.branching < 2 || config.branching > 64) return Error("VocabularyConfig.branching: must be in 2..64", "branching");
  if (config.levels < 1 || config.levels > 8) return Error("VocabularyConfig.levels: must be in 1..8", "levels");
  if (std::pow(static_cast<double>(config.branching), config.levels) > 1e7) return Error("VocabularyConfig: branching^levels must not exceed 10^7 words", "levels");
  if (config.max_iterations < 1) return Error("VocabularyConfig.max_iterations: must be at least 1", "max_iterations");
  return ok_status();
}

Result<Vocabulary> Vocabulary::train(const std::vector<cv::Mat>& image_descriptors, const VocabularyConfig& config, VocabularyTrainingSummary* summary) {
  if (Status valid = validate(config); !valid) return valid.error();
  std::vector<const unsigned char*> descriptors;
  std::vector<const cv::Mat*> images;
  for (std::size_t i = 0; i < image_descriptors.size(); ++i) {
    const cv::Mat& image = image_descriptors[i];
    if (!is_orb_layout(image)) return Error(fmt::format("image {}: descriptors must be continuous CV_8UC1 rows of 32 bytes (ORB), got type {} with {} columns", i, image.type(), image.cols));
    if (image.empty()) continue;
    images.push_back(&image);
    for (int row = 0; row < image.rows; ++row) descriptors.push_back(image.ptr<unsigned char>(row));
  }
  if (static_cast<int>(descriptors.size()) < config.branching) {
    return Error(fmt::format("{} descriptors in {} images: training needs at least branching = {}", descriptors.size(), images.size(), config.branching));
  }

  Vocabulary vocabulary;
  vocabulary.branching_ = config.branching;
  vocabulary.levels_ = config.levels;
  vocabulary.training_images_ = static_cast<int>(images.size());
  vocabulary.nodes_.emplace_back();  // the root
  std::mt19937_64 random(config.seed);
  int iterations = 0;

  // Breadth-first: each node's members split into `branching` clusters by k-majority.
  struct Pending {
    uint32_t node;
    std::vector<int> members;
    int level;
  };
  std::vector<Pending> queue;
  queue.push_back({0, std::vector<int>(descriptors.size()), 0});
  std::iota(queue.back().members.begin(), queue.back().members.end(), 0);
  for (std::size_t head = 0; head < queue.size(); ++head) {
    Pending pending = std::move(queue[head]);
    if (pending.level == config.levels) continue;
    const std::vector<int>& members = pending.members;
    std::vector<std::vector<int>> clusters;
    if (static_cast<int>(members.size()) <= config.branching) {
      for (int member : members) clusters.push_back({member});
    } else {
      // k-means++ seeding: the next centre drawn with probability proportional to the squared
      // distance to the nearest centre so far.
      std::vector<std::array<unsigned char, kDescriptorBytes>> centres;
      auto add_centre = [&](int member) {
        centres.emplace_back();
        std::memcpy(centres.back().data(), descriptors[static_cast<std::size_t>(member)], kDescriptorBytes);
      };
      add_centre(members[std::uniform_int_distribution<std::size_t>(0, members.size() - 1)(random)]);
      std::vector<double> nearest(members.size(), std::numeric_limits<double>::max());
      while (static_cast<int>(centres.size()) < config.branching) {
        double total = 0.0;
        for (std::size_t m = 0; m < members.size(); ++m) {
          const double distance = hamming_distance(descriptors[static_cast<std::size_t>(members[m])], centres.back().data());
          nearest[m] = std::min(nearest[m], distance * distance);
          total += nearest[m];
        }
        if (total <= 0.0) break;  // every member equals a centre already
        double draw = std::uniform_real_distribution<double>(0.0, total)(random);
        std::size_t chosen = 0;
        for (; chosen + 1 < members.size() && draw >= nearest[chosen]; ++chosen) draw -= nearest[chosen];
        add_centre(members[chosen]);
      }
      std::vector<int> assignment(members.size(), -1);
      for (int round = 0; round < config.max_iterations; ++round) {
        ++iterations;
        bool changed = false;
        clusters.assign(centres.size(), {});
        for (std::size_t m = 0; m < members.size(); ++m) {
          const unsigned char* descriptor = descriptors[static_cast<std::size_t>(members[m])];
          int best = 0, best_distance = std::numeric_limits<int>::max();
          for (std::size_t c = 0; c < centres.size(); ++c) {
            const int distance = hamming_distance(descriptor, centres[c].data());
            if (distance < best_distance) best = static_cast<int>(c), best_distance = distance;
          }
          changed |= assignment[m] != best;
          assignment[m] = best;
          clusters[static_cast<std::size_t>(best)].push_back(members[m]);
        }
        // An emptied cluster is dropped; the indices shift, so the next round counts as changed.
        if (std::erase_if(clusters, [](const std::vector<int>& cluster) { return cluster.empty(); }) > 0) {
          std::fill(assignment.begin(), assignment.end(), -1);
          changed = true;
        }
        centres.resize(clusters.size());
        for (std::size_t c = 0; c < clusters.size(); ++c) majority(descriptors, clusters[c], centres[c].data());
        if (!changed) break;
      }
    }
    for (std::vector<int>& cluster : clusters) {
      Node child;
      child.parent = pending.node;
      majority(descriptors, cluster, child.descriptor);
      const auto index = static_cast<uint32_t>(vocabulary.nodes_.size());
      vocabulary.nodes_.push_back(child);
      vocabulary.nodes_[pending.node].children.push_back(index);
      queue.push_back({index, std::move(cluster), pending.level + 1});
    }
  }
  vocabulary.index_words();

  // Inverse document frequency of each word over the training images.
  std::vector<int> documents(vocabulary.words_.size(), 0);
  std::vector<int> seen_in(vocabulary.words_.size(), -1);
  for (std::size_t i = 0; i < images.size(); ++i) {
    for (int row = 0; row < images[i]->rows; ++row) {
      const uint32_t word = vocabulary.word_of(images[i]->ptr<unsigned char>(row));
      if (seen_in[word] != static_cast<int>(i)) seen_in[word] = static_cast<int>(i), ++documents[word];
    }
  }
  for (std::size_t word = 0; word < vocabulary.words_.size(); ++word) {
    // A word no training descriptor descends to (a majority centre can differ from its members)
    // is as rare as possible.
    const double count = std::max(documents[word], 1);
    vocabulary.nodes_[vocabulary.words_[word]].weight = std::log(static_cast<double>(images.size()) / count);
  }
  if (summary != nullptr) *summary = {static_cast<int>(images.size()), static_cast<int>(descriptors.size()), vocabulary.words(), iterations};
  return vocabulary;
}

void Vocabulary::index_words() {
  words_.clear();
  for (uint32_t index = 0; index < nodes_.size(); ++index) nodes_[index].children.clear();
  for (uint32_t index = 1; index < nodes_.size(); ++index) nodes_[nodes_[index].parent].children.push_back(index);
  for (uint32_t index = 0; index < nodes_.size(); ++index) {
    nodes_[index].word = -1;
    if (index != 0 && nodes_[index].children.empty()) {
      nodes_[index].word = static_cast<int32_t>(words_.size());
      words_.push_back(index);
    }
  }
}

uint32_t Vocabulary::leaf_of(const unsigned char* descriptor) const {
  uint32_t node = 0;
  while (!nodes_[node].children.empty()) {
    uint32_t best = nodes_[node].children.front();
    int best_distance = std::numeric_limits<int>::max();
    for (uint32_t child : nodes_[node].children) {
      const int distance = hamming_distance(descriptor, nodes_[child].descriptor);
      if (distance < best_distance) best = child, best_distance = distance;
    }
    node = best;
  }
  return node;
}

uint32_t Vocabulary::word_of(const unsigned char* descriptor, int levels_up, uint32_t* node) const {
  const uint32_t leaf = leaf_of(descriptor);
  if (node != nullptr) {
    uint32_t ancestor = leaf;
    for (int up = 0; up < levels_up && nodes_[ancestor].parent != 0 && nodes_[ancestor].parent != kNoParent; ++up) ancestor = nodes_[ancestor].parent;
    *node = ancestor;
  }
  return static_cast<uint32_t>(nodes_[leaf].word);
}

BowVector Vocabulary::transform(const cv::Mat& descriptors, FeatureVector* features, int direct_index_levels_up) const {
  BowVector bow;
  if (features != nullptr) features->clear();
  if (descriptors.empty() || !is_orb_layout(descriptors) || words_.empty()) return bow;
  for (int row = 0; row < descriptors.rows; ++row) {
    uint32_t node = 0;
    const uint32_t word = word_of(descriptors.ptr<unsigned char>(row), direct_index_levels_up, &node);
    bow[word] += nodes_[words_[word]].weight;
    if (features != nullptr) (*features)[node].push_back(row);
  }
  double norm = 0.0;
  for (const auto& entry : bow) norm += std::abs(entry.second);
  if (norm > 0.0) {
    for (auto& entry : bow) entry.second /= norm;
  }
  std::erase_if(bow, [](const auto& entry) { return entry.second == 0.0; });
  return bow;
}

double Vocabulary::score(const BowVector& a, const BowVector& b) {
  double difference = 0.0;
  auto ia = a.begin(), ib = b.begin();
  while (ia != a.end() || ib != b.end()) {
    if (ib == b.end() || (ia != a.end() && ia->first < ib->first)) {
      difference += std::abs(ia++->second);
    } else if (ia == a.end() || ib->first < ia->first) {
      difference += std::abs(ib++->second);
    } else {
      difference += std::abs(ia++->second - ib++->second);
    }
  }
  return std::clamp(1.0 - 0.5 * difference, 0.0, 1.0);
}

Status Vocabulary::save(const std::string& path) const {
  std::string out(kMagic, sizeof(kMagic));
  put<uint32_t>(out, kVersion);
  put<uint32_t>(out, static_cast<uint32_t>(branching_));
  put<uint32_t>(out, static_cast<uint32_t>(levels_));
  put<uint32_t>(out, static_cast<uint32_t>(nodes_.size()));
  put<uint32_t>(out, static_cast<uint32_t>(training_images_));
  for (const Node& node : nodes_) {
    put<uint32_t>(out, node.parent);
    out.append(reinterpret_cast<const char*>(node.descriptor), kDescriptorBytes);
    put<double>(out, node.weight);
  }
  put<uint32_t>(out, binary_file::crc32_of(out, out.size()));
  const std::string partial = path + ".partial";
  return commit_partial_file(partial, path, write_file_durably(partial, out));
}

Result<Vocabulary> Vocabulary::load(const std::string& path) {
  Result<std::string> read = read_file(path);
  if (!read) return read.error();
  const std::string& bytes = *read;
  constexpr std::size_t kHeader = sizeof(kMagic) + 5 * 4;
  if (bytes.size() < kHeader + 4) return Error(fmt::format("{}: {} bytes, too short for a vocabulary header", path, bytes.size()));
  if (std::memcmp(bytes.data(), kMagic, sizeof(kMagic)) != 0) return Error(fmt::format("{}: not a hanzo-fusion vocabulary (magic bytes differ)", path));
  std::size_t offset = sizeof(kMagic);
  const auto version = take<uint32_t>(bytes, offset);
  if (version != kVersion) return Error(fmt::format("{}: vocabulary version {} is not supported (this build reads version {})", path, version, kVersion));
  Vocabulary vocabulary;
  vocabulary.branching_ = static_cast<int>(take<uint32_t>(bytes, offset));
  vocabulary.levels_ = static_cast<int>(take<uint32_t>(bytes, offset));
  const auto node_count = take<uint32_t>(bytes, offset);
  vocabulary.training_images_ = static_cast<int>(take<uint32_t>(bytes, offset));
  if (Status valid = validate(VocabularyConfig{vocabulary.branching_, vocabulary.levels_, 1, 1}); !valid) {
    return Error(fmt::format("{}: header: {}", path, valid.error().message));
  }
  if (node_count < 2) return Error(fmt::format("{}: {} nodes: a vocabulary needs a root and at least one word", path, node_count));
  const std::size_t expected = kHeader + static_cast<std::size_t>(node_count) * kNodeBytes + 4;
  if (bytes.size() != expected) {
    return Error(fmt::format("{}: {} bytes, but {} nodes need {} ({})", path, bytes.size(), node_count, expected, bytes.size() < expected ? "truncated" : "trailing bytes"));
  }
  uint32_t stored_crc;
  std::memcpy(&stored_crc, bytes.data() + bytes.size() - 4, 4);
  const uint32_t crc = binary_file::crc32_of(bytes, bytes.size() - 4);
  if (crc != stored_crc) return Error(fmt::format("{}: checksum mismatch (stored {:08x}, computed {:08x}): the file is corrupted", path, stored_crc, crc));
  vocabulary.nodes_.resize(node_count);
  for (uint32_t index = 0; index < node_count; ++index) {
    Node& node = vocabulary.nodes_[index];
    node.parent = take<uint32_t>(bytes, offset);
    std::memcpy(node.descriptor, bytes.data() + offset, kDescriptorBytes);
    offset += kDescriptorBytes;
    node.weight = take<double>(bytes, offset);
    if (index == 0 ? node.parent != kNoParent : node.parent >= index) {
      return Error(fmt::format("{}: node {}: parent {} must {}", path, index, node.parent, index == 0 ? "be none (the root)" : "come before the node"));
    }
    if (!std::isfinite(node.weight) || node.weight < 0.0) return Error(fmt::format("{}: node {}: weight {} is not a finite non-negative number", path, index, node.weight));
  }
  vocabulary.index_words();
  for (uint32_t index = 0; index < node_count; ++index) {
    if (static_cast<int>(vocabulary.nodes_[index].children.size()) > vocabulary.branching_) {
      return Error(fmt::format("{}: node {} has {} children, more than the branching {}", path, index, vocabulary.nodes_[index].children.size(), vocabulary.branching_));
    }
  }
  return vocabulary;
}

Result<Vocabulary> Vocabulary::load_default() {
  const Result<std::string> path = find_model_file(kDefaultFile, HANZO_INSTALLED_MODELS_DIR, HANZO_SOURCE_MODELS_DIR);
  if (!path) return Error(fmt::format("default vocabulary: {}", path.error().message));
  Result<Vocabulary> loaded = load(*path);
  if (!loaded) return Error(fmt::format("default vocabulary: {}", loaded.error().message));
  return loaded;
}

}  // namespace hanzo::fusion::vision
