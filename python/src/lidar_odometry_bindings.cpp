// Python bindings of 3D LiDAR odometry (lidar/lidar_odometry.hpp): sweeps as N x 3 numpy arrays
// (sensor frame, m) with optional per-point times (s from the sweep time) and ring indices,
// poses as Pose3. Bad input raises ValueError with the library's message.

#include <cmath>

#include <pybind11/eigen.h>
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>

#include "hanzo/fusion/lidar/lidar_odometry.hpp"

namespace py = pybind11;
using namespace hanzo::fusion;

namespace {

using PointRows = Eigen::Matrix<double, Eigen::Dynamic, 3, Eigen::RowMajor>;

lidar::LidarOdometryEstimate add_scan(lidar::LidarOdometry& odometry, double time_s, const PointRows& points,
                                      const std::optional<std::vector<double>>& times,
                                      const std::optional<std::vector<int>>& rings) {
  if (!std::isfinite(time_s) || time_s <= 0) throw py::value_error("add_scan: time_s must be a positive finite number");
  const std::size_t count = static_cast<std::size_t>(points.rows());
  if (times && times->size() != count) throw py::value_error("add_scan: times must have one value per point");
  if (rings && rings->size() != count) throw py::value_error("add_scan: rings must have one value per point");
  cloud::PointCloud scan;
  scan.positions.resize(count);
  for (std::size_t i = 0; i < count; ++i) scan.positions[i] = points.row(static_cast<Eigen::Index>(i)).transpose().cast<float>();
  if (times) {
    for (const double t : *times) scan.times.push_back(static_cast<float>(t));
  }
  if (rings) {
    for (const int ring : *rings) {
      if (ring < 0 || ring > 65535) throw py::value_error("add_scan: ring indices must be in [0, 65535]");
      scan.rings.push_back(static_cast<uint16_t>(ring));
    }
  }
  auto estimate = odometry.add_scan(Timestamp::from_seconds(time_s), scan);
  if (!estimate) throw py::value_error(estimate.error().message);
  return *estimate;
}

}  // namespace

void bind_lidar_odometry(py::module_& module) {
  py::class_<lidar::LidarOdometryEstimate>(module, "LidarOdometryEstimate")
      .def_property_readonly("time_s", [](const lidar::LidarOdometryEstimate& e) { return e.time.seconds(); },
                             "The middle of the sweep, which the pose refers to")
      .def_readonly("pose", &lidar::LidarOdometryEstimate::T_world_lidar, "T_world_lidar")
      .def_readonly("covariance", &lidar::LidarOdometryEstimate::covariance, "6 x 6, tangent (x, y, z, rx, ry, rz)")
      .def_readonly("degenerate", &lidar::LidarOdometryEstimate::degenerate)
      .def_readonly("constraint_ratio", &lidar::LidarOdometryEstimate::constraint_ratio)
      .def_readonly("weather_degraded", &lidar::LidarOdometryEstimate::weather_degraded)
      .def_readonly("phantom_points", &lidar::LidarOdometryEstimate::phantom_points)
      .def_readonly("iterations", &lidar::LidarOdometryEstimate::iterations)
      .def_readonly("correspondences", &lidar::LidarOdometryEstimate::correspondences)
      .def_readonly("inlier_rmse", &lidar::LidarOdometryEstimate::inlier_rmse)
      .def_readonly("map_points", &lidar::LidarOdometryEstimate::map_points);

  py::class_<lidar::LidarOdometry>(module, "LidarOdometry",
                                   "LiDAR odometry: each sweep registered to a sliding voxel map (docs/lidar-odometry.md)")
      .def(py::init([](double voxel, double source_voxel, const SE3& initial_pose) {
             lidar::LidarOdometryConfig config;
             config.map.voxel_size = voxel;
             config.registration.max_neighbour_distance = voxel;
             config.source_voxel_size = source_voxel;
             if (Status valid = config.validate(); !valid) throw py::value_error(valid.error().message);
             return lidar::LidarOdometry(config, initial_pose);
           }),
           py::arg("voxel") = 1.0, py::arg("source_voxel") = 1.0, py::arg("initial_pose") = SE3())
      .def("add_scan", &add_scan,
           "A sweep: N x 3 points (sensor frame, m), optional per-point times (s after time_s) and ring indices "
           "(range-image normals need them)",
           py::arg("time_s"), py::arg("points"), py::arg("times") = std::nullopt, py::arg("rings") = std::nullopt)
      .def_property_readonly("pose", &lidar::LidarOdometry::pose, "The latest T_world_lidar")
      .def_property_readonly("scans", &lidar::LidarOdometry::scans)
      .def("map_points", [](const lidar::LidarOdometry& odometry) {
        const std::vector<Eigen::Vector3f> points = odometry.local_map().points();
        PointRows out(static_cast<Eigen::Index>(points.size()), 3);
        for (std::size_t i = 0; i < points.size(); ++i) out.row(static_cast<Eigen::Index>(i)) = points[i].cast<double>().transpose();
        return out;
      }, "The local map's points (N x 3, world frame)");
}
