// Python bindings of the sensor models the factor graph's IMU and camera factors take
// (FactorGraph.add_imu_factor, add_projection_factor, add_stereo_factor in bindings.cpp):
// ImuPreintegration (Forster et al. 2017) and PinholeCamera. Vectors are numpy arrays; an IMU
// bias is a 6-vector (accelerometer m/s^2, gyroscope rad/s). Bad input raises ValueError naming
// what is wrong.

#include <cmath>
#include <string>
#include <vector>

#include <fmt/format.h>
#include <pybind11/eigen.h>
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>

#include "hanzo/fusion/core/pinhole_camera.hpp"
#include "hanzo/fusion/graph/imu_preintegration.hpp"

namespace py = pybind11;
using namespace hanzo::fusion;

namespace {

using Vector6d = Eigen::Matrix<double, 6, 1>;

graph::ImuBias bias_from(const Vector6d& bias) {
  if (!bias.allFinite()) throw py::value_error("IMU bias: non-finite value");
  graph::ImuBias result;
  result.accelerometer = bias.head<3>();
  result.gyroscope = bias.tail<3>();
  return result;
}

PinholeCamera::Distortion distortion_from(const std::string& name) {
  if (name == "none") return PinholeCamera::Distortion::kNone;
  if (name == "radtan") return PinholeCamera::Distortion::kRadtan;
  if (name == "equidistant") return PinholeCamera::Distortion::kEquidistant;
  throw py::value_error(fmt::format("PinholeCamera: distortion '{}': use 'none', 'radtan' (k1 k2 p1 p2 k3) or 'equidistant' (k1 k2 k3 k4)", name));
}

std::string distortion_name(PinholeCamera::Distortion distortion) {
  switch (distortion) {
    case PinholeCamera::Distortion::kNone: return "none";
    case PinholeCamera::Distortion::kRadtan: return "radtan";
    case PinholeCamera::Distortion::kEquidistant: return "equidistant";
  }
  return "none";
}

PinholeCamera make_camera(double fx, double fy, double cx, double cy, const std::string& distortion, const std::vector<double>& coefficients) {
  PinholeCamera camera;
  camera.fx = fx;
  camera.fy = fy;
  camera.cx = cx;
  camera.cy = cy;
  camera.distortion = distortion_from(distortion);
  if (!(std::isfinite(fx) && std::isfinite(fy) && fx > 0.0 && fy > 0.0 && std::isfinite(cx) && std::isfinite(cy))) {
    throw py::value_error(fmt::format("PinholeCamera: focal lengths must be finite and > 0 and the principal point finite (fx {}, fy {}, cx {}, cy {})",
                                      fx, fy, cx, cy));
  }
  const std::size_t expected = camera.distortion == PinholeCamera::Distortion::kRadtan        ? 5
                               : camera.distortion == PinholeCamera::Distortion::kEquidistant ? 4
                                                                                              : 0;
  if (coefficients.size() > expected || (expected == 4 && coefficients.size() != 4) || (expected == 5 && coefficients.size() < 4)) {
    throw py::value_error(fmt::format("PinholeCamera: distortion '{}' takes {} coefficients, got {}", distortion,
                                      expected == 5 ? "4 or 5" : std::to_string(expected), coefficients.size()));
  }
  for (std::size_t i = 0; i < coefficients.size(); ++i) {
    if (!std::isfinite(coefficients[i])) throw py::value_error("PinholeCamera: non-finite distortion coefficient");
    camera.coefficients[i] = coefficients[i];
  }
  return camera;
}

}  // namespace

void bind_sensor_models(py::module_& module) {
  py::class_<graph::ImuPreintegration>(
      module, "ImuPreintegration",
      "IMU samples between two keyframes preintegrated on the manifold (Forster et al. 2017), for FactorGraph.add_imu_factor")
      .def(py::init([](double process_noise_accel, double process_noise_gyro, double sample_interval, const Eigen::Vector3d& gravity,
                       const Vector6d& bias) {
             if (!(std::isfinite(process_noise_accel) && process_noise_accel > 0.0 && std::isfinite(process_noise_gyro) &&
                   process_noise_gyro > 0.0)) {
               throw py::value_error("ImuPreintegration: process_noise_accel and process_noise_gyro must be finite and > 0");
             }
             if (!(std::isfinite(sample_interval) && sample_interval > 0.0)) {
               throw py::value_error("ImuPreintegration: sample_interval must be finite and > 0 (1 / IMU rate, s)");
             }
             if (!gravity.allFinite()) throw py::value_error("ImuPreintegration: non-finite gravity");
             graph::ImuPreintegrationConfig config;
             config.process_noise_accel = process_noise_accel;
             config.process_noise_gyro = process_noise_gyro;
             config.sample_interval = sample_interval;
             config.gravity = gravity;
             return graph::ImuPreintegration(config, bias_from(bias));
           }),
           "Per-sample standard deviations (m/s^2, rad/s) at the IMU's sample interval (s); gravity in the world frame (m/s^2); "
           "the bias estimate the samples are integrated with (accelerometer, gyroscope)",
           py::arg("process_noise_accel") = 0.1, py::arg("process_noise_gyro") = 0.01, py::arg("sample_interval") = 0.005,
           py::arg("gravity") = Eigen::Vector3d(0.0, 0.0, -9.80665), py::arg("bias") = Vector6d::Zero())
      .def(
          "integrate",
          [](graph::ImuPreintegration& self, const Eigen::Vector3d& specific_force, const Eigen::Vector3d& angular_velocity, double dt) {
            if (Status added = self.integrate(specific_force, angular_velocity, dt); !added) throw py::value_error(added.error().message);
          },
          "Adds one sample (accelerometer m/s^2, gyroscope rad/s, IMU frame) held over dt seconds", py::arg("specific_force"),
          py::arg("angular_velocity"), py::arg("dt"))
      .def_property_readonly("sample_count", &graph::ImuPreintegration::sample_count)
      .def_property_readonly("delta_time", &graph::ImuPreintegration::delta_time, "t_j - t_i, seconds")
      .def_property_readonly("delta_rotation", [](const graph::ImuPreintegration& self) { return Eigen::Matrix3d(self.deltas().rotation.matrix()); })
      .def_property_readonly("delta_velocity", [](const graph::ImuPreintegration& self) { return Eigen::Vector3d(self.deltas().velocity); })
      .def_property_readonly("delta_position", [](const graph::ImuPreintegration& self) { return Eigen::Vector3d(self.deltas().position); })
      .def_property_readonly("covariance", [](const graph::ImuPreintegration& self) { return Eigen::MatrixXd(self.covariance()); },
                             "9x9, (rotation, velocity, position)")
      .def(
          "predict",
          [](const graph::ImuPreintegration& self, const SE3& pose_i, const Eigen::Vector3d& velocity_i, const Vector6d& bias) {
            SE3 pose_j;
            Eigen::Vector3d velocity_j;
            self.predict(pose_i, velocity_i, bias_from(bias), &pose_j, &velocity_j);
            return py::make_tuple(pose_j, velocity_j);
          },
          "(pose_j, velocity_j) predicted from T_world_imu and the world velocity at i, with the deltas corrected for bias",
          py::arg("pose_i"), py::arg("velocity_i"), py::arg("bias") = Vector6d::Zero());

  py::class_<PinholeCamera>(module, "PinholeCamera",
                            "Pinhole intrinsics (pixels) with 'none', 'radtan' (OpenCV plumb_bob: k1 k2 p1 p2 [k3]) or "
                            "'equidistant' (OpenCV fisheye: k1 k2 k3 k4) distortion; camera frame x right, y down, z forward")
      .def(py::init(&make_camera), py::arg("fx"), py::arg("fy"), py::arg("cx"), py::arg("cy"), py::arg("distortion") = "none",
           py::arg("coefficients") = std::vector<double>{})
      .def(
          "project",
          [](const PinholeCamera& camera, const Eigen::Vector3d& point_camera) -> py::object {
            const auto pixel = camera.project(point_camera);
            if (!pixel) return py::none();
            return py::cast(Eigen::Vector2d(*pixel));
          },
          "The pixel of a camera-frame point, None at or behind the camera", py::arg("point_camera"))
      .def_property_readonly("distortion", [](const PinholeCamera& camera) { return distortion_name(camera.distortion); });
}
