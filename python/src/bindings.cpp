// Python bindings (module hanzo.fusion._fusion, re-exported by hanzo/fusion/__init__.py): the
// factor-graph backend as the spec's Python example uses it, with numpy arrays for vectors and
// matrices. Bad input (non-orthonormal rotations, wrong shapes, covariances that are not
// positive definite, keys without a value) raises ValueError with a message naming it.

#include <cmath>
#include <map>
#include <optional>
#include <stdexcept>

#include <fmt/format.h>
#include <pybind11/eigen.h>
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>

#include "hanzo/fusion/core/geodesy.hpp"
#include "hanzo/fusion/graph/batch_optimizer.hpp"
#include "hanzo/fusion/graph/chordal_initialization.hpp"
#include "hanzo/fusion/graph/g2o_io.hpp"
#include "hanzo/fusion/graph/optimality_certificate.hpp"
#include "hanzo/fusion/graph/incremental_smoother.hpp"
#include "hanzo/fusion/graph/imu_factors.hpp"
#include "hanzo/fusion/graph/pose_factors.hpp"
#include "hanzo/fusion/graph/projection_factors.hpp"

namespace py = pybind11;
using namespace hanzo::fusion;

namespace {

template <typename T>
T value_or_raise(Result<T> result) {
  if (!result) throw py::value_error(result.error().message);
  return std::move(*result);
}

SO3 rotation_from(const Eigen::Matrix3d& R) {
  if (!R.allFinite() || (R.transpose() * R - Eigen::Matrix3d::Identity()).cwiseAbs().maxCoeff() > 1e-6 || R.determinant() < 0.0) {
    throw py::value_error("Pose3: the rotation must be a finite orthonormal 3x3 matrix with determinant +1");
  }
  return SO3::from_matrix(R);
}

// Noise from a numpy array: 1-D = standard deviations, 2-D = covariance.
graph::GaussianNoise noise_from(const Eigen::MatrixXd& noise, int dimension, const char* what) {
  Result<graph::GaussianNoise> model = Error("");
  if (noise.cols() == 1 || noise.rows() == 1) {
    const Eigen::VectorXd sigmas = noise.reshaped();
    if (sigmas.size() != dimension) throw py::value_error(fmt::format("{}: expected {} standard deviations, got {}", what, dimension, sigmas.size()));
    model = graph::GaussianNoise::from_sigmas(sigmas);
  } else {
    if (noise.rows() != dimension || noise.cols() != dimension) {
      throw py::value_error(fmt::format("{}: expected a {}x{} covariance, got {}x{}", what, dimension, dimension, noise.rows(), noise.cols()));
    }
    model = graph::GaussianNoise::from_covariance(noise);
  }
  if (!model) throw py::value_error(fmt::format("{}: {}", what, model.error().message));
  return *model;
}

py::object to_python(const graph::Value& value) {
  if (const auto* se3 = std::get_if<SE3>(&value)) return py::cast(*se3);
  if (const auto* se2 = std::get_if<SE2>(&value)) return py::cast(*se2);
  if (const auto* vector = std::get_if<Eigen::Vector3d>(&value)) return py::cast(*vector);
  const auto& bias = std::get<graph::ImuBias>(value);
  return py::cast(bias.vector());
}

graph::Value from_python(const py::object& object) {
  if (py::isinstance<SE3>(object)) return object.cast<SE3>();
  if (py::isinstance<SE2>(object)) return object.cast<SE2>();
  const Eigen::VectorXd vector = object.cast<Eigen::VectorXd>();
  if (!vector.allFinite()) throw py::value_error("a value must be finite");
  if (vector.size() == 3) return Eigen::Vector3d(vector);
  if (vector.size() == 6) {
    graph::ImuBias bias;
    bias.accelerometer = vector.head<3>();
    bias.gyroscope = vector.tail<3>();
    return bias;
  }
  throw py::value_error("a value must be a Pose3, a Pose2, a 3-vector (velocity, point) or a 6-vector (IMU bias: accelerometer, gyroscope)");
}

struct OptimizeResult {
  graph::Values values;
  graph::OptimizationSummary summary;
  std::shared_ptr<const graph::FactorGraph> graph;
  std::vector<graph::Key> fixed;
  std::shared_ptr<const graph::PoseGraph> source;  // the g2o / TORO file, when read from one

  const graph::PoseGraph& file() const {
    if (!source) throw py::value_error("this graph was not read from a g2o / TORO file");
    return *source;
  }
  double g2o_chi2() const { return value_or_raise(graph::g2o_chi2(file(), values)); }
  double se_sync_objective() const { return value_or_raise(graph::se_sync_objective(file(), values)); }
  void write_g2o(const std::string& path) const {
    if (Status written = graph::write_g2o(path, file(), values); !written) throw py::value_error(written.error().message);
  }
  py::dict certificate() const {
    const graph::OptimalityCertificate certificate = value_or_raise(graph::certify_global_optimality(file(), values));
    py::dict result;
    result["certified"] = certificate.certified;
    result["min_eigenvalue"] = certificate.min_eigenvalue;
    result["se_sync_objective"] = certificate.objective_refined;
    result["max_translation_change"] = certificate.max_translation_change;
    result["max_rotation_change"] = certificate.max_rotation_change;
    result["message"] = certificate.message;
    return result;
  }

  py::object at(graph::Key key) const {
    const auto found = values.all().find(key);
    if (found == values.all().end()) throw py::key_error(fmt::format("no value for {}", graph::key_to_string(key)));
    return to_python(found->second);
  }
  Eigen::MatrixXd marginal_covariance(graph::Key key) const {
    graph::BatchOptimizerConfig config;
    config.fixed = fixed;
    return value_or_raise(graph::marginal_covariances(*graph, values, {key}, config)).front();
  }
};

// The spec's FactorGraph: factors plus optional initial values; optimize() fills in missing
// initial poses by chaining between factors (GPS positions for poses no chain reaches) and
// anchors the gauge when no prior does (see optimize()).
class PyFactorGraph {
 public:
  /// A g2o / TORO file: its between factors, initial guesses and fixed vertices. objective
  /// "geodesic": g2o's factors; "chordal": SE-Sync's objective (its published optima).
  static PyFactorGraph from_file(const std::string& path, const std::string& objective) {
    if (objective != "geodesic" && objective != "chordal") {
      throw py::value_error(fmt::format("objective '{}': use 'geodesic' or 'chordal'", objective));
    }
    PyFactorGraph result;
    auto source = std::make_shared<graph::PoseGraph>(value_or_raise(graph::read_g2o(path)));
    *result.graph_ = value_or_raise(source->factor_graph(objective == "chordal" ? graph::PoseGraph::Objective::kChordal
                                                                                : graph::PoseGraph::Objective::kGeodesic));
    result.initial_ = source->initial;
    result.fixed_ = source->fixed;
    result.source_ = std::move(source);
    return result;
  }
  /// The factors and the initial values inserted so far (for IncrementalSmoother.update).
  const graph::FactorGraph& factors() const { return *graph_; }
  const graph::Values& initial_values() const { return initial_; }

  void add_between_factor(graph::Key key_from, graph::Key key_to, const py::object& measurement, const Eigen::MatrixXd& noise) {
    if (py::isinstance<SE3>(measurement)) {
      graph_->emplace<graph::BetweenFactorSE3>(key_from, key_to, measurement.cast<SE3>(), noise_from(noise, 6, "between factor noise"));
    } else if (py::isinstance<SE2>(measurement)) {
      graph_->emplace<graph::BetweenFactorSE2>(key_from, key_to, measurement.cast<SE2>(), noise_from(noise, 3, "between factor noise"));
    } else {
      throw py::value_error("add_between_factor: the measurement must be a Pose3 or a Pose2");
    }
    chains_.push_back({key_from, key_to, from_python(measurement)});
  }
  void add_prior_factor(graph::Key key, const py::object& prior, const Eigen::MatrixXd& noise) {
    if (py::isinstance<SE3>(prior)) {
      graph_->emplace<graph::PriorFactorSE3>(key, prior.cast<SE3>(), noise_from(noise, 6, "prior noise"));
    } else if (py::isinstance<SE2>(prior)) {
      graph_->emplace<graph::PriorFactorSE2>(key, prior.cast<SE2>(), noise_from(noise, 3, "prior noise"));
    } else {
      const graph::Value value = from_python(prior);  // a velocity / point or an IMU bias
      if (const auto* vector = std::get_if<Eigen::Vector3d>(&value)) {
        graph_->emplace<graph::PriorFactorVector3>(key, *vector, noise_from(noise, 3, "prior noise"));
      } else if (const auto* bias = std::get_if<graph::ImuBias>(&value)) {
        graph_->emplace<graph::PriorFactorImuBias>(key, *bias, noise_from(noise, 6, "prior noise"));
      } else {
        throw py::value_error("add_prior_factor: the prior must be a Pose3, a Pose2, a 3-vector or a 6-vector (IMU bias)");
      }
      if (!initial_.exists(key)) initial_.insert(key, value);
      return;
    }
    anchored_by_prior_ = true;
    if (!initial_.exists(key)) initial_.insert(key, from_python(prior));
  }
  void add_imu_factor(graph::Key pose_i, graph::Key velocity_i, graph::Key pose_j, graph::Key velocity_j, graph::Key bias_i,
                      const graph::ImuPreintegration& preintegration) {
    graph_->add(value_or_raise(graph::ImuFactor::create(pose_i, velocity_i, pose_j, velocity_j, bias_i, preintegration)));
  }
  void add_bias_random_walk_factor(graph::Key bias_i, graph::Key bias_j, double dt, double accel_bias_random_walk, double gyro_bias_random_walk) {
    graph_->add(value_or_raise(graph::ImuBiasRandomWalkFactor::create(bias_i, bias_j, dt, accel_bias_random_walk, gyro_bias_random_walk)));
  }
  void add_gravity_factor(graph::Key pose, const Eigen::Vector3d& specific_force, const Eigen::MatrixXd& noise, const Eigen::Vector3d& gravity) {
    if (!specific_force.allFinite() || !gravity.allFinite()) throw py::value_error("add_gravity_factor: non-finite specific force or gravity");
    graph_->emplace<graph::GravityFactor>(pose, specific_force, noise_from(noise, 3, "gravity factor noise"), gravity);
  }
  void add_projection_factor(graph::Key pose, graph::Key landmark, const Eigen::Vector2d& pixel, const PinholeCamera& camera,
                             const SE3& T_body_camera, const Eigen::MatrixXd& noise) {
    if (!pixel.allFinite()) throw py::value_error("add_projection_factor: non-finite pixel");
    graph_->emplace<graph::ProjectionFactor>(pose, landmark, pixel, camera, T_body_camera, noise_from(noise, 2, "projection noise"));
  }
  void add_stereo_factor(graph::Key pose, graph::Key landmark, const Eigen::Vector3d& measured, const PinholeCamera& camera,
                         double baseline, const SE3& T_body_camera, const Eigen::MatrixXd& noise) {
    if (!measured.allFinite()) throw py::value_error("add_stereo_factor: non-finite measurement");
    if (camera.distortion != PinholeCamera::Distortion::kNone) {
      throw py::value_error("add_stereo_factor: a stereo pair must be rectified (the camera's distortion must be 'none')");
    }
    if (!(std::isfinite(baseline) && baseline > 0.0)) throw py::value_error(fmt::format("add_stereo_factor: baseline {} m is not > 0", baseline));
    graph_->emplace<graph::StereoProjectionFactor>(pose, landmark, measured, camera, baseline, T_body_camera,
                                                   noise_from(noise, 3, "stereo noise"));
  }
  void add_gps_factor(graph::Key key, const Eigen::Vector3d& measurement, const Eigen::MatrixXd& noise, const Eigen::Vector3d& lever_arm) {
    if (!measurement.allFinite() || !lever_arm.allFinite()) throw py::value_error("add_gps_factor: non-finite measurement or lever arm");
    graph_->emplace<graph::GpsFactor>(key, measurement, lever_arm, noise_from(noise, 3, "GPS noise"));
    gps_.emplace(key, measurement);
  }
  void insert(graph::Key key, const py::object& value) { initial_.insert(key, from_python(value)); }
  std::size_t size() const { return graph_->size(); }

  OptimizeResult optimize(int max_iterations, const std::string& initialization) const {
    if (initialization != "initial" && initialization != "chordal") {
      throw py::value_error(fmt::format("initialization '{}': use 'initial' or 'chordal'", initialization));
    }
    if (source_) {  // a file: its vertices and FIX lines
      graph::BatchOptimizerConfig config;
      config.fixed = fixed_;
      config.max_iterations = max_iterations;
      OptimizeResult result;
      result.values = initialization == "chordal" ? value_or_raise(graph::chordal_initialization(*source_)) : initial_;
      result.summary = value_or_raise(graph::optimize(*graph_, result.values, config));
      result.graph = graph_;
      result.fixed = fixed_;
      result.source = source_;
      return result;
    }
    if (initialization == "chordal") throw py::value_error("chordal initialization needs a graph read from a g2o / TORO file");
    graph::Values values = initial_;
    for (bool changed = true; changed;) {  // chain between factors from known poses
      changed = false;
      for (const Chain& chain : chains_) {
        const bool has_from = values.exists(chain.from), has_to = values.exists(chain.to);
        if (has_from == has_to) continue;
        values.insert(has_from ? chain.to : chain.from, has_from ? compose(values.all().at(chain.from), chain.measurement, false)
                                                               : compose(values.all().at(chain.to), chain.measurement, true));
        changed = true;
      }
      if (!changed && !chains_.empty()) {  // a pose nothing reaches yet: its GPS fix, or the origin for the very first
        for (const Chain& chain : chains_) {
          for (graph::Key key : {chain.from, chain.to}) {
            if (values.exists(key) || changed) continue;
            const auto gps = gps_.find(key);
            if (gps == gps_.end() && values.size() > 0) continue;
            const Eigen::Vector3d position = gps != gps_.end() ? gps->second : Eigen::Vector3d::Zero();
            if (std::holds_alternative<SE2>(chain.measurement)) {
              values.insert(key, SE2(0.0, position.head<2>()));
            } else {
              values.insert(key, SE3(SO3(), position));
            }
            changed = true;
          }
        }
      }
    }
    for (const auto& [key, position] : gps_) {
      if (!values.exists(key)) values.insert(key, SE3(SO3(), position));
    }
    // The gauge: a prior anchors the graph; GPS alone may leave the heading free (one fix), so
    // a weak prior on the first pose takes what the fixes leave; otherwise the first pose is fixed.
    std::vector<graph::Key> fixed;
    auto factors = graph_;
    if (!anchored_by_prior_ && !chains_.empty()) {
      const graph::Key first = chains_.front().from;
      if (gps_.empty()) {
        fixed.push_back(first);
      } else {
        factors = std::make_shared<graph::FactorGraph>(*graph_);
        const graph::Value& start = values.all().at(first);
        const Eigen::VectorXd sigmas = std::holds_alternative<SE2>(start) ? Eigen::VectorXd(Eigen::Vector3d(1e3, 1e3, M_PI))
                                                                           : (Eigen::VectorXd(6) << 1e3, 1e3, 1e3, M_PI, M_PI, M_PI).finished();
        const graph::GaussianNoise weak = graph::GaussianNoise::from_sigmas(sigmas).value();
        if (const auto* se2 = std::get_if<SE2>(&start)) {
          factors->emplace<graph::PriorFactorSE2>(first, *se2, weak);
        } else {
          factors->emplace<graph::PriorFactorSE3>(first, std::get<SE3>(start), weak);
        }
      }
    }
    graph::BatchOptimizerConfig config;
    config.fixed = fixed;
    config.max_iterations = max_iterations;
    OptimizeResult result;
    result.summary = value_or_raise(graph::optimize(*factors, values, config));
    result.values = std::move(values);
    result.graph = factors;
    result.fixed = std::move(fixed);
    return result;
  }

 private:
  struct Chain {
    graph::Key from;
    graph::Key to;
    graph::Value measurement;
  };
  static graph::Value compose(const graph::Value& pose, const graph::Value& measurement, bool inverse) {
    if (const auto* se2 = std::get_if<SE2>(&pose)) {
      const SE2& z = std::get<SE2>(measurement);
      return *se2 * (inverse ? z.inverse() : z);
    }
    const SE3& z = std::get<SE3>(measurement);
    return std::get<SE3>(pose) * (inverse ? z.inverse() : z);
  }

  std::shared_ptr<graph::FactorGraph> graph_ = std::make_shared<graph::FactorGraph>();
  graph::Values initial_;
  std::vector<Chain> chains_;
  std::map<graph::Key, Eigen::Vector3d> gps_;
  bool anchored_by_prior_ = false;
  std::vector<graph::Key> fixed_;                  // a file's fixed vertices
  std::shared_ptr<const graph::PoseGraph> source_;  // the file it was read from
};

// graph::IncrementalSmoother for Python: updates are FactorGraphs holding the new factors and
// the initial values of the new variables (insert()).
class PyIncrementalSmoother {
 public:
  PyIncrementalSmoother(int recent_variables, bool background_batch) {
    graph::IncrementalSmootherConfig config;
    config.recent_variables = recent_variables;
    config.background_batch = background_batch;
    smoother_ = std::make_unique<graph::IncrementalSmoother>(config);
  }
  py::dict update(const PyFactorGraph& new_factors) {
    const graph::IncrementalUpdateSummary summary = value_or_raise(smoother_->update(new_factors.factors(), new_factors.initial_values()));
    py::dict result;
    result["optimized_variables"] = summary.optimized_variables;
    result["local_chi2_before"] = summary.local_chi2_before;
    result["local_chi2_after"] = summary.local_chi2_after;
    result["batch_merged"] = summary.batch_merged;
    return result;
  }
  py::object at(graph::Key key) const {
    const auto found = smoother_->estimate().all().find(key);
    if (found == smoother_->estimate().all().end()) throw py::key_error(fmt::format("no value for {}", graph::key_to_string(key)));
    return to_python(found->second);
  }
  /// Runs the full batch to convergence; returns its final cost.
  double wait_for_batch() { return value_or_raise(smoother_->wait_for_batch()).final_chi2; }
  std::size_t size() const { return smoother_->estimate().size(); }

 private:
  std::unique_ptr<graph::IncrementalSmoother> smoother_;
};

}  // namespace

void bind_laser_slam(py::module_& module);  // laser_slam_bindings.cpp
void bind_lidar_odometry(py::module_& module);  // lidar_odometry_bindings.cpp
void bind_session(py::module_& module);  // session_bindings.cpp
void bind_object_store(py::module_& module);  // object_store_bindings.cpp
void bind_sensor_log(py::module_& module);  // log_bindings.cpp
void bind_evaluation(py::module_& module);  // evaluation_bindings.cpp
void bind_sensor_models(py::module_& module);   // sensor_model_bindings.cpp

PYBIND11_MODULE(_fusion, module) {
  module.doc() = "hanzo-fusion: factor graphs for sensor fusion and SLAM";
  module.attr("__version__") = HANZO_FUSION_VERSION;

  module.def("X", &graph::X, "The key of pose i", py::arg("i"));
  module.def("V", &graph::V, "The key of velocity i", py::arg("i"));
  module.def("B", &graph::B, "The key of IMU bias i", py::arg("i"));
  module.def("L", &graph::L, "The key of landmark j", py::arg("j"));
  module.def("key_to_string", &graph::key_to_string, py::arg("key"));
  bind_sensor_models(module);  // before FactorGraph, whose signatures name its classes
  module.def(
      "Point3", [](double x, double y, double z) { return Eigen::Vector3d(x, y, z); }, "A 3D point as a numpy array", py::arg("x"),
      py::arg("y"), py::arg("z"));
  module.def(
      "geodetic_to_enu",
      [](double latitude, double longitude, double altitude, double datum_latitude, double datum_longitude, double datum_altitude) {
        const EnuFrame frame = value_or_raise(EnuFrame::create({datum_latitude, datum_longitude, datum_altitude}));
        return frame.to_enu({latitude, longitude, altitude});
      },
      "WGS84 latitude, longitude (degrees), altitude (m) to east, north, up metres from a datum", py::arg("latitude"), py::arg("longitude"),
      py::arg("altitude"), py::arg("datum_latitude"), py::arg("datum_longitude"), py::arg("datum_altitude"));

  py::class_<SE3>(module, "Pose3", "A rigid transform in 3D (rotation R, translation t): p' = R p + t")
      .def(py::init<>())
      .def(py::init([](const Eigen::Matrix3d& R, const Eigen::Vector3d& t) {
             if (!t.allFinite()) throw py::value_error("Pose3: non-finite translation");
             return SE3(rotation_from(R), t);
           }),
           py::arg("R"), py::arg("t"))
      .def_static(
          "from_matrix",
          [](const Eigen::Matrix4d& T) {
            if (!T.allFinite() || !T.row(3).isApprox(Eigen::RowVector4d(0, 0, 0, 1))) throw py::value_error("Pose3: not a homogeneous 4x4 matrix");
            return SE3(rotation_from(T.topLeftCorner<3, 3>()), T.block<3, 1>(0, 3));
          },
          py::arg("T"))
      .def_static(
          "exp", [](const Eigen::Matrix<double, 6, 1>& xi) { return SE3::exp(xi); }, "From a tangent vector (translation, rotation)",
          py::arg("xi"))
      .def("log", [](const SE3& T) { return Eigen::Matrix<double, 6, 1>(T.log()); })
      .def("rotation", [](const SE3& T) { return Eigen::Matrix3d(T.rotation().matrix()); })
      .def("translation", [](const SE3& T) { return Eigen::Vector3d(T.translation()); })
      .def("matrix", [](const SE3& T) { return Eigen::Matrix4d(T.matrix()); })
      .def("inverse", [](const SE3& T) { return T.inverse(); })
      .def("__mul__", [](const SE3& a, const SE3& b) { return a * b; })
      .def("__mul__", [](const SE3& a, const Eigen::Vector3d& p) { return Eigen::Vector3d(a * p); })
      .def("__repr__", [](const SE3& T) {
        const Eigen::Vector3d t = T.translation(), r = T.rotation().log();
        return fmt::format("Pose3(t=[{:.6g}, {:.6g}, {:.6g}], rotation_vector=[{:.6g}, {:.6g}, {:.6g}])", t.x(), t.y(), t.z(), r.x(), r.y(), r.z());
      });

  py::class_<SE2>(module, "Pose2", "A rigid transform in 2D")
      .def(py::init<>())
      .def(py::init([](double x, double y, double theta) { return SE2(theta, Eigen::Vector2d(x, y)); }), py::arg("x"), py::arg("y"),
           py::arg("theta"))
      .def("x", [](const SE2& T) { return T.translation().x(); })
      .def("y", [](const SE2& T) { return T.translation().y(); })
      .def("theta", &SE2::angle)
      .def("inverse", [](const SE2& T) { return T.inverse(); })
      .def("__mul__", [](const SE2& a, const SE2& b) { return a * b; })
      .def("__repr__", [](const SE2& T) { return fmt::format("Pose2(x={:.6g}, y={:.6g}, theta={:.6g})", T.translation().x(), T.translation().y(), T.angle()); });

  py::class_<OptimizeResult>(module, "OptimizeResult")
      .def("at", &OptimizeResult::at, "The optimized value of a key", py::arg("key"))
      .def("marginal_covariance", &OptimizeResult::marginal_covariance,
           "Covariance of a variable in its tangent space (Pose3: translation, rotation)", py::arg("key"))
      .def_property_readonly("initial_error", [](const OptimizeResult& r) { return r.summary.initial_chi2; })
      .def_property_readonly("final_error", [](const OptimizeResult& r) { return r.summary.final_chi2; })
      .def_property_readonly("iterations", [](const OptimizeResult& r) { return r.summary.iterations; })
      .def_property_readonly("converged", [](const OptimizeResult& r) { return r.summary.converged; })
      .def("g2o_chi2", &OptimizeResult::g2o_chi2, "g2o's chi2 of the result (graphs read from a file)")
      .def("se_sync_objective", &OptimizeResult::se_sync_objective,
           "SE-Sync's objective of the result, comparable with its published optima (graphs read from a file)")
      .def("write_g2o", &OptimizeResult::write_g2o, "Writes the file's graph with the optimized vertices", py::arg("path"))
      .def("certificate", &OptimizeResult::certificate,
           "SE-Sync's global-optimality certificate of the result, refined on SE-Sync's objective: a dict with certified, "
           "min_eigenvalue, se_sync_objective, max_translation_change, max_rotation_change, message (graphs read from a file)")
      .def("keys", [](const OptimizeResult& r) {
        std::vector<graph::Key> keys;
        for (const auto& [key, value] : r.values.all()) keys.push_back(key);
        return keys;
      });

  py::class_<PyFactorGraph>(module, "FactorGraph", "Factors of a pose graph; noise is a covariance matrix or a vector of sigmas")
      .def(py::init<>())
      .def("add_between_factor", &PyFactorGraph::add_between_factor, "Odometry or loop closure: pose key_to in the frame of key_from",
           py::arg("key_from"), py::arg("key_to"), py::arg("measurement"), py::arg("noise"))
      .def("add_prior_factor", &PyFactorGraph::add_prior_factor, py::arg("key"), py::arg("prior"), py::arg("noise"))
      .def("add_gps_factor", &PyFactorGraph::add_gps_factor, "A GNSS position in the local ENU frame (metres; see geodetic_to_enu)",
           py::arg("key"), py::arg("measurement"), py::arg("noise"), py::arg("lever_arm") = Eigen::Vector3d::Zero())
      .def("add_imu_factor", &PyFactorGraph::add_imu_factor,
           "IMU preintegration between keyframes i and j (poses T_world_imu, world velocities, the bias at i)", py::arg("pose_i"),
           py::arg("velocity_i"), py::arg("pose_j"), py::arg("velocity_j"), py::arg("bias_i"), py::arg("preintegration"))
      .def("add_bias_random_walk_factor", &PyFactorGraph::add_bias_random_walk_factor,
           "IMU biases drifting as random walks (m/s^2/sqrt(s), rad/s/sqrt(s)) over dt seconds", py::arg("bias_i"), py::arg("bias_j"),
           py::arg("dt"), py::arg("accel_bias_random_walk"), py::arg("gyro_bias_random_walk"))
      .def("add_gravity_factor", &PyFactorGraph::add_gravity_factor,
           "Roll and pitch of a pose T_world_imu from a static accelerometer's specific force (m/s^2)", py::arg("key"),
           py::arg("specific_force"), py::arg("noise"), py::arg("gravity") = Eigen::Vector3d(0.0, 0.0, -9.80665))
      .def("add_projection_factor", &PyFactorGraph::add_projection_factor,
           "The pixel of landmark L(j) (a world point) seen by a camera mounted at T_body_camera on pose X(i)", py::arg("pose"),
           py::arg("landmark"), py::arg("pixel"), py::arg("camera"), py::arg("T_body_camera"), py::arg("noise"))
      .def("add_stereo_factor", &PyFactorGraph::add_stereo_factor,
           "(u_left, u_right, v) of a landmark in a rectified stereo pair, the right camera baseline metres along the left's x",
           py::arg("pose"), py::arg("landmark"), py::arg("measured"), py::arg("camera"), py::arg("baseline"), py::arg("T_body_camera"),
           py::arg("noise"))
      .def("insert", &PyFactorGraph::insert, "An initial value (optional: optimize() chains between factors)", py::arg("key"), py::arg("value"))
      .def("optimize", &PyFactorGraph::optimize,
           "Batch Levenberg-Marquardt from the initial values ('initial') or, for a graph read from a file, from the chordal "
           "relaxation of its rotations ('chordal')",
           py::arg("max_iterations") = 100, py::arg("initialization") = "initial")
      .def("__len__", &PyFactorGraph::size);
  module.def("read_g2o", &PyFactorGraph::from_file,
             "A pose graph from a g2o (VERTEX_SE2 / EDGE_SE2, VERTEX_SE3:QUAT / EDGE_SE3:QUAT, FIX) or TORO .graph file; "
             "objective 'geodesic' (g2o's between factors) or 'chordal' (SE-Sync's objective, whose optima it publishes)",
             py::arg("path"), py::arg("objective") = "geodesic");
  py::class_<PyIncrementalSmoother>(module, "IncrementalSmoother",
                                    "Keyframe-rate smoothing: each update() adds factors and new variables and re-optimizes around them")
      .def(py::init<int, bool>(), py::arg("recent_variables") = 50, py::arg("background_batch") = true)
      .def("update", &PyIncrementalSmoother::update,
           "Adds a FactorGraph's factors and the initial values inserted into it (new variables only)", py::arg("new_factors"))
      .def("at", &PyIncrementalSmoother::at, "The current estimate of a key", py::arg("key"))
      .def("wait_for_batch", &PyIncrementalSmoother::wait_for_batch, "Runs the full batch to convergence; returns its chi2")
      .def("__len__", &PyIncrementalSmoother::size);

  bind_laser_slam(module);
  bind_lidar_odometry(module);
  bind_session(module);
  bind_object_store(module);
  bind_sensor_log(module);
  bind_evaluation(module);
}
