// Python bindings of trajectory evaluation (eval/: evo's APE and RPE definitions, its
// timestamp association and alignments) and trajectory files (io/trajectory.hpp).
// Trajectories are N x 8 numpy arrays, one row (t, x, y, z, qw, qx, qy, qz) per pose: time in
// seconds, T_world_body, as Session.poses() and Session.optimized_trajectory() give them.
// Bad input (wrong shape, times that do not increase, zero quaternions, no associated pairs)
// raises ValueError naming it.

#include <cmath>
#include <string>

#include <fmt/format.h>
#include <pybind11/eigen.h>
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>

#include "hanzo/fusion/eval/association.hpp"
#include "hanzo/fusion/eval/pose_error.hpp"
#include "hanzo/fusion/io/trajectory.hpp"

namespace py = pybind11;
using namespace hanzo::fusion;

namespace {

using PoseRows = Eigen::Matrix<double, Eigen::Dynamic, 8, Eigen::RowMajor>;

template <typename T>
T value_or_raise(Result<T> result, const std::string& what) {
  if (!result) throw py::value_error(fmt::format("{}: {}", what, result.error().message));
  return std::move(*result);
}

io::Trajectory trajectory_from(const Eigen::Ref<const Eigen::MatrixXd>& rows, const char* name) {
  if (rows.cols() != 8) throw py::value_error(fmt::format("{}: expected N x 8 rows (t, x, y, z, qw, qx, qy, qz), got {} columns", name, rows.cols()));
  io::Trajectory trajectory;
  for (Eigen::Index i = 0; i < rows.rows(); ++i) {
    if (!rows.row(i).allFinite()) throw py::value_error(fmt::format("{}: row {} is not finite", name, i));
    const Timestamp time = Timestamp::from_seconds(rows(i, 0));
    if (!trajectory.timestamps.empty() && time <= trajectory.timestamps.back()) {
      throw py::value_error(fmt::format("{}: row {}: time {} does not increase", name, i, rows(i, 0)));
    }
    const Eigen::Quaterniond q(rows(i, 4), rows(i, 5), rows(i, 6), rows(i, 7));
    if (q.norm() < 1e-9) throw py::value_error(fmt::format("{}: row {}: zero quaternion", name, i));
    io::PoseMatrix pose = io::PoseMatrix::Identity();
    pose.block<3, 3>(0, 0) = q.normalized().toRotationMatrix();
    pose.block<3, 1>(0, 3) = rows.row(i).segment<3>(1).transpose();
    trajectory.timestamps.push_back(time);
    trajectory.poses.push_back(pose);
  }
  return trajectory;
}

PoseRows rows_from(const io::Trajectory& trajectory) {
  PoseRows rows(static_cast<Eigen::Index>(trajectory.size()), 8);
  for (std::size_t i = 0; i < trajectory.size(); ++i) {
    const Eigen::Quaterniond q(trajectory.poses[i].block<3, 3>(0, 0));
    const Eigen::Vector3d t = trajectory.position(i);
    rows.row(static_cast<Eigen::Index>(i)) << trajectory.timestamps[i].seconds(), t.x(), t.y(), t.z(), q.w(), q.x(), q.y(), q.z();
  }
  return rows;
}

eval::AssociatedTrajectories associate(const Eigen::Ref<const Eigen::MatrixXd>& reference, const Eigen::Ref<const Eigen::MatrixXd>& estimate,
                                       double max_time_difference, double time_offset) {
  eval::AssociationConfig config;
  config.max_time_difference_s = max_time_difference;
  config.estimate_time_offset_s = time_offset;
  return value_or_raise(eval::associate(trajectory_from(reference, "reference"), trajectory_from(estimate, "estimate"), config), "association");
}

py::dict statistics_dict(const eval::ErrorStatistics& statistics, const std::vector<double>& errors, const eval::SimilarityTransform& alignment) {
  py::dict result;
  result["rmse"] = statistics.rmse;
  result["mean"] = statistics.mean;
  result["median"] = statistics.median;
  result["std"] = statistics.std;
  result["min"] = statistics.min;
  result["max"] = statistics.max;
  result["sse"] = statistics.sse;
  result["count"] = errors.size();
  result["errors"] = Eigen::VectorXd(Eigen::Map<const Eigen::VectorXd>(errors.data(), static_cast<Eigen::Index>(errors.size())));
  py::dict transform;
  transform["rotation"] = alignment.rotation;
  transform["translation"] = alignment.translation;
  transform["scale"] = alignment.scale;
  result["alignment"] = transform;
  return result;
}

py::dict ape(const Eigen::Ref<const Eigen::MatrixXd>& reference, const Eigen::Ref<const Eigen::MatrixXd>& estimate, const std::string& alignment,
             const std::string& relation, double max_time_difference, double time_offset, int align_num_poses) {
  eval::ApeConfig config;
  config.alignment = value_or_raise(eval::alignment_from_name(alignment), "alignment");
  config.relation = value_or_raise(eval::pose_relation_from_name(relation), "relation");
  config.align_num_poses = align_num_poses;
  const eval::AssociatedTrajectories pairs = associate(reference, estimate, max_time_difference, time_offset);
  const eval::ApeResult result = value_or_raise(eval::compute_ape(pairs.reference, pairs.estimate, config), "ape");
  py::dict out = statistics_dict(result.statistics, result.errors, result.alignment);
  out["estimate_aligned"] = rows_from(result.estimate_aligned);
  out["reference"] = rows_from(result.reference);
  return out;
}

py::dict rpe(const Eigen::Ref<const Eigen::MatrixXd>& reference, const Eigen::Ref<const Eigen::MatrixXd>& estimate, double delta,
             const std::string& delta_unit, const std::string& relation, bool all_pairs, const std::string& alignment,
             double max_time_difference, double time_offset) {
  eval::RpeConfig config;
  config.delta = delta;
  config.delta_unit = value_or_raise(eval::delta_unit_from_name(delta_unit), "delta_unit");
  config.relation = value_or_raise(eval::pose_relation_from_name(relation), "relation");
  config.all_pairs = all_pairs;
  config.alignment = value_or_raise(eval::alignment_from_name(alignment), "alignment");
  const eval::AssociatedTrajectories pairs = associate(reference, estimate, max_time_difference, time_offset);
  const eval::RpeResult result = value_or_raise(eval::compute_rpe(pairs.reference, pairs.estimate, config), "rpe");
  py::dict out = statistics_dict(result.statistics, result.errors, result.alignment);
  out["pairs"] = result.pairs;
  return out;
}

}  // namespace

void bind_evaluation(py::module_& module) {
  module.def(
      "read_trajectory",
      [](const std::string& path, const std::string& format) {
        return rows_from(value_or_raise(io::read_trajectory(path, value_or_raise(io::trajectory_format_from_name(format), "format")), path));
      },
      py::arg("path"), py::arg("format") = "tum", "A TUM, KITTI or EuRoC trajectory file as N x 8 rows (t, x, y, z, qw, qx, qy, qz)");
  module.def(
      "write_trajectory",
      [](const std::string& path, const Eigen::Ref<const Eigen::MatrixXd>& poses, const std::string& format) {
        const Status written = io::write_trajectory(path, trajectory_from(poses, "poses"), value_or_raise(io::trajectory_format_from_name(format), "format"));
        if (!written) throw py::value_error(written.error().message);
      },
      py::arg("path"), py::arg("poses"), py::arg("format") = "tum", "Writes N x 8 rows as a TUM, KITTI or EuRoC file (atomically)");
  module.def("ape", &ape, py::arg("reference"), py::arg("estimate"), py::arg("alignment") = "none", py::arg("relation") = "trans_part",
             py::arg("max_time_difference") = 0.01, py::arg("time_offset") = 0.0, py::arg("align_num_poses") = -1,
             "Absolute pose error as evo computes it. alignment: none, se3, sim3, scale, translation, origin; relation: trans_part (m), "
             "angle_deg, angle_rad, rot_part, full. Returns rmse, mean, median, std, min, max, sse, count, errors, alignment, "
             "estimate_aligned, reference");
  module.def("rpe", &rpe, py::arg("reference"), py::arg("estimate"), py::arg("delta") = 1.0, py::arg("delta_unit") = "f",
             py::arg("relation") = "trans_part", py::arg("all_pairs") = false, py::arg("alignment") = "none",
             py::arg("max_time_difference") = 0.01, py::arg("time_offset") = 0.0,
             "Relative pose error over pose pairs delta apart (delta_unit: f, m, deg, rad), as evo computes it. Returns the statistics, "
             "errors, pairs, alignment");
}
