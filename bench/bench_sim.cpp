// Simulator speed.
//
// 1. Ray casting, the simulator's engine: the LiDAR rays of 20 OS1-64 sweeps (1.3 M rays) along
//    the urban_vehicle trajectory through its city (buildings, poles, trees, parked cars),
//    with hanzo's BVH (sim::World) and with Intel Embree 3 (the engine behind Open3D's
//    RaycastingScene; Debian's Open3D 0.16 RaycastingScene returns no hits at all, so Embree is
//    called directly) on the same scene as triangles (cylinders as 24-sided prisms), one thread
//    and all threads (TBB for both).
//    Counters: items_per_second = rays/s; agreement = share of rays whose hit distances agree
//    within 5 cm (misses agreeing too; the prisms differ from true cylinders by millimetres).
// 2. Generating 60 s of the urban_vehicle scenario with all its sensors on one core, the
//    simulation time of each sensor as a counter (seconds), messages written nowhere.
// 3. Rendering alone: frames/s of the urban front camera.

#include <cmath>
#include <cstring>
#include <numbers>

#include <benchmark/benchmark.h>
#include <embree3/rtcore.h>
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include "hanzo/fusion/sim/scenario_simulation.hpp"

namespace {

using namespace hanzo::fusion;

constexpr const char* kUrban = "examples/scenarios/urban_vehicle.yaml";

struct RayBatch {
  std::vector<float> rays;  // origin xyz, direction xyz per ray (Open3D's layout)
  std::size_t count() const { return rays.size() / 6; }
};

// The static part of the urban scenario and the rays of 20 OS1-64 sweeps along its trajectory.
struct UrbanRays {
  sim::WorldDescription description;
  std::unique_ptr<sim::World> world;
  RayBatch batch;
};

const UrbanRays& urban_rays() {
  static const UrbanRays data = [] {
    UrbanRays result;
    Result<sim::Scenario> scenario = sim::load_scenario(kUrban);
    if (!scenario) throw std::runtime_error(scenario.error().message);
    result.description = scenario->world;
    result.description.moving_boxes.clear();
    result.world = std::make_unique<sim::World>(result.description);
    const sim::SplineTrajectory trajectory = *sim::make_trajectory(*scenario);
    const sim::LidarPattern pattern = sim::LidarPattern::preset(sim::LidarModel::kOusterOs1_64);
    const SE3 T_body_lidar(SO3(), Eigen::Vector3d(0.8, 0.0, 1.5));
    for (int sweep = 0; sweep < 20; ++sweep) {
      const SE3 pose = trajectory.sample(scenario->start_time + Duration::from_seconds(4.0 + 3.0 * sweep)).T_world_body * T_body_lidar;
      for (int column = 0; column < pattern.columns; ++column) {
        const double azimuth = 2.0 * std::numbers::pi * column / pattern.columns;
        for (double elevation : pattern.elevations) {
          const Eigen::Vector3d direction =
              pose.rotation() * Eigen::Vector3d(std::cos(elevation) * std::cos(azimuth), std::cos(elevation) * std::sin(azimuth), std::sin(elevation));
          const Eigen::Vector3d& origin = pose.translation();
          for (int axis = 0; axis < 3; ++axis) result.batch.rays.push_back(static_cast<float>(origin[axis]));
          for (int axis = 0; axis < 3; ++axis) result.batch.rays.push_back(static_cast<float>(direction[axis]));
        }
      }
    }
    return result;
  }();
  return data;
}

constexpr double kMaxRange = 120.0;

// Runs cast(range) over [0, count) on this thread or on all threads (TBB).
template <typename Cast>
void for_all_rays(std::size_t count, bool all_threads, const Cast& cast) {
  const tbb::blocked_range<std::size_t> all(0, count, 1024);
  if (all_threads) {
    tbb::parallel_for(all, cast);
  } else {
    cast(all);
  }
}

std::vector<float> cast_hanzo(const UrbanRays& data, bool all_threads) {
  std::vector<float> hits(data.batch.count());
  const sim::WorldSnapshot snapshot = data.world->at(Timestamp{});
  auto cast = [&](const tbb::blocked_range<std::size_t>& range) {
    for (std::size_t i = range.begin(); i < range.end(); ++i) {
      const float* r = &data.batch.rays[6 * i];
      const auto hit = snapshot.cast(Eigen::Vector3d(r[0], r[1], r[2]), Eigen::Vector3d(r[3], r[4], r[5]).normalized(), kMaxRange);
      hits[i] = hit ? static_cast<float>(hit->distance) : std::numeric_limits<float>::infinity();
    }
  };
  for_all_rays(hits.size(), all_threads, cast);
  return hits;
}

// The same scene as triangles for Embree.
struct EmbreeScene {
  RTCDevice device = nullptr;
  RTCScene scene = nullptr;
  ~EmbreeScene() {
    rtcReleaseScene(scene);
    rtcReleaseDevice(device);
  }
};

std::unique_ptr<EmbreeScene> embree_scene(const sim::WorldDescription& description) {
  std::vector<float> vertices;
  std::vector<uint32_t> triangles;
  auto vertex = [&](const Eigen::Vector3d& p) {
    for (int axis = 0; axis < 3; ++axis) vertices.push_back(static_cast<float>(p[axis]));
    return static_cast<uint32_t>(vertices.size() / 3 - 1);
  };
  auto triangle = [&](uint32_t a, uint32_t b, uint32_t c) {
    triangles.push_back(a);
    triangles.push_back(b);
    triangles.push_back(c);
  };
  auto quad = [&](uint32_t a, uint32_t b, uint32_t c, uint32_t d) {
    triangle(a, b, c);
    triangle(a, c, d);
  };
  const double ground = description.ground_height;
  quad(vertex({-5000, -5000, ground}), vertex({5000, -5000, ground}), vertex({5000, 5000, ground}), vertex({-5000, 5000, ground}));
  for (const sim::Box& box : description.boxes) {
    const double c = std::cos(box.yaw), s = std::sin(box.yaw);
    uint32_t corner[8];
    for (int i = 0; i < 8; ++i) {
      const Eigen::Vector3d local((i & 1 ? 1 : -1) * box.half_size.x(), (i & 2 ? 1 : -1) * box.half_size.y(), (i & 4 ? 1 : -1) * box.half_size.z());
      corner[i] = vertex(box.center + Eigen::Vector3d(c * local.x() - s * local.y(), s * local.x() + c * local.y(), local.z()));
    }
    quad(corner[0], corner[1], corner[3], corner[2]);
    quad(corner[4], corner[5], corner[7], corner[6]);
    quad(corner[0], corner[1], corner[5], corner[4]);
    quad(corner[2], corner[3], corner[7], corner[6]);
    quad(corner[0], corner[2], corner[6], corner[4]);
    quad(corner[1], corner[3], corner[7], corner[5]);
  }
  constexpr int kSides = 24;
  for (const sim::Cylinder& cylinder : description.cylinders) {
    const uint32_t top_center = vertex(cylinder.base_center + Eigen::Vector3d(0, 0, cylinder.height));
    for (int k = 0; k <= kSides; ++k) {
      const double angle = 2.0 * std::numbers::pi * k / kSides;
      const Eigen::Vector3d rim(cylinder.radius * std::cos(angle), cylinder.radius * std::sin(angle), 0.0);
      const uint32_t bottom = vertex(cylinder.base_center + rim);
      vertex(cylinder.base_center + rim + Eigen::Vector3d(0, 0, cylinder.height));
      if (k == 0) continue;
      const uint32_t previous = bottom - 2;  // the previous rim's bottom; its top is previous + 1
      quad(previous, bottom, bottom + 1, previous + 1);
      triangle(top_center, previous + 1, bottom + 1);
    }
  }
  auto result = std::make_unique<EmbreeScene>();
  result->device = rtcNewDevice(nullptr);
  result->scene = rtcNewScene(result->device);
  RTCGeometry geometry = rtcNewGeometry(result->device, RTC_GEOMETRY_TYPE_TRIANGLE);
  auto* vertex_buffer = static_cast<float*>(
      rtcSetNewGeometryBuffer(geometry, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT3, 3 * sizeof(float), vertices.size() / 3));
  std::memcpy(vertex_buffer, vertices.data(), vertices.size() * sizeof(float));
  auto* index_buffer = static_cast<uint32_t*>(
      rtcSetNewGeometryBuffer(geometry, RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT3, 3 * sizeof(uint32_t), triangles.size() / 3));
  std::memcpy(index_buffer, triangles.data(), triangles.size() * sizeof(uint32_t));
  rtcCommitGeometry(geometry);
  rtcAttachGeometry(result->scene, geometry);
  rtcReleaseGeometry(geometry);
  rtcCommitScene(result->scene);
  return result;
}

std::vector<float> cast_embree(const EmbreeScene& scene, const RayBatch& batch, bool all_threads) {
  std::vector<float> hits(batch.count());
  auto cast = [&](const tbb::blocked_range<std::size_t>& range) {
    RTCIntersectContext context;
    rtcInitIntersectContext(&context);
    for (std::size_t i = range.begin(); i < range.end(); ++i) {
      const float* r = &batch.rays[6 * i];
      RTCRayHit ray{};
      ray.ray.org_x = r[0];
      ray.ray.org_y = r[1];
      ray.ray.org_z = r[2];
      ray.ray.dir_x = r[3];
      ray.ray.dir_y = r[4];
      ray.ray.dir_z = r[5];
      ray.ray.tnear = 0.0F;
      ray.ray.tfar = static_cast<float>(kMaxRange);
      ray.ray.mask = 0xFFFFFFFFU;
      ray.hit.geomID = RTC_INVALID_GEOMETRY_ID;
      rtcIntersect1(scene.scene, &context, &ray);
      hits[i] = ray.hit.geomID == RTC_INVALID_GEOMETRY_ID ? std::numeric_limits<float>::infinity() : ray.ray.tfar;
    }
  };
  for_all_rays(hits.size(), all_threads, cast);
  return hits;
}

double agreement(const std::vector<float>& a, const std::vector<float>& b) {
  std::size_t same = 0;
  for (std::size_t i = 0; i < a.size(); ++i) {
    if ((std::isinf(a[i]) && std::isinf(b[i])) || std::abs(a[i] - b[i]) < 0.05F) ++same;
  }
  return static_cast<double>(same) / static_cast<double>(a.size());
}

void BM_RayCastHanzo(benchmark::State& state) {
  const UrbanRays& data = urban_rays();
  const bool all_threads = state.range(0) == 0;
  std::vector<float> hits;
  for (auto _ : state) {
    hits = cast_hanzo(data, all_threads);
    benchmark::DoNotOptimize(hits.data());
  }
  state.SetItemsProcessed(static_cast<int64_t>(state.iterations() * data.batch.count()));
  state.counters["agreement"] = agreement(hits, cast_embree(*embree_scene(data.description), data.batch, true));
  state.SetLabel(all_threads ? "all threads" : "1 thread");
}
BENCHMARK(BM_RayCastHanzo)->Arg(1)->Arg(0)->Unit(benchmark::kMillisecond)->UseRealTime();

void BM_RayCastEmbree(benchmark::State& state) {
  const UrbanRays& data = urban_rays();
  const bool all_threads = state.range(0) == 0;
  const auto scene = embree_scene(data.description);
  std::vector<float> hits;
  for (auto _ : state) {
    hits = cast_embree(*scene, data.batch, all_threads);
    benchmark::DoNotOptimize(hits.data());
  }
  state.SetItemsProcessed(static_cast<int64_t>(state.iterations() * data.batch.count()));
  state.counters["agreement"] = agreement(hits, cast_hanzo(data, true));
  state.SetLabel(all_threads ? "all threads" : "1 thread");
}
BENCHMARK(BM_RayCastEmbree)->Arg(1)->Arg(0)->Unit(benchmark::kMillisecond)->UseRealTime();

// Rendering alone: 20 frames of urban_vehicle's front camera (640x480 rgb8, radtan) spread over
// its loop, one thread and all threads; items_per_second = frames/s.
void BM_CameraFrames(benchmark::State& state) {
  Result<sim::Scenario> scenario = sim::load_scenario(kUrban);
  if (!scenario) {
    state.SkipWithError(scenario.error().message.c_str());
    return;
  }
  const sim::World world(scenario->world);
  const sim::SplineTrajectory trajectory = *sim::make_trajectory(*scenario);
  sim::CameraSimulatorConfig config;
  for (const sim::ScenarioSensor& sensor : scenario->sensors) {
    if (const auto* camera = std::get_if<sim::CameraSimulatorConfig>(&sensor.simulator)) config = *camera;
  }
  config.num_threads = static_cast<int>(state.range(0));
  Result<sim::CameraSimulator> camera = sim::CameraSimulator::create(config, world, trajectory);
  if (!camera) {
    state.SkipWithError(camera.error().message.c_str());
    return;
  }
  constexpr int kFrames = 20;
  for (auto _ : state) {
    for (int frame = 0; frame < kFrames; ++frame) {
      msgs::ImageMessage image = camera->measure(scenario->start_time + Duration::from_seconds(4.0 + 3.0 * frame));
      benchmark::DoNotOptimize(image.data.data());
    }
  }
  state.SetItemsProcessed(static_cast<int64_t>(state.iterations()) * kFrames);
  state.SetLabel(state.range(0) == 1 ? "1 thread" : "all threads");
}
BENCHMARK(BM_CameraFrames)->Arg(1)->Arg(0)->Unit(benchmark::kMillisecond)->UseRealTime();

// 60 s of urban_vehicle, every sensor, one core; per-sensor simulation seconds as counters.
void BM_UrbanScenario60s(benchmark::State& state) {
  Result<sim::Scenario> scenario = sim::load_scenario(kUrban);
  if (!scenario) {
    state.SkipWithError(scenario.error().message.c_str());
    return;
  }
  scenario->duration = 60.0;
  scenario->num_threads = 1;
  for (auto _ : state) {
    auto simulation = sim::ScenarioSimulation::create(*scenario);
    std::size_t messages = 0;
    const Status status = (*simulation)->run([&messages](const sim::ScenarioSensor&, msgs::SensorMessage&& message) {
      benchmark::DoNotOptimize(message);
      ++messages;
      return ok_status();
    });
    if (!status) state.SkipWithError(status.error().message.c_str());
    for (const sim::SensorRunStatistics& sensor : (*simulation)->statistics()) {
      state.counters[sensor.name + "_s"] = sensor.simulation_seconds;
    }
    state.counters["messages"] = static_cast<double>(messages);
  }
}
BENCHMARK(BM_UrbanScenario60s)->Iterations(1)->Unit(benchmark::kSecond)->UseRealTime();

}  // namespace

BENCHMARK_MAIN();
