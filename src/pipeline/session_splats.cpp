#include "session_splats.hpp"

#include <fmt/format.h>

#if HANZO_FUSION_WITH_AI
#include <algorithm>
#include <chrono>
#include <cmath>
#include <condition_variable>
#include <deque>
#include <mutex>
#include <random>
#include <thread>
#include <unordered_set>

#include <tbb/task_arena.h>

#include "hanzo/fusion/core/logging.hpp"
#include "hanzo/fusion/neural/log_views.hpp"
#include "hanzo/fusion/neural/map_layers.hpp"
#include "hanzo/fusion/neural/splat_trainer.hpp"
#endif

namespace hanzo::fusion::pipeline {

#if HANZO_FUSION_WITH_AI

namespace {

constexpr std::size_t kMaxPendingImages = 4;
constexpr std::size_t kMaxPooledPoints = 400000;
constexpr int kNewestViewEvery = 4;  // every fourth step trains on the newest view
constexpr std::size_t kDensifyRoom = 2;  // densification grows the seeded Gaussians at most this many times

/// The trainer's schedule for a scene without an end: densification throughout, no opacity
/// resets (they would blank the whole map a reader may fetch at any moment), and the position
/// learning rate's decay spread over a million steps.
neural::SplatTrainingConfig open_ended_training(const SessionSplatsConfig& config) {
  neural::SplatTrainingConfig training;
  training.iterations = 1000000;
  training.sh_degree = 1;
  training.sh_degree_interval = 500;
  training.densify_from = 100;
  training.densify_until = training.iterations;
  training.opacity_reset_interval = training.iterations;
  training.max_gaussians = config.settings.max_gaussians;  // lowered as the trainer goes (train_step)
  training.seed = config.seed;
  return training;
}

int64_t voxel_key(const Eigen::Vector3f& point, double voxel) {
  constexpr int64_t kOffset = 1 << 20, kMask = (1 << 21) - 1;
  const auto cell = [&](float value) { return (static_cast<int64_t>(std::floor(value / voxel)) + kOffset) & kMask; };
  return (cell(point.x()) << 42) | (cell(point.y()) << 21) | cell(point.z());
}

}  // namespace

struct SessionSplats::Impl {
  SplatCameraModel camera;
  SessionSplatsConfig config;
  neural::SplatTrainingConfig training;
  int downscale = 1;
  tbb::task_arena arena;

  // The caller's thread only.
  std::deque<msgs::ImageMessage> pending;
  std::optional<Timestamp> last_image_time;
  std::optional<SE3> last_view_pose;
  std::vector<Eigen::Vector3f> pool;
  std::unordered_set<int64_t> seeded;
  std::mt19937_64 seed_random;

  // Shared with the worker (mutex).
  mutable std::mutex mutex;
  struct View {
    uint64_t anchor = 0;
    SE3 T_anchor_camera;
    neural::PosedView view;
  };
  std::deque<View> views;
  std::vector<neural::GaussianCloud> incoming;  // Gaussians for the trainer, before its next step
  SessionSplatsSummary counts;
  std::condition_variable wake;
  bool stop = false;

  // The trainer (the worker's, or the caller's in replay).
  mutable std::mutex trainer_mutex;
  std::optional<neural::SplatTrainer> trainer;
  std::size_t seeds = 0;  // Gaussians the views seeded
  std::mt19937_64 view_random;
  std::thread worker;

  bool ready_to_train() const { return !views.empty() && (trainer || !incoming.empty()); }
  /// One optimizer step (trainer_mutex held); false when there is nothing to train yet.
  bool train_step();
  void add_view(const msgs::ImageMessage& image, const SE3& T_world_camera, uint64_t anchor, const SE3& T_world_anchor);
  /// Gaussians for a new view: pooled map points it sees, else random ones in front of it.
  neural::GaussianCloud seed_gaussians(const neural::PosedView& view);
  void run_worker();
};

bool SessionSplats::Impl::train_step() {
  neural::PosedView view;
  std::vector<neural::GaussianCloud> arrived;
  {
    std::lock_guard lock(mutex);
    if (!ready_to_train()) return false;
    arrived.swap(incoming);
    const auto iteration = static_cast<int>(counts.iterations);
    const std::size_t index = iteration % kNewestViewEvery == 0 ? views.size() - 1 : std::uniform_int_distribution<std::size_t>(0, views.size() - 1)(view_random);
    view = views[index].view;
  }
  // Densification may at most double what the views seeded (it would otherwise fill the cap
  // early and leave no room for the places the robot reaches later); seeds fit up to max_gaussians.
  const auto budget = [this] { return static_cast<int>(std::min<std::size_t>(config.settings.max_gaussians, kDensifyRoom * seeds)); };
  for (neural::GaussianCloud& cloud : arrived) {
    if (cloud.size() == 0) continue;
    seeds += cloud.size();
    if (!trainer) {
      Result<neural::SplatTrainer> created = neural::SplatTrainer::create(std::move(cloud), config.scene_extent, training);
      if (!created) {
        logger()->warn("session splats: training not started: {}", created.error().message);
        continue;
      }
      trainer.emplace(std::move(created).value());
    } else {
      trainer->set_max_gaussians(std::min(config.settings.max_gaussians, std::max(budget(), static_cast<int>(trainer->cloud().size() + cloud.size()))));
      if (Status added = trainer->add_gaussians(cloud); !added) logger()->warn("session splats: Gaussians not added: {}", added.error().message);
    }
    trainer->set_max_gaussians(budget());
  }
  if (!trainer) return false;
  arena.execute([&] { trainer->step(view); });
  std::lock_guard lock(mutex);
  ++counts.iterations;
  counts.gaussians = trainer->cloud().size();
  return true;
}

neural::GaussianCloud SessionSplats::Impl::seed_gaussians(const neural::PosedView& view) {
  const neural::SplatCamera& c = view.camera;
  std::vector<Eigen::Vector3f> points;
  const auto wanted = static_cast<std::size_t>(config.gaussians_per_view);
  if (config.seed_from_map) {
    std::vector<std::size_t> seen;
    for (std::size_t i = 0; i < pool.size(); ++i) {
      const Eigen::Vector3d p = c.R_camera_world * pool[i].cast<double>() + c.t_camera_world;
      if (p.z() < 0.2 || p.z() > config.max_depth) continue;
      const double u = c.fx * p.x() / p.z() + c.cx, v = c.fy * p.y() / p.z() + c.cy;
      if (u >= 0.0 && v >= 0.0 && u <= c.width - 1 && v <= c.height - 1) seen.push_back(i);
    }
    // An even selection; the chosen leave the pool (the others may seed a later view).
    const std::size_t count = std::min(wanted, seen.size());
    if (count == 0) return {};
    std::vector<bool> taken(pool.size(), false);
    for (std::size_t k = 0; k < count; ++k) taken[seen[k * seen.size() / count]] = true;
    std::vector<Eigen::Vector3f> kept;
    kept.reserve(pool.size() - count);
    for (std::size_t i = 0; i < pool.size(); ++i) (taken[i] ? points : kept).push_back(pool[i]);
    pool = std::move(kept);
  } else {  // no 3D LiDAR: random points in front of the camera
    std::uniform_real_distribution<double> column(0.0, c.width - 1), row(0.0, c.height - 1), depth(1.0, std::max(1.0, config.max_depth / 2.0));
    const Eigen::Matrix3d R_world_camera = c.R_camera_world.transpose();
    for (std::size_t k = 0; k < wanted / 4; ++k) {
      const double z = depth(seed_random);
      const Eigen::Vector3d ray((column(seed_random) - c.cx) / c.fx, (row(seed_random) - c.cy) / c.fy, 1.0);
      points.push_back((R_world_camera * (z * ray - c.t_camera_world)).cast<float>());
    }
  }
  return neural::initialize_gaussians_at_points({view}, points, static_cast<int>(points.size()), training.sh_degree, seed_random());
}

void SessionSplats::Impl::add_view(const msgs::ImageMessage& image, const SE3& T_world_camera, uint64_t anchor, const SE3& T_world_anchor) {
  Result<neural::PosedView> view = neural::image_view(image, camera.intrinsics, camera.distortion, T_world_camera, downscale);
  if (!view) {
    logger()->warn("session splats: {} image not used: {}", camera.sensor, view.error().message);
    std::lock_guard lock(mutex);
    ++counts.images_skipped;
    return;
  }
  view->name = fmt::format("{}@{}", camera.sensor, image.timestamp.to_iso8601());
  neural::GaussianCloud gaussians = seed_gaussians(*view);
  last_view_pose = T_world_camera;
  {
    std::lock_guard lock(mutex);
    views.push_back({anchor, T_world_anchor.inverse() * T_world_camera, std::move(view).value()});
    if (views.size() > config.max_views) views.pop_front();
    incoming.push_back(std::move(gaussians));
    ++counts.views;
  }
  if (config.realtime) {
    wake.notify_one();
    return;
  }
  std::lock_guard lock(trainer_mutex);
  const auto start = std::chrono::steady_clock::now();
  for (int step = 0; step < config.settings.steps_per_view; ++step) {
    if (!train_step()) break;
  }
  logger()->debug("session splats: view {}, {} Gaussians, {} steps in {:.3f} s", counts.views, counts.gaussians, config.settings.steps_per_view,
                  std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count());
}

void SessionSplats::Impl::run_worker() {
  while (true) {
    {
      std::unique_lock lock(mutex);
      wake.wait(lock, [this] { return stop || ready_to_train(); });
      if (stop) return;
    }
    const auto start = std::chrono::steady_clock::now();
    {
      std::lock_guard lock(trainer_mutex);
      train_step();
    }
    const std::chrono::duration<double> took = std::chrono::steady_clock::now() - start;
    std::unique_lock lock(mutex);
    counts.training_seconds += took.count();
    // Idle so that the steps take cpu_share of this thread's time.
    const auto idle = std::chrono::duration<double>(took.count() * (1.0 / config.settings.cpu_share - 1.0));
    wake.wait_for(lock, idle, [this] { return stop; });
    if (stop) return;
  }
}

Result<std::unique_ptr<SessionSplats>> SessionSplats::create(SplatCameraModel camera, SessionSplatsConfig config) {
  const config::SplatMappingConfig& settings = config.settings;
  if (settings.image_width < 16 || settings.steps_per_view < 1 || !(settings.cpu_share > 0.0 && settings.cpu_share <= 1.0) || settings.max_gaussians < 1000) {
    return Error("mapping.splats: image_width must be >= 16, steps_per_view >= 1, cpu_share in (0, 1], max_gaussians >= 1000");
  }
  if (config.max_views < 1 || config.gaussians_per_view < 1 || !(config.seed_voxel > 0.0) || !(config.max_depth > 1.0) || !(config.scene_extent > 0.0)) {
    return Error("SessionSplatsConfig: max_views and gaussians_per_view must be >= 1, seed_voxel and scene_extent > 0, max_depth > 1 m");
  }
  const msgs::CameraIntrinsics& intrinsics = camera.intrinsics;
  if (intrinsics.width == 0 || intrinsics.height == 0 || !(intrinsics.fx > 0.0) || !(intrinsics.fy > 0.0)) {
    return Error(fmt::format("mapping.splats: camera {} has no image size or focal length in its calibration", camera.sensor));
  }
  auto impl = std::make_unique<Impl>();
  impl->downscale = std::max(1, static_cast<int>(std::lround(static_cast<double>(intrinsics.width) / settings.image_width)));
  impl->training = open_ended_training(config);
  HANZO_RETURN_IF_ERROR(with_context(neural::validate(impl->training), "mapping.splats"));
  const int threads = config.realtime ? 1 : config.threads;
  impl->arena.initialize(threads <= 0 ? tbb::task_arena::automatic : threads);
  impl->seed_random.seed(config.seed);
  impl->view_random.seed(config.seed + 1);
  impl->camera = std::move(camera);
  impl->config = std::move(config);
  auto splats = std::unique_ptr<SessionSplats>(new SessionSplats(std::move(impl)));
  if (splats->impl_->config.realtime) splats->impl_->worker = std::thread([raw = splats->impl_.get()] { raw->run_worker(); });
  return splats;
}

SessionSplats::~SessionSplats() {
  {
    std::lock_guard lock(impl_->mutex);
    impl_->stop = true;
  }
  impl_->wake.notify_all();
  if (impl_->worker.joinable()) impl_->worker.join();
}

const std::string& SessionSplats::sensor() const { return impl_->camera.sensor; }

void SessionSplats::add_image(const msgs::ImageMessage& image) {
  Impl& s = *impl_;
  if (image.encoding == msgs::ImageEncoding::kDepth16 || image.encoding == msgs::ImageEncoding::kDepth32f) return;
  if (s.last_image_time && (image.timestamp - *s.last_image_time).seconds() < s.config.image_interval_s) return;
  s.last_image_time = image.timestamp;
  s.pending.push_back(image);
  if (s.pending.size() > kMaxPendingImages) {  // no pose came for the oldest (before the first keyframe, or a gap)
    s.pending.pop_front();
    std::lock_guard lock(s.mutex);
    ++s.counts.images_skipped;
  }
}

void SessionSplats::add_points(const std::vector<Eigen::Vector3f>& points_world) {
  Impl& s = *impl_;
  for (const Eigen::Vector3f& point : points_world) {
    if (s.seeded.insert(voxel_key(point, s.config.seed_voxel)).second) s.pool.push_back(point);
  }
  if (s.pool.size() > kMaxPooledPoints) s.pool.erase(s.pool.begin(), s.pool.begin() + static_cast<std::ptrdiff_t>(s.pool.size() - kMaxPooledPoints / 2));
}

void SessionSplats::take_views(const std::function<std::optional<SE3>(Timestamp)>& T_world_body_at, uint64_t anchor, const SE3& T_world_anchor) {
  Impl& s = *impl_;
  while (!s.pending.empty()) {
    const msgs::ImageMessage& image = s.pending.front();
    const std::optional<SE3> T_world_body = T_world_body_at(image.timestamp + s.camera.time_offset);
    if (!T_world_body) return;  // not yet covered: wait (add_image bounds the wait)
    const SE3 T_world_camera = *T_world_body * s.camera.T_body_camera;
    bool moved = true;
    if (s.last_view_pose) {
      const SE3 motion = s.last_view_pose->inverse() * T_world_camera;
      moved = motion.translation().norm() >= s.config.min_translation || motion.rotation().log().norm() * 180.0 / M_PI >= s.config.min_rotation_degrees;
    }
    if (moved) s.add_view(image, T_world_camera, anchor, T_world_anchor);
    s.pending.pop_front();
  }
}

void SessionSplats::move_views(const std::function<std::optional<SE3>(uint64_t)>& T_world_keyframe) {
  std::lock_guard lock(impl_->mutex);
  for (Impl::View& view : impl_->views) {
    if (const std::optional<SE3> T_world_anchor = T_world_keyframe(view.anchor)) neural::place_camera(view.view.camera, *T_world_anchor * view.T_anchor_camera);
  }
}

std::optional<msgs::GaussianSplatLayer> SessionSplats::layer() const {
  const SessionSplatsSummary counts = summary();
  std::lock_guard lock(impl_->trainer_mutex);
  if (!impl_->trainer) return std::nullopt;
  msgs::NeuralProvenance provenance;
  provenance.source = fmt::format("session camera {}", impl_->camera.sensor);
  provenance.views = static_cast<uint32_t>(std::min<uint64_t>(counts.views, impl_->config.max_views));
  provenance.iterations = static_cast<uint64_t>(impl_->trainer->iteration());
  provenance.training_seconds = counts.training_seconds;
  return neural::to_splat_layer(impl_->trainer->cloud(), std::move(provenance));
}

SessionSplatsSummary SessionSplats::summary() const {
  std::lock_guard lock(impl_->mutex);
  return impl_->counts;
}

#else  // built without the AI module

struct SessionSplats::Impl {};

Result<std::unique_ptr<SessionSplats>> SessionSplats::create(SplatCameraModel, SessionSplatsConfig) {
  return Error("mapping.splats: this build has no neural module (configure with -DHANZO_FUSION_AI=ON, which needs libtorch-dev)");
}
SessionSplats::~SessionSplats() = default;
const std::string& SessionSplats::sensor() const {
  static const std::string none;
  return none;
}
void SessionSplats::add_image(const msgs::ImageMessage&) {}
void SessionSplats::add_points(const std::vector<Eigen::Vector3f>&) {}
void SessionSplats::take_views(const std::function<std::optional<SE3>(Timestamp)>&, uint64_t, const SE3&) {}
void SessionSplats::move_views(const std::function<std::optional<SE3>(uint64_t)>&) {}
std::optional<msgs::GaussianSplatLayer> SessionSplats::layer() const { return std::nullopt; }
SessionSplatsSummary SessionSplats::summary() const { return {}; }

#endif

SessionSplats::SessionSplats(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}

}  // namespace hanzo::fusion::pipeline
