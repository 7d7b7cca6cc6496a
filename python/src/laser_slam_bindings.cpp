// Python bindings of 2D laser SLAM (pipeline/planar_laser_slam.hpp) and the CARMEN log reader:
// scans as N x 2 numpy arrays (metres, laser frame), poses as Pose2. Bad input raises
// ValueError with the library's message.

#include <fmt/format.h>
#include <pybind11/eigen.h>
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>

#include "hanzo/fusion/io/carmen_import.hpp"
#include "hanzo/fusion/pipeline/planar_laser_slam.hpp"

namespace py = pybind11;
using namespace hanzo::fusion;

namespace {

using PointRows = Eigen::Matrix<double, Eigen::Dynamic, 2, Eigen::RowMajor>;

// A CARMEN log's scans and logged poses, ready for numpy.
struct PyCarmenLog {
  std::vector<double> times;      // s
  std::vector<PointRows> scans;   // laser frame, m
  Eigen::MatrixXd poses;          // N x 3: x, y, theta of each scan's logged pose
};

PyCarmenLog read_carmen(const std::string& path) {
  auto log = io::read_carmen(path, {});
  if (!log) throw py::value_error(log.error().message);
  PyCarmenLog out;
  out.poses.resize(static_cast<Eigen::Index>(log->scans.size()), 3);
  for (size_t i = 0; i < log->scans.size(); ++i) {
    const msgs::PointCloudMessage& scan = log->scans[i];
    out.times.push_back(scan.timestamp.seconds());
    PointRows points(static_cast<Eigen::Index>(scan.points.size()), 2);
    for (size_t j = 0; j < scan.points.size(); ++j) points.row(static_cast<Eigen::Index>(j)) << scan.points[j].x(), scan.points[j].y();
    out.scans.push_back(std::move(points));
    const SE2 pose = io::planar_pose(log->report.scan_poses.poses[i]);
    out.poses.row(static_cast<Eigen::Index>(i)) << pose.translation().x(), pose.translation().y(), pose.angle();
  }
  return out;
}

pipeline::PlanarScanEstimate add_scan(pipeline::PlanarLaserSlam& slam, double time_s, const PointRows& points, const SE2& odometry) {
  if (!std::isfinite(time_s)) throw py::value_error("add_scan: the time is not finite");
  lidar::PlanarPoints planar(static_cast<size_t>(points.rows()));
  for (Eigen::Index i = 0; i < points.rows(); ++i) planar[static_cast<size_t>(i)] = points.row(i).transpose();
  auto estimate = slam.add_scan(Timestamp::from_seconds(time_s), planar, odometry);
  if (!estimate) throw py::value_error(estimate.error().message);
  return *estimate;
}

py::dict summary_of(const pipeline::PlanarLaserSlam& slam) {
  const pipeline::PlanarLaserSlamSummary& s = slam.summary();
  py::dict d;
  d["scans"] = s.scans;
  d["keyframes"] = s.keyframes;
  d["unmatched_scans"] = s.unmatched_scans;
  d["degenerate_scans"] = s.degenerate_scans;
  d["recovered_matches"] = s.recovered_matches;
  d["loop_candidates"] = s.loop_candidates;
  d["loop_closures"] = s.loop_closures;
  d["optimizations"] = s.optimizations;
  return d;
}

}  // namespace

void bind_laser_slam(py::module_& module) {
  py::class_<PyCarmenLog>(module, "CarmenLog", "Scans (N x 2 arrays, laser frame) and logged poses (x, y, theta) of a CARMEN log")
      .def_readonly("times", &PyCarmenLog::times)
      .def_readonly("scans", &PyCarmenLog::scans)
      .def_readonly("poses", &PyCarmenLog::poses)
      .def("__len__", [](const PyCarmenLog& log) { return log.scans.size(); });
  module.def("read_carmen", &read_carmen, "Reads a CARMEN log (FLASER lines; plain or .gz)", py::arg("path"));

  py::class_<pipeline::PlanarScanEstimate>(module, "PlanarScanEstimate")
      .def_readonly("pose", &pipeline::PlanarScanEstimate::T_map_laser, "T_map_laser")
      .def_readonly("keyframe", &pipeline::PlanarScanEstimate::keyframe)
      .def_readonly("scan_matched", &pipeline::PlanarScanEstimate::scan_matched)
      .def_readonly("degenerate", &pipeline::PlanarScanEstimate::degenerate)
      .def_readonly("loop_closures_added", &pipeline::PlanarScanEstimate::loop_closures_added);

  py::class_<pipeline::PlanarLaserSlam>(module, "PlanarLaserSlam",
                                        "2D laser SLAM: scan-to-map matching, loop closure, pose-graph optimization (docs/laser-slam.md)")
      .def(py::init([](bool loop_closure) {
             pipeline::PlanarLaserSlamConfig config;
             config.loop_closure = loop_closure;
             return pipeline::PlanarLaserSlam(config);
           }),
           py::arg("loop_closure") = true)
      .def("add_scan", &add_scan, "A scan (N x 2 points, laser frame, m) at time_s with the laser's odometry pose",
           py::arg("time_s"), py::arg("points"), py::arg("odometry"))
      .def("finish", [](pipeline::PlanarLaserSlam& slam) {
        if (Status done = slam.finish(); !done) throw py::value_error(done.error().message);
      }, "Optimizes the whole graph to convergence")
      .def("trajectory", [](const pipeline::PlanarLaserSlam& slam) {
        const io::Trajectory trajectory = slam.trajectory();
        Eigen::MatrixXd poses(static_cast<Eigen::Index>(trajectory.size()), 3);
        std::vector<double> times;
        for (size_t i = 0; i < trajectory.size(); ++i) {
          const SE2 pose = io::planar_pose(trajectory.poses[i]);
          poses.row(static_cast<Eigen::Index>(i)) << pose.translation().x(), pose.translation().y(), pose.angle();
          times.push_back(trajectory.timestamps[i].seconds());
        }
        return py::make_tuple(times, poses);
      }, "(times, N x 3 array of x, y, theta) of every scan, optimized")
      .def("summary", &summary_of);
}
