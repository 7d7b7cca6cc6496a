#include "hanzo/fusion/lidar/scan_context.hpp"

#include <algorithm>
#include <cmath>

#include <fmt/format.h>

namespace hanzo::fusion::lidar {

Status ScanContextConfig::validate() const {
  if (num_rings < 1 || num_sectors < 1) return Error(fmt::format("num_rings / num_sectors must be >= 1 (got {} / {})", num_rings, num_sectors));
  if (!(max_range > 0)) return Error(fmt::format("max_range: {} <= 0", max_range));
  if (!std::isfinite(height_offset)) return Error("height_offset is not finite");
  if (candidates < 1) return Error(fmt::format("candidates: {} < 1", candidates));
  if (!(max_distance > 0 && max_distance <= 1)) return Error(fmt::format("max_distance: {} outside (0, 1]", max_distance));
  if (exclude_recent < 0) return Error(fmt::format("exclude_recent: {} < 0", exclude_recent));
  return {};
}

Result<ScanContext> make_scan_context(const cloud::PointCloud& scan, const ScanContextConfig& config) {
  HANZO_RETURN_IF_ERROR(config.validate());
  ScanContext context;
  context.num_rings = config.num_rings;
  context.num_sectors = config.num_sectors;
  context.bins = Eigen::MatrixXd::Zero(config.num_rings, config.num_sectors);
  const double ring_width = config.max_range / config.num_rings;
  const double sector_width = 2.0 * M_PI / config.num_sectors;
  size_t used = 0;
  for (const Eigen::Vector3f& point : scan.positions) {
    if (!point.allFinite()) continue;
    const double range = std::hypot(point.x(), point.y());
    if (range >= config.max_range || range <= 0.0) continue;
    double azimuth = std::atan2(point.y(), point.x());
    if (azimuth < 0) azimuth += 2.0 * M_PI;
    const int ring = std::min(config.num_rings - 1, static_cast<int>(range / ring_width));
    const int sector = std::min(config.num_sectors - 1, static_cast<int>(azimuth / sector_width));
    // Heights below the offset plane count as empty (0), as in the paper's implementation.
    double& bin = context.bins(ring, sector);
    bin = std::max(bin, static_cast<double>(point.z()) + config.height_offset);
    ++used;
  }
  if (used == 0) return Error(fmt::format("scan context: none of the {} points lies within {} m", scan.size(), config.max_range));
  context.ring_key = (context.bins.array() > 0.0).cast<double>().rowwise().mean();
  return context;
}

Result<ScanContextDistance> scan_context_distance(const ScanContext& query, const ScanContext& candidate) {
  if (query.num_rings != candidate.num_rings || query.num_sectors != candidate.num_sectors || query.bins.rows() != query.num_rings ||
      candidate.bins.rows() != candidate.num_rings || query.bins.cols() != query.num_sectors || candidate.bins.cols() != candidate.num_sectors) {
    return Error(fmt::format("scan context distance: descriptors of {}x{} and {}x{} bins", query.num_rings, query.num_sectors,
                             candidate.num_rings, candidate.num_sectors));
  }
  const int sectors = query.num_sectors;
  const Eigen::VectorXd query_norms = query.bins.colwise().norm();
  const Eigen::VectorXd candidate_norms = candidate.bins.colwise().norm();
  ScanContextDistance best;
  for (int shift = 0; shift < sectors; ++shift) {
    double sum = 0.0;
    int columns = 0;
    for (int j = 0; j < sectors; ++j) {
      const int k = (j + shift) % sectors;
      if (query_norms(j) <= 0.0 || candidate_norms(k) <= 0.0) continue;
      sum += 1.0 - query.bins.col(j).dot(candidate.bins.col(k)) / (query_norms(j) * candidate_norms(k));
      ++columns;
    }
    const double distance = columns > 0 ? sum / columns : 1.0;
    if (distance < best.distance) {
      best.distance = distance;
      best.shift = shift;
    }
  }
  best.yaw = std::remainder(2.0 * M_PI * best.shift / sectors, 2.0 * M_PI);
  return best;
}

ScanContextDatabase::ScanContextDatabase(ScanContextConfig config) : config_(config) {}

Status ScanContextDatabase::add(uint64_t id, ScanContext descriptor) {
  HANZO_RETURN_IF_ERROR(config_.validate());
  if (descriptor.num_rings != config_.num_rings || descriptor.num_sectors != config_.num_sectors ||
      descriptor.ring_key.size() != config_.num_rings) {
    return Error(fmt::format("scan context database: a {}x{} descriptor, expected {}x{}", descriptor.num_rings, descriptor.num_sectors,
                             config_.num_rings, config_.num_sectors));
  }
  entries_.push_back({id, std::move(descriptor)});
  return {};
}

Result<std::optional<ScanContextMatch>> ScanContextDatabase::query(const ScanContext& descriptor) const {
  HANZO_RETURN_IF_ERROR(config_.validate());
  if (descriptor.ring_key.size() != config_.num_rings) {
    return Error(fmt::format("scan context database: a query with {} rings, expected {}", descriptor.ring_key.size(), config_.num_rings));
  }
  const size_t searchable = entries_.size() > static_cast<size_t>(config_.exclude_recent) ? entries_.size() - static_cast<size_t>(config_.exclude_recent) : 0;
  std::vector<std::pair<double, size_t>> by_ring_key;
  by_ring_key.reserve(searchable);
  for (size_t i = 0; i < searchable; ++i) by_ring_key.emplace_back((entries_[i].descriptor.ring_key - descriptor.ring_key).squaredNorm(), i);
  const size_t candidates = std::min(by_ring_key.size(), static_cast<size_t>(config_.candidates));
  std::partial_sort(by_ring_key.begin(), by_ring_key.begin() + static_cast<long>(candidates), by_ring_key.end());
  std::optional<ScanContextMatch> best;
  for (size_t c = 0; c < candidates; ++c) {
    const Entry& entry = entries_[by_ring_key[c].second];
    ScanContextDistance distance;
    HANZO_ASSIGN_OR_RETURN(distance, scan_context_distance(descriptor, entry.descriptor));
    if (distance.distance < config_.max_distance && (!best || distance.distance < best->distance.distance)) best = ScanContextMatch{entry.id, distance};
  }
  return best;
}

}  // namespace hanzo::fusion::lidar
