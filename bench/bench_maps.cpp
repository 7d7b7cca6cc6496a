// Occupancy mapping speed and memory, hanzo-fusion against OctoMap 1.9 (the standard 3D
// occupancy library; Debian's liboctomap) in the same run:
//
//  - Intel2D: the intel lab CARMEN log (906 scans of 180 beams, corrected poses) into a 0.05 m
//    grid, all scans per iteration. hanzo-fusion's 2D grid; OctoMap gets the same planar rays
//    in 3D (it has no 2D map). Counters: ms per scan, memory, percentage of the logged end points
//    in occupied cells.
//  - Scan3D: one real LiDAR scan (lidar_small_gicp/source.ply, voxel-downsampled to 0.05 m)
//    into a fresh 3D grid at 0.1 / 0.2 m. Counters: points, observed cells, memory.
//  - Tsdf: 30 depth images (640 x 480, millimetre depth) of a 6 m x 6 m x 3 m room with a
//    sphere, from a camera circling it, integrated and meshed at 2 cm and 5 cm voxels
//    (truncation 3 voxels) against Open3D 0.16's ScalableTSDFVolume. Open3D integrates with
//    OpenMP on every core; hanzo-fusion on one thread. Counters: ms per frame, meshing ms,
//    triangles, memory (hanzo-fusion).
//  - WarehouseTsdf: the same warehouse seen by a 16-beam LiDAR every 2 m along the aisles,
//    integrated into a 0.05 m TSDF: memory for the observed surfaces of 10,000 m^2.
//  - Warehouse2D: the memory case, a simulated 100 m x 100 m warehouse (10,000 m^2,
//    shelf rows, pillars) mapped at 0.05 m by a 360-beam planar scanner every 0.5 m along a
//    lawnmower path. Counters: observed area, memory.
// Both libraries use the same sensor model (hit 0.85, miss 0.47, clamping 0.12 / 0.97) and one
// thread.

#include <chrono>
#include <cmath>
#include <limits>
#include <filesystem>
#include <map>
#include <memory>
#include <string>

#include <benchmark/benchmark.h>
#include <octomap/OcTree.h>
#include <unistd.h>

#include "hanzo/fusion/cloud/cloud_io.hpp"
#include "hanzo/fusion/cloud/voxel_grid.hpp"
#include "hanzo/fusion/io/carmen_import.hpp"
#include "hanzo/fusion/maps/occupancy_grid.hpp"
#include "hanzo/fusion/maps/tsdf.hpp"
#include "maps_peers.hpp"
#include "hanzo/fusion/sim/world.hpp"

namespace {

using namespace hanzo::fusion;

struct PlanarScan {
  Eigen::Vector2d origin;
  std::vector<Eigen::Vector2d> end_points;
};

const std::vector<PlanarScan>& intel_scans() {
  static const std::vector<PlanarScan> scans = [] {
    const std::string log = (std::filesystem::temp_directory_path() / ("hanzo_bench_intel_" + std::to_string(::getpid()) + ".mcap")).string();
    io::CarmenImportReport report;
    {
      auto writer = io::SensorLogWriter::open(log);
      report = io::import_carmen(std::string(HANZO_DATA_DIR) + "/laser2d_carmen/intel-corrected.log.gz", **writer, {}).value();
      (void)(*writer)->close();
    }
    std::vector<PlanarScan> out;
    auto reader = std::move(io::SensorLogReader::open(log).value());
    io::LogEntry entry;
    while (*reader->next(entry)) {
      const auto& cloud = std::get<msgs::PointCloudMessage>(std::get<msgs::SensorMessage>(entry.message));
      const SE3 pose = report.scan_poses.pose_se3(out.size());
      PlanarScan scan{pose.translation().head<2>(), {}};
      for (const Eigen::Vector3f& point : cloud.points) scan.end_points.push_back((pose * point.cast<double>()).head<2>());
      out.push_back(std::move(scan));
    }
    std::filesystem::remove(log);
    return out;
  }();
  return scans;
}

/// Milliseconds per scan from the benchmark's own measured time (the map's creation included).
double ms_per_scan(double seconds, const benchmark::State& state, std::size_t scans_per_iteration) {
  return 1e3 * seconds / (static_cast<double>(state.iterations()) * static_cast<double>(scans_per_iteration));
}

double seconds_since(std::chrono::steady_clock::time_point start) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
}

maps::OccupancyConfig config_at(double resolution) {
  maps::OccupancyConfig config;
  config.resolution = resolution;
  return config;
}

std::unique_ptr<octomap::OcTree> octree_at(double resolution) {
  const maps::OccupancyConfig config = config_at(resolution);
  auto tree = std::make_unique<octomap::OcTree>(resolution);
  tree->setProbHit(config.probability_hit);
  tree->setProbMiss(config.probability_miss);
  tree->setClampingThresMin(config.probability_min);
  tree->setClampingThresMax(config.probability_max);
  tree->setOccupancyThres(config.occupied_threshold);
  return tree;
}

void BM_Intel2D_Hanzo(benchmark::State& state) {
  const auto& scans = intel_scans();
  std::optional<maps::OccupancyGrid2D> grid;
  double seconds = 0.0;
  for (auto _ : state) {
    const auto start = std::chrono::steady_clock::now();
    grid.emplace(config_at(0.05));
    for (const PlanarScan& scan : scans) (void)grid->insert_scan(scan.origin, scan.end_points);
    seconds += seconds_since(start);
  }
  std::size_t occupied = 0;
  std::size_t total = 0;
  for (const PlanarScan& scan : scans) {
    for (const Eigen::Vector2d& point : scan.end_points) {
      ++total;
      occupied += grid->state(point) == maps::CellState::kOccupied ? 1 : 0;
    }
  }
  state.counters["ms_per_scan"] = ms_per_scan(seconds, state, scans.size());
  state.counters["memory_MB"] = static_cast<double>(grid->memory_bytes()) / 1e6;
  state.counters["end_points_in_occupied_pct"] = 100.0 * static_cast<double>(occupied) / static_cast<double>(total);
}

void BM_Intel2D_OctoMap(benchmark::State& state) {
  const auto& scans = intel_scans();
  std::unique_ptr<octomap::OcTree> tree;
  double seconds = 0.0;
  for (auto _ : state) {
    const auto start = std::chrono::steady_clock::now();
    tree = octree_at(0.05);
    for (const PlanarScan& scan : scans) {
      octomap::Pointcloud cloud;
      for (const Eigen::Vector2d& point : scan.end_points) cloud.push_back(static_cast<float>(point.x()), static_cast<float>(point.y()), 0.0f);
      tree->insertPointCloud(cloud, octomap::point3d(static_cast<float>(scan.origin.x()), static_cast<float>(scan.origin.y()), 0.0f));
    }
    seconds += seconds_since(start);
  }
  std::size_t occupied = 0;
  std::size_t total = 0;
  for (const PlanarScan& scan : scans) {
    for (const Eigen::Vector2d& point : scan.end_points) {
      ++total;
      const octomap::OcTreeNode* node = tree->search(point.x(), point.y(), 0.0);
      occupied += node != nullptr && tree->isNodeOccupied(node) ? 1 : 0;
    }
  }
  state.counters["ms_per_scan"] = ms_per_scan(seconds, state, scans.size());
  state.counters["memory_MB"] = static_cast<double>(tree->memoryUsage()) / 1e6;
  state.counters["end_points_in_occupied_pct"] = 100.0 * static_cast<double>(occupied) / static_cast<double>(total);
}

const std::vector<Eigen::Vector3d>& real_scan() {
  static const std::vector<Eigen::Vector3d> points = [] {
    const auto cloud = cloud::voxel_downsample(cloud::read_cloud(std::string(HANZO_DATA_DIR) + "/lidar_small_gicp/source.ply").value(), 0.05);
    std::vector<Eigen::Vector3d> out;
    for (const Eigen::Vector3f& point : cloud.positions) out.push_back(point.cast<double>());
    return out;
  }();
  return points;
}

void BM_Scan3D_Hanzo(benchmark::State& state) {
  const double resolution = static_cast<double>(state.range(0)) / 100.0;
  const auto& points = real_scan();
  std::optional<maps::OccupancyGrid3D> grid;
  for (auto _ : state) {
    grid.emplace(config_at(resolution));
    (void)grid->insert_scan(Eigen::Vector3d::Zero(), points);
  }
  state.counters["points"] = static_cast<double>(points.size());
  state.counters["observed_cells"] = static_cast<double>(grid->observed_cell_count());
  state.counters["memory_MB"] = static_cast<double>(grid->memory_bytes()) / 1e6;
}

void BM_Scan3D_OctoMap(benchmark::State& state) {
  const double resolution = static_cast<double>(state.range(0)) / 100.0;
  const auto& points = real_scan();
  octomap::Pointcloud cloud;
  for (const Eigen::Vector3d& point : points) cloud.push_back(static_cast<float>(point.x()), static_cast<float>(point.y()), static_cast<float>(point.z()));
  std::unique_ptr<octomap::OcTree> tree;
  for (auto _ : state) {
    tree = octree_at(resolution);
    tree->insertPointCloud(cloud, octomap::point3d(0, 0, 0));
  }
  state.counters["points"] = static_cast<double>(points.size());
  state.counters["observed_cells"] = static_cast<double>(tree->getNumLeafNodes());  // pruned leaves: fewer than cells
  state.counters["memory_MB"] = static_cast<double>(tree->memoryUsage()) / 1e6;
}

/// 100 m x 100 m: outer walls, 9 shelf rows (2 m deep, 80 m long, 4 m high) with cross aisles,
/// pillars every 10 m.
sim::World warehouse() {
  sim::WorldDescription description;
  const auto add_box = [&](double x, double y, double half_x, double half_y, double half_z) {
    sim::Box box;
    box.center = {x, y, half_z};
    box.half_size = {half_x, half_y, half_z};
    description.boxes.push_back(box);
  };
  add_box(50.0, -0.5, 51.0, 0.5, 3.0);
  add_box(50.0, 100.5, 51.0, 0.5, 3.0);
  add_box(-0.5, 50.0, 0.5, 51.0, 3.0);
  add_box(100.5, 50.0, 0.5, 51.0, 3.0);
  for (int row = 0; row < 9; ++row) {
    const double y = 10.0 + 10.0 * row;
    add_box(30.0, y, 18.0, 1.0, 2.0);
    add_box(72.0, y, 18.0, 1.0, 2.0);
  }
  for (int i = 1; i < 10; ++i) {
    sim::Cylinder pillar;
    pillar.base_center = {10.0 * i, 5.0, 0.0};
    pillar.radius = 0.3;
    pillar.height = 6.0;
    description.cylinders.push_back(pillar);
  }
  return sim::World(description);
}

void BM_Warehouse2D_Hanzo(benchmark::State& state) {
  static const sim::World world = warehouse();
  std::optional<maps::OccupancyGrid2D> grid;
  std::size_t scans = 0;
  for (auto _ : state) {
    grid.emplace(config_at(0.05));
    scans = 0;
    // Aisles between the shelf rows (y = 5, 15, ..., 95), driven east then west.
    for (int aisle = 0; aisle < 10; ++aisle) {
      const double y = 5.0 + 10.0 * aisle;
      for (double x = 2.0; x <= 98.0; x += 0.5) {
        const Eigen::Vector3d origin(aisle % 2 == 0 ? x : 100.0 - x, y, 0.5);
        std::vector<Eigen::Vector2d> end_points;
        for (int beam = 0; beam < 360; ++beam) {
          const double angle = beam * M_PI / 180.0;
          const Eigen::Vector3d direction(std::cos(angle), std::sin(angle), 0.0);
          const auto hit = world.cast(origin, direction, 30.0, Timestamp{});
          if (hit) end_points.push_back(hit->point.head<2>());
        }
        (void)grid->insert_scan(origin.head<2>(), end_points);
        ++scans;
      }
    }
  }
  state.counters["scans"] = static_cast<double>(scans);
  state.counters["observed_m2"] = static_cast<double>(grid->observed_cell_count()) * 0.05 * 0.05;
  state.counters["memory_MB"] = static_cast<double>(grid->memory_bytes()) / 1e6;
  state.counters["layer_MB"] = static_cast<double>(grid->to_layer().occupancy.size() * sizeof(float)) / 1e6;
}

struct DepthFrame {
  std::vector<float> meters;
  std::vector<uint16_t> millimetres;
  SE3 T_world_camera;
};

constexpr int kDepthWidth = 640;
constexpr int kDepthHeight = 480;

msgs::CameraIntrinsics depth_camera() {
  msgs::CameraIntrinsics camera;
  camera.fx = 525.0;
  camera.fy = 525.0;
  camera.cx = 319.5;
  camera.cy = 239.5;
  camera.width = kDepthWidth;
  camera.height = kDepthHeight;
  return camera;
}

/// The room [-3, 3] x [-3, 3] x [0, 3] seen from inside, with a sphere of 0.6 m at (0, 0, 1).
const std::vector<DepthFrame>& room_frames() {
  static const std::vector<DepthFrame> frames = [] {
    std::vector<DepthFrame> out;
    const msgs::CameraIntrinsics camera = depth_camera();
    const Eigen::Vector3d sphere(0.0, 0.0, 1.0);
    for (int frame = 0; frame < 30; ++frame) {
      const double angle = 2.0 * M_PI * frame / 30.0;
      const Eigen::Vector3d eye(2.0 * std::cos(angle), 2.0 * std::sin(angle), 1.5);
      const Eigen::Vector3d forward = (sphere - eye).normalized();
      const Eigen::Vector3d right = forward.cross(Eigen::Vector3d::UnitZ()).normalized();
      Eigen::Matrix3d rotation;
      rotation << right, forward.cross(right), forward;
      DepthFrame depth{{}, {}, SE3(SO3::from_matrix(rotation), eye)};
      for (int v = 0; v < kDepthHeight; ++v) {
        for (int u = 0; u < kDepthWidth; ++u) {
          const Eigen::Vector3d direction = (rotation * Eigen::Vector3d((u - camera.cx) / camera.fx, (v - camera.cy) / camera.fy, 1.0)).normalized();
          double t = std::numeric_limits<double>::infinity();
          const Eigen::Vector3d low(-3.0, -3.0, 0.0);
          const Eigen::Vector3d high(3.0, 3.0, 3.0);
          for (int axis = 0; axis < 3; ++axis) {
            if (direction[axis] > 1e-12) t = std::min(t, (high[axis] - eye[axis]) / direction[axis]);
            if (direction[axis] < -1e-12) t = std::min(t, (low[axis] - eye[axis]) / direction[axis]);
          }
          const Eigen::Vector3d to_centre = eye - sphere;
          const double b = to_centre.dot(direction);
          const double discriminant = b * b - (to_centre.squaredNorm() - 0.36);
          if (discriminant >= 0.0 && -b - std::sqrt(discriminant) > 0.0) t = std::min(t, -b - std::sqrt(discriminant));
          const uint16_t millimetres = static_cast<uint16_t>(std::lround(1000.0 * t * direction.dot(forward)));
          depth.millimetres.push_back(millimetres);
          depth.meters.push_back(static_cast<float>(millimetres) / 1000.0f);
        }
      }
      out.push_back(std::move(depth));
    }
    return out;
  }();
  return frames;
}

void BM_Tsdf_Hanzo(benchmark::State& state) {
  const double voxel = static_cast<double>(state.range(0)) / 1000.0;
  const auto& frames = room_frames();
  std::optional<maps::TsdfVolume> volume;
  msgs::MeshLayer mesh;
  double integrate_seconds = 0.0;
  double mesh_seconds = 0.0;
  for (auto _ : state) {
    auto start = std::chrono::steady_clock::now();
    volume.emplace(maps::TsdfConfig{.voxel_size = voxel});
    for (const DepthFrame& frame : frames) {
      (void)volume->integrate_depth({kDepthWidth, kDepthHeight, frame.meters}, depth_camera(), frame.T_world_camera);
    }
    integrate_seconds += seconds_since(start);
    start = std::chrono::steady_clock::now();
    mesh = volume->extract_mesh();
    mesh_seconds += seconds_since(start);
  }
  const double iterations = static_cast<double>(state.iterations());
  state.counters["ms_per_frame"] = 1e3 * integrate_seconds / (iterations * static_cast<double>(frames.size()));
  state.counters["mesh_ms"] = 1e3 * mesh_seconds / iterations;
  state.counters["triangles"] = static_cast<double>(mesh.triangle_indices.size() / 3);
  state.counters["memory_MB"] = static_cast<double>(volume->memory_bytes()) / 1e6;
}

void BM_Tsdf_Open3D(benchmark::State& state) {
  const double voxel = static_cast<double>(state.range(0)) / 1000.0;
  const auto& frames = room_frames();
  const msgs::CameraIntrinsics camera = depth_camera();
  bench::Open3dMeshSize mesh;
  double integrate_seconds = 0.0;
  double mesh_seconds = 0.0;
  for (auto _ : state) {
    auto start = std::chrono::steady_clock::now();
    bench::Open3dTsdf volume(voxel, 3.0 * voxel, kDepthWidth, kDepthHeight, camera.fx, camera.fy, camera.cx, camera.cy);
    for (const DepthFrame& frame : frames) volume.integrate(frame.millimetres, frame.T_world_camera.inverse().matrix());
    integrate_seconds += seconds_since(start);
    start = std::chrono::steady_clock::now();
    mesh = volume.extract_mesh();
    mesh_seconds += seconds_since(start);
  }
  const double iterations = static_cast<double>(state.iterations());
  state.counters["ms_per_frame"] = 1e3 * integrate_seconds / (iterations * static_cast<double>(frames.size()));
  state.counters["mesh_ms"] = 1e3 * mesh_seconds / iterations;
  state.counters["triangles"] = static_cast<double>(mesh.triangles);
}

void BM_WarehouseTsdf_Hanzo(benchmark::State& state) {
  static const sim::World world = warehouse();
  std::optional<maps::TsdfVolume> volume;
  std::size_t scans = 0;
  double seconds = 0.0;
  for (auto _ : state) {
    volume.emplace(maps::TsdfConfig{.voxel_size = 0.05, .max_range = 30.0});
    scans = 0;
    seconds = 0.0;
    for (int aisle = 0; aisle < 10; ++aisle) {
      for (double x = 2.0; x <= 98.0; x += 2.0) {
        const Eigen::Vector3d origin(x, 5.0 + 10.0 * aisle, 1.0);
        std::vector<Eigen::Vector3d> returns;
        for (int ring = 0; ring < 16; ++ring) {
          const double elevation = (-15.0 + 2.0 * ring) * M_PI / 180.0;
          for (int column = 0; column < 360; ++column) {
            const double azimuth = column * M_PI / 180.0;
            const Eigen::Vector3d direction(std::cos(elevation) * std::cos(azimuth), std::cos(elevation) * std::sin(azimuth), std::sin(elevation));
            if (const auto hit = world.cast(origin, direction, 30.0, Timestamp{})) returns.push_back(hit->point);
          }
        }
        const auto start = std::chrono::steady_clock::now();
        (void)volume->integrate_scan(origin, returns);
        seconds += seconds_since(start);
        ++scans;
      }
    }
  }
  state.counters["scans"] = static_cast<double>(scans);
  state.counters["ms_per_scan"] = 1e3 * seconds / static_cast<double>(scans);
  state.counters["blocks"] = static_cast<double>(volume->block_count());
  state.counters["memory_MB"] = static_cast<double>(volume->memory_bytes()) / 1e6;
}

}  // namespace

BENCHMARK(BM_Tsdf_Hanzo)->Arg(20)->Arg(50)->Unit(benchmark::kMillisecond);
BENCHMARK(BM_Tsdf_Open3D)->Arg(20)->Arg(50)->Unit(benchmark::kMillisecond);
BENCHMARK(BM_WarehouseTsdf_Hanzo)->Unit(benchmark::kMillisecond)->Iterations(1);
BENCHMARK(BM_Intel2D_Hanzo)->Unit(benchmark::kMillisecond);
BENCHMARK(BM_Intel2D_OctoMap)->Unit(benchmark::kMillisecond);
BENCHMARK(BM_Scan3D_Hanzo)->Arg(10)->Arg(20)->Unit(benchmark::kMillisecond);
BENCHMARK(BM_Scan3D_OctoMap)->Arg(10)->Arg(20)->Unit(benchmark::kMillisecond);
BENCHMARK(BM_Warehouse2D_Hanzo)->Unit(benchmark::kMillisecond)->Iterations(1);
BENCHMARK_MAIN();
